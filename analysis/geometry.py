"""Signed distances to the scene's shapes (validation of contact points, collision checks)."""

from __future__ import annotations

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.kinematics import BodyRef, HandKinematics, segment_distance
from analysis.pose import Pose
from analysis.scene import Box, Cylinder, Disk, Polygon, Scene, Segment, Sphere


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

    ``None`` for shapes whose distance is not computed (meshes).
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
    """Signed distance of the world point ``p`` to the object at its scene pose."""
    R = object_rotation(scene)[: scene.dim, : scene.dim]
    local = R.T @ (np.asarray(p, dtype=float) - object_origin(scene))
    return shape_signed_distance(scene.object.shape, local, scene.dim)


def body_surface_distance(scene: Scene, hand: HandKinematics, ref: BodyRef, p: Array) -> float | None:
    """Distance of ``p`` to the surface of a finger link (its axis inflated by the link radius)
    or of a fixed body (given in world coordinates)."""
    if ref.finger is None:
        body = next(b for b in scene.fixed_bodies if b.name == ref.name)
        return shape_signed_distance(body.shape, np.asarray(p, dtype=float), scene.dim)
    a, b = hand.body_segment(ref, hand.q0)
    return segment_distance(np.asarray(p, dtype=float), a, b) - hand.body_radius(ref)


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
    raise SceneError(("object", "shape", "type"), f"no characteristic size for '{shape.type}' objects")
