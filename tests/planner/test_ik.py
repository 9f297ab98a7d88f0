"""Inverse kinematics of a fingertip at a target with the last link along the normal."""

from __future__ import annotations

import numpy as np

from analysis.kinematics import BodyRef, SerialChain
from planner.ik import ALIGNMENT_MARGIN, alignment_bound, fingertip_ik


def test_ik_puts_the_tip_on_the_target(free_left) -> None:  # type: ignore[no-untyped-def]
    hand, st = free_left
    target, normal = np.array([-0.5, 0.5]), np.array([1.0, 0.0])
    sols = fingertip_ik(hand, 0, target, normal, [st.q[:2]])
    assert sols
    q = st.q.copy()
    q[:2] = sols[0]
    a, b = hand.body_segment(BodyRef("left/1", 0, 1), q)
    np.testing.assert_allclose(b, target, atol=1e-7)
    assert (b - a) @ normal / np.linalg.norm(b - a) >= 0.5 - 1e-9



def _palm_chain():  # type: ignore[no-untyped-def]
    from pathlib import Path

    from analysis.kinematics import HandKinematics
    from analysis.loader import load_scene

    scene = load_scene(Path(__file__).resolve().parents[2] / "examples" / "sphere_four_finger_palm.json")
    return HandKinematics.from_scene(scene)


def test_alignment_bound_bounds_every_configuration() -> None:
    """For the palm scene's fingers (a yaw joint, then three parallel bending joints) the last
    link of any configuration lies in the plane of ``alignment_bound(chain, tip)``: its alignment
    with any normal is at most the length of the normal's projection on that plane."""
    hand = _palm_chain()
    rng = np.random.default_rng(5)
    for chain in hand.fingers:
        for _ in range(200):
            q = rng.uniform(-np.pi, np.pi, chain.n_joints)
            a, b = chain.body_segment(chain.n_joints - 1, q)
            u = (b - a) / np.linalg.norm(b - a)
            plane = alignment_bound(chain, b)
            assert plane is not None
            assert abs(float(u @ plane)) < 1e-9  # the last link lies in the plane
            n = rng.normal(size=3)
            n /= np.linalg.norm(n)
            assert float(u @ n) <= float(np.linalg.norm(n - (n @ plane) * plane)) + 1e-9


def test_targets_out_of_the_plane_bound_have_no_solution() -> None:
    """Where the bound is below the alignment asked for, fingertip_ik answers [] without solving,
    and IPOPT itself finds no solution there from any of 5 seeds (the skip drops only failures);
    a chain that is not of that kind gets no bound."""
    from planner.ik import _ik_solver

    hand = _palm_chain()
    chain = hand.fingers[0]
    rng = np.random.default_rng(2)
    solver = _ik_solver(chain, 3)
    skipped = 0
    for _ in range(40):
        target = np.array([0.0, 0.0, 0.5]) + 0.5 * (v := rng.normal(size=3)) / np.linalg.norm(v)
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        plane = alignment_bound(chain, target)
        assert plane is not None
        if float(np.linalg.norm(normal - (normal @ plane) * plane)) >= 0.5 - ALIGNMENT_MARGIN:
            continue
        skipped += 1
        seeds = [rng.uniform(-np.pi, np.pi, 4) for _ in range(5)]
        assert fingertip_ik(hand, 0, target, normal, seeds) == []
        for s in seeds:
            solver(x0=s, p=np.r_[s, target, normal], lbg=np.r_[np.zeros(3), 0.5], ubg=np.r_[np.zeros(3), np.inf])
            assert not solver.stats()["success"]
    assert skipped >= 5
    axes = chain.axes.copy()
    axes[2] = [1.0, 0.0, 0.0]  # the third joint no longer parallel to the second
    bent = SerialChain(chain.name, chain.base_R, chain.base_p, axes, chain.origins, chain.tip, chain.radii, chain.q0)
    assert alignment_bound(bent, np.array([0.0, 0.0, 1.0])) is None


def test_ik_problems_are_shared_by_equal_chains_and_bounded() -> None:
    """The IPOPT problem is keyed by the chain's geometry: the same scene loaded twice (as every
    plan does) reuses it, a chain with another joint origin gets its own, and the cache stays at
    most ``_IK_SOLVERS_MAX`` problems however many chains are seen (no chain is kept alive)."""
    from planner import ik

    first, again = _palm_chain().fingers[0], _palm_chain().fingers[0]
    assert first is not again
    solver = ik._ik_solver(first, 3)
    assert ik._ik_solver(again, 3) is solver
    moved = SerialChain(first.name, first.base_R, first.base_p + np.array([0.0, 0.0, 1e-3]), first.axes,
                        first.origins, first.tip, first.radii, first.q0)
    assert ik._ik_solver(moved, 3) is not solver
    assert ik._ik_solver(first, 2) is not solver  # the planar problem has other constraints
    for k in range(ik._IK_SOLVERS_MAX + 3):  # about 5 ms each to build
        other = SerialChain(first.name, first.base_R, first.base_p + np.array([k * 1e-3, 0.0, 0.0]), first.axes,
                            first.origins, first.tip, first.radii, first.q0)
        ik._ik_solver(other, 3)
    assert len(ik._IK_SOLVERS) == ik._IK_SOLVERS_MAX
    assert ik._ik_key(moved, 3) not in ik._IK_SOLVERS  # the least recently used went first


def _planar_chain(lengths, base, angle):  # type: ignore[no-untyped-def]
    from analysis.rotations import rotz

    n = len(lengths)
    origins = np.zeros((n, 3))
    origins[1:, 0] = lengths[:-1]
    return SerialChain("f", rotz(angle), np.r_[base, 0.0], np.tile([0.0, 0.0, 1.0], (n, 1)), origins,
                       np.array([lengths[-1], 0.0, 0.0]), np.zeros(n), np.zeros(n))


def test_planar_reach_gap_is_the_distance_to_the_reachable_set() -> None:
    """``planar_reach_gap`` against brute force on random planar chains of 1 to 4 links: every
    configuration whose last link is aligned gives gap 0 at its own tip; the gap of a random
    target equals the smallest distance, over 20,001 aligned directions of the last link, of the
    last joint's position from the annulus that the other links reach (computed from the
    configurations: its extremes are at joints of 0 or pi, which are among them)."""
    import itertools

    from planner.ik import planar_reach_gap

    rng = np.random.default_rng(11)
    for _ in range(60):
        n = int(rng.integers(1, 5))
        lengths = rng.uniform(0.2, 1.0, n)
        chain = _planar_chain(lengths, rng.normal(size=2), rng.uniform(-np.pi, np.pi))
        p0 = chain.base_p[:2]
        # the annulus from sampled configurations of the first n - 1 links
        folds = np.array(list(itertools.product((0.0, np.pi), repeat=n)))  # stretched and folded
        qs = np.vstack([rng.uniform(-np.pi, np.pi, (100, n)), folds])
        radii = np.array([np.linalg.norm(chain.body_segment(n - 1, q)[0][:2] - p0) for q in qs])
        r_lo, r_hi = float(radii.min()), float(radii.max())
        for q in qs[:20]:  # a configuration's own tip, with the normal it is aligned with
            a, b = chain.body_segment(n - 1, q)
            u = (b - a)[:2] / np.linalg.norm((b - a)[:2])
            nrm = rng.normal(size=2)
            nrm /= np.linalg.norm(nrm)
            # 0 up to the square root of round-off (a one-link chain: the annulus is a point)
            own = planar_reach_gap(chain, b[:2], nrm, float(u @ nrm) - 1e-12)
            assert own is not None and own <= 1e-7
        for _ in range(20):
            target = p0 + rng.normal(size=2) * 1.5 * lengths.sum()
            nrm = rng.normal(size=2)
            nrm /= np.linalg.norm(nrm)
            align = float(rng.uniform(-0.5, 0.99))
            phis = np.arctan2(nrm[1], nrm[0]) + np.arccos(align) * np.linspace(-1.0, 1.0, 20001)
            W = target - lengths[-1] * np.column_stack([np.cos(phis), np.sin(phis)])  # (k, 2) last joints
            dist = np.linalg.norm(W - p0, axis=1)
            brute = float(np.min(np.maximum(np.maximum(r_lo - dist, dist - r_hi), 0.0)))
            gap = planar_reach_gap(chain, target, nrm, align)
            assert gap is not None
            # the sampled annulus lies inside the true one by at most its sampling error
            assert gap <= brute + 1e-9
            # the directions' spacing moves the last joint by at most L_n times it
            assert gap >= brute - lengths[-1] * 2.0 * np.arccos(align) / 20000 - 1e-12
    assert planar_reach_gap(_planar_chain([1.0], np.zeros(2), 0.0), np.zeros(2), np.array([1.0, 0.0]), 1.01) \
        == float("inf")


def test_planar_targets_out_of_reach_have_no_ipopt_solution() -> None:
    """Where the gap exceeds PLANAR_REACH_MARGIN, fingertip_ik answers [] without solving, and IPOPT
    itself finds no solution there from any of 4 seeds (the skip drops only failures); targets the
    test lets through are solved as before. A chain that is not planar in z gets no gap."""
    from planner.ik import PLANAR_ALIGNMENT_SLACK, PLANAR_REACH_MARGIN, _ik_solver, planar_reach_gap

    rng = np.random.default_rng(3)
    chain = _planar_chain([0.9, 0.9], np.array([-0.6, 0.0]), 0.0)
    from analysis.kinematics import HandKinematics

    hand = HandKinematics(2, [chain], [])
    solver = _ik_solver(chain, 2)
    skipped = solved = 0
    for _ in range(60):
        target = rng.uniform(-2.0, 2.0, 2)
        normal = rng.normal(size=2)
        normal /= np.linalg.norm(normal)
        gap = planar_reach_gap(chain, target, normal, 0.5 - PLANAR_ALIGNMENT_SLACK)
        assert gap is not None
        seeds = [rng.uniform(-np.pi, np.pi, 2) for _ in range(4)]
        if gap > PLANAR_REACH_MARGIN:
            skipped += 1
            assert fingertip_ik(hand, 0, target, normal, seeds) == []
            for s in seeds:
                solver(x0=s, p=np.r_[s, target, normal], lbg=np.r_[np.zeros(2), 0.5], ubg=np.r_[np.zeros(2), np.inf])
                assert not solver.stats()["success"]
        else:
            solved += len(fingertip_ik(hand, 0, target, normal, seeds)) > 0
    assert skipped >= 10 and solved >= 10
    tilted = SerialChain("f", chain.base_R, chain.base_p, np.tile([0.0, 1.0, 0.0], (2, 1)), chain.origins, chain.tip,
                         chain.radii, chain.q0)
    assert planar_reach_gap(tilted, np.zeros(2), np.array([1.0, 0.0]), 0.5) is None
