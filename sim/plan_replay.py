"""Continuous MuJoCo replay of a whole plan: one simulation, from the scene, through every step.

:func:`simulate_plan` is the physics check of a plan as a robot would execute it: the object and
the hand start at rest at the scene's configuration and are never reset, so whatever an earlier
step leaves behind (creep of the object during a regrasp, overshoot of an object motion, a new
contact's slight penetration) is carried into the later steps and into the final pose. (The
step-by-step check :func:`sim.step_replay.replay_plan` restarts every step from its planned
state instead.)

Model
-----
One model, :func:`sim.torque_replay.build_model` of the start scene, with the quasi-static
parameters of :mod:`sim.torque_replay` (``DEFAULT_PARAMS``; object damping equal in every
pose coordinate, light finger damping, small masses, see :func:`sim.torque_replay.damping`).
Every link of every finger and every fixed body has a contact pair with the object, so the
contacts a plan makes later are simulated like the scene's own. The force scale (the ``tau``
argument of ``build_model``) is that of the **largest torque anywhere in the plan** (the
stationary and chosen torques of all steps, by max-norm, as :func:`sim.torque_replay.force_scale`
reads it): damping, masses and contact stiffness are fixed for the whole run, so they are sized
for the strongest load (the object motion's member of T, eq. 32); under the smaller holding
torques the object is then only more heavily damped, which slows creep and does not change any
equilibrium.

Control of the hand
-------------------
At every moment each finger is either

* **torque-controlled** (it has a contact in the planned state of that moment): its motors
  apply the entries of the current torque ``tau`` ``(M,)`` (scene joint order), the paper's
  model of a grasp (eq. 18 holding, eq. 32 moving); or
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

Steps (``kind`` of :class:`planner.graph.Transition`)
-----------------------------------------------------
Start: torques and the scene's external wrench rise together from zero (the smooth ramp
``3x^2 - 2x^3`` of ``sim.torque_replay._ramp`` over ``params.ramp_time``) to the first step's
stationary torque ``tau_st`` (18), then settle. Every later change of torque is the same smooth
ramp from the torque in force to the new one. Each step first ramps to its own
``torques.stationary`` (a no-op when the previous step already ends there, which is the usual
case).

* ``release`` (33, F -> D): the ramp to the step's ``tau_st`` unloads the releasing finger (its
  entries are zero: it carries no contact of the combination) while the remaining contacts hold
  the object; then the finger is driven along the step's ``joint_path`` (blended from the
  simulated configuration into the planned one) while the others keep ``tau_st``.
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
:func:`final_holding_torque` (bodies ``contacts_after`` at
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
metric ``|dp| + s |dtheta|`` of ``simulate_torques`` (``s`` the object size,
:func:`analysis.geometry.object_size`). The object is **dropped** when that deviation exceeds
``params.drop_rel * s``, when no contact pushes on the object for ``unloaded_time`` while some
load is applied (a torque or the external wrench is non-zero), or when the state stops being
finite. The run stops at a drop. Displacements are pose-vector differences
(:meth:`planner.state.GraspState.pose_vector`: 2-D ``(x, y, theta)``, 3-D ``(p, rotation
vector)``), the same definition as the plan's ``displacement``; the plan's tolerance is on
``relative_error = |simulated - planned| / |planned|`` of the total displacement.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.rotations import matrix_to_quat_wxyz, matrix_to_rotvec, rotvec_to_matrix
from analysis.scene import Scene
from sim.torque_replay import (
    DEFAULT_PARAMS,
    OBJECT_BODY,
    OBJECT_GEOM,
    SimulationParams,
    _ramp,
    build_model,
    finger_dof_addresses,
    finger_qpos_addresses,
    force_scale,
    reset_to_scene,
)

KINDS = ("release", "contact", "object_motion")
Mask = NDArray[np.bool_]


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
    motion_time: float = 2.0  # an object motion gives up after this long (then reported short)
    unloaded_time: float = 0.05  # no loaded contact for this long (while loaded) means dropped
    tolerance: float = 0.05  # relative error of the total displacement the replay must meet


DEFAULT_OPTIONS = PlanSimulationOptions()


@dataclass(frozen=True)
class StepSimulation:
    """One step of the continuous replay."""

    index: int
    kind: str
    combination: str
    driven_finger: str | None  # the finger that releases or makes contact (None: object motion)
    planned: Array  # (D,) planned object displacement of the step (pose-vector difference)
    simulated: Array  # (D,) simulated displacement over the step
    max_deviation: float  # largest |dp| + s |dtheta| from the planned object path during the step
    tracking_error: float  # rad, largest per-step tracking error of driven fingers (0: none driven)
    joint_error: float  # rad, max |q - joint_path[-1]| over all joints at the end of the step
    duration: float  # simulated seconds
    dropped: bool
    note: str

    def to_json(self) -> dict[str, Any]:
        return {
            "index": self.index, "kind": self.kind, "combination": self.combination,
            "driven_finger": self.driven_finger, "planned": self.planned.tolist(),
            "simulated": self.simulated.tolist(), "max_deviation": self.max_deviation,
            "tracking_error": self.tracking_error, "joint_error": self.joint_error,
            "duration": self.duration, "dropped": self.dropped, "note": self.note,
        }


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

    @property
    def planned(self) -> Array:
        """Planned total displacement ``(D,)``."""
        return np.asarray(self.planned_final_pose - self.start_pose)

    @property
    def simulated(self) -> Array:
        """Simulated total displacement ``(D,)``."""
        return np.asarray(self.simulated_final_pose - self.start_pose)

    @property
    def relative_error(self) -> float:
        """``|simulated - planned| / |planned|`` of the total displacement (absolute if none planned)."""
        n = float(np.linalg.norm(self.planned))
        err = float(np.linalg.norm(self.simulated - self.planned))
        return err / n if n > 0 else err

    @property
    def final_pose_error(self) -> float:
        """``|simulated final pose - planned final pose|`` as a fraction of ``|planned displacement|``."""
        n = float(np.linalg.norm(self.planned))
        err = float(np.linalg.norm(self.simulated_final_pose - self.planned_final_pose))
        return err / n if n > 0 else err

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
        """Not dropped and within ``tolerance`` of the planned displacement."""
        return (not self.dropped) and len(self.steps) > 0 and self.relative_error <= self.tolerance

    def to_json(self) -> dict[str, Any]:
        return {
            "ok": self.ok, "dropped": self.dropped, "drop_reason": self.drop_reason,
            "relative_error": self.relative_error, "final_pose_error": self.final_pose_error,
            "tolerance": self.tolerance, "planned": self.planned.tolist(), "simulated": self.simulated.tolist(),
            "start_pose": self.start_pose.tolist(), "planned_final_pose": self.planned_final_pose.tolist(),
            "simulated_final_pose": self.simulated_final_pose.tolist(),
            "max_regrasp_deviation": self.max_regrasp_deviation, "tracking_error": self.tracking_error,
            "object_size": self.object_size, "force_scale": self.force_scale, "duration": self.duration,
            "steps": [s.to_json() for s in self.steps],
        }


# --------------------------------------------------------------------------------------------
# The plan file


@dataclass(frozen=True)
class _Step:
    index: int
    kind: str
    combination: str
    before: tuple[str, ...]
    after: tuple[str, ...]
    q_path: Array  # (n, M)
    object_path: Array  # (k, D)
    tau_st: Array | None  # (M,)
    tau: Array | None  # (M,)
    points_after: Array | None  # (L_after, d) world contact points after the step, if given


def _array(value: Any, loc: tuple[str | int, ...], shape: tuple[int | None, ...]) -> Array:
    """``value`` as a finite float array of ``shape`` (``None``: any length >= 1), else SceneError."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(loc, "must be an array of numbers") from None
    want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
    if a.ndim != len(shape) or any(s is not None and a.shape[i] != s for i, s in enumerate(shape)):
        raise SceneError(loc, f"must have shape {want}, got {a.shape}")
    if a.size == 0 or not np.all(np.isfinite(a)):
        raise SceneError(loc, f"must be a non-empty {want} array of finite numbers")
    return a


def parse_plan(data: Mapping[str, Any], scene: Scene, hand: HandKinematics | None = None) -> list[_Step]:
    """Check a plan's JSON form (:meth:`planner.plan.Plan.to_json`) against the scene and return
    its steps; raises :class:`SceneError` naming the first bad field."""
    hand = hand or HandKinematics.from_scene(scene)
    M, D = hand.M, scene.D
    if not isinstance(data, Mapping) or "steps" not in data:
        raise SceneError(("steps",), "missing: this is not a plan (Plan.to_json / ctp plan --out)")
    if data.get("found") is False:
        raise SceneError(("found",), f"the plan was not found ({data.get('reason', 'no reason given')}); "
                                     "nothing to replay")
    raw = data["steps"]
    if not isinstance(raw, list) or not raw:
        raise SceneError(("steps",), "must be a non-empty list of steps")
    for key in ("start_pose", "final_pose"):
        if key not in data:
            raise SceneError((key,), "missing")
        _array(data[key], (key,), (D,))
    out: list[_Step] = []
    for i, st in enumerate(raw):
        loc: tuple[str | int, ...] = ("steps", i)
        if not isinstance(st, Mapping):
            raise SceneError(loc, "must be an object")
        kind = st.get("kind")
        if kind not in KINDS:
            raise SceneError((*loc, "kind"), f"must be one of {', '.join(KINDS)} (got {kind!r})")
        bodies: dict[str, tuple[str, ...]] = {}
        for key in ("contacts_before", "contacts_after"):
            names = st.get(key)
            if not isinstance(names, list) or not all(isinstance(b, str) for b in names):
                raise SceneError((*loc, key), "must be a list of body names")
            for j, b in enumerate(names):
                if hand.resolve_body(b) is None:
                    raise SceneError((*loc, key, j), f"unknown body '{b}' (known: {', '.join(hand.body_names())})")
            bodies[key] = tuple(names)
        comb = st.get("combination")
        if not isinstance(comb, str) or len(comb) != len(bodies["contacts_before"]) + (kind == "contact"):
            raise SceneError((*loc, "combination"), "must be a string with one letter per contact")
        q_path = _array(st.get("joint_path"), (*loc, "joint_path"), (None, M))
        obj = _array(st.get("object_path"), (*loc, "object_path"), (None, D))
        torques = st.get("torques")
        if not isinstance(torques, Mapping):
            raise SceneError((*loc, "torques"), "must be an object with 'stationary' and 'chosen'")
        tau_st = None if torques.get("stationary") is None else _array(
            torques["stationary"], (*loc, "torques", "stationary"), (M,))
        tau = None if torques.get("chosen") is None else _array(torques["chosen"], (*loc, "torques", "chosen"), (M,))
        if kind == "object_motion" and tau is None:
            raise SceneError((*loc, "torques", "chosen"), "an object motion needs its chosen torque (32)")
        if kind == "release" and tau_st is None:
            raise SceneError((*loc, "torques", "stationary"), "a release needs the stationary torque (18)")
        pts = st.get("contact_points_after")
        points = None if pts is None else _array(pts, (*loc, "contact_points_after"),
                                                 (len(bodies["contacts_after"]), scene.dim))
        out.append(_Step(i, kind, comb, bodies["contacts_before"], bodies["contacts_after"], q_path, obj, tau_st, tau,
                         points))
    return out


# --------------------------------------------------------------------------------------------
# Geometry helpers


def _pose_distance(a: Array, b: Array, dim: int, s: float) -> float:
    """``|dp| + s |dtheta|`` between two pose vectors ``(D,)`` (3-D: angle of ``R_a R_b^T``)."""
    dp = float(np.linalg.norm(a[:dim] - b[:dim]))
    if dim == 2:
        dth = abs(math.remainder(float(a[2] - b[2]), 2 * math.pi))
    else:
        dth = float(np.linalg.norm(matrix_to_rotvec(rotvec_to_matrix(a[3:]) @ rotvec_to_matrix(b[3:]).T)))
    return dp + s * dth


def _path_deviation(pose: Array, path: Array, dim: int, s: float) -> float:
    """Distance of ``pose`` ``(D,)`` from the polyline ``path`` ``(k, D)`` (weighted coordinates
    ``(p, s rot)`` for the projection; the distance itself by :func:`_pose_distance`)."""
    if len(path) == 1 or np.allclose(path, path[0]):
        return _pose_distance(pose, path[0], dim, s)
    w = np.ones(path.shape[1])
    w[dim:] = s
    x = pose * w  # (D,)
    best = math.inf
    for a, b in itertools.pairwise(path):
        seg = (b - a) * w
        n2 = float(seg @ seg)
        u = 0.0 if n2 == 0 else float(np.clip((x - a * w) @ seg / n2, 0.0, 1.0))
        best = min(best, _pose_distance(pose, a + u * (b - a), dim, s))
    return best


def _arc_fractions(path: Array) -> Array:
    """Cumulative arc length ``(n,)`` of a polyline ``(n, k)``, as a fraction of the total (0..1)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)  # (n - 1,)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    return cum / cum[-1] if cum[-1] > 0 else np.linspace(0.0, 1.0, len(path))


def _interp_rows(path: Array, frac: Array, u: float) -> Array:
    """Point ``(k,)`` at arc-length fraction ``u`` of a polyline ``(n, k)`` with fractions ``frac``."""
    if len(path) == 1:
        return np.asarray(path[0])
    return np.array([np.interp(u, frac, path[:, j]) for j in range(path.shape[1])])


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
        self.b_q = np.array(self.model.dof_damping[self.dadr])  # (M,)
        self.obj_id = self.model.body(OBJECT_BODY).id
        self.obj_geom = self.model.geom(OBJECT_GEOM).id
        if self.dim == 2:
            self.obj_adr = int(self.model.jnt_qposadr[self.model.joint("object:x").id])
            self.p_o = np.array(self.data.xpos[self.obj_id][:2])  # the slides' origin
        else:
            self.obj_adr = int(self.model.jnt_qposadr[self.model.joint("object:free").id])
        w = np.asarray(scene.external_wrench, dtype=float)  # (D,)
        self.xfrc = np.zeros(6)
        if self.dim == 2:
            self.xfrc[:2], self.xfrc[5] = w[:2], w[2]
        else:
            self.xfrc[:] = w
        self.w_on = 0.0  # fraction of the external wrench applied
        self.tau = np.zeros(hand.M)  # (M,) torque in force
        self.t = 0.0
        self.unloaded = 0.0
        # per-step accumulators
        self.max_dev = 0.0
        self.track = 0.0

    # -- state --------------------------------------------------------------------------------

    def pose(self) -> Array:
        """Object pose vector ``(D,)`` now."""
        q = self.data.qpos
        if self.dim == 2:
            x, y, th = q[self.obj_adr: self.obj_adr + 3]
            return np.array([self.p_o[0] + x, self.p_o[1] + y, th])
        return np.concatenate([q[self.obj_adr: self.obj_adr + 3], matrix_to_rotvec(self.rotation())])

    def rotation(self) -> Array:
        """Object rotation ``(3, 3)`` now (from ``qpos``: ``xmat`` lags one step behind after ``mj_step``)."""
        if self.dim == 2:
            c, s = math.cos(float(self.data.qpos[self.obj_adr + 2])), math.sin(float(self.data.qpos[self.obj_adr + 2]))
            return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        R = np.zeros(9)
        quat = np.array(self.data.qpos[self.obj_adr + 3: self.obj_adr + 7])
        mujoco.mju_quat2Mat(R, quat / np.linalg.norm(quat))
        return R.reshape(3, 3)

    def dr_from(self, pose0: Array, R0: Array) -> Array:
        """Displacement ``dr`` ``(D,)`` since ``pose0`` as ``sim.torque_replay._object_dr`` defines it."""
        pose = self.pose()
        if self.dim == 2:
            return pose - pose0
        return np.concatenate([pose[:3] - pose0[:3], matrix_to_rotvec(self.rotation() @ R0.T)])

    def q(self) -> Array:
        return np.array(self.data.qpos[self.qadr])  # (M,)

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
            if any_driven:
                self.track = max(self.track, float(np.max(np.abs(d.qpos[qa] - q_next))))
            self._monitor(planned_path, tau)
            if stop is not None and stop(t + h):
                return

    def _monitor(self, planned_path: Array, tau: Array) -> None:
        d = self.data
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            raise _Drop("the simulation diverged")
        dev = _path_deviation(self.pose(), planned_path, self.dim, self.s)
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
                lam = _ramp(t, T)
                self.w_on = lam
                return tau0 + lam * (target - tau0)
            self.run(T, tau_w, planned_path, driven, lambda t: q_hold)
            self.w_on = 1.0
        elif not np.allclose(tau0, target, rtol=0.0, atol=1e-12 * (1.0 + float(np.max(np.abs(target))))):
            self.run(T, lambda t: tau0 + _ramp(t, T) * (target - tau0), planned_path, driven, lambda t: q_hold)
        self.tau = target
        if settle:
            self.run(self.options.settle_time, lambda t: target, planned_path, driven, lambda t: q_hold)


def final_holding_torque(scene: Scene, hand: HandKinematics, st: _Step) -> Array | None:
    """``tau_st`` ``(M,)`` of (18) (most interior, every contact sticking) of the grasp after the
    last step, rebuilt from the plan file: bodies ``contacts_after`` at ``contact_points_after``,
    hand at ``joint_path[-1]``, object at ``object_path[-1]``; each contact's normal is the
    object's inward surface normal there (central differences of its signed distance), its ``mu``
    that of the scene's contact on the same body, else the smallest scene ``mu`` (the planner's
    default for new contacts). ``None`` when the grasp cannot be rebuilt or has no stationary
    grasp."""
    from analysis.geometry import shape_signed_distance
    from analysis.scene import scene_from_dict
    from planner.state import StateAnalysis, all_f, state_from_scene

    if st.points_after is None or not st.after:
        return None
    d = scene.dim
    pose = st.object_path[-1]  # (D,)
    R = rotvec_to_matrix(np.array([0.0, 0.0, pose[2]])) if d == 2 else rotvec_to_matrix(pose[3:])
    Rd = R[:d, :d]
    mus = {c.body: float(c.mu) for c in scene.contacts}
    mu_default = min(mus.values()) if mus else 0.0
    step = 1e-6 * object_size(scene)
    contacts = []
    for body, p in zip(st.after, st.points_after, strict=True):
        local = Rd.T @ (p - pose[:d])  # (d,) object frame
        grad = np.zeros(d)
        for k in range(d):
            e = np.zeros(d)
            e[k] = step
            hi, lo = shape_signed_distance(scene.object.shape, local + e, d), shape_signed_distance(
                scene.object.shape, local - e, d)
            if hi is None or lo is None:
                return None
            grad[k] = (hi - lo) / (2 * step)
        if not np.linalg.norm(grad) > 0:
            return None
        n = -(Rd @ grad) / np.linalg.norm(grad)
        contacts.append({"body": body, "point": [float(x) for x in p], "normal": [float(x) for x in n],
                         "mu": mus.get(body, mu_default)})
    data = scene.model_dump(mode="json", exclude_none=True)
    obj_pose: dict[str, Any] = {"position": [float(x) for x in pose[:d]]}
    if d == 2:
        obj_pose["angle"] = float(pose[2])
    else:
        obj_pose["quat_wxyz"] = [float(x) for x in matrix_to_quat_wxyz(R)]
    data["object"]["pose"] = obj_pose
    for i, f in enumerate(data["fingers"]):
        f["q"] = [float(x) for x in st.q_path[-1][hand.finger_slice(i)]]
    data["contacts"] = contacts
    try:
        final = scene_from_dict(data)
        fh = HandKinematics.from_scene(final)
        state = state_from_scene(final, fh)
        grasp = StateAnalysis.of(final, state, fh).stationary(all_f(state))
    except SceneError:
        return None
    return None if grasp is None else np.asarray(grasp.tau, dtype=float)


def _constant(tau: Array) -> Callable[[float], Array]:
    """The torque schedule ``t -> tau`` ``(M,)``."""
    return lambda t: tau


def _finger_of(hand: HandKinematics, body: str) -> int | None:
    ref = hand.resolve_body(body)
    return None if ref is None else ref.finger


def _mask(hand: HandKinematics, fingers: set[int]) -> Mask:
    m = np.zeros(hand.M, dtype=bool)
    for f in fingers:
        m[hand.finger_slice(f)] = True
    return m


def _fingers_touching(hand: HandKinematics, bodies: tuple[str, ...]) -> set[int]:
    return {f for b in bodies if (f := _finger_of(hand, b)) is not None}


def _moving_finger(hand: HandKinematics, st: _Step) -> int | None:
    """The finger whose joints move along the step's path, else the one whose body appears in only
    one of contacts_before / contacts_after."""
    span = np.ptp(st.q_path, axis=0)  # (M,)
    moving = [f for f in range(len(hand.fingers)) if float(np.max(span[hand.finger_slice(f)], initial=0.0)) > 1e-9]
    if len(moving) == 1:
        return moving[0]
    changed = _fingers_touching(hand, tuple(set(st.before) ^ set(st.after)))
    return next(iter(changed)) if len(changed) == 1 else (moving[0] if moving else None)


def _path_time(st: _Step, mask: Mask, options: PlanSimulationOptions) -> float:
    """Duration of a driven move: 1.5 x length / joint_speed (the smooth profile's mean speed is
    2/3 of its peak), at least ``min_move_time``."""
    length = float(np.sum(np.linalg.norm(np.diff(st.q_path[:, mask], axis=0), axis=1)))
    return max(options.min_move_time, 1.5 * length / options.joint_speed)


def _driven_profile(st: _Step, mask: Mask, q_start: Array, duration: float) -> Callable[[float], Array]:
    """``q(t)`` ``(M,)`` along the step's joint path (smooth in time, uniform in arc length of the
    driven joints), blended from the simulated start ``q_start`` into the planned path."""
    frac = _arc_fractions(st.q_path[:, mask])
    offset = q_start - st.q_path[0]  # (M,)

    def q_of(t: float) -> Array:
        u = _ramp(t, duration)
        return _interp_rows(st.q_path, frac, u) + (1.0 - u) * offset

    return q_of


def simulate_plan(
    scene: Scene,
    plan: Any,
    *,
    params: SimulationParams = DEFAULT_PARAMS,
    options: PlanSimulationOptions = DEFAULT_OPTIONS,
) -> PlanSimulation:
    """Replay a whole plan in one MuJoCo simulation (see the module docstring).

    ``plan``: a :class:`planner.plan.Plan` or its JSON form (``Plan.to_json()``, a ``ctp plan
    --out`` file); ``scene`` the scene it was planned from. Raises :class:`SceneError` naming the
    field when the plan does not fit the scene or is not a found plan.
    """
    data: Mapping[str, Any] = plan.to_json() if hasattr(plan, "to_json") else plan
    hand = HandKinematics.from_scene(scene)
    steps = parse_plan(data, scene, hand)
    if data.get("final_holding_torque") is not None:  # checked before the run, not when it is needed
        _array(data["final_holding_torque"], ("final_holding_torque",), (hand.M,))
    start_pose = np.asarray(data["start_pose"], dtype=float)  # (D,)
    final_pose = np.asarray(data["final_pose"], dtype=float)  # (D,)
    torques = [t for st in steps for t in (st.tau_st, st.tau) if t is not None]
    tau_scale = max(torques, key=lambda t: float(np.max(np.abs(t)))) if torques else np.zeros(hand.M)
    run = _Run(scene, hand, params, tau_scale, options)
    s, dim = run.s, scene.dim
    if _pose_distance(run.pose(), start_pose, dim, s) > 1e-6 * s:
        raise SceneError(("start_pose",), "is not the scene's object pose: the plan was made for another scene")
    if not np.allclose(steps[0].q_path[0], hand.q0, atol=1e-6):
        raise SceneError(("steps", 0, "joint_path"), "does not start at the scene's finger configuration")

    out: list[StepSimulation] = []
    dropped, reason = False, ""
    # start: torques and external wrench rise together to the first holding torque
    first = steps[0]
    hold0 = first.tau_st if first.tau_st is not None else np.zeros(hand.M)
    busy0 = _fingers_touching(hand, first.before)
    free0 = _mask(hand, set(range(len(hand.fingers))) - busy0)
    try:
        run.ramp_to(hold0, first.object_path[:1], free0, first.q_path[0], wrench=True)
    except _Drop as e:
        dropped, reason = True, f"at the start: {e}"

    for i, st in enumerate(steps):
        if dropped:
            break
        nxt = steps[i + 1] if i + 1 < len(steps) else None
        t0, pose0, R0 = run.t, run.pose(), run.rotation()
        run.max_dev, run.track = 0.0, 0.0
        planned = st.object_path[-1] - st.object_path[0]  # (D,)
        busy_before = _fingers_touching(hand, st.before)
        busy_after = _fingers_touching(hand, st.after)
        all_f = set(range(len(hand.fingers)))
        finger = None if st.kind == "object_motion" else _moving_finger(hand, st)
        note = ""
        try:
            if st.kind == "release":
                assert st.tau_st is not None
                run.ramp_to(st.tau_st, st.object_path[:1], _mask(hand, all_f - busy_before), st.q_path[0])
                driven = _mask(hand, all_f - busy_after)
                T = _path_time(st, driven, options)
                run.run(T, _constant(st.tau_st), st.object_path[:1], driven, _driven_profile(st, driven, run.q(), T))
                run.ramp_to(st.tau_st, st.object_path[:1], driven, st.q_path[-1])  # settle
                note = f"released in {T:.3g} s"
            elif st.kind == "contact":
                driven = _mask(hand, all_f - busy_before)
                if st.tau_st is not None:
                    run.ramp_to(st.tau_st, st.object_path[:1], driven, st.q_path[0], settle=False)
                T = _path_time(st, driven, options)
                hold = run.tau.copy()
                run.run(T, _constant(hold), st.object_path[:1], driven, _driven_profile(st, driven, run.q(), T))
                after = _mask(hand, all_f - busy_after)
                if nxt is not None and nxt.tau_st is not None:
                    run.ramp_to(nxt.tau_st, st.object_path[-1:], after, st.q_path[-1])
                    note = f"moved in {T:.3g} s, loaded with the next step's tau_st"
                else:
                    final_tau = _final_tau(data, scene, hand, st)
                    run.ramp_to(hold if final_tau is None else final_tau, st.object_path[-1:], after, st.q_path[-1])
                    note = f"moved in {T:.3g} s, " + (
                        "torque kept (final grasp not rebuilt)" if final_tau is None else "final grasp's tau_st")
            else:
                note = _object_motion(run, data, scene, hand, st, nxt, pose0, R0)
        except _Drop as e:
            dropped, reason = True, f"step {st.index} ({st.kind}): {e}"
            note = str(e)
        out.append(StepSimulation(
            index=st.index, kind=st.kind, combination=st.combination,
            driven_finger=None if finger is None else hand.fingers[finger].name,
            planned=planned, simulated=run.pose() - pose0, max_deviation=run.max_dev,
            tracking_error=run.track, joint_error=float(np.max(np.abs(run.q() - st.q_path[-1]))),
            duration=run.t - t0, dropped=dropped, note=note,
        ))
    return PlanSimulation(
        steps=tuple(out), start_pose=start_pose, planned_final_pose=final_pose, simulated_final_pose=run.pose(),
        object_size=s, force_scale=run.F, dropped=dropped, drop_reason=reason, duration=run.t,
        tolerance=options.tolerance,
    )


def _final_tau(data: Mapping[str, Any], scene: Scene, hand: HandKinematics, st: _Step) -> Array | None:
    """The holding torque after the last step: the plan's ``final_holding_torque`` (``tau_st`` of
    the final grasp, computed by the planner) when the file has it, else rebuilt by
    :func:`final_holding_torque`."""
    given = data.get("final_holding_torque")
    if given is not None:
        return _array(given, ("final_holding_torque",), (hand.M,))
    return final_holding_torque(scene, hand, st)


def _object_motion(run: _Run, data: Mapping[str, Any], scene: Scene, hand: HandKinematics, st: _Step,
                   nxt: _Step | None, pose0: Array, R0: Array) -> str:
    """Eq. (30)-(32): ramp to the chosen torque, move the planned distance, ramp to the holding torque."""
    assert st.tau is not None
    options, T = run.options, run.params.ramp_time
    busy = _fingers_touching(hand, st.before)
    free = _mask(hand, set(range(len(hand.fingers))) - busy)
    dist = float(np.linalg.norm(st.object_path[-1] - st.object_path[0]))
    frac_obj = _arc_fractions(st.object_path)
    progress = {"u": 0.0, "prev": 0.0, "v": 0.0, "reached": 0.0}

    def q_of(t: float) -> Array:  # free fingers follow the object's progress
        return _interp_rows(st.q_path, frac_obj, progress["u"])

    def braking(t: float) -> bool:
        r = float(np.linalg.norm(run.dr_from(pose0, R0)))
        progress["v"] = (r - progress["prev"]) / run.h
        progress["prev"] = r
        progress["u"] = min(1.0, r / dist) if dist > 0 else 1.0
        if r + max(progress["v"], 0.0) * T / 2 >= dist:
            progress["reached"] = 1.0
            return True
        return False

    if st.tau_st is not None:
        run.ramp_to(st.tau_st, st.object_path[:1], free, st.q_path[0], settle=False)
    tau0 = run.tau.copy()
    chosen = st.tau
    run.run(options.motion_time, lambda t: tau0 + _ramp(t, T) * (chosen - tau0), st.object_path, free, q_of,
            stop=braking)
    reached = progress["reached"] > 0
    if nxt is not None and nxt.tau_st is not None:
        hold, src = nxt.tau_st, "the next step's tau_st"
    elif (final_tau := _final_tau(data, scene, hand, st)) is not None:
        hold, src = final_tau, "the final grasp's tau_st"
    else:
        hold = st.tau_st if st.tau_st is not None else chosen
        src = "its own tau_st (final grasp not rebuilt)"
    run.ramp_to(hold, st.object_path, free, q_of(0.0))
    moved = float(np.linalg.norm(run.dr_from(pose0, R0)))
    return (f"moved {moved:.4g} of {dist:.4g} planned; held with {src}"
            + ("" if reached else f"; did not reach the distance in {options.motion_time} s"))


__all__ = [
    "DEFAULT_OPTIONS",
    "PlanSimulation",
    "PlanSimulationOptions",
    "StepSimulation",
    "final_holding_torque",
    "parse_plan",
    "simulate_plan",
]
