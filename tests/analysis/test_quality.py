"""Known answers for analysis/quality.py: Ferrari-Canny epsilon and the DPFC wrench ball."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from analysis.combination import CombinationParts, analyze_combination
from analysis.contacts import system_from_arrays
from analysis.dpfc import dpfc
from analysis.quality import combination_quality, epsilon, wrench_ball
from analysis.stationary import stationary_grasps


def _opposed(R: float, mu: float):  # two opposing contacts on a disk of radius R, fixed bodies
    pts = np.array([[R, 0.0], [-R, 0.0]])
    return system_from_arrays(pts, -pts / R, np.zeros(2), mu=mu, w_ex=np.zeros(3), object_size=R)


def _tripod(R: float, mu: float):  # three contacts at 120 degrees, gravity [0, -1, 0]
    a = np.pi / 2 + 2 * np.pi * np.arange(3) / 3
    pts = R * np.c_[np.cos(a), np.sin(a)]
    return system_from_arrays(pts, -pts / R, np.zeros(2), mu=mu, w_ex=np.array([0.0, -1.0, 0.0]), object_size=R)


def _cradle(R: float, mu: float):  # two contacts below the centre at +-30 degrees from the bottom, gravity
    a = np.deg2rad([240.0, 300.0])
    pts = R * np.c_[np.cos(a), np.sin(a)]
    return system_from_arrays(pts, -pts / R, np.zeros(2), mu=mu, w_ex=np.array([0.0, -1.0, 0.0]), object_size=R)


def _eps(sy, comb: str) -> float:
    p = CombinationParts.build(sy, comb)
    r = epsilon(p.st, p.fs, sy.scales).radius
    assert r is not None
    return r


def test_epsilon_two_opposing_contacts_closed_form() -> None:
    # scaled primitive wrenches (-+1, +-mu, +-mu): a tetrahedron whose faces lie at mu / sqrt(mu^2 + 2)
    for mu in (0.3, 0.5, 1.0):
        assert abs(_eps(_opposed(0.1, mu), "FF") - mu / np.sqrt(mu**2 + 2)) < 1e-9


def test_epsilon_zero_without_interior_and_monotone_in_mu() -> None:
    assert _eps(_opposed(0.1, 0.5), "FD") == 0.0  # one contact: no closure
    assert _eps(_tripod(0.1, 0.5), "SSS") == 0.0  # normals through the centre: no moment
    assert _eps(_tripod(0.1, 0.6), "FFF") > _eps(_tripod(0.1, 0.3), "FFF") > 0.0


def _ball(sy, comb: str):
    p = CombinationParts.build(sy, comb)
    grasp = stationary_grasps(sy, p.sel, p.st, p.fs)[0]
    return p, grasp, wrench_ball(dpfc(p.st, p.fs, grasp), sy.scales)


def test_scale_invariance() -> None:
    a, b = _cradle(0.1, 0.5), _cradle(2.5, 0.5)
    assert abs(_eps(_tripod(0.1, 0.5), "FFF") - _eps(_tripod(2.5, 0.5), "FFF")) < 1e-9
    ra, rb = _ball(a, "FF")[2].radius, _ball(b, "FF")[2].radius
    assert ra is not None and rb is not None and abs(ra - rb) < 1e-6 * max(1.0, ra)


def _resisted(p, grasp, w: np.ndarray) -> bool:
    """Independent check (scipy linprog): forces in F with tau unchanged balance w_ex + w."""
    A_eq, b_eq = p.st.G_c, -(p.system.w_ex + w)
    if p.st.J_c.shape[1]:
        A_eq = np.vstack([A_eq, p.st.J_c.T])
        b_eq = np.r_[b_eq, grasp.tau]
    res = linprog(np.zeros(p.st.G_c.shape[1]), A_ub=p.fs.C, b_ub=np.full(p.fs.C.shape[0], 1e-10), A_eq=A_eq,
                  b_eq=b_eq, bounds=(None, None), method="highs")
    return bool(res.status == 0)


def test_wrench_ball_by_sampling() -> None:
    sy = _cradle(0.1, 0.5)
    p, grasp, ball = _ball(sy, "FF")  # a pointed cone translated by -w_ex: a finite ball
    r = ball.radius
    assert r is not None and r > 0.0 and ball.weakest is not None
    S_inv = np.r_[1.0, 1.0, sy.scales.length]  # |w|_l = |S w|: w = S^-1 u
    rng = np.random.default_rng(7)
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    assert all(_resisted(p, grasp, 0.99 * r * S_inv * v) for v in u)
    outside = [not _resisted(p, grasp, 1.05 * r * S_inv * v) for v in np.vstack([u, ball.weakest])]
    assert outside[-1] and any(outside)


def test_wrench_ball_zero_without_interior() -> None:
    ball = _ball(_tripod(0.1, 0.5), "SSS")[2]  # normal forces only: no moment can be resisted
    assert ball.radius == 0.0


def test_wrench_ball_force_closure_on_fixed_bodies_is_unbounded() -> None:
    # fixed fingers, three frictional contacts at 120 degrees: internal forces resist any wrench
    assert _ball(_tripod(0.1, 0.5), "FFF")[2].radius == np.inf


def test_combination_quality_is_the_reports_quality() -> None:
    """The table's radii (combination_quality) are those of each combination's full report JSON,
    and a combination without a stationary grasp has none."""
    sy = _tripod(0.05, 0.5)
    graded = 0
    for comb in ("FFF", "FFS", "SSS", "SFD", "FDF"):
        q = combination_quality(sy, comb)
        rep = analyze_combination(sy, comb).to_json()
        if "quality" not in rep:
            assert q is None
            continue
        assert q is not None
        graded += 1
        assert q.to_json()["epsilon"] == rep["quality"]["epsilon"]
        assert q.to_json()["wrench_ball"] == rep["quality"]["wrench_ball"]
    assert graded >= 3
    assert combination_quality(sy, "DDD") is None  # gravity, nothing holds the disk
