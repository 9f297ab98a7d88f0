"""The 3-D example: a plan from the enveloping grasp to active closure, checked by the analysis
and replayed in MuJoCo, step by step and as one continuous simulation (slow: about 20-40 s of
planning on 2 shared cores)."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import EXAMPLES

from analysis.geometry import object_size
from analysis.loader import load_scene
from planner import Goal, plan
from planner.verify import verify_plan
from sim.plan_replay import simulate_plan
from sim.step_replay import replay_plan


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
    # the whole plan in one simulation from the scene, through the JSON form a plan file holds
    c = simulate_plan(scene, p.to_json())
    assert not c.dropped, c.drop_reason
    np.testing.assert_allclose(c.planned, p.displacement, atol=1e-9)
    assert c.relative_error <= 0.05, (c.simulated, c.planned)
    assert float(np.linalg.norm(c.simulated_final_pose - p.final_pose)) <= 0.05 * float(np.linalg.norm(p.displacement))
    assert c.max_regrasp_deviation <= 2e-3 * object_size(scene)  # still while fingers regrasp
    assert 0.0 <= c.tracking_error <= 1e-4
    assert [s.driven_finger for s in c.steps] == [getattr(st.transition.figures, "finger", None) for st in p.steps]
