"""OMPL finger transfers, checked independently every 1 mm of joint motion."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from analysis.kinematics import BodyRef
from analysis.scene import Scene
from planner.collision import DENSE_STEP, CollisionModel
from planner.ik import fingertip_ik
from planner.transfer import plan_transfer, transfer_key


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


def test_transfer_is_collision_free_every_millimetre(planar_scene: Scene, free_left) -> None:  # type: ignore[no-untyped-def]
    hand, st = free_left
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



def test_transfer_key_holds_what_the_transfer_depends_on(planar_scene: Scene, free_left) -> None:  # type: ignore[no-untyped-def]
    """The search keeps transfers by ``transfer_key``: moving a finger the transfer is not checked
    against (the planar fingers move in different layers) keeps the key and the answer; a finger
    it is checked against, the object pose or the goal configuration change the key."""
    hand, st = free_left
    model = CollisionModel.of(planar_scene, hand)
    assert model.finger_pairs == frozenset()  # the planar fingers overlap in the scene: not checked
    tip = BodyRef("left/1", 0, 1)
    goal = fingertip_ik(hand, 0, np.array([-0.5, 0.5]), np.array([1.0, 0.0]), [st.q[:2]])[0]
    q_other = st.q.copy()
    q_other[2:4] += [0.2, -0.1]  # the right finger moved
    other = st.with_contacts(st.contacts, q_other)
    key = transfer_key(model, st, 0, goal, tip, 0.05, 3, 300)
    assert transfer_key(model, other, 0, goal, tip, 0.05, 3, 300) == key
    a = plan_transfer(model, st, 0, goal, tip, 0.05, seed=3)
    b = plan_transfer(model, other, 0, goal, tip, 0.05, seed=3)
    assert a is not None and b is not None
    np.testing.assert_array_equal(a.waypoints, b.waypoints)
    assert (a.length, a.clearance, a.checks) == (b.length, b.clearance, b.checks)
    # a finger checked against the moving one: its joints are part of the key
    paired = replace(model, finger_pairs=frozenset({(0, 1)}), _cache={})
    assert transfer_key(paired, other, 0, goal, tip, 0.05, 3, 300) != transfer_key(paired, st, 0, goal, tip, 0.05, 3,
                                                                                     300)
    moved = st.with_pose(st.pose.displaced(np.array([0.01, 0.0, 0.0])))
    assert transfer_key(model, moved, 0, goal, tip, 0.05, 3, 300) != key
    assert transfer_key(model, st, 0, goal + 1e-9, tip, 0.05, 3, 300) != key
    assert transfer_key(model, st, 0, goal, tip, 0.05, 4, 300) != key
