"""A 3-D sphere, or a cylinder along the link, rolling on the side of a moving finger link (issue 11
item 1), to every order.

A sticking contact of a sphere (radius ``r``) on the side of a capsule link (radius ``rho``, axis
``a(q) -> b(q)``) does not keep its material points together in a finite motion: the sphere rolls
on the link, the contact point moving along the link's axis and round it, and on the sphere by
``r`` times the turn of the sphere relative to the link. A glued point pivots the sphere about it
relative to the link and presses it ``r (1 - cos phi)`` into the link (``phi`` the relative turn).

Rolling on a moving link is non-holonomic: no rows ``F(x) = 0`` give it exactly along every path
(unlike a cylinder on a plane, :mod:`planner.manifold`). :class:`LinkRollingMotion` follows it as
the velocity constraints it is. In the ambient coordinates ``x = [q (M); s (6)]`` of
:class:`~planner.manifold.ContactManifold` (``s = (dp, w)``, the sphere at ``p_0 + dp`` with
rotation ``exp(w) R_0``, its angular velocity ``omega = J_l(w) w'``) the rolling contact has

* the gap ``g(x) = |p - y| - rho - r = 0`` (``y`` the foot of the centre ``p`` on the axis,
  ``u = (p - y) / |p - y|`` the unit normal from the link into the sphere), holonomic;
* the no-slip rows: the sphere's material point at the contact ``c = p - r u`` moves with the
  link's material point there (eq. 1 and 2 with the two velocities equal, all three components),
  ``p' + omega x (-r u) - J_L(c) q' = 0``, i.e. ``[-J_L(c), I, r [u]x J_l(w)] x' = 0``
  ``(3, M + 6)``; its normal component is the gap's derivative ``u^T (p' - J_L(y) q')``.

The other contacts are :func:`planner.object_motion.motion_manifold`'s rows (the glued ones, a
sphere rolling on a table, sliding gaps, the rows holding the object to the analysed direction
``dr``). :meth:`LinkRollingMotion.integrate` follows the direction ``dr`` with the hand's motion
``dq`` of (31): per step of length ``h`` the velocity ``x'`` closest to ``[dq; dr]`` that satisfies
every velocity row with progress ``dr . s' = 1`` (minimum-norm correction), taken at the
midpoint (second order), then a Newton projection of the holonomic rows (the other contacts' rows
and the gaps) whose steps keep the no-slip rows' tangential parts zero, so the slip is at the
integration's accuracy, ``O(h^2)`` summed over the path. :func:`link_roll_check` measures the path
from its states alone: the gap per state, the slip between consecutive states (the relative
motion of the sphere in the link's frame, ``dc + omega_rel x (-r u_mid)``, summed) and the two
travels of the contact point (along the link's surface and on the sphere), equal when it rolls.

A cylinder (radius ``r``, axis ``a = R e_z``) lying along a capsule link, the axes parallel, touches
it along a line, given by the scene as two contacts at its ends (axial coordinates ``z_k``, object
frame, as on a table). Each is the sphere's contact with the centre replaced by the point
``P_k = p + z_k a`` of the cylinder's axis: gap ``|P_k - y_k| - rho - r`` (``y_k`` its foot on the
link's axis), contact ``c_k = P_k - r u_k``, no-slip rows ``p' + omega x (z_k a - r u_k) - J_L(c_k)
q' = 0``, i.e. ``[-J_L(c_k), I, -[z_k a - r u_k]x J_l(w)]``. Two points without relative velocity
leave the relative twist a turn about the line through them, the common axis direction: the
cylinder rolls on the link and stays parallel to it (:attr:`LinkRollCheck.axis_angle` measures
it). A cylinder whose axis is not parallel to the link's touches it at a point whose relative
motion is not a roll about the common axis; those contacts keep their glued points, as does a
single contact of a cylinder on a link (a line contact needs its two ends).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.geometry import link_shapes
from analysis.kinematics import BodyRef, HandKinematics
from analysis.pose import Pose
from analysis.rotations import matrix_to_rotvec, skew
from analysis.scene import Cylinder, Scene, Sphere
from planner.manifold import PROJECTION_RCOND, ContactManifold, _left_jacobian_so3
from planner.state import GraspState

#: the foot of the sphere's centre must lie this fraction of the axis away from its ends for a
#: contact to roll on the link's side (at an end cap the contact is a sphere on a sphere)
SIDE_MARGIN = 1e-6
#: scene units: the largest summed slip of a rolling link contact along an integrated path
LINK_ROLL_SLIP_TOL = 1e-6
#: the largest sine of the angle between a cylinder's axis and a capsule link's axis for their line
#: contact to roll (a larger angle: the contacts keep their glued points)
PARALLEL_TOL = 1e-6


def object_radius(scene: Scene) -> float:
    """The radius ``r`` of a sphere or cylinder object (0 for any other shape)."""
    shape = scene.object.shape
    return float(shape.radius) if isinstance(shape, Sphere | Cylinder) else 0.0


def axial_offset(scene: Scene, state: GraspState, i: int) -> float:
    """The axial coordinate ``z_k`` (object frame) of contact ``i`` of a cylinder (0 for a sphere):
    where along the line contact it lies; it keeps it while it rolls about the common axis."""
    return float(state.contacts[i].point_object[2]) if isinstance(scene.object.shape, Cylinder) else 0.0


def axis_point(pose: Pose, offset: float) -> Array:
    """``P = p + z a`` ``(3,)``: the point at axial coordinate ``offset`` of the object's axis (its
    centre for a sphere, ``offset = 0``)."""
    return pose.position + offset * pose.rotation[:, 2]


def link_rolls(hand: HandKinematics, scene: Scene, state: GraspState, sticking: Sequence[int]) -> tuple[int, ...]:
    """The sticking contacts of a 3-D sphere object on the side of a capsule finger link of positive
    radius (the foot of the centre on the link's axis strictly inside it, :data:`SIDE_MARGIN`):
    these roll. For a cylinder object, the contacts on the side of a capsule link whose axis is
    parallel to the cylinder's (:data:`PARALLEL_TOL`), the foot of ``P_k = p + z_k a`` inside the
    link, where the link has two of them at distinct axial coordinates (the ends of the line
    contact). Links of radius 0 (lines: the bundled palm and wrap fingers), links with URDF
    collision shapes (not capsules), fixed bodies and cylinders across a link are left out: they
    keep their glued points."""
    shape = scene.object.shape
    if scene.dim != 3 or not isinstance(shape, Sphere | Cylinder):
        return ()
    out: list[int] = []
    for i in sticking:
        ref = hand.resolve_body(state.contacts[i].body)
        if (ref is None or ref.finger is None or link_shapes(hand, ref, state.q) is not None
                or not hand.body_radius(ref) > 0.0):
            continue
        a, b = hand.body_segment(ref, state.q)
        e = b - a
        if isinstance(shape, Cylinder):
            axis = state.pose.rotation[:, 2]
            if float(np.linalg.norm(np.cross(axis, e))) > PARALLEL_TOL * float(np.linalg.norm(e)):
                continue
        P = axis_point(state.pose, axial_offset(scene, state, i))
        t = float((P - a) @ e / max(float(e @ e), 1e-300))
        if SIDE_MARGIN < t < 1 - SIDE_MARGIN:
            out.append(i)
    if isinstance(shape, Cylinder):  # a line contact: two ends on the same link
        def ends(i: int) -> list[float]:
            return [axial_offset(scene, state, j) for j in out if state.contacts[j].body == state.contacts[i].body]
        out = [i for i in out if max(ends(i)) - min(ends(i)) > SIDE_MARGIN * float(shape.height)]
    return tuple(out)


def link_contact(hand: HandKinematics, ref: BodyRef, radius: float, q: Array, p: Array) -> tuple[float, Array, Array]:
    """The sphere of ``radius`` centred at ``p`` ``(3,)`` (or the cylinder's cross-section about its
    axis point ``P_k``) against the capsule link ``ref`` at ``q``:
    ``(gap, u, y)``: ``|p - y| - rho - r``, the unit normal ``u`` ``(3,)`` from the link into the
    sphere and the foot ``y`` ``(3,)`` of the centre on the link's axis."""
    a, b = hand.body_segment(ref, q)
    e = b - a
    t = float(np.clip((p - a) @ e / max(float(e @ e), 1e-300), 0.0, 1.0))
    y = a + t * e
    d = np.asarray(p, dtype=float) - y
    dist = float(np.linalg.norm(d))
    return dist - hand.body_radius(ref) - radius, d / max(dist, 1e-300), y


@dataclass(frozen=True)
class LinkRollPath:
    """An integrated object motion with contacts rolling on links (:meth:`LinkRollingMotion.integrate`)."""

    X: Array  # (n, M + 6) states [q; s]
    poses: Array  # (n, 6) pose vectors
    rolls: tuple[int, ...]  # the contacts that roll on links
    max_residual: float  # largest |H(x)| over the states (other contacts' rows, gaps, direction rows)
    slip: float  # largest summed slip of a rolling contact (:func:`link_roll_check`)


@dataclass(frozen=True)
class LinkRollCheck:
    """:func:`link_roll_check` of one rolling contact along a path."""

    max_gap: float  # largest |gap| over the states
    slip: float  # summed |dc + omega_rel x (-r u_mid)| over the segments (link frame)
    travel_link: float  # summed displacement of the contact point on the link's surface (link frame)
    travel_object: float  # summed displacement of the contact point on the sphere (object frame)
    turn: float  # summed relative turn |omega_rel| of the sphere against the link
    axis_angle: float = 0.0  # a cylinder: the largest sine of the angle between its axis and the link's


class LinkRollingMotion:
    """The object motions of ``state`` with the sticking contacts ``rolls`` (:func:`link_rolls`)
    rolling on capsule link sides and the others given by ``base``, the contact manifold of the
    other contacts (:func:`planner.object_motion.link_rolling_motion` builds both)."""

    def __init__(self, hand: HandKinematics, scene: Scene, state: GraspState, rolls: Sequence[int],
                 base: ContactManifold):
        self.hand, self.scene, self.state = hand, scene, state
        self.rolls = tuple(rolls)
        self.refs: list[BodyRef] = []
        for i in self.rolls:
            ref = hand.resolve_body(state.contacts[i].body)
            assert ref is not None
            self.refs.append(ref)
        self.radius = object_radius(scene)
        self.offsets = [axial_offset(scene, state, i) for i in self.rolls]  # z_k (0 for a sphere)
        self.base = base
        self.M, self.D = hand.M, self.base.D

    def pose(self, s: Array) -> Pose:
        return self.base.pose(s)

    def holonomic(self, x: Array) -> Array:
        """``H(x)``: the other contacts' rows and the direction rows (:class:`ContactManifold`), then
        each rolling contact's gap."""
        pose = self.pose(x[self.M:])
        gaps = [link_contact(self.hand, ref, self.radius, x[: self.M], axis_point(pose, z))[0]
                for ref, z in zip(self.refs, self.offsets, strict=True)]
        return np.concatenate([self.base.function(x), gaps])

    def no_slip(self, x: Array) -> Array:
        """The rolling contacts' velocity rows ``(3 k, M + 6)``: ``[-J_L(c), I, -[z a - r u]x J_l(w)]``
        (``z = 0`` for a sphere: ``r [u]x J_l(w)``)."""
        q, s = x[: self.M], x[self.M:]
        pose = self.pose(s)
        Jl = _left_jacobian_so3(s[3:])
        rows = np.zeros((3 * len(self.refs), self.M + self.D))
        for k, (ref, z) in enumerate(zip(self.refs, self.offsets, strict=True)):
            P = axis_point(pose, z)
            _, u, _ = link_contact(self.hand, ref, self.radius, q, P)
            c = P - self.radius * u
            arm = z * pose.rotation[:, 2] - self.radius * u  # (3,) c - p
            r = slice(3 * k, 3 * k + 3)
            rows[r, : self.M] = -self.hand.point_jacobian(ref, c, q)
            rows[r, self.M: self.M + 3] = np.eye(3)
            rows[r, self.M + 3:] = -skew(arm) @ Jl
        return rows

    def velocity(self, x: Array, prefer: Array, dr: Array) -> Array:
        """``x'`` ``(M + 6,)``: the velocity closest to ``prefer`` (``[dq; dr]``) with every velocity
        row satisfied (the other contacts' rows' derivatives, the no-slip rows) and ``dr . s' = 1``."""
        K = np.vstack([self.base.jacobian(x), self.no_slip(x), np.concatenate([np.zeros(self.M), dr])[None, :]])
        rhs = np.zeros(K.shape[0])
        rhs[-1] = 1.0
        return prefer + np.linalg.lstsq(K, rhs - K @ prefer, rcond=PROJECTION_RCOND)[0]

    def project(self, x: Array, dr: Array, tolerance: float = 1e-12, iters: int = 30) -> tuple[Array, float]:
        """Newton projection of ``x`` onto ``H = 0`` with the progress ``dr . s`` held and the
        no-slip rows' tangential parts zero in every step (the normal part is the gap's step):
        ``(x, |H|)``."""
        x = np.array(x, dtype=float)
        res = 0.0
        M = self.M
        for _ in range(iters):
            F = self.base.function(x)
            q, pose = x[:M], self.pose(x[M:])
            geo = [link_contact(self.hand, ref, self.radius, q, axis_point(pose, z))
                   for ref, z in zip(self.refs, self.offsets, strict=True)]
            res = float(np.linalg.norm(np.concatenate([F, [g for g, _, _ in geo]])))
            if res <= tolerance:
                break
            rhs_roll = np.concatenate([-g * u for g, u, _ in geo]) if geo else np.zeros(0)
            K = np.vstack([self.base.jacobian(x), self.no_slip(x), np.concatenate([np.zeros(M), dr])[None, :]])
            rhs = np.concatenate([-F, rhs_roll, [0.0]])
            x = x + np.linalg.lstsq(K, rhs, rcond=PROJECTION_RCOND)[0]
        return x, res

    def integrate(self, dr: Array, distance: float, dq: Array | None = None, steps: int = 200) -> LinkRollPath:
        """Follow the unit object direction ``dr`` ``(6,)`` for ``distance`` (progress ``dr . s``) in
        ``steps`` midpoint steps, each projected (:meth:`project`); the hand prefers ``dq``
        ``(M,)`` per unit of progress (eq. 31; default 0, the smallest hand motion)."""
        dr = np.asarray(dr, dtype=float)
        dr = dr / np.linalg.norm(dr)
        prefer = np.concatenate([np.zeros(self.M) if dq is None else np.asarray(dq, dtype=float), dr])
        h = distance / steps
        x = np.concatenate([self.state.q, np.zeros(self.D)])
        X, worst = [x.copy()], 0.0
        for _ in range(steps):
            v0 = self.velocity(x, prefer, dr)
            v1 = self.velocity(x + 0.5 * h * v0, prefer, dr)
            x, res = self.project(x + h * v1, dr)
            worst = max(worst, res)
            X.append(x.copy())
        Xa = np.array(X)  # (steps + 1, M + 6)
        slip = max((chk.slip for chk in self.checks(Xa)), default=0.0)
        poses = np.array([self.pose(xx[self.M:]).vector() for xx in Xa])
        return LinkRollPath(Xa, poses, self.rolls, worst, slip)

    def checks(self, X: Array) -> list[LinkRollCheck]:
        """:func:`link_roll_check` of every rolling contact along the states ``X`` ``(n, M + 6)``."""
        return [link_roll_check(self.hand, ref, self.radius, X, self.state.pose, z, self.axial)
                for ref, z in zip(self.refs, self.offsets, strict=True)]

    @property
    def axial(self) -> bool:
        """Whether the object is a cylinder (its axis checked parallel to the links')."""
        return isinstance(self.scene.object.shape, Cylinder)


def link_roll_check(hand: HandKinematics, ref: BodyRef, radius: float, X: Array, start: Pose, offset: float = 0.0,
                    axial: bool = False) -> LinkRollCheck:
    """A sphere of ``radius`` rolling on the capsule link ``ref`` along the states ``X`` ``(n, M + 6)``
    (``[q; s]``, the sphere at ``start.displaced(s)``), measured from the states alone: per state
    the gap; per segment, in the link's frame (``R_L^T (p - o_L)`` the centre ``c``, ``R_L^T R`` the
    sphere's rotation), the relative turn ``omega_rel = log(R_rel,k+1 R_rel,k^T)`` and the slip
    ``|dc + omega_rel x (-r u_mid)|`` (``u_mid`` the normal halfway; zero to third order per segment
    when it rolls, exactly the plane's ``dp + omega x (-r n)`` of
    :func:`planner.object_motion.rolling_slip` on a flat side), and the contact point's travels on
    the link (link frame) and on the sphere (object frame). A cylinder's contact at the axial
    coordinate ``offset`` (``axial``): the same with its axis point ``P = p + z a`` for the centre,
    and the largest sine of the angle between its axis and the link's."""
    X = np.asarray(X, dtype=float)
    M = hand.M
    gaps, cs, Rs, us, on_link, on_obj, tilt = [], [], [], [], [], [], [0.0]
    for x in X:
        q = x[:M]
        pose = start.displaced(x[M:])
        P = axis_point(pose, offset)
        g, u, _ = link_contact(hand, ref, radius, q, P)
        R_L, o_L = hand.body_pose(ref, q)
        gaps.append(abs(g))
        cs.append(R_L.T @ (P - o_L))
        Rs.append(R_L.T @ pose.rotation)
        us.append(R_L.T @ u)
        contact = P - radius * u
        on_link.append(R_L.T @ (contact - o_L))
        on_obj.append(pose.to_local(contact))
        if axial:
            a, b = hand.body_segment(ref, q)
            e = (b - a) / np.linalg.norm(b - a)
            tilt.append(float(np.linalg.norm(np.cross(pose.rotation[:, 2], e))))
    slip = turn = 0.0
    for k in range(len(X) - 1):
        w = matrix_to_rotvec(Rs[k + 1] @ Rs[k].T)  # (3,)
        um = us[k] + us[k + 1]
        um = um / np.linalg.norm(um)
        slip += float(np.linalg.norm(cs[k + 1] - cs[k] + np.cross(w, -radius * um)))
        turn += float(np.linalg.norm(w))
    travel = [float(sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(pts))) for pts in (on_link, on_obj)]
    return LinkRollCheck(max(gaps, default=0.0), slip, travel[0], travel[1], turn, max(tilt))
