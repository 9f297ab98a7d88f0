"""Step-by-step MuJoCo replay of a plan (physics cross-check), built on
:func:`sim.torque_replay.simulate_torques`.

Each step is replayed from its own planned state (the scene of the state before the step, at rest):

* ``release`` / ``contact`` (33): the object must stay put. The grasp after the step is loaded
  with its stationary torque ``tau_st`` (18) for ``hold_time``, its joints held by the continuous
  replay's hold servo (:class:`sim.plan_replay.PlanSimulationOptions`, ``hold_rate``) in the
  motions that move the contacts; the object must not move more than
  ``hold_tol`` object sizes nor be dropped. (The finger's transfer path itself is a free-space
  motion that exerts nothing on the object; it is not simulated.)
* ``object_motion`` (30-32): the chosen torque of T is applied to the state before the step, with
  the step's combination as the expected contact states, until the object has travelled the
  planned distance (``stop_distance``), the fingers' damping lowered for the step's joint speeds
  (``phi``, :func:`sim.mjcf.damping`); its displacement is compared with the planned one.

The object's total displacement is the sum of the steps' displacements, compared with the plan's.
Errors are position (scene units) and rotation (radians) apart, each relative to the planned
motion as in :class:`sim.plan_replay.PoseError` (a step: its end pose against the planned one; the
total: the summed translations, and the summed rotation coordinates, exact in 2-D and to first
order in 3-D, where the steps' rotations are small).
``simulate_torques`` restarts from a scene, so the steps are chained through the planned states,
not through the simulated ones: this checks every step's physics, not the drift of a whole run.
The whole run, one simulation through every step, is :func:`sim.plan_replay.simulate_plan`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.pose import Pose
from analysis.scene import Scene
from planner.plan import Plan
from planner.state import StateAnalysis, all_f, state_scene
from sim.plan_paths import joint_speed_ratio
from sim.plan_replay import DEFAULT_OPTIONS, PoseError
from sim.torque_replay import simulate_torques


@dataclass(frozen=True)
class StepReplay:
    index: int
    kind: str
    planned: Array  # (D,) planned object displacement of the step
    simulated: Array  # (D,) simulated displacement
    dropped: bool
    ok: bool
    note: str
    error: PoseError | None = None  # object motions: the end pose against the planned one


@dataclass(frozen=True)
class PlanReplay:
    steps: tuple[StepReplay, ...]
    planned: Array  # (D,) total planned displacement
    simulated: Array  # (D,)
    size: float = 1.0  # object size (analysis.geometry.object_size)
    dim: int = 2

    @property
    def error(self) -> PoseError:
        """Position and rotation error of the total displacement (see the module docstring)."""
        d = self.dim
        return PoseError.of_errors(float(np.linalg.norm(self.simulated[:d] - self.planned[:d])),
                                   float(np.linalg.norm(self.simulated[d:] - self.planned[d:])),
                                   float(np.linalg.norm(self.planned[:d])), float(np.linalg.norm(self.planned[d:])),
                                   self.size)

    @property
    def relative_error(self) -> float:
        """The larger of the relative position and rotation errors of the total displacement."""
        return self.error.relative

    @property
    def dropped(self) -> bool:
        return any(s.dropped for s in self.steps)

    @property
    def ok(self) -> bool:
        return all(s.ok for s in self.steps)


def replay_plan(scene: Scene, plan: Plan, hold_time: float = 0.1, hold_tol: float = 0.01,
                motion_time: float = 2.0, tolerance: float = 0.05,
                hold_rate: float = DEFAULT_OPTIONS.hold_rate) -> PlanReplay:
    """Replay every step of a found plan in MuJoCo (see the module docstring); an object motion
    is ``ok`` when its relative position and rotation errors are each within ``tolerance``; holds
    have the continuous replay's joint servo (``hold_rate``, 1/s; 0: torque control only)."""
    if not plan.found:
        raise ValueError("only a found plan can be replayed")
    hand = HandKinematics.from_scene(scene)
    size = object_size(scene)
    out: list[StepReplay] = []
    total_sim = np.zeros(scene.D)
    total_plan = np.zeros(scene.D)
    for step in plan.steps:
        t = step.transition
        planned = t.object_path[-1] - t.object_path[0]
        if t.kind == "object_motion":
            sc = state_scene(scene, step.before, hand)
            assert t.tau is not None
            dist = float(np.linalg.norm(planned))  # |dr|, the stop distance of simulate_torques
            error: PoseError | None = None
            res = simulate_torques(sc, t.tau, duration=motion_time, combination=t.combination, stop_distance=dist,
                                   phi=joint_speed_ratio(t.q_path, t.object_path))
            sim = np.asarray(res.dr, dtype=float)
            start = Pose.from_vector(t.object_path[0], scene.dim)
            error = PoseError.of(start, Pose.from_vector(t.object_path[-1], scene.dim), start.displaced(sim), size)
            ok = (not res.dropped) and error.relative <= tolerance
            note = error.describe(tolerance)
        else:
            error = None
            sc = state_scene(scene, step.after, hand)
            sa = StateAnalysis.of(scene, step.after, hand)
            grasp = sa.stationary(all_f(step.after))
            assert grasp is not None
            res = simulate_torques(sc, grasp.tau, duration=hold_time, hold_rate=hold_rate)
            sim = np.asarray(res.dr, dtype=float)
            moved = float(np.linalg.norm(sim[: scene.dim]))
            ok = (not res.dropped) and moved <= hold_tol * size
            note = f"held: moved {moved:.2e}"
        total_sim += sim
        total_plan += planned
        out.append(StepReplay(step.index, t.kind, planned, sim, bool(res.dropped), bool(ok), note, error))
    return PlanReplay(tuple(out), total_plan, total_sim, size, scene.dim)
