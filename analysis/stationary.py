"""Stationary grasp (paper eq. 18): joint torques that hold the object still.

``-w_ex = D tau_st + Xi xi_st = G_c W_f x_st`` with ``W_f x_st`` in the friction set ``F``.
The unknowns are the contact forces ``f_c = W_f x_st`` (every ``f_c`` is reachable, as
``W_f = [(J_c^T)^+, Gamma]`` spans the force space), and ``tau_st = J_c^T f_c``. In the
stationary state an S-point carries a normal force only (no slip, no kinetic friction).

Two members are offered:

* ``"min_grip"``: the least total normal force (an LP);
* ``"interior"`` (default): the most interior one, maximising the smallest distance ``s`` of
  ``f_c`` to the friction-set facets (rows of unit norm) and to ``n_f = 0`` at every loaded
  contact, with the total normal force at most ``2 N*`` (twice the minimum grip; ``1`` when
  ``N* = 0``) so that the margin is not bought by squeezing without bound.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.exceptions import NoStationaryGrasp, SolverError
from analysis.friction import FrictionSet
from analysis.solvers.highs import solve_lp
from analysis.statics import Statics

Kind = Literal["interior", "min_grip"]


@dataclass(frozen=True)
class StationaryGrasp:
    """A solution of eq. (18)."""

    kind: Kind
    f_c: Array  # (L_c,) contact forces
    tau: Array  # (M,) tau_st = J_c^T f_c
    xi_t: Array  # (p_bar,) xi~_st = Gamma^T f_c
    margin: float  # smallest distance to a friction facet (interior) or 0
    total_normal: float

    def __post_init__(self) -> None:
        assert np.all(np.isfinite(self.f_c)) and np.all(np.isfinite(self.tau))

    @property
    def x(self) -> Array:
        """``x_st = [tau_st; xi~_st]``."""
        return np.concatenate([self.tau, self.xi_t])

    def equilibrium_residual(self, st: Statics, w_ex: Array) -> float:
        """``|G_c f_c + w_ex|``: zero for a stationary grasp."""
        return float(np.linalg.norm(st.G_c @ self.f_c + w_ex))


def _normal_rows(fs: FrictionSet) -> Array:
    """Rows of ``fs.N`` of the contacts that carry force: ``(L_loaded, L_c)``."""
    keep = np.any(fs.N != 0.0, axis=1)
    return fs.N[keep]


def min_total_normal(system: GraspSystem, st: Statics, fs: FrictionSet) -> tuple[float, Array] | None:
    """``N* = min sum n_f`` subject to (18); ``None`` when (18) has no solution."""
    L_c = st.G_c.shape[1]
    if L_c == 0:
        return (0.0, np.zeros(0)) if np.allclose(system.w_ex, 0.0) else None
    Nr = _normal_rows(fs)
    res = solve_lp(Nr.sum(axis=0), A_ub=fs.C, b_ub=np.zeros(fs.C.shape[0]), A_eq=st.G_c, b_eq=-system.w_ex)
    if res.status != "optimal":
        return None
    assert res.x is not None and res.objective is not None
    return float(res.objective), res.x


def _minimum(system: GraspSystem, sel: Selection, st: Statics, fs: FrictionSet) -> tuple[float, Array]:
    found = min_total_normal(system, st, fs)
    if found is None:
        raise NoStationaryGrasp(
            f"combination {sel.combination}: no contact forces in the friction set balance the external "
            "wrench (eq. 18 infeasible)"
        )
    return found


def _interior(system: GraspSystem, st: Statics, fs: FrictionSet, n_star: float, f_min: Array) -> StationaryGrasp:
    """The most interior solution of (18), given the minimum grip ``(N*, f_min)``."""
    L_c = st.G_c.shape[1]
    if L_c == 0:
        return _make("interior", f_min, st, fs, 0.0)
    Nr = _normal_rows(fs)
    budget = 2.0 * n_star if n_star > 1e-9 else 1.0
    # variables [f_c (L_c), s]: maximise s s.t. C f + s <= 0, -n_f + s <= 0, sum n_f <= budget
    m = fs.C.shape[0]
    A_ub = np.vstack(
        [
            np.hstack([fs.C, np.ones((m, 1))]),
            np.hstack([-Nr, np.ones((Nr.shape[0], 1))]),
            np.hstack([Nr.sum(axis=0)[None, :], np.zeros((1, 1))]),
        ]
    )
    b_ub = np.concatenate([np.zeros(m + Nr.shape[0]), [budget]])
    A_eq = np.hstack([st.G_c, np.zeros((st.G_c.shape[0], 1))])
    res = solve_lp(
        np.r_[np.zeros(L_c), 1.0], A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=-system.w_ex, maximize=True
    )
    if res.status != "optimal":  # feasible (f_min, s = min margin) and bounded by the budget
        raise SolverError("HiGHS", f"interior stationary grasp LP ended '{res.status}'")
    assert res.x is not None
    if res.x[-1] < 0.0:
        # f_min with s = 0 is feasible, so a negative optimum is a numerical failure on a
        # near-singular G_c (its point violates the friction rows): keep the minimum grip
        return _make("interior", f_min, st, fs, 0.0)
    return _make("interior", res.x[:L_c], st, fs, float(res.x[-1]))


def stationary_grasp(
    system: GraspSystem, sel: Selection, st: Statics, fs: FrictionSet, kind: Kind = "interior"
) -> StationaryGrasp:
    """Solve eq. (18); raise :class:`NoStationaryGrasp` when the contacts cannot hold the object."""
    n_star, f_min = _minimum(system, sel, st, fs)
    if kind == "min_grip":
        return _make("min_grip", f_min, st, fs, 0.0)
    return _interior(system, st, fs, n_star, f_min)


def stationary_grasps(
    system: GraspSystem, sel: Selection, st: Statics, fs: FrictionSet
) -> tuple[StationaryGrasp, StationaryGrasp]:
    """Both members of (18), ``(interior, min_grip)``, from one minimum-grip LP."""
    n_star, f_min = _minimum(system, sel, st, fs)
    return _interior(system, st, fs, n_star, f_min), _make("min_grip", f_min, st, fs, 0.0)


def _make(kind: Kind, f_c: Array, st: Statics, fs: FrictionSet, margin: float) -> StationaryGrasp:
    return StationaryGrasp(
        kind=kind,
        f_c=f_c,
        tau=st.J_c.T @ f_c,
        xi_t=st.Gamma.T @ f_c,
        margin=margin,
        total_normal=float((fs.N @ f_c).sum()),
    )
