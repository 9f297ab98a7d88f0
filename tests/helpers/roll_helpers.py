"""The 5 cm rolls of the rolling examples (a sphere, a cylinder on its side, pushed along a table by a
finger), planned without sliding, verified and replayed in MuJoCo: shared by their replay tests."""

from __future__ import annotations

from typing import Any

from closure_helpers import EXAMPLES

from analysis.loader import load_scene
from analysis.pose import Pose
from planner import Goal, plan
from planner.options import PlannerOptions
from planner.verify import verify_plan
from sim.plan_replay import simulate_plan


def roll_and_replay(example: str, options: PlannerOptions | None = None) -> tuple[Any, Any, Any, Pose, Pose]:
    """``examples/<example>.json`` rolled 5 cm along +x (``--no-sliding``, or ``options``): the plan found and
    passing ``verify_plan``, its continuous MuJoCo replay not dropped and within 5 % of the planned
    displacement (position and rotation each). Returns the scene, the plan, the simulation and
    MuJoCo's start and final poses of the object."""
    scene = load_scene(EXAMPLES / f"{example}.json")
    p = plan(scene, Goal(type="displacement", displacement=[0.05, 0.0, 0.0, 0.0, 0.0, 0.0], position_tolerance=0.005,
                         rotation_tolerance="free"), options=options or PlannerOptions(sliding_motions=False))
    assert p.found and verify_plan(scene, p) == [], p.reason
    sim = simulate_plan(scene, p)
    assert not sim.dropped, sim.drop_reason
    err = sim.error
    assert err.relative_position <= 0.05 and err.relative_rotation <= 0.05, sim.to_json()
    assert sim.ok
    return scene, p, sim, Pose.from_vector(sim.start_pose, 3), Pose.from_vector(sim.simulated_final_pose, 3)
