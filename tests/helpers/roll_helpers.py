"""The 5 cm rolls of the rolling examples (a sphere, a cylinder on its side, pushed along a table by a
finger), planned without sliding, verified and replayed in MuJoCo: shared by their replay tests."""

from __future__ import annotations

from typing import Any

import numpy as np
from closure_helpers import EXAMPLES
from scipy.spatial.transform import Rotation

from analysis.loader import load_scene
from analysis.pose import Pose
from analysis.scene import Finger3D, Scene
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
    p, sim = plan_verify_replay(scene, Goal(type="displacement", displacement=[0.05, 0.0, 0.0, 0.0, 0.0, 0.0],
                                            position_tolerance=0.005, rotation_tolerance="free"),
                                options or PlannerOptions(sliding_motions=False))
    return scene, p, sim, Pose.from_vector(sim.start_pose, 3), Pose.from_vector(sim.simulated_final_pose, 3)


def plan_verify_replay(scene: Scene, goal: Goal, options: PlannerOptions | None = None) -> tuple[Any, Any]:
    """``scene`` planned towards ``goal``: the plan found and passing ``verify_plan``, its continuous
    MuJoCo replay not dropped and within 5 % of the planned displacement (position and rotation
    each). Returns the plan and the simulation."""
    p = plan(scene, goal, options=options)
    assert p.found and verify_plan(scene, p) == [], p.reason
    sim = simulate_plan(scene, p)
    assert not sim.dropped, sim.drop_reason
    err = sim.error
    assert err.relative_position <= 0.05 and err.relative_rotation <= 0.05, sim.to_json()
    assert sim.ok
    return p, sim


def independent_link_axis(scene: Scene, q: np.ndarray, link: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Independent forward kinematics of the scene's first finger (scipy rotations, not the
    project's kinematics): link ``link``'s axis ends ``(3,)`` and its frame's rotation ``(3, 3)``."""
    f = scene.fingers[0]
    assert isinstance(f, Finger3D)
    w, x, y, z = f.base.quat_wxyz
    Rk = Rotation.from_quat([x, y, z, w]).as_matrix()
    pk = np.asarray(f.base.position, dtype=float)
    for j, joint in enumerate(f.joints[: link + 1]):
        pk = pk + Rk @ np.asarray(joint.origin, dtype=float)
        Rk = Rk @ Rotation.from_rotvec(q[j] * np.asarray(joint.axis, dtype=float)).as_matrix()
    end = f.joints[link + 1].origin if link + 1 < len(f.joints) else f.tip
    return pk, pk + Rk @ np.asarray(end, dtype=float), Rk
