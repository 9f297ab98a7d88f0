"""Collision model, IK, OMPL transfers (checked every 1 mm of joint motion) and object motion."""

from __future__ import annotations

import numpy as np

from analysis.kinematics import BodyRef, HandKinematics
from analysis.scene import Scene
from planner.ompl_paths import (
    DENSE_STEP,
    CollisionModel,
    _box_segments_distance,
    fingertip_ik,
    plan_transfer,
    segment_segment_distance,
    segment_segment_distances,
)
from planner.state import state_from_scene


def test_segment_distance_matches_sampling() -> None:
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, 401)
    for _ in range(30):
        a0, a1, b0, b1 = rng.normal(size=(4, 3))
        P = a0 + t[:, None] * (a1 - a0)
        Q = b0 + t[:, None] * (b1 - b0)
        brute = np.min(np.linalg.norm(P[:, None] - Q[None], axis=2))
        d = segment_segment_distance(a0, a1, b0, b1)
        assert d <= brute + 1e-12 and d >= brute - 1e-2


def test_vectorised_distances_match_the_scalar_and_dense_ones() -> None:
    rng = np.random.default_rng(1)
    A0, A1, B0, B1 = rng.normal(size=(4, 50, 3))
    A1[:5] = A0[:5]  # degenerate segments (points) on either side
    B1[5:10] = B0[5:10]
    B1[10] = B0[10] = A0[10] = A1[10]
    B0[11], B1[11] = A0[11] + 1.0, A1[11] + 1.0  # parallel
    vec = segment_segment_distances(A0, A1, B0, B1)
    ref = [segment_segment_distance(*x) for x in zip(A0, A1, B0, B1, strict=True)]
    np.testing.assert_allclose(vec, ref, atol=1e-12)
    # box: within step / 2 of the distance sampled every step / 100 (convexity bracket)
    c, h, step = np.array([0.1, -0.2, 0.0]), np.array([0.5, 0.3, 0.05]), 0.01
    got = _box_segments_distance(c, h, A0, A1 * 2.0, step)
    t = np.linspace(0, 1, 20001)
    for i in range(50):
        P = A0[i] + t[:, None] * (A1[i] * 2.0 - A0[i])
        qd = np.abs(P - c) - h
        dense = float(np.min(np.linalg.norm(np.maximum(qd, 0), axis=1) + np.minimum(qd.max(axis=1), 0)))
        assert dense - 1e-12 <= got[i] <= dense + step / 2


def _free_left(planar_scene: Scene):  # type: ignore[no-untyped-def]
    hand = HandKinematics.from_scene(planar_scene)
    st = state_from_scene(planar_scene, hand)
    q = st.q.copy()
    q[:2] = [2.0, 0.3]  # left finger lifted away
    return hand, st.with_contacts(st.contacts[2:], q)


def test_ik_puts_the_tip_on_the_target(planar_scene: Scene) -> None:
    hand, st = _free_left(planar_scene)
    target, normal = np.array([-0.5, 0.5]), np.array([1.0, 0.0])
    sols = fingertip_ik(hand, 0, target, normal, [st.q[:2]])
    assert sols
    q = st.q.copy()
    q[:2] = sols[0]
    a, b = hand.body_segment(BodyRef("left/1", 0, 1), q)
    np.testing.assert_allclose(b, target, atol=1e-7)
    assert (b - a) @ normal / np.linalg.norm(b - a) >= 0.5 - 1e-9


def _dense_check(model: CollisionModel, finger: int, q_full: np.ndarray, path: np.ndarray, st,  # type: ignore[no-untyped-def]
                 touch_from: int, tip: BodyRef) -> float:
    """Every 1 mm (1e-3 rad) of joint motion, independent of the planner's certificate."""
    sl = model.hand.finger_slice(finger)
    q = q_full.copy()
    worst = np.inf
    for s in range(len(path) - 1):
        n = max(2, int(np.ceil(np.linalg.norm(path[s + 1] - path[s]) / DENSE_STEP)) + 1)
        for t in np.linspace(0.0, 1.0, n):
            q[sl] = path[s] + t * (path[s + 1] - path[s])
            touching = [tip] if s >= touch_from else []
            worst = min(worst, model.finger_clearance(finger, q, st.position, st.rotation, touching))
    return float(worst)


def test_transfer_is_collision_free_every_millimetre(planar_scene: Scene) -> None:
    hand, st = _free_left(planar_scene)
    model = CollisionModel.of(planar_scene, hand)
    tip = BodyRef("left/1", 0, 1)
    sols = fingertip_ik(hand, 0, np.array([-0.5, 0.5]), np.array([1.0, 0.0]), [st.q[:2]])
    path = plan_transfer(model, st, 0, sols[0], tip, 0.05, seed=3)
    assert path is not None
    np.testing.assert_allclose(path.waypoints[0], st.q[:2])
    np.testing.assert_allclose(path.waypoints[-1], sols[0])
    assert _dense_check(model, 0, st.q, path.waypoints, st, len(path.waypoints) - 2, tip) >= 0.0
    again = plan_transfer(model, st, 0, sols[0], tip, 0.05, seed=3)
    assert again is not None and np.allclose(again.waypoints, path.waypoints)  # seeded


def test_clearance_detects_penetration(planar_scene: Scene) -> None:
    hand, st = _free_left(planar_scene)
    model = CollisionModel.of(planar_scene, hand)
    q = st.q.copy()
    q[:2] = [1.0, 0.0]  # link 0 through the disk
    assert model.finger_clearance(0, q, st.position, st.rotation) < 0.0
    q[:2] = [0.0, 0.0]  # the finger lies on the palm
    assert model.finger_clearance(0, q, st.position, st.rotation) < 0.0


def test_object_motion_stays_on_the_contact_manifold(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    """The lift of the planar plan: at every waypoint the sticking contacts coincide (A_c [dq; dr]
    = 0 integrated and projected) and the palm contact has separated at the end."""
    from planner.ompl_paths import moved

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
    assert np.all(np.asarray(t.figures["separations"]) > 0)
    assert t.object_path[-1][1] > t.object_path[0][1]  # lifted off the palm


def _motion_step(plan):  # type: ignore[no-untyped-def]
    step = next(s for s in plan.steps if s.transition.kind == "object_motion")
    t = step.transition
    sticking = [i for i, ch in enumerate(t.combination) if ch == "F"]
    separating = [i for i, ch in enumerate(t.combination) if ch == "D"]
    return step, sticking, separating


def test_contact_manifold_jacobian_and_tangent_space(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    """F'(x) equals central finite differences away from the start, F(x0) = 0, and at the start
    the tangent space null(F'(x0)) is the paper's motion space null(A_c) = span(Lambda) (eq. 7)."""
    from planner.ompl_paths import ContactManifold
    from planner.state import StateAnalysis

    hand = HandKinematics.from_scene(planar_scene)
    step, sticking, _ = _motion_step(planar_plan)
    before = step.before
    man = ContactManifold(hand, before, sticking)
    x0 = np.concatenate([before.q, np.zeros(man.D)])
    assert float(np.linalg.norm(man.function(x0))) < 1e-12
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = x0 + 0.05 * rng.standard_normal(len(x0))
        J = man.jacobian(x)  # (d n, M + D)
        Jn = np.column_stack([(man.function(x + e) - man.function(x - e)) / 2e-6
                              for e in 1e-6 * np.eye(len(x))])
        np.testing.assert_allclose(J, Jn, atol=1e-7)
    from scipy.linalg import null_space

    N = null_space(man.jacobian(x0))
    Lam = StateAnalysis.of(planar_scene, before, hand).parts(step.transition.combination).ms.Lambda
    assert N.shape[1] == Lam.shape[1]
    np.testing.assert_allclose(N @ N.T, Lam @ Lam.T, atol=1e-9)


def test_spatial_manifold_jacobian_matches_finite_differences() -> None:
    """The 3-D rotation part: d(exp(w) y)/dw = -[exp(w) y]x J_l(w), at random w."""
    from closure_helpers import EXAMPLES

    from analysis.scene import load_scene
    from planner.ompl_paths import ContactManifold

    scene = load_scene(EXAMPLES / "sphere_four_finger_palm.json")
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    man = ContactManifold(hand, st, list(range(st.L)))
    rng = np.random.default_rng(4)
    x0 = np.concatenate([st.q, np.zeros(man.D)])
    assert float(np.linalg.norm(man.function(x0))) < 1e-9
    for scale in (1e-3, 0.3, 1.5):
        x = x0 + scale * rng.standard_normal(len(x0))
        Jn = np.column_stack([(man.function(x + e) - man.function(x - e)) / 2e-7
                              for e in 1e-7 * np.eye(len(x))])
        np.testing.assert_allclose(man.jacobian(x), Jn, atol=1e-6)


def test_ompl_object_motion_is_on_the_manifold_and_collision_free(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    """The lift planned by OMPL's constrained planning: ends where the analysis says, every state
    on the manifold, joint steps at most DENSE_STEP, and every state collision-free when checked
    independently."""
    from planner.ompl_paths import integrate_object_motion, plan_object_motion

    hand = HandKinematics.from_scene(planar_scene)
    model = CollisionModel.of(planar_scene, hand)
    step, sticking, separating = _motion_step(planar_plan)
    t, before = step.transition, step.before
    assert t.figures["ompl_planner_states"] >= 2 and t.figures["manifold_residual"] < 1e-6
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
    from planner.ompl_paths import moved

    touching = [hand.resolve_body(before.contacts[i].body) for i in (*sticking, *separating)]
    allow = [model.start_allowance(f, before.q, before.position, before.rotation) for f in range(len(hand.fingers))]
    for q, pose in zip(om.q_path, om.pose_path, strict=True):
        st = moved(before, pose - before.pose_vector())
        for f in range(len(hand.fingers)):
            mine = [b for b in touching if b is not None and b.finger == f]
            assert model.finger_clearance(f, q, st.position, st.rotation, mine, allow[f]) >= -1e-9


def test_ompl_object_motion_refuses_a_colliding_goal(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    """A goal configuration with a link through the object has no valid path: None, not a path."""
    from planner.ompl_paths import ObjectMotion, plan_object_motion

    hand = HandKinematics.from_scene(planar_scene)
    model = CollisionModel.of(planar_scene, hand)
    step, sticking, separating = _motion_step(planar_plan)
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
