"""Independent re-check of a plan's steps by the closure analysis (no planner caches).

For every step the states before and after are rebuilt as scenes (which validates that every
contact point lies on its body and on the object) and:

* ``release`` (33): the stationary grasp (18) of the remaining contacts exists and the first
  finger motion of the step separates every released contact (``J_d dq < 0``) while keeping the
  others (``J_c dq = 0`` to first order);
* ``contact`` (33): the new grasp has a stationary grasp (18) and the finger path is
  collision-free (certified);
* ``object_motion`` (30-32): every waypoint of the path lies on the contact manifold (F-points
  together, S-points touching), the combination has a stationary grasp, the direction is a DAFC
  member (22 by the LP oracle), the torque set (32) for it is not empty, and the chosen torque's
  contact forces satisfy (32) (residuals); every segment of the object path lies within 0.99
  cosine of that re-analysed direction (the object goes where its torque moves it); for F- and
  D-points, the chosen torque's contact forces stay in the friction set (16) at every eighth of
  the path (the torque holds the contacts all along, :func:`_torque_hold_problems`); for a 2-D disk
  every sticking contact on a link's side rolls: at every waypoint the disk touches the link (gap
  zero) and the arc the contact point travelled on the link equals ``r`` times the disk's turn
  relative to the link, and the state after the step has the contact at the rolled point
  (:func:`_rolling_problems`, from the positions alone); for a 3-D sphere every sticking
  contact on a fixed body's face rolls: at every waypoint the sphere touches the plane, between
  waypoints its contact point does not slip, the contact point travels on the plane and on the
  sphere ``r`` times the rolling turn, and the state after the step has the rolled contact
  (:func:`_plane_rolling_problems`); for a 3-D sphere every sticking contact on a capsule link's
  side rolls: at every waypoint the gap is zero, between waypoints the sphere does not slip
  against the link, the contact point travels as far on the link as on the sphere, and the state
  after the step has the rolled contact (:func:`_link_rolling_problems`); and densely
  (waypoints at most ``DENSE_STEP`` apart), at every waypoint, the object penetrates no fixed
  body and no link penetrates the object, a fixed body or another link;
* every step: its torque and its holding torque within the joints' limits
  (:func:`_torque_limit_problems`);
* ``slide`` (33 with one S-point, the object still): densely, the sliding contact's gap and face,
  the kept contacts, the path's clearance, and at every waypoint the holding contacts' stationary
  grasp (18) and eq. (33) with the sliding contact's kinetic friction (:func:`_slide_problems`);
* every state after a step holds the object (18 for all-F).

:func:`verify_plan` returns the list of problems (empty when every step passes).
"""

from __future__ import annotations

import itertools

import numpy as np

from analysis._types import Array
from analysis.contacts import build_system
from analysis.exceptions import CTPError
from analysis.geometry import shape_normal_cone, shape_signed_distance
from analysis.kinematics import BodyRef, HandKinematics
from analysis.loader import GEOMETRY_TOL
from analysis.pose import Pose
from analysis.regrasp import sliding_equilibrium
from analysis.rotations import matrix_to_rotvec
from analysis.scene import Box, Cylinder, Disk, Scene, Sphere
from analysis.torque_limits import LIMIT_TOL, hand_torque_limits, over_limit
from analysis.torques import torque_set
from planner.collision import DENSE_STEP, PENETRATION_TOL, CollisionModel, path_clearance_certified
from planner.link_release import OVERLAP_SLACK, ROUNDING
from planner.link_roll import axial_offset, axis_point, link_contact, link_roll_check, link_rolls, object_radius
from planner.manifold import pose_displacement
from planner.motion_length import line_contacts, torque_margin, waypoint_state
from planner.object_motion import (
    MIN_DIRECTION_COSINE,
    direction_cosines,
    link_rolling_motion,
    motion_manifold,
    rolls_on_links,
    rolls_on_planes,
)
from planner.plan import Plan, PlanStep
from planner.state import GraspContact, GraspState, StateAnalysis, all_f

#: a contact the moving finger keeps during a ``contact`` step may move this much (scene units)
KEPT_CONTACT_TOL = 1e-6


def verify_step(scene: Scene, hand: HandKinematics, step: PlanStep) -> list[str]:
    problems: list[str] = []
    t = step.transition
    tag = f"step {step.index} ({t.kind})"
    try:
        before = StateAnalysis.of(scene, step.before, hand)
        after = StateAnalysis.of(scene, step.after, hand)
    except CTPError as e:
        return [f"{tag}: state is not a valid scene: {e}"]
    if after.stationary(all_f(step.after)) is None:
        problems.append(f"{tag}: the grasp after the step has no stationary grasp (18)")
    problems.extend(_torque_limit_problems(scene, hand, step, tag))
    if t.kind == "release":
        if before.stationary(t.combination) is None:
            problems.append(f"{tag}: no stationary grasp (18) of the remaining contacts")
        dq = t.q_path[1] - t.q_path[0]
        sy = build_system(before.scene, hand, step.before.q)
        for i, letter in enumerate(t.combination):
            rate = float(sy.normals[i] @ (sy.J_blocks[i] @ dq))  # A_d [dq; 0] for a D-point
            if letter == "D" and not rate < 0.0:
                problems.append(f"{tag}: released contact {i} does not separate (n^T J dq = {rate:.3g})")
            if letter == "F" and np.linalg.norm(sy.J_blocks[i] @ dq) > 1e-6 + 1e-3 * np.linalg.norm(dq):
                problems.append(f"{tag}: kept contact {i} moves")
    elif t.kind == "contact":
        if before.stationary(all_f(step.before)) is None:
            problems.append(f"{tag}: no stationary grasp (18) while the finger moves")
        model = CollisionModel.of(scene, hand)
        moved = np.flatnonzero(np.any(np.abs(np.diff(t.q_path, axis=0)) > 0, axis=0))
        fingers = {f for f in range(len(hand.fingers))
                   for j in moved if j in range(*hand.finger_slice(f).indices(hand.M))}
        made = [r for c in step.after.contacts if c.body not in t.contacts_before
                and (r := hand.resolve_body(c.body)) is not None]
        for f in fingers:
            sl = hand.finger_slice(f)
            chain = hand.fingers[f]
            new_refs = [r for r in made if r.finger == f] or [BodyRef(f"{chain.name}/{chain.n_joints - 1}", f,
                                                                      chain.n_joints - 1)]
            kept = [(i, r) for i, c in enumerate(step.before.contacts)
                    if (r := hand.resolve_body(c.body)) is not None and r.finger == f]
            for i, r in kept:  # a finger that keeps contacts while it moves (a link laid on a face)
                drift = max(float(np.linalg.norm(hand.point_position(r, step.before.contacts[i].point_body, q)
                                                 - step.before.world_point(i))) for q in t.q_path)
                if drift > KEPT_CONTACT_TOL:
                    problems.append(f"{tag}: kept contact {i} ({step.before.contacts[i].body}) moves by {drift:.3g}")
            kept_refs = [r for _, r in kept]
            allow = model.start_allowance(f, step.before.q, step.before.position, step.before.rotation)
            if kept_refs:  # the overlaps of an arm's neighbouring links may deepen as in a link release
                allow = np.where(allow < 0.0, allow - OVERLAP_SLACK * model.min_radius, allow) - ROUNDING
            n = len(t.q_path)
            ok, clear, _ = path_clearance_certified(model, f, step.before.q, t.q_path[: n - 1, sl],
                                                    step.before.position, step.before.rotation, kept_refs, 0, allow)
            if ok:
                ok, clear, _ = path_clearance_certified(model, f, step.before.q, t.q_path[n - 2:, sl],
                                                        step.before.position, step.before.rotation,
                                                        [*kept_refs, *new_refs], 0, allow)
            if not ok:
                problems.append(f"{tag}: finger path collides (clearance {clear:.3g})")
    elif t.kind == "slide":
        problems.extend(_slide_problems(scene, hand, step, tag))
    elif t.kind == "object_motion":
        grasp = before.stationary(t.combination)
        if grasp is None:
            return [*problems, f"{tag}: no stationary grasp (18) for {t.combination}"]
        problems.extend(_manifold_problems(scene, hand, step, tag))
        problems.extend(_rolling_problems(scene, hand, step, tag))
        problems.extend(_plane_rolling_problems(scene, hand, step, tag))
        problems.extend(_link_rolling_problems(scene, hand, step, tag))
        p = before.parts(t.combination)
        oracle = p.oracle()
        assert t.torque_set is not None
        direction = np.asarray(t.torque_set["direction"], float)
        test = oracle.test(direction)
        if not test.member:
            problems.append(f"{tag}: direction not in DAFC (22): {test.reason}")
        else:
            try:
                ts = torque_set(p.system, p.sel, p.ms, p.st, p.fs, grasp, direction, oracle=oracle)
                res = ts.residuals(ts.f_c)
                if res["inequality"] > 1e-6 or res.get("equality", 0.0) > 1e-6:
                    problems.append(f"{tag}: chosen torque violates (32): {res}")
                problems.extend(_direction_problems(step, np.asarray(ts.direction, float), tag))
            except CTPError as e:
                problems.append(f"{tag}: torque set (32) empty: {e}")
        problems.extend(_torque_hold_problems(scene, hand, step, tag))
        problems.extend(_penetration_problems(scene, hand, step, tag))
    return problems


#: a sliding contact's body point stays this close (scene units) to its face along a slide, and
#: the state after the slide has the contact at that point within it
SLIDE_GAP_TOL = 1e-6


def _slide_problems(scene: Scene, hand: HandKinematics, step: PlanStep, tag: str) -> list[str]:
    """A ``slide`` (eq. 33 with one S-point, the object still), densely (every waypoint, at most
    :data:`DENSE_STEP` apart in every joint): the object does not move; the sliding contact's body
    point lies on the plane of the face it started on (gap within :data:`SLIDE_GAP_TOL`) and inside
    that face (the face's normal its only normal); every other contact of a finger stays where it
    is (:data:`KEPT_CONTACT_TOL`); the finger's path is certified collision-free, its touching links
    allowed to touch, not to penetrate; at every waypoint the state with the contact where it has
    slid is a valid scene, the other contacts have a stationary grasp (18) with the sliding contact
    ``D`` and eq. (33) holds with its kinetic friction against the waypoint's slip; and the state
    after the step has the contact at the body point's end position."""
    t = step.transition
    out: list[str] = []
    b = step.before
    slid = [i for i, ch in enumerate(t.combination) if ch == "S"]
    if len(slid) != 1 or len(t.combination) != b.L:
        return [f"{tag}: a slide has exactly one S letter, one per contact ({t.combination})"]
    i = slid[0]
    c = b.contacts[i]
    ref = hand.resolve_body(c.body)
    if ref is None or ref.finger is None or not isinstance(scene.object.shape, Box) or b.dim != 3:
        return [f"{tag}: only a finger link's contact on a box slides ({c.body})"]
    if float(np.max(np.abs(t.object_path - b.pose_vector()), initial=0.0)) > CHAIN_TOL:
        out.append(f"{tag}: the object moves during a slide")
    if len(t.q_path) > 1 and float(np.max(np.abs(np.diff(t.q_path, axis=0)))) > DENSE_STEP * (1 + 1e-9):
        out.append(f"{tag}: the path is not dense (more than {DENSE_STEP:g} rad between waypoints)")
    R = b.rotation[:3, :3]
    h = np.asarray(scene.object.shape.size, dtype=float) / 2  # (3,)
    centre = np.asarray(scene.object.shape.position if scene.object.shape.position is not None else np.zeros(3), float)
    n_obj = -np.asarray(c.normal_object, dtype=float)  # outward, object frame
    ax = int(np.argmax(np.abs(n_obj)))
    plane = centre[ax] + np.sign(n_obj[ax]) * h[ax]
    gap, k_gap, k_out = 0.0, 0, -1
    for k, q in enumerate(t.q_path):
        p = R.T @ (hand.point_position(ref, c.point_body, q) - b.position)  # (3,) object frame
        g = abs(float(np.sign(n_obj[ax]) * (p[ax] - plane)))
        if g > gap:
            gap, k_gap = g, k
        off = max(float(abs(p[a] - centre[a]) - h[a]) for a in range(3) if a != ax)
        if off >= 0.0 and k_out < 0:
            k_out = k
    if gap > SLIDE_GAP_TOL:
        out.append(f"{tag}: the sliding contact {i} ({c.body}) leaves its face (gap {gap:.3g} at waypoint {k_gap})")
    if k_out >= 0:
        out.append(f"{tag}: the sliding contact {i} ({c.body}) leaves its face over an edge (at waypoint {k_out})")
    for j, cj in enumerate(b.contacts):
        rj = hand.resolve_body(cj.body)
        if j == i or rj is None or rj.finger is None:
            continue
        drift = max(float(np.linalg.norm(hand.point_position(rj, cj.point_body, q) - b.world_point(j)))
                    for q in t.q_path)
        if drift > KEPT_CONTACT_TOL:
            out.append(f"{tag}: kept contact {j} ({cj.body}) moves by {drift:.3g}")
    model = CollisionModel.of(scene, hand)
    f = ref.finger
    sl = hand.finger_slice(f)
    touching = [r for cc in b.contacts if (r := hand.resolve_body(cc.body)) is not None and r.finger == f]
    allow = model.start_allowance(f, b.q, b.position, b.rotation)
    allow = np.where(allow < 0.0, allow - OVERLAP_SLACK * model.min_radius, allow) - ROUNDING
    ok, clear, _ = path_clearance_certified(model, f, b.q, t.q_path[:, sl], b.position, b.rotation, touching, 0, allow)
    if not ok:
        out.append(f"{tag}: the sliding finger's path collides or penetrates (clearance {clear:.3g})")
    if out:
        return out
    comb_d = t.combination.replace("S", "D")
    for k, q in enumerate(t.q_path):
        dq = t.q_path[k + 1] - q if k + 1 < len(t.q_path) else q - t.q_path[k - 1]
        x = hand.point_position(ref, c.point_body, q)
        moved = GraspContact(c.body, c.point_body, R.T @ (x - b.position), c.normal_object, c.mu)
        here = GraspState(tuple(moved if j == i else cc for j, cc in enumerate(b.contacts)), q, b.position,
                          b.rotation, b.dim)
        try:
            sa = StateAnalysis.of(scene, here, hand)
        except CTPError as e:
            return [f"{tag}: at waypoint {k} the slid contact is not a valid scene: {e}"]
        if sa.stationary(comb_d) is None:
            return [f"{tag}: at waypoint {k} the holding contacts have no stationary grasp (18)"]
        p = sa.parts(t.combination)
        if not sliding_equilibrium(p.system, p.sel, p.st, p.fs, dq):
            return [f"{tag}: at waypoint {k} no equilibrium (33) with the sliding contact's kinetic friction"]
    after = next((j for j, bb in enumerate(step.after.bodies()) if bb == c.body), None)
    end = hand.point_position(ref, c.point_body, t.q_path[-1])
    if after is None or float(np.linalg.norm(step.after.world_point(after) - end)) > SLIDE_GAP_TOL:
        out.append(f"{tag}: the state after the slide does not have contact {i} ({c.body}) where it slid")
    return out


def _direction_problems(step: PlanStep, direction: Array, tag: str) -> list[str]:
    """Every segment of the object path goes along the re-analysed DAFC ``direction`` ``(D,)``
    (the motion its torque produces), within :data:`MIN_DIRECTION_COSINE`."""
    t = step.transition
    S = np.array([pose_displacement(step.before, pose) for pose in t.object_path])  # (n, D)
    if len(S) < 2 or float(np.linalg.norm(S[-1] - S[0])) <= 1e-12:
        return [f"{tag}: the object does not move"]
    cos = direction_cosines(S, direction / np.linalg.norm(direction))
    k = int(np.argmin(cos))
    if cos[k] < MIN_DIRECTION_COSINE:
        return [f"{tag}: object path segment {k} leaves the analysed direction (cosine {cos[k]:.4f} < "
                f"{MIN_DIRECTION_COSINE})"]
    return []


#: waypoints of an object motion at which :func:`_torque_hold_problems` re-computes the forces
TORQUE_HOLD_WAYPOINTS = 8


def _torque_hold_problems(scene: Scene, hand: HandKinematics, step: PlanStep, tag: str) -> list[str]:
    """The step's one torque keeps the sticking contacts in their friction set (16) all along its
    motion: at :data:`TORQUE_HOLD_WAYPOINTS` waypoints, evenly spaced to the last, the contact
    forces it produces there (:func:`analysis.torque_forces.torque_forces`, eq. 29 with ``W_2`` of
    22) exist and have a margin >= 0 (:mod:`planner.motion_length`). Combinations of F- and
    D-points without line contacts only (an S-point's kinetic friction needs its slip, which the
    path does not record; line contacts: :mod:`planner.motion_length`). A waypoint before the last
    whose grasp the scene check rejects is passed over: a forearm across a box's edge has its
    normal turned to the link's surface (:func:`planner.motion_length.turned_normals`) only at the
    states the planner analyses, in between it snaps to a face (the Panda's pivot); the last
    waypoint, the state after the step, must be analysable."""
    t = step.transition
    keep = [i for i, ch in enumerate(t.combination) if ch != "D"]
    if set(t.combination) - {"F", "D"} or t.tau is None or line_contacts(hand, [step.before.contacts[i] for i in keep]):
        return []
    n = len(t.q_path)

    def analyse(state: GraspState) -> StateAnalysis:
        return StateAnalysis.of(scene, state, hand)

    for k in sorted({round(j * (n - 1) / TORQUE_HOLD_WAYPOINTS) for j in range(1, TORQUE_HOLD_WAYPOINTS + 1)}):
        try:
            there = waypoint_state(scene, hand, step.before, keep, t.q_path[k], t.object_path[k])
            margin = torque_margin(analyse, there, "F" * len(keep), t.tau)
        except CTPError as e:
            if k < n - 1:  # a corner's normal between the states the planner analyses (see above)
                continue
            return [f"{tag}: at waypoint {k} the grasp cannot be analysed: {e}"]
        if margin < 0.0:
            return [f"{tag}: at waypoint {k} of {n} the chosen torque's contact forces leave the friction set "
                    f"(16) by {-margin:.3g} N" if np.isfinite(margin) else
                    f"{tag}: at waypoint {k} of {n} no contact forces produce the chosen torque"]
    return []


def _penetration_problems(scene: Scene, hand: HandKinematics, step: PlanStep, tag: str) -> list[str]:
    """Densely, at every waypoint of an object motion (consecutive waypoints at most
    :data:`DENSE_STEP` apart in every joint): the object does not penetrate a fixed body (deeper
    than :data:`PENETRATION_TOL`, or than an overlap it has at the start) and no finger link
    penetrates the object, a fixed body, another link (the links in contact may touch the object;
    overlaps at the start may persist, not deepen: :meth:`CollisionModel.start_allowance`)."""
    t = step.transition
    model = CollisionModel.of(scene, hand)
    out: list[str] = []
    if len(t.q_path) > 1 and float(np.max(np.abs(np.diff(t.q_path, axis=0)))) > DENSE_STEP * (1 + 1e-9):
        out.append(f"{tag}: the path is not dense (a joint moves {np.max(np.abs(np.diff(t.q_path, axis=0))):.3g} "
                   f"rad between waypoints, more than {DENSE_STEP:g})")
    b = step.before
    refs = [hand.resolve_body(c.body) for c in b.contacts]
    touching = [[r for r in refs if r is not None and r.finger == f] for f in range(len(hand.fingers))]
    allow = [model.start_allowance(f, b.q, b.position, b.rotation) for f in range(len(hand.fingers))]
    floor = min(0.0, model.object_clearance(b.position, b.rotation)) - PENETRATION_TOL
    for k, (q, vec) in enumerate(zip(t.q_path, t.object_path, strict=True)):
        pose = Pose.from_vector(vec, scene.dim)
        oc = model.object_clearance(pose.position, pose.rotation)
        if oc < floor:
            out.append(f"{tag}: at waypoint {k} the object penetrates a fixed body by {-oc:.3g}")
            break
        worst = min(model.finger_clearance(f, q, pose.position, pose.rotation, touching[f], allow[f])
                    for f in range(len(hand.fingers)))
        if worst < -1e-9:
            out.append(f"{tag}: at waypoint {k} a finger link penetrates (clearance {worst:.3g})")
            break
    return out


def _manifold_problems(scene: Scene, hand: HandKinematics, step: PlanStep, tag: str) -> list[str]:
    """Every waypoint of an object motion lies on the contact manifold of its kept contacts (body
    point = object point; for a 2-D disk, rolling on a link's side: :func:`motion_manifold`; for a
    3-D sphere on a capsule link's side, its gap: :meth:`LinkRollingMotion.holonomic`) and of
    its sliding ones (touching), eq. (7) to every order, within 1e-6.
    The sliding contacts are the step's ``sliding_contacts``, as the planner followed them."""
    t = step.transition
    sliding = [int(i) for i in getattr(t.figures, "sliding_contacts", ())]
    sticking = [i for i, ch in enumerate(t.combination) if ch != "D" and i not in sliding]
    try:
        rolling = link_rolling_motion(scene, hand, step.before, sticking, sliding)
        # a sphere rolling on a link's side: its gap, not a glued point
        F = motion_manifold(scene, hand, step.before, sticking, sliding).function if rolling is None else \
            rolling.holonomic
    except CTPError as e:
        return [f"{tag}: {e}"]
    worst = max(float(np.linalg.norm(F(np.concatenate([q, pose_displacement(step.before, pose)]))))
                for q, pose in zip(t.q_path, t.object_path, strict=True))
    return [] if worst <= 1e-6 else [f"{tag}: path leaves the contact manifold (residual {worst:.2g})"]


#: rolling kinematics of a step hold within this (scene units): the gap, the arc on the link
#: against ``r`` times the relative turn, the rolled contact of the state after the step
ROLL_TOL = 1e-6


def _axis_foot(hand: HandKinematics, ref: BodyRef, q: Array, centre: Array) -> tuple[float, float, Array, float, float]:
    """``(t, L, u, phi, dist)`` of the disk centre ``centre`` ``(2,)`` and the link ``ref`` at ``q``:
    the centre's foot on the link's axis ``a -> b`` (fraction of it, unclipped), the axis' length,
    the unit vector ``(2,)`` from the closest axis point to the centre, the axis' angle and the
    centre's distance from the axis segment."""
    a, b = hand.body_segment(ref, q)
    e = b[:2] - a[:2]  # (2,)
    L = float(np.linalg.norm(e))
    t = float((centre - a[:2]) @ e) / (L * L)
    v = centre - (a[:2] + min(max(t, 0.0), 1.0) * e)  # (2,)
    dist = float(np.linalg.norm(v))
    return t, L, v / dist, float(np.arctan2(e[1], e[0])), dist


def _surface_arc(side: float, rho: float, t: float, L: float, u: Array, phi: float) -> float:
    """Arc length of the touching point along a capsule's surface (counter-clockwise round it): on
    the side ``side`` (``+1`` left of the axis) ``-side t L`` (``t`` clipped to the link), plus
    ``rho psi`` round an end cap, ``psi`` the angle of ``u`` ``(2,)`` from the side's outward
    normal (``phi`` the axis' angle)."""
    n = side * np.array([-np.sin(phi), np.cos(phi)])  # (2,) the side's outward normal
    psi = float(np.arctan2(n[0] * u[1] - n[1] * u[0], n @ u))
    return -side * min(max(t, 0.0), 1.0) * L + rho * psi


def _rolling_problems(scene: Scene, hand: HandKinematics, step: PlanStep, tag: str) -> list[str]:
    """The rolling kinematics of an object motion of a 2-D disk (radius ``r``), from the positions
    of the waypoints alone (not the planner's manifold): for every sticking contact on a finger
    link whose disk centre at the start projects inside the link's axis ``a -> b`` (a side
    contact, on the side ``side = +-1``), at every waypoint the centre ``c`` is ``rho + r`` from
    the axis (gap zero) and the arc length the contact travelled on the link's surface,
    ``sigma - sigma_0`` with ``sigma = -side t L + rho psi`` (``t`` the centre's foot on the axis,
    clipped to the link; ``psi`` the angle rolled round an end cap; counter-clockwise round the
    capsule), equals ``r`` times the disk's turn relative to the link, ``(theta - theta_0) -
    (phi - phi_0)`` (``phi`` the axis' angle): rolling without slipping, the arc on the disk equal
    to the arc on the link (a disk turning counter-clockwise on the link rolls clockwise round
    it). The state after the step has the contact at the rolled point ``c - r u`` on the link and
    on the disk (``u`` the unit vector from the axis to ``c``), all within :data:`ROLL_TOL`."""
    if not rolls_on_links(scene):
        return []
    t = step.transition
    shape = scene.object.shape
    assert isinstance(shape, Disk)  # rolls_on_links
    r = float(shape.radius)
    sliding = {int(i) for i in getattr(t.figures, "sliding_contacts", ())}
    out: list[str] = []
    before, after = step.before, step.after
    theta0 = float(t.object_path[0][2])
    for i, ch in enumerate(t.combination):
        if ch == "D" or i in sliding:
            continue
        c = before.contacts[i]
        ref = hand.resolve_body(c.body)
        if ref is None or ref.finger is None:
            continue
        rho = hand.body_radius(ref)
        t0, L0, u0, phi0, _ = _axis_foot(hand, ref, before.q, before.position)
        if not 1e-6 < t0 < 1 - 1e-6:
            continue  # at a link's end: a pivot on the tip, glued (exact there)
        e0 = np.array([np.cos(phi0), np.sin(phi0)])
        side = 1.0 if float(e0[0] * u0[1] - e0[1] * u0[0]) > 0 else -1.0
        sigma0 = _surface_arc(side, rho, t0, L0, u0, phi0)
        worst_gap, worst_slip, k_slip = 0.0, 0.0, 0
        for k, (q, vec) in enumerate(zip(t.q_path, t.object_path, strict=True)):
            centre = np.asarray(vec[:2], dtype=float)
            tt, L, u, phi, dist = _axis_foot(hand, ref, q, centre)
            worst_gap = max(worst_gap, abs(dist - rho - r))
            dphi = (phi - phi0 + np.pi) % (2 * np.pi) - np.pi
            rel = (float(vec[2]) - theta0) - dphi  # the disk's turn relative to the link
            slip = abs((_surface_arc(side, rho, tt, L, u, phi) - sigma0) - r * rel)
            if slip > worst_slip:
                worst_slip, k_slip = slip, k
        if worst_gap > ROLL_TOL:
            out.append(f"{tag}: rolling contact {i} ({c.body}) leaves the link's surface (gap {worst_gap:.3g})")
        if worst_slip > ROLL_TOL:
            out.append(f"{tag}: rolling contact {i} ({c.body}) slips: at waypoint {k_slip} the arc on the link "
                       f"differs from r times the relative turn by {worst_slip:.3g}")
        j = next((j for j, b in enumerate(after.bodies()) if b == c.body), None)
        if j is None:
            out.append(f"{tag}: rolling contact {i} ({c.body}) is missing after the step")
            continue
        _, _, u1, _, _ = _axis_foot(hand, ref, after.q, after.position)
        y = after.position - r * u1  # (2,) where the disk touches the link at the end
        on_link = hand.point_position(ref, after.contacts[j].point_body, after.q)
        err = max(float(np.linalg.norm(on_link - y)), float(np.linalg.norm(after.world_point(j) - y)))
        if err > ROLL_TOL:
            out.append(f"{tag}: the state after the step does not have contact {i} ({c.body}) where it rolled "
                       f"(off by {err:.3g})")
    return out


def _plane_rolling_problems(scene: Scene, hand: HandKinematics, step: PlanStep, tag: str) -> list[str]:
    """The rolling kinematics of an object motion of a 3-D sphere (radius ``r``) on the flat face of
    a fixed body (:func:`~planner.object_motion.rolls_on_planes`), from the waypoints' poses alone
    (not the planner's manifold), for every sticking contact on such a face (outward normal ``n``,
    the face's at the contact of the state before the step):

    * the gap, the sphere's signed distance from the body minus ``r``, is zero at every waypoint;
    * no slip: between consecutive waypoints ``k, k + 1`` the sphere turns by the rotation vector
      ``omega_k = log(R_{k+1} R_k^T)`` (world) and its centre moves by ``dp_k``; the material point
      of the sphere at the contact moves by ``dp_k - r omega_k x n`` over a constant twist, which
      is zero when it rolls; the sum of these slips' lengths over the path is zero;
    * contact-point travel: the contact point on the plane, ``p - r n``, travels
      ``sum |dp_k|``, the one on the sphere, ``R_k^T (-r n)`` (object frame), ``r`` times the sum
      of the angles between consecutive ones, and both equal ``r`` times the sphere's rolling turn
      ``sum |omega_k - (omega_k . n) n|`` (its spin about ``n`` moves neither);
    * the state after the step has the contact at the rolled point ``p - r n`` (on the body) and
      ``R^T (-r n)`` with the inward normal ``R^T n`` (on the sphere).

    A cylinder lying on the face (its axis ``a`` parallel to it, the contact on its curved
    surface at axial offset ``z``, object frame; others are glued) is checked the same way at its
    contact point ``p + z a - r n``: the gap is the distance of the axis point ``p + z a`` from the
    body minus ``r`` (both ends of its line contact: the axis stays parallel to the face), the
    slip is that of its material point there, ``dp_k + omega_k x (z a_k - r n)`` (a turn about
    any axis but its own, a yaw, slips its ends), the travels and the rolled contact are at that
    point.

    All within :data:`ROLL_TOL` (scene units), the travels and the slip summed over the path."""
    if not rolls_on_planes(scene):
        return []
    t = step.transition
    shape = scene.object.shape
    assert isinstance(shape, Sphere | Cylinder)  # rolls_on_planes
    r = float(shape.radius)
    sliding = {int(i) for i in getattr(t.figures, "sliding_contacts", ())}
    before, after = step.before, step.after
    poses = [Pose.from_vector(v, 3) for v in t.object_path]
    out: list[str] = []
    for i, ch in enumerate(t.combination):
        if ch == "D" or i in sliding:
            continue
        c = before.contacts[i]
        ref = hand.resolve_body(c.body)
        if ref is None or ref.finger is not None:
            continue
        body = next(b for b in scene.fixed_bodies if b.name == ref.name)
        cone = shape_normal_cone(body.shape, before.world_point(i), 3, GEOMETRY_TOL)
        if cone is None or cone.generators.shape[0] != 1:
            continue  # an edge or a vertex of the body: glued
        n = np.asarray(cone.generators[0], dtype=float)
        n = n / np.linalg.norm(n)
        z = 0.0  # a cylinder's contact: its axial offset (object frame)
        if isinstance(shape, Cylinder):
            z = float(c.point_object[2])
            if abs(float(before.pose.rotation[:, 2] @ n)) > 1e-9 or abs(
                    float(np.linalg.norm(np.asarray(c.point_object, dtype=float)[:2])) - r) > GEOMETRY_TOL:
                continue  # not lying on the face, or on an end face: glued
        gaps = []
        for pose in poses:
            sd = shape_signed_distance(body.shape, pose.position + z * pose.rotation[:, 2], 3)
            gaps.append(np.inf if sd is None else abs(float(sd) - r))
        worst_gap = float(np.max(gaps))
        slip, plane_travel, sphere_travel, turn = 0.0, 0.0, 0.0, 0.0
        for a, b in itertools.pairwise(poses):
            omega = matrix_to_rotvec(b.rotation @ a.rotation.T)  # (3,)
            dp = b.position - a.position  # (3,)
            slip += float(np.linalg.norm(dp + np.cross(omega, z * a.rotation[:, 2] - r * n)))
            plane_travel += float(np.linalg.norm(dp + z * (b.rotation[:, 2] - a.rotation[:, 2])))
            za, zb = a.rotation.T @ -n, b.rotation.T @ -n  # the contact point on the sphere (unit)
            sphere_travel += r * float(np.arctan2(np.linalg.norm(np.cross(za, zb)), za @ zb))
            turn += float(np.linalg.norm(omega - (omega @ n) * n))
        if worst_gap > ROLL_TOL:
            out.append(f"{tag}: rolling contact {i} ({c.body}) leaves the plane (gap {worst_gap:.3g})")
        if slip > ROLL_TOL:
            out.append(f"{tag}: rolling contact {i} ({c.body}) slips by {slip:.3g} over "
                       "the path (the sphere's contact point does not stay at rest on the plane)")
        for name, travel in (("plane", plane_travel), ("sphere", sphere_travel)):
            if abs(travel - r * turn) > ROLL_TOL:
                out.append(f"{tag}: rolling contact {i} ({c.body}): the contact point travels {travel:.6g} on the "
                           f"{name}, not r times the rolling turn {r * turn:.6g}")
        y = after.position + z * after.pose.rotation[:, 2] - r * n  # (3,) where it touches the plane at the end
        out.extend(_rolled_contact_problems(hand, ref, after, c.body, y, n, r, tag, i))
    return out


def _rolled_contact_problems(hand: HandKinematics, ref: BodyRef, after: GraspState, body: str, y: Array,
                             n: Array, r: float, tag: str, i: int) -> list[str]:
    """The state after a rolling step has a contact on ``body`` at the rolled point ``y`` (3,) with
    the normal ``n`` (3,): of that body's contacts the nearest one (a cylinder has two on the
    table), its body point, world point and ``r`` times its normal each within :data:`ROLL_TOL`."""
    errs = [max(float(np.linalg.norm(hand.point_position(ref, after.contacts[j].point_body, after.q) - y)),
                float(np.linalg.norm(after.world_point(j) - y)),
                r * float(np.linalg.norm(after.world_normal(j) - n)))
            for j, name in enumerate(after.bodies()) if name == body]
    if not errs:
        return [f"{tag}: rolling contact {i} ({body}) is missing after the step"]
    if min(errs) > ROLL_TOL:
        return [f"{tag}: the state after the step does not have contact {i} ({body}) where it rolled "
                f"(off by {min(errs):.3g})"]
    return []


def _link_rolling_problems(scene: Scene, hand: HandKinematics, step: PlanStep, tag: str) -> list[str]:
    """The rolling kinematics of an object motion of a 3-D sphere (radius ``r``) on the side of a
    capsule link (:func:`planner.link_roll.link_rolls`), from the waypoints alone
    (:func:`planner.link_roll.link_roll_check`): the gap ``|p - y| - rho - r`` zero at every
    waypoint; the slip, in the link's frame, ``|dc + omega_rel x (-r u_mid)|`` summed over the
    segments, zero; the contact point's travel on the link (link frame) equal to its travel on the
    sphere (object frame); the state after the step has the contact at the rolled point
    ``p - r u`` (on the link and on the sphere) with the normal ``u``. A cylinder lying along the
    link (its line contact's two ends): the same at each end with its axis point ``P = p + z a`` for
    the centre, and its axis parallel to the link's. All within :data:`ROLL_TOL`."""
    t = step.transition
    sliding = {int(i) for i in getattr(t.figures, "sliding_contacts", ())}
    sticking = [i for i, ch in enumerate(t.combination) if ch != "D" and i not in sliding]
    rolls = link_rolls(hand, scene, step.before, sticking)
    if not rolls:
        return []
    r = object_radius(scene)
    axial = isinstance(scene.object.shape, Cylinder)
    X = np.array([np.concatenate([q, pose_displacement(step.before, pose)])
                  for q, pose in zip(t.q_path, t.object_path, strict=True)])  # (n, M + 6)
    after = step.after
    out: list[str] = []
    for i in rolls:
        c = step.before.contacts[i]
        ref = hand.resolve_body(c.body)
        assert ref is not None
        z = axial_offset(scene, step.before, i)
        chk = link_roll_check(hand, ref, r, X, step.before.pose, z, axial)
        if chk.axis_angle > ROLL_TOL:
            out.append(f"{tag}: rolling contact {i} ({c.body}): the cylinder's axis leaves the link's "
                       f"(sine {chk.axis_angle:.3g})")
        if chk.max_gap > ROLL_TOL:
            out.append(f"{tag}: rolling contact {i} ({c.body}) leaves the link's surface (gap {chk.max_gap:.3g})")
        if chk.slip > ROLL_TOL:
            out.append(f"{tag}: rolling contact {i} ({c.body}) slips by {chk.slip:.3g} on the link over the path")
        if abs(chk.travel_link - chk.travel_object) > ROLL_TOL:
            out.append(f"{tag}: rolling contact {i} ({c.body}): the contact point travels {chk.travel_link:.6g} on "
                       f"the link and {chk.travel_object:.6g} on the sphere")
        P = axis_point(after.pose, z)
        _, u, _ = link_contact(hand, ref, r, after.q, P)
        y = P - r * u  # (3,) the rolled contact
        out.extend(_rolled_contact_problems(hand, ref, after, c.body, y, u, r, tag, i))
    return out


#: a step starts where the one before it ended, joints (rad or scene units) and object pose, within
#: this (plan files round paths to 1e-10)
CHAIN_TOL = 1e-6


def _torque_limit_problems(scene: Scene, hand: HandKinematics, step: PlanStep, tag: str) -> list[str]:
    """The step's torques within the joints' limits (the URDF effort limits and the scene's
    ``tau_max``, :func:`analysis.torque_limits.hand_torque_limits`) to ``LIMIT_TOL``: the chosen
    torque ``tau`` (object motions: a member of T, 32) and the holding torque ``tau_st`` (18)."""
    limits = hand_torque_limits(scene, hand)  # (M,) or None
    if limits is None:
        return []
    out = []
    for name, tau in (("torque", step.transition.tau), ("holding torque (18)", step.transition.tau_stationary)):
        if tau is None:
            continue
        for j in over_limit(np.asarray(tau, dtype=float), limits, LIMIT_TOL):
            out.append(f"{tag}: the {name} of joint {hand.joint_labels()[j]} is {float(tau[j]):.4g} N m, over its "
                       f"limit {float(limits[j]):.4g} N m")
    return out


def verify_plan(scene: Scene, plan: Plan) -> list[str]:
    """Problems found when re-checking every step of ``plan`` (empty: the plan passes): each step
    (:func:`verify_step`), and that each step starts where the one before it ended (the hand's
    joints and the object's pose within :data:`CHAIN_TOL`: no jump between two steps)."""
    hand = HandKinematics.from_scene(scene)
    out: list[str] = []
    for step in plan.steps:
        out.extend(verify_step(scene, hand, step))
    for a, b in itertools.pairwise(plan.steps):
        for name, end, start in (("joints", a.transition.q_path[-1], b.transition.q_path[0]),
                                 ("object pose", a.transition.object_path[-1], b.transition.object_path[0])):
            jump = float(np.max(np.abs(np.asarray(start, dtype=float) - np.asarray(end, dtype=float))))
            if jump > CHAIN_TOL:
                out.append(f"step {b.index}: starts {jump:.3g} away from where step {a.index} ended ({name})")
    return out
