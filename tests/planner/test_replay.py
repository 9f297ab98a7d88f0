"""MuJoCo replay of the planar plan: the object ends within 5 % of the planned displacement and is
never dropped; every regrasp step holds the object still."""

from __future__ import annotations

import numpy as np

from analysis.scene import Scene
from planner.replay import replay_plan


def test_planar_plan_replays_in_mujoco(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    r = replay_plan(planar_scene, planar_plan)
    assert not r.dropped
    assert all(s.ok for s in r.steps), [s.note for s in r.steps if not s.ok]
    assert float(np.linalg.norm(r.planned)) > 0.0
    assert r.relative_error <= 0.05
    lift = [s for s in r.steps if s.kind == "object_motion"]
    assert lift and all(s.simulated[1] > 0 for s in lift)  # the object really rises off the palm
