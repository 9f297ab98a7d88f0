"""Contacts found from the geometry: every place where the object touches a finger link or a
fixed body at the scene's configuration (issue 10, ``"contacts": "auto"`` / ``ctp contacts``).

Geometry (the same model the validation in :mod:`analysis.loader` and the planner's collision
checks use):

* a finger link is the capsule around its axis
  (:meth:`~analysis.kinematics.HandKinematics.body_segment`) of the link's radius (radius 0: the
  bare segment), or, for a URDF finger with ``"link_geometry": "urdf"``, the URDF's own collision
  shapes of the link (:func:`analysis.geometry.link_shapes`: boxes, spheres, cylinders, capsules,
  meshes as their convex hulls); a link of several shapes has the contacts of each;
* a fixed body is its shape in world coordinates (``segment``, ``box`` axis-aligned about its
  ``position``, ``disk``/``sphere`` about the origin, ``polygon``);
* the object is its shape at its pose (``box``, ``sphere``, ``cylinder``, ``mesh`` (its convex
  hull, :mod:`analysis.mesh`) in 3-D; ``disk``, ``box``, ``polygon`` in 2-D).

:func:`link_distances` gives the signed distance of every link to the object and to every fixed
body at any configuration, with the witness point and direction whose product with the point
Jacobian is the distance's gradient: the placement (:mod:`analysis.placement`) and collision
checks use the same geometry. :class:`SceneGeometry` keeps the same coal bodies for many queries
at moving configurations and object poses: the planner's collision checks
(:mod:`planner.collision`) take a URDF link's collision shapes and a mesh object from it.

A 2-D scene lies in the plane ``z = 0``: a disk is the sphere of its radius (its section by the
plane is the disk), a box or polygon the prism over it (``|z| <= PRISM_HALF_HEIGHT``), so the
distance of planar geometry to planar geometry is the planar distance and the witness points
lie in the plane.

coal (hpp-fcl) gives each pair's signed distance ``d`` and witness points ``x_o`` (object) and
``x_b`` (body). A pair with ``d <= tolerance`` touches; one with ``tolerance < d < NEAR_FACTOR *
tolerance`` is a near miss. A penetrating pair (``d < 0``) is a contact of negative gap: the
loader refuses it where it is deeper than the validation's tolerance. At a touching pair the
contact normal ``n`` (into the object) is the object's surface normal at ``x_o`` where the object
is smooth there, else the body's surface normal at ``x_b`` where that is smooth, else the
direction coal reports (an edge across an edge, a vertex on an edge): so ``-n`` lies in the
object's normal cone and ``n`` in the body's.

**Patches.** Let ``F_o`` be the object's support feature facing the body (its points ``x`` with
``-n . x >= max - t``: a vertex, an edge or a face) and ``F_b`` the body's facing the object
(``n . x >= max - t``), for ``t = min(tolerance, FEATURE_TOL)``: a corner of a patch must be on
both surfaces to the validation's accuracy, so an edge tilted off a face by more than that
touches at its lower end only. Projected on the plane perpendicular to ``n`` (the line in
2-D), the contact region is ``proj F_o  ∩  proj F_b``. Where both are at least 1-dimensional
and the intersection is more than a point, the contacts are the corners of that convex region
(a box face on a table: four corners; a box edge along a capsule: the two end points of the
overlap), each lifted back onto ``F_o`` (so on the object's surface, exactly); otherwise the
one contact is ``x_o``. Curved features (a sphere, a capsule's round end, a cylinder's side
away from the axis) are single points; a cylinder's cap (where its rim is level to ``t``) is
taken as the regular ``CAP_SIDES``-gon inscribed in its rim, its side line (where level to ``t``)
as the segment between the rims. A contact that two links of one finger give at the same point
is kept once where one of them has length 0 (a fingertip sphere; see ``_distinct``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
from pydantic import Field

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import body_normal_cone, link_shapes, object_normal_cone, object_pose
from analysis.kinematics import BodyRef, HandKinematics
from analysis.mesh import hull_of, load_mesh
from analysis.scene import Box, Contact, Cylinder, Disk, FixedBody, Mesh, Polygon, Scene, Segment, Sphere

#: Default distance (scene units) within which two surfaces are in contact.
DEFAULT_TOLERANCE = 1e-3
#: Default friction coefficient of a detected contact (when its body names none).
DEFAULT_MU = 0.5
#: Pairs closer than this many tolerances but not touching are near misses.
NEAR_FACTOR = 10.0
#: Half height of the prisms that carry 2-D boxes and polygons (scene units; any positive value
#: gives the same planar distances, as every planar body lies in ``z = 0``).
PRISM_HALF_HEIGHT = 1.0
#: Distance within which a point is on a face, edge or vertex when its normal cone is taken:
#: the validation's ``analysis.loader.GEOMETRY_TOL`` (a test keeps them equal; the loader
#: imports this module, so it cannot be imported here).
FEATURE_TOL = 1e-4
#: Normals of one contact found twice (on two links that meet there) differ by at most this
#: (the validation's ``NORMAL_CONE_TOL``): on a curved object the two witness points may differ
#: by coal's accuracy.
NORMAL_TOL = 1e-3
#: Sides of the polygon inscribed in a cylinder's rim that stands for a flat cap in contact.
CAP_SIDES = 8

__all__ = [
    "DEFAULT_MU",
    "DEFAULT_TOLERANCE",
    "NEAR_FACTOR",
    "DetectedContact",
    "Detection",
    "LinkDistance",
    "NearMiss",
    "SceneGeometry",
    "UnlistedPoints",
    "UnplacedScene",
    "detect_contacts",
    "link_distances",
    "link_refs",
    "unlisted_points",
]


@dataclass(frozen=True)
class DetectedContact:
    """One contact: ``point`` (world, on the object's surface) on ``body``, unit ``normal`` (world,
    into the object), friction ``mu``, and ``gap``, the signed distance of the pair (0 when
    touching exactly, at most the tolerance; negative: the body penetrates the object that deep)."""

    body: str
    point: tuple[float, ...]
    normal: tuple[float, ...]
    mu: float
    gap: float

    def to_json(self) -> dict[str, object]:
        """The contact as a scene's ``contacts`` entry (``gap`` is not part of a scene)."""
        return {"body": self.body, "point": list(self.point), "normal": list(self.normal), "mu": self.mu}


@dataclass(frozen=True)
class NearMiss:
    """A body closer to the object than ``NEAR_FACTOR * tolerance`` but not touching it: its
    ``distance`` and the witness points on the object and on the body."""

    body: str
    distance: float
    object_point: tuple[float, ...]
    body_point: tuple[float, ...]


@dataclass(frozen=True)
class Detection:
    """The contacts found (bodies in scene order: each finger's links, then the fixed bodies) and
    the near misses, for ``tolerance``."""

    contacts: tuple[DetectedContact, ...]
    near_misses: tuple[NearMiss, ...]
    tolerance: float
    #: the body nearest the object and its distance (None: the scene has no bodies)
    nearest: tuple[str, float] | None = None


class UnplacedScene(Scene):
    """A scene whose contacts are still to be found: the scene model with ``contacts`` optional
    (every other field and structural check as :class:`~analysis.scene.Scene`)."""

    contacts: list[Contact] = Field(default_factory=list)


# --------------------------------------------------------------------------------------------
# coal shapes


@dataclass(frozen=True)
class _Solid:
    """A convex body as coal sees it, with what the patch step needs: its kind and, for flat
    features, the data to list them (world coordinates, 3-D)."""

    geom: object  # a coal.CollisionGeometry
    tf: object  # its coal.Transform3s
    kind: str  # "round" (sphere, disk), "capsule", "poly" (box, polygon, prism), "cylinder"
    vertices: Array  # (k, 3) poly: the vertices; capsule: the axis end points
    radius: float = 0.0  # capsule radius; cylinder radius
    axis: Array | None = None  # cylinder: unit axis (world)
    centre: Array | None = None  # cylinder: centre (world)
    half_height: float = 0.0  # cylinder


def _as3(x: Array) -> Array:
    x = np.asarray(x, dtype=float)
    return x if x.shape[0] == 3 else np.array([x[0], x[1], 0.0])


def _frame_to(z: Array) -> Array:
    """A rotation ``(3, 3)`` whose third column is the unit vector ``z``."""
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _capsule(a: Array, b: Array, radius: float) -> _Solid:
    a, b = _as3(a), _as3(b)
    length = float(np.linalg.norm(b - a))
    if length == 0.0:
        return _Solid(coal.Sphere(max(radius, 0.0)), coal.Transform3s(np.eye(3), a), "round", a[None, :])
    tf = coal.Transform3s(_frame_to(b - a), (a + b) / 2.0)
    return _Solid(coal.Capsule(radius, length), tf, "capsule", np.array([a, b]), radius=radius)


def _box_vertices(centre: Array, half: Array) -> Array:
    signs = np.array(np.meshgrid(*([[-1.0, 1.0]] * len(half)), indexing="ij")).reshape(len(half), -1).T
    return centre + signs * half  # (2^d, d)


def _prism(points2: Array) -> _Solid:
    """The prism ``|z| <= PRISM_HALF_HEIGHT`` over a convex planar point set ``(k, 2)`` (world)."""
    pts = coal.StdVec_Vec3s()
    for p in points2:
        for z in (-PRISM_HALF_HEIGHT, PRISM_HALF_HEIGHT):
            pts.append(np.array([p[0], p[1], z]))
    geom = coal.Convex.convexHull(pts, False, "")
    V = np.column_stack([points2, np.zeros(len(points2))])
    return _Solid(geom, coal.Transform3s(), "poly", V)


def _shape_solid(shape: object, R: Array, p: Array, dim: int, where: tuple[str | int, ...]) -> _Solid:
    """The coal body of a scene shape placed by rotation ``R`` ``(3, 3)`` and origin ``p`` ``(3,)``."""
    if isinstance(shape, Disk | Sphere):
        return _Solid(coal.Sphere(shape.radius), coal.Transform3s(R, p), "round", p[None, :])
    if isinstance(shape, Box):
        c = np.zeros(dim) if shape.position is None else np.asarray(shape.position, dtype=float)
        V = _box_vertices(c, np.asarray(shape.size, dtype=float) / 2.0)  # (2^d, d), body frame
        if dim == 2:
            return _prism((R[:2, :2] @ V.T).T + p[:2])
        centre = p + R @ c
        geom = coal.Box(*[float(s) for s in shape.size])
        return _Solid(geom, coal.Transform3s(R, centre), "poly", (R @ V.T).T + p)
    if isinstance(shape, Polygon):
        V = np.asarray(shape.vertices, dtype=float)
        return _prism((R[:2, :2] @ V.T).T + p[:2])
    if isinstance(shape, Cylinder):
        axis = R[:, 2].copy()
        return _Solid(coal.Cylinder(shape.radius, shape.height), coal.Transform3s(R, p), "cylinder",
                      np.zeros((0, 3)), radius=shape.radius, axis=axis, centre=p.copy(),
                      half_height=shape.height / 2.0)
    if isinstance(shape, Segment):
        a, b = (np.asarray(x, dtype=float) for x in shape.points)
        return _capsule(R @ _as3(a) + p, R @ _as3(b) + p, 0.0)
    if isinstance(shape, Mesh):
        hull = load_mesh(shape.file)
        return _Solid(hull.geom, coal.Transform3s(R, p), "poly", (R @ hull.vertices.T).T + p)
    kind = getattr(shape, "type", type(shape).__name__)
    raise SceneError((*where, "type"), f"contacts cannot be detected on '{kind}' shapes "
                     "(box, sphere, cylinder, disk, polygon and segment can)")


def _object_solid(scene: Scene) -> _Solid:
    pose = object_pose(scene)
    return _shape_solid(scene.object.shape, pose.rotation, _as3(pose.position), scene.dim, ("object", "shape"))


def _fixed_solid(body: FixedBody, i: int, dim: int) -> _Solid:
    return _shape_solid(body.shape, np.eye(3), np.zeros(3), dim, ("fixed_bodies", i, "shape"))


# --------------------------------------------------------------------------------------------
# Support features and patches


def _feature(s: _Solid, u: Array, tol: float, witness: Array) -> Array:
    """The points ``(k, 3)`` spanning the support feature of ``s`` in the unit direction ``u``
    (points within ``tol`` of the supporting plane); curved features: the ``witness`` point."""
    if s.kind == "poly":
        h = s.vertices @ u
        return s.vertices[h >= h.max() - tol]
    if s.kind == "capsule":
        h = s.vertices @ u
        return s.vertices[h >= h.max() - tol] + s.radius * u
    if s.kind == "cylinder":
        assert s.axis is not None and s.centre is not None
        c = float(u @ s.axis)
        radial = u - c * s.axis
        rho = float(np.linalg.norm(radial))
        if 2.0 * s.radius * rho <= tol:  # the cap is flat to ``tol`` across its diameter
            cap = s.centre + np.sign(c) * s.half_height * s.axis
            E = _frame_to(s.axis)[:, :2]
            ang = 2.0 * np.pi * np.arange(CAP_SIDES) / CAP_SIDES
            return cap + s.radius * (np.cos(ang)[:, None] * E[:, 0] + np.sin(ang)[:, None] * E[:, 1])
        if 2.0 * s.half_height * abs(c) <= tol and rho > 0:  # the side line, flat to ``tol`` along its length
            side = s.centre + s.radius * radial / rho
            return np.array([side - s.half_height * s.axis, side + s.half_height * s.axis])
    return witness[None, :]


def _tangent_basis(n: Array, dim: int) -> Array:
    """Orthonormal basis ``(dim - 1, 3)`` of the directions perpendicular to ``n`` (2-D: in the
    plane)."""
    if dim == 2:
        return np.array([[-n[1], n[0], 0.0]])
    return _frame_to(n)[:, :2].T


def _affine_rank(P: Array, tol: float) -> int:
    if len(P) <= 1:
        return 0
    sv = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    return int(np.sum(sv > tol))


def _convex_hull_2d(P: Array) -> Array:
    """Counter-clockwise hull ``(k, 2)`` of points ``(m, 2)`` (monotone chain)."""
    pts = sorted({(float(x), float(y)) for x, y in P})
    if len(pts) <= 2:
        return np.array(pts)

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple[float, float]] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _clip(subject: Array, clip: Array) -> Array:
    """Sutherland-Hodgman: the convex polygon ``subject`` ``(k, 2)`` (or a segment, ``k = 2``)
    cut by the counter-clockwise convex polygon ``clip`` ``(m, 2)``."""
    out = [tuple(p) for p in subject]
    closed = len(subject) > 2
    for i in range(len(clip)):
        a, b = clip[i], clip[(i + 1) % len(clip)]
        e = b - a

        def inside(p: tuple[float, ...], a: Array = a, e: Array = e) -> bool:
            return float(e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])) >= -1e-12

        def cut(p: tuple[float, ...], q: tuple[float, ...], a: Array = a, e: Array = e) -> tuple[float, ...]:
            sp = e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])
            sq = e[0] * (q[1] - a[1]) - e[1] * (q[0] - a[0])
            t = sp / (sp - sq)
            return (p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]))

        src, out = out, []
        if not src:
            break
        n_edges = len(src) if closed else len(src) - 1
        if not closed and len(src) == 2:
            p, q = src
            ip, iq = inside(p), inside(q)
            if ip and iq:
                out = [p, q]
            elif ip:
                out = [p, cut(p, q)]
            elif iq:
                out = [cut(p, q), q]
            continue
        for j in range(n_edges):
            p, q = src[j], src[(j + 1) % len(src)]
            if inside(q):
                if not inside(p):
                    out.append(cut(p, q))
                out.append(q)
            elif inside(p):
                out.append(cut(p, q))
    return np.array(out).reshape(-1, 2)


def _patch_2d(A: Array, B: Array, tol: float) -> Array:
    """Corners ``(k, 2)`` of ``conv A ∩ conv B`` for planar point sets of affine rank >= 1."""
    ra, rb = _affine_rank(A, tol), _affine_rank(B, tol)
    if ra == 1 and rb == 1:  # two segments: their overlap if collinear, else a crossing point
        pa = _segment_ends(A)
        pb = _segment_ends(B)
        e = (pa[1] - pa[0]) / np.linalg.norm(pa[1] - pa[0])
        off = float(abs(e[0] * (pb[0][1] - pa[0][1]) - e[1] * (pb[0][0] - pa[0][0])))
        off1 = float(abs(e[0] * (pb[1][1] - pa[0][1]) - e[1] * (pb[1][0] - pa[0][0])))
        if max(off, off1) > tol:
            return np.zeros((0, 2))
        ta, tb = sorted(float((p - pa[0]) @ e) for p in pa), sorted(float((p - pa[0]) @ e) for p in pb)
        lo, hi = max(ta[0], tb[0]), min(ta[1], tb[1])
        if hi < lo:
            return np.zeros((0, 2))
        return np.array([pa[0] + lo * e, pa[0] + hi * e])
    if ra == 1:
        return _clip(_segment_ends(A), _convex_hull_2d(B))
    if rb == 1:
        return _clip(_segment_ends(B), _convex_hull_2d(A))
    return _clip(_convex_hull_2d(A), _convex_hull_2d(B))


def _segment_ends(P: Array) -> Array:
    """The two extreme points ``(2, m)`` of a (nearly) collinear point set."""
    c = P.mean(axis=0)
    _, _, Vt = np.linalg.svd(P - c)
    t = (P - c) @ Vt[0]
    return np.array([P[int(np.argmin(t))], P[int(np.argmax(t))]])


def _lift(F: Array, T: Array, t: Array) -> Array:
    """The point of the flat feature ``F`` ``(k, 3)`` whose tangent coordinates ``F @ T.T`` are
    ``t`` ``(dim-1,)``: the affine map from the tangent coordinates to 3-D fitted on ``F`` (exact
    on a planar face or a straight edge)."""
    coords = F @ T.T  # (k, dim-1)
    X = np.column_stack([coords, np.ones(len(F))])
    coef, *_ = np.linalg.lstsq(X, F, rcond=None)  # (dim, 3)
    return np.append(t, 1.0) @ coef


def _patch_points(obj: _Solid, body: _Solid, n: Array, u_o: Array, u_b: Array, x_o: Array, tol: float,
                  dim: int) -> list[Array]:
    """The contact points (on the object) of a touching pair with normal ``n`` into the object;
    the features are those facing ``u_o`` (the object's) and ``u_b`` (the body's)."""
    F_o = _feature(obj, u_o, tol, x_o)
    F_b = _feature(body, u_b, tol, x_o)
    T = _tangent_basis(n, dim)  # (dim-1, 3)
    A, B = F_o @ T.T, F_b @ T.T  # tangent coordinates
    if dim == 2:
        A, B = A[:, 0], B[:, 0]
        if np.ptp(A) <= tol or np.ptp(B) <= tol:
            return [x_o]
        lo, hi = max(A.min(), B.min()), min(A.max(), B.max())
        if hi - lo <= tol:
            return [x_o]
        return [_lift(F_o, T, np.array([lo])), _lift(F_o, T, np.array([hi]))]
    if _affine_rank(A, tol) == 0 or _affine_rank(B, tol) == 0:
        return [x_o]
    corners = _patch_2d(A, B, tol)
    if len(corners) == 0 or _affine_rank(corners, tol) == 0:
        return [x_o]
    keep: list[Array] = []
    for c in corners:
        if all(np.linalg.norm(c - k) > tol for k in keep):
            keep.append(c)
    if len(keep) > 2:  # drop corners on a straight run between their neighbours
        hull = _convex_hull_2d(np.array(keep))
        keep = list(hull)
    return [_lift(F_o, T, c) for c in keep]


# --------------------------------------------------------------------------------------------
# Detection


def _distance(obj: _Solid, body: _Solid) -> tuple[float, Array, Array, Array]:
    """coal's distance (signed: negative when penetrating), the witness points on the object and
    on the body, and the unit direction from the object to the body."""
    req = coal.DistanceRequest()
    req.gjk_tolerance = 1e-12
    req.enable_signed_distance = True
    res = coal.DistanceResult()
    d = coal.distance(obj.geom, obj.tf, body.geom, body.tf, req, res)
    x_o = np.asarray(res.getNearestPoint1(), dtype=float).copy()
    x_b = np.asarray(res.getNearestPoint2(), dtype=float).copy()
    u = np.asarray(res.normal, dtype=float).copy()
    return float(d), x_o, x_b, u


def _contact_normal(scene: Scene, hand: HandKinematics, ref: BodyRef, x_o: Array, x_b: Array,
                    coal_u: Array, dim: int) -> tuple[Array, Array, Array]:
    """Unit normal ``n`` ``(3,)`` into the object: the object's surface normal where it is smooth,
    else the body's, else coal's direction (see the module docstring); and the outward normals
    ``(3,)`` of the object's and of the body's own surfaces where each is smooth (else ``-n``,
    ``n``), which pick their flat features: two faces a hair's breadth from parallel are each
    taken whole, not by the other's slightly tilted normal (a table a metre wide would lose one
    side for a tilt of 1e-4)."""
    n: Array | None = None
    u_o: Array | None = None
    u_b: Array | None = None
    cone = object_normal_cone(scene, x_o[:dim], FEATURE_TOL)
    if cone is not None and cone.generators.shape[0] == 1:
        u_o = _as3(cone.generators[0])
        n = -u_o
    cone = body_normal_cone(scene, hand, ref, x_b[:dim], FEATURE_TOL)
    if cone is not None and cone.generators.shape[0] == 1:
        u_b = _as3(cone.generators[0])
        n = u_b if n is None else n
    if n is None:
        n = -coal_u
        if dim == 2:
            n[2] = 0.0
        n = n / np.linalg.norm(n)
    return n, -n if u_o is None else u_o, n if u_b is None else u_b


def link_refs(scene: Scene, hand: HandKinematics) -> list[BodyRef]:
    """Every finger link of the hand, in scene order (each finger's links from the root)."""
    out: list[BodyRef] = []
    for i, model in enumerate(hand.fingers):
        for name in model.body_names():
            ref = hand.resolve_body(name)
            assert ref is not None and ref.finger == i
            out.append(ref)
    return out


def _coal_solid(geom: object, R: Array, t: Array) -> _Solid:
    """A URDF collision shape placed in the world (a mesh: its convex hull)."""
    tf = coal.Transform3s(R, t)
    if isinstance(geom, coal.Sphere):
        return _Solid(geom, tf, "round", t[None, :])
    if isinstance(geom, coal.Box):
        V = _box_vertices(np.zeros(3), np.asarray(geom.halfSide, dtype=float))
        return _Solid(geom, tf, "poly", (R @ V.T).T + t)
    if isinstance(geom, coal.Cylinder):
        return _Solid(geom, tf, "cylinder", np.zeros((0, 3)), radius=float(geom.radius), axis=R[:, 2].copy(),
                      centre=t.copy(), half_height=float(geom.halfLength))
    if isinstance(geom, coal.Capsule):
        e = float(geom.halfLength) * R[:, 2]
        return _Solid(geom, tf, "capsule", np.array([t - e, t + e]), radius=float(geom.radius))
    hull = hull_of(geom)  # a mesh or convex body; other shapes: SceneError from analysis.mesh
    return _Solid(hull.geom, tf, "poly", (R @ hull.vertices.T).T + t)


def _link_solids(hand: HandKinematics, ref: BodyRef, q: Array) -> list[_Solid]:
    """The link's geometry at ``q``: its capsule, or its URDF collision shapes."""
    shapes = link_shapes(hand, ref, q)
    if shapes is not None:
        return [_coal_solid(g, np.asarray(R, dtype=float), np.asarray(t, dtype=float)) for g, R, t in shapes]
    a, b = hand.body_segment(ref, q)
    return [_capsule(a, b, hand.body_radius(ref))]


def _body_solids(scene: Scene, hand: HandKinematics, q: Array) -> list[tuple[BodyRef, list[_Solid], float | None]]:
    """Every body a contact can lie on, in scene order, at the configuration ``q`` ``(M,)``, with
    its coal bodies and friction (None: the default)."""
    out: list[tuple[BodyRef, list[_Solid], float | None]] = []
    for ref in link_refs(scene, hand):
        assert ref.finger is not None
        out.append((ref, _link_solids(hand, ref, q), scene.fingers[ref.finger].mu))
    for i, fb in enumerate(scene.fixed_bodies):
        out.append((BodyRef(name=fb.name), [_fixed_solid(fb, i, scene.dim)], fb.mu))
    return out


@dataclass(frozen=True)
class LinkDistance:
    """The signed distance ``distance`` (negative: penetration) of a finger link to ``target``
    (``"object"`` or a fixed body's name) at a configuration, the witness point ``link_point``
    ``(3,)`` on the link and the unit direction ``direction`` ``(3,)`` from the target to the link:
    the derivative of the distance in the joints is ``direction @ J(link_point)`` (the link's
    point Jacobian) wherever the nearest features do not switch."""

    link: BodyRef
    target: str
    distance: float
    link_point: Array
    direction: Array


def link_distances(scene: Scene, hand: HandKinematics, q: Array,
                   links: list[BodyRef] | None = None) -> list[LinkDistance]:
    """For each finger link (``links``, default every link in scene order) at the configuration
    ``q`` ``(M,)``: its signed distance to the object and to every fixed body, with witness point
    and direction (see :class:`LinkDistance`). The geometry is the detector's (and the
    validation's): the link's capsule, the object and fixed bodies as their shapes."""
    obj = _object_solid(scene)
    fixed = [(fb.name, _fixed_solid(fb, i, scene.dim)) for i, fb in enumerate(scene.fixed_bodies)]
    out: list[LinkDistance] = []
    for ref in link_refs(scene, hand) if links is None else links:
        solids = _link_solids(hand, ref, q)
        if not solids:
            continue
        for name, target in [("object", obj), *fixed]:
            d, _, x_b, u = min((_distance(target, solid) for solid in solids), key=lambda r: r[0])
            if scene.dim == 2:
                x_b[2] = u[2] = 0.0
            nu = float(np.linalg.norm(u))
            out.append(LinkDistance(ref, name, d, x_b, u / nu if nu > 0 else u))
    return out


# --------------------------------------------------------------------------------------------
# Repeated distance queries (the planner's collision checks)

#: A body placed in the world as coal takes it: ``(coal geometry, coal.Transform3s)``.
Placed = tuple[Any, Any]


class SceneGeometry:
    """The detector's geometry of a scene, for many signed-distance queries at moving
    configurations and object poses (the planner's collision checks, :mod:`planner.collision`).

    Every body is what :func:`link_distances` and :func:`detect_contacts` take it to be: a URDF
    link with ``"link_geometry": "urdf"`` its collision shapes (a mesh: its convex hull,
    :func:`analysis.mesh.hull_of`), any other link the capsule about its axis (of a radius the
    caller chooses: the planner takes the bare axis, radius 0, and subtracts its own capsule
    radius), the object its shape (a mesh: its hull) at any pose, a fixed body its shape. The
    coal geometries are built once; a query only places them (a link: its pose at ``q``, one
    forward-kinematics evaluation; the object: ``(R, p) * T_local``) and calls coal's signed
    distance (GJK, EPA when penetrating, ``gjk_tolerance = 1e-12``)."""

    def __init__(self, scene: Scene, hand: HandKinematics):
        self.scene = scene
        self.hand = hand
        self._req = coal.DistanceRequest()
        self._req.gjk_tolerance = 1e-12
        self._req.enable_signed_distance = True
        obj = _shape_solid(scene.object.shape, np.eye(3), np.zeros(3), scene.dim, ("object", "shape"))
        tf: Any = obj.tf
        self._object_local = (obj.geom, np.array(tf.getRotation(), dtype=float),
                              np.array(tf.getTranslation(), dtype=float))
        self.fixed: list[Placed] = [(s.geom, s.tf) for s in
                                    (_fixed_solid(fb, i, scene.dim) for i, fb in enumerate(scene.fixed_bodies))]
        self._local: dict[tuple[int, int], list[tuple[Any, Array, Array]] | None] = {}

    def local_shapes(self, finger: int, link: int) -> list[tuple[Any, Array, Array]] | None:
        """The URDF collision shapes of a link in its own frame, ``(coal geometry, R (3, 3), t (3,))``
        (a mesh replaced by its convex hull, as the detector takes it); ``None``: a capsule link."""
        key = (finger, link)
        if key not in self._local:
            shapes = getattr(self.hand.fingers[finger], "collision_shapes", None)
            local = None if shapes is None else shapes(link)
            if local is not None:
                local = [(g if isinstance(g, coal.Sphere | coal.Box | coal.Cylinder | coal.Capsule)
                          else hull_of(g).geom, np.asarray(R, dtype=float), np.asarray(t, dtype=float))
                         for g, R, t in local]
            self._local[key] = local
        return self._local[key]

    def has_shapes(self, finger: int) -> bool:
        """Whether the finger's links are URDF collision shapes (``"link_geometry": "urdf"``)."""
        return self.local_shapes(finger, 0) is not None

    def link_bodies(self, ref: BodyRef, q: Array, radius: float = 0.0) -> list[Placed]:
        """The link ``ref`` at the hand configuration ``q`` ``(M,)``: its URDF shapes placed by the
        link's pose, or its capsule of ``radius`` about :meth:`HandKinematics.body_segment`."""
        assert ref.finger is not None and ref.link is not None
        local = self.local_shapes(ref.finger, int(ref.link))
        if local is None:
            a, b = self.hand.body_segment(ref, q)
            s = _capsule(a, b, radius)
            return [(s.geom, s.tf)]
        R_l, p_l = self.hand.body_pose(ref, q)
        R_l, p_l = np.asarray(R_l, dtype=float), _as3(p_l)
        return [(g, coal.Transform3s(R_l @ R, p_l + R_l @ t)) for g, R, t in local]

    def segment_body(self, a: Array, b: Array, radius: float = 0.0) -> Placed:
        """The capsule of ``radius`` about the segment ``[a, b]`` (world, ``(dim,)``)."""
        s = _capsule(a, b, radius)
        return (s.geom, s.tf)

    def object_at(self, position: Array, rotation: Array) -> Placed:
        """The object at the pose ``position`` ``(dim,)``, ``rotation`` ``(3, 3)``."""
        g, R0, t0 = self._object_local
        R = np.asarray(rotation, dtype=float)
        return (g, coal.Transform3s(R @ R0, _as3(position) + R @ t0))

    def distance(self, a: Sequence[Placed], b: Sequence[Placed]) -> float:
        """Smallest signed distance (negative: penetration depth) between the bodies ``a`` and
        ``b`` (each a union of placed convex shapes); ``inf`` when either is empty. A fresh
        ``DistanceResult`` per pair: coal keeps the smaller of a reused result's distance and the
        new one for convex hulls (a stale penetration would be reported)."""
        best = np.inf
        for ga, ta in a:
            for gb, tb in b:
                best = min(best, float(coal.distance(ga, ta, gb, tb, self._req, coal.DistanceResult())))
        return float(best)


def _clean(v: Array) -> tuple[float, ...]:
    """Components as floats, round-off below 1e-15 (and -0.0) written as 0."""
    return tuple(0.0 if abs(float(x)) < 1e-15 else float(x) for x in v)


def detect_contacts(scene: Scene, *, tolerance: float = DEFAULT_TOLERANCE, mu: float = DEFAULT_MU) -> Detection:
    """Every contact between the object and the fixed bodies and finger links of ``scene`` at its
    configuration ``q`` (the scene's own ``contacts`` are ignored), within ``tolerance``, and the
    near misses (see the module docstring). A body's ``mu`` field, where given, overrides
    ``mu``. SceneError for a non-positive tolerance, a negative ``mu``, or a mesh file that is
    missing or not a mesh (at ``object.shape.file``)."""
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise SceneError(("tolerance",), f"must be a positive number (got {tolerance})")
    if not (np.isfinite(mu) and mu >= 0):
        raise SceneError(("mu",), f"must be a non-negative number (got {mu})")
    dim = scene.dim
    hand = HandKinematics.from_scene(scene)
    obj = _object_solid(scene)
    contacts: list[DetectedContact] = []
    near: list[NearMiss] = []
    nearest: tuple[str, float] | None = None
    for ref, solids, body_mu in _body_solids(scene, hand, hand.q0):
        for solid in solids:
            d, x_o, x_b, u = _distance(obj, solid)
            if nearest is None or d < nearest[1]:
                nearest = (ref.name, d)
            if d > tolerance:
                if d < NEAR_FACTOR * tolerance:
                    near.append(NearMiss(ref.name, d, tuple(float(v) for v in x_o[:dim]),
                                         tuple(float(v) for v in x_b[:dim])))
                continue
            if dim == 2:
                x_o[2] = x_b[2] = 0.0
            n, u_o, u_b = _contact_normal(scene, hand, ref, x_o, x_b, u, dim)
            for p in _patch_points(obj, solid, n, u_o, u_b, x_o, min(tolerance, FEATURE_TOL), dim):
                contacts.append(DetectedContact(
                    body=ref.name, point=_clean(p[:dim]), normal=_clean(n[:dim]),
                    mu=float(mu if body_mu is None else body_mu), gap=d))
    near = _nearest_misses(near, {c.body for c in contacts})
    return Detection(tuple(_distinct(contacts, hand)), tuple(near), float(tolerance), nearest)


def _nearest_misses(near: list[NearMiss], touching: set[str]) -> list[NearMiss]:
    """One near miss per body (its nearest shape), none for a body that touches elsewhere."""
    best: dict[str, NearMiss] = {}
    for m in near:
        if m.body not in touching and (m.body not in best or m.distance < best[m.body].distance):
            best[m.body] = m
    return [m for m in near if best.get(m.body) is m]


def _distinct(contacts: list[DetectedContact], hand: HandKinematics) -> list[DetectedContact]:
    """The contacts without the repeats that a link of length 0 makes: such a link (a fingertip
    link, a wrist link between coinciding joint origins) is the sphere at the end of the link
    before it, so where links of one finger give the same point (within ``FEATURE_TOL``) with the
    same normal and one of them has length 0, the contact is kept once, on that link (the first
    such). Links of positive length that share the sphere about their joint keep their contacts
    (a line contact across the joint)."""

    def point_link(body: str) -> bool:
        ref = hand.resolve_body(body)
        if ref is None or ref.finger is None:
            return False
        a, b = hand.body_segment(ref, hand.q0)
        return bool(np.linalg.norm(np.asarray(b) - np.asarray(a)) == 0.0)

    def same(c: DetectedContact, k: DetectedContact) -> bool:
        return (k.body != c.body and hand.finger_of(k.body) is not None
                and hand.finger_of(k.body) == hand.finger_of(c.body)
                and float(np.linalg.norm(np.subtract(k.point, c.point))) <= FEATURE_TOL
                and float(np.linalg.norm(np.subtract(k.normal, c.normal))) <= NORMAL_TOL)

    out: list[DetectedContact] = []
    for i, c in enumerate(contacts):
        group = [k for k in contacts if same(c, k)]
        points = [k for k in [*group, c] if point_link(k.body)]
        if group and points:
            first = min(points, key=contacts.index)
            if contacts.index(first) != i:
                continue
        out.append(c)
    return out


@dataclass(frozen=True)
class UnlistedPoints:
    """A body that touches the object along a line or a patch (``found`` points, the detector's
    end points or corners, ``extent`` apart at most) of which the scene lists fewer (``listed``,
    at least one)."""

    body: str
    listed: int
    found: int
    extent: float

    def describe(self) -> str:
        kind, ends, size = ("line", "end points", "long") if self.found == 2 else ("patch", "corners", "across")
        them = "them as point contacts" if self.listed > 1 else "it as a point contact"
        return (f"{self.body} lies on the object along a {kind} {self.extent:.3g} {size} ({self.found} {ends}) "
                f"but the scene lists {self.listed} point{'s' if self.listed > 1 else ''} of it: the analysis takes "
                f"{them}, about which the object may turn where the flat contact does not let it (in MuJoCo, "
                f"on a robot); 'ctp contacts' lists the {kind}'s {ends}")


def unlisted_points(scene: Scene, tolerance: float = FEATURE_TOL) -> tuple[UnlistedPoints, ...]:
    """The bodies whose contact with the object at the scene's configuration is a line or a patch
    (:func:`detect_contacts` within ``tolerance``, default the validation's accuracy) while the
    scene lists fewer of its points: a link lying flat on a face given as one point (Baxter's
    forearms in examples/baxter_hug_box.json; examples/baxter_hug_box_lines.json lists both end
    points). Bodies the scene lists no contact on are not reported (the scene may leave them out)."""
    det = detect_contacts(scene, tolerance=tolerance)
    listed: dict[str, int] = {}
    hand = HandKinematics.from_scene(scene)
    for c in scene.contacts:
        ref = hand.resolve_body(c.body)
        name = c.body if ref is None else ref.name
        listed[name] = listed.get(name, 0) + 1
    points: dict[str, list[Array]] = {}
    for dc in det.contacts:
        points.setdefault(dc.body, []).append(np.asarray(dc.point, dtype=float))
    out = []
    for body, pts in points.items():
        n = listed.get(body, 0)
        if 0 < n < len(pts) and len(pts) >= 2:
            P = np.array(pts)  # (k, d)
            extent = float(np.max(np.linalg.norm(P[:, None, :] - P[None, :, :], axis=2)))
            out.append(UnlistedPoints(body, n, len(pts), extent))
    return tuple(out)
