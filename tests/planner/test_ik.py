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
