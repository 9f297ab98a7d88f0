"""Signed distances to the scene's shapes (validation of contact points, collision checks) and
their normal cones (validation of contact normals at faces, edges and vertices).

The normal cone of a convex body ``K`` at a boundary point ``p`` is
``N_K(p) = {g : g^T (x - p) <= 0 for all x in K}``: one ray where the surface is smooth (a sphere,
a capsule, a box face), the cone of the adjacent faces' outward normals at an edge or a vertex
(a box corner: three axes; a polygon corner: two edge normals; a cylinder rim: the radial
direction and the axis). A contact normal ``n`` (into the object) is valid where
``-n in N_object(p)`` and ``n in N_body(p)``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.kinematics import BodyRef, HandKinematics, segment_distance
from analysis.mesh import load_mesh, point_signed_distance, shape_cone
from analysis.pose import Pose
from analysis.scene import Box, Cylinder, Disk, Mesh, Polygon, Scene, Segment, Sphere


def object_pose(scene: Scene) -> Pose:
    """The object's pose at the scene's configuration: ``p_o`` and its rotation."""
    pose = scene.object.pose
    return Pose.from_fields(pose.position, scene.dim, angle=pose.angle, quat_wxyz=pose.quat_wxyz)


def object_rotation(scene: Scene) -> Array:
    """World rotation ``(3, 3)`` of the object frame."""
    return object_pose(scene).rotation


def object_origin(scene: Scene) -> Array:
    """``p_o``: where the external wrench acts, ``(d,)``."""
    return object_pose(scene).position


def shape_signed_distance(shape: object, p_local: Array, dim: int) -> float | None:
    """Signed distance (negative inside) of a point given in the shape's frame.

    ``None`` for a mesh (it needs its file: :func:`object_signed_distance` reads it).
    """
    p = np.asarray(p_local, dtype=float)[:dim]
    if isinstance(shape, Disk | Sphere):
        return float(np.linalg.norm(p) - shape.radius)
    if isinstance(shape, Box):
        c = np.asarray(shape.position if shape.position is not None else np.zeros(dim), dtype=float)
        return float(box_signed_distance(p, c, np.asarray(shape.size, dtype=float) / 2.0))
    if isinstance(shape, Polygon):
        V = np.asarray(shape.vertices, dtype=float)
        worst = -np.inf
        for i in range(len(V)):
            a, b = V[i], V[(i + 1) % len(V)]
            e = b - a
            n_out = np.array([e[1], -e[0]]) / np.linalg.norm(e)  # outward for CCW polygons
            worst = max(worst, float(n_out @ (p - a)))
        if worst > 0:
            return min(segment_distance(p, V[i], V[(i + 1) % len(V)]) for i in range(len(V)))
        return worst
    if isinstance(shape, Cylinder):
        r = float(np.linalg.norm(p[:2])) - shape.radius
        z = abs(float(p[2])) - shape.height / 2.0
        return float(np.linalg.norm(np.maximum([r, z], 0.0)) + min(max(r, z), 0.0))
    if isinstance(shape, Segment):
        a, b = (np.asarray(x, dtype=float) for x in shape.points)
        return segment_distance(p, a, b)
    return None


def box_signed_distance(P: Array, center: Array, half_extents: Array) -> Array:
    """Signed distances ``(...)`` (negative inside) of points ``P`` ``(..., d)``, in the box's
    frame, to the axis-aligned box of centre ``center`` ``(d,)`` and half-extents ``half_extents``
    ``(d,)``: ``|max(q, 0)| + min(max_k q_k, 0)`` with ``q = |P - center| - half_extents``."""
    q = np.abs(P - center) - half_extents  # (..., d)
    out = np.maximum(q, 0.0)
    return np.sqrt((out * out).sum(axis=-1)) + np.minimum(q.max(axis=-1), 0.0)


def object_signed_distance(scene: Scene, p: Array) -> float | None:
    """Signed distance of the world point ``p`` to the object at its scene pose (a mesh: its
    convex hull, :mod:`analysis.mesh`)."""
    R = object_rotation(scene)[: scene.dim, : scene.dim]
    local = R.T @ (np.asarray(p, dtype=float) - object_origin(scene))
    if isinstance(scene.object.shape, Mesh):  # its convex hull (SceneError for a bad file)
        return load_mesh(scene.object.shape.file).signed_distance(local)
    return shape_signed_distance(scene.object.shape, local, scene.dim)


def link_shapes(hand: HandKinematics, ref: BodyRef, q: Array) -> list[tuple[object, Array, Array]] | None:
    """The URDF collision shapes of a finger link placed in the world at ``q``, as ``(coal shape,
    R (3, 3), t (3,))``; ``None`` where the link is a capsule (its finger's ``link_geometry``)."""
    if ref.finger is None:
        return None
    shapes = getattr(hand.fingers[ref.finger], "collision_shapes", None)
    local = None if shapes is None else shapes(ref.link)
    if local is None:
        return None
    R_l, p_l = hand.body_pose(ref, q)
    return [(g, R_l @ R, p_l + R_l @ t) for g, R, t in local]


def _nearest_shape(shapes: list[tuple[object, Array, Array]], x: Array) -> tuple[float, int]:
    d = [point_signed_distance(g, R, t, x) for g, R, t in shapes]
    k = int(np.argmin(d))
    return float(d[k]), k


def body_surface_distance(scene: Scene, hand: HandKinematics, ref: BodyRef, p: Array) -> float | None:
    """Distance of ``p`` to the surface of a finger link (its axis inflated by the link radius, or
    its URDF collision shapes: the nearest of them) or of a fixed body (given in world
    coordinates). ``None`` for a URDF link without collision shapes."""
    if ref.finger is None:
        body = next(b for b in scene.fixed_bodies if b.name == ref.name)
        return shape_signed_distance(body.shape, np.asarray(p, dtype=float), scene.dim)
    shapes = link_shapes(hand, ref, hand.q0)
    if shapes is not None:
        return _nearest_shape(shapes, np.asarray(p, dtype=float))[0] if shapes else None
    a, b = hand.body_segment(ref, hand.q0)
    return segment_distance(np.asarray(p, dtype=float), a, b) - hand.body_radius(ref)


@dataclass(frozen=True)
class NormalCone:
    """The cone ``{G^T c : c >= 0}`` spanned by the unit outward normals ``generators`` ``(k, d)``
    of the faces that meet at a boundary point (``k = 0``: the point is on no face)."""

    generators: Array  # (k, d)

    def distance(self, u: Array) -> float:
        """Euclidean distance ``|u - proj_N(u)|`` of ``u`` ``(d,)`` to the cone.

        The projection lies in the relative interior of a face spanned by some subset ``S`` of
        the generators, where it is the least-squares fit of ``u`` by ``G_S`` with ``c_S >= 0``; so
        the distance is the least residual over the subsets whose fit is non-negative (exact;
        ``k <= 6`` here, so at most 63 solves of size ``d x |S|``)."""
        u = np.asarray(u, dtype=float)
        best = float(np.linalg.norm(u))  # the empty face: proj = 0
        G = self.generators
        for size in range(1, G.shape[0] + 1):
            for S in itertools.combinations(range(G.shape[0]), size):
                GS = G[list(S)].T  # (d, |S|)
                c, *_ = np.linalg.lstsq(GS, u, rcond=None)
                if np.all(c >= -1e-12):
                    best = min(best, float(np.linalg.norm(u - GS @ np.maximum(c, 0.0))))
        return best

    def contains(self, u: Array, tol: float) -> bool:
        """Whether the unit vector ``u`` is within ``tol`` (the sine of an angle) of the cone.

        The distance is the smallest residual over the faces (:meth:`distance`); the rays, and the
        planes spanned by two pairs of opposite rays (a bare segment's perpendiculars, whose cone is
        that plane: the subset of the two rays on the side of ``u`` fits it with non-negative
        coefficients), and the half-space of such a plane with rays on one side of it (a segment's
        end), bound the distance from above, so a residual to one of them within ``tol`` (less a
        rounding margin) answers yes without the enumeration of every subset."""
        u = np.asarray(u, dtype=float)
        G = self.generators
        if G.shape[0]:
            along = G @ u  # (k,)
            ray = np.sqrt(np.maximum(0.0, float(u @ u) - np.maximum(along, 0.0) ** 2))  # (k,) residual to each ray
            if float(ray.min()) <= tol - 1e-12:
                return True
            opposite = [(i, j) for i, j in itertools.combinations(range(G.shape[0]), 2)
                        if float(G[i] @ G[j]) < -1.0 + 1e-12]
            for (i, i2), (k, k2) in itertools.combinations(opposite, 2):  # two lines: a plane
                B = np.linalg.qr(np.stack([G[i], G[k]], axis=1))[0]  # (d, 2) orthonormal basis
                if float(np.linalg.norm(u - B @ (B.T @ u))) <= tol - 1e-12:
                    return True
                if G.shape[1] == 3:  # the plane and rays all on one side of it: that half-space
                    n = np.cross(B[:, 0], B[:, 1])  # (3,) unit normal of the plane
                    side = np.delete(G, [i, i2, k, k2], axis=0) @ n
                    one_side = len(side) and (np.all(side > 1e-12) or np.all(side < -1e-12))
                    if one_side and max(0.0, -float(u @ n) * float(np.sign(side[0]))) <= tol - 1e-12:
                        return True
        return self.distance(u) <= tol


def _unit(v: Array) -> Array:
    return v / np.linalg.norm(v)


def _perpendiculars(e: Array) -> Array:
    """Orthonormal basis ``(d-1, d)`` of the complement of the unit vector ``e``."""
    if e.shape[0] == 2:
        return np.array([[-e[1], e[0]]])
    _, _, Vt = np.linalg.svd(e[None, :])
    return Vt[1:]  # (2, 3)


def segment_normal_cone(p: Array, a: Array, b: Array, radius: float, tol: float) -> NormalCone:
    """Normal cone at ``p`` of the segment ``[a, b]`` inflated by ``radius`` (a link's capsule).

    ``radius > tol``: the capsule is smooth, one ray ``(p - q) / |p - q|`` from the closest axis
    point ``q``. Otherwise the bare segment: the complement of its direction ``e`` at an interior
    point (``+-`` each perpendicular), plus ``-e`` within ``tol`` of ``a`` and ``+e`` within ``tol``
    of ``b``."""
    p, a, b = (np.asarray(x, dtype=float) for x in (p, a, b))
    ab = b - a
    length = float(np.linalg.norm(ab))
    t = float(np.clip((p - a) @ ab / length**2, 0.0, 1.0)) if length > 0 else 0.0
    off = p - (a + t * ab)
    if radius > tol and float(np.linalg.norm(off)) > 0:
        return NormalCone(_unit(off)[None, :])
    if length == 0:  # a point: every direction
        E = np.eye(p.shape[0])
        return NormalCone(np.vstack([E, -E]))
    e = ab / length
    P = _perpendiculars(e)
    gens = [*P, *(-P)]
    if t * length <= tol:
        gens.append(-e)
    if (1.0 - t) * length <= tol:
        gens.append(e)
    return NormalCone(np.array(gens))


def shape_normal_cone(shape: object, p_local: Array, dim: int, tol: float) -> NormalCone | None:
    """Normal cone of a shape at ``p_local`` (its frame) ``(d,)``: the outward normals of every
    face, edge or vertex feature within ``tol`` of the point (so a point within ``tol`` of an edge
    has the edge's cone). ``None`` for a mesh (:func:`object_normal_cone` reads its file)."""
    p = np.asarray(p_local, dtype=float)[:dim]
    if isinstance(shape, Disk | Sphere):
        r = float(np.linalg.norm(p))
        return NormalCone((p / r)[None, :] if r > 0 else np.zeros((0, dim)))
    if isinstance(shape, Box):
        c = np.asarray(shape.position if shape.position is not None else np.zeros(dim), dtype=float)
        q = np.abs(p - c) - np.asarray(shape.size, dtype=float) / 2.0  # (d,) > -tol on the faces at p
        faces = [np.sign(p[k] - c[k]) * np.eye(dim)[k] for k in range(dim) if q[k] >= -tol]
        return NormalCone(np.array(faces).reshape(-1, dim))
    if isinstance(shape, Polygon):
        V = np.asarray(shape.vertices, dtype=float)
        gens = []
        for i in range(len(V)):
            a, b = V[i], V[(i + 1) % len(V)]
            if segment_distance(p, a, b) <= tol:
                e = _unit(b - a)
                gens.append(np.array([e[1], -e[0]]))  # outward for CCW polygons
        return NormalCone(np.array(gens).reshape(-1, 2))
    if isinstance(shape, Cylinder):
        rho = float(np.linalg.norm(p[:2]))
        gens = []
        if rho >= shape.radius - tol and rho > 0:
            gens.append(np.array([p[0] / rho, p[1] / rho, 0.0]))
        if abs(float(p[2])) >= shape.height / 2.0 - tol:
            gens.append(np.array([0.0, 0.0, np.sign(p[2])]))
        return NormalCone(np.array(gens).reshape(-1, 3))
    if isinstance(shape, Segment):
        a, b = (np.asarray(x, dtype=float) for x in shape.points)
        return segment_normal_cone(p, a, b, 0.0, tol)
    return None


def object_normal_cone(scene: Scene, p: Array, tol: float) -> NormalCone | None:
    """Normal cone of the object at the world point ``p``, in world coordinates."""
    R = object_rotation(scene)[: scene.dim, : scene.dim]
    local = R.T @ (np.asarray(p, dtype=float) - object_origin(scene))
    if isinstance(scene.object.shape, Mesh):
        return NormalCone(load_mesh(scene.object.shape.file).normal_cone(local, tol) @ R.T)
    cone = shape_normal_cone(scene.object.shape, local, scene.dim, tol)
    return None if cone is None else NormalCone(cone.generators @ R.T)


def body_normal_cone(scene: Scene, hand: HandKinematics, ref: BodyRef, p: Array, tol: float) -> NormalCone | None:
    """Normal cone at ``p`` of a fixed body (given in world coordinates) or of a finger link (its
    axis inflated by the link radius, or the nearest of its URDF collision shapes), in world
    coordinates."""
    if ref.finger is None:
        body = next(b for b in scene.fixed_bodies if b.name == ref.name)
        return shape_normal_cone(body.shape, np.asarray(p, dtype=float), scene.dim, tol)
    shapes = link_shapes(hand, ref, hand.q0)
    if shapes is not None:
        if not shapes:
            return None
        x = np.asarray(p, dtype=float)
        _, k = _nearest_shape(shapes, x)
        return NormalCone(shape_cone(*shapes[k], x, tol))
    a, b = hand.body_segment(ref, hand.q0)
    return segment_normal_cone(np.asarray(p, dtype=float), a, b, hand.body_radius(ref), tol)


def object_size(scene: Scene) -> float:
    """Characteristic size ``s`` of the object (radius, half-diagonal, ...), scene units."""
    shape = scene.object.shape
    if isinstance(shape, Disk | Sphere):
        return float(shape.radius)
    if isinstance(shape, Box):
        return 0.5 * float(np.linalg.norm(shape.size))
    if isinstance(shape, Polygon):
        return float(np.max(np.linalg.norm(np.asarray(shape.vertices, dtype=float), axis=1)))
    if isinstance(shape, Cylinder):
        return float(max(shape.radius, 0.5 * shape.height))
    if isinstance(shape, Mesh):  # half the diagonal of the hull's bounding box
        return 0.5 * float(np.linalg.norm(np.ptp(load_mesh(shape.file).vertices, axis=0)))
    raise SceneError(("object", "shape", "type"), f"no characteristic size for '{shape.type}' objects")
