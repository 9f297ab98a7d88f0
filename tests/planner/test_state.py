"""Grasp states: round trip to scenes, keys, moved objects."""

from __future__ import annotations

from pathlib import Path

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


@pytest.mark.parametrize("name", ["planar_disk_envelope", "sphere_four_finger_palm", "sphere_four_finger_wrap"])
def test_released_states_keep_their_parents_geometry(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A finger let go (a release edge: the others' contacts untouched, the object still) leaves a
    state whose contacts are its parent's, each on a body where it was (same_geometry): its scene
    is built without checking the geometry again, and the full check (check_geometry) finds
    nothing wrong with it, on every release of the scene's grasp. Moving the object, or a finger
    that keeps a contact, or changing a contact, is not the same geometry."""
    from dataclasses import replace

    from analysis.loader import check_geometry, load_scene
    from planner.goals import Goal
    from planner.graph import ContactStateGraph
    from planner.state import same_geometry

    scene = load_scene(Path(__file__).resolve().parents[2] / "examples" / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    g = ContactStateGraph(scene, hand, Goal(type="active"))
    st = state_from_scene(scene, hand)
    g.add(st)
    built: list[bool] = []
    of = StateAnalysis.of.__func__  # type: ignore[attr-defined]

    def counted(cls: type, base: Scene, state: object, hand_: HandKinematics, geometry: bool = True) -> StateAnalysis:
        built.append(geometry)
        return of(cls, base, state, hand_, geometry)  # type: ignore[no-any-return]

    monkeypatch.setattr(StateAnalysis, "of", classmethod(counted))
    releases = g.release_edges(st)
    assert releases
    assert built.count(False) == len(releases)  # each released state's scene: no geometry check
    for _, new in releases:
        assert same_geometry(st, new, hand)
        assert g.cache(new).state is new
        check_geometry(state_scene(scene, new, hand))  # the full check: no error
    _, new = releases[0]
    assert not same_geometry(st, new.with_pose(moved(new, np.r_[1e-9, np.zeros(scene.D - 1)]).pose, new.q), hand)
    f = hand.finger_of(new.contacts[0].body)
    assert f is not None
    q = new.q.copy()
    q[hand.finger_slice(f)] += 1e-12  # a finger that keeps a contact moved
    assert not same_geometry(st, new.with_contacts(new.contacts, q), hand)
    c0 = replace(new.contacts[0], point_object=new.contacts[0].point_object + 1e-12)
    assert not same_geometry(st, new.with_contacts((c0, *new.contacts[1:])), hand)
