"""HiGHS adapter: linear programs in the project's own types (the only module importing highspy).

Infeasible and unbounded are answers (``LPResult.status``); anything else HiGHS reports
(time limit, numerical trouble, load errors) is raised as :class:`SolverError` or
:class:`SolverTimeLimit`. Two models keep one HiGHS instance each so that a sequence of related
LPs re-solves warm from the previous basis:

* :class:`LPModel`: ``min/max c^T x`` over fixed constraints whose objective, equality right-hand
  side, column bounds or a few coefficients change between solves (the DAFC oracle over many
  directions, the enumeration of combinations, generator reduction);
* :class:`RowBoundLP`: feasibility of ``lower <= H v <= upper`` in the box ``|v|_inf <= 1`` where
  only the row bounds change (the realisability LPs of the contact-mode enumeration).

An optimal :class:`LPResult` carries the multipliers (row duals, reduced costs) and reports its
own residuals: primal (equality, inequality, bound violation), dual (stationarity) and the
duality gap.

Within :func:`analysis.memo.scope` (the planner opens one per plan) a one-shot LP
(:func:`solve_lp`) whose data, options and method equal, bit for bit, those of an LP already
solved in the scope is not solved again: its result is returned (its arrays read-only). A fresh
HiGHS instance is deterministic, so this is the result the solve would give.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import highspy
import numpy as np
from highspy._core import _Highs
from numpy.typing import NDArray

from analysis import memo
from analysis._types import Array
from analysis.exceptions import SolverError, SolverTimeLimit

INF = highspy.kHighsInf

#: HiGHS primal/dual feasibility tolerance.
FEAS_TOL = 1e-10

#: The least violation (:meth:`LPModel.least_violation`) above which an LP undecided by every retry
#: is infeasible (and at least 10x the model's feasibility tolerance).
VIOLATION_PROOF = 1e-9

#: Statuses after which the solve is repeated (fresh, then with HiGHS' default settings): an
#: undecided run, not an answer.
_RETRY = (highspy.HighsModelStatus.kUnknown, highspy.HighsModelStatus.kSolveError, highspy.HighsModelStatus.kNotset)

Status = Literal["optimal", "infeasible", "unbounded"]

_OPTIMAL = highspy.HighsModelStatus.kOptimal
#: ``passModel``'s codes of a column-wise matrix and of minimisation.
_COLWISE = int(highspy.MatrixFormat.kColwise)
_MINIMIZE = int(highspy.ObjSense.kMinimize)


@dataclass(frozen=True)
class LPProblem:
    """The data of ``min/max c^T x  s.t.  A_ub x <= b_ub,  A_eq x = b_eq,  lb <= x <= ub``
    (``-inf``/``inf`` bounds where a variable is free), as it was when a result was solved."""

    c: Array  # (n,) objective in the caller's sense
    A_ub: Array  # (m_ub, n)
    b_ub: Array  # (m_ub,)
    A_eq: Array  # (m_eq, n)
    b_eq: Array  # (m_eq,)
    lb: Array  # (n,)
    ub: Array  # (n,)
    maximize: bool = False

    @property
    def sense(self) -> float:
        """``s``: HiGHS minimises ``s c^T x`` (``s = -1`` for a maximisation)."""
        return -1.0 if self.maximize else 1.0


@dataclass(frozen=True)
class LPResult:
    """Outcome of ``min c^T x`` (or max) subject to the model's constraints.

    For an optimal result the multipliers satisfy the KKT conditions of the minimisation HiGHS
    solved, ``min s c^T x`` (``s = problem.sense``)::

        s c + A_ub^T y_ub + A_eq^T y_eq + z = 0,   y_ub >= 0,
        z_j <= 0 where x_j = lb_j,   z_j >= 0 where x_j = ub_j,   z_j = 0 in between,

    (so ``y_ub`` and ``y_eq`` are the row duals, ``z`` the reduced costs, in the sign convention
    of qpsolvers' ``Solution``). The residual methods return ``inf`` where a quantity is missing
    (no point, no multipliers).
    """

    status: Status
    x: Array | None  # (n,) optimal point, None unless optimal
    objective: float | None  # in the caller's sense (max problems report the max)
    y_ub: Array | None = None  # (m_ub,) multipliers of A_ub x <= b_ub, >= 0
    y_eq: Array | None = None  # (m_eq,) multipliers of A_eq x = b_eq
    z: Array | None = None  # (n,) multipliers of the bounds (reduced costs)
    problem: LPProblem | None = None

    @property
    def found(self) -> bool:
        return self.status == "optimal"

    @property
    def has_duals(self) -> bool:
        return self.y_ub is not None and self.y_eq is not None and self.z is not None

    # -- primal ---------------------------------------------------------------------------------

    def equality_violation(self) -> float:
        """``|A_eq x - b_eq|_inf``."""
        if self.x is None or self.problem is None:
            return np.inf
        P = self.problem
        return float(np.max(np.abs(P.A_eq @ self.x - P.b_eq), initial=0.0))

    def inequality_violation(self) -> float:
        """``max(A_ub x - b_ub, 0)``."""
        if self.x is None or self.problem is None:
            return np.inf
        P = self.problem
        return float(np.max(P.A_ub @ self.x - P.b_ub, initial=0.0))

    def bound_violation(self) -> float:
        """``max(lb - x, x - ub, 0)``."""
        if self.x is None or self.problem is None:
            return np.inf
        P = self.problem
        return float(max(np.max(P.lb - self.x, initial=0.0), np.max(self.x - P.ub, initial=0.0)))

    def primal_residual(self) -> float:
        """The largest of the equality, inequality and bound violations."""
        return max(self.equality_violation(), self.inequality_violation(), self.bound_violation())

    # -- dual -----------------------------------------------------------------------------------

    def dual_residual(self) -> float:
        """Stationarity ``|s c + A_ub^T y_ub + A_eq^T y_eq + z|_inf``."""
        if self.x is None or self.problem is None or not self.has_duals:
            return np.inf
        assert self.y_ub is not None and self.y_eq is not None and self.z is not None
        P = self.problem
        r = P.sense * P.c + P.A_ub.T @ self.y_ub + P.A_eq.T @ self.y_eq + self.z  # (n,)
        return float(np.max(np.abs(r), initial=0.0))

    def duality_gap(self) -> float:
        """``|s c^T x + b_ub^T y_ub + b_eq^T y_eq + lb^T z^- + ub^T z^+|`` (finite bounds only;
        ``z^-``, ``z^+`` the negative and positive parts of ``z``)."""
        if self.x is None or self.problem is None or not self.has_duals:
            return np.inf
        assert self.y_ub is not None and self.y_eq is not None and self.z is not None
        P = self.problem
        lo, up = np.isfinite(P.lb), np.isfinite(P.ub)
        bounds = P.lb[lo] @ np.minimum(self.z[lo], 0.0) + P.ub[up] @ np.maximum(self.z[up], 0.0)
        return float(abs(P.sense * P.c @ self.x + P.b_ub @ self.y_ub + P.b_eq @ self.y_eq + bounds))

    def is_optimal(self, tol: float) -> bool:
        """Primal residual, dual residual and duality gap all below ``tol``."""
        return max(self.primal_residual(), self.dual_residual(), self.duality_gap()) < tol


class LPModel:
    """``min/max c^T x  s.t.  A_ub x <= b_ub,  A_eq x = b_eq,  lb <= x <= ub``.

    Bounds default to free variables. ``solve(c)`` may be called many times with different
    objectives; HiGHS warm-starts from the last basis.
    """

    def __init__(
        self,
        n: int,
        A_ub: Array | None = None,  # (m_ub, n)
        b_ub: Array | None = None,  # (m_ub,)
        A_eq: Array | None = None,  # (m_eq, n)
        b_eq: Array | None = None,  # (m_eq,)
        lb: Array | float | None = None,
        ub: Array | float | None = None,
        time_limit: float | None = None,
        feasibility: float = FEAS_TOL,
    ):
        self.n = n
        self._feasibility = feasibility
        A_ub = np.zeros((0, n)) if A_ub is None else np.asarray(A_ub, dtype=float).reshape(-1, n)
        A_eq = np.zeros((0, n)) if A_eq is None else np.asarray(A_eq, dtype=float).reshape(-1, n)
        b_ub = np.zeros(0) if b_ub is None else np.asarray(b_ub, dtype=float).ravel()
        b_eq = np.zeros(0) if b_eq is None else np.asarray(b_eq, dtype=float).ravel()
        if not (np.all(np.isfinite(A_ub)) and np.all(np.isfinite(A_eq))):
            raise SolverError("HiGHS", "constraint matrix has non-finite entries")
        if not (np.all(np.isfinite(b_ub)) and np.all(np.isfinite(b_eq))):
            raise SolverError("HiGHS", "constraint bounds have non-finite entries")
        # The model's data, kept for the residuals of its results. Each change replaces an array
        # (never writes into it), so a result keeps the data it was solved from.
        self.A_ub, self.b_ub, self.A_eq, self.b_eq = A_ub, b_ub, A_eq, b_eq
        self.lb, self.ub = _bounds(lb, n, -INF), _bounds(ub, n, INF)
        self._n_ub = A_ub.shape[0]
        options: dict[str, bool | int | float | str] = {
            "presolve": "off",
            "simplex_strategy": 4,
            # tight feasibility: near-singular grasps (e.g. the Allegro scene) otherwise accept
            # friction violations of ~1e-7 and call an infeasible stationary grasp feasible
            "primal_feasibility_tolerance": feasibility,
            "dual_feasibility_tolerance": FEAS_TOL,
        }
        if time_limit is not None:
            options["time_limit"] = float(time_limit)
        self._h = _load(
            self.A,
            np.concatenate([np.full(len(b_ub), -INF), b_eq]),
            np.concatenate([b_ub, b_eq]),
            self.lb,
            self.ub,
            options,
            "model could not be loaded",
        )
        self._idx = np.arange(n, dtype=np.int32)

    @property
    def A(self) -> Array:
        """The constraint matrix ``[A_ub; A_eq]`` ``(m, n)``."""
        return np.vstack([self.A_ub, self.A_eq])

    @property
    def n_ub(self) -> int:
        """Number of inequality rows (equality rows follow them)."""
        return self._n_ub

    def change_coefficients(self, rows: Array, cols: Array, values: Array) -> None:
        """Overwrite entries of the constraint matrix (rows index ``[A_ub; A_eq]``)."""
        r_all = np.ravel(rows).astype(int)
        c_all = np.ravel(cols).astype(int)
        v_all = np.ravel(values).astype(float)
        if not (len(r_all) == len(c_all) == len(v_all)):
            raise ValueError("change_coefficients: rows, cols and values differ in length")
        # entries already holding their value need no HiGHS call (the model is unchanged by it)
        n_ub = self._n_ub
        in_ub = r_all < n_ub  # (k,)
        current = np.empty(len(v_all))
        current[in_ub] = self.A_ub[r_all[in_ub], c_all[in_ub]]
        current[~in_ub] = self.A_eq[r_all[~in_ub] - n_ub, c_all[~in_ub]]
        changed = current != v_all
        if not changed.any():
            return
        if len(np.unique(r_all * self.n + c_all)) < len(r_all):
            changed[:] = True  # an entry named twice: every write in order, as given
        # only the arrays that change are replaced (a result keeps the data it was solved from)
        A_ub = self.A_ub.copy() if bool(in_ub[changed].any()) else self.A_ub
        A_eq = self.A_eq.copy() if not bool(in_ub[changed].all()) else self.A_eq
        for r, c, v in zip(r_all[changed].tolist(), c_all[changed].tolist(), v_all[changed].tolist(), strict=True):
            self._h.changeCoeff(r, c, v)
            if r < n_ub:
                A_ub[r, c] = v
            else:
                A_eq[r - n_ub, c] = v
        self.A_ub, self.A_eq = A_ub, A_eq

    def use_defaults(self) -> None:
        """Solve from now on with HiGHS' default strategy (presolve, dual simplex), from scratch: the
        second opinion when a warm primal-simplex answer fails its caller's residual check."""
        self._h.setOptionValue("presolve", "choose")
        self._h.setOptionValue("simplex_strategy", 1)
        self._h.clearSolver()

    def use_ipm(self) -> None:
        """Solve from now on with HiGHS' interior-point method and crossover, from scratch: the third
        opinion when the simplex runs end undecided on a near-degenerate model."""
        self._h.setOptionValue("solver", "ipm")
        self._h.setOptionValue("run_crossover", "on")
        self._h.clearSolver()

    def set_ub_rhs(self, b_ub: Array) -> None:
        """New right-hand side of the inequality rows."""
        b = np.asarray(b_ub, dtype=float).ravel()
        idx = np.arange(len(b), dtype=np.int32)
        self._h.changeRowsBounds(len(b), idx, np.full(len(b), -INF), b)  # type: ignore[attr-defined]
        self.b_ub = b.copy()

    def solve_cold(self, c: Array, maximize: bool = False) -> LPResult:
        """:meth:`solve` from scratch (no warm start): the answer, including which of several
        optimal points is returned, does not depend on the model's earlier solves."""
        self._h.clearSolver()
        return self.solve(c, maximize)

    def set_col_bounds(self, j: int, lb: float, ub: float) -> None:
        lo, up = float(lb) if np.isfinite(lb) else -INF, float(ub) if np.isfinite(ub) else INF
        self._h.changeColBounds(int(j), lo, up)
        self.lb, self.ub = self.lb.copy(), self.ub.copy()
        self.lb[int(j)], self.ub[int(j)] = lo, up

    def set_bounds(self, lb: Array | float | None, ub: Array | float | None) -> None:
        """New bounds of every column (as the constructor takes them; warm start kept)."""
        lo, up = _bounds(lb, self.n, -INF), _bounds(ub, self.n, INF)
        self._h.changeColsBounds(self.n, self._idx, lo, up)
        self.lb, self.ub = lo, up

    def set_eq_rhs(self, b_eq: Array) -> None:
        """New right-hand side of the equality rows (warm start kept)."""
        b = np.asarray(b_eq, dtype=float).ravel()
        idx = np.arange(self._n_ub, self._n_ub + len(b), dtype=np.int32)
        self._h.changeRowsBounds(len(b), idx, b, b)  # type: ignore[attr-defined]
        self.b_eq = np.concatenate([b, self.b_eq[len(b):]])

    def problem(self, c: Array, maximize: bool = False) -> LPProblem:
        """The model's current data with the objective ``c``."""
        return LPProblem(np.asarray(c, dtype=float).ravel(), self.A_ub, self.b_ub, self.A_eq, self.b_eq,
                         self.lb, self.ub, maximize)

    def _retry(self, ms: highspy.HighsModelStatus) -> highspy.HighsModelStatus:
        """The model status after the retries of an undecided run (``ms`` in ``_RETRY``)."""
        if ms in _RETRY:
            # a warm start from an unbounded/degenerate basis can end undecided: solve afresh
            self._h.clearSolver()
            self._h.run()
            ms = self._h.getModelStatus()
        if ms in _RETRY:
            # primal simplex without presolve can still fail on a near-degenerate model (seen on
            # the Allegro scene): once more with HiGHS' defaults, then back to the warm settings
            self._h.setOptionValue("presolve", "choose")
            self._h.setOptionValue("simplex_strategy", 1)
            self._h.clearSolver()
            self._h.run()
            ms = self._h.getModelStatus()
            self._h.setOptionValue("presolve", "off")
            self._h.setOptionValue("simplex_strategy", 4)
        if ms in _RETRY:
            # last: the interior-point method with crossover, which does not share the simplex
            # runs' pivoting trouble on near-degenerate (perturbed, nearly parallel) rows
            self._h.setOptionValue("solver", "ipm")
            self._h.setOptionValue("run_crossover", "on")
            self._h.clearSolver()
            self._h.run()
            ms = self._h.getModelStatus()
            self._h.setOptionValue("solver", "choose")
        return ms

    def least_violation(self) -> float | None:
        """The least uniform violation ``t >= 0`` of the constraints (``A_ub x <= b_ub + t``,
        ``|A_eq x - b_eq| <= t``, ``lb - t <= x <= ub + t``), from a model of its own with HiGHS'
        defaults (always feasible, bounded below by 0), or None if that run is undecided too.

        A ``t`` above the feasibility tolerance proves the constraints infeasible: the last step of
        an undecided solve (:meth:`solve`). An infeasible least-excess LP of the Baxter lines scene
        (``tests/analysis/highs_unknown_lp.json``, violated by 4.2e-6) ends 'Unknown' or 'Solve
        error' in every run of the retry chain, depending on HiGHS' state; this LP decides it."""
        A = self.A  # (m, n)
        m_ub, n = self._n_ub, self.n
        lo, hi = np.flatnonzero(np.isfinite(self.lb)), np.flatnonzero(np.isfinite(self.ub))
        eye = np.eye(n)
        rows = np.vstack([A, -A[m_ub:], -eye[lo], eye[hi]])  # (m + m_eq + |lo| + |hi|, n)
        upper = np.concatenate([self.b_ub, self.b_eq, -self.b_eq, -self.lb[lo], self.ub[hi]])
        h = _load(np.hstack([rows, -np.ones((rows.shape[0], 1))]), np.full(len(upper), -INF), upper,
                  np.r_[np.full(n, -INF), 0.0], np.full(n + 1, INF), {},  # t >= 0
                  "violation model could not be loaded")
        h.changeColCost(n, 1.0)
        h.run()
        if h.getModelStatus() != _OPTIMAL:
            return None
        return float(h.getInfo().objective_function_value)

    def solve(self, c: Array, maximize: bool = False) -> LPResult:
        c = np.asarray(c, dtype=float).ravel()
        sense = -1.0 if maximize else 1.0
        self._h.changeColsCost(self.n, self._idx, sense * c)
        self._h.run()
        ms = self._h.getModelStatus()
        if ms != _OPTIMAL:  # the common case skips the retry chain
            ms = self._retry(ms)
        problem = self.problem(c, maximize)
        if ms == _OPTIMAL:
            sol = self._h.getSolution()
            x = np.asarray(sol.col_value, dtype=float)
            # HiGHS' duals satisfy s c - A^T row_dual - col_dual = 0: negated, they are LPResult's
            y = -np.asarray(sol.row_dual, dtype=float)
            return LPResult("optimal", x, float(c @ x), y_ub=y[: self._n_ub], y_eq=y[self._n_ub :],
                            z=-np.asarray(sol.col_dual, dtype=float), problem=problem)
        if ms == highspy.HighsModelStatus.kInfeasible:
            return LPResult("infeasible", None, None, problem=problem)
        if ms == highspy.HighsModelStatus.kUnbounded:
            return LPResult("unbounded", None, np.inf if maximize else -np.inf, problem=problem)
        if ms == highspy.HighsModelStatus.kUnboundedOrInfeasible:
            # Decide with a feasibility solve (zero objective) from scratch.
            self._h.changeColsCost(self.n, self._idx, np.zeros(self.n))
            self._h.clearSolver()
            self._h.run()
            ms2 = self._h.getModelStatus()
            if ms2 == highspy.HighsModelStatus.kInfeasible:
                return LPResult("infeasible", None, None, problem=problem)
            if ms2 == highspy.HighsModelStatus.kOptimal:
                return LPResult("unbounded", None, np.inf if maximize else -np.inf, problem=problem)
            ms = ms2
        if ms in (highspy.HighsModelStatus.kTimeLimit, highspy.HighsModelStatus.kIterationLimit):
            raise SolverTimeLimit("HiGHS", self._h.modelStatusToString(ms))
        if ms in _RETRY:
            t = self.least_violation()  # undecided after every retry: is it infeasible?
            if t is not None and t > max(VIOLATION_PROOF, 10.0 * self._feasibility):
                return LPResult("infeasible", None, None, problem=problem)
        raise SolverError("HiGHS", f"LP ended with status '{self._h.modelStatusToString(ms)}'")


def _csc(A: Array) -> tuple[NDArray[np.int32], NDArray[np.int32], Array]:
    """Column-compressed arrays of a dense matrix (zeros dropped)."""
    cols, rows = np.nonzero(A.T)  # column-major order of the non-zeros
    counts = np.bincount(cols, minlength=A.shape[1])
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    return start, rows.astype(np.int32), A[rows, cols]


def _load(
    A: Array,  # (m, n)
    row_lower: Array,  # (m,)
    row_upper: Array,  # (m,)
    col_lower: Array,  # (n,)
    col_upper: Array,  # (n,)
    options: dict[str, bool | int | float | str],
    load_error: str,
) -> _Highs:
    """A silent HiGHS instance holding ``row_lower <= A x <= row_upper``, ``col_lower <= x <=
    col_upper`` with zero objective; ``SolverError(load_error)`` if HiGHS rejects it.

    The instance is highspy's core class ``_Highs`` (the public ``highspy.Highs`` adds Python
    callbacks for interrupts, a third of a small model's load time; no callback is used here),
    and the model is passed as arrays (one call) rather than through a ``HighsLp`` whose
    attributes are copied one by one: the same model, the same solves (identical points, duals
    and iteration counts on random and degenerate LPs, ``tests/analysis/test_solvers.py``)."""
    m, n = A.shape
    h = _Highs()
    h.setOptionValue("output_flag", False)
    for name, option in options.items():
        h.setOptionValue(name, option)
    start, index, value = _csc(A)
    status = h.passModel(n, m, len(value), _COLWISE, _MINIMIZE, 0.0, np.zeros(n),
                         np.ascontiguousarray(col_lower, dtype=float), np.ascontiguousarray(col_upper, dtype=float),
                         np.ascontiguousarray(row_lower, dtype=float), np.ascontiguousarray(row_upper, dtype=float),
                         start, index, value, np.zeros(n, dtype=np.int32))
    if status == highspy.HighsStatus.kError:
        raise SolverError("HiGHS", load_error)
    return h


def _bounds(b: Array | float | None, n: int, default: float) -> Array:
    if b is None:
        return np.full(n, default)
    arr = np.broadcast_to(np.asarray(b, dtype=float), (n,)).copy()
    arr[~np.isfinite(arr)] = default
    return arr


def solve_lp(
    c: Array,
    A_ub: Array | None = None,
    b_ub: Array | None = None,
    A_eq: Array | None = None,
    b_eq: Array | None = None,
    lb: Array | float | None = None,
    ub: Array | float | None = None,
    maximize: bool = False,
    time_limit: float | None = None,
    feasibility: float = FEAS_TOL,
    method: Literal["warm", "defaults", "ipm"] = "warm",
) -> LPResult:
    """One-shot LP (see :class:`LPModel`; ``method``: its settings, or after
    :meth:`LPModel.use_defaults` or :meth:`LPModel.use_ipm`). Inside :func:`analysis.memo.scope`
    an LP with the same data, options and method as one solved before returns that result."""
    c = np.asarray(c, dtype=float).ravel()

    def solve() -> LPResult:
        model = LPModel(len(c), A_ub, b_ub, A_eq, b_eq, lb, ub, time_limit, feasibility)
        if method == "defaults":
            model.use_defaults()
        elif method == "ipm":
            model.use_ipm()
        return model.solve(c, maximize=maximize)

    if not memo.active():
        return solve()
    key = ("solve_lp", memo.exact_key(c, A_ub, b_ub, A_eq, b_eq, lb, ub), bool(maximize), time_limit,
           float(feasibility), method)
    return memo.remembered(key, solve, lambda r: (r.x, r.y_ub, r.y_eq, r.z))


class RowBoundLP:
    """Feasibility of ``lower <= H v <= upper``, ``|v|_inf <= 1`` (zero objective).

    The rows ``H`` ``(K, n)`` are fixed; each query changes only row bounds, so HiGHS re-solves
    warm from the previous basis. ``feasibility`` is HiGHS' primal feasibility tolerance, and a
    returned point is checked against the bounds with slack ``10 feasibility``. Infeasible is an
    answer (``None``); anything else that is not a feasible point raises :class:`SolverError`
    (after one cold retry). ``count`` is the number of queries so far. The contact-mode
    enumeration (:mod:`analysis.modes`) decides the realisability of its search nodes with it.
    """

    def __init__(self, H: Array, feasibility: float):
        self.H = np.ascontiguousarray(H, dtype=float)  # (K, n)
        K, n = self.H.shape
        self.K, self.n = K, n
        self.count = 0
        self._tol = feasibility
        self._idx = np.arange(K, dtype=np.int32)
        options: dict[str, bool | int | float | str] = {
            "presolve": "off",
            "primal_feasibility_tolerance": feasibility,
            "dual_feasibility_tolerance": 1e-9,
        }
        self._h = _load(self.H, np.full(K, -INF), np.full(K, INF), -np.ones(n), np.ones(n), options,
                        "mode enumeration LP could not be loaded")

    def solve(self, lower: Array, upper: Array) -> Array | None:
        """A point ``(n,)`` of the polytope, or ``None`` if it is empty."""
        self.count += 1
        if self.K == 0 or self.n == 0:
            ok = bool(np.all(lower <= self._tol) and np.all(upper >= -self._tol))
            return np.zeros(self.n) if ok else None
        self._h.changeRowsBounds(self.K, self._idx, lower, upper)  # type: ignore[attr-defined]
        for attempt in range(2):
            self._h.run()
            ms = self._h.getModelStatus()
            if ms == highspy.HighsModelStatus.kInfeasible:
                return None
            if ms == highspy.HighsModelStatus.kOptimal:
                v = np.asarray(self._h.getSolution().col_value, dtype=float)
                Hv = self.H @ v
                slack = 10 * self._tol + 1e-12
                if np.all(Hv >= lower - slack) and np.all(Hv <= upper + slack):
                    return v
                if attempt == 0:
                    self._h.clearSolver()
                    continue
                raise SolverError("HiGHS", "mode LP returned a point violating its constraints")
            if ms in (highspy.HighsModelStatus.kTimeLimit, highspy.HighsModelStatus.kIterationLimit):
                raise SolverTimeLimit("HiGHS", self._h.modelStatusToString(ms))
            if attempt == 0:
                self._h.clearSolver()
                continue
            raise SolverError("HiGHS", f"mode LP ended with status '{self._h.modelStatusToString(ms)}'")
        raise AssertionError("unreachable")


def solve_sparse_lp(
    c: Array,  # (n,)
    start: NDArray[np.int32],  # (n + 1,) column starts of the constraint matrix (CSC)
    index: NDArray[np.int32],  # (nnz,) row indices
    value: Array,  # (nnz,)
    row_lower: Array,  # (m,)
    row_upper: Array,  # (m,)
    col_lower: Array,  # (n,)
    col_upper: Array,  # (n,)
    maximize: bool = False,
    feasibility: float = FEAS_TOL,
) -> tuple[Status, Array | None]:
    """One-shot ``min/max c^T x`` s.t. ``row_lower <= A x <= row_upper``, ``col_lower <= x <=
    col_upper`` with ``A`` given column-compressed (large block-diagonal LPs: many small problems
    in one HiGHS call). Returns the status and the optimal point (None unless optimal); an
    undecided run is retried as :class:`LPModel` does, then raised as :class:`SolverError`."""
    n, m = len(c), len(row_lower)
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("primal_feasibility_tolerance", feasibility)
    h.setOptionValue("dual_feasibility_tolerance", FEAS_TOL)
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = n, m
    lp.col_cost_ = (-1.0 if maximize else 1.0) * np.asarray(c, dtype=float)
    lp.col_lower_, lp.col_upper_ = np.asarray(col_lower, dtype=float), np.asarray(col_upper, dtype=float)
    lp.row_lower_, lp.row_upper_ = np.asarray(row_lower, dtype=float), np.asarray(row_upper, dtype=float)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = start
    lp.a_matrix_.index_ = index
    lp.a_matrix_.value_ = value
    if h.passModel(lp) == highspy.HighsStatus.kError:
        raise SolverError("HiGHS", "the sparse LP was rejected")
    h.run()
    ms = h.getModelStatus()
    if ms in _RETRY:
        h.setOptionValue("solver", "ipm")
        h.setOptionValue("run_crossover", "on")
        h.clearSolver()
        h.run()
        ms = h.getModelStatus()
    if ms == _OPTIMAL:
        return "optimal", np.asarray(h.getSolution().col_value, dtype=float)
    if ms == highspy.HighsModelStatus.kInfeasible:
        return "infeasible", None
    if ms == highspy.HighsModelStatus.kUnbounded:
        return "unbounded", None
    raise SolverError("HiGHS", f"sparse LP ended with status '{h.modelStatusToString(ms)}'")
