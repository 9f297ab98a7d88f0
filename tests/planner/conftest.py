"""Fixtures shared by the planner tests: a free finger of the planar scene, the object motion of
the planar plan."""

from __future__ import annotations

from typing import Any

import pytest

from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from planner.state import state_from_scene


@pytest.fixture
def free_left(planar_scene: Scene) -> tuple[HandKinematics, Any]:
    """The planar scene's hand and its grasp with the left finger lifted away (its contacts dropped)."""
    hand = HandKinematics.from_scene(planar_scene)
    st = state_from_scene(planar_scene, hand)
    q = st.q.copy()
    q[:2] = [2.0, 0.3]  # left finger lifted away
    return hand, st.with_contacts(st.contacts[2:], q)


@pytest.fixture
def motion_step(planar_plan):  # type: ignore[no-untyped-def]
    """The first object motion of the planar plan, its sticking and its separating contacts."""
    step = next(s for s in planar_plan.steps if s.transition.kind == "object_motion")
    t = step.transition
    sticking = [i for i, ch in enumerate(t.combination) if ch == "F"]
    separating = [i for i, ch in enumerate(t.combination) if ch == "D"]
    return step, sticking, separating
