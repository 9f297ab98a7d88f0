"""Rolling contacts of a planar disk on a link (ContactManifold(rolling=True)): exact rolling
kinematics (contact travel on the link = arc on the disk = r * relative rotation), against the
glued-point rows, which hold only to first order."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from closure_helpers import EXAMPLES
from scipy.linalg import null_space

from analysis.exceptions import SceneError
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Disk, Scene
from planner import Goal, plan
from planner.manifold import ContactManifold
from planner.motion_edges import _direction_candidates, _torque_set
from planner.nodes import GraphNodes
from planner.object_motion import integrate_object_motion, rolled_contacts
from planner.state import GraspState, StateAnalysis, all_f, state_from_scene

SCENE = EXAMPLES / "planar_disk_rolling_link.json"
R = 0.3  # the disk's radius in SCENE
RHO = 0.05  # the link's radius


def _setup() -> tuple[Scene, HandKinematics, GraspState]:
    scene = load_scene(SCENE)
    hand = HandKinematics.from_scene(scene)
    return scene, hand, state_from_scene(scene, hand)


def solve_object(man: ContactManifold, q: np.ndarray, dtheta: float, tol: float = 1e-12) -> np.ndarray:
    """The object displacement ``s`` ``(3,)`` with the hand held at ``q`` and the disk turned by
    ``dtheta``: Newton on the 2 contact rows plus ``s_theta = dtheta`` (3 equations, 3 unknowns)."""
    s = np.array([0.0, 0.0, dtheta])
    for _ in range(50):
        x = np.concatenate([q, s])
        F = np.r_[man.function(x)[: man.contact_rows], s[2] - dtheta]
        if float(np.linalg.norm(F)) < tol:
            return s
        J = np.vstack([man.jacobian(x)[: man.contact_rows, man.M:], [0.0, 0.0, 1.0]])
        s = s - np.linalg.solve(J, F)
    raise AssertionError(f"no solution for dtheta = {dtheta}: |F| = {np.linalg.norm(F):.3g}")


def test_rolling_rows_jacobian_and_tangent_space() -> None:
    """F'(x) equals central differences; at s = 0 the tangent space is the glued point's (both
    say: the two material points have equal velocities), which test_manifold ties to null(A_c)."""
    scene, hand, st = _setup()
    roll = ContactManifold(hand, st, [0], scene=scene, rolling=True)
    glued = ContactManifold(hand, st, [0])
    assert len(roll.rolls) == 1 and not roll.items
    x0 = np.concatenate([st.q, np.zeros(3)])
    assert float(np.linalg.norm(roll.function(x0))) < 1e-12
    rng = np.random.default_rng(11)
    for _ in range(3):
        x = x0 + 0.05 * rng.standard_normal(len(x0))
        Jn = np.column_stack([(roll.function(x + e) - roll.function(x - e)) / 2e-6 for e in 1e-6 * np.eye(len(x))])
        np.testing.assert_allclose(roll.jacobian(x), Jn, atol=1e-6)
    Nr, Ng = null_space(roll.jacobian(x0)), null_space(glued.jacobian(x0))
    assert Nr.shape[1] == Ng.shape[1] == 2
    np.testing.assert_allclose(Nr @ Nr.T, Ng @ Ng.T, atol=1e-7)


def test_rolling_jacobian_on_the_side_and_round_the_end_cap() -> None:
    """The rolling rows' Jacobian (analytic: the foot parameter, the gap and the angles of the
    centre's offset and of the axis) equals central differences (h = 1e-6, no angle wrap in
    between) with the disk on the link's side (the foot inside the axis) and rolled past its end
    round the cap (the foot held at the end, dt = 0), at random hand configurations."""
    scene, hand, st = _setup()
    roll = ContactManifold(hand, st, [0], scene=scene, rolling=True)
    cap = solve_object(roll, st.q, -4.0)  # rolled 1.2 along the side: past the end at x = 1
    rng = np.random.default_rng(5)
    checked = {"side": 0, "cap": 0}
    for s0 in (np.zeros(3), np.array([0.2, 0.0, -0.7]), cap):
        for _ in range(10):
            x = np.concatenate([st.q, s0]) + 0.02 * rng.standard_normal(hand.M + 3)
            a, b = hand.body_segment(roll.rolls[0][1], x[: hand.M])
            c = roll.pose(x[hand.M:]).position
            t = float((c - a) @ (b - a)) / float((b - a) @ (b - a))
            checked["side" if 0.0 < t < 1.0 else "cap"] += 1
            Jn = np.column_stack([(roll.function(x + e) - roll.function(x - e)) / 2e-6 for e in 1e-6 * np.eye(len(x))])
            np.testing.assert_allclose(roll.jacobian(x), Jn, rtol=0, atol=1e-7)
    assert checked["side"] >= 10 and checked["cap"] >= 5


@pytest.mark.parametrize("phi", [0.0, 0.2, -0.35])
@pytest.mark.parametrize("dtheta", [0.05, -0.3, 0.8])
def test_disk_rolls_on_link_side_exactly(phi: float, dtheta: float) -> None:
    """The link turned by ``phi`` about its base, the disk by ``dtheta``: the contact point moves
    along the link by ``-r (dtheta - phi)`` (link frame, disk on the link's left side), the disk's
    centre stays at ``rho + r`` from the link's axis, the contact's point on the disk moves by the
    arc ``r |dtheta - phi|``; the glued point instead sinks the disk into the link by
    ``r (1 - cos(dtheta - phi))`` and keeps the contact where it was."""
    scene, hand, st = _setup()
    ref = hand.resolve_body("arm/0")
    assert ref is not None
    roll = ContactManifold(hand, st, [0], scene=scene, rolling=True)
    q = st.q + phi
    s = solve_object(roll, q, dtheta)
    x = np.concatenate([q, s])
    i, y, p_obj, n_obj = roll.rolling_contact(0, x)
    assert i == 0
    rel = dtheta - phi
    pb0 = hand.to_local(ref, st.world_point(0), st.q)  # (3,) the start contact, link frame
    pb1 = hand.to_local(ref, y, q)
    np.testing.assert_allclose(pb1[0] - pb0[0], -R * rel, atol=1e-9)  # travel along the link
    np.testing.assert_allclose(pb1[1], RHO, atol=1e-9)  # on the link's surface
    pose = roll.pose(s)
    c_link = hand.to_local(ref, pose.position, q)
    np.testing.assert_allclose(c_link[:2], [pb1[0], RHO + R], atol=1e-9)  # centre above the contact
    po0 = st.contacts[0].point_object
    chord = float(np.linalg.norm(p_obj - po0))
    np.testing.assert_allclose(chord, 2 * R * abs(np.sin(rel / 2)), atol=1e-9)  # the arc r |rel| on the disk
    np.testing.assert_allclose(n_obj, -p_obj / R, atol=1e-9)

    glued = ContactManifold(hand, st, [0])
    sg = solve_object(glued, q, dtheta)
    gap = roll.body_distance(ref, glued.pose(sg).position, q)[0] - R
    np.testing.assert_allclose(gap, -R * (1 - np.cos(rel)), atol=1e-9)  # second-order penetration


def test_disk_rolls_round_the_end_cap() -> None:
    """Past the link's end the contact rolls round the cap of radius rho: the centre stays at
    ``rho + r`` from the axis' end and the arcs agree, ``r dbeta = travel on the side + rho psi``
    (``psi`` the angle rolled round the cap), checked from positions, not from the manifold's
    own coordinates."""
    scene, hand, st = _setup()
    ref = hand.resolve_body("arm/0")
    assert ref is not None
    roll = ContactManifold(hand, st, [0], scene=scene, rolling=True)
    dtheta = -4.0  # clockwise: rolls 1.2 along the side (to x = 1.2 > the end at 1.0), then round the cap
    s = solve_object(roll, st.q, dtheta)
    pose = roll.pose(s)
    end = np.array([1.0, 0.0])
    v = pose.position - end
    np.testing.assert_allclose(np.linalg.norm(v), RHO + R, atol=1e-9)
    psi = float(np.arctan2(v[0], v[1]))  # clockwise from straight up: the angle rolled round the cap
    assert psi > 0.05
    side_travel = 1.0  # from x = 0 to the axis end at x = 1
    p_obj = roll.rolling_contact(0, np.concatenate([st.q, s]))[2]
    beta0 = np.arctan2(*st.contacts[0].point_object[:2][::-1])
    beta1 = np.arctan2(p_obj[1], p_obj[0])
    dbeta = (beta1 - beta0 + np.pi) % (2 * np.pi) - np.pi  # the arc on the disk (counter-clockwise)
    # the disk turned by -4 rad absolute: its contact point moved counter-clockwise on it by the
    # arc rolled on the link (side plus cap), 4 - 2 pi wraps: compare modulo 2 pi
    arc = side_travel + RHO * psi
    np.testing.assert_allclose(((R * dbeta - arc) / R + np.pi) % (2 * np.pi) - np.pi, 0.0, atol=1e-9)


def test_rolling_needs_a_planar_disk_or_a_sphere() -> None:
    """Rolling is followed for 2-D disks (on links' sides), 3-D spheres (on fixed bodies' faces,
    tests/planner/test_rolling_3d.py) and 3-D cylinders (tests/planner/test_rolling_cylinder.py):
    a box refuses it, and a sphere's contact on a finger link
    keeps its glued point."""
    box = load_scene(EXAMPLES / "panda_forearm_box.json")
    hand = HandKinematics.from_scene(box)
    with pytest.raises(SceneError, match="2-D disk, 3-D sphere and 3-D cylinder"):
        ContactManifold(hand, state_from_scene(box, hand), [0], scene=box, rolling=True)
    scene = load_scene(EXAMPLES / "sphere_four_finger_palm.json")
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    man = ContactManifold(hand, st, [0, 4], scene=scene, rolling=True)  # f1/2 glued, the palm rolls
    assert len(man.items) == 1 and not man.rolls and [k[0] for k in man.plane_rolls] == [4]


def test_planar_plan_object_motion_rolls_on_link_tips(planar_scene: Scene, motion_step: Any) -> None:
    """The planar example's object motion turns the disk relative to its two sticking links
    (about 0.019 rad) with the contacts at the links' sharp tips (``rho = 0``): there rolling is
    pivoting (no arc on the tip, none on the disk), so the glued points are exact and the rolling
    manifold keeps them; at the end each tip still touches the disk (gap ~ 0)."""
    hand = HandKinematics.from_scene(planar_scene)
    step, sticking, _ = motion_step
    before, t = step.before, step.transition
    man = ContactManifold(hand, before, sticking, scene=planar_scene, rolling=True)
    assert not man.rolls and len(man.items) == len(sticking)
    q1, pose1 = t.q_path[-1], before.pose.displaced(t.object_path[-1] - before.pose.vector())
    for i in sticking:
        ref = hand.resolve_body(before.contacts[i].body)
        assert ref is not None
        a0, b0 = hand.body_segment(ref, before.q)
        a1, b1 = hand.body_segment(ref, q1)
        turn_link = np.arctan2(*(b1 - a1)[:2][::-1]) - np.arctan2(*(b0 - a0)[:2][::-1])
        rel = (t.object_path[-1][2] - t.object_path[0][2]) - turn_link
        assert abs(rel) > 1e-3  # the disk does turn relative to the link
        shape = planar_scene.object.shape
        assert isinstance(shape, Disk)
        gap = man.body_distance(ref, pose1.position, q1)[0] - shape.radius
        assert abs(gap) < 1e-8


def test_one_link_disk_rolls_but_is_not_held_once_the_link_tilts() -> None:
    """Why the rolling plan is planned in the V of two links (test_rolling_plan.py), not here: the
    only object motion of this scene with a torque set (32) lowers the link and the disk together,
    and the planner's state after it has the contact where it rolled (under the disk's centre on
    the tilted link's side, normal through the centre), but a single contact whose force must
    pass through the centre cannot balance the vertical load on a tilted link: no stationary grasp
    (18), so no plan."""
    scene, hand, st = _setup()
    p = plan(scene, Goal(type="displacement", displacement=[0.0, -0.05, 0.0], position_tolerance=0.005,
                         rotation_tolerance="free"))
    assert not p.found
    assert p.rejections.get("no stationary grasp (18) of the new contacts", 0) >= 1
    nodes = GraphNodes(scene, hand, p.goal)
    sa = StateAnalysis.of(scene, st, hand)
    parts, grasp = sa.parts("F"), sa.stationary("F")
    oracle = parts.oracle()
    dr = _direction_candidates(nodes, st, parts, (), sa.summary("F").example_direction)[-1]
    ts = _torque_set(nodes, parts, grasp, oracle, dr)
    assert ts is not None
    motion = integrate_object_motion(nodes.model, st, ts.direction, ts.dq, [0], [], 0.009, check_path=False,
                                     motion_space=parts.ms.Lambda_r_t)
    assert motion is not None
    q1, s1 = motion.q_path[-1], motion.pose_path[-1] - st.pose_vector()
    assert abs(q1[0] - st.q[0]) > 5e-3  # the link tilted
    after = st.with_contacts(rolled_contacts(hand, scene, st, [0], q1, s1), q1).with_pose(st.pose.displaced(s1))
    ref = hand.resolve_body("arm/0")
    assert ref is not None
    pb = after.contacts[0].point_body
    np.testing.assert_allclose(pb[1], RHO, atol=1e-9)  # on the link's side ...
    c_link = hand.to_local(ref, after.position, q1)
    np.testing.assert_allclose(c_link[:2], [pb[0], RHO + R], atol=1e-9)  # ... under the centre
    assert StateAnalysis.of(scene, after, hand).stationary(all_f(after)) is None
