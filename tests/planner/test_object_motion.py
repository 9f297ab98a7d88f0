"""Object motions: integrated on the contact manifold, then planned by OMPL's constrained planning."""

from __future__ import annotations

import numpy as np

from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from planner.collision import DENSE_STEP, CollisionModel
from planner.object_motion import ObjectMotion, integrate_object_motion, moved, plan_object_motion


def test_object_motion_stays_on_the_contact_manifold(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    """The lift of the planar plan: at every waypoint the sticking contacts coincide (A_c [dq; dr]
    = 0 integrated and projected) and the palm contact has separated at the end."""
    hand = HandKinematics.from_scene(planar_scene)
    step = next(s for s in planar_plan.steps if s.transition.kind == "object_motion")
    t, before = step.transition, step.before
    sticking = [i for i, ch in enumerate(t.combination) if ch == "F"]
    assert sticking and "D" in t.combination
    for q, pose in zip(t.q_path, t.object_path, strict=True):
        st = moved(before, pose - before.pose_vector())
        for i in sticking:
            c = before.contacts[i]
            ref = hand.resolve_body(c.body)
            assert ref is not None
            np.testing.assert_allclose(hand.point_position(ref, c.point_body, q), st.world_point(i), atol=1e-6)
    assert np.all(np.asarray(t.figures.separations) > 0)
    assert t.object_path[-1][1] > t.object_path[0][1]  # lifted off the palm


def test_ompl_object_motion_is_on_the_manifold_and_collision_free(planar_scene: Scene, motion_step) -> None:  # type: ignore[no-untyped-def]
    """The lift planned by OMPL's constrained planning: ends where the analysis says, every state
    on the manifold, joint steps at most DENSE_STEP, and every state collision-free when checked
    independently."""
    hand = HandKinematics.from_scene(planar_scene)
    model = CollisionModel.of(planar_scene, hand)
    step, sticking, separating = motion_step
    t, before = step.transition, step.before
    assert t.figures.ompl_planner_states >= 2 and t.figures.manifold_residual < 1e-6
    assert np.max(np.abs(np.diff(t.q_path, axis=0))) <= DENSE_STEP + 1e-12
    straight = integrate_object_motion(model, before, np.asarray(t.torque_set["direction"]),
                                       np.asarray(t.torque_set["dq"]), sticking, separating,
                                       float(np.linalg.norm(t.object_path[-1] - t.object_path[0])), check_path=False)
    assert straight is not None
    om = plan_object_motion(model, before, straight, sticking, separating)
    assert om is not None
    np.testing.assert_allclose(om.q_path[0], before.q, atol=1e-12)
    np.testing.assert_allclose(om.q_path[-1], straight.q_path[-1], atol=1e-9)
    np.testing.assert_allclose(om.pose_path[-1], straight.pose_path[-1], atol=1e-9)
    assert om.max_joint_step <= DENSE_STEP and om.max_residual < 1e-6
    touching = [hand.resolve_body(before.contacts[i].body) for i in (*sticking, *separating)]
    allow = [model.start_allowance(f, before.q, before.position, before.rotation) for f in range(len(hand.fingers))]
    for q, pose in zip(om.q_path, om.pose_path, strict=True):
        st = moved(before, pose - before.pose_vector())
        for f in range(len(hand.fingers)):
            mine = [b for b in touching if b is not None and b.finger == f]
            assert model.finger_clearance(f, q, st.position, st.rotation, mine, allow[f]) >= -1e-9


def test_ompl_object_motion_refuses_a_colliding_goal(planar_scene: Scene, motion_step) -> None:  # type: ignore[no-untyped-def]
    """A goal configuration with a link through the object has no valid path: None, not a path."""
    hand = HandKinematics.from_scene(planar_scene)
    model = CollisionModel.of(planar_scene, hand)
    step, sticking, separating = motion_step
    before = step.before
    f0 = 0  # finger 0 lets go (its contacts leave the manifold) and ends with link 0 through the disk
    keep = [i for i in sticking if (r := hand.resolve_body(before.contacts[i].body)) is None or r.finger != f0]
    assert 0 < len(keep) < len(sticking)
    q_bad = before.q.copy()
    q_bad[hand.finger_slice(f0)] = [1.0, 0.0]
    goal = ObjectMotion(np.array([before.q, q_bad]), np.array([before.pose_vector()] * 2), np.ones(len(separating)),
                        0.0, 0.0)
    assert model.finger_clearance(f0, q_bad, before.position, before.rotation) < 0.0
    assert plan_object_motion(model, before, goal, keep, separating) is None
    q_ok = before.q.copy()  # the same motion without the collision is planned
    goal_ok = ObjectMotion(np.array([before.q, q_ok]), goal.pose_path, goal.separations, 0.0, 0.0)
    assert plan_object_motion(model, before, goal_ok, keep, separating) is not None


def test_object_motion_edges_are_lazy_with_a_lower_bound(planar_scene: Scene, planar_plan, motion_step) -> None:  # type: ignore[no-untyped-def]
    """Expanding the state before the planar plan's lift gives its object motion as a lazy edge: the
    node (the integration's end) is known before OMPL plans, the bound (straight joint and object
    distances to that end, plus the effort) is below the cost the validation finds and within 1 %
    of it for this straight lift, and the validated transition is the plan's step (same paths,
    same cost)."""
    from planner.goals import Goal
    from planner.graph import ContactStateGraph

    step, _, _ = motion_step
    hand = HandKinematics.from_scene(planar_scene)
    g = ContactStateGraph(planar_scene, hand, Goal(type="active"))
    succ = [s for s in g.object_motion_edges(step.before) if g.states[s.node].bodies() == step.after.bodies()]
    assert len(succ) == 1 and succ[0].validate is not None
    s = succ[0]
    assert s.node not in g.validated and s.node == step.after.key()
    got = s.validate()
    assert got is not None
    cost, t = got
    assert s.cost <= cost and cost - s.cost < 0.01 * cost
    assert cost == step.transition.cost
    np.testing.assert_array_equal(t.q_path, step.transition.q_path)
    np.testing.assert_array_equal(t.object_path, step.transition.object_path)
    assert s.node in g.validated
    # the straight distances: the joint path and the object path each at least that long
    jl = float(np.sum(np.linalg.norm(np.diff(t.q_path, axis=0), axis=1)))
    assert jl >= float(np.linalg.norm(t.q_path[-1] - t.q_path[0]))
