"""Solver adapters: known answers for HiGHS and cdd wrappers."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.solvers.cdd import Generators, cone_generators, polyhedron_generators, reduce_generators
from analysis.solvers.highs import LPModel, solve_lp


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
