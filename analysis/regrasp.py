"""Finger motions that regrasp without moving the object (paper eq. 33).

With ``dr = 0`` the finger motions that keep the F/S/N constraints are ``dq = Lambda~_qr
dzeta~_r``; D-points must not penetrate (``J_d dq <= 0``) and the object must stay in
equilibrium, S-points adding kinetic friction against their slip ``-J_s dq``:

    A' = {dq = Lambda~_qr z : J_d Lambda~_qr z <= 0,
          G_c f_c + w_s(f_c, dq) = -w_ex,  f_c in F,  S friction = -mu n slip/|slip|}.

Without S-points the force condition is the stationary grasp (18), independent of ``dq``, so A'
is exactly the polyhedral cone ``{J_d dq <= 0}`` on the redundancy (vertices/rays by cdd). With
S-points each generator is checked by an LP with its own friction directions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.friction import FrictionSet, kinetic_friction
from analysis.motion import MotionSpace
from analysis.solvers.cdd import Generators, cone_generators
from analysis.solvers.highs import solve_lp
from analysis.statics import Statics


@dataclass(frozen=True)
class RegraspCone:
    """The cone A' of eq. (33) in joint space."""

    J_d: Array  # (#D, M) normal rows of the D-points (A' = {dq in range(Lambda~_qr): J_d dq <= 0})
    Lambda_qr_t: Array  # (M, r) redundancy basis
    rays: Array  # (k, M) generators (unit) of the kinematic cone
    lines: Array  # (l, M)
    feasible: Array  # (k + 2 l,) bool: generator keeps the object in equilibrium (S friction)
    exact: bool

    def contains(self, dq: Array, tol: float = 1e-9) -> bool:
        """Kinematic membership: in the redundancy and not penetrating any D-point."""
        dq = np.asarray(dq, dtype=float)
        P = self.Lambda_qr_t @ self.Lambda_qr_t.T
        in_range = float(np.linalg.norm(P @ dq - dq)) <= 1e-7 * max(1.0, float(np.linalg.norm(dq)))
        return in_range and bool(np.all(self.J_d @ dq <= tol))

    def directions(self) -> Array:
        return np.vstack([self.rays, self.lines, -self.lines]).reshape(-1, self.J_d.shape[1])


def regrasp_cone(
    system: GraspSystem, sel: Selection, ms: MotionSpace, st: Statics, fs: FrictionSet
) -> RegraspCone:
    """Eq. (33)."""
    M = system.M
    Lqr = ms.Lambda_qr_t  # (M, r)
    J_d = ms.A_d[:, :M]  # (#D, M)
    r = Lqr.shape[1]
    if r == 0:
        return RegraspCone(J_d, Lqr, np.zeros((0, M)), np.zeros((0, M)), np.zeros(0, bool), True)
    g: Generators = cone_generators(J_d @ Lqr) if J_d.shape[0] else Generators(
        np.zeros((1, r)), np.zeros((0, r)), np.eye(r)
    )
    rays = (g.rays @ Lqr.T).reshape(-1, M)
    lines = (g.lines @ Lqr.T).reshape(-1, M)
    dirs = np.vstack([rays, lines, -lines]).reshape(-1, M)
    if sel.s_index or not len(dirs):
        feasible = np.array([_equilibrium_with_sliding(system, sel, st, fs, dq) for dq in dirs], dtype=bool)
    else:  # no S-point: the equilibrium does not depend on dq (the stationary grasp, 18), one LP for all
        feasible = np.full(len(dirs), _equilibrium_with_sliding(system, sel, st, fs, dirs[0]), dtype=bool)
    return RegraspCone(J_d, Lqr, rays, lines, feasible, exact=not sel.s_index)


def sliding_equilibrium(
    system: GraspSystem, sel: Selection, st: Statics, fs: FrictionSet, dq: Array
) -> bool:
    """Eq. (33) for one finger motion ``dq`` ``(M,)`` with the object still: whether some ``f_c`` in
    the friction set ``F`` (16) of the F-points and the S-points' kinetic friction against their
    slip ``-J_s dq`` (11-12, on the cone boundary, ``n >= 0``) balance the external wrench,
    ``G_c f_c + w_s = -w_ex`` (one LP; False when an S-point does not slip)."""
    return _equilibrium_with_sliding(system, sel, st, fs, dq)


def _equilibrium_with_sliding(
    system: GraspSystem, sel: Selection, st: Statics, fs: FrictionSet, dq: Array
) -> bool:
    """LP: is there ``f_c in F`` with ``G_c f_c + w_s = -w_ex`` for the finger motion ``dq``?"""
    G_eff = st.G_c
    if sel.s_index:
        slip = np.array([-(system.J_blocks[i] @ dq) for i in sel.s_index])  # object rel. finger
        if np.any(np.linalg.norm(slip, axis=1) < 1e-9 * max(1.0, float(np.linalg.norm(dq)))):
            return False  # an S-point must slide
        G_eff = st.G_c + kinetic_friction(system, sel, slip).G_w
    if G_eff.shape[1] == 0:
        return bool(np.allclose(system.w_ex, 0.0))
    res = solve_lp(np.zeros(G_eff.shape[1]), A_ub=fs.C, b_ub=np.zeros(fs.C.shape[0]), A_eq=G_eff,
                   b_eq=-system.w_ex)
    return res.found
