"""Solver adapters: known answers for the HiGHS and cdd wrappers; HiGHS results report their duals
and residuals (KKT on random feasible LPs)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from analysis.solvers.cdd import Generators, _pointed, cone_generators, polyhedron_generators, reduce_generators
from analysis.solvers.highs import INF, LPModel, RowBoundLP, solve_lp


def test_lp_statuses():
    # max x + y s.t. x + y <= 1, x, y >= 0 -> 1
    r = solve_lp(np.array([1.0, 1.0]), A_ub=np.array([[1.0, 1.0]]), b_ub=np.array([1.0]), lb=0.0, maximize=True)
    assert r.status == "optimal" and r.objective == pytest.approx(1.0, abs=1e-9)
    r = solve_lp(np.array([1.0, 0.0]), lb=0.0, maximize=True)
    assert r.status == "unbounded"
    r = solve_lp(np.zeros(1), A_ub=np.array([[1.0], [-1.0]]), b_ub=np.array([-1.0, -1.0]))
    assert r.status == "infeasible"


def test_warm_model_objectives_and_rhs():
    model = LPModel(2, A_ub=np.array([[1.0, 2.0], [3.0, 1.0]]), b_ub=np.array([4.0, 6.0]), lb=0.0)
    assert model.solve(np.array([1.0, 1.0]), maximize=True).objective == pytest.approx(2.8, abs=1e-9)
    assert model.solve(np.array([1.0, 0.0]), maximize=True).objective == pytest.approx(2.0, abs=1e-9)
    eq = LPModel(2, A_eq=np.array([[1.0, 1.0]]), b_eq=np.array([1.0]), lb=0.0)
    eq.set_eq_rhs(np.array([3.0]))
    assert eq.solve(np.array([1.0, 2.0]), maximize=True).objective == pytest.approx(6.0, abs=1e-9)
    eq.set_col_bounds(1, 0.0, 0.0)
    assert eq.solve(np.array([1.0, 2.0]), maximize=True).objective == pytest.approx(3.0, abs=1e-9)


def test_box_vertices():
    A = np.vstack([np.eye(3), -np.eye(3)])
    g = polyhedron_generators(A, np.ones(6))
    assert g.vertices.shape == (8, 3) and g.rays.shape[0] == 0
    assert np.allclose(np.sort(np.abs(g.vertices).ravel()), 1.0)


def test_cone_generators_include_origin_and_lines():
    # {x : x_0 <= 0} in R^2: origin, ray -e0, line e1
    g = cone_generators(np.array([[1.0, 0.0]]))
    assert g.vertices.shape == (1, 2) and np.allclose(g.vertices, 0.0)
    assert np.allclose(np.abs(g.lines), [[0.0, 1.0]])
    assert np.allclose(g.rays, [[-1.0, 0.0]])


@pytest.mark.parametrize("extra", [0, 40])  # below and above the LP-reduction threshold
def test_reduce_generators_keeps_only_extreme_points(extra):
    rng = np.random.default_rng(3)
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    V = np.vstack([cube, rng.random((extra, 3))])
    R = np.vstack([np.eye(3), rng.random((extra, 3))])
    R /= np.linalg.norm(R, axis=1, keepdims=True)
    g = reduce_generators(Generators(V, R, np.zeros((0, 3))))
    # cube + positive orthant cone: the only vertex is the origin, the rays are the axes
    assert g.vertices.shape[0] == 1 and np.allclose(g.vertices[0], 0.0)
    assert sorted(map(tuple, np.round(g.rays, 9))) == sorted(map(tuple, np.eye(3)))
    h = reduce_generators(Generators(V, np.zeros((0, 3)), np.zeros((0, 3))))
    assert sorted(map(tuple, np.round(h.vertices, 9))) == sorted(map(tuple, cube))



def test_reduce_generators_survives_the_rays_that_abort_cdd() -> None:
    """One vertex and 19 nearly parallel rays in 16-D (the torque set of SSDDSSSDFDDF in the
    12-contact wrap) made pycddlib's matrix_canonicalize abort the process; run in a child process
    so that a regression fails this test instead of killing the run. Every ray is extreme: no
    nonnegative combination of the other 18 gives it (scipy's LP, independent of HiGHS' model)."""
    path = Path(__file__).with_name("cdd_abort_generators.json")
    code = ("import json, sys, numpy as np; from analysis.solvers.cdd import Generators, reduce_generators; "
            f"d = json.load(open({str(path)!r})); "
            "g = reduce_generators(Generators(np.array(d['vertices']), np.array(d['rays']), np.zeros((0, 16)))); "
            "print(json.dumps({'v': g.vertices.tolist(), 'r': g.rays.tolist()}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).parents[2])
    assert out.returncode == 0, out.stderr[-500:]
    got = json.loads(out.stdout)
    data = json.loads(path.read_text())
    R = np.array(data["rays"])
    R /= np.linalg.norm(R, axis=1, keepdims=True)
    np.testing.assert_allclose(got["v"], data["vertices"], rtol=0, atol=1e-9)
    assert len(got["r"]) == len(R) == 19
    for i in range(len(R)):
        others = np.delete(R, i, axis=0)
        res = linprog(np.zeros(len(others)), A_eq=others.T, b_eq=R[i], bounds=[(0, None)] * len(others),
                      method="highs")
        assert res.status == 2  # infeasible: ray i is extreme
    # each returned ray is one of the input rays (unit length)
    for r in got["r"]:
        assert np.min(np.linalg.norm(R - np.array(r), axis=1)) < 1e-9


def test_reduce_generators_with_lines() -> None:
    """A slab's worth of generators with a line (cdd's canonical form): the line z, the rays x and
    y (the redundant ray (1, 1, 5) / |.| is the sum of x, y and the line), the vertex at the origin
    (the vertex (1, 1, 0) = origin + x + y is redundant)."""
    V = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    R = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 5.0]])
    R /= np.linalg.norm(R, axis=1, keepdims=True)
    g = reduce_generators(Generators(V, R, np.array([[0.0, 0.0, 1.0]])))
    assert g.vertices.shape[0] == 1 and abs(g.vertices[0, :2]).max() < 1e-9
    assert np.allclose(np.abs(g.lines), [[0.0, 0.0, 1.0]])
    assert sorted(map(tuple, np.round(np.abs(g.rays[:, :2]), 9))) == [(0.0, 1.0), (1.0, 0.0)]

# -- LPResult: duals and residuals ---------------------------------------------------------------


def _random_feasible_lp(rng: np.random.Generator, n: int, m_ub: int, m_eq: int, free: bool):
    """An LP with a known feasible point ``x0``; bounded below either by a finite box or (``free``)
    by an objective built from dual-feasible multipliers ``c = -(A_ub^T y - A_eq^T w)``, ``y >= 0``."""
    x0 = rng.normal(size=n)
    A_ub = rng.normal(size=(m_ub, n))
    b_ub = A_ub @ x0 + rng.uniform(0.0, 1.0, m_ub) * (rng.random(m_ub) < 0.7)  # some rows tight at x0
    A_eq = rng.normal(size=(m_eq, n))
    b_eq = A_eq @ x0
    if free:
        lb, ub = np.full(n, -np.inf), np.full(n, np.inf)
        c = -(A_ub.T @ rng.uniform(0.0, 1.0, m_ub) + A_eq.T @ rng.normal(size=m_eq))
    else:
        lb, ub = x0 - rng.uniform(0.0, 2.0, n), x0 + rng.uniform(0.0, 2.0, n)
        c = rng.normal(size=n)
    return c, A_ub, b_ub, A_eq, b_eq, lb, ub


@pytest.mark.parametrize("seed", range(12))
def test_random_feasible_lps_have_zero_residuals_and_kkt_duals(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 9))
    m_ub, m_eq = int(rng.integers(0, 2 * n)), int(rng.integers(0, n))
    c, A_ub, b_ub, A_eq, b_eq, lb, ub = _random_feasible_lp(rng, n, m_ub, m_eq, free=seed % 3 == 0)
    maximize = seed % 2 == 1
    if maximize:
        c = -c  # max (-c)^T x is the same bounded problem
    r = solve_lp(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, lb=lb, ub=ub, maximize=maximize)
    assert r.status == "optimal" and r.has_duals
    assert r.x is not None and r.y_ub is not None and r.y_eq is not None and r.z is not None
    assert r.y_ub.shape == (m_ub,) and r.y_eq.shape == (m_eq,) and r.z.shape == (n,)
    tol = 1e-7
    assert r.equality_violation() < tol and r.inequality_violation() < tol and r.bound_violation() < tol
    assert r.primal_residual() < tol and r.dual_residual() < tol and r.duality_gap() < tol
    assert r.is_optimal(tol)
    # KKT of min s c^T x, written out: stationarity, dual signs, complementary slackness
    s = -1.0 if maximize else 1.0
    np.testing.assert_allclose(s * c + A_ub.T @ r.y_ub + A_eq.T @ r.y_eq + r.z, 0.0, atol=tol)
    assert np.all(r.y_ub >= -tol)
    np.testing.assert_allclose(r.y_ub * (b_ub - A_ub @ r.x), 0.0, atol=tol)
    at_lb, at_ub = np.abs(r.x - lb) <= tol, np.abs(r.x - ub) <= tol
    assert np.all(r.z[~at_lb] >= -tol) and np.all(r.z[~at_ub] <= tol)
    # strong duality: the objective equals the dual objective
    finite_lb, finite_ub = np.isfinite(lb), np.isfinite(ub)
    dual = -(b_ub @ r.y_ub + b_eq @ r.y_eq + lb[finite_lb] @ np.minimum(r.z[finite_lb], 0.0)
             + ub[finite_ub] @ np.maximum(r.z[finite_ub], 0.0))
    assert s * r.objective == pytest.approx(dual, abs=1e-6)


def test_infeasible_and_unbounded_lps_report_it():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(1, 3))
    # a x <= -1 and -a x <= -1: a x <= -1 and a x >= 1
    r = solve_lp(rng.normal(size=3), A_ub=np.vstack([A, -A]), b_ub=np.array([-1.0, -1.0]))
    assert r.status == "infeasible" and not r.found and r.x is None and not r.has_duals
    assert r.primal_residual() == np.inf and r.dual_residual() == np.inf and r.duality_gap() == np.inf
    assert not r.is_optimal(1.0)
    r = solve_lp(np.ones(2), A_eq=np.array([[1.0, 1.0], [1.0, 1.0]]), b_eq=np.array([0.0, 1.0]), lb=0.0)
    assert r.status == "infeasible"
    r = solve_lp(np.array([1.0, 0.0]), lb=0.0, maximize=True)
    assert r.status == "unbounded" and r.objective == np.inf and r.primal_residual() == np.inf


def _violation_by_scipy(A_ub: np.ndarray, b_ub: np.ndarray, A_eq: np.ndarray, b_eq: np.ndarray,
                        lb: np.ndarray) -> float:
    """The least uniform violation of ``A_ub x <= b_ub``, ``A_eq x = b_eq``, ``x >= lb`` by scipy's
    linprog, written out here independently of :meth:`LPModel.least_violation`."""
    n = A_ub.shape[1]
    fin = np.flatnonzero(np.isfinite(lb))
    rows = np.vstack([A_ub, A_eq, -A_eq, -np.eye(n)[fin]])
    b = np.concatenate([b_ub, b_eq, -b_eq, -lb[fin]])
    res = linprog(np.r_[np.zeros(n), 1.0], A_ub=np.hstack([rows, -np.ones((len(b), 1))]), b_ub=b,
                  bounds=[(None, None)] * n + [(0.0, None)], method="highs")
    assert res.status == 0, res.message
    return float(res.fun)


def test_an_lp_undecided_by_every_retry_is_decided_by_its_least_violation() -> None:
    """The least-excess LP of a release check on the Baxter lines scene ends 'Unknown' or 'Solve
    error' in every run of the retry chain (it is infeasible by 4.2e-6, near HiGHS' tolerances);
    it used to stop ``ctp plan ... --link-sliding`` with "HiGHS: LP ended with status 'Unknown'".
    Its least violation decides it infeasible, and equals scipy's independent one."""
    d = json.loads(Path(__file__).with_name("highs_unknown_lp.json").read_text())
    lb = np.array([-np.inf if v is None else v for v in d["lb"]])
    A_ub, b_ub, A_eq, b_eq = (np.array(d[k]) for k in ("A_ub", "b_ub", "A_eq", "b_eq"))
    r = solve_lp(np.array(d["c"]), A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, lb=lb)
    assert r.status == "infeasible"
    t = LPModel(len(d["c"]), A_ub, b_ub, A_eq, b_eq, lb).least_violation()
    ref = _violation_by_scipy(A_ub, b_ub, A_eq, b_eq, lb)
    assert t is not None and ref > 1e-6
    assert t == pytest.approx(ref, rel=1e-6)


def test_least_violation_known_answers() -> None:
    rng = np.random.default_rng(3)
    # x <= -1 and x >= 1: violated by 1 at x = 0; with x >= 2 as a bound as well: by 1.5 at x = 0.5
    A = np.array([[1.0], [-1.0]])
    assert LPModel(1, A, np.array([-1.0, -1.0])).least_violation() == pytest.approx(1.0, abs=1e-9)
    assert LPModel(1, np.array([[1.0]]), np.array([-1.0]), lb=2.0).least_violation() == pytest.approx(1.5, abs=1e-9)
    # a feasible system (a point satisfies it by construction) is violated by nothing
    A_ub, A_eq = rng.normal(size=(8, 4)), rng.normal(size=(2, 4))
    x0 = rng.normal(size=4)
    t = LPModel(4, A_ub, A_ub @ x0 + 0.1, A_eq, A_eq @ x0, lb=x0 - 1.0, ub=x0 + 1.0).least_violation()
    assert t is not None and t <= 1e-9


def test_known_duals_of_a_small_lp():
    # max x + y s.t. x + 2y <= 4, 3x + y <= 6, x, y >= 0: x = (1.6, 1.2), shadow prices (0.4, 0.2)
    r = solve_lp(np.array([1.0, 1.0]), A_ub=np.array([[1.0, 2.0], [3.0, 1.0]]), b_ub=np.array([4.0, 6.0]),
                 lb=0.0, maximize=True)
    np.testing.assert_allclose(r.x, [1.6, 1.2], atol=1e-9)
    np.testing.assert_allclose(r.y_ub, [0.4, 0.2], atol=1e-9)
    np.testing.assert_allclose(r.z, 0.0, atol=1e-9)
    assert r.y_eq is not None and r.y_eq.shape == (0,)


def test_warm_model_results_keep_the_data_they_were_solved_from():
    rng = np.random.default_rng(11)
    A_eq = rng.uniform(0.5, 1.0, size=(2, 4))
    model = LPModel(4, A_eq=A_eq, b_eq=A_eq @ np.ones(4), lb=0.0, ub=3.0)
    first = model.solve(rng.normal(size=4))
    changed = A_eq.copy()
    changed[1, 2] = 0.25
    model.change_coefficients(np.array([1]), np.array([2]), np.array([0.25]))
    model.set_col_bounds(0, 0.0, 0.0)
    model.set_eq_rhs(changed @ np.array([0.0, 2.0, 2.0, 2.0]))  # feasible at that point
    second = model.solve(rng.normal(size=4))
    for r in (first, second):
        assert r.found and r.is_optimal(1e-7)
    assert first.problem is not None and second.problem is not None
    np.testing.assert_array_equal(first.problem.b_eq, A_eq @ np.ones(4))
    assert first.problem.A_eq[1, 2] == A_eq[1, 2] and second.problem.A_eq[1, 2] == 0.25
    assert second.x is not None and second.x[0] == 0.0 and second.problem.ub[0] == 0.0


def test_row_bound_lp_finds_points_and_reports_empty_polytopes():
    H = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    lp = RowBoundLP(H, 1e-9)
    v = lp.solve(np.array([0.5, -INF, -INF]), np.array([INF, INF, 0.0]))  # x >= 0.5, x + y <= 0
    assert v is not None and v[0] >= 0.5 - 1e-9 and v[0] + v[1] <= 1e-9 and np.max(np.abs(v)) <= 1 + 1e-9
    assert lp.solve(np.array([0.5, 0.6, -INF]), np.array([INF, INF, 1.0])) is None  # x + y >= 1.1 > 1
    assert lp.solve(np.array([2.0, -INF, -INF]), np.array([INF, INF, INF])) is None  # outside the box
    assert lp.count == 3


def test_pointed_cone_test() -> None:
    """``cone(R)`` is pointed unless a nonnegative combination of its rays vanishes: the axes of
    the orthant and seeded rays inside it are pointed; x, -x (an implicit line) or three rays
    summing to zero are not, and those keep cdd's canonical form (which finds the line)."""
    rng = np.random.default_rng(7)
    inside = rng.random((20, 4)) + 1e-3
    assert _pointed(np.vstack([np.eye(4), inside / np.linalg.norm(inside, axis=1, keepdims=True)]))
    assert not _pointed(np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]]))
    tri = np.array([[1.0, 0.0], [-0.5, 3**0.5 / 2], [-0.5, -(3**0.5) / 2]])
    assert not _pointed(tri)
    g = reduce_generators(Generators(np.zeros((1, 2)), np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]]),
                                     np.zeros((0, 2))))
    assert np.allclose(np.abs(g.lines), [[1.0, 0.0]]) and np.allclose(g.rays, [[0.0, 1.0]])


def _reference_solve(A_ub: np.ndarray, b_ub: np.ndarray, lb: np.ndarray, ub: np.ndarray, c: np.ndarray,
                     feasibility: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The same LP through highspy's public class and a ``HighsLp`` (the adapter's former path)."""
    import highspy

    m, n = A_ub.shape
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    for name, value in {"presolve": "off", "simplex_strategy": 4, "primal_feasibility_tolerance": feasibility,
                        "dual_feasibility_tolerance": 1e-10}.items():
        h.setOptionValue(name, value)
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = n, m
    lp.col_cost_ = np.zeros(n)
    lp.col_lower_, lp.col_upper_ = lb, ub
    lp.row_lower_, lp.row_upper_ = np.full(m, -INF), b_ub
    cols, rows = np.nonzero(A_ub.T)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = np.r_[0, np.cumsum(np.bincount(cols, minlength=n))].astype(np.int32)
    lp.a_matrix_.index_ = rows.astype(np.int32)
    lp.a_matrix_.value_ = A_ub[rows, cols]
    h.passModel(lp)
    h.changeColsCost(n, np.arange(n, dtype=np.int32), c)
    h.run()
    sol = h.getSolution()
    return (np.array(sol.col_value), np.array(sol.row_dual), np.array(sol.col_dual),
            int(h.getInfo().simplex_iteration_count))


@pytest.mark.parametrize("seed", range(4))
def test_lp_model_loads_the_same_model_as_highs_lp(seed):
    """LPModel passes its model to HiGHS' core class as arrays: on random LPs, sparse and degenerate
    (integer data), with bounds and free columns, it returns bit for bit the point and the
    multipliers of the same LP loaded through ``highspy.Highs`` and a ``HighsLp``."""
    rng = np.random.default_rng(seed)
    for trial in range(40):
        m, n = int(rng.integers(3, 25)), int(rng.integers(2, 12))
        A = rng.standard_normal((m, n))
        A[rng.random((m, n)) < 0.3] = 0.0
        if trial % 2:
            A = np.round(A)  # degenerate vertices
        b = np.abs(rng.standard_normal(m)) * (trial % 3 > 0)
        lb, ub = (np.full(n, -INF), np.full(n, INF)) if trial % 5 == 0 else (np.full(n, -1.0), np.full(n, 1.0))
        c = np.round(rng.standard_normal(n))
        x, y, z, iters = _reference_solve(A, b, lb, ub, c, 1e-9)
        model = LPModel(n, A_ub=A, b_ub=b, lb=lb, ub=ub, feasibility=1e-9)
        res = model.solve(c)
        assert int(model._h.getInfo().simplex_iteration_count) == iters
        if res.status != "optimal":
            continue
        assert res.x is not None and res.y_ub is not None and res.z is not None
        assert np.array_equal(res.x, x) and np.array_equal(res.y_ub, -y) and np.array_equal(res.z, -z)


def test_set_bounds_then_cold_solve_equals_a_new_model():
    """``set_bounds`` + ``set_ub_rhs`` + ``solve_cold`` on a kept model (the slip-sector search's
    motion LP) gives what a new model with those data gives: the same vertex, to rounding (HiGHS
    keeps some state of the model across ``clearSolver``, so the last bits may differ)."""
    rng = np.random.default_rng(5)
    A = rng.standard_normal((12, 6))
    kept = LPModel(6, A_ub=A, b_ub=np.ones(12), lb=-1.0, ub=1.0)
    kept.solve_cold(rng.standard_normal(6))
    for _ in range(10):
        b, lim, c = np.abs(rng.standard_normal(12)), float(rng.uniform(0.5, 3.0)), rng.standard_normal(6)
        lb = np.r_[np.full(3, -lim), np.zeros(3)]
        ub = np.r_[np.full(3, lim), np.full(3, np.inf)]
        kept.set_ub_rhs(b)
        kept.set_bounds(lb, ub)
        again = kept.solve_cold(c)
        fresh = LPModel(6, A_ub=A, b_ub=b, lb=lb, ub=ub).solve_cold(c)
        assert again.status == fresh.status == "optimal"
        assert again.x is not None and fresh.x is not None
        np.testing.assert_allclose(again.x, fresh.x, rtol=0.0, atol=1e-13)
        assert again.problem is not None and np.array_equal(again.problem.ub, fresh.problem.ub)  # type: ignore[union-attr]
        assert np.all(again.x[:3] <= lim) and np.all(again.x[3:] >= 0.0)


def test_lp_memo_solves_each_distinct_lp_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Inside ``analysis.memo.scope`` an LP with the same data, options and method returns the first result
    (one HiGHS model built), equal bit for bit to a fresh solve outside the block; an LP differing
    in one entry, the sense, the tolerance or the method is solved anew; the shared arrays are
    read-only; nested blocks share one memo, and a new block starts empty."""
    import analysis.solvers.highs as highs
    from analysis import memo

    built = {"n": 0}
    orig_init = highs.LPModel.__init__

    def counting_init(self: LPModel, *a: object, **k: object) -> None:
        built["n"] += 1
        orig_init(self, *a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(highs.LPModel, "__init__", counting_init)
    rng = np.random.default_rng(12)
    n, m = 6, 9
    A = rng.normal(size=(m, n))
    b = A @ rng.uniform(0.1, 1.0, n) + rng.uniform(0.1, 1.0, m)  # feasible at a positive point
    c = rng.normal(size=n)
    args = {"A_ub": A, "b_ub": b, "A_eq": A[:1], "b_eq": A[:1] @ np.full(n, 0.5), "lb": 0.0, "ub": 2.0}
    fresh = solve_lp(c, **args)  # type: ignore[arg-type]
    assert fresh.status == "optimal" and built["n"] == 1
    with memo.scope():
        first = solve_lp(c, **args)  # type: ignore[arg-type]
        again = solve_lp(c.copy(), **{k: np.array(v, dtype=float) for k, v in args.items()})  # type: ignore[arg-type]
        assert again is first and built["n"] == 2
        assert first.x is not None and fresh.x is not None
        np.testing.assert_array_equal(first.x, fresh.x)
        np.testing.assert_array_equal(first.y_ub, fresh.y_ub)  # type: ignore[arg-type]
        assert first.objective == fresh.objective
        with pytest.raises(ValueError):
            first.x[0] = 1.0  # shared: read-only
        A2 = A.copy()
        A2[3, 2] += 1e-12
        others = [solve_lp(c, **{**args, "A_ub": A2}),  # type: ignore[arg-type]
                  solve_lp(c, **args, maximize=True),  # type: ignore[arg-type]
                  solve_lp(c, **args, feasibility=1e-9),  # type: ignore[arg-type]
                  solve_lp(c, **args, method="defaults")]  # type: ignore[arg-type]
        assert built["n"] == 6 and all(o is not first for o in others)
        with memo.scope():  # nested: the outer block's results
            assert solve_lp(c, **args) is first  # type: ignore[arg-type]
        assert built["n"] == 6
        np.testing.assert_allclose(others[3].x, fresh.x, atol=1e-8)  # type: ignore[arg-type]  # the same optimum
    with memo.scope():
        assert solve_lp(c, **args) is not first  # type: ignore[arg-type]
    assert solve_lp(c, **args) is not first  # type: ignore[arg-type]
    assert built["n"] == 8
