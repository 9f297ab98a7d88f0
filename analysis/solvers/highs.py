"""HiGHS adapter: linear (and convex quadratic) programs in the project's own types.

Infeasible and unbounded are answers (``LPResult.status``); anything else HiGHS reports
(time limit, numerical trouble, load errors) is raised as :class:`SolverError` or
:class:`SolverTimeLimit`. ``LPModel`` keeps one HiGHS instance so a sequence of LPs that differ
only in their objective re-solves warm from the previous basis (the DAFC oracle over many
directions, the enumeration of combinations).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import highspy
import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.exceptions import SolverError, SolverTimeLimit

INF = highspy.kHighsInf

#: HiGHS primal/dual feasibility tolerance.
FEAS_TOL = 1e-10

#: Statuses after which the solve is repeated (fresh, then with HiGHS' default settings): an
#: undecided run, not an answer.
_RETRY = (highspy.HighsModelStatus.kUnknown, highspy.HighsModelStatus.kSolveError, highspy.HighsModelStatus.kNotset)

Status = Literal["optimal", "infeasible", "unbounded"]


@dataclass(frozen=True)
class LPResult:
    """Outcome of ``min c^T x`` (or max) subject to the model's constraints."""

    status: Status
    x: Array | None  # (n,) optimal point, None unless optimal
    objective: float | None  # in the caller's sense (max problems report the max)

    @property
    def found(self) -> bool:
        return self.status == "optimal"


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
    ):
        self.n = n
        A_ub = np.zeros((0, n)) if A_ub is None else np.asarray(A_ub, dtype=float).reshape(-1, n)
        A_eq = np.zeros((0, n)) if A_eq is None else np.asarray(A_eq, dtype=float).reshape(-1, n)
        b_ub = np.zeros(0) if b_ub is None else np.asarray(b_ub, dtype=float).ravel()
        b_eq = np.zeros(0) if b_eq is None else np.asarray(b_eq, dtype=float).ravel()
        if not (np.all(np.isfinite(A_ub)) and np.all(np.isfinite(A_eq))):
            raise SolverError("HiGHS", "constraint matrix has non-finite entries")
        if not (np.all(np.isfinite(b_ub)) and np.all(np.isfinite(b_eq))):
            raise SolverError("HiGHS", "constraint bounds have non-finite entries")
        self.A = np.vstack([A_ub, A_eq])  # (m, n)
        self._n_ub = A_ub.shape[0]
        lp = highspy.HighsLp()
        lp.num_col_ = n
        lp.num_row_ = self.A.shape[0]
        lp.col_cost_ = np.zeros(n)
        lp.col_lower_ = _bounds(lb, n, -INF)
        lp.col_upper_ = _bounds(ub, n, INF)
        lp.row_lower_ = np.concatenate([np.full(len(b_ub), -INF), b_eq])
        lp.row_upper_ = np.concatenate([b_ub, b_eq])
        start, index, value = _csc(self.A)
        lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        lp.a_matrix_.start_ = start
        lp.a_matrix_.index_ = index
        lp.a_matrix_.value_ = value
        self._h = highspy.Highs()
        self._h.setOptionValue("output_flag", False)
        self._h.setOptionValue("presolve", "off")
        self._h.setOptionValue("simplex_strategy", 4)
        # tight feasibility: near-singular grasps (e.g. the Allegro scene) otherwise accept
        # friction violations of ~1e-7 and call an infeasible stationary grasp feasible
        self._h.setOptionValue("primal_feasibility_tolerance", FEAS_TOL)
        self._h.setOptionValue("dual_feasibility_tolerance", FEAS_TOL)
        if time_limit is not None:
            self._h.setOptionValue("time_limit", float(time_limit))
        status = self._h.passModel(lp)
        if status == highspy.HighsStatus.kError:
            raise SolverError("HiGHS", "model could not be loaded")
        self._idx = np.arange(n, dtype=np.int32)

    @property
    def n_ub(self) -> int:
        """Number of inequality rows (equality rows follow them)."""
        return self._n_ub

    def change_coefficients(self, rows: Array, cols: Array, values: Array) -> None:
        """Overwrite entries of the constraint matrix (rows index ``[A_ub; A_eq]``)."""
        for r, c, v in zip(np.ravel(rows), np.ravel(cols), np.ravel(values), strict=True):
            self._h.changeCoeff(int(r), int(c), float(v))

    def set_col_bounds(self, j: int, lb: float, ub: float) -> None:
        self._h.changeColBounds(int(j), float(lb) if np.isfinite(lb) else -INF, float(ub) if np.isfinite(ub) else INF)

    def set_eq_rhs(self, b_eq: Array) -> None:
        """New right-hand side of the equality rows (warm start kept)."""
        b = np.asarray(b_eq, dtype=float).ravel()
        idx = np.arange(self._n_ub, self._n_ub + len(b), dtype=np.int32)
        self._h.changeRowsBounds(len(b), idx, b, b)  # type: ignore[attr-defined]

    def solve(self, c: Array, maximize: bool = False) -> LPResult:
        c = np.asarray(c, dtype=float).ravel()
        sense = -1.0 if maximize else 1.0
        self._h.changeColsCost(self.n, self._idx, sense * c)
        self._h.run()
        ms = self._h.getModelStatus()
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
        if ms == highspy.HighsModelStatus.kOptimal:
            x = np.asarray(self._h.getSolution().col_value, dtype=float)
            return LPResult("optimal", x, float(c @ x))
        if ms == highspy.HighsModelStatus.kInfeasible:
            return LPResult("infeasible", None, None)
        if ms == highspy.HighsModelStatus.kUnbounded:
            return LPResult("unbounded", None, np.inf if maximize else -np.inf)
        if ms == highspy.HighsModelStatus.kUnboundedOrInfeasible:
            # Decide with a feasibility solve (zero objective) from scratch.
            self._h.changeColsCost(self.n, self._idx, np.zeros(self.n))
            self._h.clearSolver()
            self._h.run()
            ms2 = self._h.getModelStatus()
            if ms2 == highspy.HighsModelStatus.kInfeasible:
                return LPResult("infeasible", None, None)
            if ms2 == highspy.HighsModelStatus.kOptimal:
                return LPResult("unbounded", None, np.inf if maximize else -np.inf)
            ms = ms2
        if ms in (highspy.HighsModelStatus.kTimeLimit, highspy.HighsModelStatus.kIterationLimit):
            raise SolverTimeLimit("HiGHS", self._h.modelStatusToString(ms))
        raise SolverError("HiGHS", f"LP ended with status '{self._h.modelStatusToString(ms)}'")


def _csc(A: Array) -> tuple[NDArray[np.int32], NDArray[np.int32], Array]:
    """Column-compressed arrays of a dense matrix (zeros dropped)."""
    cols, rows = np.nonzero(A.T)  # column-major order of the non-zeros
    counts = np.bincount(cols, minlength=A.shape[1])
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    return start, rows.astype(np.int32), A[rows, cols]


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
) -> LPResult:
    """One-shot LP (see :class:`LPModel`)."""
    c = np.asarray(c, dtype=float).ravel()
    model = LPModel(len(c), A_ub, b_ub, A_eq, b_eq, lb, ub, time_limit)
    return model.solve(c, maximize=maximize)
