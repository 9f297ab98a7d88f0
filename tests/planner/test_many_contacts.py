"""The planner takes any number of contacts (the cap of 16 is for full enumeration only)."""

from __future__ import annotations

import pytest
from cube_planes import cube_in_planes

from analysis.kinematics import HandKinematics
from analysis.loader import scene_from_dict
from planner import Goal, plan
from planner.state import state_from_scene, state_scene


def test_a_32_contact_scene_is_planned_for() -> None:
    """A cube against the floor and a wall, 4 x 4 contacts on each: its grasp state goes back to
    an equal scene, and the search answers (no fingers: nothing can move it, so no plan) instead
    of refusing the scene."""
    scene = scene_from_dict(cube_in_planes(2, grid=4))
    assert len(scene.contacts) == 32
    hand = HandKinematics.from_scene(scene)
    again = state_scene(scene, state_from_scene(scene, hand), hand)
    for c, c0 in zip(again.contacts, scene.contacts, strict=True):
        assert c.body == c0.body and c.point == pytest.approx(c0.point, abs=1e-12)
        assert c.normal == pytest.approx(c0.normal, abs=1e-12)
    result = plan(scene, Goal(type="active"), time_limit=30.0)
    assert not result.found and "every reachable state (1) was expanded" in result.reason
