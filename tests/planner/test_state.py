"""Grasp states: round trip to scenes, keys, moved objects."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.exceptions import SceneError
from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from planner.object_motion import moved
from planner.state import AnalysisCache, StateAnalysis, all_f, state_from_scene, state_scene


def test_round_trip_reproduces_the_scene(planar_scene: Scene) -> None:
    hand = HandKinematics.from_scene(planar_scene)
    st = state_from_scene(planar_scene, hand)
    sc = state_scene(planar_scene, st, hand)
    for a, b in zip(planar_scene.contacts, sc.contacts, strict=True):
        assert a.body == b.body
        np.testing.assert_allclose(a.point, b.point, atol=1e-9)
        np.testing.assert_allclose(a.normal, b.normal, atol=1e-9)
    np.testing.assert_allclose(st.pose_vector(), [0.0, 0.5, 0.0])
    # each contact's body point, carried by the hand at q, is the object point
    for i, c in enumerate(st.contacts):
        ref = hand.resolve_body(c.body)
        assert ref is not None
        np.testing.assert_allclose(hand.point_position(ref, c.point_body, st.q), st.world_point(i), atol=1e-9)


def test_analysis_of_the_enveloping_grasp_is_passive(planar_scene: Scene) -> None:
    hand = HandKinematics.from_scene(planar_scene)
    st = state_from_scene(planar_scene, hand)
    sa = StateAnalysis.of(planar_scene, st, hand)
    assert all_f(st) == "FFFFF"
    assert sa.stationary("FFFFF") is not None
    s = sa.summary("FFFFF")
    assert s.a_bar == 0 and not s.feasible  # passive closure: the object cannot move


def test_keys_and_cache(planar_scene: Scene) -> None:
    hand = HandKinematics.from_scene(planar_scene)
    st = state_from_scene(planar_scene, hand)
    fewer = st.with_contacts(st.contacts[2:])
    assert st.key() != fewer.key() and st.key() == state_from_scene(planar_scene, hand).key()
    cache = AnalysisCache(planar_scene, hand)
    a = cache(st)
    assert cache(st) is a and cache.hits == 1 and cache.misses == 1


def test_moving_the_object_breaks_finger_contacts(planar_scene: Scene) -> None:
    hand = HandKinematics.from_scene(planar_scene)
    st = moved(state_from_scene(planar_scene, hand), np.array([0.0, 0.1, 0.0]))
    np.testing.assert_allclose(st.pose_vector(), [0.0, 0.6, 0.0])
    np.testing.assert_allclose(st.world_point(4), [0.0, 0.1])  # the palm point moved with the object
    with pytest.raises(SceneError):  # the finger links are no longer at the contact points
        state_scene(planar_scene, st, hand)
