"""OMPL finger transfers, checked independently every 1 mm of joint motion."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
from ompl import base as ob

from analysis.kinematics import BodyRef
from analysis.scene import Scene
from planner.budget import CheckBudget
from planner.collision import DENSE_STEP, CollisionModel, path_clearance_certified
from planner.ik import fingertip_ik
from planner.transfer import _bisection_order, _SegmentValidator, plan_transfer, transfer_key


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


def test_segment_validator_checks_what_ompls_discrete_validator_checks() -> None:
    """``_bisection_order`` is the order of OMPL's DiscreteMotionValidator (middle first, then the
    middles of the halves, breadth first) and visits every inner state once; the validator
    answers like checking each state on its own and counts the checks up to the first invalid."""
    assert _bisection_order(1).tolist() == []
    assert _bisection_order(2).tolist() == [1]
    assert _bisection_order(8).tolist() == [4, 2, 6, 1, 3, 5, 7]
    for nd in range(2, 60):
        assert sorted(_bisection_order(nd).tolist()) == list(range(1, nd))
    space = ob.RealVectorStateSpace(2)
    bounds = ob.RealVectorBounds(2)
    bounds.setLow(-2.0)
    bounds.setHigh(2.0)
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityCheckingResolution(0.01)
    si.setup()
    budget = CheckBudget(10**6, 60.0)
    wall = 0.3  # states with x > wall are invalid

    def valid_many(X: np.ndarray) -> np.ndarray:
        return np.asarray(X[:, 0] <= wall)

    mv = _SegmentValidator(si, space, 2, valid_many, budget)
    a, b = space.allocState(), space.allocState()
    a[0], a[1] = -1.0, 0.0
    b[0], b[1] = 0.2, 0.5
    nd = space.validSegmentCount(a, b)
    assert mv.checkMotion(a, b) and budget.used == nd  # the end and the nd - 1 inner states
    b[0] = 0.9
    budget.used = 0
    assert not mv.checkMotion(a, b) and budget.used == 1  # the end is invalid: one check
    b[0] = 0.29
    a[0] = 0.31  # the start itself is not checked (OMPL assumes it valid); the end is valid
    budget.used = 0
    nd = space.validSegmentCount(a, b)
    order = _bisection_order(nd)
    states = 0.31 + (0.29 - 0.31) * order / nd
    first_bad = int(np.flatnonzero(states > wall)[0])
    assert not mv.checkMotion(a, b) and budget.used == 1 + first_bad + 1


def test_certificate_agrees_with_a_dense_check(planar_scene: Scene, free_left) -> None:  # type: ignore[no-untyped-def]
    """``path_clearance_certified`` (bisection from the ends, a part certified by its two ends'
    clearances) against an independent check every 1e-3 rad, on seeded random paths of the
    left finger around the disk: a certified path never goes deeper than the dense floor allows
    (``K * DENSE_STEP / 2`` between two checked configurations), and a refused one does collide
    within that floor; both verdicts occur."""
    hand, st = free_left
    model = CollisionModel.of(planar_scene, hand)
    K = model.lipschitz(0)
    rng = np.random.default_rng(4)
    verdicts = set()
    allow = model.start_allowance(0, st.q, st.position, st.rotation)
    for _ in range(25):
        path = np.vstack([st.q[:2], st.q[:2] + rng.normal(0.0, 1.2, 2), st.q[:2] + rng.normal(0.0, 1.2, 2)])
        ok, clear, checks = path_clearance_certified(model, 0, st.q, path, st.position, st.rotation)
        # every 1e-3 rad (finger_clearances: one finger_clearance per row, bit for bit, tested in
        # test_collision_fastmin)
        dense = min(float(model.finger_clearances(
            0, st.q, a + np.linspace(0.0, 1.0, int(np.ceil(np.linalg.norm(b - a) / DENSE_STEP)) + 1)[:, None] * (b - a),
            st.position, st.rotation, allow).min()) for a, b in itertools.pairwise(path))
        verdicts.add(ok)
        if ok:
            assert dense >= -K * DENSE_STEP / 2 and clear >= 0.0
        else:
            assert clear < 0.0 and dense < K * DENSE_STEP / 2
        assert checks >= 2
    assert verdicts == {True, False}


def test_the_bindings_expose_only_the_two_state_check_motion() -> None:
    """_SegmentValidator overrides ``checkMotion(s1, s2)``, the one overload OMPL's bindings give
    Python; a binding that adds the ``lastValid`` overload must be handled there too."""
    from ompl import base as ob

    doc = ob.MotionValidator.checkMotion.__doc__ or ""
    assert doc.count("checkMotion(") == 1 and "arg1" in doc and "arg2" not in doc, doc
