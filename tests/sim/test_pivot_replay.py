"""The pivot (issue 11) replayed in MuJoCo: the Panda's forearm tips the tall box of
examples/panda_forearm_tall_box.json by 0.2 rad about its near bottom edge (tests/planner/
test_pivot.py), one continuous simulation with the plan's torques (T, 32) and the default posture
torque on the arm's self-motion. The first step (FFFDD, the far corners lifting) is 0.12 long in
the motion metric and the box turns at about 0.02/s under its torque, so it needs ~6 s: with a
``motion_time`` of 2 s (the replay's earlier default) it is cut short and the replay ends ~40 %
short of the planned turn; with the default 8 s per motion it ends within 5 % of the planned
displacement, never dropped."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.loader import load_scene
from analysis.pose import Pose
from analysis.scene import Scene
from planner import Goal, plan
from planner.plan import Plan
from sim.plan_replay import PlanSimulationOptions, simulate_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TURN = 0.2  # rad about -y through the near bottom edge
MOTION_TIME = 8.0  # s per object motion, the default (2 s, the earlier default, is too short for the first step)


@pytest.fixture(scope="module")
def box_scene() -> Scene:
    return load_scene(EXAMPLES / "panda_forearm_tall_box.json")


def _edge(scene: Scene) -> np.ndarray:
    p = np.asarray(scene.object.pose.position, float)
    half = np.asarray(scene.object.shape.size, float) / 2  # type: ignore[union-attr]
    return np.array([p[0] - half[0], p[1], p[2] - half[2]])


@pytest.fixture(scope="module")
def pivot_plan(box_scene: Scene) -> Plan:
    p = np.asarray(box_scene.object.pose.position, float)
    c = _edge(box_scene)
    s, co = np.sin(-TURN), np.cos(-TURN)
    R = np.array([[co, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, co]])  # about y by -TURN
    moved = c + R @ (p - c) - p
    pl = plan(box_scene, Goal(type="displacement", displacement=[*moved.tolist(), 0.0, -TURN, 0.0],
                              position_tolerance=0.003, rotation_tolerance=0.01))
    assert pl.found, pl.reason
    return pl


@pytest.mark.slow
def test_pivot_replays_within_5_percent(box_scene: Scene, pivot_plan: Plan) -> None:
    assert PlanSimulationOptions().motion_time == MOTION_TIME  # the default: what ctp simulate does
    sim = simulate_plan(box_scene, pivot_plan)
    assert not sim.dropped, sim.drop_reason
    assert len(sim.steps) == len(pivot_plan.steps)
    err = sim.error
    assert err.relative_position <= 0.05 and err.relative_rotation <= 0.05, sim.to_json()
    assert sim.ok
    # the box turned about -y by (nearly) the planned angle, nothing else
    assert float(sim.simulated[4]) == pytest.approx(float(pivot_plan.displacement[4]), rel=0.05)
    assert float(np.max(np.abs(sim.simulated[[1, 3, 5]]))) < 1e-4
    # about the near bottom edge: its corners stayed where they were on the table all along
    start = Pose.from_vector(np.asarray(pivot_plan.start_pose), 3)
    half = np.asarray(box_scene.object.shape.size, float) / 2  # type: ignore[union-attr]
    corners = [np.array([-half[0], sy * half[1], -half[2]]) for sy in (-1.0, 1.0)]  # object frame
    for v in sim.object_path.poses:
        pose = Pose.from_vector(v, 3)
        for k in corners:
            assert float(np.linalg.norm(pose.to_world(k) - start.to_world(k))) < 2e-3


@pytest.mark.slow
def test_two_seconds_a_motion_cut_the_lift_off_short(box_scene: Scene, pivot_plan: Plan) -> None:
    """The finding behind MOTION_TIME: with 2 s a motion (the earlier default) the first motion (the
    far corners lifting) gives up at well under half its planned length, and the replay misses the
    plan by more than its 5 % tolerance (not dropped: the box rests on its edge)."""
    sim = simulate_plan(box_scene, pivot_plan, options=PlanSimulationOptions(motion_time=2.0))
    assert not sim.dropped, sim.drop_reason
    first = sim.steps[0]
    assert float(np.linalg.norm(first.simulated)) < 0.5 * float(np.linalg.norm(first.planned))
    assert not sim.ok and sim.error.relative_rotation > 0.05
