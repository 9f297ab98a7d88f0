"""Whole-arm regrasps, the link laid on a face again (issue 11 item 2, :mod:`planner.link_replace`).

Baxter hugging the box (examples/baxter_hug_box.json) lifts its left forearm off the box, its elbow
kept on it (a link release), and lays the forearm on the box's side again, touching it at another
point, the right arm pinned. Checked independently of the planner's own checks:

* the pinned placement: the right arm's joints are exactly those of the state, the kept elbow
  contact's body point stays at its world point, the forearm's axis ends lie at its radius over
  the face, the new contact point lies on the box's surface (its signed distance through
  :func:`analysis.geometry.object_signed_distance`) inside one face, and its normal is that face's
  normal (central differences of the signed distance: the face's normal cone is that one normal);
* the two steps (release, then contact) verify (:func:`planner.verify.verify_plan`: stationary
  grasp (18) before and after, the path collision-free certified with the elbow touching
  throughout and the forearm on the last segment, the kept contact not moving), and the holding
  torques are within Baxter's URDF effort limits.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from analysis.geometry import object_signed_distance
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Scene
from analysis.torque_limits import hand_torque_limits
from planner import Goal, plan
from planner.graph import ContactStateGraph
from planner.link_replace import (
    face_targets,
    first_valid,
    kept_contacts,
    place_link_pinned,
    replace_edges,
    replace_links,
)
from planner.plan import Plan, PlanStep
from planner.state import GraspState, all_f, state_from_scene, state_scene
from planner.verify import verify_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TOL = 1e-9  # m: equation residuals of the placement


@pytest.fixture(scope="module")
def baxter() -> Scene:
    return load_scene(EXAMPLES / "baxter_hug_box.json")


@pytest.fixture(scope="module")
def released(baxter: Scene) -> tuple[ContactStateGraph, Plan, GraspState]:
    """The graph of a search and the plan that lifts the left forearm off (FDFFFF), its end state."""
    p = plan(baxter, Goal(type="combination", combination="FDFFFF"))
    assert p.found, p.reason
    hand = HandKinematics.from_scene(baxter)
    g = ContactStateGraph(baxter, hand, p.goal)
    after = p.steps[-1].after
    g.add(after)
    return g, p, after


def _inward_normal(scene: Scene, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    grad = np.array([(object_signed_distance(scene, x + h * e) - object_signed_distance(scene, x - h * e)) / (2 * h)
                     for e in np.eye(3)])
    return -grad / np.linalg.norm(grad)


def test_pinned_placement_keeps_the_other_arm_and_the_elbow(baxter: Scene, released) -> None:  # type: ignore[no-untyped-def]
    g, _, state = released
    hand = g.hand
    forearm = hand.resolve_body("left/left_upper_forearm")
    assert replace_links(g, state, 0) == [forearm]
    assert replace_links(g, state, 1) == []  # the right arm touches with every link it touched
    kept = kept_contacts(g, state, 0)
    assert [k.ref.name for k in kept] == ["left/left_lower_elbow"]
    found = 0
    for target in face_targets(g, state, 0):
        pl = place_link_pinned(g, state, 0, forearm, target) or place_link_pinned(g, state, 0, forearm, target,
                                                                                    over_point=False)
        if pl is None:
            continue
        found += 1
        right = hand.finger_slice(1)
        np.testing.assert_array_equal(pl.q[right], state.q[right])  # the holding arm is pinned
        i = next(i for i, c in enumerate(state.contacts) if c.body == "left/left_lower_elbow")
        x_elbow = hand.point_position(kept[0].ref, state.contacts[i].point_body, pl.q)
        assert float(np.linalg.norm(x_elbow - state.world_point(i))) <= TOL
        a, b = hand.body_segment(forearm, pl.q)
        r = hand.body_radius(forearm)
        for e in (a, b):  # the forearm lies flat on the face plane
            assert abs(float(target.n @ (np.asarray(e) - target.p)) - r) <= TOL
        x = hand.point_position(forearm, pl.point_body, pl.q)
        sc = state_scene(baxter, state, hand)
        assert abs(float(object_signed_distance(sc, x))) <= 1e-9
        n_in = _inward_normal(sc, x)
        np.testing.assert_allclose(n_in, -target.n, rtol=0, atol=1e-6)  # the face's normal cone is -n_in
    assert found >= 1


@pytest.fixture(scope="module")
def relaid(baxter: Scene, released) -> tuple[Plan, object, object]:  # type: ignore[no-untyped-def]
    """The release plan with the re-placement appended, the edge and its validation."""
    g, p, state = released
    edges = replace_edges(g, state)
    assert edges
    done = first_valid(edges)
    assert done is not None, g.rejections
    e, (cost, t) = done
    new = g.states[e.node]
    held = g.analysis(new).stationary(all_f(new))
    assert held is not None
    full = replace(p, steps=(*p.steps, PlanStep(len(p.steps), t, state, new)), final_contacts=new.bodies(),
                   final_combination=all_f(new), cost=p.cost + cost, final_tau=np.asarray(held.tau))
    return full, e, done[1]


def test_baxter_lays_its_forearm_on_the_box_again_and_the_plan_verifies(baxter: Scene, released, relaid) -> None:  # type: ignore[no-untyped-def]
    g, p, state = released
    hand = g.hand
    full, e, (cost, t) = relaid
    steps = list(p.steps)
    assert t.kind == "contact"
    assert cost == pytest.approx(t.cost)
    new = g.states[e.node]
    assert "left/left_upper_forearm" in new.bodies()
    old = next(c for c in steps[0].before.contacts if c.body == "left/left_upper_forearm")
    made = next(c for c in new.contacts if c.body == "left/left_upper_forearm")
    assert float(np.linalg.norm(made.point_object - old.point_object)) > 0.01  # at another point
    # only the left arm moves, the object stays
    right = hand.finger_slice(1)
    np.testing.assert_array_equal(t.q_path[:, right], np.tile(state.q[right], (len(t.q_path), 1)))
    np.testing.assert_array_equal(t.object_path, np.tile(state.pose_vector(), (len(t.q_path), 1)))
    assert [s.transition.kind for s in full.steps] == ["release", "contact"]
    assert verify_plan(baxter, full) == []
    limits = hand_torque_limits(baxter, hand)
    assert limits is not None
    held = g.analysis(new).stationary(all_f(new))
    assert held is not None
    for tau in (t.tau_stationary, held.tau):
        assert tau is not None
        assert np.all(np.abs(np.asarray(tau)) <= limits + 1e-9)


def test_link_replacement_is_off_by_default(baxter: Scene) -> None:
    hand = HandKinematics.from_scene(baxter)
    g = ContactStateGraph(baxter, hand, Goal(type="active"))
    assert not g.options.link_replacement
    st = state_from_scene(baxter, hand)
    g.add(st)
    assert all(s.data is None or s.data.kind != "contact" or "forearm" not in str(s.data.contacts_after)
               for s in g.successors(st.key()))


def test_the_kept_elbow_moving_is_caught_by_verify(baxter: Scene, relaid) -> None:  # type: ignore[no-untyped-def]
    """The check of a finger's kept contacts in verify_plan can fail: the contact step's path with
    the left shoulder turned by 1e-3 rad at its inner waypoints moves the kept elbow."""
    full, _, _ = relaid
    step = full.steps[-1]
    q = step.transition.q_path.copy()
    q[1:-1, 0] += 1e-3
    bad = replace(full, steps=(full.steps[0], replace(step, transition=replace(step.transition, q_path=q))))
    problems = verify_plan(baxter, bad)
    assert any("kept contact" in m and "left_lower_elbow" in m for m in problems), problems


def test_the_release_and_re_placement_replay_in_mujoco(baxter: Scene, relaid) -> None:  # type: ignore[no-untyped-def]
    """One continuous MuJoCo replay (sim.plan_replay) of the release and the re-placement: the box
    is not dropped and stays within the replay's tolerance of where it was (the plan does not move
    it: the error is relative to the replay's floor scale, ``min_radius``), the box within 0.1 mm of
    its start, the left arm ends at the contact configuration within 0.01 rad."""
    from sim.plan_replay import simulate_plan

    full, _, _ = relaid
    rep = simulate_plan(baxter, full)
    js = rep.to_json()
    assert rep.ok and not rep.dropped, js
    assert js["relative_position_error"] <= 0.05 and js["relative_rotation_error"] <= 0.05, js
    assert js["position_error"] <= 1e-4, js  # m: the box stays where it was
    assert [s.kind for s in rep.steps] == ["release", "contact"]
    assert rep.steps[-1].joint_error <= 0.01


def test_a_free_arm_lays_its_forearm_over_a_face_point(baxter: Scene, released) -> None:  # type: ignore[no-untyped-def]
    """Without kept contacts the pinned placement lays the forearm over the target point itself (a
    new configuration): the left arm's contacts dropped from the released state, every placement
    found keeps the right arm's joints, touches the face at the target point (residual 1e-9 m),
    lies flat on it and differs from the arm's configuration."""
    g, _, state = released
    hand = g.hand
    free = state.with_contacts(tuple(c for c in state.contacts if not c.body.startswith("left/")), state.q)
    assert kept_contacts(g, free, 0) == []
    forearm = hand.resolve_body("left/left_upper_forearm")
    sc = state_scene(baxter, free, hand)
    right, left = hand.finger_slice(1), hand.finger_slice(0)
    found = 0
    for target in face_targets(g, free, 0):
        pl = place_link_pinned(g, free, 0, forearm, target)
        if pl is None:
            continue
        found += 1
        assert pl.over_point
        np.testing.assert_array_equal(pl.q[right], free.q[right])
        x = hand.point_position(forearm, pl.point_body, pl.q)
        assert float(np.linalg.norm(x - target.p)) <= 1e-8
        assert abs(float(object_signed_distance(sc, x))) <= 1e-9
        np.testing.assert_allclose(_inward_normal(sc, x), -target.n, rtol=0, atol=1e-6)
        r = hand.body_radius(forearm)
        for e in hand.body_segment(forearm, pl.q):
            assert abs(float(target.n @ (np.asarray(e) - target.p)) - r) <= TOL
        assert float(np.linalg.norm(pl.q[left] - free.q[left])) > 1e-3
    assert found >= 2


def test_the_graph_expands_re_placements_with_the_option(baxter: Scene, released) -> None:  # type: ignore[no-untyped-def]
    """With ``link_replacement`` the graph's successors of the released state include the lazy
    re-placement of the forearm (a new node with the forearm touching); without it they do not."""
    from planner.options import PlannerOptions

    _, p, state = released
    hand = HandKinematics.from_scene(baxter)
    found = {}
    for on in (False, True):
        g = ContactStateGraph(baxter, hand, p.goal, PlannerOptions(link_replacement=on))
        g.add(state)
        succ = g.successors(state.key())
        found[on] = [s for s in succ if s.validate is not None
                     and "left/left_upper_forearm" in g.states[s.node].bodies()]
    assert found[False] == []
    assert len(found[True]) == 1
