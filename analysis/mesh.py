"""Convex meshes and the URDF's collision shapes (coal), for the validation (:mod:`analysis.geometry`)
and the detector (:mod:`analysis.detect`): an object of shape ``mesh`` (an STL or OBJ file) and
the URDF's collision meshes are taken as their convex hulls; boxes, spheres, cylinders and
capsules as they are.

A hull is kept with its vertices and its facets ``n_i . x <= h_i`` (unit outward ``n_i``), from
which the signed distance of a point and the normal cone at a boundary point follow exactly:
inside, the distance to the boundary is ``min_i (h_i - n_i . x)``; outside, coal's distance to
the point; the normal cone at ``x`` is spanned by the ``n_i`` whose plane passes within ``tol``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError

#: Mesh files the object shape ``mesh`` takes.
MESH_SUFFIXES = (".stl", ".obj")
#: Facets whose unit normals differ by less than this are one face (a quad as two triangles).
_SAME_NORMAL = 1e-9

__all__ = ["MESH_SUFFIXES", "ConvexHull", "Primitive", "convex_hull", "hull_of", "load_mesh",
           "point_signed_distance", "primitive_of", "resolve_mesh_path", "shape_cone"]


@dataclass(frozen=True)
class ConvexHull:
    """A convex polytope in its own frame: ``vertices`` ``(k, 3)``, facets ``normals`` ``(m, 3)``
    (unit, outward) and ``support`` ``(m,)`` (``n_i . x <= support_i`` inside), and the coal
    geometry ``geom`` (a ``coal.ConvexBase``)."""

    vertices: Array
    normals: Array
    support: Array
    geom: Any

    def signed_distance(self, p: Array) -> float:
        """Signed distance (negative inside) of the point ``p`` ``(3,)`` (hull frame)."""
        p = np.asarray(p, dtype=float)
        gap = self.normals @ p - self.support  # (m,)
        if float(gap.max()) <= 0.0:
            return float(gap.max())
        req = coal.DistanceRequest()
        req.gjk_tolerance = 1e-12
        res = coal.DistanceResult()
        d = coal.distance(self.geom, coal.Transform3s(), coal.Sphere(0.0), coal.Transform3s(np.eye(3), p), req, res)
        return float(d)

    def normal_cone(self, p: Array, tol: float) -> Array:
        """Generators ``(k, 3)`` of the normal cone at ``p`` (hull frame): the distinct outward
        normals of the facets whose plane passes within ``tol`` of ``p``."""
        gap = self.normals @ np.asarray(p, dtype=float) - self.support
        out: list[Array] = []
        for n in self.normals[np.abs(gap) <= tol]:
            if all(float(np.linalg.norm(n - k)) > _SAME_NORMAL for k in out):
                out.append(n)
        return np.array(out).reshape(-1, 3)


def convex_hull(geometry: Any) -> ConvexHull:
    """The convex hull of a coal mesh (a ``BVHModel``) or convex body (``ConvexBase``)."""
    if isinstance(geometry, coal.ConvexBase):
        conv = geometry
    else:
        if getattr(geometry, "convex", None) is None:
            geometry.buildConvexHull(False, "Qt")
        conv = geometry.convex
    V = np.asarray(conv.points(), dtype=float).copy()
    N = np.asarray(conv.normals(), dtype=float).copy()
    h = -np.asarray(conv.offsets(), dtype=float).copy()  # coal's facets: n . x + offset <= 0
    used = np.unique(np.argwhere(np.abs(V @ N.T - h) <= 1e-9)[:, 0])  # hull vertices only
    return ConvexHull(V[used] if len(used) else V, N, h, conv)


def resolve_mesh_path(file: str) -> Path:
    """The mesh file of an object shape: an absolute path, one relative to the current folder,
    ``"example-robot-data:<path inside robots/>"`` or an uploaded robot's
    ``"robot:<sha256>/<path>"``; SceneError at ``object.shape.file`` when it does not exist or is
    not an STL/OBJ file."""
    loc = ("object", "shape", "file")
    if file.startswith(("example-robot-data:", "robot:")):
        from analysis.urdf import resolve_urdf_path  # deferred: pinocchio, for these prefixes only

        try:  # the same containment rules as a URDF file (symbolic links resolved, no server path)
            path = resolve_urdf_path(file)
        except SceneError as e:
            raise SceneError(loc, e.reason.replace("URDF file", "mesh file")) from None
    else:
        path = Path(file).expanduser()
        if not path.is_absolute():
            path = Path.cwd() / path
    if not path.is_file():
        raise SceneError(loc, f"mesh file not found: '{file}'")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise SceneError(loc, f"'{file}' is not a mesh file (STL or OBJ: {', '.join(MESH_SUFFIXES)})")
    return path


@functools.lru_cache(maxsize=32)
def _load(path: str, mtime_ns: int) -> ConvexHull:
    del mtime_ns  # part of the cache key only
    model = coal.MeshLoader().load(path, np.ones(3))
    if model.num_vertices < 4:
        raise ValueError(f"has {model.num_vertices} vertices")
    return convex_hull(model)


def load_mesh(file: str) -> ConvexHull:
    """The convex hull of the mesh file ``file`` (:func:`resolve_mesh_path`), cached; a file that
    is not a readable mesh of a solid is a SceneError at ``object.shape.file``."""
    path = resolve_mesh_path(file)
    try:
        hull = _load(str(path), path.stat().st_mtime_ns)
    except (RuntimeError, ValueError, IndexError) as e:
        why = " ".join(str(e).replace(str(path.parent), "").split())
        why = why.split("message:", 1)[-1].split(" Hint:", 1)[0].strip()
        raise SceneError(("object", "shape", "file"), f"cannot read the mesh '{path.name}': {why or 'not a mesh'}"
                         ) from None
    if len(hull.normals) < 4 or float(np.ptp(hull.vertices, axis=0).min()) <= 0.0:
        raise SceneError(("object", "shape", "file"), f"the mesh '{path.name}' encloses no volume (a flat mesh)")
    return hull


#: Hulls of coal meshes met so far, by the id of the (cached, never freed) coal object.
_HULLS: dict[int, tuple[Any, ConvexHull]] = {}


def hull_of(geometry: Any) -> ConvexHull:
    """:func:`convex_hull` of a coal mesh or convex body, computed once per object."""
    key = id(geometry)
    hit = _HULLS.get(key)
    if hit is None or hit[0] is not geometry:
        hit = (geometry, convex_hull(geometry))
        _HULLS[key] = hit
    return hit[1]


def _is_mesh(geometry: Any) -> bool:
    return isinstance(geometry, coal.ConvexBase) or hasattr(geometry, "buildConvexHull")


def point_signed_distance(geometry: Any, R: Array, t: Array, x: Array) -> float:
    """Signed distance (negative inside) of the world point ``x`` ``(3,)`` to a coal shape placed
    by ``R`` ``(3, 3)``, ``t`` ``(3,)`` (a mesh: its convex hull)."""
    local = np.asarray(R, dtype=float).T @ (np.asarray(x, dtype=float) - np.asarray(t, dtype=float))
    if _is_mesh(geometry):
        return hull_of(geometry).signed_distance(local)
    if isinstance(geometry, coal.Sphere):
        return float(np.linalg.norm(local) - geometry.radius)
    if isinstance(geometry, coal.Box):
        q = np.abs(local) - np.asarray(geometry.halfSide, dtype=float)
        return float(np.linalg.norm(np.maximum(q, 0.0)) + min(float(q.max()), 0.0))
    if isinstance(geometry, coal.Cylinder):
        r = float(np.linalg.norm(local[:2])) - geometry.radius
        z = abs(float(local[2])) - geometry.halfLength
        return float(np.linalg.norm(np.maximum([r, z], 0.0)) + min(max(r, z), 0.0))
    if isinstance(geometry, coal.Capsule):
        z = float(np.clip(local[2], -geometry.halfLength, geometry.halfLength))
        return float(np.linalg.norm(local - np.array([0.0, 0.0, z])) - geometry.radius)
    raise SceneError((), f"collision shape {type(geometry).__name__} is not supported "
                     "(meshes, boxes, spheres, cylinders and capsules are)")


@dataclass(frozen=True)
class Primitive:
    """A collision shape in plain numbers, for engines other than coal (the MuJoCo model,
    :mod:`sim.mjcf`): ``kind`` ``"sphere"`` (``size = (r,)``), ``"box"`` (half sides), ``"cylinder"``
    and ``"capsule"`` (``(r, half length)``, along the shape's own z), or ``"hull"`` (a mesh: the
    ``vertices`` ``(k, 3)`` of its convex hull, :func:`hull_of`), in the shape's own frame."""

    kind: str
    size: tuple[float, ...]
    vertices: Array | None = None


def primitive_of(geometry: Any) -> Primitive:
    """The :class:`Primitive` of a coal shape (a URDF collision object); SceneError for a shape
    the detector does not take (the same shapes as :func:`point_signed_distance`)."""
    if isinstance(geometry, coal.Sphere):
        return Primitive("sphere", (float(geometry.radius),))
    if isinstance(geometry, coal.Box):
        return Primitive("box", tuple(float(h) for h in np.asarray(geometry.halfSide, dtype=float)))
    if isinstance(geometry, coal.Cylinder):
        return Primitive("cylinder", (float(geometry.radius), float(geometry.halfLength)))
    if isinstance(geometry, coal.Capsule):
        return Primitive("capsule", (float(geometry.radius), float(geometry.halfLength)))
    if _is_mesh(geometry):
        return Primitive("hull", (), hull_of(geometry).vertices)
    raise SceneError((), f"collision shape {type(geometry).__name__} is not supported "
                     "(meshes, boxes, spheres, cylinders and capsules are)")


def shape_cone(geometry: Any, R: Array, t: Array, x: Array, tol: float) -> Array:
    """Generators ``(k, 3)`` (world) of the normal cone of a placed coal shape at the boundary
    point ``x``: the outward normals of every face within ``tol`` (a mesh: of its hull)."""
    R = np.asarray(R, dtype=float)
    p = R.T @ (np.asarray(x, dtype=float) - np.asarray(t, dtype=float))
    gens: list[Array] = []
    if _is_mesh(geometry):
        return hull_of(geometry).normal_cone(p, tol) @ R.T
    if isinstance(geometry, coal.Sphere):
        r = float(np.linalg.norm(p))
        gens = [p / r] if r > 0 else []
    elif isinstance(geometry, coal.Box):
        h = np.asarray(geometry.halfSide, dtype=float)
        gens = [np.sign(p[k]) * np.eye(3)[k] for k in range(3) if abs(p[k]) - h[k] >= -tol]
    elif isinstance(geometry, coal.Cylinder):
        rho = float(np.linalg.norm(p[:2]))
        if rho >= geometry.radius - tol and rho > 0:
            gens.append(np.array([p[0] / rho, p[1] / rho, 0.0]))
        if abs(float(p[2])) >= geometry.halfLength - tol:
            gens.append(np.array([0.0, 0.0, np.sign(p[2])]))
    elif isinstance(geometry, coal.Capsule):
        off = p - np.array([0.0, 0.0, float(np.clip(p[2], -geometry.halfLength, geometry.halfLength))])
        r = float(np.linalg.norm(off))
        gens = [off / r] if r > 0 else []
    else:
        point_signed_distance(geometry, R, t, x)  # raises for an unsupported shape
    return np.array(gens).reshape(-1, 3) @ R.T
