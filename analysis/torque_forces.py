"""The contact forces a given joint torque produces (eq. 29 read backwards, with W_2 of eq. 22).

The torque set (32) is built at one grasp, for the motion's first instant. A plan holds its
chosen torque ``tau`` constant while the object moves a finite distance, so at a later grasp of
the same contacts (the hand at ``q``, the object at its pose) the question is the converse: which
contact forces does that ``tau`` produce there, and are they still in the friction set?

With massless fingers (the paper's model) every joint torque is balanced by contact forces,
``tau = T f_c`` (29, ``T = J_c^T`` plus the kinetic friction's joint part at S-points; eq. 8),
and the object, moving in the motion space, carries no unbalanced wrench in the directions its
contacts block: ``Xi^T w = 0``, ``w = W f_c + w_ex`` (the ``W_2`` row of 22, ``W = G_c`` plus
kinetic friction). Those are linear in ``f_c``; their solutions are ``f_c`` up to the internal
forces that load neither the joints nor the object (none in a generic grasp: every F-point of a
tip-contact finger is then determinate). :func:`torque_forces` finds, among them, the one deepest
inside the friction set ``C f_c <= 0`` (16), an LP maximising the margin ``m`` with
``C f_c + m <= 0`` (rows of unit norm, so ``m`` is the distance in newtons to the nearest facet;
negative: outside the friction set by that much).

The part of ``tau`` no contact force can balance (its component off ``range(T)``: the
self-motion of a redundant hand, joint motions that move no contact) is reported apart as
``unbalanced``; the analysis requires it to vanish (``Lambda~_qr^T tau_ad = 0`` of 30), a replay
holds it with a posture torque.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.exceptions import SolverError
from analysis.friction import FrictionSet, kinetic_friction
from analysis.linalg import orth
from analysis.solvers.highs import solve_lp
from analysis.statics import Statics

#: relative tolerance of the equalities: ``tau``'s part in ``range(T)`` and ``Xi^T w = 0`` hold to
#: this times the torque and wrench scale, else no force produces ``tau`` at this grasp
EQUALITY_RTOL = 1e-7


@dataclass(frozen=True)
class TorqueForces:
    """The contact forces one joint torque produces at one grasp (:func:`torque_forces`).

    ``realised``: some forces satisfy ``T f_c = tau`` (up to ``unbalanced``) and ``Xi^T w = 0``;
    ``f_c`` ``(L_c,)`` those deepest in the friction set (``None`` when not realised); ``margin``
    (newtons) their smallest distance to a facet of the friction set (16), negative outside it
    (``-inf`` when not realised); ``unbalanced`` ``(M,)`` the part of ``tau`` off ``range(T)``."""

    realised: bool
    f_c: Array | None  # (L_c,)
    margin: float
    unbalanced: Array  # (M,)

    @property
    def in_friction_set(self) -> bool:
        """The forces lie in the friction set (16): ``margin >= 0``."""
        return self.realised and self.margin >= 0.0


def torque_forces(system: GraspSystem, sel: Selection, st: Statics, fs: FrictionSet, tau: Array,
                  slips: Array | None = None) -> TorqueForces:
    """The forces ``tau`` ``(M,)`` produces at the grasp of ``system`` with the combination
    ``sel`` (module docstring); ``slips`` ``(#S, d)``: the S-points' slips (required with S-points,
    for their kinetic friction, eq. 12). Raises :class:`SolverError` when HiGHS fails."""
    tau = np.asarray(tau, dtype=float).ravel()  # (M,)
    W_map, T_map = st.G_c, st.J_c.T  # (D, L_c), (M, L_c)
    if sel.s_index:
        if slips is None:
            raise ValueError("slips: required for a combination with S-points")
        kf = kinetic_friction(system, sel, slips)
        W_map, T_map = st.G_c + kf.G_w, st.J_c.T + kf.J_w
    L_c = T_map.shape[1]
    U = orth(T_map)  # (M, r) range of T
    unbalanced = tau - U @ (U.T @ tau)  # (M,)
    w_ex = system.w_ex  # (D,)
    scale_t = 1.0 + float(np.max(np.abs(tau), initial=0.0))
    scale_w = 1.0 + float(np.max(np.abs(w_ex), initial=0.0))
    if L_c == 0:
        ok = float(np.max(np.abs(st.Xi.T @ w_ex), initial=0.0)) <= EQUALITY_RTOL * scale_w
        return TorqueForces(ok, np.zeros(0) if ok else None, np.inf if ok else -np.inf, unbalanced)
    # variables [f_c (L_c), m]: max m, C f + m <= 0, U^T T f = U^T tau, Xi^T W f = -Xi^T w_ex
    A_eq = np.vstack([np.hstack([U.T @ T_map / scale_t, np.zeros((U.shape[1], 1))]),
                      np.hstack([st.Xi.T @ W_map / scale_w, np.zeros((st.Xi.shape[1], 1))])])
    b_eq = np.concatenate([U.T @ tau / scale_t, -(st.Xi.T @ w_ex) / scale_w])
    C = fs.C  # (m, L_c), unit rows
    A_ub = np.hstack([C, np.ones((C.shape[0], 1))])
    cap = scale_t + scale_w  # the margin is bounded (a grasp with no friction row would be unbounded)
    lb = np.r_[np.full(L_c, -np.inf), -np.inf]
    ub = np.r_[np.full(L_c, np.inf), cap]
    res = solve_lp(np.r_[np.zeros(L_c), 1.0], A_ub=A_ub, b_ub=np.zeros(C.shape[0]), A_eq=A_eq, b_eq=b_eq,
                   lb=lb, ub=ub, maximize=True)
    if res.status == "infeasible":
        return TorqueForces(False, None, -np.inf, unbalanced)
    if not res.found or res.x is None:
        raise SolverError("highs", f"forces of a torque: {res.status}")
    f = np.asarray(res.x[:L_c])
    if max(float(np.max(np.abs(A_eq[:, :L_c] @ f - b_eq), initial=0.0)), 0.0) > EQUALITY_RTOL:
        return TorqueForces(False, None, -np.inf, unbalanced)
    margin = float(-np.max(C @ f, initial=-cap)) if C.shape[0] else cap
    return TorqueForces(True, f, margin, unbalanced)


__all__ = ["EQUALITY_RTOL", "TorqueForces", "torque_forces"]
