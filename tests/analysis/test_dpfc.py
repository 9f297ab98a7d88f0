"""Direction of passive force closure (paper eq. 28): the wrenches w_p = G_c Gamma xi~ that
internal forces balance without changing tau_st, with f_st - Gamma xi~ in the friction set."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import example_system, parts_of, sample_combinations, scipy_lp

from analysis.combination import CombinationParts
from analysis.contacts import build_system
from analysis.dpfc import DPFC, dpfc
from analysis.exceptions import NoStationaryGrasp
from analysis.loader import scene_from_dict
from analysis.stationary import StationaryGrasp, stationary_grasp

TOL = 1e-8


def _in_generators(dp: DPFC, w: np.ndarray) -> bool:
    """w in conv(vertices) + cone(rays) + span(lines), by an LP (scipy)."""
    g = dp.generators
    V, R, Ln = g.vertices, g.rays, g.lines
    cols = np.vstack([V, R, Ln, -Ln]).T  # (D, k)
    nv = len(V)
    A_eq = np.vstack([cols, np.r_[np.ones(nv), np.zeros(cols.shape[1] - nv)][None, :]])
    b_eq = np.r_[w, 1.0]
    k = cols.shape[1]
    status, _, _ = scipy_lp(np.zeros(k), -np.eye(k), np.zeros(k), A_eq, b_eq)
    return status == 0


def _walls_scene() -> CombinationParts:
    """A disk between two fixed frictionless walls (no fingers, no external wrench)."""
    scene = scene_from_dict({
        "dim": 2,
        "object": {"pose": {"position": [0.0, 0.0], "angle": 0.0}, "shape": {"type": "disk", "radius": 0.5}},
        "external_wrench": [0.0, 0.0, 0.0],
        "fixed_bodies": [{"name": "left", "shape": {"type": "segment", "points": [[-0.5, -1.0], [-0.5, 1.0]]}},
                         {"name": "right", "shape": {"type": "segment", "points": [[0.5, -1.0], [0.5, 1.0]]}}],
        "contacts": [{"body": "left", "point": [-0.5, 0.0], "normal": [1.0, 0.0], "mu": 0.0},
                     {"body": "right", "point": [0.5, 0.0], "normal": [-1.0, 0.0], "mu": 0.0}],
    })
    return CombinationParts.build(build_system(scene), "NN")


@pytest.mark.parametrize("kind", ["interior", "min_grip"])
def test_disk_between_walls_by_hand(kind: str) -> None:
    """Both contact forces are internal (J = 0): w_p = (xi1 - xi2, 0, 0) with xi_i <= n_i,st,
    so DPFC is the whole x axis (a line) however the disk is squeezed; the disk can move along y
    and turn (a~ = 2), which no contact resists."""
    p = _walls_scene()
    assert (p.ms.a_bar, p.st.p) == (2, 1)
    g = stationary_grasp(p.system, p.sel, p.st, p.fs, kind)  # type: ignore[arg-type]
    dp = dpfc(p.st, p.fs, g)
    assert dp.dim == 1
    assert dp.generators.lines.shape == (1, 3)
    np.testing.assert_allclose(np.abs(dp.generators.lines[0]), [1.0, 0.0, 0.0], rtol=0, atol=1e-12)
    for w, inside in [([5.0, 0.0, 0.0], True), ([-7.0, 0.0, 0.0], True), ([0.0, 1.0, 0.0], False),
                      ([1.0, 0.0, 0.1], False)]:
        assert dp.contains(np.array(w), p.st, p.fs, g) == inside


def test_frictionless_fingertips_have_no_passive_directions() -> None:
    """Two frictionless fingertips (J_c of full row rank): no internal force, DPFC = {0}."""
    from closure_helpers import disk_scene

    p = CombinationParts.build(build_system(disk_scene(1)), "NN")
    g = stationary_grasp(p.system, p.sel, p.st, p.fs)
    dp = dpfc(p.st, p.fs, g)
    assert dp.dim == 0 and p.st.p == 0
    np.testing.assert_allclose(dp.vertices, np.zeros((1, 3)), rtol=0, atol=0)


def _cases() -> list[tuple[str, str]]:
    out = []
    for name, n in (("planar_disk_envelope", 30), ("sphere_four_finger_palm", 12)):
        out += [(name, c) for c in sample_combinations(example_system(name), n, seed=9)]
    return out


def _check_generators(p: CombinationParts, g: StationaryGrasp, dp: DPFC) -> None:
    """Every vertex is G_c Gamma xi~ with f_st - Gamma xi~ in F; every ray/line is
    G_c Gamma xi~ with -Gamma xi~ in the recession cone of F (C Gamma xi~ >= 0)."""
    st, fs = p.st, p.fs
    GG = st.G_c @ st.Gamma
    pb = GG.shape[1]
    CG = fs.C @ st.Gamma
    for v in dp.vertices:
        status, _, xi = scipy_lp(np.zeros(pb), -CG, -(fs.C @ g.f_c) + TOL, GG, v)
        assert status == 0 and xi is not None
        assert fs.violation(g.f_c - st.Gamma @ xi) <= 1e-7
    for r in np.vstack([dp.generators.rays, dp.generators.lines, -dp.generators.lines]):
        status, _, xi = scipy_lp(np.zeros(pb), -CG, np.full(CG.shape[0], TOL), GG, r)
        assert status == 0, r


def test_generators_map_back_to_admissible_internal_forces() -> None:
    checked = 0
    rng = np.random.default_rng(10)
    for name, c in _cases():
        p = parts_of(name, c)
        try:
            g = stationary_grasp(p.system, p.sel, p.st, p.fs)
        except NoStationaryGrasp:
            continue
        dp = dpfc(p.st, p.fs, g)
        assert dp.dim <= p.st.p
        if p.st.Gamma.shape[1] == 0:
            continue
        checked += 1
        _check_generators(p, g, dp)
        # contains() agrees with the generators: convex combinations (plus rays) are inside
        V, dirs = dp.vertices, dp.rays
        for _ in range(5):
            lam = rng.random(len(V))
            w = (lam / lam.sum()) @ V + (rng.random(len(dirs)) @ dirs if len(dirs) else 0.0)
            assert dp.contains(w, p.st, p.fs, g)
        # random points in the span of the passive wrenches: contains() == generator membership,
        # away from the boundary (both agree at 0.999 s and 1.001 s); far out is outside unless
        # the direction recedes
        centre = V.mean(axis=0)
        agreed = 0
        for _ in range(12):
            d = p.st.Xi @ rng.normal(size=p.st.p)
            for s in (0.1, 1.0, 10.0, 1e3):
                inside = _in_generators(dp, centre + s * d)
                if inside != _in_generators(dp, centre + 0.999 * s * d) or inside != _in_generators(
                        dp, centre + 1.001 * s * d):
                    continue
                assert dp.contains(centre + s * d, p.st, p.fs, g) == inside
                agreed += 1
        assert agreed > 20
        # a wrench with a component outside range(Xi) is never a DPFC direction
        if p.st.p < p.system.D:
            off = rng.normal(size=p.system.D)
            off -= p.st.Xi @ (p.st.Xi.T @ off)
            assert not dp.contains(centre + off / np.linalg.norm(off), p.st, p.fs, g)
    assert checked >= 5


def test_passive_closure_contains_a_ball() -> None:
    """All-F on the planar envelope grasp is passive closure: the interior stationary grasp
    has a positive friction margin and G_c Gamma has full rank, so every small external wrench
    is balanced by internal forces alone (DPFC contains a neighbourhood of 0)."""
    p = parts_of("planar_disk_envelope", "FFFFF")
    g = stationary_grasp(p.system, p.sel, p.st, p.fs)
    assert g.margin > 0.0 and p.st.p == p.system.D
    dp = dpfc(p.st, p.fs, g)
    assert dp.dim == 3
    rng = np.random.default_rng(12)
    for _ in range(20):
        w = rng.normal(size=3)
        assert dp.contains(1e-3 * g.margin * w / np.linalg.norm(w), p.st, p.fs, g)
