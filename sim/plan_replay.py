"""Continuous MuJoCo replay of a whole plan: one simulation, from the scene, through every step.

:func:`simulate_plan` is the physics check of a plan as a robot would execute it: the object and
the hand start at rest at the scene's configuration and are never reset, so whatever an earlier
step leaves behind (creep of the object during a regrasp, overshoot of an object motion, a new
contact's slight penetration) is carried into the later steps and into the final pose. (The
step-by-step check :func:`sim.step_replay.replay_plan` restarts every step from its planned
state instead.)

Model
-----
One model, :func:`sim.mjcf.build_model` of the start scene, with the quasi-static
parameters of :mod:`sim.mjcf` (``DEFAULT_PARAMS``; object damping equal in every
pose coordinate, light finger damping, small masses, see :func:`sim.mjcf.damping`).
Every link of every finger and every fixed body has a contact pair with the object, so the
contacts a plan makes later are simulated like the scene's own. The force scale (the ``tau``
argument of ``build_model``) is that of the **largest torque anywhere in the plan** (the
stationary and chosen torques of all steps, by max-norm, as :func:`sim.mjcf.force_scale`
reads it): damping, masses and contact stiffness are fixed for the whole run, so they are sized
for the strongest load (the object motion's member of T, eq. 32); under the smaller holding
torques the object is then only more heavily damped, which slows creep and does not change any
equilibrium.

Control of the hand
-------------------
At every moment each finger is either

* **torque-controlled** (it has a contact in the planned state of that moment): its motors
  apply the entries of the current torque ``tau`` ``(M,)`` (scene joint order), the paper's
  model of a grasp (eq. 18 holding, eq. 32 moving); with ``options.posture_rate > 0`` plus a
  posture torque on the hand's self-motion only (joint motions that move no kept contact point:
  :func:`sim.torque_replay.self_motion_torque`), towards the planned configuration of the
  moment, which a redundant arm needs (the Panda's forearm push: under constant torques its
  elbow swings out of its plane after about 6 cm; the Allegro's four-joint fingers holding a
  cylinder with their tips: the object drifts 50 um within 0.09 s without it, 24 um with it) and
  which is zero on the planned path. It acts during object motions (the contacts the step keeps)
  and while the grasp holds: the start ramp (every contact of the start), a release (the
  contacts it keeps, at the configuration before), a contact (the grasp before, then the grasp
  with the new contact at the planned end) and the optional ``final_hold``. While the grasp
  holds still (releases, contacts, the final hold; not the start ramp, while the load comes on),
  a **joint servo** (``options.hold_rate``, stiffness ``hold_rate b_q``, the Allegro's 3.1 N m/rad
  at the default 500/s, a real Allegro's servo of about 3 N m/rad) also holds the joint motions
  that move the contact points, at the configuration the hold starts from (the simulated one: a
  hold does not undo an earlier step's error). A hold is the place a plan claims that its holding
  torque (18) balances the object; that torque does no first-order work along any motion its
  sticking contacts allow (``G f = -w_ex``, ``tau = J^T f``), so under torque control alone a hold
  is neutral to first order and decided by second-order geometry the analysis does not model
  (point contacts glued; MuJoCo's tip spheres roll): the Allegro's four-tip grasp drifts 66 um in
  its 0.09 s and 0.81 mm in 0.2 s more, at a growing rate, a figure of the hold's length, not of
  the plan. A real hand holds its posture with a servo and the plan's torque as feed-forward; the
  servo's largest torque is reported (``hold_servo``, per step and over the run against the
  largest holding torque), and a stationary grasp leaves it little to do (the bundled plans:
  at most 4 % of their holding torque). **Object motions never get the servo**: the object is
  moved by the plan's torque (32) and the self-motion posture, which moves no contact. The
  fingers' joint damping ``b_q`` is lowered during an object motion whose joints turn faster
  than ``1/s`` per unit object motion (:func:`sim.mjcf.damping`, ``phi`` from the step's paths),
  in the joint motions that move the contacts (the self-motion keeps the nominal damping through
  the posture torque, else a constant torque's self-motion part drifts the posture faster):
  the analysis' fingers are massless, and the damping's torque would otherwise load the contacts
  with forces the analysis does not have (the nine-contact wrap's lift, ``s phi = 3.15``). The
  replay states all this in :attr:`PlanSimulation.control`; or
* **driven** (it has no contact: it is moving to or from the object along its planned joint
  path, or waiting): it follows the planned joint waypoints *kinematically*. Before every
  MuJoCo step its joints' ``qpos`` is set to the path at ``t``, ``qvel`` to the path's velocity
  over the step, and its motors apply ``b_q qdot`` (``b_q`` the joint damping), so that, absent
  contacts, the step ends on the path at ``t + h``. A position servo was not used: the links'
  masses are tiny (``inertia_time`` times the damping, a millisecond time constant) and a
  feedback gain stiff enough to hold a finger against contact forces would be explicit in
  Python and unstable at the 0.2 ms step; a kinematic finger is exact and unconditionally
  stable. The *tracking error* reported is ``max |q(t + h) - q_path(t + h)|`` after the step,
  before the next reset: zero to round-off while the finger moves freely, large if it ran into
  something (the object included) during the step.

Steps (``kind`` of :class:`planner.transition.Transition`)
----------------------------------------------------------
Start: torques and the scene's external wrench rise together from zero (the smooth ramp
``3x^2 - 2x^3`` of :func:`sim.torque_replay.smooth_ramp` over ``params.ramp_time``) to the first step's
stationary torque ``tau_st`` (18), then settle. Every later change of torque is the same smooth
ramp from the torque in force to the new one. Each step first ramps to its own
``torques.stationary`` (a no-op when the previous step already ends there, which is the usual
case).

* ``release`` (33, F -> D): the ramp to the step's ``tau_st`` unloads the releasing finger (its
  entries are zero: it carries no contact of the combination) while the remaining contacts hold
  the object; then the finger is driven along the step's ``joint_path`` (blended from the
  simulated configuration into the planned one) while the others keep ``tau_st``. A finger that
  lets go of some of its links and keeps others (a link release, :mod:`planner.link_release`)
  keeps touching, so it stays torque-controlled with ``tau_st``; its path moves none of its kept
  contact points (the planner projects it onto them), so it is a self-motion, and the posture
  torque, its reference moving along the path (rate at least ``3 / T`` for the move time ``T``),
  takes the finger along it: the released link comes off the object (the Allegro thumb's pad,
  ``tests/sim/test_mjcf_urdf_geometry.py``) and no force is pushed onto the object. Along the
  release path the torque goes from the step's ``tau_st`` (at the path's start) to the holding
  torque of the grasp after the step (the next step's ``tau_st``, else the final grasp's), with
  the path's progress, and the settle holds with the latter: a link release turns the finger's
  kept links, so their contact Jacobians and the torque that holds (18) change with the path
  (the Allegro thumb: 0.0087 N m on its second joint, 17 %; kept at ``tau_st`` the unbalanced
  difference drifted the grasp 30 um against the servo, 44.5 um in all, 6.4 % of the 0.7 mm
  floor; now 15.5 um, 2.2 %). For a whole finger's release the two torques are the same (the
  kept fingers do not move) and nothing changes.
* ``contact`` (33, D -> F): the moving finger is driven along ``joint_path`` (the OMPL transfer,
  last waypoint touching) while the others hold with ``tau_st``; on arrival it becomes
  torque-controlled and the torques ramp to the holding torque of the grasp after the step.
* ``object_motion`` (30-32): ramp to ``torques.chosen`` (a member of T, eq. 32) and run until
  the object has moved from its pose at the start of the step by the planned distance
  ``|object_path[-1] - object_path[0]|`` (norm of the displacement ``dr`` of
  :func:`sim.torque_replay.simulate_torques`: ``(dx, dy, dtheta)`` or ``(dp, w)``); the ramp
  back to the holding torque starts ``v T / 2`` before that distance (``v`` the current speed of
  ``|dr|``, ``T`` the ramp time), which is how far a quasi-static object still travels while the
  excess torque ramps down, so the object comes to rest near the planned distance rather than
  beyond it (measured: 1.4-1.5 % beyond it in both examples; the ramp-down lets the loaded
  contacts relax a little more than ``v T / 2``). Free fingers (none in the usual plans) are
  driven along their ``joint_path`` columns in proportion to the object's progress.

The holding torque of the grasp after a step is the ``torques.stationary`` of the *next* step
(the planner computes it on that grasp: for a following ``release`` the stationary torque of the
remaining contacts, for a ``contact`` or ``object_motion`` the stationary torque of the grasp or
of the combination in force). After the *last* step the holding torque is ``tau_st`` (18, most
interior, all contacts sticking) of the final grasp: the plan's ``final_holding_torque``
(computed by the planner), or for plan files without it, rebuilt from the file by
:func:`sim.final_grasp.final_holding_torque` (bodies ``contacts_after`` at
``contact_points_after``, ``joint_path[-1]``, ``object_path[-1]``; normals from the object's
surface, which the plan file does not store). Without it (a mesh object, an inconsistent grasp)
an ``object_motion`` holds with its own ``torques.stationary`` (computed at the pose *before*
the motion, so not quite stationary after it: in the planar example the object then creeps on
at about 0.015 per second) and a ``contact`` keeps the torque in force. Every step ends with
``settle_time`` of holding.

Monitoring and report
---------------------
Every MuJoCo step the object's pose is compared with the planned object path of the moment (the
constant pose of a regrasp step, the polyline ``object_path`` of an object motion) in the
metric ``|dp| + s |dtheta|`` of ``simulate_torques`` (:func:`sim.plan_paths.path_deviation`,
``s`` the object size, :func:`analysis.geometry.object_size`). The object is **dropped** when
that deviation exceeds ``params.drop_rel * s``, when no contact pushes on the object for
``unloaded_time`` while some load is applied (a torque or the external wrench is non-zero), or
when the state stops being finite. The run stops at a drop. Displacements are pose-vector
differences (:meth:`analysis.pose.Pose.vector`: 2-D ``(x, y, theta)``, 3-D ``(p, rotation
vector)``), the same definition as the plan's ``displacement``.

The outcome is measured on the final pose, position and rotation apart (:class:`PoseError`): the
position error ``|p_sim - p_plan|`` in scene units (metres) and the rotation error, the angle of
``R_plan^T R_sim`` in radians. Each is also given relative to the planned displacement, the
planned translation ``t = |dp|`` and rotation angle ``theta``: the position error over
``max(t, theta s, 0.01 s)`` and the rotation error over ``max(theta, t / s, 0.01)`` (``s`` the
object size; a rotation ``e`` moves the object's surface by about ``e s``, so a plan that only
translates judges its rotation error against ``t / s``, one that only rotates its position error
against ``theta s``, and a plan that does not move the object at all against 1 % of its size).
The replay is within ``tolerance`` when neither relative error exceeds it (and nothing was
dropped); ``ctp simulate`` exits with code 3 otherwise.

The object's path is recorded along the run (:class:`ObjectPath`, ``PlanSimulation.object_path``):
its pose vector every ``options.path_interval`` simulated seconds (5 ms) and at the end of the
start ramp and of every step, each sample tagged with its step, so the dashboard can draw it over
the planned ``object_path`` and each step's ``simulated`` displacement is the difference of its
last sample and the last sample before the step.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError, SolverTimeLimit
from analysis.geometry import object_size
from analysis.kinematics import BodyRef, HandKinematics
from analysis.pose import Pose
from analysis.scene import Scene
from planner.plan import Plan, PlanStep
from planner.transition import Transition
from sim.final_grasp import holding_torque_after
from sim.mjcf import (
    DEFAULT_PARAMS,
    OBJECT_BODY,
    OBJECT_GEOM,
    SimulationParams,
    build_model,
    external_xfrc,
    finger_dof_addresses,
    finger_qpos_addresses,
    force_scale,
    geom_of_contact,
    joint_speed_factor,
    object_pose,
    reset_to_scene,
)
from sim.plan_paths import (
    Mask,
    arc_fractions,
    driven_profile,
    interp_rows,
    joint_speed_ratio,
    move_time,
    path_deviation,
)
from sim.torque_replay import self_motion_projector, self_motion_torque, smooth_ramp

# --------------------------------------------------------------------------------------------
# Options and results


@dataclass(frozen=True)
class PlanSimulationOptions:
    """Timing of the continuous replay (seconds; speeds in rad/s)."""

    #: peak joint-space speed (rad/s) of a driven finger. The object creeps while a regrasp lasts
    #: (MuJoCo's soft friction: sticking contacts under tangential load creep at a rate set by
    #: ``impratio`` and ``solimp``), so slower transfers cost accuracy: in the planar example
    #: 2 rad/s gives a 4.5 % final error, 4 rad/s 2.8 %.
    joint_speed: float = 4.0
    min_move_time: float = 0.02  # shortest finger move (a release path is a few hundredths of a rad)
    settle_time: float = 0.02  # holding at the end of every step (and after the start ramp)
    #: an object motion gives up after this long (then reported short): the quasi-static replay's speed
    #: is its damping's, not the plan's; the Panda's pivot turns at about 0.02/s and needs ~6 s
    motion_time: float = 8.0
    unloaded_time: float = 0.05  # no loaded contact for this long (while loaded) means dropped
    tolerance: float = 0.05  # relative position and rotation errors the replay must meet (PoseError)
    path_interval: float = 0.005  # simulated seconds between two samples of the object path (ObjectPath)
    #: 1/s; > 0 adds to the torque-controlled joints a posture torque on the hand's self-motion only
    #: (:func:`sim.torque_replay.self_motion_torque`, gains ``posture_rate * b_q``: the self-motion
    #: returns to the planned posture at this rate), which no contact force can balance and which
    #: vanishes on the planned path, as a whole-arm controller holds a redundant arm's posture
    #: (without it the Panda's push loses the box: its self-motion is unstable under constant
    #: torques; the same holds while a grasp holds still, the start and regrasps); 0: pure torque
    #: control, the paper's model alone
    posture_rate: float = 50.0
    #: 1/s; > 0 holds, while the grasp holds still (releases, contacts, the final hold; not during
    #: the start ramp, while the load comes on, nor ever during an object motion, which the plan's
    #: torque alone must produce), the joint motions of the touching fingers that move
    #: their contact points at the configuration the hold starts from, gains ``hold_rate * b_q``
    #: (stiffness, N m/rad): a real hand's joint servo holding its posture. The analysis' holding
    #: torque (18) does no first-order work along any motion its sticking contacts allow, so under
    #: torque control alone a hold is decided at second order, by the geometry of the contacts
    #: (MuJoCo's tip spheres roll): the Allegro's four-tip grasp drifts on at millimetres per
    #: second. The servo's largest torque is reported per step (``hold_servo``): a stationary
    #: grasp needs none of it; 0: pure torque control in holds too
    hold_rate: float = 500.0
    #: seconds the final grasp goes on holding (its holding torque, the posture torque) after the
    #: last step, a check of how it keeps the object; the final pose is taken after it (0: none)
    final_hold: float = 0.0

    def __post_init__(self) -> None:
        if not self.path_interval > 0:
            raise ValueError(f"path_interval: must be positive (got {self.path_interval!r})")
        if not (self.final_hold >= 0 and np.isfinite(self.final_hold)):
            raise ValueError(f"final_hold: must be a finite time >= 0 in s (got {self.final_hold!r})")
        if not (self.posture_rate >= 0 and np.isfinite(self.posture_rate)):
            raise ValueError(f"posture_rate: must be a finite rate >= 0 in 1/s (got {self.posture_rate!r})")
        if not (self.hold_rate >= 0 and np.isfinite(self.hold_rate)):
            raise ValueError(f"hold_rate: must be a finite rate >= 0 in 1/s (got {self.hold_rate!r})")


DEFAULT_OPTIONS = PlanSimulationOptions()


#: the smallest planned motion the relative errors are taken against, in object sizes (position)
#: and radians (rotation): a plan that does not move the object is judged against 1 % of its size
REST_SCALE = 0.01


@dataclass(frozen=True)
class PoseError:
    """How far a simulated pose ended from the planned one, position and rotation apart.

    ``position`` (scene units) and ``rotation`` (radians) are the errors; ``planned_translation``
    (scene units) and ``planned_rotation`` (radians) the planned motion they are judged against;
    ``position_scale`` (scene units) and ``rotation_scale`` (radians) the planned motion's scales
    of the module docstring, and ``relative_position`` and ``relative_rotation`` the errors over
    them (no unit)."""

    position: float
    rotation: float
    planned_translation: float
    planned_rotation: float
    position_scale: float
    rotation_scale: float
    relative_position: float
    relative_rotation: float

    @classmethod
    def of(cls, start: Pose, planned: Pose, simulated: Pose, size: float) -> PoseError:
        """The error of ``simulated`` against ``planned``, the planned motion from ``start``."""
        pos = float(np.linalg.norm(simulated.position - planned.position))
        rot = simulated.rotation_angle_to(planned)
        t = float(np.linalg.norm(planned.position - start.position))
        th = planned.rotation_angle_to(start)
        return cls.of_errors(pos, rot, t, th, size)

    @classmethod
    def of_errors(cls, position: float, rotation: float, translation: float, turn: float, size: float) -> PoseError:
        """From the errors and the planned translation and rotation angle (see the module docstring)."""
        p_scale = max(translation, turn * size, REST_SCALE * size)
        r_scale = max(turn, translation / size, REST_SCALE)
        return cls(position, rotation, translation, turn, p_scale, r_scale, position / p_scale, rotation / r_scale)

    @property
    def relative(self) -> float:
        """The larger of the two relative errors."""
        return max(self.relative_position, self.relative_rotation)

    def to_json(self) -> dict[str, float]:
        return {"position_error": self.position, "rotation_error": self.rotation,
                "planned_translation": self.planned_translation, "planned_rotation": self.planned_rotation,
                "position_scale": self.position_scale, "rotation_scale": self.rotation_scale,
                "relative_position_error": self.relative_position,
                "relative_rotation_error": self.relative_rotation}

    def describe(self, tolerance: float) -> str:
        """One line: both errors with their units and relative values."""
        return (f"position error {self.position:.3g} m ({self.relative_position:.2%} of {self.position_scale:.3g} m), "
                f"rotation error {self.rotation:.3g} rad ({self.relative_rotation:.2%} of "
                f"{self.rotation_scale:.3g} rad); planned {self.planned_translation:.3g} m and "
                f"{self.planned_rotation:.3g} rad; tolerance {tolerance:.0%} each")


@dataclass(frozen=True)
class ObjectPath:
    """The simulated object pose along the replay, sampled every ``interval`` simulated seconds
    (the first MuJoCo step at or after each multiple) and at the end of the start ramp and of
    every step, so that the last sample of step ``k`` is the pose its ``simulated`` displacement
    ends at and the last sample of the step before (or of the start ramp) the pose it starts from.

    ``times`` ``(T,)`` simulated seconds from the start, non-decreasing; ``poses`` ``(T, D)`` pose
    vectors (:meth:`analysis.pose.Pose.vector`: 2-D ``(x, y, theta)``, 3-D ``(p, rotation
    vector)``, as the plan's ``object_path``); ``steps`` ``(T,)`` the index of the plan step
    during which the sample was taken, ``-1`` for the start ramp (the first sample, at time 0,
    is the start pose)."""

    interval: float
    times: Array  # (T,)
    poses: Array  # (T, D)
    steps: Array  # (T,) int

    def of_step(self, index: int) -> Array:
        """The samples of step ``index`` preceded by the last sample before it ``(k + 1, D)``:
        the path from the pose the step starts at to the pose it ends at."""
        sel = np.flatnonzero(self.steps == index)
        if sel.size == 0:
            return np.zeros((0, self.poses.shape[1]))
        return np.asarray(self.poses[max(0, int(sel[0]) - 1): int(sel[-1]) + 1])

    def to_json(self) -> dict[str, Any]:
        return {"interval": self.interval, "times": self.times.tolist(), "poses": self.poses.tolist(),
                "steps": [int(k) for k in self.steps]}


@dataclass(frozen=True)
class StepSimulation:
    """One step of the continuous replay."""

    index: int
    kind: str
    combination: str
    driven_finger: str | None  # the finger that releases or makes contact (None: object motion)
    planned: Array  # (D,) planned object displacement of the step (dp and the turn log(R R_0^T))
    simulated: Array  # (D,) simulated displacement over the step
    max_deviation: float  # largest |dp| + s |dtheta| from the planned object path during the step
    tracking_error: float  # rad, largest per-step tracking error of driven fingers (0: none driven)
    joint_error: float  # rad, max |q - joint_path[-1]| over all joints at the end of the step
    duration: float  # simulated seconds
    dropped: bool
    note: str
    #: N m, the largest torque of the hold servo in the step (``PlanSimulationOptions.hold_rate``;
    #: 0 during object motions, which have none): what the holding torque left to the servo
    hold_servo: float = 0.0
    #: a ``slide``: the sliding contact's displacement ``(d,)`` as planned (the link's body point) and
    #: as simulated (MuJoCo's contact point between the link and the object nearest to the planned
    #: one, end minus start of the slide); None for other steps
    slide_planned: Array | None = None
    slide_simulated: Array | None = None

    @property
    def slide_error(self) -> float | None:
        """``|simulated - planned| / |planned|`` of a slide's contact displacement (None: not a slide)."""
        if self.slide_planned is None or self.slide_simulated is None:
            return None
        return float(np.linalg.norm(self.slide_simulated - self.slide_planned) / np.linalg.norm(self.slide_planned))

    def to_json(self) -> dict[str, Any]:
        out = {
            "index": self.index, "kind": self.kind, "combination": self.combination,
            "driven_finger": self.driven_finger, "planned": self.planned.tolist(),
            "simulated": self.simulated.tolist(), "max_deviation": self.max_deviation,
            "tracking_error": self.tracking_error, "joint_error": self.joint_error,
            "duration": self.duration, "dropped": self.dropped, "note": self.note,
            "hold_servo": self.hold_servo,
        }
        if self.slide_planned is not None and self.slide_simulated is not None:
            out.update(slide_planned=self.slide_planned.tolist(), slide_simulated=self.slide_simulated.tolist(),
                       slide_error=self.slide_error)
        return out


@dataclass(frozen=True)
class PlanSimulation:
    """Outcome of :func:`simulate_plan`."""

    steps: tuple[StepSimulation, ...]
    start_pose: Array  # (D,) planned (and simulated) start pose vector
    planned_final_pose: Array  # (D,)
    simulated_final_pose: Array  # (D,)
    object_size: float
    force_scale: float  # F of the model (damping and masses), from the largest torque of the plan
    dropped: bool
    drop_reason: str
    duration: float  # simulated seconds
    tolerance: float
    object_path: ObjectPath  # the simulated object pose along the run, sampled
    #: the hand configuration ``(M,)`` and MuJoCo's contact points of the object (MuJoCo body name
    #: of the touching link or fixed body -> world point ``(d,)``) once the start ramp has settled
    #: and at the end: where a rolling contact really went (not in the JSON)
    start_q: Array | None = None
    final_q: Array | None = None
    start_contacts: dict[str, Array] | None = None
    final_contacts: dict[str, Array] | None = None
    #: how the hand was controlled, in words (:func:`control_model`), for the replay's output
    control: str = ""
    #: N m: the hold servo's largest torque anywhere in the run (start ramp, steps, final hold) and
    #: the largest joint torque of the plan's holding torques (18), which a stationary grasp needs
    hold_servo: float = 0.0
    holding_torque: float = 0.0

    @property
    def hold_servo_share(self) -> float:
        """The hold servo's largest torque over the largest holding torque (no unit; 0 without
        either): how much of holding the object the servo, not the plan's torque, did."""
        return self.hold_servo / self.holding_torque if self.holding_torque > 0 else 0.0

    @property
    def planned(self) -> Array:
        """Planned total displacement ``(D,)``: ``dp`` and the turn ``log(R R_0^T)``
        (:meth:`analysis.pose.Pose.displacement_from`, as ``Plan.displacement``)."""
        return _displacement(self.start_pose, self.planned_final_pose)

    @property
    def simulated(self) -> Array:
        """Simulated total displacement ``(D,)``, as :attr:`planned`."""
        return _displacement(self.start_pose, self.simulated_final_pose)

    @property
    def error(self) -> PoseError:
        """Position (scene units) and rotation (radians) error of the final pose, each also
        relative to the planned displacement (:class:`PoseError`)."""
        d = len(self.start_pose) // 3 + 1  # D = 3 (2-D) or 6 (3-D)
        return PoseError.of(Pose.from_vector(self.start_pose, d), Pose.from_vector(self.planned_final_pose, d),
                            Pose.from_vector(self.simulated_final_pose, d), self.object_size)

    @property
    def relative_error(self) -> float:
        """The larger of the relative position and rotation errors of the final pose (no unit)."""
        return self.error.relative

    @property
    def max_regrasp_deviation(self) -> float:
        """Largest ``|dp| + s |dtheta|`` of the object from its planned pose during regrasp steps."""
        return max((s.max_deviation for s in self.steps if s.kind != "object_motion"), default=0.0)

    @property
    def tracking_error(self) -> float:
        """Largest per-step tracking error (rad) of the driven fingers."""
        return max((s.tracking_error for s in self.steps), default=0.0)

    @property
    def ok(self) -> bool:
        """Not dropped, the position and the rotation each within ``tolerance`` of the planned
        displacement (:attr:`error`), and every ``slide``'s contact displacement within ``tolerance``
        of the planned one (:attr:`StepSimulation.slide_error`; a slide whose link MuJoCo does not
        find touching the object fails)."""
        slides = [s.slide_error for s in self.steps if s.kind == "slide"]
        return (not self.dropped) and len(self.steps) > 0 and self.relative_error <= self.tolerance and all(
            e is not None and e <= self.tolerance for e in slides)

    def to_json(self) -> dict[str, Any]:
        return {
            "ok": self.ok, "dropped": self.dropped, "drop_reason": self.drop_reason,
            "relative_error": self.relative_error, **self.error.to_json(),
            "tolerance": self.tolerance, "planned": self.planned.tolist(), "simulated": self.simulated.tolist(),
            "start_pose": self.start_pose.tolist(), "planned_final_pose": self.planned_final_pose.tolist(),
            "simulated_final_pose": self.simulated_final_pose.tolist(),
            "max_regrasp_deviation": self.max_regrasp_deviation, "tracking_error": self.tracking_error,
            "object_size": self.object_size, "force_scale": self.force_scale, "duration": self.duration,
            "steps": [s.to_json() for s in self.steps], "object_path": self.object_path.to_json(),
            "control": self.control, "hold_servo": self.hold_servo, "holding_torque": self.holding_torque,
            "hold_servo_share": self.hold_servo_share,
        }


# --------------------------------------------------------------------------------------------
# The simulation


class _Drop(Exception):
    pass


class _Run:
    """The one MuJoCo simulation of a plan and its monitoring."""

    def __init__(self, scene: Scene, hand: HandKinematics, params: SimulationParams, tau_scale: Array,
                 options: PlanSimulationOptions):
        self.scene, self.hand, self.params, self.options = scene, hand, params, options
        self.dim, self.D = scene.dim, scene.D
        self.s = object_size(scene)
        self.F = force_scale(scene, tau_scale)
        self.model = build_model(scene, params, tau_scale)
        self.data = mujoco.MjData(self.model)
        reset_to_scene(self.model, self.data)
        self.h = float(params.timestep)
        self.qadr = finger_qpos_addresses(self.model, scene)  # (M,)
        self.dadr = finger_dof_addresses(self.model, scene)  # (M,)
        self.b_q = np.array(self.model.dof_damping[self.dadr])  # (M,) the joints' damping now
        #: (M,) the nominal finger damping, the posture and servo gains per unit rate: an object motion
        #: lowers ``b_q`` for its joint speeds (joint_damping), the posture holds as stiffly
        self.b_posture = self.b_q.copy()
        self.lowered: list[float] = []  # the factors by which object motions lowered the damping
        self.obj_id = self.model.body(OBJECT_BODY).id
        self.obj_geom = self.model.geom(OBJECT_GEOM).id
        self.xfrc = external_xfrc(scene)  # (6,)
        self.w_on = 0.0  # fraction of the external wrench applied
        self.tau = np.zeros(hand.M)  # (M,) torque in force
        self.t = 0.0
        self.unloaded = 0.0
        # per-step accumulators
        self.max_dev = 0.0
        self.track = 0.0
        # the sampled object path (ObjectPath): times, pose vectors, step index (-1: start ramp)
        self.step_index = -1
        self.path_t: list[float] = [0.0]
        self.path_pose: list[Array] = [self.pose().vector()]
        self.path_step: list[int] = [-1]
        self.next_sample = float(options.path_interval)
        self.posture: Callable[[Array], Array] | None = None  # q (M,) -> self-motion torque (M,)
        self.time_limit: float | None = None  # wall-clock seconds the run may take (simulate_plan)
        self.deadline = math.inf  # time.monotonic() at which the run stops
        self.mj_steps = 0
        self.hold_servo = 0.0  # N m, the hold servo's largest torque in the step (_hold_posture)
        self.hold_servo_max = 0.0  # N m, and in the whole run

    def joint_damping(self, factor: float) -> None:
        """Set the fingers' joint damping to the nominal one over ``factor`` (>= 1): an object
        motion whose joints turn fast (:func:`sim.mjcf.damping`); 1 restores it."""
        self.b_q = self.b_posture / factor
        self.model.dof_damping[self.dadr] = self.b_q
        if factor > 1.0:
            self.lowered.append(factor)

    def gains(self, rate: float) -> Array:
        """``rate * b_posture`` ``(M,)`` (N m/rad), the stiffness of a posture or servo torque, at
        most ``STABLE_GAIN b_q / h`` (the torque is explicit, evaluated before each MuJoCo step)."""
        return np.minimum(rate * self.b_posture, STABLE_GAIN * self.b_q / self.h)

    def sample(self) -> None:
        """Record the object's pose now in the path (replacing a sample of the same step taken at
        the same time; a step that took no time still gets its own sample)."""
        if self.path_t[-1] == self.t and self.path_step[-1] == self.step_index:
            self.path_pose[-1] = self.pose().vector()
            return
        self.path_t.append(self.t)
        self.path_pose.append(self.pose().vector())
        self.path_step.append(self.step_index)

    def object_path(self) -> ObjectPath:
        return ObjectPath(float(self.options.path_interval), np.array(self.path_t),
                          np.array(self.path_pose).reshape(len(self.path_t), self.D),
                          np.array(self.path_step, dtype=int))

    # -- state --------------------------------------------------------------------------------

    def pose(self) -> Pose:
        """The object's pose now."""
        return object_pose(self.model, self.data, self.dim)

    def q(self) -> Array:
        return np.array(self.data.qpos[self.qadr])  # (M,)

    def object_contacts(self) -> dict[str, Array]:
        """MuJoCo's contacts of the object now: the touching body's name -> world point ``(d,)``."""
        m, d = self.model, self.data
        out: dict[str, Array] = {}
        for j in range(d.ncon):
            c = d.contact[j]
            g1, g2 = int(c.geom1), int(c.geom2)
            if self.obj_geom in (g1, g2):
                other = g2 if g1 == self.obj_geom else g1
                out[m.body(int(m.geom_bodyid[other])).name] = np.array(c.pos[: self.dim])
        return out

    def _loaded(self) -> bool:
        d = self.data
        n = d.ncon
        if n == 0:
            return False
        c = d.contact
        g1, g2, adr = c.geom1[:n], c.geom2[:n], c.efc_address[:n]
        sel = ((g1 == self.obj_geom) | (g2 == self.obj_geom)) & (adr >= 0)
        return bool(np.any(d.efc_force[adr[sel]] > 0.0))

    # -- stepping -----------------------------------------------------------------------------

    def run(
        self,
        duration: float,
        tau_of: Callable[[float], Array],
        planned_path: Array,
        driven: Mask,
        q_of: Callable[[float], Array] | None = None,
        stop: Callable[[float], bool] | None = None,
    ) -> None:
        """Advance ``duration`` seconds (or until ``stop(local time)``): torque ``tau_of(t)``
        ``(M,)`` on torque-controlled joints, joints in ``driven`` ``(M,)`` on ``q_of(t)`` ``(M,)``;
        the object is monitored against ``planned_path`` ``(k, D)``. Raises :class:`_Drop`."""
        h = self.h
        n = max(1, math.ceil(duration / h - 1e-9))
        d, m = self.data, self.model
        qa, da = self.qadr[driven], self.dadr[driven]
        any_driven = bool(np.any(driven))
        for k in range(n):
            t = k * h
            tau = tau_of(t + 0.5 * h)
            ctrl = tau.copy()
            if self.posture is not None:
                ctrl[~driven] += self.posture(self.q())[~driven]
            if any_driven:
                assert q_of is not None
                q_now, q_next = q_of(t)[driven], q_of(t + h)[driven]
                v = (q_next - q_now) / h
                d.qpos[qa] = q_now
                d.qvel[da] = v
                ctrl[driven] = self.b_q[driven] * v
            self.tau = tau
            d.ctrl[:] = ctrl
            d.xfrc_applied[self.obj_id] = self.w_on * self.xfrc
            mujoco.mj_step(m, d)
            self.t += h
            self.mj_steps += 1
            if self.mj_steps % 256 == 0 and time.monotonic() > self.deadline:
                raise SolverTimeLimit("mujoco", f"the replay reached its time limit of {self.time_limit:.3g} s "
                                                f"(wall clock) after {self.t:.3g} s of simulated time")
            if self.t >= self.next_sample - 1e-12:
                self.sample()
                while self.next_sample <= self.t + 1e-12:
                    self.next_sample += self.options.path_interval
            if any_driven:
                self.track = max(self.track, float(np.max(np.abs(d.qpos[qa] - q_next))))
            self._monitor(planned_path, tau)
            if stop is not None and stop(t + h):
                return

    def _monitor(self, planned_path: Array, tau: Array) -> None:
        d = self.data
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            raise _Drop("the simulation diverged")
        dev = path_deviation(self.pose(), planned_path, self.s)
        self.max_dev = max(self.max_dev, dev)
        if dev > self.params.drop_rel * self.s:
            raise _Drop(f"the object left the planned path by {dev:.3g} > {self.params.drop_rel * self.s:.3g}")
        load = (self.w_on > 0 and bool(np.any(self.xfrc))) or bool(np.any(np.abs(tau) > 0))
        self.unloaded = 0.0 if (not load or self._loaded()) else self.unloaded + self.h
        if self.unloaded > self.options.unloaded_time:
            raise _Drop(f"no contact pushed on the object for {self.unloaded:.3g} s")

    def ramp_to(self, target: Array, planned_path: Array, driven: Mask, q_hold: Array,
                wrench: bool = False, settle: bool = True) -> None:
        """Smoothly change the torque in force to ``target`` ``(M,)`` over ``params.ramp_time``
        (with ``wrench``: the external wrench rises from zero with it), then settle."""
        T = self.params.ramp_time
        tau0 = self.tau.copy()
        target = np.asarray(target, dtype=float)
        if wrench:
            def tau_w(t: float) -> Array:
                lam = smooth_ramp(t, T)
                self.w_on = lam
                return tau0 + lam * (target - tau0)
            self.run(T, tau_w, planned_path, driven, lambda t: q_hold)
            self.w_on = 1.0
        elif not np.allclose(tau0, target, rtol=0.0, atol=1e-12 * (1.0 + float(np.max(np.abs(target))))):
            self.run(T, lambda t: tau0 + smooth_ramp(t, T) * (target - tau0), planned_path, driven, lambda t: q_hold)
        self.tau = target
        if settle:
            self.run(self.options.settle_time, lambda t: target, planned_path, driven, lambda t: q_hold)


def _constant(tau: Array) -> Callable[[float], Array]:
    """The torque schedule ``t -> tau`` ``(M,)``."""
    return lambda t: tau


def _mask(hand: HandKinematics, fingers: set[int]) -> Mask:
    m = np.zeros(hand.M, dtype=bool)
    for f in fingers:
        m[hand.finger_slice(f)] = True
    return m


def _fingers_touching(hand: HandKinematics, bodies: tuple[str, ...]) -> set[int]:
    return {f for b in bodies if (f := hand.finger_of(b)) is not None}


def _moving_finger(hand: HandKinematics, st: Transition) -> int | None:
    """The finger whose joints move along the step's path, else the one whose body appears in only
    one of contacts_before / contacts_after."""
    span = np.ptp(st.q_path, axis=0)  # (M,)
    moving = [f for f in range(len(hand.fingers)) if float(np.max(span[hand.finger_slice(f)], initial=0.0)) > 1e-9]
    if len(moving) == 1:
        return moving[0]
    changed = _fingers_touching(hand, tuple(set(st.contacts_before) ^ set(st.contacts_after)))
    return next(iter(changed)) if len(changed) == 1 else (moving[0] if moving else None)


def simulate_plan(
    scene: Scene,
    plan: Plan | Mapping[str, Any],
    *,
    params: SimulationParams = DEFAULT_PARAMS,
    options: PlanSimulationOptions = DEFAULT_OPTIONS,
    time_limit: float | None = None,
) -> PlanSimulation:
    """Replay a whole plan in one MuJoCo simulation (see the module docstring).

    ``time_limit`` (wall-clock seconds, from the call): past it the run stops with
    :class:`analysis.exceptions.SolverTimeLimit` (the service's plan jobs replay within what is
    left of their own limit).

    ``plan``: a :class:`planner.plan.Plan` or its JSON form (``Plan.to_json()``, a ``ctp plan
    --out`` file, read by :meth:`Plan.from_json`); ``scene`` the scene it was planned from. A
    ``Plan`` is replayed as its file would be (through ``to_json``, values rounded to 1e-10), so
    the two give the same run. Raises :class:`SceneError` naming the field when the plan does not
    fit the scene or is not a found plan.
    """
    hand = HandKinematics.from_scene(scene)
    plan = Plan.from_json(plan.to_json() if isinstance(plan, Plan) else plan, scene, hand)
    if not plan.found:
        raise SceneError(("found",), f"the plan was not found ({plan.reason or 'no reason given'}); "
                                     "nothing to replay")
    steps = plan.steps
    torques = [t for st in steps for t in (st.transition.tau_stationary, st.transition.tau) if t is not None]
    tau_scale = max(torques, key=lambda t: float(np.max(np.abs(t)))) if torques else np.zeros(hand.M)
    t_call = time.monotonic()
    if time_limit is not None and not time_limit > 0:
        raise SceneError(("time_limit",), f"must be positive (got {time_limit!r})")
    run = _Run(scene, hand, params, tau_scale, options)
    if time_limit is not None:
        run.time_limit, run.deadline = float(time_limit), t_call + float(time_limit)
    s, dim = run.s, scene.dim
    if run.pose().distance(Pose.from_vector(plan.start_pose, dim), s) > 1e-6 * s:
        raise SceneError(("start_pose",), "is not the scene's object pose: the plan was made for another scene")
    if not np.allclose(steps[0].transition.q_path[0], hand.q0, atol=1e-6):
        raise SceneError(("steps", 0, "joint_path"), "does not start at the scene's finger configuration")

    out: list[StepSimulation] = []
    dropped, reason = False, ""
    # start: torques and external wrench rise together to the first holding torque
    first = steps[0].transition
    hold0 = first.tau_stationary if first.tau_stationary is not None else np.zeros(hand.M)
    busy0 = _fingers_touching(hand, first.contacts_before)
    free0 = _mask(hand, set(range(len(hand.fingers))) - busy0)
    before = steps[0].before
    # no servo while the load comes on: the contacts settle into MuJoCo's geometry (a link across a
    # box's edge starts eps (sqrt 2 - 1) short of the shrunk box and closes the gap under its torque)
    run.posture = _hold_posture(run, hand, _finger_points(hand, before.contacts, "F" * before.L), first.q_path[0],
                                servo=False)
    try:
        run.ramp_to(hold0, first.object_path[:1], free0, first.q_path[0], wrench=True)
    except _Drop as e:
        dropped, reason = True, f"at the start: {e}"
    run.sample()  # the pose the first step starts from
    start_q, start_contacts = run.q(), run.object_contacts()

    for i, step in enumerate(steps):
        if dropped:
            break
        st = step.transition
        nxt = steps[i + 1].transition if i + 1 < len(steps) else None
        t0, pose0 = run.t, run.pose()
        run.max_dev, run.track, run.step_index, run.hold_servo = 0.0, 0.0, step.index, 0.0
        run.posture = None  # an object motion sets its own (options.posture_rate)
        if st.kind != "object_motion":  # the contacts the regrasp keeps hold at the planned posture
            letters = {"release": st.combination, "slide": st.combination.replace("S", "D")}.get(
                st.kind, "F" * step.before.L)  # a release's D lets go, a slide's S is driven
            run.posture = _hold_posture(run, hand, _finger_points(hand, step.before.contacts, letters), st.q_path[0])
        planned = _displacement(st.object_path[0], st.object_path[-1])  # (D,)
        busy_before = _fingers_touching(hand, st.contacts_before)
        busy_after = _fingers_touching(hand, st.contacts_after)
        all_f = set(range(len(hand.fingers)))
        finger = None if st.kind == "object_motion" else _moving_finger(hand, st)
        note = ""
        slide: tuple[Array, Array] | None = None
        try:
            if st.kind == "release":
                tau_st = st.tau_stationary
                assert tau_st is not None
                run.ramp_to(tau_st, st.object_path[:1], _mask(hand, all_f - busy_before), st.q_path[0])
                driven = _mask(hand, all_f - busy_after)
                # a finger that lets go of some links and keeps others (a link release) stays
                # torque-controlled; its path moves none of the kept contact points, so the
                # self-motion posture, following the path, takes it along
                span = np.ptp(st.q_path, axis=0)  # (M,)
                link_release = ~driven & (span > 1e-9)
                T = move_time(st.q_path, driven | link_release, options.joint_speed, options.min_move_time)
                kept = _finger_points(hand, step.before.contacts, st.combination)
                if np.any(link_release) and options.posture_rate > 0:
                    run.posture = _hold_posture(run, hand, kept, st.q_path[0],
                                                moving=_after(run, driven_profile(st.q_path, driven | link_release,
                                                                                  run.q(), T)),
                                                rate=max(options.posture_rate, LINK_RELEASE_TIME_CONSTANTS / T))
                # the holding torque of the grasp after the step (the next step's tau_st, else the
                # final grasp's), reached along the path: a link release moves the finger's kept
                # contacts' Jacobians with it, so tau_st (at the path's start) no longer holds at its end
                after_tau, _ = _hold_after(plan, scene, hand, step, nxt)
                tau_after = tau_st if after_tau is None else after_tau

                def tau_along(t: float, tau0: Array = tau_st, tau1: Array = tau_after, T: float = T) -> Array:
                    return tau0 + smooth_ramp(t, T) * (tau1 - tau0)  # the path's progress (driven_profile)

                run.run(T, tau_along, st.object_path[:1], driven,
                        driven_profile(st.q_path, driven, run.q(), T))
                run.posture = _hold_posture(run, hand, kept, st.q_path[-1])
                run.ramp_to(tau_after, st.object_path[:1], driven, st.q_path[-1])  # settle
                note = f"released in {T:.3g} s" + (" (a link release, by the posture torque)"
                                                    if np.any(link_release) else "")
            elif st.kind == "contact":
                driven = _mask(hand, all_f - busy_before)
                if st.tau_stationary is not None:
                    run.ramp_to(st.tau_stationary, st.object_path[:1], driven, st.q_path[0], settle=False)
                T = move_time(st.q_path, driven, options.joint_speed, options.min_move_time)
                hold = run.tau.copy()
                run.run(T, _constant(hold), st.object_path[:1], driven, driven_profile(st.q_path, driven, run.q(), T))
                after = _mask(hand, all_f - busy_after)
                run.posture = _hold_posture(run, hand, _finger_points(hand, step.after.contacts, "F" * step.after.L),
                                            st.q_path[-1])  # the new contact held too, at the planned end
                after_tau, src = _hold_after(plan, scene, hand, step, nxt)
                run.ramp_to(hold if after_tau is None else after_tau, st.object_path[-1:], after, st.q_path[-1])
                note = f"moved in {T:.3g} s, " + {"next": "loaded with the next step's tau_st",
                                                  "final": "final grasp's tau_st",
                                                  "none": "torque kept (final grasp not rebuilt)"}[src]
            elif st.kind == "slide":
                note, slide = _slide(run, plan, scene, hand, step, nxt)
            else:
                note = _object_motion(run, plan, scene, hand, step, nxt, pose0)
        except _Drop as e:
            dropped, reason = True, f"step {step.index} ({st.kind}): {e}"
            note = str(e)
        out.append(StepSimulation(
            index=step.index, kind=st.kind, combination=st.combination,
            driven_finger=None if finger is None else hand.fingers[finger].name,
            planned=planned, simulated=run.pose().displacement_from(pose0), max_deviation=run.max_dev,
            tracking_error=run.track, joint_error=float(np.max(np.abs(run.q() - st.q_path[-1]))),
            duration=run.t - t0, dropped=dropped, note=note, hold_servo=run.hold_servo,
            slide_planned=None if slide is None else slide[0], slide_simulated=None if slide is None else slide[1],
        ))
        run.sample()  # the pose this step's simulated displacement ends at
    if not dropped and options.final_hold > 0:
        last = steps[-1]
        final_state = last.after
        run.posture = _hold_posture(run, hand, _finger_points(hand, final_state.contacts, "F" * final_state.L),
                                    last.transition.q_path[-1])
        free = _mask(hand, set(range(len(hand.fingers))) - _fingers_touching(hand, last.transition.contacts_after))
        try:
            run.run(options.final_hold, _constant(run.tau.copy()), last.transition.object_path[-1:], free,
                    lambda t: last.transition.q_path[-1])
        except _Drop as e:
            dropped, reason = True, f"while holding after the last step: {e}"
        run.sample()
    return PlanSimulation(
        steps=tuple(out), start_pose=plan.start_pose, planned_final_pose=plan.final_pose,
        simulated_final_pose=run.pose().vector(), object_size=s, force_scale=run.F, dropped=dropped,
        drop_reason=reason, duration=run.t, tolerance=options.tolerance, object_path=run.object_path(),
        start_q=start_q, final_q=run.q(), start_contacts=start_contacts, final_contacts=run.object_contacts(),
        control=control_model(options, run), hold_servo=run.hold_servo_max,
        holding_torque=max((float(np.max(np.abs(t.tau_stationary), initial=0.0)) for st_ in steps
                            if (t := st_.transition).tau_stationary is not None), default=0.0),
    )


#: a posture or servo stiffness ``K`` is at most this times ``b_q / h`` (``h`` the time step): the
#: torque is computed before each step from the configuration then, so ``K h / b_q`` must stay well
#: below 2 (the default rates give 0.01 and 0.1; the wrap's lowered finger damping raises them 9.6x)
STABLE_GAIN = 0.5


#: MuJoCo steps between two evaluations of the self-motion projector of a holding grasp (its
#: Jacobians): the hand hardly moves while it holds, and the posture returns at 50 1/s, slow next to
#: the 5 ms this spans at the 0.2 ms step
HOLD_PROJECTOR_EVERY = 25


#: a link release (the finger keeps other contacts, so it stays torque-controlled and the posture
#: torque takes it along its path) lasts the finger's move time ``T`` with the posture rate raised
#: to at least this many over ``T`` (1/s), so the finger keeps up with its path
LINK_RELEASE_TIME_CONSTANTS = 3.0


def _hold_after(plan: Plan, scene: Scene, hand: HandKinematics, step: PlanStep,
                nxt: Transition | None) -> tuple[Array | None, str]:
    """The torque that holds the grasp once ``step`` is done, and where it comes from: the next
    step's ``tau_st`` (``"next"``), else the final grasp's (``"final"``,
    :func:`sim.final_grasp.holding_torque_after`), else None (``"none"``: not rebuilt)."""
    if nxt is not None and nxt.tau_stationary is not None:
        return nxt.tau_stationary, "next"
    final_tau = holding_torque_after(plan, scene, hand, step)
    return final_tau, "none" if final_tau is None else "final"


def control_model(options: PlanSimulationOptions, run: _Run) -> str:
    """The replay's model of the hand, in words (the module docstring, "Control of the hand")."""
    holds = "holds: the planned holding torque (18)"
    if options.hold_rate > 0:
        k = float(np.max(run.gains(options.hold_rate), initial=0.0))
        holds += (f" and a joint servo ({options.hold_rate:g}/s, {k:.3g} N m/rad) on the touching fingers' joint "
                  "motions that move their contacts, about the configuration each hold starts from")
    else:
        holds += ", torque control only"
    motions = "object motions: the plan's torque (32)"
    if options.posture_rate > 0:
        holds += f"; self-motion posture {options.posture_rate:g}/s"
        motions += f" and the self-motion posture ({options.posture_rate:g}/s), no servo"
    else:
        motions += " only"
    holds += "; a release's torque goes along its path to the holding torque of the grasp after it"
    damp = (f"; finger damping lowered {min(run.lowered):.3g}-{max(run.lowered):.3g}x during the object motions "
            "whose joints turn faster than 1/s per unit object motion" if run.lowered else "")
    return f"{holds}; {motions}{damp}"


def _after(run: _Run, profile: Callable[[float], Array]) -> Callable[[], Array]:
    """``profile`` ``(M,)`` read at the run's time since now."""
    t_start = run.t
    return lambda: profile(run.t - t_start)


def _finger_points(hand: HandKinematics, contacts: Sequence[Any], letters: str) -> list[tuple[BodyRef, Array]]:
    """``(finger body, point in its frame)`` of the contacts (:class:`planner.state.GraspContact`)
    on finger links whose letter is not D."""
    return [(ref, c.point_body) for c, letter in zip(contacts, letters, strict=True)
            if letter != "D" and (ref := hand.resolve_body(c.body)) is not None and ref.finger is not None]


def _hold_posture(run: _Run, hand: HandKinematics, points: list[tuple[BodyRef, Array]],
                  q_ref: Array, moving: Callable[[], Array] | None = None,
                  rate: float | None = None, servo: bool = True) -> Callable[[Array], Array] | None:
    """The posture torque while the grasp holds (the start ramp, regrasp steps, the final hold):
    the hand pulled along its self-motion (joint motions that move none of the contact ``points``)
    towards the planned configuration ``q_ref`` ``(M,)``, or ``moving()`` ``(M,)`` (the planned
    configuration of the moment: a link release), gains ``posture_rate`` (or ``rate``) times
    ``b_posture``; and, with ``options.hold_rate > 0``, the joint motions that do move the contact
    points held at the configuration the hand has now (not the planned one: a hold does not undo
    what the steps before it did), gains ``hold_rate`` times ``b_posture``: the joint servo of a
    real hand holding its posture, which no contact force of a stationary grasp needs
    (:class:`PlanSimulationOptions`; its largest torque is the step's ``hold_servo``); not with
    ``servo=False`` (the start ramp). ``None`` when both rates are 0."""
    opts = run.options
    hold_rate = opts.hold_rate if servo else 0.0
    if not (opts.posture_rate > 0 or hold_rate > 0):
        return None
    gains = run.gains(opts.posture_rate if rate is None else rate)  # (M,)
    stiff = run.gains(hold_rate)  # (M,)
    q_fixed = np.array(q_ref, dtype=float)
    q_now = run.q()  # (M,) the configuration the hold keeps its contacts at
    free: list[slice] = []  # fingers without a contact: their whole configuration is self-motion
    touching: list[tuple[slice, list[tuple[BodyRef, Array]]]] = []  # fingers with contacts
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        mine = [pt for pt in points if pt[0].finger == f]
        if not mine:
            free.append(sl)
            continue
        probe = self_motion_torque(hand, mine, q_fixed, q_fixed + 1.0, np.ones(hand.M))[sl]  # P P 1 on the finger
        # (every joint of a planar two-link finger moves its contact: no self-motion to hold)
        if float(np.max(np.abs(probe))) > 1e-9 or hold_rate > 0:
            touching.append((sl, mine))
    if not free and not touching:
        return None

    projectors: list[Array] = []  # (M, M) per touching finger, renewed every HOLD_PROJECTOR_EVERY calls
    calls = [0]

    def torque(q: Array) -> Array:
        out = np.zeros(hand.M)
        q_ref = q_fixed if moving is None else moving()
        if opts.posture_rate > 0:
            for sl in free:
                out[sl] = gains[sl] * (q_ref[sl] - q[sl])
        if calls[0] % HOLD_PROJECTOR_EVERY == 0:
            projectors[:] = [self_motion_projector(hand, mine, q) for _, mine in touching]
        calls[0] += 1
        servo = np.zeros(hand.M)
        for (sl, _), P in zip(touching, projectors, strict=True):
            if opts.posture_rate > 0:
                out[sl] += (P @ (gains * (P @ (q_ref - q))))[sl]
            if hold_rate > 0:
                Q = np.eye(hand.M) - P  # the joint motions that move the finger's contact points
                servo[sl] = (Q @ (stiff * (Q @ (q_now - q))))[sl]
        top = float(np.max(np.abs(servo), initial=0.0))
        run.hold_servo, run.hold_servo_max = max(run.hold_servo, top), max(run.hold_servo_max, top)
        return out + servo

    return torque


def _posture(run: _Run, hand: HandKinematics, step: PlanStep,
             ref: Callable[[], Array]) -> Callable[[Array], Array] | None:
    """The self-motion posture torque of an object motion (``options.posture_rate > 0``, else
    ``None``): the finger contacts the step keeps (not D) held where they are, the hand pulled
    along its self-motion towards ``ref()`` ``(M,)``, the planned configuration at the moment."""
    rate = run.options.posture_rate
    if not rate > 0:
        return None
    st = step.transition
    points = [(ref_, c.point_body) for c, letter in zip(step.before.contacts, st.combination, strict=True)
              if letter != "D" and (ref_ := hand.resolve_body(c.body)) is not None and ref_.finger is not None]
    gains = run.gains(rate)
    b_self = run.b_posture - run.b_q  # (M,) the damping the self-motion keeps (sim.mjcf.damping)

    def torque(q: Array) -> Array:
        P = self_motion_projector(hand, points, q)  # (M, M)
        return np.asarray(P @ (gains * (P @ (ref() - q))) - P @ (b_self * (P @ run.data.qvel[run.dadr])))

    return torque


def _link_contact_point(run: _Run, geom_body: str, near: Array) -> Array | None:
    """MuJoCo's contact point ``(d,)`` between the object and the link body ``geom_body`` nearest to
    ``near`` ``(d,)`` (the planned contact point) now (None: they do not touch)."""
    m, d = run.model, run.data
    pts = []
    for j in range(d.ncon):
        c = d.contact[j]
        g1, g2 = int(c.geom1), int(c.geom2)
        if run.obj_geom in (g1, g2):
            other = g2 if g1 == run.obj_geom else g1
            if m.body(int(m.geom_bodyid[other])).name == geom_body:
                pts.append(np.array(c.pos[: run.dim]))
    if not pts:
        return None
    return pts[int(np.argmin([float(np.linalg.norm(p - near)) for p in pts]))]


def _slide(run: _Run, plan: Plan, scene: Scene, hand: HandKinematics, step: PlanStep,
           nxt: Transition | None) -> tuple[str, tuple[Array, Array] | None]:
    """A ``slide`` (eq. 33 with an S-point, :mod:`planner.link_slide`): the torques ramp to the
    step's ``tau_st`` (18 of the holding contacts, the sliding finger's entries zero: it carries no
    force), the sliding finger is driven along ``joint_path`` (kinematically, as a free finger: its
    link keeps the planned zero gap, MuJoCo's soft contact pressing what it will) while the others
    hold the object, then it becomes torque-controlled again and the torques ramp to the holding
    torque of the grasp after the step. Returns the note and the planned and simulated contact
    displacements: the link's body point's, and that of MuJoCo's contact of the link nearest to it
    (None where MuJoCo has no contact of the link at the start or the end)."""
    st = step.transition
    assert st.tau_stationary is not None
    i = st.combination.index("S")
    c = step.before.contacts[i]
    ref = hand.resolve_body(c.body)
    assert ref is not None and ref.finger is not None
    driven = _mask(hand, {ref.finger})
    run.ramp_to(st.tau_stationary, st.object_path[:1], driven, st.q_path[0])
    name = geom_of_contact(hand, c.body)
    p0 = hand.point_position(ref, c.point_body, st.q_path[0])
    p1 = hand.point_position(ref, c.point_body, st.q_path[-1])
    x0 = _link_contact_point(run, name, p0)
    T = move_time(st.q_path, driven, run.options.joint_speed, run.options.min_move_time)
    run.run(T, _constant(st.tau_stationary), st.object_path[:1], driven, driven_profile(st.q_path, driven, run.q(), T))
    x1 = _link_contact_point(run, name, p1)
    planned = p1 - p0
    run.posture = _hold_posture(run, hand, _finger_points(hand, step.after.contacts, "F" * step.after.L),
                                st.q_path[-1])
    after_tau, _ = _hold_after(plan, scene, hand, step, nxt)
    run.ramp_to(st.tau_stationary if after_tau is None else after_tau, st.object_path[-1:], _mask(hand, set()),
                st.q_path[-1])
    if x0 is None or x1 is None:
        return f"slid in {T:.3g} s; MuJoCo has no contact of {c.body} at the {'start' if x0 is None else 'end'}", None
    err = float(np.linalg.norm((x1 - x0) - planned) / np.linalg.norm(planned))
    return (f"slid in {T:.3g} s: contact moved {np.linalg.norm(x1 - x0):.4g} (planned {np.linalg.norm(planned):.4g}, "
            f"error {100 * err:.2f} %)"), (planned, x1 - x0)


def _displacement(start: Array, end: Array) -> Array:
    """The displacement ``s`` ``(D,)`` from the pose vector ``start`` to ``end``
    (``Pose.displaced(s)``'s meaning: ``dp`` and, in 3-D, the rotation vector of ``R R_0^T``; the
    pose vectors' difference is not the turn of an object that starts turned)."""
    d = 2 if len(start) == 3 else 3
    return Pose.from_vector(end, d).displacement_from(Pose.from_vector(start, d))


def _object_motion(run: _Run, plan: Plan, scene: Scene, hand: HandKinematics, step: PlanStep,
                   nxt: Transition | None, pose0: Pose) -> str:
    """Eq. (30)-(32): ramp to the chosen torque, move the planned distance, ramp to the holding torque."""
    st = step.transition
    assert st.tau is not None
    options, T = run.options, run.params.ramp_time
    busy = _fingers_touching(hand, st.contacts_before)
    free = _mask(hand, set(range(len(hand.fingers))) - busy)
    # the planned distance in the measure braking() takes of the simulated one (the shortest
    # displacement: dp and log(R R_0^T)); the pose vectors' difference is not it where the object
    # starts turned (a cylinder lying on its side, -90 degrees about x: 12 % more turn than it rolls)
    d = pose0.dim
    dist = float(np.linalg.norm(Pose.from_vector(st.object_path[-1], d).shortest_displacement_from(
        Pose.from_vector(st.object_path[0], d))))
    phi = joint_speed_ratio(st.q_path, st.object_path)
    run.joint_damping(joint_speed_factor(run.s, phi))  # the analysis' fingers are massless: sim.mjcf.damping
    frac_obj = arc_fractions(st.object_path)
    progress = {"u": 0.0, "prev": 0.0, "v": 0.0, "reached": 0.0}
    run.posture = _posture(run, hand, step, lambda: interp_rows(st.q_path, frac_obj, progress["u"]))

    def q_of(t: float) -> Array:  # free fingers follow the object's progress
        return interp_rows(st.q_path, frac_obj, progress["u"])

    def braking(t: float) -> bool:
        r = float(np.linalg.norm(run.pose().shortest_displacement_from(pose0)))
        progress["v"] = (r - progress["prev"]) / run.h
        progress["prev"] = r
        progress["u"] = min(1.0, r / dist) if dist > 0 else 1.0
        if r + max(progress["v"], 0.0) * T / 2 >= dist:
            progress["reached"] = 1.0
            return True
        return False

    if st.tau_stationary is not None:
        run.ramp_to(st.tau_stationary, st.object_path[:1], free, st.q_path[0], settle=False)
    tau0 = run.tau.copy()
    chosen = st.tau
    run.run(options.motion_time, lambda t: tau0 + smooth_ramp(t, T) * (chosen - tau0), st.object_path, free, q_of,
            stop=braking)
    reached = progress["reached"] > 0
    after_tau, which = _hold_after(plan, scene, hand, step, nxt)
    if after_tau is not None:
        hold = after_tau
        src = "the next step's tau_st" if which == "next" else "the final grasp's tau_st"
    else:
        hold = st.tau_stationary if st.tau_stationary is not None else chosen
        src = "its own tau_st (final grasp not rebuilt)"
    run.ramp_to(hold, st.object_path, free, q_of(0.0))
    run.joint_damping(1.0)
    moved = float(np.linalg.norm(run.pose().shortest_displacement_from(pose0)))
    return (f"moved {moved:.4g} of {dist:.4g} planned; held with {src}"
            + ("" if reached else f"; did not reach the distance in {options.motion_time} s"))


__all__ = [
    "DEFAULT_OPTIONS",
    "ObjectPath",
    "PlanSimulation",
    "PlanSimulationOptions",
    "PoseError",
    "StepSimulation",
    "control_model",
    "simulate_plan",
]
