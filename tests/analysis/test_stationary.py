"""Stationary grasp (paper eq. 18): -w_ex = G_c f_c with f_c in the friction set."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from closure_helpers import (
    BOX_B,
    BOX_C,
    EXAMPLE_NAMES,
    box_scene,
    disk_scene,
    example_system,
    parts_of,
    sample_combinations,
    scipy_lp,
)

from analysis.combination import CombinationParts
from analysis.contacts import GraspSystem, all_combinations, build_system
from analysis.exceptions import NoStationaryGrasp
from analysis.stationary import min_total_normal, stationary_grasp

#: Residual tolerance (forces of order one). The Allegro scene has combinations whose G_c is
#: within 1e-9 of rank deficiency; there the LP answers are only as exact as HiGHS' primal
#: feasibility tolerance (1e-7).
TOL = {name: 1e-9 for name in EXAMPLE_NAMES} | {"allegro_right_box": 2e-7}
N_SAMPLE = 40
#: combinations whose G_c is nearly singular (HiGHS once returned an "optimal" interior point
#: violating friction by 0.055 for SDFSSS)
EXTRA = {"allegro_right_box": ["SDFSSS", "SFFSSS", "SSFDSS", "DSFFFF"]}


@pytest.mark.parametrize("name", EXAMPLE_NAMES)
def test_solutions_satisfy_equilibrium_and_friction(name: str) -> None:
    system = example_system(name)
    tol = TOL[name]
    solved = 0
    for c in sample_combinations(system, N_SAMPLE, seed=5) + EXTRA.get(name, []):
        p = parts_of(name, c)
        st, fs = p.st, p.fs
        found = min_total_normal(system, st, fs)
        if found is None:
            with pytest.raises(NoStationaryGrasp):
                stationary_grasp(system, p.sel, st, fs)
            continue
        solved += 1
        n_star = found[0]
        # the least total normal force agrees with an independent LP (scipy)
        loaded = fs.N[np.any(fs.N != 0.0, axis=1)].sum(axis=0)
        status, obj, _ = scipy_lp(loaded, fs.C, np.zeros(fs.C.shape[0]), st.G_c, -system.w_ex)
        if status == 0:
            # (on the Allegro scene's near-singular G_c a 1e-7 residual moves the optimum by ~1e-6)
            assert obj is not None and n_star == pytest.approx(obj, abs=max(1e-6, 100 * tol))
        else:  # scipy's HiGHS calls it infeasible: then it must be feasible only within tolerance
            assert name == "allegro_right_box"
            assert _least_equilibrium_violation(system.w_ex, st.G_c, fs.C, loaded, 10 * n_star + 1) <= tol
        grasps = {kind: stationary_grasp(system, p.sel, st, fs, kind) for kind in ("min_grip", "interior")}
        for g in grasps.values():
            scale = max(1.0, float(np.abs(g.f_c).max()))
            assert g.equilibrium_residual(st, system.w_ex) <= tol * scale
            assert fs.violation(g.f_c) <= tol * scale
            np.testing.assert_allclose(g.tau, st.J_c.T @ g.f_c, rtol=0, atol=1e-12)
            np.testing.assert_allclose(g.xi_t, st.Gamma.T @ g.f_c, rtol=0, atol=1e-12)
            assert g.total_normal == pytest.approx(float((fs.N @ g.f_c).sum()), abs=1e-12)
        low, inner = grasps["min_grip"], grasps["interior"]
        assert low.total_normal == pytest.approx(n_star, abs=tol)
        assert low.total_normal <= inner.total_normal + tol
        # the interior member: margin >= 0 to every facet and to n_f = 0, within the budget 2 N*
        assert inner.margin >= 0.0
        assert np.max(fs.C @ inner.f_c) <= -inner.margin + tol
        n_f = fs.N @ inner.f_c
        loaded_rows = np.any(fs.N != 0.0, axis=1)
        assert np.all(n_f[loaded_rows] >= inner.margin - tol)
        assert inner.total_normal <= (2.0 * n_star if n_star > 1e-9 else 1.0) + tol
    assert solved >= 3  # the sample must exercise solutions


@pytest.mark.parametrize("name", EXAMPLE_NAMES)
def test_all_detached_with_gravity_has_no_stationary_grasp(name: str) -> None:
    system = example_system(name)
    assert np.linalg.norm(system.w_ex) > 0.0
    p = parts_of(name, "D" * system.L)
    with pytest.raises(NoStationaryGrasp):
        stationary_grasp(system, p.sel, p.st, p.fs)


def _least_equilibrium_violation(w_ex: np.ndarray, G: np.ndarray, C: np.ndarray, loaded: np.ndarray,
                                 budget: float) -> float:
    """min t s.t. |G f + w_ex|_inf <= t, C f <= 0, total normal force <= budget."""
    n, m, D = G.shape[1], C.shape[0], G.shape[0]
    A = np.block([[C, np.zeros((m, 1))], [G, -np.ones((D, 1))], [-G, -np.ones((D, 1))],
                  [loaded[None, :], np.zeros((1, 1))]])
    b = np.concatenate([np.zeros(m), -w_ex, w_ex, [budget]])
    status, obj, _ = scipy_lp(np.r_[np.zeros(n), 1.0], A, b)
    assert status == 0 and obj is not None
    return obj


_UPGRADES = {"D": "SF", "S": "F", "N": "", "F": ""}


@pytest.mark.parametrize("name", ["planar_disk_envelope", "sphere_four_finger_palm"])
def test_feasibility_is_monotone_under_upgrades(name: str) -> None:
    """The force set of a contact grows D -> S -> F (nothing, normal only, cone), so a
    stationary grasp of a combination is one of every combination upgrading any contact."""
    system = example_system(name)
    feasible = {c: min_total_normal(system, parts_of(name, c).st, parts_of(name, c).fs) is not None
                for c in all_combinations(system)}
    assert any(feasible.values()) and not all(feasible.values())
    for c, ok in feasible.items():
        if not ok:
            continue
        for i, s in enumerate(c):
            for up in _UPGRADES[s]:
                assert feasible[c[:i] + up + c[i + 1 :]], f"{c} feasible but {c[:i] + up + c[i + 1:]} not"


# --------------------------------------------------------------------------------------------
# Stationary grasps derived by hand


def _grasps(system: GraspSystem, combination: str) -> tuple[CombinationParts, dict[str, np.ndarray]]:
    p = CombinationParts.build(system, combination)
    return p, {kind: stationary_grasp(system, p.sel, p.st, p.fs, kind).f_c for kind in ("min_grip", "interior")}


def test_block_on_table_by_hand() -> None:
    """Block (unit weight) on two supports at x = -+0.4 pushed at height h by a frictionless tip.

    SSN: the S supports carry normal forces only, so the push is 0 and, by moments about the
    centre, n1 = n2 = 1/2 (unique). FFN: any solution has n1 + n2 = 1 (vertical balance), so the
    least total normal force is 1. DFN (right support only): the push must balance the weight's
    moment about the support, n3 h = c, and friction there must hold f_x = -c/h, possible iff
    c/h <= mu: with mu = 0.5, h = 0.9 the unique solution is (-c/h, 1, c/h); with h = 0.25
    there is none. SDN/DSN/DDN: a single support or none cannot balance the weight's moment.
    """
    low = build_system(box_scene(0.25, 0.5))
    _, g = _grasps(low, "SSN")
    for f in g.values():
        np.testing.assert_allclose(f, [0.5, 0.5, 0.0], rtol=0, atol=1e-9)
    _, g = _grasps(low, "SSD")
    for f in g.values():
        np.testing.assert_allclose(f, [0.5, 0.5], rtol=0, atol=1e-9)
    p = CombinationParts.build(low, "FFN")
    assert stationary_grasp(low, p.sel, p.st, p.fs, "min_grip").total_normal == pytest.approx(1.0, abs=1e-9)
    assert stationary_grasp(low, p.sel, p.st, p.fs, "interior").total_normal <= 2.0 + 1e-9
    for comb in ("DFN", "FDN", "SDN", "DSN", "DDN", "DDD"):
        p = CombinationParts.build(low, comb)
        with pytest.raises(NoStationaryGrasp):
            stationary_grasp(low, p.sel, p.st, p.fs)
    high = build_system(box_scene(0.9, 0.5))
    _, g = _grasps(high, "DFN")
    c_h = BOX_C / 0.9
    for f in g.values():
        np.testing.assert_allclose(f, [-c_h, 1.0, c_h], rtol=0, atol=1e-9)
    assert BOX_B > 0  # the weight acts at the centre, 0.5 above the table


def test_frictionless_disk_by_hand() -> None:
    """No external wrench: f = 0 holds the disk (min grip); the interior member squeezes with
    n1 = n2 = 1/2, the largest equal pair within the budget n1 + n2 <= 1. With one finger
    detached the other cannot push (n1 = 0)."""
    system = build_system(disk_scene(1))
    _, g = _grasps(system, "NN")
    np.testing.assert_allclose(g["min_grip"], [0.0, 0.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(g["interior"], [0.5, 0.5], rtol=0, atol=1e-9)
    _, g = _grasps(system, "ND")
    for f in g.values():
        np.testing.assert_allclose(f, [0.0], rtol=0, atol=1e-12)
    for combination in itertools.product("ND", repeat=2):
        p = CombinationParts.build(system, "".join(combination))
        assert min_total_normal(system, p.st, p.fs) is not None
