"""A goal reached through a link's re-placement (issue 11 item 2, :mod:`planner.link_replace`).

Baxter hugging the box (examples/baxter_hug_box.json) is asked to touch the box with its left
forearm 5 cm further along the forearm's line (a ``contact`` goal, ``link_replacement``): the search
lifts the forearm off (a link release, the elbow kept) and lays it back with its contact at the
point of its side nearest the goal's point. Checked independently of the planner's own checks:

* the goal's point as a face target (:func:`planner.link_replace.goal_target`): on the face plane
  of the box (y = 0.2), none for a point off that plane beyond the tolerance, for another link or
  another goal;
* the contact made lies on the forearm's side (its distance from the forearm's axis is the
  radius), the goal's point is across the axis from it (no component along the axis: the nearest
  point), and within the goal's tolerance;
* the plan verifies (:func:`planner.verify.verify_plan`), its MuJoCo replay keeps the box where it
  was (within the replay's tolerance, not dropped) and the left arm ends at the planned
  configuration; without ``link_replacement`` the same search finds no plan.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Scene
from planner import Goal, plan
from planner.graph import ContactStateGraph
from planner.link_replace import first_valid, goal_target, replace_edges
from planner.options import PlannerOptions
from planner.state import GraspState, state_from_scene
from planner.verify import verify_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
FOREARM = "left/left_upper_forearm"
ALONG = 0.05  # m: the goal's point this far along the forearm's axis (towards the elbow) from its contact
ACROSS = 3e-4  # m: and this far across the axis in the face plane (within the default tolerance, 3.2 mm)


@pytest.fixture(scope="module")
def baxter() -> Scene:
    return load_scene(EXAMPLES / "baxter_hug_box.json")


def _goal_point(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """The goal's point (world) and the forearm's unit axis at the start, from the scene alone."""
    hand = HandKinematics.from_scene(scene)
    start = state_from_scene(scene, hand)
    i = next(i for i, c in enumerate(start.contacts) if c.body == FOREARM)
    a, b = (np.asarray(e, dtype=float) for e in hand.body_segment(hand.resolve_body(FOREARM), start.q))
    u = (b - a) / np.linalg.norm(b - a)
    u = -u if u[2] < 0 else u  # towards the elbow (up)
    n = np.array([0.0, 1.0, 0.0])  # the box's +y face
    assert abs(float(u @ n)) < 1e-9  # the forearm lies flat on it
    return start.world_point(i) + ALONG * u + ACROSS * np.cross(n, u), u


@pytest.fixture(scope="module")
def released(baxter: Scene) -> tuple[ContactStateGraph, GraspState, Goal]:
    """A graph searching towards the contact goal, and the state with the left forearm lifted off."""
    p = plan(baxter, Goal(type="combination", combination="FDFFFF"))
    assert p.found, p.reason
    point, _ = _goal_point(baxter)
    goal = Goal(type="contact", body=FOREARM, point=point.tolist())
    hand = HandKinematics.from_scene(baxter)
    g = ContactStateGraph(baxter, hand, goal, PlannerOptions(link_replacement=True))
    state = p.steps[-1].after
    g.add(state)
    return g, state, goal


def test_the_goal_point_is_a_face_target_only_for_its_link(baxter: Scene, released) -> None:  # type: ignore[no-untyped-def]
    g, state, goal = released
    hand = g.hand
    forearm, elbow = hand.resolve_body(FOREARM), hand.resolve_body("left/left_lower_elbow")
    t = goal_target(g, state, forearm)
    assert t is not None
    np.testing.assert_allclose(t.n, [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(t.p, goal.point, atol=1e-12)  # already on the face plane y = 0.2
    assert goal_target(g, state, elbow) is None  # another link
    off = np.asarray(goal.point) + np.array([0.0, 0.01, 0.0])  # 1 cm off the face: beyond 3.2 mm
    for other in (Goal(type="contact", body=FOREARM, point=off.tolist()), Goal(type="active")):
        g2 = ContactStateGraph(baxter, hand, other, PlannerOptions(link_replacement=True))
        assert goal_target(g2, state, forearm) is None
    near = np.asarray(goal.point) + np.array([0.0, 0.002, 0.0])  # 2 mm off: projected onto the face
    g3 = ContactStateGraph(baxter, hand, Goal(type="contact", body=FOREARM, point=near.tolist()),
                           PlannerOptions(link_replacement=True))
    t3 = goal_target(g3, state, forearm)
    assert t3 is not None
    np.testing.assert_allclose(t3.p, goal.point, atol=1e-12)


def test_the_re_placement_touches_nearest_the_goal_point(baxter: Scene, released) -> None:  # type: ignore[no-untyped-def]
    g, state, goal = released
    hand = g.hand
    done = first_valid(replace_edges(g, state))
    assert done is not None, g.rejections
    edge, (_, t) = done
    new = g.states[edge.node]
    i = next(i for i, c in enumerate(new.contacts) if c.body == FOREARM)
    x = new.world_point(i)
    ref = hand.resolve_body(FOREARM)
    a, b = (np.asarray(e, dtype=float) for e in hand.body_segment(ref, new.q))
    u = (b - a) / np.linalg.norm(b - a)
    on_axis = a + float((x - a) @ u) * u
    assert abs(float(np.linalg.norm(x - on_axis)) - hand.body_radius(ref)) <= 1e-9  # on the forearm's side
    G = np.asarray(goal.point)
    assert abs(float((G - x) @ u)) <= 1e-6  # the nearest point of the side: G is across the axis from x
    assert float(np.linalg.norm(G - x)) <= goal.position_tol(g.size)
    assert abs(float(x[1]) - 0.2) <= 1e-9  # on the +y face
    old = next(c for c in state.contacts if c.body == "left/left_lower_elbow")
    assert new.contacts[0].body == old.body  # the elbow kept
    assert t.kind == "contact"


@pytest.mark.slow
def test_a_contact_goal_is_reached_by_release_and_re_placement(baxter: Scene) -> None:
    """The search finds the plan itself (release, re-placement), it verifies and replays in MuJoCo;
    without ``link_replacement`` the search finds none in 4 expansions."""
    from sim.plan_replay import simulate_plan

    point, _ = _goal_point(baxter)
    goal = Goal(type="contact", body=FOREARM, point=point.tolist())
    p = plan(baxter, goal, options=PlannerOptions(link_replacement=True), max_expansions=6)
    assert p.found, p.reason
    assert [s.transition.kind for s in p.steps] == ["release", "contact"]
    last = p.steps[-1].after
    i = next(i for i, c in enumerate(last.contacts) if c.body == FOREARM)
    assert float(np.linalg.norm(last.world_point(i) - point)) <= goal.position_tol(object_size(baxter))
    assert float(np.linalg.norm(last.world_point(i) - point)) >= 0.9 * ACROSS  # not closer than the line lets it
    assert verify_plan(baxter, p) == []
    rep = simulate_plan(baxter, p)
    js = rep.to_json()
    assert rep.ok and not rep.dropped, js
    assert js["position_error"] <= 1e-4, js  # m: the box stays where it was
    assert [s.kind for s in rep.steps] == ["release", "contact"]
    assert rep.steps[-1].joint_error <= 0.01
    assert not plan(baxter, goal, max_expansions=4).found


@pytest.mark.slow
def test_a_point_off_the_forearm_s_line_is_reached_through_the_elbow_s_slide(baxter: Scene) -> None:
    """With slides as well, a point 2.2 cm off the forearm's line (on the +y face) is reached by a
    whole-arm regrasp: the forearm lifted off, the elbow slid up the face, the forearm laid on a new
    line through the point; the plan verifies and replays in MuJoCo, the box still. The point is
    where the forearm lies after the elbow's slide up (+z) found without the goal."""
    from sim.plan_replay import simulate_plan

    start_point, u = _goal_point(baxter)
    point = np.array([0.60596, 0.2, 1.01061])
    n = np.array([0.0, 1.0, 0.0])
    start_contact = start_point - ALONG * u - ACROSS * np.cross(n, u)
    off_line = float(np.cross(n, u) @ (point - start_contact))
    assert abs(off_line) > 0.02  # m: not on the forearm's line at the start (the re-placement alone cannot)
    goal = Goal(type="contact", body=FOREARM, point=point.tolist())
    p = plan(baxter, goal, options=PlannerOptions(link_replacement=True, contact_slides=True), max_expansions=30)
    assert p.found, p.reason
    assert [s.transition.kind for s in p.steps] == ["release", "slide", "contact"]
    assert p.steps[1].transition.figures.body == "left/left_lower_elbow"  # type: ignore[union-attr]
    last = p.steps[-1].after
    i = next(i for i, c in enumerate(last.contacts) if c.body == FOREARM)
    assert float(np.linalg.norm(last.world_point(i) - point)) <= goal.position_tol(object_size(baxter))
    assert verify_plan(baxter, p) == []
    rep = simulate_plan(baxter, p)
    js = rep.to_json()
    assert rep.ok and not rep.dropped, js
    assert js["position_error"] <= 1e-4, js
    assert rep.steps[1].slide_error is not None and rep.steps[1].slide_error <= 0.05
