"""Physical scales (analysis.scales): LPs posed in units of F0 and l, verdicts certified in newtons."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import example_system, scipy_lp

from analysis.combination import CombinationParts, analyze_combination, summarize
from analysis.contacts import system_from_arrays
from analysis.dpfc import dpfc
from analysis.enumerate import enumerate_combinations, parse_where
from analysis.exceptions import CombinationError, NoStationaryGrasp
from analysis.scales import GRIP_BOUND, grasp_scales
from analysis.stationary import certifies, min_total_normal, stationary_grasp, stationary_residuals


def test_scales_have_known_values() -> None:
    # 2 kg under gravity, lever arms of 0.2 m, an object of size 0.25 m
    sc = grasp_scales(3, np.array([0.0, 0.0, -19.62, 0.0, 0.0, 0.0]), np.full((4, 3), 0.2 / np.sqrt(3)), 0.25)
    assert sc.force == pytest.approx(19.62) and sc.length == pytest.approx(0.25)
    np.testing.assert_allclose(sc.wrench_weights(), [1 / 19.62] * 3 + [1 / (19.62 * 0.25)] * 3)
    assert sc.grip_bound == pytest.approx(GRIP_BOUND * 19.62)
    # a pure moment of 2 N m on a 0.5 m object is a force scale of 4 N; no object size: lever arms
    sc = grasp_scales(2, np.array([0.0, 0.0, 2.0]), np.array([[0.5, 0.0], [0.0, -0.3]]))
    assert sc.length == pytest.approx(0.5) and sc.force == pytest.approx(4.0)
    # no load: 1 N
    assert grasp_scales(2, np.zeros(3), np.array([[1.0, 0.0]])).force == 1.0
    # positive work of a rotation is measured in F0 l per radian
    assert sc.work_tol(np.array([0.0, 0.0, 1.0])) == pytest.approx(1e-6 * 4.0 * 0.5)


def _wedge(eps: float):
    """A unit disk of weight 1 N held by two frictionless contacts at (-+1, 0) whose normals
    point inwards and up by ``eps``: holding it takes normal forces of ``1 / (2 eps)`` each."""
    n1 = np.array([1.0, eps]) / np.hypot(1.0, eps)
    n2 = np.array([-1.0, eps]) / np.hypot(1.0, eps)
    return system_from_arrays(np.array([[-1.0, 0.0], [1.0, 0.0]]), np.vstack([n1, n2]), np.zeros(2), mu=0.0,
                              w_ex=np.array([0.0, -1.0, 0.0]))


def test_motion_sizes_of_rows_are_the_motion_size_of_each() -> None:
    """``motion_sizes`` (the batched DAFC tests' thresholds) is ``|(v, l omega)|`` of each row:
    ``motion_size`` of the row, and known values."""
    sc = grasp_scales(2, np.array([0.0, 0.0, 2.0]), np.array([[0.5, 0.0], [0.0, -0.3]]))  # l = 0.5
    DR = np.random.default_rng(13).standard_normal((9, 3))
    np.testing.assert_allclose(sc.motion_sizes(DR), [sc.motion_size(dr) for dr in DR], rtol=1e-15, atol=0)
    np.testing.assert_allclose(sc.motion_sizes(np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 2.0]])), [5.0, 1.0], rtol=1e-15)


def test_grasps_beyond_the_grip_bound_do_not_hold() -> None:
    for eps, holds in ((1e-2, True), (2e-3, True), (9.99e-4, False), (1e-9, False)):
        sy = _wedge(eps)
        p = CombinationParts.build(sy, "NN")
        found = min_total_normal(sy, p.st, p.fs)
        assert (found is not None) == holds, eps
        if eps >= 1e-4:  # the same question asked of scipy without a bound: it holds, with 1/eps newtons
            status, obj, _ = scipy_lp(p.fs.N.sum(axis=0), p.fs.C, np.zeros(p.fs.C.shape[0]), p.st.G_c, -sy.w_ex,
                                      box=1e9)
            assert status == 0 and obj == pytest.approx(np.hypot(1.0, eps) / eps, rel=1e-6)
        if found is not None:
            total, f_c = found
            assert total == pytest.approx(np.hypot(1.0, eps) / eps, rel=1e-9)
            eq, fr = stationary_residuals(sy, p.st, p.fs, f_c)
            assert eq <= 1e-9 and fr <= 1e-9 and certifies(sy, p.st, p.fs, f_c)
        else:
            with pytest.raises(NoStationaryGrasp) as e:
                stationary_grasp(sy, p.sel, p.st, p.fs)
            assert "1000 x 1 N" in str(e.value)
            assert not summarize(p).feasible


def test_a_certificate_with_a_violated_row_is_refused() -> None:
    sy = _wedge(1e-2)
    p = CombinationParts.build(sy, "NN")
    _total, f_c = min_total_normal(sy, p.st, p.fs)
    assert certifies(sy, p.st, p.fs, f_c)
    assert not certifies(sy, p.st, p.fs, f_c * (1 + 1e-4))  # equilibrium off by 1e-4 F0 * 50
    assert not certifies(sy, p.st, p.fs, -f_c)  # pulling contacts
    assert not certifies(sy, p.st, p.fs, f_c * 0.0)


def test_near_singular_allegro_combinations_are_flagged_degenerate() -> None:
    sy = example_system("allegro_right_box")
    report = analyze_combination(sy, "SDFSSS")
    assert not report.summary.feasible and report.summary.reason.startswith("no stationary grasp (18); degenerate")
    assert any(n.startswith("degenerate") for n in report.notes)
    assert report.to_json()["notes"] == list(report.notes)
    assert not analyze_combination(sy, "FFFFFF").notes


def test_parse_where_filters_letter_counts() -> None:
    keep = parse_where("D>=2, F<=1")
    assert keep("DDFS") and keep("DDSS") and not keep("DFFS") and not keep("DDFF")
    assert parse_where("s==0 and n!=1")("FFDD")
    for bad in ("X>=1", "D>>1", "", "D>=-1"):
        with pytest.raises(CombinationError) as e:
            parse_where(bad)
        assert e.value.loc == ("where",)


def test_limit_stops_after_that_many_feasible_combinations() -> None:
    sy = example_system("planar_disk_envelope")
    full, _ = enumerate_combinations(sy, workers=1)
    part, stats = enumerate_combinations(sy, workers=1, limit=5)
    assert sum(r.feasible for r in part) == 5 and stats.stopped_at_limit
    by_name = {r.combination: r for r in full}
    assert all(by_name[r.combination].feasible == r.feasible for r in part)
    some, _ = enumerate_combinations(sy, workers=1, where=parse_where("D>=4"))
    assert {r.combination for r in some} == {c for c in by_name if c.count("D") >= 4}


def test_dpfc_of_a_twelve_contact_wrap_is_described_not_enumerated() -> None:
    from pathlib import Path

    from analysis.contacts import build_system
    from analysis.loader import load_scene

    sy = build_system(load_scene(Path(__file__).resolve().parents[2] / "examples" / "sphere_wrap_three_link.json"))
    p = CombinationParts.build(sy, "F" * 12)
    g = stationary_grasp(sy, p.sel, p.st, p.fs)
    d = dpfc(p.st, p.fs, g)
    assert not d.enumerated and d.A_xi is not None and d.W_xi is not None
    assert d.dim == p.st.p == 6
    assert len(d.vertices) == 2 * p.st.p
    for w in d.vertices:  # every reported extreme wrench is in DPFC (an independent membership LP)
        assert d.contains(w, p.st, p.fs, g)
