"""The 3-D example: a plan from the enveloping grasp to active closure, checked by the analysis
and replayed in MuJoCo (slow: about 20-40 s of planning on 2 shared cores)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import EXAMPLES

from analysis.scene import load_scene
from planner import Goal, plan
from planner.replay import replay_plan
from planner.verify import verify_plan


@pytest.mark.slow
def test_sphere_plan_to_active_closure_replays() -> None:
    scene = load_scene(EXAMPLES / "sphere_four_finger_palm.json")
    p = plan(scene, Goal(type="active"))
    assert p.found, p.reason
    kinds = [s.transition.kind for s in p.steps]
    assert "contact" in kinds and kinds[-1] == "object_motion" and "palm" not in p.final_contacts
    assert verify_plan(scene, p) == []
    r = replay_plan(scene, p)
    assert not r.dropped and all(s.ok for s in r.steps)
    assert float(np.linalg.norm(r.planned)) > 0 and r.relative_error <= 0.05
