"""The rolling plan (tests/planner/test_rolling_plan.py: the disk in the V of two links moved 3 cm to
the left, rolling on both) replayed continuously in MuJoCo with the plan's torques (T, 32): the
disk ends within 5 % of the planned displacement, position and rotation each, and MuJoCo's contact
point on each link moves along the link by ``r`` times the disk's turn relative to the link
within 5 %, where the plan put it (also within 5 %)."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import EXAMPLES
from roll_helpers import plan_verify_replay

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from planner import Goal
from sim.mjcf import link_body_name

R = 0.3  # the disk's radius


@pytest.mark.slow
def test_rolling_plan_replays_within_5_percent() -> None:
    scene = load_scene(EXAMPLES / "planar_disk_rolling_v.json")
    hand = HandKinematics.from_scene(scene)
    p, sim = plan_verify_replay(scene, Goal(type="displacement", displacement=[-0.03, 0.0, 0.0],
                                            position_tolerance=0.003, rotation_tolerance="free"))
    np.testing.assert_allclose(sim.simulated[[0, 2]], sim.planned[[0, 2]], rtol=0.05)
    assert sim.start_q is not None and sim.final_q is not None
    assert sim.start_contacts is not None and sim.final_contacts is not None
    first, last = p.steps[0].before, p.steps[-1].after
    for i, (finger, side) in enumerate((("left", 1.0), ("right", -1.0))):
        ref = hand.resolve_body(f"{finger}/0")
        assert ref is not None
        name = link_body_name(finger, 0)
        assert name in sim.start_contacts and name in sim.final_contacts, "the disk lost a link"
        angles = []
        for q in (sim.start_q, sim.final_q):
            a, b = hand.body_segment(ref, q)
            angles.append(float(np.arctan2(b[1] - a[1], b[0] - a[0])))
        rel = float(sim.simulated[2]) - (angles[1] - angles[0])  # the disk's turn relative to the link
        assert abs(rel) > 0.05
        travel = float(hand.to_local(ref, sim.final_contacts[name], sim.final_q)[0]
                       - hand.to_local(ref, sim.start_contacts[name], sim.start_q)[0])
        assert abs(travel - (-side * R * rel)) <= 0.05 * R * abs(rel), (travel, rel)  # rolling kinematics
        planned = float(hand.to_local(ref, last.world_point(i), last.q)[0]
                        - hand.to_local(ref, first.world_point(i), first.q)[0])
        assert abs(travel - planned) <= 0.05 * abs(planned), (travel, planned)  # where the plan rolled it
