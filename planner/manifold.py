"""The contact manifold of a grasp state (paper eq. 5, 7 and 19, to every order) and its projection.

In the ambient coordinates ``x = [q (M); s (D)]`` of OMPL's constrained planning (``q`` the hand
configuration, ``s`` the object displacement from the state's pose, :meth:`analysis.pose.Pose.displaced`),
:class:`ContactManifold` is ``F(x) = 0``: every sticking contact's body point stays on its object
point (eq. 7) and every sliding contact keeps touching (eq. 5, normal component only: a disk or
sphere on any body, an object point of any other object on a fixed body's surface, or a capsule
link lying along a face of a box or polygon, its axis point the link's radius off the face). Its
Jacobian at ``s = 0`` is ``A_c`` (eq. 19), so its tangent space there is the motion space.
:func:`project_manifold` projects an ambient point onto it (minimum-norm Newton steps, as OMPL's
``ProjectedStateSpace`` does); :func:`pose_displacement` gives the ``s`` of a pose vector.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import link_shapes, shape_normal_cone, shape_signed_distance
from analysis.kinematics import BodyRef, HandKinematics, SerialChain
from analysis.loader import GEOMETRY_TOL
from analysis.pose import Pose
from analysis.rotations import skew
from analysis.scene import Box, Cylinder, Disk, Polygon, Scene, Sphere
from planner.state import GraspState

_EYE3 = np.eye(3)
#: a planar point given by its first two coordinates (an array, or floats of :meth:`ContactManifold._planar_fk`)
_Point = Array | Sequence[float]
_EYE2 = np.eye(2)


def _left_jacobian_so3(w: Array) -> Array:
    """``J_l(w)`` ``(3, 3)`` of SO(3): ``exp(w + dw) = exp(J_l(w) dw) exp(w)`` to first order."""
    th = float(np.linalg.norm(w))
    W = skew(w)
    if th < 1e-6:
        return _EYE3 + 0.5 * W + (W @ W) / 6.0
    return _EYE3 + (1 - np.cos(th)) / th**2 * W + (th - np.sin(th)) / th**3 * (W @ W)


class ContactManifold:
    """The contact manifold of a grasp state's sticking contacts, in the ambient coordinates
    ``x = [q (M); s (D)]`` of OMPL's constrained planning: ``q`` the hand configuration and ``s``
    the object displacement from the state's pose (2-D ``(dx, dy, dtheta)``; 3-D ``(dp, w)``, the
    object at ``p_o + dp`` with rotation ``exp(w) R_0``).

    ``F(x)`` ``(d * n_F + n_S,)`` stacks, for every sticking contact ``i``, the body point minus the
    object point, ``x_b,i(q) - (p_o + dp + R(s) c_i)``, which is zero on the manifold (the F-points
    of eq. 7 do not move relative to each other), and for every sliding contact (S or N) the gap
    between the body's surface and the object's, which is zero while it slides (eq. 5: only the
    normal component is constrained, the tangential motion is free): on a disk or sphere the
    distance of its centre from the body minus the radius (the contact point moves on both), on
    any other object a contact on a fixed body only, whose object point ``c_i`` (a box corner on a
    table) stays on the body's surface, ``sd_body(p_o + dp + R(s) c_i) = 0``, with Jacobian
    ``u^T [I, -[R c_i]x J_l(w)]`` (``u`` the body's outward unit normal there), or a capsule link
    sliding on a flat face of a box or polygon object (a forearm along a box's side, S at a link):
    the link's axis point ``a`` over the contact stays the link's radius ``rho`` off the face's
    plane, ``(R(s) u_o) . (a(q) - p_o - dp) - h - rho = 0`` (``u_o . x = h`` the face in the
    object frame), Jacobian ``[u^T J_a, -u^T, ((u x (a - p)) J_l(w))^T]``; a link's two such rows
    (its line contact's ends) keep it parallel to the face. A contact at the joint with another
    link of its finger that sticks there (a forearm's end at the elbow, where the elbow's line
    ends) has no row (:meth:`_implied_at_joint`). The Jacobian is ``[J_c, -G^T]`` in
    these coordinates, so ``F'(x) [dq; ds] = 0`` at ``s = 0`` is ``A_c [dq; dr] = 0`` (eq. 7, 19).

    With ``direction`` (a unit ``dr`` ``(D,)``, the analysed DAFC direction of an object motion)
    ``F`` also has the rows ``B^T s``, ``B`` an orthonormal basis of the directions of
    ``motion_space`` (``(D, a~)``, the object directions of the motion space, ``Lambda~_r``;
    default: every direction) orthogonal to ``dr``: the object then moves along the direction
    whose torque the analysis chose and along no other direction the contacts allow; where the
    object motions the contacts allow form a flat set the path is the line ``s = t dr``, where
    they form a curved one (two arms each holding the box with two links) it is the curve of
    that set tangent to ``dr``. OMPL's constrained planning on this manifold cannot take the
    object elsewhere.

    With ``rolling=True`` (a 2-D disk only) a sticking contact on the side of a finger link rolls
    instead of keeping its two points glued: the disk turning relative to the link moves the
    contact point on both surfaces by the same arc length (rolling without slipping, exact, not
    first order only). Its two rows are the gap ``|p_o - y(q)| - rho - r = 0`` (as a sliding
    contact's) and the rolling row ``(sigma - sigma_0) + r (beta - beta_0) = 0``, ``sigma`` the
    arc length of the contact point along the capsule's surface (counter-clockwise: ``-side t L``
    on the side, plus ``rho psi`` round an end cap, ``psi`` the angle of ``u`` from the side's
    normal) and ``beta`` the contact point's angle on the disk (object frame, counter-clockwise):
    moving counter-clockwise on one surface is moving clockwise on the other. Their first-order
    rows span the same space as the glued point's (equal velocities of the two material points),
    so the tangent space at ``s = 0`` is still the motion space. A glued point pivots the disk
    about it and, on a link's side, pushes it into the link by ``r (1 - cos dtheta)`` while the
    true contact point moves by ``r dtheta``; at a sharp link tip (``rho = 0``) both agree, so
    contacts at a link's end keep the glued rows. :meth:`rolling_contact` gives the contact after
    a motion.

    With ``rolling=True`` for a 3-D sphere (radius ``r``) a sticking contact on a flat face of a
    fixed body (a table: the face's outward normal ``n`` points into the sphere) rolls instead of
    pivoting about a glued point. Its three rows are ``dp + r n x w = 0`` (``s = (dp, w)``): the
    normal one, ``n . dp = 0``, keeps the centre ``r`` off the plane (the gap, exact), the two
    tangential ones are the no-slip condition ``v = r omega x n`` integrated along the ray
    ``s = t (v, omega)``: the object turns about the fixed world axis ``omega`` at a constant rate
    (``R = exp(t omega) R_0``) while its centre moves by ``t v``, a constant twist whose contact
    point on the sphere, ``p - r n``, has velocity ``v + omega x (-r n) = 0`` at every ``t``:
    rolling without slipping, exact and not first order only, the contact point moving by
    ``r |omega_t| t`` on the plane and on the sphere (``omega_t`` the tangential part of
    ``omega``; a spin ``omega . n`` moves neither). Rolling is non-holonomic: along a path of
    this manifold that is not such a ray (``w`` not of one direction) the sphere slips by
    ``r |(J_l(w) - I) dw x n|``, second order; the direction rows keep an object motion on the
    ray ``s = t dr`` whenever the other contacts leave the sphere every rolling motion (the
    motion space is the rolling twists), :func:`planner.object_motion.plan_object_motion` refuses
    a path that slips (:func:`planner.object_motion.rolling_slip`) and :mod:`planner.verify`
    measures the slip along every path. The rows' Jacobian ``[0, I, r [n]x]`` has the row space
    of the glued point's ``[-I, -r [n]x]`` (its object point ``-r n`` from the centre), so the
    tangent space at ``s = 0`` is still the motion space. A glued point pivots the sphere about
    it, sinking it ``r (1 - cos theta)`` into the plane. :meth:`plane_rolling_contact` gives the
    contact after a motion.

    With ``rolling=True`` for a 3-D cylinder (radius ``r``, axis the object's z axis, ``a_0`` in
    the world at the start) lying on a flat face of a fixed body (``a_0 . n = 0``), each sticking
    contact on its curved surface there (the ends of its line contact) has the same three rows
    ``dp + r n x w = 0``, and the cylinder has two more, ``P w = 0`` (``P`` ``(2, 3)`` orthonormal,
    orthogonal to ``a_0``): it turns about its own axis only, ``R = exp(theta a_0) R_0``, which
    keeps the axis at ``a_0``, and its centre moves by ``r theta a_0 x n``. Rolling about a fixed
    axis is holonomic, so these rows hold exactly along any path: every point of the manifold is
    the cylinder rolled by ``theta`` without slipping (its contact line at rest, every point of it:
    ``v + omega x (z a_0 - r n) = 0``), the contact line moving by ``r theta`` on the plane and on
    the cylinder. The rows' Jacobian ``[0, I, r [n]x]`` and ``[0, 0, P]`` has rank 5, the row space
    of the two glued ends' (``-I, [y_i]x`` with ``y_i = z_i a_0 - r n``: their difference forces
    ``omega || a_0``), so the tangent space at ``s = 0`` is still the motion space."""

    def __init__(self, hand: HandKinematics, state: GraspState, sticking: Sequence[int],
                 sliding: Sequence[int] = (), scene: Scene | None = None, direction: Array | None = None,
                 motion_space: Array | None = None, rolling: bool = False):
        self.hand, self.state, self.dim = hand, state, state.dim
        self.start: Pose = state.pose  # the object pose at s = 0
        self._last_pose: tuple[bytes, Pose] | None = None  # _pose_at's
        self.M, self.D = hand.M, self.start.D
        self.items: list[tuple[BodyRef | None, Array, Array]] = []  # (finger body or None, point_body, point_obj)
        #: rolling contacts: (contact index, link, side +-1, sigma_0, gamma_0)
        self.rolls: list[tuple[int, BodyRef, float, float, float]] = []
        #: rolling contacts of a 3-D sphere on a flat face of a fixed body: (contact index, body,
        #: the face's outward unit normal ``n`` ``(3,)``, world)
        self.plane_rolls: list[tuple[int, BodyRef, Array]] = []
        self.radius = 0.0
        #: a cylinder's axis in the world at the start ``(3,)`` (None: not a cylinder)
        self.axis: Array | None = None
        if rolling:
            if scene is None or not isinstance(scene.object.shape, Disk | Sphere | Cylinder) or (
                    (self.dim == 2) != isinstance(scene.object.shape, Disk)):
                raise SceneError(("object", "shape"), "rolling contacts are followed for 2-D disk, 3-D sphere and "
                                 "3-D cylinder objects only (pass the scene of a disk, a sphere or a cylinder)")
            self.scene = scene
            self.radius = float(scene.object.shape.radius)
            if isinstance(scene.object.shape, Cylinder):
                self.axis = self.start.rotation[:, 2].copy()
        for i in sticking:
            c = state.contacts[i]
            ref = hand.resolve_body(c.body)
            assert ref is not None
            if rolling and self.dim == 3 and ref.finger is None:
                n = self._fixed_face_normal(ref, state.world_point(i))
                if n is not None and self._rolls_on_face(i, n):
                    self.plane_rolls.append((i, ref, n))
                    continue
            if rolling and self.dim == 2 and ref.finger is not None:
                side = self._rolling_side(ref, state.q)
                if side is not None:
                    sig, gamma = self._roll_coords(ref, side, state.q, self.start)
                    self.rolls.append((i, ref, side, sig, gamma))
                    continue
            if ref.finger is None:  # a fixed body: its (world) point stays where it is
                self.items.append((None, state.world_point(i), np.asarray(c.point_object, float)))
            else:
                self.items.append((ref, np.asarray(c.point_body, float), np.asarray(c.point_object, float)))
        self.sliding: list[BodyRef] = []
        #: per sliding contact: ``None`` (a disk or sphere: the gap of its centre) or the object-frame
        #: point ``(d,)`` (a vertex, edge or face corner of any other object on a fixed body: that point
        #: stays on the body's surface while it slides along it)
        self.sliding_points: list[Array | None] = []
        #: per sliding contact: ``None``, or for a link sliding on a face of a box or polygon (a
        #: forearm lying on a box's side) ``(a_b, u_o, h)``: the link's axis point under the contact
        #: (link frame ``(3,)``), the face's outward unit normal and its offset ``u_o . x = h``
        #: (object frame): the axis point stays the link's radius off the face's plane
        self.sliding_faces: list[tuple[Array, Array, float] | None] = []
        if sliding:
            if scene is None:
                raise SceneError(("object", "shape"), "sliding contacts need the scene (its shapes)")
            self.scene = scene
            shape = scene.object.shape
            if isinstance(shape, Disk | Sphere):
                self.radius = float(shape.radius)
        for i in sliding:
            c = state.contacts[i]
            ref = hand.resolve_body(c.body)
            assert ref is not None
            face = None
            if isinstance(self.scene.object.shape, Disk | Sphere):
                self.sliding_points.append(None)
            elif ref.finger is None:
                self.sliding_points.append(np.asarray(c.point_object, dtype=float))
            else:
                face = self._link_on_face(i, ref, state)
                self.sliding_points.append(None)
            self.sliding_faces.append(face)
            self.sliding.append(ref)
        #: ``B`` ``(D, k)``: an orthonormal basis of the complement of ``direction`` in the motion
        #: space (``k = a~ - 1``); the rows ``B^T s = 0`` keep the object on the analysed direction
        self.direction: Array | None = None
        self.complement = np.zeros((self.D, 0))
        if direction is not None:
            u = np.asarray(direction, dtype=float).reshape(self.D)
            if not float(np.linalg.norm(u)) > 1e-12:
                raise ValueError("the direction of an object motion must be non-zero")
            self.direction = u = u / np.linalg.norm(u)
            W = np.eye(self.D) if motion_space is None else np.asarray(motion_space, dtype=float).reshape(self.D, -1)
            C = W - np.outer(u, u @ W)  # the motion space's directions, made orthogonal to u
            Uc, sv, _ = np.linalg.svd(C, full_matrices=False)
            self.complement = Uc[:, sv > 1e-9]  # (D, k)
        self._roll0 = self.dim * len(self.items)  # first rolling row
        self._plane0 = self._roll0 + 2 * len(self.rolls)  # first row of a sphere rolling on a plane
        #: a cylinder rolling on a plane: ``P`` ``(2, 3)``, an orthonormal basis of the directions
        #: orthogonal to its axis at the start; the rows ``P w = 0`` keep it turning about that axis
        self.axis_rows = np.zeros((0, 3))
        if self.axis is not None and self.plane_rolls:
            self.axis_rows = np.linalg.svd(self.axis[None, :])[2][1:]  # (2, 3)
        self._axis0 = self._plane0 + 3 * len(self.plane_rolls)  # first row of a cylinder's axis
        self._slide0 = self._axis0 + self.axis_rows.shape[0]  # first sliding row
        #: the row of each sliding contact (none for a link's contact at the joint with a link that
        #: sticks to the same face, :meth:`_implied_at_joint`)
        self._row_of: dict[int, int] = {}
        for k in range(len(self.sliding)):
            if not self._implied_at_joint(k, sticking):
                self._row_of[k] = len(self._row_of)
        self._base = self._slide0 + len(self._row_of)
        #: per finger, the signs ``(n,)`` of its joint axes along z when every finger is a serial chain
        #: turning about z in the plane (the scene's planar fingers): the Jacobian columns of a point
        #: ``x`` are then ``a_j z x (x - p_j)`` in the plane (:meth:`_planar_columns`); else None
        self._z_axes: list[Array] | None = self._planar_axes(hand) if self.dim == 2 else None
        #: per finger for the planar float path (:meth:`_planar_fk`): base angle, first joint's
        #: position, the link vectors (joint to joint, the last to the tip) and the axis signs
        self._planar_chains: list[tuple[float, float, float, list[tuple[float, float]], list[float]]] = []
        if self._z_axes is not None:
            for f, axes in zip(hand.fingers, self._z_axes, strict=True):
                assert isinstance(f, SerialChain)
                p0 = f.base_p + f.base_R @ f.origins[0]  # (3,)
                links = [(float(o[0]), float(o[1])) for o in (*f.origins[1:], f.tip)]
                self._planar_chains.append((float(np.arctan2(f.base_R[1, 0], f.base_R[0, 0])), float(p0[0]),
                                            float(p0[1]), links, [float(a) for a in axes]))
        self._fk_last: tuple[bytes, list[list[tuple[float, float, float, float]]]] | None = None
        #: rows of the contacts (without the direction's)
        self.contact_rows = self._base
        self.rows = self._base + self.complement.shape[1]

    def _link_on_face(self, i: int, ref: BodyRef, state: GraspState) -> tuple[Array, Array, float]:
        """``(a_b, u_o, h)`` of :attr:`sliding_faces` for contact ``i``, a capsule link on a flat face of
        a box or polygon object; SceneError naming what is not supported (an edge or a vertex of
        the object, a curved or mesh object, a link of URDF collision shapes)."""
        c = state.contacts[i]
        shape = self.scene.object.shape
        where = ("contacts", i)
        if not isinstance(shape, Box | Polygon):
            raise SceneError(where, f"a sliding contact of a link ({c.body}) is followed on disks, spheres and the "
                             f"faces of boxes and polygons (the object is a {shape.type})")
        if link_shapes(self.hand, ref, state.q) is not None:
            raise SceneError(where, f"a sliding contact of a link ({c.body}) is followed for capsule links only "
                             "(this link has its URDF collision shapes)")
        po = np.asarray(c.point_object, dtype=float)
        u_o = -np.asarray(c.normal_object, dtype=float)  # (d,) outward, object frame
        cone = shape_normal_cone(shape, po, self.dim, GEOMETRY_TOL)
        # the contact's normal is a face's normal there (the end of a line contact may lie on the
        # face's edge: a forearm reaching past the box's side), not a direction inside an edge's cone
        if cone is None or not any(float(g @ u_o) > 1 - 1e-9 for g in cone.generators):
            raise SceneError(where, f"a sliding contact of a link ({c.body}) is followed on a face of the object "
                             "(its normal is no face's normal: it touches an edge or a vertex)")
        x = state.world_point(i)  # (d,)
        a, b = self.hand.body_segment(ref, state.q)
        a, e = a[: self.dim], b[: self.dim] - a[: self.dim]
        t = float(np.clip((x - a) @ e / max(float(e @ e), 1e-300), 0.0, 1.0))
        foot = a + t * e  # (d,) the axis point under the contact
        return self.hand.to_local(ref, foot, state.q), u_o, float(u_o @ po)

    def _implied_at_joint(self, k: int, sticking: Sequence[int]) -> bool:
        """Whether sliding contact ``k`` (a link on a face) sits at the joint with another link of its
        finger whose sticking contact there has the same axis point: a forearm's contact at the
        elbow joint, where the elbow's line contact ends. The joint centre is then glued to the
        object through the other link, so the forearm's axis stays on the face there; its own row
        would be redundant to first order and not to second (the sticking link may turn about its
        contact line, which moves the joint centre off the face by ``rho (1 - cos)``; the capsule's
        own surface forbids that turn, which glued points do not see), a cusp no projection can
        follow. The contact keeps sliding (it turns about the joint with the other link)."""
        face = self.sliding_faces[k]
        if face is None:
            return False
        ref = self.sliding[k]
        a = self.hand.point_position(ref, face[0], self.state.q)
        for i in sticking:
            c = self.state.contacts[i]
            other = self.hand.resolve_body(c.body)
            if other is None or other.finger != ref.finger or other.link == ref.link:
                continue
            p0, p1 = self.hand.body_segment(other, self.state.q)
            p0, e = p0[: self.dim], p1[: self.dim] - p0[: self.dim]
            x = self.state.world_point(i)
            t = float(np.clip((x - p0) @ e / max(float(e @ e), 1e-300), 0.0, 1.0))
            if float(np.linalg.norm(p0 + t * e - a)) <= GEOMETRY_TOL:
                return True
        return False

    def _face_gap(self, k: int, q: Array, pose: Pose) -> tuple[float, Array, Array]:
        """Sliding contact ``k`` of a link on a face: the gap ``u . (a - p_o) - h - rho`` (``u`` the
        face's outward normal in the world, ``a`` the link's axis point), ``u`` ``(d,)`` and ``a``
        ``(d,)``."""
        face = self.sliding_faces[k]
        assert face is not None
        a_b, u_o, h = face
        ref = self.sliding[k]
        a = self.hand.point_position(ref, a_b, q)
        u = pose.R_d @ u_o
        return float(u @ (a - pose.position)) - h - self.hand.body_radius(ref), u, a

    def body_distance(self, ref: BodyRef, c: Array, q: Array) -> tuple[float, Array, Array]:
        """Distance of the object centre ``c`` ``(d,)`` from the surface of the body ``ref`` at ``q``,
        the unit vector ``u`` ``(d,)`` from the body towards ``c`` and the closest body point ``(d,)``
        on the body's axis (fixed bodies: on the surface)."""
        d = self.dim
        if ref.finger is None:
            body = next(b for b in self.scene.fixed_bodies if b.name == ref.name)

            def sd_at(x: Array) -> float:
                v = shape_signed_distance(body.shape, x, d)
                assert v is not None  # fixed shapes all have distances
                return v

            h = 1e-7  # central differences of the body's distance field: its gradient points at c
            grad = np.array([sd_at(c + h * e) - sd_at(c - h * e) for e in np.eye(d)]) / (2 * h)
            u = grad / np.linalg.norm(grad)
            sd = sd_at(c)
            return sd, u, c - sd * u
        a, b = self.hand.body_segment(ref, q)
        a, b = a[:d], b[:d]
        e = b - a
        t = float(np.clip((c - a) @ e / max(float(e @ e), 1e-300), 0.0, 1.0))
        y = a + t * e
        dist = float(np.linalg.norm(c - y))
        return dist - self.hand.body_radius(ref), (c - y) / max(dist, 1e-300), y

    def _rolling_side(self, ref: BodyRef, q: Array) -> float | None:
        """``+1`` (``-1``) when the disk at the start touches the left (right) side of the link's axis
        ``a -> b``, ``None`` when its centre's foot point is at an end of the axis (the tip)."""
        a, b = self.hand.body_segment(ref, q)
        e, c = b[:2] - a[:2], self.start.position - a[:2]  # (2,), (2,)
        t = float(c @ e / max(float(e @ e), 1e-300))
        if not 1e-6 < t < 1 - 1e-6:
            return None
        return 1.0 if float(e[0] * c[1] - e[1] * c[0]) > 0 else -1.0

    def _roll_coords(self, ref: BodyRef, side: float, q: Array, pose: Pose) -> tuple[float, float]:
        """``(sigma, gamma)`` of the contact of the disk at ``pose`` with the link ``ref`` at ``q``: the
        arc length along the link's surface (counter-clockwise, from the foot of its axis' start)
        and the world angle of the touching point seen from the disk's centre (the point's angle on
        the disk is ``beta = gamma - theta``, ``theta`` the disk's angle)."""
        a, b = self.hand.body_segment(ref, q)
        a, e = a[:2], b[:2] - a[:2]  # (2,), (2,)
        L = float(np.linalg.norm(e))
        eh = e / L
        c = pose.position
        t = float(np.clip((c - a) @ eh / L, 0.0, 1.0))
        u = c - (a + t * L * eh)
        u = u / max(float(np.linalg.norm(u)), 1e-300)  # from the axis towards the centre
        n = side * np.array([-eh[1], eh[0]])  # the side's outward normal
        psi = float(np.arctan2(n[0] * u[1] - n[1] * u[0], n @ u))
        return -side * t * L + self.hand.body_radius(ref) * psi, float(np.arctan2(-u[1], -u[0]))

    def _roll_at(self, k: int, a: _Point, b: _Point, c: _Point, theta: float) -> tuple[float, float]:
        """Rolling contact ``k``'s gap and rolling row (see :meth:`_rolling_rows`) for the link's
        axis ``a -> b``, the disk centre ``c`` (``(2,)`` each) and the disk's turn ``theta`` from
        the start (:meth:`body_distance` and :meth:`_roll_coords` in one; plain float arithmetic:
        a projection evaluates it a few hundred times per motion)."""
        _, ref, side, sig0, gamma0 = self.rolls[k]
        a0, a1 = float(a[0]), float(a[1])
        e0, e1 = float(b[0]) - a0, float(b[1]) - a1
        w0, w1 = float(c[0]) - a0, float(c[1]) - a1
        L = math.hypot(e0, e1)
        t = min(max((w0 * e0 + w1 * e1) / (L * L), 0.0), 1.0)
        v0, v1 = w0 - t * e0, w1 - t * e1  # from the closest axis point to the centre
        dist = math.hypot(v0, v1)
        u0, u1 = v0 / max(dist, 1e-300), v1 / max(dist, 1e-300)
        r_link = self.hand.body_radius(ref)
        n0, n1 = -side * e1 / L, side * e0 / L  # the side's outward normal
        psi = math.atan2(n0 * u1 - n1 * u0, n0 * u0 + n1 * u1)
        sig, gamma = -side * t * L + r_link * psi, math.atan2(-u1, -u0)
        dbeta = (gamma - gamma0 + math.pi) % (2 * math.pi) - math.pi - theta
        return dist - r_link - self.radius, (sig - sig0) + self.radius * dbeta

    def _rolling_rows(self, x: Array) -> Array:
        """``(2 n_roll,)``: per rolling contact its gap and its rolling row; ``beta - beta_0`` is the
        touching point's turn seen from the centre (``gamma - gamma_0``, within half a turn) minus
        the disk's turn ``s_theta`` (not wrapped: a disk may roll more than half a turn)."""
        q, s = x[: self.M], x[self.M:]
        c = self._pose_at(s).position
        out = np.empty(2 * len(self.rolls))
        for k, roll in enumerate(self.rolls):
            a, b = self.hand.body_segment(roll[1], q)
            out[2 * k: 2 * k + 2] = self._roll_at(k, a, b, c, float(s[2]))
        return out

    def _roll_grad(self, k: int, a: Array, b: Array, c: Array) -> Array:
        """``(2, 7)``: :meth:`_roll_grad_rows` as an array."""
        return np.array(self._roll_grad_rows(k, a, b, c))

    def _roll_grad_rows(self, k: int, a: _Point, b: _Point, c: _Point) -> tuple[list[float], list[float]]:
        """The two rows (7 floats each) of the derivatives of :meth:`_roll_at` (gap, rolling row) in
        the axis ends ``a``, ``b``, the centre ``c`` (``(2,)`` each) and the turn ``theta``. With ``e = b - a``,
        ``w = c - a``, the foot parameter ``t = w.e / |e|^2`` (held at 0 or 1 beyond the ends, where
        ``dt = 0``) and ``v = w - t e``: ``d|v| = u.dv``, the angle of ``v`` (of ``u``, of ``gamma``)
        changes by ``v_perp.dv / |v|^2`` and that of ``e`` (of the side's normal) by
        ``e_perp.de / |e|^2``, ``psi`` by their difference, ``sigma = -side t |e| + rho psi``.

        In plain float arithmetic, ``z = (a, b, c, theta)``: ``de/dz = [-I, I, 0, 0]``,
        ``dw/dz = [-I, 0, I, 0]``, so ``dt = (e.dw + w.de - 2 t e.de) / |e|^2`` and
        ``dv = dw - t de - e dt`` column by column."""
        _, ref, side, _, _ = self.rolls[k]
        a0, a1 = float(a[0]), float(a[1])
        e0, e1 = float(b[0]) - a0, float(b[1]) - a1
        w0, w1 = float(c[0]) - a0, float(c[1]) - a1
        L2 = e0 * e0 + e1 * e1
        L = math.sqrt(L2)
        t_raw = (w0 * e0 + w1 * e1) / L2
        t = min(max(t_raw, 0.0), 1.0)
        v0, v1 = w0 - t * e0, w1 - t * e1  # from the foot on the axis to the centre
        dist2 = v0 * v0 + v1 * v1
        dist = math.sqrt(dist2)
        # the columns of de/dz and dw/dz, as (x, y) pairs over z = (a_x, a_y, b_x, b_y, c_x, c_y, theta)
        de = ((-1.0, 0.0), (0.0, -1.0), (1.0, 0.0), (0.0, 1.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))
        dw = ((-1.0, 0.0), (0.0, -1.0), (0.0, 0.0), (0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.0, 0.0))
        inside = 0.0 < t_raw < 1.0
        rho, r = self.hand.body_radius(ref), self.radius
        gap_row, roll_row = [], []
        for j in range(7):
            (de0, de1), (dw0, dw1) = de[j], dw[j]
            e_de = e0 * de0 + e1 * de1
            dt = (e0 * dw0 + e1 * dw1 + w0 * de0 + w1 * de1 - 2.0 * t * e_de) / L2 if inside else 0.0
            dv0 = dw0 - t * de0 - e0 * dt
            dv1 = dw1 - t * de1 - e1 * dt
            d_angle_v = (-v1 * dv0 + v0 * dv1) / dist2  # the angle of v: of u and of gamma
            d_angle_e = (-e1 * de0 + e0 * de1) / L2  # the angle of e: of the side's normal
            d_sigma = -side * (L * dt + t * e_de / L) + rho * (d_angle_v - d_angle_e)
            gap_row.append((v0 * dv0 + v1 * dv1) / dist)
            roll_row.append(d_sigma + r * d_angle_v)
        roll_row[6] -= r  # beta = gamma - theta
        return gap_row, roll_row

    def _rolling_jacobian(self, x: Array) -> Array:
        """``(2 n_roll, M + D)`` of :meth:`_rolling_rows`: the derivatives in the axis ends ``a``,
        ``b``, the centre ``c`` and the turn (:meth:`_roll_grad`), times their Jacobians (``a``, ``b``
        points of the link, eq. 1; ``c = p_0 + s_xy``, the turn ``s_theta``)."""
        q, s = x[: self.M], x[self.M:]
        c = self._pose_at(s).position
        J = np.zeros((2 * len(self.rolls), self.M + self.D))
        for k, roll in enumerate(self.rolls):
            ref = roll[1]
            a3, b3 = self.hand.body_segment(ref, q)
            dz = self._roll_grad(k, a3, b3, c)  # (2, 7)
            Jab = self.hand.point_jacobians(ref, np.vstack([a3, b3]), q)  # (2, 2, M): at a, at b
            rows = slice(2 * k, 2 * k + 2)
            J[rows, : self.M] = dz[:, 0:2] @ Jab[0] + dz[:, 2:4] @ Jab[1]
            J[rows, self.M: self.M + 2] = dz[:, 4:6]
            J[rows, self.M + 2] = dz[:, 6]
        return J

    def rolling_contact(self, k: int, x: Array) -> tuple[int, Array, Array, Array]:
        """Rolling contact ``k`` at ``x``: its contact index, the touching point (world ``(2,)``), the
        point on the disk and its inward normal (object frame ``(2,)``)."""
        q, s = x[: self.M], x[self.M:]
        pose = self.pose(s)
        i, ref = self.rolls[k][0], self.rolls[k][1]
        _, u, _ = self.body_distance(ref, pose.position, q)
        y = pose.position - self.radius * u  # on both surfaces when the gap is zero
        return i, y, pose.to_local(y), pose.R_d.T @ u

    def _fixed_face_normal(self, ref: BodyRef, x: Array) -> Array | None:
        """The outward unit normal ``(3,)`` of the fixed body ``ref``'s face at the world point ``x``
        ``(3,)`` where the sphere touches it there, ``None`` at an edge or a vertex (one normal
        only: a face) or for a body without normal cones."""
        body = next(b for b in self.scene.fixed_bodies if b.name == ref.name)
        cone = shape_normal_cone(body.shape, x, 3, GEOMETRY_TOL)
        if cone is None or cone.generators.shape[0] != 1:
            return None
        n = np.asarray(cone.generators[0], dtype=float)
        return n / np.linalg.norm(n)

    def _rolls_on_face(self, i: int, n: Array) -> bool:
        """Whether sticking contact ``i`` on a fixed face of outward normal ``n`` ``(3,)`` rolls: always
        for a sphere; for a cylinder where it lies on the face (its axis parallel to the face within
        1e-9) and the contact is on its curved surface (the object point ``r`` off the axis within
        :data:`~analysis.loader.GEOMETRY_TOL`; a cylinder standing on an end face keeps its glued
        points, exact there)."""
        if self.axis is None:
            return True
        po = np.asarray(self.state.contacts[i].point_object, dtype=float)
        return abs(float(self.axis @ n)) <= 1e-9 and abs(float(np.linalg.norm(po[:2])) - self.radius) <= GEOMETRY_TOL

    def plane_offset(self, k: int) -> float:
        """The axial coordinate ``z_k`` (object frame) of rolling contact ``k`` of a cylinder on a plane
        (where along its line contact it lies: it keeps it while rolling); 0 for a sphere."""
        if self.axis is None:
            return 0.0
        return float(self.state.contacts[self.plane_rolls[k][0]].point_object[2])

    def plane_rolling_contact(self, k: int, x: Array) -> tuple[int, Array, Array, Array]:
        """Rolling contact ``k`` of a sphere or a cylinder on a plane at ``x``: its contact index, the
        touching point ``p + z_k a - r n`` (world ``(3,)``, on the plane; ``a`` the cylinder's axis,
        ``z_k`` :meth:`plane_offset`, 0 for a sphere), the point on the object and its inward normal
        (object frame ``(3,)``)."""
        pose = self.pose(x[self.M:])
        i, _, n = self.plane_rolls[k]
        y = pose.position - self.radius * n + self.plane_offset(k) * pose.rotation[:, 2]
        return i, y, pose.to_local(y), pose.R_d.T @ n

    def sliding_contact(self, k: int, x: Array) -> tuple[Array, Array, Array]:
        """Sliding contact ``k`` at ``x``: body point (world ``(d,)``), object point and inward normal
        (object frame ``(d,)``) where the body touches the disk or sphere."""
        q, s = x[: self.M], x[self.M:]
        pose = self.pose(s)
        if self.sliding_faces[k] is not None:  # a link on a face: under its axis point, within the face
            gap, u, a = self._face_gap(k, q, pose)
            # the foot of the axis point on the face's plane (a - rho u where the gap row holds; a
            # contact without a row, at a joint, lands on the face too)
            y = self._within_face(k, a - (gap + self.hand.body_radius(self.sliding[k])) * u, q, pose)
            face = self.sliding_faces[k]
            assert face is not None
            return y, pose.to_local(y), -face[1]
        po = self.sliding_points[k]
        if po is not None:  # an object point on a fixed body: it stays, the body's point moves
            y = pose.to_world(po)
            _, u, _ = self.body_distance(self.sliding[k], y, q)
            return y, np.array(po, dtype=float), pose.R_d.T @ u
        _, u, _ = self.body_distance(self.sliding[k], pose.position, q)
        y = pose.position - self.radius * u  # the touching point, on both surfaces when the gap is zero
        return y, pose.to_local(y), pose.R_d.T @ u

    def _within_face(self, k: int, y: Array, q: Array, pose: Pose) -> Array:
        """The point ``y`` ``(d,)`` (world, on the face's plane, under the link's axis) moved along the
        axis' projection onto the face until it lies on the face (a forearm reaching past the box's
        edge touches it up to the edge): the nearest point of that line inside the object's face."""
        ref = self.sliding[k]
        shape = self.scene.object.shape
        a, b = self.hand.body_segment(ref, q)
        e = pose.R_d.T @ (b[: self.dim] - a[: self.dim])  # (d,) the axis, object frame
        face = self.sliding_faces[k]
        assert face is not None
        u_o = face[1]
        e = e - (e @ u_o) * u_o  # projected onto the face
        y_o = pose.to_local(y)
        if float(np.linalg.norm(e)) <= 1e-12:
            return y
        e = e / np.linalg.norm(e)
        # the face: the object's points on its plane, inside every other supporting half-space
        if isinstance(shape, Box):
            c = np.zeros(self.dim) if shape.position is None else np.asarray(shape.position, dtype=float)
            half = np.asarray(shape.size, dtype=float) / 2.0
            normals = np.vstack([np.eye(self.dim), -np.eye(self.dim)])  # (2d, d)
            offsets = np.concatenate([c + half, -(c - half)])  # (2d,)
        else:
            assert isinstance(shape, Polygon)
            V = np.asarray(shape.vertices, dtype=float)
            E = np.roll(V, -1, axis=0) - V
            normals = np.column_stack([E[:, 1], -E[:, 0]]) / np.linalg.norm(E, axis=1)[:, None]
            offsets = np.sum(normals * V, axis=1)
        lo, hi = -np.inf, np.inf  # the parameters t with y_o + t e inside (Liang-Barsky)
        for nrm, off in zip(normals, offsets, strict=True):
            if abs(float(nrm @ u_o)) > 1 - 1e-9:
                continue  # the face's own plane and the opposite face
            rate, slack = float(nrm @ e), float(off - nrm @ y_o)
            if abs(rate) <= 1e-12:
                continue
            if rate > 0:
                hi = min(hi, slack / rate)
            else:
                lo = max(lo, slack / rate)
        if lo > hi:
            return y
        t = min(max(0.0, lo), hi)
        return pose.to_world(y_o + t * e)

    def pose(self, s: Array) -> Pose:
        """The object pose at displacement ``s`` ``(D,)`` from the state's pose."""
        return self.start.displaced(s)

    def _pose_at(self, s: Array) -> Pose:
        """:meth:`pose`, remembered for the last ``s`` (exactly, by its bytes): ``F``, ``F'`` and their
        rolling rows at one point share it (internal: the arrays are not to be modified)."""
        key = np.asarray(s, dtype=float).tobytes()
        last = self._last_pose
        if last is not None and last[0] == key:
            return last[1]
        pose = self.start.displaced(s)
        self._last_pose = (key, pose)
        return pose

    def _planar_fk(self, q: Array) -> list[list[tuple[float, float, float, float]]]:
        """Planar serial chains (:meth:`_planar_axes`) in float arithmetic: per finger, per joint
        ``j`` and one more for the tip, ``(x, y, cos, sin)`` of the joint's position and of the
        world angle ``theta_j = theta_base + sum_{i <= j} a_i q_i`` of link ``j`` (the tip entry
        repeats the last link's angle); remembered for the last ``q`` (by its bytes)."""
        key = np.asarray(q, dtype=float).tobytes()
        last = self._fk_last
        if last is not None and last[0] == key:
            return last[1]
        ql = np.asarray(q, dtype=float).tolist()
        out = []
        for f, (theta, px, py, links, axes) in enumerate(self._planar_chains):
            off = int(self.hand.offsets[f])
            joints = []
            c = sn = 0.0
            for j, (vx, vy) in enumerate(links):
                theta += axes[j] * ql[off + j]
                c, sn = math.cos(theta), math.sin(theta)
                joints.append((px, py, c, sn))
                px, py = px + c * vx - sn * vy, py + sn * vx + c * vy
            joints.append((px, py, c, sn))
            out.append(joints)
        self._fk_last = (key, out)
        return out

    def _function_planar(self, x: Array) -> Array:
        """:meth:`function` for planar serial chains (:meth:`_planar_axes`) without sliding
        contacts, in float arithmetic (:meth:`_planar_fk`; the object at ``p_o + s_xy`` turned by
        ``theta_0 + s_theta``)."""
        M = self.M
        q, s = x[:M], x[M:]
        fk = self._planar_fk(q)
        sx, sy, st = (float(v) for v in s[:3])
        ox, oy = float(self.start.position[0]) + sx, float(self.start.position[1]) + sy
        th = math.atan2(float(self.start.rotation[1, 0]), float(self.start.rotation[0, 0])) + st
        oc, os_ = math.cos(th), math.sin(th)
        out = np.empty(self.rows)
        for k, (ref, pb, po) in enumerate(self.items):
            if ref is None:
                bx, by = float(pb[0]), float(pb[1])
            else:
                assert ref.finger is not None
                px, py, c, sn = fk[ref.finger][ref.link]
                bx = px + c * float(pb[0]) - sn * float(pb[1])
                by = py + sn * float(pb[0]) + c * float(pb[1])
            out[2 * k] = bx - (ox + oc * float(po[0]) - os_ * float(po[1]))
            out[2 * k + 1] = by - (oy + os_ * float(po[0]) + oc * float(po[1]))
        for k, roll in enumerate(self.rolls):
            ref = roll[1]
            assert ref.finger is not None
            a, b = fk[ref.finger][ref.link], fk[ref.finger][ref.link + 1]
            out[self._roll0 + 2 * k: self._roll0 + 2 * k + 2] = self._roll_at(k, a, b, (ox, oy), st)
        out[self._base:] = self.complement.T @ s  # on the line of the analysed direction
        return out

    def function(self, x: Array) -> Array:
        """``F(x)`` ``(rows,)``: sticking rows ``x_b,i(q) - x_o,i(s)``, then the sliding gaps."""
        if self._z_axes is not None and not self.sliding:
            return self._function_planar(x)
        q, s = x[: self.M], x[self.M:]
        pose = self._pose_at(s)
        d = self.dim
        out = np.empty(self.rows)
        for k, (ref, pb, po) in enumerate(self.items):
            xb = pb[:d] if ref is None else self.hand.point_position(ref, pb, q)
            out[d * k: d * k + d] = xb - pose.to_world(po)
        if self.rolls:
            out[self._roll0: self._plane0] = self._rolling_rows(x)
        for k, (_, _, n) in enumerate(self.plane_rolls):  # dp + r n x w: rolling on a plane
            out[self._plane0 + 3 * k: self._plane0 + 3 * k + 3] = s[:3] + self.radius * np.cross(n, s[3:])
        if self.axis_rows.shape[0]:  # a cylinder turns about its axis
            out[self._axis0: self._slide0] = self.axis_rows @ s[3:]
        for k, ref in enumerate(self.sliding):  # S-points: the gap to the disk/sphere is zero
            if k not in self._row_of:
                continue
            row = self._slide0 + self._row_of[k]
            if self.sliding_faces[k] is not None:  # a link on a face: its axis point rho off the plane
                out[row] = self._face_gap(k, q, pose)[0]
                continue
            c = self.sliding_points[k]
            if c is not None:  # an object point on a fixed body: its distance from the surface is zero
                out[row] = self.body_distance(ref, pose.to_world(c), q)[0]
                continue
            out[row] = self.body_distance(ref, pose.position, q)[0] - self.radius
        out[self._base:] = self.complement.T @ s  # on the line of the analysed direction
        return out

    @staticmethod
    def _planar_axes(hand: HandKinematics) -> list[Array] | None:
        """The z-components ``(n,)`` of each finger's joint axes when every finger is a
        :class:`~analysis.kinematics.SerialChain` whose joints all turn about z, exactly (axes
        ``(0, 0, +-1)``, a base rotation about z): its world axes are then ``(0, 0, a_j)`` at every
        configuration and its joints and links stay in the plane ``z = 0``; else None."""
        out = []
        for f in hand.fingers:
            if not isinstance(f, SerialChain):
                return None
            R = f.base_R
            if (np.any(f.axes[:, :2] != 0.0) or not np.all(np.abs(f.axes[:, 2]) == 1.0)
                    or R[2, 2] != 1.0 or np.any(R[2, :2] != 0.0) or np.any(R[:2, 2] != 0.0)
                    or f.base_p[2] != 0.0 or np.any(f.origins[:, 2] != 0.0)):
                return None
            out.append(np.array(f.axes[:, 2], dtype=float))
        return out

    def _add_planar_rows(self, J: Array, ref: BodyRef, q: Array,
                         terms: Sequence[tuple[int, float, float, float, float]]) -> None:
        """For planar serial chains (:meth:`_planar_axes`): add to ``J`` ``(rows, M + D)`` the
        combinations ``g . J(x)`` of the Jacobian columns of world points ``x`` fixed on the body
        ``ref``, each term ``(row, x_x, x_y, g_x, g_y)``. Eq. 1 in the plane: joint ``j`` (axis
        ``a_j z``, at ``p_j``) moves ``x`` by ``a_j (-(x_y - p_j,y), x_x - p_j,x)`` per radian,
        the values :meth:`HandKinematics.point_jacobian` gives (its ``x`` and ``y`` rows)."""
        assert self._z_axes is not None and ref.finger is not None
        f = ref.finger
        off = int(self.hand.offsets[f])
        joints = self._planar_fk(q)[f]
        axes = self._planar_chains[f][4]
        for j in range(ref.link + 1):
            a_j = axes[j]
            px, py = joints[j][0], joints[j][1]
            for row, x, y, gx, gy in terms:
                J[row, off + j] += gx * -(a_j * (y - py)) + gy * (a_j * (x - px))

    def _jacobian_planar(self, x: Array) -> Array:
        """:meth:`jacobian` for planar serial chains (:meth:`_planar_axes`) in float arithmetic: the
        Jacobian columns of the contact points and of the rolling links' axis ends in the plane
        (:meth:`_add_planar_rows`); the sliding rows as :meth:`_sliding_jacobian`."""
        M = self.M
        q, s = x[:M], x[M:]
        pose = self._pose_at(s)
        R = pose.rotation
        J = np.zeros((self.rows, M + self.D))  # (rows, M + 3)
        fk = self._planar_fk(q)
        for k, (ref, pb, po) in enumerate(self.items):
            r = 2 * k
            if ref is not None:
                assert ref.finger is not None
                px, py, co, sn = fk[ref.finger][ref.link]
                bx = px + co * float(pb[0]) - sn * float(pb[1])
                by = py + sn * float(pb[0]) + co * float(pb[1])
                self._add_planar_rows(J, ref, q, ((r, bx, by, 1.0, 0.0), (r + 1, bx, by, 0.0, 1.0)))
            J[r, M] = J[r + 1, M + 1] = -1.0
            y = R[:2, :2] @ po  # object point relative to p_o, world frame
            J[r, M + 2] = y[1]
            J[r + 1, M + 2] = -y[0]
        c = pose.position
        for k, roll in enumerate(self.rolls):
            ref = roll[1]
            assert ref.finger is not None
            a, b = fk[ref.finger][ref.link], fk[ref.finger][ref.link + 1]
            g0, g1 = self._roll_grad_rows(k, a, b, c)  # (7,) each: gap, rolling row
            r = self._roll0 + 2 * k
            ax, ay, bx, by = float(a[0]), float(a[1]), float(b[0]), float(b[1])
            self._add_planar_rows(J, ref, q, ((r, ax, ay, g0[0], g0[1]), (r, bx, by, g0[2], g0[3]),
                                              (r + 1, ax, ay, g1[0], g1[1]), (r + 1, bx, by, g1[2], g1[3])))
            J[r, M: M + 3] = g0[4:7]
            J[r + 1, M: M + 3] = g1[4:7]
        self._sliding_jacobian(J, q, s, pose)
        J[self._base:, M:] = self.complement.T
        return J

    def jacobian(self, x: Array) -> Array:
        """``F'(x)`` ``(rows, M + D)``: ``[J_c, -G^T]`` at ``s = 0``."""
        if self._z_axes is not None:
            return self._jacobian_planar(x)
        q, s = x[: self.M], x[self.M:]
        pose = self._pose_at(s)
        R_d = pose.R_d  # (d, d)
        d = self.dim
        J = np.zeros((self.rows, self.M + self.D))  # (d n, M + D)
        for k, (ref, pb, po) in enumerate(self.items):
            r = slice(d * k, d * k + d)
            if ref is not None:
                J[r, : self.M] = self.hand.point_jacobian(ref, self.hand.point_position(ref, pb, q), q)
            J[r, self.M: self.M + d] = -np.eye(d)
            y = R_d @ po  # object point relative to p_o, world frame
            if d == 2:
                J[r, self.M + 2] = -np.array([-y[1], y[0]])
            else:
                J[r, self.M + 3:] = skew(y) @ _left_jacobian_so3(s[3:])
        if self.rolls:
            J[self._roll0: self._plane0] = self._rolling_jacobian(x)
        for k, (_, _, n) in enumerate(self.plane_rolls):  # [0, I, r [n]x]
            r = slice(self._plane0 + 3 * k, self._plane0 + 3 * k + 3)
            J[r, self.M: self.M + 3] = np.eye(3)
            J[r, self.M + 3:] = self.radius * skew(n)
        if self.axis_rows.shape[0]:
            J[self._axis0: self._slide0, self.M + 3:] = self.axis_rows
        self._sliding_jacobian(J, q, s, pose)
        J[self._base:, self.M:] = self.complement.T
        return J


    def _sliding_jacobian(self, J: Array, q: Array, s: Array, pose: Pose) -> None:
        """The sliding contacts' rows of :meth:`jacobian`, written into ``J`` ``(rows, M + D)``."""
        R_d = pose.R_d  # (d, d)
        d = self.dim
        for k, ref in enumerate(self.sliding):  # d gap = u^T (d p_o - J(y) dq); the centre is p_o
            if k not in self._row_of:
                continue
            row = self._slide0 + self._row_of[k]
            if self.sliding_faces[k] is not None:
                # gap = (R u_o) . (a(q) - p) - h - rho: d gap = u^T J(a) dq - u^T dp + (u x (a - p)) . dphi,
                # dphi = J_l(w) dw the world rotation (2-D: perp(u) . (a - p) dtheta)
                _, u, a = self._face_gap(k, q, pose)
                J[row, : self.M] = u @ self.hand.point_jacobian(ref, a, q)
                J[row, self.M: self.M + d] = -u
                arm = a - pose.position  # (d,)
                if d == 2:
                    J[row, self.M + 2] = -u[1] * arm[0] + u[0] * arm[1]
                else:
                    J[row, self.M + 3:] = (skew(u) @ arm) @ _left_jacobian_so3(s[3:])
                continue
            c = self.sliding_points[k]
            if c is not None:  # d gap = u^T d x_o, x_o = p_o + dp + R(s) c (the body is fixed)
                _, u, _ = self.body_distance(ref, pose.to_world(c), q)
                y = R_d @ c
                J[row, self.M: self.M + d] = u
                if d == 2:
                    J[row, self.M + 2] = u @ np.array([-y[1], y[0]])
                else:
                    J[row, self.M + 3:] = -u @ skew(y) @ _left_jacobian_so3(s[3:])
                continue
            _, u, yb = self.body_distance(ref, pose.position, q)
            if ref.finger is not None:
                J[row, : self.M] = -u @ self.hand.point_jacobian(ref, yb, q)
            J[row, self.M: self.M + d] = u


#: singular values of ``F'`` below this fraction of the largest are taken as zero by the Newton
#: steps of :func:`project_manifold`: redundant rows (the two glued points of a line contact, whose
#: rows along the line repeat each other) leave singular values of round-off size (1e-14 once a
#: motion has moved the points by its own round-off), whose inverses would send a step far along
#: the manifold instead of onto it (LAPACK's default cut-off, 20 eps, keeps them)
PROJECTION_RCOND = 1e-10


def project_manifold(man: ContactManifold, x: Array, tolerance: float = 1e-11, iters: int = 50,
                     progress: tuple[Array, float] | None = None) -> tuple[Array, float]:
    """Newton projection of ``x`` ``(M + D,)`` onto ``F(x) = 0`` with minimum-norm steps (the
    pseudo-inverse of ``F'``, as OMPL's ``ProjectedStateSpace`` projects); returns the point and
    ``|F|`` there. With ``progress = (u, t)`` (``u`` ``(D,)`` unit) the object is also held at
    ``u . s = t``: its progress along the direction stays where the step put it, and the hand
    takes up the correction."""
    x = np.array(x, dtype=float)
    res = 0.0
    M = man.M
    for _ in range(iters):
        F = man.function(x)
        res = float(np.linalg.norm(F))
        if progress is None:
            if res <= tolerance:
                break
            x = x - np.linalg.lstsq(man.jacobian(x), F, rcond=PROJECTION_RCOND)[0]
            continue
        u, t = progress
        gap = float(u @ x[M:]) - t
        if res <= tolerance and abs(gap) <= tolerance:
            break
        J = np.vstack([man.jacobian(x), np.concatenate([np.zeros(M), u])[None, :]])  # (rows + 1, M + D)
        x = x - np.linalg.lstsq(J, np.append(F, gap), rcond=PROJECTION_RCOND)[0]
    return x, res


def pose_displacement(state: GraspState, pose: Array) -> Array:
    """The ambient object coordinates ``s`` ``(D,)`` of :class:`ContactManifold` of a pose vector
    ``(D,)`` (``state.pose.displaced(s)`` is that pose)."""
    if state.dim == 2:  # the angle difference as given (Pose would re-wrap it through a matrix)
        return np.asarray(pose, dtype=float) - state.pose.vector()
    return Pose.from_vector(pose, state.dim).displacement_from(state.pose)

