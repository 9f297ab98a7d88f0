"""Rolling in the planner (issue 11 item 1): a disk held in the V of two links
(examples/planar_disk_rolling_v.json) is moved 3 cm to the left; its only motion rolls it on both
links (motion space of dimension 1), so the object motions follow the rolling manifold
(ContactManifold(rolling=True)), each state after a motion carries the rolled contacts (new point
on each link and on the disk), verify_plan re-checks the rolling kinematics from the positions,
and the plan file round-trips them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from closure_helpers import EXAMPLES

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Scene
from planner import Goal, plan
from planner.object_motion import motion_manifold, rolled_contacts, rolls_on_links
from planner.plan import Plan, PlanStep
from planner.state import GraspState, state_from_scene
from planner.verify import ROLL_TOL, verify_plan

SCENE = EXAMPLES / "planar_disk_rolling_v.json"
R, RHO = 0.3, 0.05  # the disk's and the links' radii in SCENE
GOAL = Goal(type="displacement", displacement=[-0.03, 0.0, 0.0], position_tolerance=0.003,
            rotation_tolerance="free")


@pytest.fixture(scope="module")
def v_scene() -> Scene:
    return load_scene(SCENE)


@pytest.fixture(scope="module")
def v_plan(v_scene: Scene) -> Plan:
    p = plan(v_scene, GOAL)
    assert p.found, p.reason
    return p


def _link_frame_x(hand: HandKinematics, state: GraspState, i: int) -> float:
    """Where contact ``i`` of ``state`` is along its link's axis (link frame ``x``)."""
    ref = hand.resolve_body(state.contacts[i].body)
    assert ref is not None
    return float(hand.to_local(ref, state.world_point(i), state.q)[0])


def _link_angle(hand: HandKinematics, state: GraspState, i: int) -> float:
    ref = hand.resolve_body(state.contacts[i].body)
    assert ref is not None
    a, b = hand.body_segment(ref, state.q)
    return float(np.arctan2(b[1] - a[1], b[0] - a[0]))


def test_v_scene_contacts_roll_on_the_links_sides(v_scene: Scene) -> None:
    hand = HandKinematics.from_scene(v_scene)
    st = state_from_scene(v_scene, hand)
    assert rolls_on_links(v_scene)
    man = motion_manifold(v_scene, hand, st, [0, 1])
    assert [k[0] for k in man.rolls] == [0, 1] and not man.items  # both on a side: no glued rows
    assert not rolls_on_links(load_scene(EXAMPLES / "sphere_four_finger_palm.json"))  # 3-D: out of scope


def test_rolling_plan_is_found_verified_and_reaches_the_goal(v_scene: Scene, v_plan: Plan) -> None:
    """Every step is an FF object motion; the plan ends within the goal's 3 mm of 3 cm to the left,
    and verify_plan (which re-checks the rolling kinematics) finds no problem."""
    assert all(s.transition.kind == "object_motion" and s.transition.combination == "FF" for s in v_plan.steps)
    assert len(v_plan.steps) >= 2  # several motions: each later one starts from the rolled contacts
    d = v_plan.displacement
    assert abs(d[0] + 0.03) <= 0.003 and abs(d[1]) <= 0.003
    assert d[2] > 0.05  # the disk turned counter-clockwise as it rolled to the left
    assert verify_plan(v_scene, v_plan) == []


def test_states_after_the_motions_carry_the_rolled_contacts(v_scene: Scene, v_plan: Plan) -> None:
    """From the states alone: each contact's point on its link moved along the link by ``r`` times
    the disk's turn relative to the link (the left link's contact towards its base, the right
    one's towards its tip: the disk is on the left side of the left link's axis and on the right
    side of the right one's), the disk's centre is ``r + rho`` from both axes, the contact's point
    on the disk turned by the relative turn, and the object normal points from it to the centre."""
    hand = HandKinematics.from_scene(v_scene)
    first, last = v_plan.steps[0].before, v_plan.steps[-1].after
    for i, side in ((0, 1.0), (1, -1.0)):
        turn_link = _link_angle(hand, last, i) - _link_angle(hand, first, i)
        rel = (last.pose_vector()[2] - first.pose_vector()[2]) - turn_link
        travel = _link_frame_x(hand, last, i) - _link_frame_x(hand, first, i)
        assert abs(rel) > 0.05
        np.testing.assert_allclose(travel, -side * R * rel, atol=1e-6)
        ref = hand.resolve_body(last.contacts[i].body)
        assert ref is not None
        c_link = hand.to_local(ref, last.position, last.q)
        np.testing.assert_allclose(abs(c_link[1]), RHO + R, atol=1e-6)
        po0, po1 = first.contacts[i].point_object, last.contacts[i].point_object
        turn = np.arctan2(po1[1], po1[0]) - np.arctan2(po0[1], po0[0])
        np.testing.assert_allclose(turn, -rel, atol=1e-6)  # the touching point moved on the disk by -rel
        np.testing.assert_allclose(last.contacts[i].normal_object, -po1 / R, atol=1e-9)
    for a, b in zip(v_plan.steps, v_plan.steps[1:], strict=False):
        assert a.after.key() == b.before.key()  # the next motion starts from the rolled contacts


def test_rolled_contacts_move_only_the_rolling_ones(v_scene: Scene, v_plan: Plan) -> None:
    """:func:`rolled_contacts` at the end of the first motion gives the planner's state after it;
    with no sticking contacts nothing moves."""
    hand = HandKinematics.from_scene(v_scene)
    step = v_plan.steps[0]
    t = step.transition
    s = t.object_path[-1] - t.object_path[0]
    got = rolled_contacts(hand, v_scene, step.before, [0, 1], t.q_path[-1], s)
    for c, want in zip(got, step.after.contacts, strict=True):
        np.testing.assert_allclose(c.point_body, want.point_body, atol=1e-9)
        np.testing.assert_allclose(c.point_object, want.point_object, atol=1e-9)
    assert rolled_contacts(hand, v_scene, step.before, [], t.q_path[-1], s) == step.before.contacts


def test_rolling_plan_round_trips_through_its_json(v_scene: Scene, v_plan: Plan) -> None:
    data = v_plan.to_json()
    back = Plan.from_json(data, v_scene)
    assert back.to_json() == data
    for a, b in zip(v_plan.steps, back.steps, strict=True):
        for ca, cb in zip(a.after.contacts, b.after.contacts, strict=True):
            np.testing.assert_allclose(cb.point_object, ca.point_object, atol=1e-8)
            np.testing.assert_allclose(cb.point_body, ca.point_body, atol=1e-8)
            np.testing.assert_allclose(cb.normal_object, ca.normal_object, atol=1e-6)
    assert verify_plan(v_scene, back) == []


def _with_step(p: Plan, k: int, step: PlanStep) -> Plan:
    return replace(p, steps=(*p.steps[:k], step, *p.steps[k + 1:]))


def test_verify_rejects_glued_contacts_and_slipping(v_scene: Scene, v_plan: Plan) -> None:
    """A state after a motion that kept the contacts where they were (the glued points) is refused,
    and so is an object path whose disk turns more than it rolls (the centre on the same path)."""
    step = v_plan.steps[0]
    glued = replace(step, after=step.after.with_contacts(step.before.contacts))
    problems = verify_plan(v_scene, _with_step(v_plan, 0, glued))
    assert any("where it rolled" in m for m in problems), problems
    t = step.transition
    path = t.object_path.copy()
    path[:, 2] += np.linspace(0.0, 0.01, len(path))  # 0.01 rad more turn than the rolling gives
    slipping = replace(step, transition=replace(t, object_path=path))
    problems = verify_plan(v_scene, _with_step(v_plan, 0, slipping))
    assert any("slips" in m and f"{0.01 * R:.3g}" in m for m in problems), problems
    assert 0.01 * R > 1e3 * ROLL_TOL
