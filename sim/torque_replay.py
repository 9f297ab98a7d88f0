"""Physics cross-check: replay joint torques in MuJoCo, quasi-statically.

A closure analysis predicts how the object moves (a DAFC direction) and what each contact
does (the combination string, e.g. ``"FSDDD"``) when the hand applies a torque from the set
``T`` (eq. 32). :func:`simulate_torques` applies such a torque to the same hand and object in
MuJoCo and reports what happened: the object displacement ``dr`` in the paper's coordinates,
the final joint angles, whether the object was dropped, and per scene contact whether it
stuck, slid or separated, with its mean normal force and its slip distance.

The model it runs on (hand, object, contact pairs, damping: the quasi-static model) is
:mod:`sim.mjcf`; how each contact's outcome is read off MuJoCo's contacts is :mod:`sim.tracker`;
:func:`sim.report.format_report` prints a result.

Load ramp
---------
Torques and external wrench rise together from zero over ``ramp_time`` (a smooth step): a
sudden load on contacts that are exactly touching would start with an impact (a contact at zero
distance is only switched on after the first step), while scaling a stationary pair
``(tau_st, w_ex)`` together with ``tau_ad`` changes neither the predicted direction nor the
states.

Known properties of the replay, worth knowing when reading its results:

* MuJoCo's contact model is convex, not complementarity-based: a *sliding* contact also moves
  apart along its normal at about ``mu |v_t|`` (the "only way to initiate slip is to generate
  some motion in the normal direction" of MuJoCo's documentation). Under quasi-static damping
  this makes sliding contacts chatter (a disk sliding on the palm is loaded about half of the
  time, with twice the force); time averages (forces, directions) are right, e.g. the tests'
  sliding push matches the closed-form answer to a cosine of 0.9999.
* Statically indeterminate grasps: joint torques fix the contact forces only up to internal
  forces in ``null(J_c^T)`` (the paper's ``Gamma xi~``). MuJoCo settles them itself (normal
  forces from the contacts' penetrations, friction from its regularised least-force solution),
  so the forces it reports satisfy ``G f = -w_ex`` and ``J^T f = tau`` but need not equal the
  analysis's ``f_c``; with fingers squeezing against each other through F-points the realised
  internal forces can differ enough to change which contacts slide.
* Results are first order only for small motions: use ``stop_distance`` (e.g. 2 % of the
  object size) so the geometry does not change much during the run.

Expected states of a combination: ``F -> stick``, ``S -> slide``, ``D -> separate`` (which
includes "touching with zero force"), ``N -> stick`` or ``slide``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from analysis._types import Array
from analysis.contacts import build_system, parse_combination
from analysis.exceptions import SceneError
from analysis.geometry import object_size
from analysis.kinematics import BodyRef, HandKinematics
from analysis.scene import Scene
from sim.mjcf import (
    DEFAULT_PARAMS,
    Damping,
    SimulationParams,
    build_model,
    damping,
    external_xfrc,
    finger_dof_addresses,
    finger_qpos_addresses,
    object_pose,
    reset_to_scene,
)
from sim.tracker import ContactTracker, observed_states

EXPECTED_STATE = {"F": ("stick",), "S": ("slide",), "D": ("separate",), "N": ("stick", "slide")}


# --------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class ContactOutcome:
    """What one scene contact did during the run (the rules: :mod:`sim.tracker`)."""

    index: int
    body: str
    observed: str  # 'stick' | 'slide' | 'separate'
    mean_normal_force: float  # time average of n . f over the run (0 while not touching)
    mean_force: Array  # (d,) time average of the force the hand applied on the object, world
    max_normal_force: float
    loaded_fraction: float  # fraction of samples with a positive normal force
    slip: float  # path length of the tangential relative motion of the material points
    travel: float  # path length of the faster of the two material points
    final_gap: float  # distance between the body and the object at the end (< 0: penetration)
    expected: str | None = None  # the combination's letter (F, S, D, N), if given
    agrees: bool | None = None



@dataclass(frozen=True)
class SimulationResult:
    """Outcome of :func:`simulate_torques`.

    ``dr`` is the object displacement in the paper's coordinates: 2-D ``(dx, dy, dtheta)``,
    3-D ``(dp, w)`` with ``w`` the world rotation vector of ``R_end R_start^T``; ``direction``
    is ``dr / |dr|`` (zero if the object did not move).
    """

    dim: int
    duration: float  # simulated time (s); less than requested if stopped early
    dr: Array  # (D,)
    direction: Array  # (D,)
    q0: Array  # (M,)
    q: Array  # (M,) final joint angles
    tau: Array  # (M,) applied joint torques
    dropped: bool
    drop_reason: str
    contacts: tuple[ContactOutcome, ...]
    extra_contacts: tuple[tuple[str, float], ...]  # other bodies that touched: (name, mean normal force)
    times: Array  # (n,) sample times
    trajectory: Array  # (n, D) dr at the sample times
    combination: str | None = None
    stopped_early: bool = False
    object_size: float = 1.0
    damping: Damping | None = None  # damping, masses and force scale of the run
    params: SimulationParams = field(default=DEFAULT_PARAMS)

    @property
    def dq(self) -> Array:
        return self.q - self.q0  # (M,)

    @property
    def agrees(self) -> bool | None:
        """All contacts behaved as the combination says (``None`` without a combination)."""
        if self.combination is None:
            return None
        return all(bool(c.agrees) for c in self.contacts)

    def cosine(self, direction: Array) -> float:
        """Cosine between the observed ``dr`` and a direction ``(D,)`` (0 if either is zero)."""
        d = np.asarray(direction, dtype=float)
        n1, n2 = float(np.linalg.norm(self.dr)), float(np.linalg.norm(d))
        return float(self.dr @ d / (n1 * n2)) if n1 > 0 and n2 > 0 else 0.0

    def displacement_between(self, t0: float, t1: float | None = None) -> Array:
        """``dr(t1) - dr(t0)`` ``(D,)`` from the recorded trajectory (``t1`` default: the end).
        E.g. ``t0 = params.ramp_time`` gives the motion under the full torques."""
        k0 = int(np.clip(np.searchsorted(self.times, t0), 0, len(self.times) - 1))
        k1 = (
            len(self.times) - 1 if t1 is None else int(np.clip(np.searchsorted(self.times, t1), 0, len(self.times) - 1))
        )
        return np.asarray(self.trajectory[k1] - self.trajectory[k0])

    def speed(self) -> float:
        """Mean rate of ``|dr|`` over the run (scene units per second)."""
        return float(np.linalg.norm(self.dr) / self.duration) if self.duration > 0 else 0.0


# --------------------------------------------------------------------------------------------
# Simulation


def self_motion_torque(hand: HandKinematics, points: list[tuple[BodyRef, Array]], q: Array, q_ref: Array,
                       gains: Array) -> Array:
    """A posture torque ``(M,)`` that acts on the self-motion of the hand only:
    ``P diag(gains) P (q_ref - q)``, ``P = I - J_c^+ J_c`` the projector onto the joint motions that
    move none of the contact points ``points`` (``(finger body, point in its frame)``; ``J_c``
    their stacked point Jacobians at ``q``), ``q_ref`` ``(M,)`` the planned configuration.

    A redundant arm under pure torque control (the paper's model) has directions of joint motion
    that move no contact point (a 7-joint arm touching with one point: 4 of them), in which the
    contact forces cannot hold it: under constant joint torques its elbow swings sideways
    (measured on the Panda's forearm push: joints 1 and 3 counter-rotate, growing about
    ``e^(12 t)``, until the forearm leaves the box after 6 cm). The torque lies in ``range(P)``,
    orthogonal to ``range(J_c^T)``, so no contact force can balance it: it moves the hand along
    its self-motion, back onto the planned posture, and vanishes there; the torques that reach
    the contacts (``J_c^+T tau``) are unchanged by it."""
    P = self_motion_projector(hand, points, q)  # (M, M)
    return np.asarray(P @ (np.asarray(gains, float) * (P @ (np.asarray(q_ref, float) - np.asarray(q, float)))))


def self_motion_projector(hand: HandKinematics, points: list[tuple[BodyRef, Array]], q: Array) -> Array:
    """``P = I - J_c^+ J_c`` ``(M, M)`` at ``q`` ``(M,)``: the projector onto the joint motions that
    move none of the contact ``points`` (:func:`self_motion_torque`)."""
    rows = [hand.point_jacobian(ref, hand.point_position(ref, pb, q), q) for ref, pb in points]
    M = hand.M
    if not rows:
        return np.eye(M)
    J = np.vstack(rows)  # (3 k, M)
    return np.asarray(np.eye(M) - np.linalg.pinv(J, rcond=1e-10) @ J)


#: MuJoCo steps between two evaluations of the self-motion projector in :func:`simulate_torques`
SELF_MOTION_EVERY = 25


def smooth_ramp(t: float, T: float) -> float:
    """Smooth ramp from 0 (``t = 0``) to 1 (``t >= T``): ``3x^2 - 2x^3``."""
    if T <= 0 or t >= T:
        return 1.0
    x = max(t, 0.0) / T
    return x * x * (3.0 - 2.0 * x)


def simulate_torques(
    scene: Scene,
    tau: Array,
    *,
    duration: float,
    combination: str | None = None,
    params: SimulationParams = DEFAULT_PARAMS,
    stop_distance: float | None = None,
    sample_every: int = 1,
    phi: float | None = None,
    hold_rate: float = 0.0,
) -> SimulationResult:
    """Apply constant joint torques ``tau`` ``(M,)`` (scene finger order; ``tau = J^T f`` for
    contact forces ``f`` the fingers apply on the object) together with the scene's external
    wrench, for ``duration`` seconds, starting at rest at the scene configuration.

    Torques and wrench rise together from zero over ``params.ramp_time`` (a smooth ramp; scaling
    a stationary pair ``(tau_st, w_ex)`` and ``tau_ad`` by the same factor changes neither the
    predicted direction nor the contact states, and a sudden load would start with an impact).
    Forces, slip and travel are evaluated over the samples after the ramp (during the ramp the
    contacts also deform elastically, which is not sliding), or over the second half of the run
    if it stopped early, before a quarter of it lay after the ramp.

    ``stop_distance``: stop early once ``|dr|`` exceeds it (keeps the motion small, where the
    first-order analysis applies). ``sample_every``: contacts are read every this many steps.
    ``combination``: a string such as ``"FSDDD"``; each contact outcome then carries the expected
    state and whether it agrees. ``phi``: the joint speed per unit object speed of the motion the
    torque is for (eq. 31, ``TorqueSet.phi``), which lowers the fingers' damping where the joints
    turn fast (:func:`sim.mjcf.damping`) in the joint motions that move the contacts (of the
    combination's F, S, N points; all contacts without one); the self-motion, which no contact
    force balances, keeps the nominal damping (an added torque ``-(b_q0 - b_q) P P dq/dt``, ``P``
    the self-motion projector of :func:`self_motion_torque`), so a constant torque's drift along
    it is as slow as before. ``hold_rate`` (1/s, > 0): a hold, with the joint servo of the continuous
    replay (:class:`sim.plan_replay.PlanSimulationOptions`, stiffness ``hold_rate b_q``) holding the
    joint motions that move the contacts where they are once the load has come on (after the ramp,
    as the continuous replay does not servo its start ramp). Raises :class:`SceneError` for
    a wrong ``tau`` length, a non-positive duration, a bad combination or ``hold_rate``.
    """
    hand = HandKinematics.from_scene(scene)
    tau = np.asarray(tau, dtype=float).ravel()  # (M,)
    if tau.shape != (hand.M,) or not np.all(np.isfinite(tau)):
        raise SceneError(("tau",), f"must be {hand.M} finite joint torques (got shape {tau.shape})")
    if not duration > 0:
        raise SceneError(("duration",), "must be positive")
    comb = None if combination is None else parse_combination(combination, build_system(scene, hand))

    dim, D = scene.dim, scene.D
    s = object_size(scene)
    model = build_model(scene, params, tau, phi)
    data = mujoco.MjData(model)
    reset_to_scene(model, data)
    tracker = ContactTracker(scene, hand, model, params)
    obj_id = tracker.obj_id

    w_ex = np.asarray(scene.external_wrench, dtype=float)  # (D,)
    xfrc = external_xfrc(scene)  # (6,)
    qadr = finger_qpos_addresses(model, scene)
    q0 = np.array(data.qpos[qadr])  # (M,)
    start = object_pose(model, data, dim)

    h = params.timestep
    n_steps = max(1, math.ceil(duration / h - 1e-9))
    times: list[float] = [0.0]
    traj: list[Array] = [np.zeros(D)]
    n_samples = 0
    stopped, dropped, reason = False, False, ""
    unloaded_run = 0  # consecutive samples without any contact pushing on the object
    dadr = finger_dof_addresses(model, scene)  # (M,)
    # a lowered finger damping (phi) is lowered for the joint motions that move the contacts only:
    # the self-motion, whose damping no contact force balances, keeps the nominal one
    b_nom = damping(scene, tau, params).finger_damping
    b_self = b_nom - damping(scene, tau, params, phi).finger_damping
    if not (hold_rate >= 0 and np.isfinite(hold_rate)):
        raise SceneError(("hold_rate",), f"must be a finite rate >= 0 in 1/s (got {hold_rate!r})")
    stiff = min(hold_rate * b_nom, 0.5 * b_nom / h)  # the continuous replay's cap (STABLE_GAIN)
    points = [(ref, hand.to_local(ref, np.asarray(c.point, dtype=float), hand.q0))
              for i, c in enumerate(scene.contacts)
              if (comb is None or comb[i] != "D") and (ref := hand.resolve_body(c.body)) is not None
              and ref.finger is not None] if (b_self > 0 or stiff > 0) else []
    P = np.zeros((hand.M, hand.M))
    q_hold: Array | None = None  # (M,) the hold servo's reference, taken once the load is on
    for step in range(1, n_steps + 1):
        lam = smooth_ramp((step - 0.5) * h, params.ramp_time)
        data.ctrl[:] = lam * tau
        if b_self > 0 or stiff > 0:
            if step % SELF_MOTION_EVERY == 1:
                P = self_motion_projector(hand, points, np.array(data.qpos[qadr]))
            if b_self > 0:
                data.ctrl[:] -= b_self * (P @ (P @ data.qvel[dadr]))
            if stiff > 0 and q_hold is not None:  # the hold servo: contact-moving joint motions held
                Q = np.eye(hand.M) - P
                data.ctrl[:] += stiff * (Q @ (Q @ (q_hold - data.qpos[qadr])))
        data.xfrc_applied[obj_id] = lam * xfrc
        mujoco.mj_step(model, data)
        if stiff > 0 and q_hold is None and step * h >= params.ramp_time:
            q_hold = np.array(data.qpos[qadr])  # the servo holds where the loaded grasp settled
        if step % sample_every and step != n_steps:
            continue
        n_samples += 1
        t = step * h
        loaded = tracker.sample(data, t, h * sample_every)
        unloaded_run = 0 if loaded else unloaded_run + 1
        dr_now = object_pose(model, data, dim).shortest_displacement_from(start)  # (D,)
        times.append(t)
        traj.append(dr_now)
        if not np.all(np.isfinite(dr_now)):
            dropped, reason = True, "the simulation diverged"
            break
        moved = float(np.linalg.norm(dr_now[:dim])) + s * float(np.linalg.norm(dr_now[dim:]))
        if moved > params.drop_rel * s:
            dropped, reason = True, f"the object moved {moved:.3g} > {params.drop_rel * s:.3g}"
            break
        if stop_distance is not None and float(np.linalg.norm(dr_now)) > stop_distance:
            stopped = True
            break
    if not dropped and n_samples and unloaded_run >= max(1, n_samples // 10):
        dropped, reason = True, "the object lost all contacts"
    mujoco.mj_forward(model, data)  # contacts at the final state
    final_gap = tracker.final_gaps(data)

    L = len(scene.contacts)
    stats = tracker.statistics(params.ramp_time)
    observed = observed_states(stats, final_gap, float(np.linalg.norm(w_ex[:dim])), s, params)
    outcomes = []
    for i in range(L):
        expected = comb[i] if comb is not None else None
        outcomes.append(
            ContactOutcome(
                index=i,
                body=scene.contacts[i].body,
                observed=observed[i],
                mean_normal_force=float(stats.mean_normal[i]),
                mean_force=stats.mean_force[i],
                max_normal_force=float(stats.max_normal[i]),
                loaded_fraction=float(stats.loaded_fraction[i]),
                slip=float(stats.slip[i]),
                travel=float(stats.travel[i]),
                final_gap=float(final_gap[i]),
                expected=expected,
                agrees=None if expected is None else observed[i] in EXPECTED_STATE[expected],
            )
        )
    dr = traj[-1]
    nrm = float(np.linalg.norm(dr))
    return SimulationResult(
        dim=dim,
        duration=float(times[-1]),
        dr=dr,
        direction=dr / nrm if nrm > 0 else np.zeros(D),
        q0=q0,
        q=np.array(data.qpos[qadr]),
        tau=tau,
        dropped=dropped,
        drop_reason=reason,
        contacts=tuple(outcomes),
        extra_contacts=tuple(sorted(stats.extra.items())),
        times=np.array(times),
        trajectory=np.array(traj),
        combination=comb,
        stopped_early=stopped,
        object_size=s,
        damping=damping(scene, tau, params, phi),
        params=params,
    )


__all__ = ["EXPECTED_STATE", "ContactOutcome", "SimulationResult", "simulate_torques", "smooth_ramp"]
