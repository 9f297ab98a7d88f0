"""The Allegro right hand (URDF fingers evaluated by pinocchio) holding a bar: numeric IK within
the joint limits, start overlaps, and plans whose every step passes the independent re-check of
planner/verify.py.

Active closure is out of reach for this grasp (see docs/theory.md, "Planner on the Allegro
example"): the planned goal is the regrasp from the power grasp to a fingertip grasp on the palm
(``fingertips``), and the ``active`` goal ends with a clear no-path result."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import EXAMPLES

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from planner import plan
from planner.collision import CollisionModel
from planner.goals import Goal
from planner.graph import ContactStateGraph
from planner.ik import joint_limits, numeric_ik
from planner.plan import PlanStep
from planner.state import state_from_scene
from planner.verify import verify_plan, verify_step


@pytest.fixture(scope="module")
def allegro():  # type: ignore[no-untyped-def]
    scene = load_scene(EXAMPLES / "allegro_right_box.json")
    hand = HandKinematics.from_scene(scene)
    return scene, hand, state_from_scene(scene, hand)


def test_numeric_ik_reaches_a_reachable_tip_within_limits(allegro) -> None:  # type: ignore[no-untyped-def]
    _, hand, st = allegro
    f = 1  # middle
    sl = hand.finger_slice(f)
    chain = hand.fingers[f]
    lo, hi = joint_limits(hand, f)
    assert np.all(np.isfinite(lo)) and np.all(lo < hi)
    q_goal = np.clip(st.q[sl] + np.array([0.1, -0.3, -0.2, 0.1]), lo, hi)
    a, b = chain.body_segment(chain.n_joints - 1, q_goal)
    u = (b - a) / np.linalg.norm(b - a)
    x = numeric_ik(hand, f, b, u, st.q[sl], min_alignment=0.9)
    assert x is not None
    a2, b2 = chain.body_segment(chain.n_joints - 1, x)
    np.testing.assert_allclose(b2, b, atol=1e-8)
    assert (b2 - a2) @ u / np.linalg.norm(b2 - a2) >= 0.9 - 1e-9
    assert np.all(x >= lo) and np.all(x <= hi)
    # out of reach: no solution (not an exception)
    assert numeric_ik(hand, f, b + np.array([0.0, 0.0, 1.0]), u, st.q[sl]) is None


def test_start_overlaps_are_allowed_but_may_not_grow(allegro) -> None:  # type: ignore[no-untyped-def]
    scene, hand, st = allegro
    model = CollisionModel.of(scene, hand)
    f = 3  # the thumb's capsules overlap slightly at the start
    assert model.finger_clearance(f, st.q, st.position, st.rotation) < 0.0
    allow = model.start_allowance(f, st.q, st.position, st.rotation)
    assert model.finger_clearance(f, st.q, st.position, st.rotation, (), allow) >= 0.0
    # some joint motion of the thumb deepens an overlap: rejected even with the allowance
    sl = hand.finger_slice(f)
    worse = []
    for k in range(sl.start, sl.stop):
        for step in (-0.2, 0.2):
            q = st.q.copy()
            q[k] += step
            worse.append(model.finger_clearance(f, q, st.position, st.rotation, (), allow))
    assert min(worse) < 0.0


@pytest.mark.slow
def test_allegro_regrasp_steps_pass_the_analysis(allegro) -> None:  # type: ignore[no-untyped-def]
    scene, hand, st = allegro
    g = ContactStateGraph(scene, hand, Goal(type="active"))
    g.add(st)
    releases = g.release_edges(st)
    assert releases
    checked = 0
    for t_rel, released in releases:
        assert verify_step(scene, hand, PlanStep(0, t_rel, st, released)) == []
        for succ in g.contact_edges(released):
            assert succ.validate is not None
            got = succ.validate()
            if got is None:
                continue
            _, t_con = got
            after = g.states[succ.node]
            assert t_con.kind == "contact" and len(after.contacts) == len(released.contacts) + 1
            assert verify_step(scene, hand, PlanStep(1, t_con, released, after)) == []
            checked += 1
            break
    assert checked >= 1


@pytest.mark.slow
def test_allegro_plan_to_a_fingertip_grasp_passes_the_analysis(allegro) -> None:  # type: ignore[no-untyped-def]
    scene, _, _ = allegro
    p = plan(scene, Goal(type="fingertips"), time_limit=120.0)
    assert p.found, p.reason
    kinds = [s.transition.kind for s in p.steps]
    assert kinds.count("contact") == 3 and kinds.count("release") == 3  # index, middle, ring regrasp
    finger_contacts = [b for b in p.final_contacts if b != "palm"]
    assert sorted(b.split("/")[0] for b in finger_contacts) == ["index", "middle", "ring", "thumb"]
    assert {"index/link_3.0", "middle/link_7.0", "ring/link_11.0", "thumb/link_15.0_tip"} == set(finger_contacts)
    assert verify_plan(scene, p) == []


@pytest.mark.slow
def test_allegro_active_closure_is_a_clear_no_path(allegro) -> None:  # type: ignore[no-untyped-def]
    scene, _, _ = allegro
    p = plan(scene, Goal(type="active"), time_limit=120.0)
    assert not p.found
    assert "expanded without reaching the goal" in p.reason and "no stationary grasp (18)" in p.reason
