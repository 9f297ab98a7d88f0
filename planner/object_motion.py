"""Object motions (paper eq. 30-32): integration of the motion chosen by (31), then OMPL's
constrained planning on the contact manifold.

The analysis fixes the start, the direction ``dr`` (a DAFC member) and the finger motion ``dq``
chosen by (31). :func:`integrate_object_motion` follows them in small steps on
``A_c [dq; dr] = 0``, each projected back onto the contact manifold with the object held to the
analysed direction (:class:`~planner.manifold.ContactManifold` with ``direction``:
:func:`~planner.manifold.project_manifold` on hand and object together), which gives the end
configuration (the D-contacts separated by the planned clearance). :func:`plan_object_motion`
then plans the path between the two ends with OMPL's constrained planning: a
``ProjectedStateSpace`` over ``x = [q; s]`` (hand configuration and object displacement) with the
same constraint (the F-points stay together, exactly, not only to first order; the object moves
along ``dr`` and along no other direction of the motion space, so a path cannot take it where its
torque does not), ``RRTConnect`` whose motions are manifold geodesics checked for joint limits and
collisions (the links against the object, the fixed bodies and each other, and the object against
the fixed bodies), and the solution densified on the manifold until no joint moves more than
:data:`~planner.collision.DENSE_STEP` between checked states, each of which is checked again, and
every segment of the object path within :data:`MIN_DIRECTION_COSINE` of ``dr``. Where a step of the
integration or a densified state slides along the manifold instead of onto it (the redundant rows
of line contacts), it is projected again with the object's progress along ``dr`` held; where
OMPL's path fails those checks, the integrated path is densified and checked the same way
(``ompl_planner_states = 0`` says so).

For a 2-D disk object (:func:`rolls_on_links`) the sticking contacts on the side of a finger link
roll (:class:`~planner.manifold.ContactManifold` with ``rolling=True``: the contact point moves by
``r`` times the disk's turn relative to the link on both surfaces, exactly), those at a sharp link
tip and on fixed bodies keep their glued points (exact there); for a 3-D sphere
(:func:`rolls_on_planes`) the sticking contacts on a flat face of a fixed body (a table) roll (the
sphere turns about a fixed axis ``omega`` while its centre moves by ``r omega x n``, exactly), and
those on the side of a capsule link of positive radius roll too (:mod:`planner.link_roll`: rolling
on a moving link is non-holonomic, so the motion is integrated on its velocity rows and its path
checked as it is, not planned by OMPL); its contacts on links of radius 0 and at link tips stay
glued; :func:`rolled_contacts` gives the contacts where the motion leaves them.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from analysis._types import Array
from analysis.geometry import link_shapes, segment_normal_cone, shape_normal_cone, shape_signed_distance
from analysis.kinematics import BodyRef, HandKinematics
from analysis.loader import GEOMETRY_TOL
from analysis.pose import Pose
from analysis.rotations import matrix_to_rotvec
from analysis.scene import Cylinder, Disk, Scene, Sphere
from planner.budget import CheckBudget
from planner.collision import DENSE_STEP, PENETRATION_TOL, CollisionModel
from planner.ik import joint_limits
from planner.link_roll import (
    LINK_ROLL_SLIP_TOL,
    LinkRollingMotion,
    axial_offset,
    axis_point,
    link_contact,
    link_rolls,
    object_radius,
)
from planner.manifold import ContactManifold, pose_displacement, project_manifold
from planner.state import GraspContact, GraspState


@dataclass(frozen=True)
class ObjectMotion:
    """An integrated object motion: hand and object paths, the final contacts."""

    q_path: Array  # (n, M)
    pose_path: Array  # (n, D) pose vectors
    separations: Array  # (#D,) final gap of each separating contact
    length: float  # object path length (pose-vector norm)
    max_residual: float  # largest contact-constraint residual after projection
    #: the unit object direction ``dr`` ``(D,)`` followed (the analysed DAFC direction), if any
    direction: Array | None = None
    #: ``(D, a~)`` the motion space's object directions it was followed in (None: every direction)
    motion_space: Array | None = None


def rolls_on_links(scene: Scene) -> bool:
    """Do the sticking contacts on a link's side roll in object motions on the contact manifold? For
    a 2-D disk object (:class:`~planner.manifold.ContactManifold` ``rolling=True``); a 3-D sphere
    rolls there on the flat faces of fixed bodies (:func:`rolls_on_planes`), and on capsule link
    sides by its velocity rows (:func:`planner.link_roll.link_rolls`, not a manifold)."""
    return scene.dim == 2 and isinstance(scene.object.shape, Disk)


def rolls_on_planes(scene: Scene) -> bool:
    """Do the sticking contacts of a 3-D sphere on the flat faces of fixed bodies (a table) roll in
    object motions (:class:`~planner.manifold.ContactManifold` ``rolling=True``: the sphere turns
    about a fixed axis while its centre moves by ``r omega x n``, the contact point moving by ``r``
    times the turn on the plane and on the sphere)? Always for a sphere with fixed bodies: an F
    contact on a plane is a rolling one (its glued point would sink the sphere into the plane). And
    for a 3-D cylinder: its contacts on its curved surface with a face its axis lies parallel to
    roll about its axis (exact: holonomic), the others stay glued."""
    return scene.dim == 3 and isinstance(scene.object.shape, Sphere | Cylinder) and bool(scene.fixed_bodies)


def motion_manifold(scene: Scene, hand: HandKinematics, state: GraspState, sticking: Sequence[int],
                    sliding: Sequence[int] = (), direction: Array | None = None,
                    motion_space: Array | None = None) -> ContactManifold:
    """The contact manifold an object motion from ``state`` follows (and :mod:`planner.verify`
    checks): the sticking contacts glued (eq. 7), rolling on a link's side for a 2-D disk
    (:func:`rolls_on_links`) and on a fixed body's face for a 3-D sphere (:func:`rolls_on_planes`),
    the ``sliding`` ones touching (eq. 5)."""
    return ContactManifold(hand, state, sticking, sliding, scene, direction=direction, motion_space=motion_space,
                           rolling=rolls_on_links(scene) or rolls_on_planes(scene))


def rolled_contacts(hand: HandKinematics, scene: Scene, state: GraspState, sticking: Sequence[int], q: Array,
                    s: Array, contacts: Sequence[GraspContact] | None = None) -> tuple[GraspContact, ...]:
    """The contacts after an object motion from ``state`` that ends with the hand at ``q`` ``(M,)``
    and the object at displacement ``s`` ``(D,)``: every rolling contact (a sticking contact on a
    link's side of a 2-D disk, :func:`motion_manifold`; of a 3-D sphere on a table or a capsule
    link's side, :func:`_link_rolled`) at its rolled point (new point on the body, new point and
    inward normal on the object, :meth:`ContactManifold.rolling_contact`), the others as in
    ``contacts`` (default: ``state.contacts``)."""
    out = list(state.contacts if contacts is None else contacts)
    if not sticking:
        return tuple(out)
    _link_rolled(hand, scene, state, sticking, q, s, out)
    if not (rolls_on_links(scene) or rolls_on_planes(scene)):
        return tuple(out)
    man = motion_manifold(scene, hand, state, sticking)
    x = np.concatenate([np.asarray(q, dtype=float), np.asarray(s, dtype=float)])  # (M + D,)
    for k in range(len(man.rolls)):
        i, y, p_obj, n_obj = man.rolling_contact(k, x)
        ref = man.rolls[k][1]
        c = out[i]
        out[i] = GraspContact(c.body, hand.to_local(ref, y, q), p_obj, n_obj, c.mu, c.origin)
    for k in range(len(man.plane_rolls)):  # a sphere on a plane: the new point on both
        i, y, p_obj, n_obj = man.plane_rolling_contact(k, x)
        ref = man.plane_rolls[k][1]
        c = out[i]
        out[i] = GraspContact(c.body, hand.to_local(ref, y, q), p_obj, n_obj, c.mu, c.origin)
    return tuple(out)


def _link_rolled(hand: HandKinematics, scene: Scene, state: GraspState, sticking: Sequence[int], q: Array,
                 s: Array, out: list[GraspContact]) -> None:
    """Set in ``out`` each contact of a 3-D sphere, or a cylinder along the link, rolling on a capsule
    link's side (:func:`planner.link_roll.link_rolls`) at its rolled point ``c = P - r u`` (new
    point on the link and on the object, inward normal ``R^T u``; ``P = p + z a`` the object's
    axis point at the contact's axial coordinate, the centre ``p`` of a sphere, ``u`` the unit
    normal from the link's axis to ``P``) with the hand at ``q`` and the object at displacement ``s``."""
    rolls = link_rolls(hand, scene, state, sticking)
    if not rolls:
        return
    r = object_radius(scene)
    pose = state.pose.displaced(np.asarray(s, dtype=float))
    for i in rolls:
        ref = hand.resolve_body(state.contacts[i].body)
        assert ref is not None
        P = axis_point(pose, axial_offset(scene, state, i))
        _, u, _ = link_contact(hand, ref, r, np.asarray(q, dtype=float), P)
        c_w = P - r * u
        c = out[i]
        out[i] = GraspContact(c.body, hand.to_local(ref, c_w, q), pose.to_local(c_w), pose.R_d.T @ u, c.mu, c.origin)


def project_contacts(
    hand: HandKinematics, state: GraspState, q: Array, sticking: Sequence[int], iters: int = 30
) -> tuple[Array, float]:
    """Gauss-Newton projection of ``q`` onto the manifold of the sticking contacts: body point
    (``point_body`` on its body at ``q``) = object point (``point_object`` at the state's pose)."""
    q = np.array(q, dtype=float)
    res = 0.0
    for _ in range(iters):
        rows, errs = [], []
        for i in sticking:
            c = state.contacts[i]
            ref = hand.resolve_body(c.body)
            assert ref is not None
            if ref.finger is None:
                continue
            x = hand.point_position(ref, c.point_body, q)
            errs.append(state.world_point(i) - x)
            rows.append(hand.point_jacobian(ref, x, q))
        if not rows:
            return q, 0.0
        e = np.concatenate(errs)
        res = float(np.linalg.norm(e))
        if res < 1e-11:
            break
        q = q + np.linalg.lstsq(np.vstack(rows), e, rcond=None)[0]
    return q, res


def moved(state: GraspState, pose_step: Array) -> GraspState:
    """The state with the object displaced by ``pose_step`` ``(D,)`` (``dr`` of the paper: 2-D
    ``(dx, dy, dtheta)``; 3-D ``(dp, w)`` with ``w`` a world rotation vector)."""
    return state.with_pose(state.pose.displaced(pose_step))


@dataclass(frozen=True)
class _MotionCheck:
    """Validity of hand configurations during an object motion that starts at ``state``: joint
    limits, and collisions with the contact links (``busy``) allowed to touch the object and the
    overlaps present at the start allowed to persist (:meth:`CollisionModel.start_allowance`),
    and the object clear of the fixed bodies (:meth:`CollisionModel.object_clearance`: it may touch
    them, or keep an overlap it has at the start, but not go deeper than :data:`PENETRATION_TOL`)."""

    model: CollisionModel
    touching: list[list[BodyRef]]  # per finger
    allow: list[Array]  # per finger
    limits: list[tuple[Array, Array]]  # per finger
    object_floor: float = -PENETRATION_TOL  # smallest object clearance to the fixed bodies allowed

    @classmethod
    def of(cls, model: CollisionModel, state: GraspState, busy: Sequence[int]) -> _MotionCheck:
        hand = model.hand
        refs = [hand.resolve_body(state.contacts[i].body) for i in busy]
        F = range(len(hand.fingers))
        start = model.object_clearance(state.position, state.rotation)
        return cls(model, [[b for b in refs if b is not None and b.finger == f] for f in F],
                   [model.start_allowance(f, state.q, state.position, state.rotation) for f in F],
                   [joint_limits(hand, f) for f in F], min(0.0, start) - PENETRATION_TOL)

    def __call__(self, q: Array, pose: Pose) -> bool:
        """Is the hand configuration ``q`` ``(M,)`` valid with the object at ``pose``?"""
        hand = self.model.hand
        position, rotation = pose.position, pose.rotation
        for f in range(len(hand.fingers)):
            qf = q[hand.finger_slice(f)]
            if np.any(qf < self.limits[f][0] - 1e-9) or np.any(qf > self.limits[f][1] + 1e-9):
                return False
            if not self.model.is_clear(f, q, position, rotation, self.touching[f], self.allow[f], -1e-9):
                return False
        return self.model.object_clearance(position, rotation) >= self.object_floor

    def all_valid(self, Q: Array, poses: Sequence[Pose]) -> bool:
        """Whether :meth:`__call__` holds at every hand configuration of ``Q`` ``(N, M)`` with the
        object at ``poses``: the joint limits, then the clearances of the fingers that
        :meth:`CollisionModel.clear_along` checks in one pass (all the states at once, equal to
        one at a time), then the other fingers and the object state by state; the first violation
        ends it (the answer is the same as checking state after state)."""
        hand, model = self.model.hand, self.model
        Q = np.asarray(Q, dtype=float)
        F = range(len(hand.fingers))
        for f in F:
            qf = Q[:, hand.finger_slice(f)]
            if not bool(np.all((qf >= self.limits[f][0] - 1e-9) & (qf <= self.limits[f][1] + 1e-9))):
                return False
        batched = [f for f in F if model.batched(f)]
        if batched:
            positions = np.array([p.position for p in poses]).reshape(len(poses), -1)  # (N, d)
            rotations = np.array([p.rotation for p in poses]).reshape(len(poses), 3, 3)  # (N, 3, 3)
            for f in batched:
                if not bool(np.all(model.clear_along(f, Q, positions, rotations, self.allow[f], self.touching[f],
                                                     -1e-9))):
                    return False
        for q, pose in zip(Q, poses, strict=True):
            for f in F:
                if f not in batched and not model.is_clear(f, q, pose.position, pose.rotation, self.touching[f],
                                                           self.allow[f], -1e-9):
                    return False
            if model.object_clearance(pose.position, pose.rotation) < self.object_floor:
                return False
        return True


def integrate_object_motion(
    model: CollisionModel,
    state: GraspState,
    dr: Array,  # (D,) unit object direction
    dq: Array,  # (M,) finger motion per unit object motion (eq. 31)
    sticking: Sequence[int],
    separating: Sequence[int],
    distance: float,
    steps: int = 20,
    check_path: bool = True,
    sliding: Sequence[int] = (),
    motion_space: Array | None = None,
) -> ObjectMotion | None:
    """Move the object by ``distance`` along ``dr`` with the fingers along ``dq``: steps
    ``[q; s] + h [dq; dr]``, each projected onto :class:`ContactManifold` with the direction rows
    (minimum-norm Newton steps on hand and object together), so the object keeps moving along
    ``dr`` and along no other direction of ``motion_space`` (``(D, a~)``, the motion space's
    object directions ``Lambda~_r``; default every direction: a straight line); ``None`` if the
    contacts cannot follow (residual above ``1e-6``), a link would penetrate the object or the
    object a fixed body, or a separating contact would not separate. With ``check_path = False``
    only the end configuration is checked for collisions (the path is then planned by
    :func:`plan_object_motion`).

    ``sliding`` contacts (S or N) keep touching while they slide: a disk or sphere on any body,
    the corner of any other object on a fixed body (a box's corners along the table)."""
    hand = model.hand
    dr = np.asarray(dr, dtype=float)
    dr = dr / np.linalg.norm(dr)
    rolling = _link_rolling(model.scene, hand, state, sticking, sliding, dr, motion_space)
    if rolling is not None:  # a sphere rolling on a link's side: integrated on its velocity rows
        return _integrate_link_rolling(model, state, rolling, dr, dq, separating, distance, steps, check_path,
                                       (*sticking, *separating, *sliding), motion_space)
    man = motion_manifold(model.scene, hand, state, sticking, sliding, direction=dr, motion_space=motion_space)
    x = np.concatenate([state.q, np.zeros(len(dr))])
    h = distance / steps
    cur = state
    q = state.q.copy()
    qs, poses = [q.copy()], [state.pose_vector()]
    worst_res = 0.0
    valid = _MotionCheck.of(model, state, (*sticking, *separating, *sliding))
    for _ in range(steps):
        x_try = x + h * np.concatenate([dq, dr])
        x, res = project_manifold(man, x_try)
        if man.direction is not None:
            # the object advances h along dr per step: where the projection took it much farther or
            # less far (dq, the hand's motion at the start, no longer fits the curved set of object
            # motions the contacts allow: two arms each holding the box with a sticking and a
            # sliding link), the step is projected again with the object's progress held
            target = float(man.direction @ x_try[hand.M:])
            if abs(float(man.direction @ x[hand.M:]) - target) > PROGRESS_SLACK * h:
                x, res = project_manifold(man, x_try, progress=(man.direction, target))
        q = x[: hand.M]
        cur = cur.with_pose(man.pose(x[hand.M:]), q)
        worst_res = max(worst_res, res)
        if res > 1e-6:
            return None
        cur = GraspState(cur.contacts, q, cur.position, cur.rotation, cur.dim)
        qs.append(q.copy())
        poses.append(cur.pose_vector())
        if not check_path and len(qs) <= steps:
            continue
        if not valid(q, cur.pose):
            return None
    seps_a = _separations(model, state, separating, q, cur.pose)
    if len(seps_a) and np.any(seps_a <= 0.0):
        return None
    length = float(np.sum(np.linalg.norm(np.diff(np.array(poses), axis=0), axis=1)))
    return ObjectMotion(np.array(qs), np.array(poses), seps_a, length, worst_res, dr,
                        None if motion_space is None else np.asarray(motion_space, dtype=float))


def _separations(model: CollisionModel, state: GraspState, separating: Sequence[int], q: Array, pose: Pose) -> Array:
    """The gap ``(#D,)`` of each separating contact's body point from the object at ``pose``, hand at ``q``."""
    hand = model.hand
    seps = []
    for i in separating:
        c = state.contacts[i]
        ref = hand.resolve_body(c.body)
        assert ref is not None
        x = hand.point_position(ref, c.point_body, q)
        sd = shape_signed_distance(model.scene.object.shape, pose.to_local(x), state.dim)
        seps.append(np.inf if sd is None else sd)
    return np.array(seps, dtype=float)


def link_rolling_motion(scene: Scene, hand: HandKinematics, state: GraspState, sticking: Sequence[int],
                        sliding: Sequence[int] = (), direction: Array | None = None,
                        motion_space: Array | None = None) -> LinkRollingMotion | None:
    """The object motions of ``state`` whose sticking contacts of a 3-D sphere on capsule link sides
    roll (:func:`planner.link_roll.link_rolls`; the other contacts on :func:`motion_manifold`), or
    None without such contacts."""
    rolls = link_rolls(hand, scene, state, sticking)
    if not rolls:
        return None
    base = motion_manifold(scene, hand, state, [i for i in sticking if i not in rolls], sliding, direction=direction,
                           motion_space=motion_space)
    return LinkRollingMotion(hand, scene, state, rolls, base)


def _link_rolling(scene: Scene, hand: HandKinematics, state: GraspState, sticking: Sequence[int],
                  sliding: Sequence[int], direction: Array | None,
                  motion_space: Array | None) -> LinkRollingMotion | None:
    """:func:`link_rolling_motion` of an object motion with a direction (else None)."""
    return None if direction is None else link_rolling_motion(scene, hand, state, sticking, sliding, direction,
                                                              motion_space)


#: the most midpoint steps :func:`_integrate_link_rolling` takes for one object motion
MAX_ROLL_STEPS = 4000


def _integrate_link_rolling(model: CollisionModel, state: GraspState, rolling: LinkRollingMotion, dr: Array, dq: Array,
                            separating: Sequence[int], distance: float, steps: int, check_path: bool,
                            busy: Sequence[int], motion_space: Array | None) -> ObjectMotion | None:
    """:func:`integrate_object_motion` of a sphere rolling on a link's side
    (:meth:`planner.link_roll.LinkRollingMotion.integrate`: velocity rows, midpoint steps), in
    steps small enough that no joint moves more than :data:`DENSE_STEP` between two states (the
    path is then checked as it is, :func:`plan_object_motion`); None where the holonomic rows leave
    ``1e-6``, it slips more than :data:`ROLL_SLIP_TOL`, it collides or a D-contact does not separate."""
    n = steps
    while True:
        path = rolling.integrate(dr, distance, dq, steps=n)
        jump = float(np.max(np.abs(np.diff(path.X[:, : model.hand.M], axis=0))))
        if jump <= DENSE_STEP or n >= MAX_ROLL_STEPS:
            break
        n = min(MAX_ROLL_STEPS, int(np.ceil(n * jump / DENSE_STEP * 1.05)))
    if jump > DENSE_STEP or path.max_residual > 1e-6 or path.slip > min(ROLL_SLIP_TOL, LINK_ROLL_SLIP_TOL):
        return None
    M = model.hand.M
    poses = [rolling.pose(x[M:]) for x in path.X]
    valid = _MotionCheck.of(model, state, busy)
    if (check_path and not valid.all_valid(path.X[:, :M], poses)) or not valid(path.X[-1, :M], poses[-1]):
        return None
    seps = _separations(model, state, separating, path.X[-1, :M], poses[-1])
    if len(seps) and np.any(seps <= 0.0):
        return None
    length = float(np.sum(np.linalg.norm(np.diff(path.poses, axis=0), axis=1)))
    return ObjectMotion(path.X[:, :M], path.poses, seps, length, path.max_residual, dr,
                        None if motion_space is None else np.asarray(motion_space, dtype=float))


#: a step of :func:`integrate_object_motion` whose projection moved the object more than this
#: fraction of the step off its planned progress along the direction is projected again with the
#: progress held
PROGRESS_SLACK = 0.1
#: and by more than this (scene units, radians) in a densified segment
PROGRESS_FLOOR = 1e-9


def corner_normal(scene: Scene, hand: HandKinematics, ref: BodyRef, q: Array, pose: Pose,
                  point_object: Array) -> Array | None:
    """The contact normal ``(d,)`` (object frame, unit, into the object) of a contact whose object
    point ``point_object`` ``(d,)`` is on a vertex or an edge of the object (a box corner on the
    table, a box edge across a forearm): there the object has a normal cone, not a normal, and
    the normal is the smooth body's, its outward surface normal at the point (a fixed body's
    face, a link's capsule at ``q`` ``(M,)``); where that lies outside the object's normal cone
    (a link lying along a face up to its edge, rolled a little on the face), the face's normal.
    ``None`` where the object is smooth at the point (its own normal holds) or the body has no
    single normal there (a URDF collision mesh, a bare segment, an edge of a fixed body)."""
    d = scene.dim
    cone = shape_normal_cone(scene.object.shape, point_object, d, GEOMETRY_TOL)
    if cone is None or cone.generators.shape[0] < 2:  # a face (or a mesh): the object's own normal
        return None
    x = pose.to_world(point_object)
    if ref.finger is None:
        body = next(b for b in scene.fixed_bodies if b.name == ref.name)
        bcone = shape_normal_cone(body.shape, x, d, GEOMETRY_TOL)
    elif link_shapes(hand, ref, q) is None:
        a, b = hand.body_segment(ref, q)
        bcone = segment_normal_cone(x, a[:d], b[:d], hand.body_radius(ref), GEOMETRY_TOL)
    else:
        return None
    if bcone is None or bcone.generators.shape[0] != 1:
        return None
    u = pose.R_d.T @ bcone.generators[0]
    u = u / np.linalg.norm(u)
    if cone.distance(-u) > 1e-9:
        # the body's normal turned out of the object's normal cone (a link lying along a face whose
        # line contact ends at the face's edge, rolled on the face by a small turn): the contact is
        # the face's, whose normal is the cone's nearest generator
        g = cone.generators[int(np.argmax(cone.generators @ -u))]
        return np.asarray(-g / np.linalg.norm(g))
    return np.asarray(u)


def keep_contacts(state: GraspState, keep: Sequence[int], q: Array) -> GraspState:
    """The state after a motion: only the contacts ``keep``, the hand at ``q``, the object where it
    is in ``state``."""
    contacts: tuple[GraspContact, ...] = tuple(state.contacts[i] for i in keep)
    return state.with_contacts(contacts, q)


@dataclass(frozen=True)
class ConstrainedObjectMotion:
    """An object motion planned by OMPL on the contact manifold (:func:`plan_object_motion`)."""

    q_path: Array  # (n, M) hand configurations
    pose_path: Array  # (n, D) object pose vectors
    displacement_path: Array  # (n, D) the ambient object coordinates s of ContactManifold
    separations: Array  # (#D,) final gap of each separating contact
    length: float  # object path length (pose-vector norm)
    max_residual: float  # largest |F(x)| over the dense path
    max_joint_step: float  # largest joint-space step between consecutive checked states
    states_checked: int
    planner_states: int  # states of OMPL's solution path before densification (0: the integrated path)
    ompl_seconds: float


def plan_object_motion(
    model: CollisionModel,
    state: GraspState,
    goal: ObjectMotion,
    sticking: Sequence[int],
    separating: Sequence[int],
    seed: int = 0,
    time_limit: float = 2.0,
    tolerance: float = 1e-8,
    sliding: Sequence[int] = (),
    checks: int = 300,
) -> ConstrainedObjectMotion | None:
    """Plan the motion of hand and object from ``state`` to the end of ``goal`` (the configuration
    reached along the DAFC direction, :func:`integrate_object_motion`) with OMPL's constrained
    planning: a ``ProjectedStateSpace`` over ``[q; s]`` with the constraint
    :class:`ContactManifold` of the sticking and ``sliding`` contacts (``A_c [dq; dr] = 0``, eq. 7
    and 19, to every order), ``RRTConnect`` (seeded, ended after ``checks`` validity checks or, as a
    safety net, ``time_limit`` seconds: :class:`CheckBudget`) whose motions are geodesics of the manifold, a validity
    checker for joint limits and collisions (:meth:`CollisionModel.finger_clearance`; the contact
    links may touch the object, overlaps present at the start may not deepen), and the solution
    densified on the manifold until no joint moves more than :data:`DENSE_STEP` between two
    checked states, every one of which is re-checked (constraint residual below
    ``100 * tolerance`` and collision-free). The constraint holds the object to the direction of
    ``goal`` (``goal.direction`` in ``goal.motion_space``; else the straight line to its end), the
    validity checker keeps it between the two ends of that path and clear of the fixed bodies, and
    every segment of the densified object path must lie within :data:`MIN_DIRECTION_COSINE` of
    the direction, and a sphere rolling on a plane must not slip along it (:func:`rolling_slip` at
    most :data:`ROLL_SLIP_TOL`). Where OMPL finds no path that passes, the integrated path ``goal`` itself is
    densified and checked the same way (its ``planner_states`` then 0). ``None`` if neither
    passes."""
    hand = model.hand
    q0, q1 = state.q, goal.q_path[-1]
    s1 = pose_displacement(state, goal.pose_path[-1])
    direction = goal.direction
    if direction is None and float(np.linalg.norm(s1)) > 1e-12:
        direction = s1 / np.linalg.norm(s1)
    rolling = _link_rolling(model.scene, hand, state, sticking, sliding, direction, goal.motion_space)
    if rolling is not None:
        return _checked_link_rolling(model, state, goal, rolling, (*sticking, *separating, *sliding), tolerance)
    man = motion_manifold(model.scene, hand, state, sticking, sliding, direction=direction,
                          motion_space=goal.motion_space)
    M, D = man.M, man.D
    n = M + D
    x0, x1 = np.concatenate([q0, np.zeros(D)]), np.concatenate([q1, s1])
    check = _MotionCheck.of(model, state, (*sticking, *separating, *sliding))
    limits = check.limits
    t1 = 0.0 if man.direction is None else float(man.direction @ s1)  # progress along dr at the end

    def valid(x: Array) -> bool:
        if man.direction is not None:  # the object between the two ends of its line
            t = float(man.direction @ x[M:])
            if t < -1e-9 or t > t1 + 1e-9:
                return False
        return check(x[:M], man.pose(x[M:]))

    def all_valid(X: Array) -> bool:  # valid at every state of X (k, n), the fingers' clearances at once
        if man.direction is not None:
            t = np.array([float(man.direction @ x[M:]) for x in X])  # as valid computes it
            if not bool(np.all((t >= -1e-9) & (t <= t1 + 1e-9))):
                return False
        return check.all_valid(X[:, :M], [man.pose(x[M:]) for x in X])

    if man.contact_rows == 0 or not valid(x0) or not valid(x1):
        return None
    if float(np.linalg.norm(man.function(x1))) > 100 * tolerance:
        return None

    J0 = man.jacobian(x0)
    rank = int(np.linalg.matrix_rank(J0, tol=1e-9))
    if rank >= n:  # the contacts and the direction leave no motion
        return None
    # OMPL needs fewer constraint rows than ambient dimensions and as many as the co-dimension:
    # redundant rows (several contacts on one link, a grasp without finger redundancy on the
    # direction's line, four box corners sliding on one table plane) are combined into ``rank``
    # rows along the left singular vectors of F'(x0); every state planned is checked on the full F
    # below (valid_full), so the combination cannot let a state leave the manifold
    U = np.linalg.svd(J0)[0][:, :rank].T if man.rows >= n or rank < man.rows else None  # (rank, rows)

    def valid_full(x: Array) -> bool:
        return U is None or float(np.linalg.norm(man.function(x))) <= 100 * tolerance

    class _Constraint(ob.Constraint):
        def __init__(self) -> None:
            super().__init__(n, man.rows if U is None else rank)

        def function(self, x: Any, out: Any) -> None:
            F = man.function(np.asarray(x))
            out[:] = F if U is None else U @ F

        def jacobian(self, x: Any, out: Any) -> None:
            J = man.jacobian(np.asarray(x))
            out[:, :] = J if U is None else U @ J

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)
    constraint = _Constraint()
    constraint.setTolerance(tolerance)
    constraint.setMaxIterations(100)
    constraint.setManifoldDimension(n - rank)
    span = np.abs(x1 - x0)
    margin = np.maximum(span, 1e-3)
    lo, hi = np.minimum(x0, x1) - margin, np.maximum(x0, x1) + margin
    if man.direction is not None:  # the object's samples about its integrated path (a line or a curve)
        S = np.array([pose_displacement(state, v) for v in goal.pose_path])  # (k, D)
        pad = 1e-9 + 0.05 * (S.max(axis=0) - S.min(axis=0))
        lo[M:] = np.minimum(S.min(axis=0), np.minimum(x0[M:], x1[M:])) - pad
        hi[M:] = np.maximum(S.max(axis=0), np.maximum(x0[M:], x1[M:])) + pad
    for f in range(len(hand.fingers)):  # joint limits bound the ambient box too
        sl = hand.finger_slice(f)
        lo[sl] = np.maximum(lo[sl], np.minimum(limits[f][0], np.minimum(x0[sl], x1[sl])))
        hi[sl] = np.minimum(hi[sl], np.maximum(limits[f][1], np.maximum(x0[sl], x1[sl])))
    ambient = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for j in range(n):
        bounds.setLow(j, float(lo[j]))
        bounds.setHigh(j, float(hi[j]))
    ambient.setBounds(bounds)
    space = ob.ProjectedStateSpace(ambient, constraint)
    si = ob.ConstrainedSpaceInformation(space)
    total = float(np.linalg.norm(x1 - x0))
    space.setDelta(max(total / 20.0, 1e-6))  # geodesic step: at least 20 checked states per motion

    def read(st: Any) -> Array:
        return np.array([space.getValueAddressAtIndex(st, j) for j in range(n)])

    ss = og.SimpleSetup(si)
    budget = CheckBudget(checks, time_limit)
    ss.setStateValidityChecker(budget.counted(lambda st: valid(x := read(st)) and valid_full(x)))
    a, b = space.allocState(), space.allocState()
    a.copy([float(v) for v in x0])
    b.copy([float(v) for v in x1])
    ss.setStartAndGoalStates(a, b, 1e-9)
    planner = og.RRTConnect(si)
    planner.setRange(max(total, 1e-6))  # try the direct geodesic first
    ss.setPlanner(planner)
    t0 = time.perf_counter()
    status = ss.solve(ob.PlannerTerminationCondition(budget.condition()))

    def checked(X: Array, planner_states: int) -> ConstrainedObjectMotion | None:
        """The path ``X`` ``(k, n)`` densified and every state of it checked, or None."""
        known: dict[bytes, float] = {}  # |F| of the states the densification projected, by their bytes
        X = _densify(man, X, DENSE_STEP, tolerance, known)
        step = float(np.max(np.abs(np.diff(X[:, :M], axis=0)))) if len(X) > 1 else 0.0
        residual = max(known[k] if (k := x.tobytes()) in known else float(np.linalg.norm(man.function(x)))
                       for x in X)
        if step > DENSE_STEP or residual > 100 * tolerance or not all_valid(X):
            return None
        if float(np.max(np.abs(X[-1] - x1))) > 1e-6:
            return None
        if man.direction is not None and direction_cosines(X[:, M:], man.direction).min() < MIN_DIRECTION_COSINE:
            return None  # a segment of the object path goes back along its line
        if man.plane_rolls and rolling_slip(man, X[:, M:]) > ROLL_SLIP_TOL:
            return None  # a sphere rolling on a plane along a path that is not a ray: it slips
        poses = np.array([man.pose(x[M:]).vector() for x in X])  # (k, D)
        length = float(np.sum(np.linalg.norm(np.diff(poses, axis=0), axis=1)))
        return ConstrainedObjectMotion(X[:, :M], poses, X[:, M:], goal.separations, length, residual, step, len(X),
                                       planner_states, time.perf_counter() - t0)

    out = None
    if bool(status) and ss.haveExactSolutionPath():
        path = ss.getSolutionPath()
        out = checked(np.array([read(path.getState(i)) for i in range(path.getStateCount())]),
                      int(path.getStateCount()))
    if out is None and goal.direction is not None and goal.motion_space is not None:
        # OMPL found no path its checks pass (on the curved set of object motions of two arms each
        # holding the box with a sticking and a sliding link its paths go back and forth along
        # the direction): the integrated path itself, densified and every state checked the
        # same way, marked by ompl_planner_states = 0
        X = np.array([np.concatenate([q, pose_displacement(state, v)])
                      for q, v in zip(goal.q_path, goal.pose_path, strict=True)])
        out = checked(X, 0)
    return out


def _checked_link_rolling(model: CollisionModel, state: GraspState, goal: ObjectMotion, rolling: LinkRollingMotion,
                          busy: Sequence[int], tolerance: float) -> ConstrainedObjectMotion | None:
    """:func:`plan_object_motion` of a sphere rolling on a link's side: rolling on a moving link is
    non-holonomic, so no manifold ``F(x) = 0`` of OMPL's constrained planning holds it; the path is
    the integrated one (:func:`_integrate_link_rolling`, ``ompl_planner_states = 0``), every state of
    it checked again: the holonomic rows (the other contacts, the gaps, the direction rows) within
    ``100 * tolerance``, joints within :data:`DENSE_STEP` between states, joint limits and
    collisions, every object segment within :data:`MIN_DIRECTION_COSINE` of the direction, the
    slip of every rolling contact (link: :func:`planner.link_roll.link_roll_check`; table:
    :func:`rolling_slip`) at most :data:`ROLL_SLIP_TOL`. None if any fails."""
    t0 = time.perf_counter()
    S = np.array([pose_displacement(state, v) for v in goal.pose_path])  # (n, D)
    X = np.hstack([goal.q_path, S])  # (n, M + D)
    residual = max(float(np.linalg.norm(rolling.holonomic(x))) for x in X)
    step = float(np.max(np.abs(np.diff(goal.q_path, axis=0)))) if len(X) > 1 else 0.0
    poses = [rolling.pose(s) for s in S]
    if residual > 100 * tolerance or step > DENSE_STEP or not _MotionCheck.of(model, state, busy).all_valid(
            goal.q_path, poses):
        return None
    assert goal.direction is not None
    if direction_cosines(S, goal.direction).min() < MIN_DIRECTION_COSINE:
        return None
    checks = rolling.checks(X)
    if max(max(c.slip, c.axis_angle) for c in checks) > ROLL_SLIP_TOL or rolling_slip(rolling.base, S) > ROLL_SLIP_TOL:
        return None
    return ConstrainedObjectMotion(goal.q_path, goal.pose_path, S, goal.separations, goal.length, residual, step,
                                   len(X), 0, time.perf_counter() - t0)


#: scene units: the largest slip (:func:`rolling_slip`) of a sphere rolling on a plane along a
#: planned object path (:func:`plan_object_motion` refuses a path that slips more)
ROLL_SLIP_TOL = 1e-6


def rolling_slip(man: ContactManifold, S: Array) -> float:
    """The slip along the object displacement path ``S`` ``(n, D)`` (the ``s`` of ``man``) of every
    sphere or cylinder rolling on a plane (:attr:`ContactManifold.plane_rolls`): per segment ``k``
    the object's material point at the contact (``y = z a_k - r n`` from the centre, ``z`` the
    cylinder contact's axial offset, 0 for a sphere) moves by ``dp_k + omega_k x y`` (``omega_k =
    log(R_{k+1} R_k^T)``, a constant twist over the segment), zero when it rolls; the largest sum
    of their lengths over the path among the contacts (0 without such contacts). Rays
    ``s = t dr`` roll exactly; other paths of the manifold slip at second order (rolling is
    non-holonomic)."""
    if not man.plane_rolls or len(S) < 2:
        return 0.0
    poses = [man.pose(s) for s in np.asarray(S, dtype=float)]
    worst = 0.0
    for k, (_, _, n) in enumerate(man.plane_rolls):
        z = man.plane_offset(k)  # a cylinder's contact: its offset along the axis (0 for a sphere)
        total = 0.0
        for a, b in itertools.pairwise(poses):
            omega = matrix_to_rotvec(b.rotation @ a.rotation.T)  # (3,)
            arm = z * a.rotation[:, 2] - man.radius * n  # (3,) the contact from the centre
            total += float(np.linalg.norm(b.position - a.position + np.cross(omega, arm)))
        worst = max(worst, total)
    return worst


#: every segment of an object path lies within this cosine of the analysed direction (issue 11)
MIN_DIRECTION_COSINE = 0.99


def direction_cosines(S: Array, direction: Array, floor: float = 1e-12) -> Array:
    """Cosines ``(k,)`` between the segments of the object displacement path ``S`` ``(n, D)`` (the
    ``s`` of :class:`ContactManifold`) and the unit ``direction`` ``(D,)``; segments shorter than
    ``floor`` (the object at rest while the hand moves) count as 1. ``ones(0)`` for one state."""
    seg = np.diff(np.asarray(S, dtype=float), axis=0)
    if not len(seg):
        return np.ones(0)
    nrm = np.linalg.norm(seg, axis=1)
    cos = (seg @ np.asarray(direction, dtype=float)) / np.where(nrm > floor, nrm, 1.0)
    return np.asarray(np.where(nrm > floor, cos, 1.0))


def _densify(man: ContactManifold, X: Array, max_step: float, tolerance: float,
             known: dict[bytes, float] | None = None) -> Array:
    """Insert states between consecutive states of ``X`` ``(k, M + D)`` so that no joint moves more
    than ``max_step``: points of the ambient segment projected back onto the manifold (Newton steps
    with the pseudo-inverse of ``F'``, as OMPL's projection does). A projected point whose object
    moved off its share of the segment's progress along the direction (a projection that slid
    along the manifold: redundant rows of line contacts) is projected again with that progress
    held, and a pair of states still farther apart than ``max_step`` is split again, up to
    :data:`DENSIFY_DEPTH` times. ``known`` (if given) receives ``|F|`` of each state a projection
    ended on by meeting the tolerance (``project_manifold``'s residual is then that of the state
    it returns, exactly), by the state's bytes."""
    out = [X[0]]
    for a, b in itertools.pairwise(X):
        out.extend(_fill(man, a, b, max_step, tolerance, 0, known))
    return np.array(out)


#: how many times :func:`_densify` splits a segment whose projected states are still too far apart
DENSIFY_DEPTH = 4


def _fill(man: ContactManifold, a: Array, b: Array, max_step: float, tolerance: float, depth: int,
          known: dict[bytes, float] | None = None) -> list[Array]:
    """The states after ``a`` up to ``b`` (included) of the densified segment ``a -> b``."""
    M = man.M
    k = int(np.ceil(float(np.max(np.abs(b[:M] - a[:M]))) / max_step * 1.02))
    pts = []
    for t in np.arange(1, k) / max(k, 1):
        y = a + t * (b - a)
        p, res = project_manifold(man, y, tolerance)
        if man.direction is not None:
            target = float(man.direction @ y[M:])
            share = abs(float(man.direction @ (b - a)[M:]))  # the segment's progress
            if abs(float(man.direction @ p[M:]) - target) > PROGRESS_SLACK * share + PROGRESS_FLOOR:
                p = project_manifold(man, y, tolerance, progress=(man.direction, target))[0]
                res = np.inf  # with the progress held, the residual returned may be an earlier iterate's
        if known is not None and res <= tolerance:  # ended by meeting the tolerance: |F(p)| itself
            known[p.tobytes()] = res
        pts.append(p)
    pts.append(b)
    if depth >= DENSIFY_DEPTH:
        return pts
    out: list[Array] = []
    prev = a
    for p in pts:
        if float(np.max(np.abs(p[:M] - prev[:M]))) > max_step:
            out.extend(_fill(man, prev, p, max_step, tolerance, depth + 1, known))
        else:
            out.append(p)
        prev = p
    return out
