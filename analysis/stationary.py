"""Stationary grasp (paper eq. 18): joint torques that hold the object still.

``-w_ex = D tau_st + Xi xi_st = G_c W_f x_st`` with ``W_f x_st`` in the friction set ``F``.
The unknowns are the contact forces ``f_c = W_f x_st`` (every ``f_c`` is reachable, as
``W_f = [(J_c^T)^+, Gamma]`` spans the force space), and ``tau_st = J_c^T f_c``. In the
stationary state an S-point carries a normal force only (no slip, no kinetic friction).

Two members are offered:

* ``"min_grip"``: the least total normal force (an LP);
* ``"interior"`` (default): the most interior one, maximising the smallest distance ``s`` of
  ``f_c`` to the friction-set facets (rows of unit norm) and to ``n_f = 0`` at every loaded
  contact, with the total normal force at most ``2 N*`` (twice the minimum grip; ``F0`` when
  ``N* = 0``) so that the margin is not bought by squeezing without bound.

Both are posed in the scales of :mod:`analysis.scales` (unknowns ``f_c / F0``, equilibrium rows
in units of ``F0`` and ``F0 l``), bounded by a total normal force of ``GRIP_BOUND F0``, and
re-checked in newtons before they are returned: a verdict "the contacts hold the object" always
comes with forces that satisfy (18) to ``FORCE_TOL F0``.

Joint torque limits (:mod:`analysis.torque_limits`, the scene's ``joint_torque_limits`` or the
URDF's efforts) bound ``tau_st = J_c^T f_c``: ``|tau_st_j| <= tau_max_j`` is a row of every LP
here. When only the limits stand in the way, :class:`NoStationaryGrasp` names the joints and the
torques they would need.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.exceptions import NoStationaryGrasp, SolverError
from analysis.friction import FrictionSet
from analysis.scales import FORCE_TOL, GRIP_BOUND, LP_FEAS_TOL, snap
from analysis.solvers.highs import solve_lp
from analysis.statics import Statics
from analysis.torque_limits import LIMIT_TOL, JointExcess, least_excess, limit_rows, over_limit

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


def stationary_residuals(system: GraspSystem, st: Statics, fs: FrictionSet, f_c: Array) -> tuple[float, float]:
    """``(equilibrium error, friction violation)`` of contact forces ``f_c`` in units of ``F0``:
    the largest component of ``G_c f_c + w_ex`` in ``(f / F0, m / (F0 l))`` and ``max(C f_c) / F0``
    (the rows of ``C`` have unit norm, so a violation is a force)."""
    sc = system.scales
    eq = sc.wrench_error(st.G_c @ f_c + system.w_ex) if st.G_c.shape[1] else sc.wrench_error(system.w_ex)
    fr = float(np.max(fs.C @ f_c, initial=0.0)) / sc.force if fs.C.shape[0] else 0.0
    return eq, max(fr, 0.0)


def certifies(system: GraspSystem, st: Statics, fs: FrictionSet, f_c: Array, tol: float = FORCE_TOL) -> bool:
    """Do the forces ``f_c`` solve (18) within ``tol * F0`` and the grip bound?"""
    eq, fr = stationary_residuals(system, st, fs, f_c)
    total = float((_normal_rows(fs) @ f_c).sum()) if f_c.size else 0.0
    within = over_limit(st.J_c.T @ f_c, system.tau_max, LIMIT_TOL).size == 0 if f_c.size else True
    return bool(eq <= tol and fr <= tol and total <= system.scales.grip_bound * (1 + tol) and within)


def _limits(system: GraspSystem, st: Statics) -> tuple[Array, Array]:
    """The joint torque limits as rows in the scaled unknowns ``g = f_c / F0``: ``(A (2 n_lim, L_c), b)``."""
    A, b = limit_rows(st.J_c.T, system.tau_max, system.scales.force)
    return snap(A), b


def _equilibrium(system: GraspSystem, st: Statics) -> tuple[Array, Array]:
    """``G_c f = -w_ex`` in the scaled unknowns ``g = f / F0``, rows in units of F0 (forces) and
    ``F0 l`` (moments): ``(A_eq (D, L_c), b_eq (D,))``."""
    sc = system.scales
    rows = sc.wrench_weights() * sc.force  # 1 on force rows, 1/l on moment rows
    return snap(rows[:, None] * st.G_c), snap(-(rows * system.w_ex) / sc.force)


def min_total_normal(system: GraspSystem, st: Statics, fs: FrictionSet) -> tuple[float, Array] | None:
    """``N* = min sum n_f`` subject to (18) and ``sum n_f <= GRIP_BOUND F0``; ``None`` when no such
    forces exist. The LP is posed in the scaled unknowns ``f / F0`` with equilibrated rows, and its
    solution is re-checked in newtons (:func:`certifies`). A run that ends undecided or whose
    solution fails the check is repeated with HiGHS' default strategy, then its interior-point
    method; after that the failure is raised as :class:`SolverError`."""
    L_c = st.G_c.shape[1]
    sc = system.scales
    if L_c == 0:
        return (0.0, np.zeros(0)) if sc.wrench_error(system.w_ex) <= FORCE_TOL else None
    n_sum = _normal_rows(fs).sum(axis=0)  # (L_c,)
    A_eq, b_eq = _equilibrium(system, st)
    A_lim, b_lim = _limits(system, st)
    A_ub = np.vstack([fs.C, n_sum[None, :], A_lim])
    b_ub = np.r_[np.zeros(fs.C.shape[0]), GRIP_BOUND, b_lim]
    failure = "no method decided the LP"
    methods: tuple[Literal["warm", "defaults", "ipm"], ...] = ("warm", "defaults", "ipm")
    for method in methods:
        try:
            res = solve_lp(n_sum, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, feasibility=LP_FEAS_TOL, method=method)
        except SolverError as e:  # undecided: ask the next method
            failure = str(e)
            continue
        if res.status != "optimal":
            return None
        assert res.x is not None
        f_c = res.x * sc.force
        if certifies(system, st, fs, f_c):
            return float(n_sum @ f_c), f_c
        eq, fr = stationary_residuals(system, st, fs, f_c)
        failure = (f"its solution fails the residual check in physical units (equilibrium {eq:.2e} F0, "
                   f"friction {fr:.2e} F0)")
    raise SolverError("HiGHS", f"stationary grasp LP: {failure}")


#: An infeasible (18) whose least friction violation is below this (units of F0) is degenerate.
DEGENERATE_TOL = 1e-6


def stationary_violation(system: GraspSystem, st: Statics, fs: FrictionSet) -> float | None:
    """``t* = min t`` s.t. ``C f_c <= t F0``, ``|G_c f_c + w_ex| <= t`` (units of F0 and F0 l),
    ``|tau_j| <= (1 + t) tau_max_j`` and the grip bound: how far (units of F0) the friction rows and
    the equilibrium must give for the contacts to hold the object (``<= 0`` when they do, strictly
    inside every loaded cone); ``None`` when no contact carries force."""
    L_c = st.G_c.shape[1]
    if L_c == 0:
        return None
    A_eq0, b_eq = _equilibrium(system, st)
    m, D = fs.C.shape[0], A_eq0.shape[0]
    n_sum = _normal_rows(fs).sum(axis=0)
    one_m, one_D = np.ones((m, 1)), np.ones((D, 1))
    A_lim, b_lim = _limits(system, st)
    one_l = np.ones((A_lim.shape[0], 1))
    A_ub = np.vstack([np.hstack([fs.C, -one_m]), np.hstack([A_eq0, -one_D]), np.hstack([-A_eq0, -one_D]),
                      np.r_[n_sum, 0.0][None, :], np.hstack([A_lim, -one_l])])
    b_ub = np.r_[np.zeros(m), b_eq, -b_eq, GRIP_BOUND, b_lim]
    lb = np.r_[np.full(L_c, -np.inf), -1.0]  # t >= -1: bounded below when the grasp is interior
    res = solve_lp(np.r_[np.zeros(L_c), 1.0], A_ub=A_ub, b_ub=b_ub, lb=lb)
    if res.status != "optimal" or res.objective is None:
        return None
    return float(res.objective)


def _minimum(system: GraspSystem, sel: Selection, st: Statics, fs: FrictionSet) -> tuple[float, Array]:
    found = min_total_normal(system, st, fs)
    if found is None and system.tau_max is not None and st.G_c.shape[1]:
        excess = _limit_excess(system, st, fs)
        if excess:
            raise NoStationaryGrasp(
                f"combination {sel.combination}: no stationary grasp (18) within the joint torque limits; "
                f"holding the object needs {'; '.join(e.describe() for e in excess)}"
            )
    if found is None:
        raise NoStationaryGrasp(
            f"combination {sel.combination}: no contact forces in the friction set balance the external "
            f"wrench with a total normal force of at most {GRIP_BOUND:g} x {system.scales.force:.4g} N "
            "(eq. 18 infeasible)"
        )
    return found


def _limit_excess(system: GraspSystem, st: Statics, fs: FrictionSet) -> tuple[JointExcess, ...]:
    """The joints over their limits in the stationary grasp that needs the least relaxation of them
    (``()`` if the limits are not what makes (18) infeasible)."""
    assert system.tau_max is not None
    n_sum = _normal_rows(fs).sum(axis=0)
    A = np.vstack([fs.C, n_sum[None, :]])
    b = np.r_[np.zeros(fs.C.shape[0]), GRIP_BOUND]
    found = least_excess((A, b), _equilibrium(system, st), snap(st.J_c.T), system.tau_max, system.scales.force,
                         system.joint_labels)
    return () if found is None else found


def _interior(system: GraspSystem, st: Statics, fs: FrictionSet, n_star: float, f_min: Array) -> StationaryGrasp:
    """The most interior solution of (18), given the minimum grip ``(N*, f_min)``."""
    L_c = st.G_c.shape[1]
    if L_c == 0:
        return _make("interior", f_min, st, fs, 0.0)
    sc = system.scales
    Nr = _normal_rows(fs)
    budget = min(2.0 * n_star / sc.force, GRIP_BOUND) if n_star > sc.zero_force else 1.0  # units of F0
    # variables [g = f_c / F0 (L_c), s]: maximise s s.t. C g + s <= 0, -n_g + s <= 0, sum n_g <= budget
    m = fs.C.shape[0]
    A_ub = np.vstack(
        [
            np.hstack([fs.C, np.ones((m, 1))]),
            np.hstack([-Nr, np.ones((Nr.shape[0], 1))]),
            np.hstack([Nr.sum(axis=0)[None, :], np.zeros((1, 1))]),
        ]
    )
    b_ub = np.concatenate([np.zeros(m + Nr.shape[0]), [budget]])
    A_lim, b_lim = _limits(system, st)
    A_ub = np.vstack([A_ub, np.hstack([A_lim, np.zeros((A_lim.shape[0], 1))])])
    b_ub = np.concatenate([b_ub, b_lim])
    A_eq0, b_eq = _equilibrium(system, st)
    A_eq = np.hstack([A_eq0, np.zeros((A_eq0.shape[0], 1))])
    res = solve_lp(np.r_[np.zeros(L_c), 1.0], A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, maximize=True)
    if res.status != "optimal":  # feasible (f_min, s = min margin) and bounded by the budget
        raise SolverError("HiGHS", f"interior stationary grasp LP ended '{res.status}'")
    assert res.x is not None
    f_c = res.x[:L_c] * sc.force
    if res.x[-1] < 0.0 or not certifies(system, st, fs, f_c):
        # f_min with s = 0 is feasible, so a negative optimum (or a point failing its residual
        # check) is a numerical failure on a near-singular G_c: keep the certified minimum grip
        return _make("interior", f_min, st, fs, 0.0)
    return _make("interior", f_c, st, fs, float(res.x[-1]) * sc.force)


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
