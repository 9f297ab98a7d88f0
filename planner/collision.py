"""Collision model of the hand (capsules, or the real geometry) and its Lipschitz clearance
certificate.

* **Capsules.** Every finger link is a capsule around its
  :meth:`~analysis.kinematics.HandKinematics.body_segment` of radius
  ``max(link radius, min_radius)`` (``min_radius``: 1 % of the object size by default, as scene
  links may have radius 0). A configuration of a moving finger is valid when none of its capsules
  penetrates the object, a fixed body (palm, table: link 0 is trimmed near its base joint, which
  is mounted on the palm) or a link of another finger, and its non-adjacent links keep apart.
  Distances to disks and spheres are exact; to boxes and polygons they are evaluated at points
  along the link at most ``min_radius`` apart (so the error is below ``min_radius / 2``, and
  the capsule radius is inflated by that amount; for boxes the signed distance is convex along a
  segment, so 17 coarse samples bracket its minimum and only that bracket is sampled finely). A
  link starting at its finger's base joint is not checked against fixed bodies over its first
  ``BASE_TRIM`` (15 %) of length (the joint is mounted on the palm), and a link that already
  overlaps a fixed body in the scene as given is taken to be mounted on it and not checked
  against fixed bodies. :meth:`CollisionModel.clearance_terms` evaluates every (link, obstacle)
  pair of a finger at once with numpy (segment-segment, segment-sphere and segment-box distances
  vectorised over the pairs).
* **Planar capsule fingers in float arithmetic.** In a planar scene whose fingers are all serial
  chains turning about z, with a disk object and fixed segments or disks, a finger's clearance at
  one configuration (and at up to :data:`PLANAR_ROWS` at once) is evaluated with plain floats
  (:meth:`CollisionModel._planar_min`): the same terms, formulas, trims and allowances as the
  numpy evaluation, without numpy's per-call overhead on arrays of two or three links; equal to
  it to round-off (the disk's distance is taken about its centre, without the object's rotation).
* **Overlaps at the start of a motion.** A grasp given by the scene may have capsules that
  overlap slightly (the Allegro example: the middle and ring links 0.3 mm into the object with
  the inflated radius, two non-adjacent thumb links 3 mm into each other, because the link
  radius is a coarse stand-in for the real geometry). Every motion (retreat, transfer, object
  motion, and the certificate of :func:`path_clearance_certified`) takes the overlaps present at
  its first configuration as an allowance (:meth:`CollisionModel.start_allowance`, per pair):
  such a pair may keep its overlap or reduce it but never deepen it; every other pair must stay
  collision-free as before. Without overlaps at the start the check is unchanged.
* **The object against the fixed bodies.** :meth:`CollisionModel.object_clearance` is the
  smallest signed distance of the object at a pose to the fixed bodies (an object motion must
  not push it into the palm or the table). Exact where one of the two is a disk or a sphere
  (the distance of its centre minus its radius); between two polytopes (boxes, polygons,
  segments; a cylinder by its rims) the smaller of the signed distances of each one's vertices
  and edge points, at most ``sample_step`` apart, to the other: a penetration is missed only
  where an edge crosses the other body over less than ``sample_step``.
* **Real geometry (issue 10).** A finger with ``"link_geometry": "urdf"`` is checked with the
  URDF's own collision shapes (boxes, spheres, cylinders, capsules, meshes as their convex hulls)
  and an object of shape ``mesh`` with its convex hull: the geometry of the contact detector and
  the scene validation (:class:`analysis.detect.SceneGeometry`, coal's signed distance, exact up
  to GJK's ``1e-12``). Every link has a *core* and a radius, and a clearance is the core's signed
  distance minus the radii: a URDF link's core is the union of its shapes (the last chain link
  also carries the links fixed beyond it, a fingertip) with radius 0, not inflated and not
  trimmed at its base (the real geometry, so a link resting on a fixed body at the start is
  ``mounted`` as before); a capsule link's core is its axis with the capsule radius above. Every
  pair where a URDF core or a mesh object takes part goes through coal; every other pair keeps
  the capsule formulas above unchanged (a capsule scene is checked exactly as before, at the same
  cost). A mesh object against the fixed bodies (:meth:`CollisionModel.object_clearance`) is
  coal's distance of its hull too. Where two bodies overlap, coal's signed distance is the
  penetration depth (the shortest translation that separates them, EPA), the capsule formulas'
  the depth of the deepest point: both are negative exactly when the bodies overlap, and an
  allowance at the start of a motion is compared with the same pair's own measure. The
  Lipschitz bound of a URDF finger covers its shapes' farthest points.
* **Certificate.** :func:`path_clearance_certified` checks a joint-space polyline, every
  configuration and not only samples: the clearance at a checked configuration bounds how far the
  joints may move (``|dx| <= K |dq|``, :meth:`CollisionModel.lipschitz`) before a capsule can
  touch, never stepping less than :data:`DENSE_STEP` where the clearance is tiny.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.detect import Placed, SceneGeometry
from analysis.geometry import box_signed_distance, object_size, shape_signed_distance
from analysis.kinematics import BodyRef, HandKinematics, SerialChain, segment_distance
from analysis.rotations import skew
from analysis.scene import Box, Cylinder, Disk, Mesh, Polygon, Scene, Segment, Sphere

#: Joint-space step (rad) of the dense collision check: 1 mm of joint motion.
DENSE_STEP = 1e-3
#: Depth (scene units) below which the object is not said to penetrate a fixed body: the contact
#: manifold is followed to ``1e-6`` (the residual checked along an object motion).
PENETRATION_TOL = 1e-6
#: Fraction of a link starting at the finger's base joint that is not checked against fixed bodies
#: (the joint housing is mounted on the palm).
BASE_TRIM = 0.15
_EYE3 = np.eye(3)
#: Up to this many configurations at once, a planar capsule finger's clearances are evaluated one
#: at a time in float arithmetic (:meth:`CollisionModel._planar_min`), beyond it vectorised with numpy.
PLANAR_ROWS = 24


# --------------------------------------------------------------------------------------------
# Distances


def segment_segment_distance(a0: Array, a1: Array, b0: Array, b1: Array) -> float:
    """Distance between the segments ``[a0, a1]`` and ``[b0, b1]`` (any dimension)."""
    d1, d2, r = a1 - a0, b1 - b0, a0 - b0
    a, e, f = float(d1 @ d1), float(d2 @ d2), float(d2 @ r)
    if a <= 1e-15 and e <= 1e-15:
        return float(np.linalg.norm(r))
    if a <= 1e-15:
        s, t = 0.0, float(np.clip(f / e, 0.0, 1.0))
    else:
        c = float(d1 @ r)
        if e <= 1e-15:
            t, s = 0.0, float(np.clip(-c / a, 0.0, 1.0))
        else:
            b = float(d1 @ d2)
            den = a * e - b * b
            s = float(np.clip((b * f - c * e) / den, 0.0, 1.0)) if den > 1e-15 else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t, s = 0.0, float(np.clip(-c / a, 0.0, 1.0))
            elif t > 1.0:
                t, s = 1.0, float(np.clip((b - c) / a, 0.0, 1.0))
    return float(np.linalg.norm((a0 + s * d1) - (b0 + t * d2)))

def _shape_segment_distance(shape: object, a: Array, b: Array, dim: int, step: float) -> float:
    """Signed distance from the segment ``[a, b]`` (shape frame) to a shape."""
    if isinstance(shape, Disk | Sphere):
        return segment_distance(np.zeros(dim), a[:dim], b[:dim]) - shape.radius
    if isinstance(shape, Segment):
        p0, p1 = (np.asarray(p, float) for p in shape.points)
        return segment_segment_distance(a[:dim], b[:dim], p0, p1)
    n = max(2, int(np.ceil(float(np.linalg.norm(b - a)) / step)) + 1)
    if isinstance(shape, Box):  # vectorised box distance at the samples
        c = np.asarray(shape.position if shape.position is not None else np.zeros(dim), dtype=float)
        h = np.asarray(shape.size, dtype=float) / 2.0
        P = a[:dim] + np.linspace(0.0, 1.0, n)[:, None] * (b[:dim] - a[:dim])  # (n, dim)
        return float(box_signed_distance(P, c, h).min())
    best = np.inf
    for t in np.linspace(0.0, 1.0, n):
        sd = shape_signed_distance(shape, a + t * (b - a), dim)
        if sd is not None:
            best = min(best, sd)
    return float(best)


def segment_segment_distances(A0: Array, A1: Array, B0: Array, B1: Array) -> Array:
    """Distances ``(N,)`` between the segments ``[A0[i], A1[i]]`` and ``[B0[i], B1[i]]``
    (arrays ``(N, dim)``): :func:`segment_segment_distance` vectorised over the pairs."""
    d1, d2, r = A1 - A0, B1 - B0, A0 - B0
    a = (d1 * d1).sum(axis=1)
    e = (d2 * d2).sum(axis=1)
    f = (d2 * r).sum(axis=1)
    c = (d1 * r).sum(axis=1)
    b = (d1 * d2).sum(axis=1)
    a_s = np.where(a > 1e-15, a, 1.0)  # a point A: c = b = 0, the formulas below give s = 0
    e_ok = e > 1e-15
    e_s = np.where(e_ok, e, 1.0)
    den = a * e - b * b
    big = den > 1e-15
    s = np.where(big, np.minimum(np.maximum((b * f - c * e) / np.where(big, den, 1.0), 0.0), 1.0), 0.0)
    t = (b * s + f) / e_s
    s = np.where(t < 0.0, np.minimum(np.maximum(-c / a_s, 0.0), 1.0),
                 np.where(t > 1.0, np.minimum(np.maximum((b - c) / a_s, 0.0), 1.0), s))
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    s = np.where(e_ok, s, np.minimum(np.maximum(-c / a_s, 0.0), 1.0))  # a point B
    t = np.where(e_ok, t, 0.0)
    diff = (A0 + s[:, None] * d1) - (B0 + t[:, None] * d2)
    return np.sqrt((diff * diff).sum(axis=1))


def _shape_segments_distance(shape: object, A: Array, B: Array, dim: int, step: float,
                             length: float | None = None) -> Array:
    """Signed distances ``(N,)`` from the segments ``[A[i], B[i]]`` (shape frame, ``(N, dim)``)
    to a shape: :func:`_shape_segment_distance` vectorised over the segments (boxes: sampled at
    most ``step`` apart along every segment, the sample count from ``length``, by default the
    longest segment)."""
    if isinstance(shape, Disk | Sphere):
        ab = B - A
        L2 = np.einsum("ij,ij->i", ab, ab)
        pos = L2 > 0.0
        # clip to [0, 1] and the norm along axis 1, as np.clip and np.linalg.norm compute them
        t = np.minimum(np.maximum(-np.einsum("ij,ij->i", A, ab) / np.where(pos, L2, 1.0), 0.0), 1.0)
        t = np.where(pos, t, 0.0)
        v = A + t[:, None] * ab
        return np.sqrt((v * v).sum(axis=1)) - shape.radius
    if isinstance(shape, Segment):
        p0, p1 = (np.broadcast_to(np.asarray(p, float)[:dim], A.shape) for p in shape.points)
        return segment_segment_distances(A, B, p0, p1)
    if isinstance(shape, Box):
        c = np.asarray(shape.position if shape.position is not None else np.zeros(dim), dtype=float)[:dim]
        h = np.asarray(shape.size, dtype=float)[:dim] / 2.0
        return _box_segments_distance(c, h, A, B, step, length=length)
    return np.array([_shape_segment_distance(shape, a, b, dim, step) for a, b in zip(A, B, strict=True)])


def shape_signed_distances(shape: object, P: Array, dim: int) -> Array:
    """Signed distances ``(k,)`` (negative inside) of the points ``P`` ``(k, dim)``, in the shape's
    frame (:func:`analysis.geometry.shape_signed_distance`, vectorised for disks, spheres, boxes
    and segments); ``inf`` for shapes without a distance (meshes)."""
    P = np.asarray(P, dtype=float)[:, :dim]
    # clip to [0, 1] and the norm along axis 1 as np.clip and np.linalg.norm compute them (the same
    # values: max then min, the square root of the sum of squares), without their call overhead
    if isinstance(shape, Disk | Sphere):
        return np.sqrt((P * P).sum(axis=1)) - shape.radius
    if isinstance(shape, Box):
        c = np.asarray(shape.position if shape.position is not None else np.zeros(dim), dtype=float)[:dim]
        return np.asarray(box_signed_distance(P, c, np.asarray(shape.size, dtype=float)[:dim] / 2.0))
    if isinstance(shape, Segment):
        a, b = (np.asarray(x, dtype=float)[:dim] for x in shape.points)
        e = b - a
        t = np.minimum(np.maximum((P - a) @ e / max(float(e @ e), 1e-300), 0.0), 1.0)
        V = P - (a + t[:, None] * e)
        return np.sqrt((V * V).sum(axis=1))
    out = [shape_signed_distance(shape, p, dim) for p in P]
    return np.array([np.inf if v is None else v for v in out], dtype=float)


def shape_boundary_samples(shape: object, dim: int, step: float) -> Array | None:
    """Points ``(k, dim)`` of a polytope-like shape, in its frame: its vertices and points of its
    edges at most ``step`` apart (boxes, polygons, segments; a cylinder: its two rims). ``None``
    for disks and spheres (their distances are exact from the centre) and meshes."""
    def edge_points(a: Array, b: Array) -> Array:
        n = max(2, int(np.ceil(float(np.linalg.norm(b - a)) / step)) + 1)
        return a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)

    if isinstance(shape, Box):
        c = np.asarray(shape.position if shape.position is not None else np.zeros(dim), dtype=float)[:dim]
        h = np.asarray(shape.size, dtype=float)[:dim] / 2.0
        signs = np.array(list(itertools.product((-1.0, 1.0), repeat=dim)))  # (2^d, d)
        V = c + signs * h
        edges = [edge_points(V[i], V[j]) for i in range(len(V)) for j in range(i + 1, len(V))
                 if int(np.sum(signs[i] != signs[j])) == 1]
        return np.vstack(edges)
    if isinstance(shape, Polygon):
        V = np.asarray(shape.vertices, dtype=float)
        return np.vstack([edge_points(V[i], V[(i + 1) % len(V)]) for i in range(len(V))])
    if isinstance(shape, Segment):
        a, b = (np.asarray(x, dtype=float)[:dim] for x in shape.points)
        return edge_points(a, b)
    if isinstance(shape, Cylinder):
        n = max(8, int(np.ceil(2.0 * np.pi * shape.radius / step)))
        ang = 2.0 * np.pi * np.arange(n) / n
        ring = np.column_stack([shape.radius * np.cos(ang), shape.radius * np.sin(ang)])
        hh = shape.height / 2.0
        return np.vstack([np.column_stack([ring, np.full(n, -hh)]), np.column_stack([ring, np.full(n, hh)])])
    return None


@functools.lru_cache(maxsize=256)
def _unit_samples(n: int) -> Array:
    """``linspace(0, 1, n)`` (cached; never modified)."""
    return np.linspace(0.0, 1.0, n)


def _box_segments_distance(c: Array, h: Array, A: Array, B: Array, step: float, coarse: int = 17,
                           length: float | None = None) -> Array:
    """Signed distances ``(N,)`` from the segments ``[A[i], B[i]]`` to the box of centre ``c`` and
    half-extents ``h``, sampled at most ``step`` apart near the minimum. The signed distance to a
    convex set is convex along a segment, so its minimum lies within one coarse interval of the
    best of ``coarse`` evenly spaced samples; only those two intervals are sampled finely."""
    D = B - A
    L = float(length) if length is not None else float(np.sqrt((D * D).sum(axis=1).max())) if len(A) else 0.0
    n = max(2, int(np.ceil(L / step)) + 1)
    if n <= 2 * coarse:  # short segments: sample them whole
        T = _unit_samples(n)
        return box_signed_distance(A[:, None, :] + T[None, :, None] * D[:, None, :], c, h).min(axis=1)
    T = _unit_samples(coarse)
    k = box_signed_distance(A[:, None, :] + T[None, :, None] * D[:, None, :], c, h).argmin(axis=1)
    lo, hi = T[np.maximum(k - 1, 0)], T[np.minimum(k + 1, coarse - 1)]
    nf = max(2, int(np.ceil(2.0 * L / (coarse - 1) / step)) + 1)
    tf = lo[:, None] + _unit_samples(nf)[None, :] * (hi - lo)[:, None]  # (N, nf)
    return box_signed_distance(A[:, None, :] + tf[:, :, None] * D[:, None, :], c, h).min(axis=1)



def _trimmed_at_base(A: Array, B: Array, base: Array, r_infl: Array) -> tuple[Array, Array]:
    """The link segments ``A -> B`` ``(n, 3)`` checked against fixed bodies: a segment that starts
    at its finger's base (mounted on a body) starts ``max(3 r_infl, BASE_TRIM L)`` further along
    it; ``skip`` ``(n,)`` where that trims the whole segment. Returns ``(A2 (n, 3), skip (n,))``."""
    D = B - A
    L = np.sqrt((D * D).sum(axis=1))
    Ab = A - base
    at_base = (Ab * Ab).sum(axis=1) < 1e-18
    trim = np.maximum(3.0 * r_infl, BASE_TRIM * L)
    skip = at_base & (2.0 * trim >= L)
    A2 = np.where(at_base[:, None], A + D * (trim / np.where(L > 0, L, 1.0))[:, None], A)
    return A2, skip


# --------------------------------------------------------------------------------------------
# Planar capsule fingers in float arithmetic (one configuration at a time)


def _segment_distance_f(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> float:
    """Distance from the point ``(cx, cy)`` to the segment ``[(ax, ay), (bx, by)]`` in float
    arithmetic: the formula of :func:`_shape_segments_distance` for a disk (the segment's point
    nearest to the centre, ``t`` clipped to ``[0, 1]``)."""
    ux, uy = ax - cx, ay - cy
    dx, dy = bx - ax, by - ay
    L2 = dx * dx + dy * dy
    t = 0.0
    if L2 > 0.0:
        t = min(max(-(ux * dx + uy * dy) / L2, 0.0), 1.0)
    vx, vy = ux + t * dx, uy + t * dy
    return math.sqrt(vx * vx + vy * vy)


def _segment_segment_distance_f(a0x: float, a0y: float, a1x: float, a1y: float,
                                b0x: float, b0y: float, b1x: float, b1y: float) -> float:
    """:func:`segment_segment_distances` of one planar pair in float arithmetic (the same
    formulas and the same cases: a segment of squared length at most ``1e-15`` is a point)."""
    d1x, d1y, d2x, d2y = a1x - a0x, a1y - a0y, b1x - b0x, b1y - b0y
    rx, ry = a0x - b0x, a0y - b0y
    a = d1x * d1x + d1y * d1y
    e = d2x * d2x + d2y * d2y
    f = d2x * rx + d2y * ry
    c = d1x * rx + d1y * ry
    b = d1x * d2x + d1y * d2y
    a_s = a if a > 1e-15 else 1.0
    if e > 1e-15:
        den = a * e - b * b
        s = min(max((b * f - c * e) / den, 0.0), 1.0) if den > 1e-15 else 0.0
        t = (b * s + f) / e
        if t < 0.0:
            s, t = min(max(-c / a_s, 0.0), 1.0), 0.0
        elif t > 1.0:
            s, t = min(max((b - c) / a_s, 0.0), 1.0), 1.0
    else:  # a point B
        s, t = min(max(-c / a_s, 0.0), 1.0), 0.0
    wx = (a0x + s * d1x) - (b0x + t * d2x)
    wy = (a0y + s * d1y) - (b0y + t * d2y)
    return math.sqrt(wx * wx + wy * wy)


def _planar_points(chain: tuple[float, float, float, list[tuple[float, float]], list[float]],
                   qf: Sequence[float]) -> list[tuple[float, float]]:
    """The joints' positions and the tip ``(n + 1)`` of a planar serial chain (base angle, first
    joint's position, link vectors, axis signs) at its joint values ``qf``: link ``k`` runs from
    point ``k`` to point ``k + 1`` at the world angle ``theta_base + sum_{i <= k} a_i q_i``."""
    theta, px, py, links, axes = chain
    pts = [(px, py)]
    for j, (vx, vy) in enumerate(links):
        theta += axes[j] * qf[j]
        c, s = math.cos(theta), math.sin(theta)
        px, py = px + c * vx - s * vy, py + s * vx + c * vy
        pts.append((px, py))
    return pts


def _planar_chain(chain: object) -> tuple[float, float, float, list[tuple[float, float]], list[float]] | None:
    """A serial chain whose joints all turn about z in the plane ``z = 0`` (axes ``(0, 0, +-1)``,
    a base rotation about z, as :meth:`planner.manifold.ContactManifold._planar_axes` asks): its
    base angle, first joint's position, link vectors (joint to joint, the last to the tip) and
    axis signs; else None."""
    if not isinstance(chain, SerialChain):
        return None
    R = chain.base_R
    if (np.any(chain.axes[:, :2] != 0.0) or not np.all(np.abs(chain.axes[:, 2]) == 1.0)
            or R[2, 2] != 1.0 or np.any(R[2, :2] != 0.0) or np.any(R[:2, 2] != 0.0)
            or chain.base_p[2] != 0.0 or np.any(chain.origins[:, 2] != 0.0) or chain.tip[2] != 0.0):
        return None
    p0 = chain.base_p + R @ chain.origins[0]  # (3,)
    links = [(float(o[0]), float(o[1])) for o in (*chain.origins[1:], chain.tip)]
    return (float(np.arctan2(R[1, 0], R[0, 0])), float(p0[0]), float(p0[1]), links,
            [float(a) for a in chain.axes[:, 2]])


@dataclass(frozen=True)
class _PlanarFinger:
    """Static data of a planar capsule finger for :meth:`CollisionModel._planar_min` (plain floats)."""

    chain: tuple[float, float, float, list[tuple[float, float]], list[float]]  # see _planar_points
    others: list[int]  # the fingers checked against this one, in _FingerData.stacked order
    other_chains: list[tuple[float, float, float, list[tuple[float, float]], list[float]]]  # theirs
    r_infl: list[float]  # (n,)
    r_true: list[float]  # (n,)
    fixed_checked: list[bool]  # (n,)
    base: tuple[float, float]  # the base joint's position (as _FingerData.base)
    #: (i, j, pair_radii, pair_half) of every pair of _FingerData.pairs, in its order
    pairs: list[tuple[int, int, float, float]]
    #: the fixed bodies: ("segment", p0x, p0y, p1x, p1y) or ("disk", radius) (about the origin)
    fixed: list[tuple[Any, ...]]
    object_radius: float  # the disk object's radius


@dataclass(frozen=True)
class _FingerData:
    """Static data of one finger for the vectorised clearance."""

    refs: list[BodyRef]
    r_infl: Array  # (n,) capsule radii (inflated by half the sample step)
    r_true: Array  # (n,) true link radii
    fixed_checked: Array  # (n,) bool: the link is checked against fixed bodies (not mounted)
    any_fixed: bool  # some link is checked against fixed bodies
    base: Array  # (dim,) base joint position
    pairs: Array  # (p, 2) own non-adjacent link pairs, then (own link, link of another checked finger)
    pair_radii: Array  # (p,) sum of the capsule radii of each pair
    #: (p,) half the sum of the link lengths of each pair, less 1e-9 of each (at q0; links are rigid)
    pair_half: Array
    rot_K: list[tuple[Array, Array]] | None  # serial chains: (K, K @ K) of every joint axis
    urdf: bool  # the links are URDF collision shapes (coal), radius 0
    coal_object: bool  # the object distances through coal (URDF links, or a mesh object)
    coal_pairs: Array  # (p_c,) indices of the pairs where a URDF core takes part (coal)
    stacked: list[BodyRef]  # the stacked links of ``pairs``: own, then the other checked fingers'


@dataclass(frozen=True)
class CollisionModel:
    """Collision model of the hand against the object, the fixed bodies and the other fingers:
    capsules, or the URDF's collision shapes and a mesh object's hull (see the module notes)."""

    scene: Scene
    hand: HandKinematics
    min_radius: float
    sample_step: float
    finger_pairs: frozenset[tuple[int, int]]  # (i, j), i < j: pairs of fingers checked against each other
    mounted: frozenset[tuple[int, int]]  # (finger, link) overlapping a fixed body in the scene: not checked
    _cache: dict[Any, Any] = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def of(cls, scene: Scene, hand: HandKinematics, min_radius: float | None = None) -> CollisionModel:
        """The model of a scene. Fingers whose capsules already overlap in the scene as given are
        taken to move in different layers (a planar hand's fingers stacked in depth, as in the
        paper's Fig. 1) and are not checked against each other; all other pairs are."""
        r = 0.01 * object_size(scene) if min_radius is None else min_radius
        everyone = frozenset((i, j) for i in range(len(hand.fingers)) for j in range(i + 1, len(hand.fingers)))
        model = cls(scene, hand, r, r, everyone, frozenset())
        apart = frozenset((i, j) for (i, j) in everyone if model.fingers_distance(i, j, hand.q0) >= 0.0)
        mounted = frozenset(
            (f, k) for f in range(len(hand.fingers)) for k, (a, b) in model.segments(f, hand.q0).items()
            if scene.fixed_bodies and model._fixed_clearance(f, k, a, b) < 0.0
        )
        return cls(scene, hand, r, r, apart, mounted)

    def object_clearance(self, position: Array, rotation: Array) -> float:
        """Smallest signed distance (negative: penetration) of the object at the pose (``position``
        ``(d,)``, ``rotation`` ``(3, 3)``) to the fixed bodies; ``inf`` without fixed bodies (see the
        module notes for the polytope case)."""
        d = self.scene.dim
        shape = self.scene.object.shape
        R = np.asarray(rotation, dtype=float)[:d, :d]
        pos = np.asarray(position, dtype=float)[:d]
        best = np.inf
        if isinstance(shape, Mesh):  # its convex hull against each body (coal)
            if not self.scene.fixed_bodies:
                return float(best)
            geo = self.geometry
            return geo.distance([geo.object_at(position, rotation)], geo.fixed)
        own = self._boundary("object", shape)
        for k, fb in enumerate(self.scene.fixed_bodies):
            if isinstance(shape, Disk | Sphere):  # exact: the centre's distance minus the radius
                best = min(best, float(shape_signed_distances(fb.shape, pos[None, :], d)[0]) - shape.radius)
                continue
            if isinstance(fb.shape, Disk | Sphere):  # fixed disks and spheres are about the origin
                local = (-pos) @ R
                best = min(best, float(shape_signed_distances(shape, local[None, :], d)[0]) - fb.shape.radius)
                continue
            if own is not None:  # the object's vertices and edges against the body
                best = min(best, float(shape_signed_distances(fb.shape, own @ R.T + pos, d).min()))
            theirs = self._boundary(("fixed", k), fb.shape)
            if theirs is not None:  # the body's vertices and edges against the object
                best = min(best, float(shape_signed_distances(shape, (theirs - pos) @ R, d).min()))
        return float(best)

    def _boundary(self, key: Any, shape: object) -> Array | None:
        """:func:`shape_boundary_samples` of a shape (cached)."""
        ck = ("boundary", key)
        if ck not in self._cache:
            self._cache[ck] = shape_boundary_samples(shape, self.scene.dim, self.sample_step)
        got: Array | None = self._cache[ck]
        return got

    @property
    def geometry(self) -> SceneGeometry:
        """The detector's geometry of the scene (built on first use: capsule scenes never do)."""
        got = self._cache.get("geometry")
        if got is None:
            got = self._cache["geometry"] = SceneGeometry(self.scene, self.hand)
        return got

    def is_urdf(self, finger: int) -> bool:
        """Whether the finger's links are checked with their URDF collision shapes."""
        key = ("urdf", finger)
        if key not in self._cache:
            shapes = getattr(self.hand.fingers[finger], "collision_shapes", None)
            self._cache[key] = shapes is not None and shapes(0) is not None
        return bool(self._cache[key])

    def cores(self, finger: int, q: Array) -> list[list[Placed]]:
        """The core of every link of ``finger`` at the hand configuration ``q`` (see the module
        notes): a URDF link's shapes (the last link with the links fixed beyond it), or a capsule
        link's bare axis."""
        geo = self.geometry
        refs = self.links(finger)
        if not self.is_urdf(finger):
            A, B = self.segment_arrays(finger, q)
            return [[geo.segment_body(a, b)] for a, b in zip(A, B, strict=True)]
        names = self.hand.fingers[finger].body_names()
        out: list[list[Placed]] = [geo.link_bodies(r, q) for r in refs]
        for k in range(len(refs), len(names)):  # links fixed beyond the last joint
            out[-1] += geo.link_bodies(BodyRef(names[k], finger, k), q)
        return out

    def _cores_cached(self, finger: int, q: Array) -> list[list[Placed]]:
        """:meth:`cores` of a finger that does not move (cached by its joint values)."""
        sl = self.hand.finger_slice(finger)
        key = ("cores", finger, np.asarray(q[sl], dtype=float).tobytes())
        got = self._cache.get(key)
        if got is None:
            if len(self._cache) > 4096:
                for k in [k for k in self._cache if k[0] in ("segs", "cores", "stacked")]:
                    del self._cache[k]
            got = self._cache[key] = self.cores(finger, q)
        return got

    def fingers_distance(self, i: int, j: int, q: Array) -> float:
        """Smallest clearance between the links of fingers ``i`` and ``j`` (capsules, or coal
        where a finger has URDF shapes)."""
        best = np.inf
        if self.is_urdf(i) or self.is_urdf(j):
            ci, cj = self.cores(i, q), self.cores(j, q)
            for a, ca in zip(self.links(i), ci, strict=True):
                for b, cb in zip(self.links(j), cj, strict=True):
                    best = min(best, self.geometry.distance(ca, cb) - self.radius(a) - self.radius(b))
            return float(best)
        for a in self.links(i):
            a0, a1 = self.hand.body_segment(a, q)
            for b in self.links(j):
                b0, b1 = self.hand.body_segment(b, q)
                best = min(best, segment_segment_distance(a0, a1, b0, b1) - self.radius(a) - self.radius(b))
        return float(best)

    def links(self, finger: int) -> list[BodyRef]:
        f = self.hand.fingers[finger]
        return [BodyRef(f"{f.name}/{k}", finger, k) for k in range(f.n_joints)]

    def radius(self, ref: BodyRef, inflate: bool = True) -> float:
        """The capsule radius of a link (``max(link radius, min_radius)``, inflated by half the
        sample step); 0 for a link with URDF shapes (its real geometry, coal distances)."""
        if ref.finger is not None and self.is_urdf(ref.finger):
            return 0.0
        r = max(self.hand.body_radius(ref), self.min_radius)
        return r + (self.sample_step / 2.0 if inflate else 0.0)

    def fixed_distance(self, a: Array, b: Array) -> float:
        best = np.inf
        for fb in self.scene.fixed_bodies:
            best = min(best, _shape_segment_distance(fb.shape, a, b, self.scene.dim, self.sample_step))
        return float(best)

    def finger_clearance(
        self,
        finger: int,
        q: Array,
        position: Array,
        rotation: Array,
        touching: Sequence[BodyRef] = (),
        allowance: Array | None = None,
    ) -> float:
        """Smallest clearance (distance minus capsule radii) of the links of ``finger`` at the hand
        configuration ``q`` ``(M,)``; negative means collision. Links in ``touching`` may touch
        the object with their true radius (their clearance to the object is not counted).
        ``allowance`` (``<= 0``, laid out as :meth:`clearance_terms`) lowers the bound of each
        term: an overlap that exists at the start of a motion may persist but not grow.

        Capsule fingers: the same minimum as ``min(clearance_terms - allowance)``, without
        evaluating blocks that cannot hold it (:meth:`_capsule_clearance_min`)."""
        fd = self._finger_data(finger)
        if not (fd.urdf or fd.coal_object):
            return self._capsule_clearance_min(fd, finger, q, position, rotation, touching, allowance)
        terms = self.clearance_terms(finger, q, position, rotation, touching)
        if allowance is not None:
            terms = terms - allowance
        return float(terms.min()) if terms.size else float(np.inf)

    def is_clear(
        self,
        finger: int,
        q: Array,
        position: Array,
        rotation: Array,
        touching: Sequence[BodyRef] = (),
        allowance: Array | None = None,
        floor: float = 0.0,
    ) -> bool:
        """``finger_clearance(...) >= floor``, exactly, without the clearance's value: a capsule
        finger evaluates a block only where a lower bound of one of its terms is below ``floor``,
        and stops once a term is below it (as :meth:`clear_many`)."""
        fd = self._finger_data(finger)
        if not (fd.urdf or fd.coal_object):
            return self._capsule_clearance_min(fd, finger, q, position, rotation, touching, allowance, floor) >= floor
        return self.finger_clearance(finger, q, position, rotation, touching, allowance) >= floor

    def finger_clearances(
        self,
        finger: int,
        q: Array,
        X: Array,
        position: Array,
        rotation: Array,
        allowance: Array | None = None,
        touching: Sequence[BodyRef] = (),
    ) -> Array:
        """:meth:`finger_clearance` at many configurations at once: ``X`` ``(N, m)`` the joints of
        ``finger``, every other joint as in ``q`` ``(M,)``; returns ``(N,)``.

        Capsule serial chains: every term of :meth:`clearance_terms` for the ``N`` configurations
        in one pass (forward kinematics and distances vectorised over them), the minimum of
        ``terms - allowance`` per configuration. Other fingers (URDF shapes, a mesh object): one
        :meth:`finger_clearance` per configuration."""
        return self._finger_clearances(finger, q, X, position, rotation, allowance, touching, None)

    def clear_many(
        self,
        finger: int,
        q: Array,
        X: Array,
        position: Array,
        rotation: Array,
        allowance: Array | None = None,
        touching: Sequence[BodyRef] = (),
        floor: float = 0.0,
    ) -> Array:
        """``finger_clearances(...) >= floor`` ``(N,)`` bool, exactly, for validity checks that want
        no clearance values (OMPL's): capsule serial chains evaluate a block (link pairs, fixed
        bodies) only where a lower bound of one of its terms is below ``floor`` and the
        configuration is not already below it (:meth:`_clearances_min` with ``floor``); every term
        evaluated is the same, bit for bit, and a term skipped is at least its bound, above ``floor``."""
        return self._finger_clearances(finger, q, X, position, rotation, allowance, touching, floor) >= floor

    def clearances_below(
        self,
        finger: int,
        q: Array,
        X: Array,
        floors: Array,
        position: Array,
        rotation: Array,
        allowance: Array | None = None,
        touching: Sequence[BodyRef] = (),
    ) -> Array:
        """:meth:`finger_clearances` ``(N,)`` exact where they are below ``floors`` ``(N,)``, and
        elsewhere a value at least the floor (and at least the clearance): a block is evaluated only
        where a lower bound of one of its terms is below the configuration's floor, as long as the
        minimum so far is not below it (:meth:`clear_many` with one floor per configuration; the
        certificate of :func:`path_clearance_certified` needs no more)."""
        return self._finger_clearances(finger, q, X, position, rotation, allowance, touching,
                                       np.asarray(floors, dtype=float), exact_below=True)

    def _finger_clearances(
        self,
        finger: int,
        q: Array,
        X: Array,
        position: Array,
        rotation: Array,
        allowance: Array | None,
        touching: Sequence[BodyRef],
        floor: float | Array | None,
        exact_below: bool = False,
    ) -> Array:
        fd = self._finger_data(finger)
        X = np.asarray(X, dtype=float)
        N = X.shape[0]
        if fd.urdf or fd.coal_object or fd.rot_K is None or N == 0:
            out = np.empty(N)
            qq = np.array(q, dtype=float)
            sl = self.hand.finger_slice(finger)
            for k in range(N):
                qq[sl] = X[k]
                out[k] = self.finger_clearance(finger, qq, position, rotation, touching, allowance)
            return out
        pf = self._planar(finger) if N <= PLANAR_ROWS else None
        if pf is not None:  # a few configurations of a planar capsule finger: in float arithmetic
            return np.array(self._planar_rows(pf, finger, q, X.tolist(), position, allowance, touching, floor,
                                              exact_below), dtype=float).reshape(N)
        n = len(fd.refs)
        d = self.scene.dim
        A, B = self._segment_arrays_many(finger, X)  # (N, n, d) each
        R = np.asarray(rotation, dtype=float)[:d, :d]
        pos = np.asarray(position, dtype=float)[:d]
        Af, Bf = A.reshape(N * n, d), B.reshape(N * n, d)  # (N n, d)
        od = _shape_segments_distance(self.scene.object.shape, (Af - pos) @ R, (Bf - pos) @ R, d, self.sample_step)
        od = od.reshape(N, n)
        stacked = self._others_stacked(finger, q)
        segs = [] if stacked is None else [(np.broadcast_to(stacked[0], (N, *stacked[0].shape)),
                                            np.broadcast_to(stacked[1], (N, *stacked[1].shape)))]
        return self._clearances_min(fd, finger, A, B, od, segs, allowance, touching, floor, exact_below)

    def _others_stacked(self, finger: int, q: Array) -> tuple[Array, Array] | None:
        """The link axes ``(n_o, d)``, ``(n_o, d)`` of the fingers checked against ``finger`` at the
        hand configuration ``q``, stacked in :attr:`_FingerData.stacked` order (cached by ``q``: a
        transfer asks for them at every check); ``None`` without such fingers."""
        others = self._cache.get(("others", finger))
        if others is None:
            others = self._cache[("others", finger)] = [
                k for k in range(len(self.hand.fingers))
                if k != finger and (min(k, finger), max(k, finger)) in self.finger_pairs]
        if not others:
            return None
        key = ("stacked", finger, np.asarray(q, dtype=float).tobytes())
        got = self._cache.get(key)
        if got is None:
            if len(self._cache) > 4096:
                for k in [k for k in self._cache if k[0] in ("segs", "stacked")]:
                    del self._cache[k]
            segs = [self._segments_cached(k, q) for k in others]
            got = self._cache[key] = (np.concatenate([sg[0] for sg in segs]), np.concatenate([sg[1] for sg in segs]))
        return got

    def clearances_along(
        self,
        finger: int,
        Q: Array,
        positions: Array,
        rotations: Array,
        allowance: Array | None = None,
        touching: Sequence[BodyRef] = (),
    ) -> Array:
        """:meth:`finger_clearance` of ``finger`` at the states of a path: the hand at ``Q[k]`` ``(N, M)``
        and the object at ``positions[k]`` ``(N, d)``, ``rotations[k]`` ``(N, 3, 3)`` (every joint and
        the object move, as along an object motion); returns ``(N,)``, equal to one state at a time
        bit for bit (as :meth:`finger_clearances`, which keeps the other joints and the object still)."""
        return self._clearances_along(finger, Q, positions, rotations, allowance, touching, None)

    def clear_along(
        self,
        finger: int,
        Q: Array,
        positions: Array,
        rotations: Array,
        allowance: Array | None = None,
        touching: Sequence[BodyRef] = (),
        floor: float = 0.0,
    ) -> Array:
        """``clearances_along(...) >= floor`` ``(N,)`` bool, exactly, with the blocks culled against
        ``floor`` (as :meth:`clear_many`)."""
        return self._clearances_along(finger, Q, positions, rotations, allowance, touching, floor) >= floor

    def _clearances_along(
        self,
        finger: int,
        Q: Array,
        positions: Array,
        rotations: Array,
        allowance: Array | None,
        touching: Sequence[BodyRef],
        floor: float | None,
    ) -> Array:
        fd = self._finger_data(finger)
        Q = np.asarray(Q, dtype=float)
        N = Q.shape[0]
        others = [k for k in range(len(self.hand.fingers))
                  if k != finger and (min(k, finger), max(k, finger)) in self.finger_pairs]
        if N == 0 or not self.batched(finger):
            return np.array([self.finger_clearance(finger, Q[k], positions[k], rotations[k], touching, allowance)
                             for k in range(N)], dtype=float).reshape(N)
        n = len(fd.refs)
        d = self.scene.dim
        A, B = self._segment_arrays_many(finger, Q[:, self.hand.finger_slice(finger)])  # (N, n, d) each
        R = np.asarray(rotations, dtype=float)[:, :d, :d]  # (N, d, d)
        pos = np.asarray(positions, dtype=float)[:, None, :d]  # (N, 1, d)
        od = _shape_segments_distance(self.scene.object.shape, ((A - pos) @ R).reshape(N * n, d),
                                      ((B - pos) @ R).reshape(N * n, d), d, self.sample_step).reshape(N, n)
        segs = [self._segment_arrays_many(k, Q[:, self.hand.finger_slice(k)]) for k in others]
        return self._clearances_min(fd, finger, A, B, od, segs, allowance, touching, floor)

    def batched(self, finger: int) -> bool:
        """Whether :meth:`clearances_along` evaluates ``finger``'s states in one pass (a capsule
        serial chain checked against capsule serial chains and a shape with a signed distance);
        else it goes one state at a time."""
        fd = self._finger_data(finger)
        if fd.urdf or fd.coal_object or fd.rot_K is None:
            return False
        return not any(self._finger_data(k).rot_K is None or self._finger_data(k).urdf
                       for k in range(len(self.hand.fingers))
                       if k != finger and (min(k, finger), max(k, finger)) in self.finger_pairs)

    def _clearances_min(
        self,
        fd: _FingerData,
        finger: int,
        A: Array,
        B: Array,
        od: Array,
        segs: list[tuple[Array, Array]],
        allowance: Array | None,
        touching: Sequence[BodyRef],
        floor: float | Array | None = None,
        exact_below: bool = False,
    ) -> Array:
        """The minimum of ``terms - allowance`` per state of :meth:`finger_clearances` and
        :meth:`clearances_along`: the finger's link axes ``A``, ``B`` ``(N, n, d)``, their distances
        ``od`` ``(N, n)`` to the object, the link axes ``(N, n_k, d)`` of each finger checked against
        it; own and other pairs and fixed bodies culled by their lower bounds.

        ``floor`` (:meth:`clear_many`): only whether each minimum is ``>= floor`` is wanted, so a
        block is evaluated only where a lower bound of one of its terms is below ``floor`` and the
        state's minimum so far is not yet below it (instead of below the minimum so far); the
        values returned are then on the same side of ``floor`` as the true minima, not their value.
        With ``exact_below`` (:meth:`clearances_below`) a block is evaluated where a bound is below
        both the floor and the minimum so far: the values below the floor are exact, the others at
        least the floor."""
        N, n, d = A.shape
        Af, Bf = A.reshape(N * n, d), B.reshape(N * n, d)  # (N n, d)
        if allowance is None:
            al = self._cache.get(("zeros", finger))
            if al is None:
                al = self._cache[("zeros", finger)] = np.zeros(2 * n + len(fd.pairs))
        else:
            al = np.asarray(allowance, dtype=float)
        touch = np.zeros(n, dtype=bool)
        for t in touching:
            if t.finger == finger and t.link is not None:
                touch[min(int(t.link), n - 1)] = True
        if touch.any():
            obj = np.where(touch, np.maximum(0.0, od - fd.r_true + 1e-9), od - fd.r_infl) - al[:n]  # (N, n)
        else:
            obj = od - fd.r_infl - al[:n]
        best = obj.min(axis=1)  # (N,) the minimum so far, as in _capsule_clearance_min
        if floor is not None and not exact_below and bool((best < floor).all()):  # all already below
            return np.asarray(best)
        i, j = fd.pairs[:, 0], fd.pairs[:, 1]
        if len(i):  # own non-adjacent pairs, then the links of the fingers checked against this one
            S0, S1 = A, B
            if segs:
                S0 = np.concatenate([A, *(sg[0] for sg in segs)], axis=1)
                S1 = np.concatenate([B, *(sg[1] for sg in segs)], axis=1)
            p = len(i)
            # only the pairs whose lower bound is below the minimum so far (as _capsule_clearance_min):
            # two segments are at least |c_a - c_b| - (L_a + L_b) / 2 apart (midpoints c, rigid links
            # of lengths L); the others cannot hold the minimum
            Mid = 0.5 * (S0 + S1)  # (N, n_s, d)
            gap = Mid[:, i] - Mid[:, j]  # (N, p, d)
            bound = np.sqrt((gap * gap).sum(axis=2)) - fd.pair_half - fd.pair_radii - al[2 * n:]  # (N, p)
            need = (bound - 1e-9 < self._cut(best, floor, exact_below)[:, None]).reshape(N * p)
            if need.any():
                pd = np.full(N * p, np.inf)
                pd[need] = segment_segment_distances(S0[:, i].reshape(N * p, d)[need], S1[:, i].reshape(N * p, d)[need],
                                                     S0[:, j].reshape(N * p, d)[need], S1[:, j].reshape(N * p, d)[need])
                best = np.minimum(best, (pd.reshape(N, p) - fd.pair_radii - al[2 * n:]).min(axis=1))
        # the fixed bodies, only for the links whose lower bound is below `best` (or `floor`: not once all are below)
        if fd.any_fixed and not (floor is not None and not exact_below and bool((best < floor).all())):
            tiles = self._cache.get(("tiles", finger, N))
            if tiles is None:
                tiles = self._cache[("tiles", finger, N)] = (np.tile(fd.r_infl, N), np.tile(fd.fixed_checked, N))
            r_all, fixed_checked = tiles  # (N n,) each
            A2, skip = _trimmed_at_base(Af, Bf, fd.base, r_all)
            al_f = al[n:2 * n]  # (n,), per link
            checked = fixed_checked & ~skip
            E = Bf - A2
            half = 0.5 * np.sqrt((E * E).sum(axis=1))
            need = checked
            if self._fixed_bounded:  # 1-Lipschitz distances: a segment is at least dist(midpoint) - L/2 away
                C = 0.5 * (A2 + Bf)
                bodies = self.scene.fixed_bodies
                lb = shape_signed_distances(bodies[0].shape, C, d) - half
                for fb in bodies[1:]:
                    lb = np.minimum(lb, shape_signed_distances(fb.shape, C, d) - half)
                need = checked & ((lb.reshape(N, n) - fd.r_infl - al_f - 1e-9)
                                  < self._cut(best, floor, exact_below)[:, None]).reshape(N * n)
            if need.any():
                # sampled as the whole block would be: the sample count from the longest link
                length = float(2.0 * half.max())
                dist = np.full(int(need.sum()), np.inf)
                for fb in self.scene.fixed_bodies:
                    dist = np.minimum(dist, _shape_segments_distance(fb.shape, A2[need], Bf[need], d, self.sample_step,
                                                                     length))
                fixed = np.full(N * n, np.inf)
                fixed[need] = dist - r_all[need] - al_f[np.flatnonzero(need) % n]
                best = np.minimum(best, fixed.reshape(N, n).min(axis=1))
        return np.asarray(best)

    @staticmethod
    def _cut(best: Array, floor: float | Array | None, exact_below: bool = False) -> Array:
        """The value ``(N,)`` below which a lower bound makes a block worth evaluating: the minimum
        so far; with a ``floor``, the floor where the minimum so far is not below it (a term surely
        above the floor cannot change the answer) and ``-inf`` where it is (the answer is known);
        ``exact_below``: the smaller of the floor and the minimum so far (exact below the floor)."""
        if floor is None:
            return best
        if exact_below:
            return np.minimum(best, floor)
        return np.where(best < floor, -np.inf, floor)

    @functools.cached_property
    def _fixed_bounded(self) -> bool:
        """Every fixed body has a signed distance for the lower bounds (not a mesh)."""
        return all(isinstance(fb.shape, Disk | Sphere | Box | Segment) for fb in self.scene.fixed_bodies)

    def _segment_arrays_many(self, finger: int, X: Array) -> tuple[Array, Array]:
        """:meth:`segment_arrays` of a capsule serial chain at the joints ``X`` ``(N, m)`` of the
        finger: ``(N, n, dim)``, ``(N, n, dim)``."""
        chain = self.hand.fingers[finger]
        assert isinstance(chain, SerialChain)
        fd = self._finger_data(finger)
        assert fd.rot_K is not None
        d = self.scene.dim
        n = len(fd.refs)
        N = X.shape[0]
        A = np.empty((N, n, 3))
        B = np.empty((N, n, 3))
        K = self._cache.get(("rotK", finger))
        if K is None:  # (n, 3, 3) each: the joints' K and K @ K, stacked
            K = self._cache[("rotK", finger)] = (np.array([k for k, _ in fd.rot_K]),
                                                 np.array([k2 for _, k2 in fd.rot_K]))
        S, C = np.sin(X[:, :n]), 1.0 - np.cos(X[:, :n])  # (N, n)
        Rot = _EYE3 + S[:, :, None, None] * K[0] + C[:, :, None, None] * K[1]  # (N, n, 3, 3) joint rotations
        R = chain.base_R  # (3, 3), then (N, 3, 3) once the first joint turns
        p = chain.base_p + R @ chain.origins[0]  # (3,), then (N, 3)
        A[:, 0] = p
        for k in range(n):
            R = R @ Rot[:, k]
            end = chain.origins[k + 1] if k + 1 < n else chain.tip
            p = p + R @ end  # the end of link k is the origin of joint k + 1
            B[:, k] = p
        A[:, 1:] = B[:, :-1]
        return A[:, :, :d], B[:, :, :d]


    def _planar(self, finger: int) -> _PlanarFinger | None:
        """The float data of ``finger`` when its clearance can be evaluated in float arithmetic
        (:meth:`_planar_min`): a planar scene whose fingers are all serial chains turning about z
        in the plane (capsules, no URDF shapes), a disk object and fixed bodies that are segments
        or disks; else None (cached)."""
        key = ("planar", finger)
        if key in self._cache:
            got: _PlanarFinger | None = self._cache[key]
            return got
        got = None
        fd = self._finger_data(finger)
        scene, hand = self.scene, self.hand
        chains = [_planar_chain(f) for f in hand.fingers] if scene.dim == 2 else [None]
        if (isinstance(scene.object.shape, Disk) and not fd.urdf and not fd.coal_object
                and all(isinstance(fb.shape, Disk | Segment) for fb in scene.fixed_bodies)
                and not any(self.is_urdf(k) for k in range(len(hand.fingers)))
                and all(c is not None for c in chains)):
            n = len(fd.refs)
            others = [k for k in range(len(hand.fingers))
                      if k != finger and (min(k, finger), max(k, finger)) in self.finger_pairs]
            fixed: list[tuple[Any, ...]] = []
            for fb in scene.fixed_bodies:
                if isinstance(fb.shape, Segment):
                    (p0x, p0y), (p1x, p1y) = ((float(v[0]), float(v[1])) for v in fb.shape.points)
                    fixed.append(("segment", p0x, p0y, p1x, p1y))
                elif isinstance(fb.shape, Disk):
                    fixed.append(("disk", float(fb.shape.radius)))
            ch = [c for c in chains if c is not None]  # every finger's (checked above)
            got = _PlanarFinger(
                ch[finger],
                others,
                [ch[k] for k in others],
                [float(v) for v in fd.r_infl],
                [float(v) for v in fd.r_true],
                [bool(v) for v in fd.fixed_checked],
                (float(fd.base[0]), float(fd.base[1])),
                [(int(i), int(j), float(r), float(h)) for (i, j), r, h in
                 zip(fd.pairs.reshape(-1, 2), fd.pair_radii, fd.pair_half, strict=True)],
                fixed,
                float(scene.object.shape.radius),
            )
            assert n == len(got.chain[3])
        self._cache[key] = got
        return got

    def _planar_points_cached(self, finger: int, chain: tuple[float, float, float, list[tuple[float, float]],
                                                             list[float]], q: Array) -> list[tuple[float, float]]:
        """:func:`_planar_points` of a finger (its ``chain``) that does not move (cached by its joint values)."""
        sl = self.hand.finger_slice(finger)
        qf = np.asarray(q, dtype=float)[sl]
        key = ("pts", finger, qf.tobytes())
        got = self._cache.get(key)
        if got is None:
            if len(self._cache) > 4096:
                for k in [k for k in self._cache if k[0] == "pts"]:
                    del self._cache[k]
            got = self._cache[key] = _planar_points(chain, qf.tolist())
        return got

    def _planar_min(
        self,
        pf: _PlanarFinger,
        qf: Sequence[float],
        others: list[list[tuple[float, float]]],
        ox: float,
        oy: float,
        touch: Sequence[bool],
        al: Sequence[float] | None,
        floor: float | None = None,
        exact_below: bool = False,
    ) -> float:
        """``min(clearance_terms - allowance)`` of a planar capsule finger (:meth:`_planar`) at its
        joint values ``qf`` ``(n,)`` in float arithmetic, the disk object centred at ``(ox, oy)``,
        ``others`` the joint points (:func:`_planar_points`) of the fingers checked against it:
        the object terms, the link pairs and the fixed bodies with the formulas of
        :meth:`clearance_terms` (the disk's distance about its centre, so without the object's
        rotation; equal to them to round-off). A pair is evaluated only where its lower bound
        ``|c_a - c_b| - (L_a + L_b) / 2`` (as :meth:`_clearances_min`) is below the minimum so far,
        so the value is the exact minimum. ``floor`` as :meth:`_clearances_min`: without
        ``exact_below`` only the side of ``floor`` is kept (it ends once below), with it the value
        is exact below ``floor``."""
        pts = _planar_points(pf.chain, qf)
        n = len(pts) - 1
        segs = [(pts[k][0], pts[k][1], pts[k + 1][0], pts[k + 1][1]) for k in range(n)]
        r_o = pf.object_radius
        best = math.inf
        for k, (ax, ay, bx, by) in enumerate(segs):
            od = _segment_distance_f(ax, ay, bx, by, ox, oy) - r_o
            term = max(0.0, od - pf.r_true[k] + 1e-9) if touch[k] else od - pf.r_infl[k]
            if al is not None:
                term = term - al[k]
            best = min(best, term)
        if floor is not None and not exact_below and best < floor:
            return best
        for o in others:
            segs += [(o[k][0], o[k][1], o[k + 1][0], o[k + 1][1]) for k in range(len(o) - 1)]
        for p, (i, j, rad, half) in enumerate(pf.pairs):
            a0x, a0y, a1x, a1y = segs[i]
            b0x, b0y, b1x, b1y = segs[j]
            a_p = al[2 * n + p] if al is not None else 0.0
            gx, gy = 0.5 * (a0x + a1x) - 0.5 * (b0x + b1x), 0.5 * (a0y + a1y) - 0.5 * (b0y + b1y)
            cut = best if floor is None else (min(best, floor) if exact_below else floor)
            if math.sqrt(gx * gx + gy * gy) - half - rad - a_p - 1e-9 >= cut:
                continue  # the pair's term is at least its bound, not below the cut
            best = min(best, _segment_segment_distance_f(a0x, a0y, a1x, a1y, b0x, b0y, b1x, b1y) - rad - a_p)
            if floor is not None and not exact_below and best < floor:
                return best
        if pf.fixed:
            bx0, by0 = pf.base
            for k, (ax, ay, bx, by) in enumerate(segs[:n]):
                if not pf.fixed_checked[k]:
                    continue
                dx, dy = bx - ax, by - ay
                if (ax - bx0) * (ax - bx0) + (ay - by0) * (ay - by0) < 1e-18:  # at the base: trimmed
                    L = math.sqrt(dx * dx + dy * dy)
                    trim = max(3.0 * pf.r_infl[k], BASE_TRIM * L)
                    if 2.0 * trim >= L:
                        continue
                    f = trim / (L if L > 0 else 1.0)
                    ax, ay = ax + dx * f, ay + dy * f
                dist = math.inf
                for fb in pf.fixed:
                    if fb[0] == "segment":
                        dist = min(dist, _segment_segment_distance_f(ax, ay, bx, by, fb[1], fb[2], fb[3], fb[4]))
                    else:
                        dist = min(dist, _segment_distance_f(ax, ay, bx, by, 0.0, 0.0) - fb[1])
                term = dist - pf.r_infl[k]
                if al is not None:
                    term = term - al[n + k]
                best = min(best, term)
        return best

    def _planar_rows(
        self,
        pf: _PlanarFinger,
        finger: int,
        q: Array,
        rows: list[list[float]],
        position: Array,
        allowance: Array | None,
        touching: Sequence[BodyRef],
        floor: float | Array | None = None,
        exact_below: bool = False,
    ) -> list[float]:
        """:meth:`_planar_min` at the finger's joint values ``rows`` ``(N, n)``, every other joint
        as in ``q`` and the object at ``position``; ``floor`` a number or one per row."""
        n = len(pf.r_infl)
        touch = [False] * n
        for t in touching:
            if t.finger == finger and t.link is not None:
                touch[min(int(t.link), n - 1)] = True
        others = [self._planar_points_cached(k, c, q) for k, c in zip(pf.others, pf.other_chains, strict=True)]
        al = None if allowance is None else np.asarray(allowance, dtype=float).tolist()
        ox, oy = float(position[0]), float(position[1])
        if floor is None or isinstance(floor, float | int):
            fl = None if floor is None else float(floor)
            return [self._planar_min(pf, x, others, ox, oy, touch, al, fl, exact_below) for x in rows]
        fls = np.broadcast_to(np.asarray(floor, dtype=float), (len(rows),)).tolist()
        return [self._planar_min(pf, x, others, ox, oy, touch, al, fls[k], exact_below) for k, x in enumerate(rows)]

    def _capsule_clearance_min(
        self,
        fd: _FingerData,
        finger: int,
        q: Array,
        position: Array,
        rotation: Array,
        touching: Sequence[BodyRef],
        allowance: Array | None,
        floor: float | None = None,
    ) -> float:
        """``min(clearance_terms - allowance)`` of a capsule finger, bit for bit: the object terms
        first, then a block (own/other link pairs, fixed bodies) only where a lower bound of one of
        its terms is below the minimum so far. The bounds use that a distance function is
        1-Lipschitz: a segment of length ``L`` and midpoint ``c`` is at least ``dist(c) - L/2``
        from a convex body, two segments at least ``|c_a - c_b| - (L_a + L_b)/2`` apart (the
        sampled box distances are never below the exact ones). ``floor`` (:meth:`is_clear`): a value
        on the same side of ``floor`` as the minimum only (blocks culled against ``floor``, none once
        below it)."""
        pf = self._planar(finger)
        if pf is not None:  # a planar capsule finger: in float arithmetic
            row = np.asarray(q, dtype=float)[self.hand.finger_slice(finger)].tolist()
            return self._planar_rows(pf, finger, q, [row], position, allowance, touching, floor)[0]
        n = len(fd.refs)
        d = self.scene.dim
        A, B = self.segment_arrays(finger, q)  # (n, d), (n, d)
        R = np.asarray(rotation, dtype=float)[:d, :d]
        pos = np.asarray(position, dtype=float)[:d]
        od = _shape_segments_distance(self.scene.object.shape, (A - pos) @ R, (B - pos) @ R, d, self.sample_step)
        touch = np.zeros(n, dtype=bool)
        for t in touching:
            if t.finger == finger and t.link is not None:
                touch[min(int(t.link), n - 1)] = True
        obj = np.where(touch, np.maximum(0.0, od - fd.r_true + 1e-9), od - fd.r_infl)  # (n,)
        al = allowance
        if al is not None:
            obj = obj - al[:n]
        best = float(obj.min()) if n else float(np.inf)
        margin = 1e-9  # the bounds' rounding, far above it
        if floor is not None and best < floor:
            return best
        i, j = fd.pairs[:, 0], fd.pairs[:, 1]
        if len(i):
            others = [k for k in range(len(self.hand.fingers))
                      if k != finger and (min(k, finger), max(k, finger)) in self.finger_pairs]
            if others:
                segs = [self._segments_cached(k, q) for k in others]
                S0 = np.vstack([A, *(sg[0] for sg in segs)])
                S1 = np.vstack([B, *(sg[1] for sg in segs)])
            else:
                S0, S1 = A, B
            P0, P1, Q0, Q1 = S0[i], S1[i], S0[j], S1[j]  # (p, d) each
            mid = 0.5 * (P0 + P1) - 0.5 * (Q0 + Q1)
            half = 0.5 * (np.sqrt(((P1 - P0) ** 2).sum(axis=1)) + np.sqrt(((Q1 - Q0) ** 2).sum(axis=1)))
            bound = np.sqrt((mid * mid).sum(axis=1)) - half - fd.pair_radii  # (p,) <= the terms
            if al is not None:
                bound = bound - al[2 * n:]
            need = bound - margin < (best if floor is None else floor)
            if need.any():
                pd = segment_segment_distances(P0[need], P1[need], Q0[need], Q1[need]) - fd.pair_radii[need]
                if al is not None:
                    pd = pd - al[2 * n:][need]
                best = min(best, float(pd.min()))
        if floor is not None and best < floor:
            return best
        if fd.any_fixed:
            A2, skip = _trimmed_at_base(A, B, fd.base, fd.r_infl)
            checked = fd.fixed_checked & ~skip
            al_f = al[n:2 * n] if al is not None else np.zeros(n)
            bounded = all(isinstance(fb.shape, Disk | Sphere | Box | Segment) for fb in self.scene.fixed_bodies)
            if checked.any():
                if bounded:
                    C = 0.5 * (A2 + B)
                    E = B - A2
                    half_f = 0.5 * np.sqrt((E * E).sum(axis=1))
                    lb = np.full(n, np.inf)
                    for fb in self.scene.fixed_bodies:
                        lb = np.minimum(lb, shape_signed_distances(fb.shape, C, d) - half_f)
                    lb = lb - fd.r_infl - al_f
                    do = bool(np.any(lb[checked] - margin < (best if floor is None else floor)))
                else:
                    do = True
                if do:  # the block exactly as clearance_terms evaluates it
                    dist = np.full(n, np.inf)
                    for fb in self.scene.fixed_bodies:
                        dist = np.minimum(dist, _shape_segments_distance(fb.shape, A2, B, d, self.sample_step))
                    fixed = np.where(checked, dist - fd.r_infl, np.inf) - al_f
                    best = min(best, float(fixed.min()))
        return best

    def start_allowance(self, finger: int, q: Array, position: Array, rotation: Array) -> Array:
        """The overlaps ``min(0, term)`` of :meth:`clearance_terms` at the start ``q`` of a motion
        (no link touching): a motion may keep them but not deepen them (see the module notes)."""
        # remembered by what it reads (the hand configuration, the object pose, exactly): a state's
        # allowances are asked for by every motion that starts there (the planar plan: 30 calls,
        # 12 distinct); a copy is returned, so no caller changes another's
        key = ("allowance", finger, np.asarray(q, dtype=float).tobytes(), np.asarray(position, dtype=float).tobytes(),
               np.asarray(rotation, dtype=float).tobytes())
        got = self._cache.get(key)
        if got is None:
            if len(self._cache) > 4096:
                for k in [k for k in self._cache if k[0] == "allowance"]:
                    del self._cache[k]
            got = self._cache[key] = np.minimum(0.0, self.clearance_terms(finger, q, position, rotation))
        return np.array(got)

    def clearance_terms(
        self,
        finger: int,
        q: Array,
        position: Array,
        rotation: Array,
        touching: Sequence[BodyRef] = (),
    ) -> Array:
        """Every clearance of :meth:`finger_clearance`, one per (link, obstacle) pair, vectorised:
        ``[object (n), fixed bodies (n), own non-adjacent link pairs, links of other fingers]``
        (the layout depends on the finger only; pairs that are not checked are ``inf``)."""
        fd = self._finger_data(finger)
        n = len(fd.refs)
        d = self.scene.dim
        A, B = self.segment_arrays(finger, q)
        R = np.asarray(rotation, dtype=float)[:d, :d]
        pos = np.asarray(position, dtype=float)[:d]
        cores = None
        if fd.coal_object:  # coal: the real geometry
            cores = self.cores(finger, q)
            body = [self.geometry.object_at(position, rotation)]
            od = np.array([self.geometry.distance(c, body) for c in cores])
        else:
            od = _shape_segments_distance(self.scene.object.shape, (A - pos) @ R, (B - pos) @ R, d, self.sample_step)
        # a link beyond the last joint (a URDF tip link) is the end of the last capsule
        touch = np.zeros(n, dtype=bool)
        for t in touching:
            if t.finger == finger and t.link is not None:
                touch[min(int(t.link), n - 1)] = True
        parts = [np.where(touch, np.maximum(0.0, od - fd.r_true + 1e-9), od - fd.r_infl)]
        fixed = np.full(n, np.inf)
        if fd.any_fixed and fd.urdf:  # URDF shapes: not trimmed, only mounted links are not checked
            assert cores is not None
            geo = self.geometry
            fixed = np.array([geo.distance(c, geo.fixed) if ok else np.inf
                              for c, ok in zip(cores, fd.fixed_checked, strict=True)])
        elif fd.any_fixed:
            A2, skip = _trimmed_at_base(A, B, fd.base, fd.r_infl)
            dist = np.full(n, np.inf)
            for fb in self.scene.fixed_bodies:
                dist = np.minimum(dist, _shape_segments_distance(fb.shape, A2, B, d, self.sample_step))
            fixed = np.where(fd.fixed_checked & ~skip, dist - fd.r_infl, np.inf)
        parts.append(fixed)
        others = [j for j in range(len(self.hand.fingers))
                  if j != finger and (min(j, finger), max(j, finger)) in self.finger_pairs]
        if others:  # own non-adjacent pairs and every pair with another finger's links, at once
            segs = [self._segments_cached(j, q) for j in others]
            S0 = np.vstack([A, *(sg[0] for sg in segs)])
            S1 = np.vstack([B, *(sg[1] for sg in segs)])
        else:
            S0, S1 = A, B
        i, j = fd.pairs[:, 0], fd.pairs[:, 1]
        if len(i):
            pd = segment_segment_distances(S0[i], S1[i], S0[j], S1[j])
            if len(fd.coal_pairs):  # pairs with a URDF core: coal between the cores
                own = cores if cores is not None else self.cores(finger, q)
                stacked = own + [c for o in others for c in self._cores_cached(o, q)]
                geo = self.geometry
                for k in fd.coal_pairs:
                    pd[k] = geo.distance(stacked[i[k]], stacked[j[k]])
            parts.append(pd - fd.pair_radii)
        return np.concatenate(parts)

    def _finger_data(self, finger: int) -> _FingerData:
        got = self._cache.get(("finger", finger))
        if got is None:
            chain = self.hand.fingers[finger]
            refs = self.links(finger)
            n = len(refs)
            sl = self.hand.finger_slice(finger)
            rot_K = None
            if isinstance(chain, SerialChain):
                rot_K = [(skew(a), skew(a) @ skew(a)) for a in chain.axes]
            r_infl = np.array([self.radius(r) for r in refs])
            radii = [r_infl]  # of the stacked segments: own links, then the other checked fingers'
            stacked_refs = list(refs)
            for j in range(len(self.hand.fingers)):
                if j != finger and (min(j, finger), max(j, finger)) in self.finger_pairs:
                    radii.append(np.array([self.radius(r) for r in self.links(j)]))
                    stacked_refs += self.links(j)
            stacked = np.concatenate(radii)
            lengths = np.concatenate([[float(np.linalg.norm(np.subtract(*self.hand.body_segment(r, self.hand.q0))))
                                       for r in self.links(k)] for k in [finger, *[
                                           j for j in range(len(self.hand.fingers))
                                           if j != finger and (min(j, finger), max(j, finger)) in self.finger_pairs]]])
            pairs = [(i, j) for i in range(n) for j in range(i + 2, n)]
            pairs += [(i, j) for i in range(n) for j in range(n, len(stacked))]
            pa = np.array(pairs, dtype=int).reshape(-1, 2)
            fixed_checked = np.array([bool(self.scene.fixed_bodies) and (finger, k) not in self.mounted
                                      for k in range(n)], dtype=bool)
            urdf = np.array([self.is_urdf(int(r.finger)) for r in stacked_refs if r.finger is not None], dtype=bool)
            coal_pairs = np.flatnonzero(urdf[pa[:, 0]] | urdf[pa[:, 1]]) if len(pa) else np.zeros(0, dtype=int)
            got = _FingerData(
                refs,
                r_infl,
                np.array([0.0 if self.is_urdf(finger) else self.hand.body_radius(r) for r in refs]),
                fixed_checked,
                bool(fixed_checked.any()),
                np.asarray(chain.body_pose(0, self.hand.q0[sl])[1][: self.scene.dim], dtype=float),
                pa,
                stacked[pa[:, 0]] + stacked[pa[:, 1]],
                0.5 * (lengths[pa[:, 0]] + lengths[pa[:, 1]]) * (1.0 - 1e-9) if len(pa) else np.zeros(0),
                rot_K,
                self.is_urdf(finger),
                self.is_urdf(finger) or isinstance(self.scene.object.shape, Mesh),
                coal_pairs,
                stacked_refs,
            )
            self._cache[("finger", finger)] = got
        return got

    def _segments_cached(self, finger: int, q: Array) -> tuple[Array, Array]:
        """:meth:`segment_arrays` of a finger that does not move (cached by its joint values)."""
        sl = self.hand.finger_slice(finger)
        key = ("segs", finger, np.asarray(q[sl], dtype=float).tobytes())
        got = self._cache.get(key)
        if got is None:
            if len(self._cache) > 4096:
                for k in [k for k in self._cache if k[0] in ("segs", "stacked")]:
                    del self._cache[k]
            got = self.segment_arrays(finger, q)
            self._cache[key] = got
        return got

    def segment_arrays(self, finger: int, q: Array) -> tuple[Array, Array]:
        """World end points ``(n, dim)``, ``(n, dim)`` of the link axes of ``finger`` at the hand
        configuration ``q`` (serial chains: one forward-kinematics pass, Rodrigues' formula with
        the joint axes' cross-product matrices precomputed)."""
        chain = self.hand.fingers[finger]
        d = self.scene.dim
        qf = np.asarray(q, dtype=float)[self.hand.finger_slice(finger)]
        fd = self._finger_data(finger)
        n = len(fd.refs)
        A = np.empty((n, 3))
        B = np.empty((n, 3))
        if isinstance(chain, SerialChain) and fd.rot_K is not None:
            R, p = chain.base_R, chain.base_p
            for k in range(n):
                p = p + R @ chain.origins[k]
                K, K2 = fd.rot_K[k]
                R = R @ (_EYE3 + np.sin(qf[k]) * K + (1.0 - np.cos(qf[k])) * K2)
                end = chain.origins[k + 1] if k + 1 < n else chain.tip
                A[k], B[k] = p, p + R @ end
        else:
            for k in range(n):
                A[k], B[k] = chain.body_segment(k, qf)
        return A[:, :d], B[:, :d]

    def _fixed_clearance(self, finger: int, link: int, a: Array, b: Array) -> float:
        """Clearance of a link to the fixed bodies; a link starting at the finger's base joint
        (mounted on the palm) is trimmed near it (a zero-length link is the joint itself)."""
        r = self.radius(self.links(finger)[link])
        if self.is_urdf(finger):  # the real shapes: no trim
            geo = self.geometry
            return geo.distance(self.cores(finger, self.hand.q0)[link], geo.fixed)
        chain = self.hand.fingers[finger]
        base = chain.body_pose(0, self.hand.q0[self.hand.finger_slice(finger)])[1][: self.scene.dim]
        if float(np.linalg.norm(a - base)) < 1e-9:
            L = float(np.linalg.norm(b - a))
            trim = max(3.0 * r, BASE_TRIM * L)
            if 2.0 * trim >= L:
                return np.inf
            a = a + (b - a) * (trim / L)
        return self.fixed_distance(a, b) - r

    def segments(self, finger: int, q: Array) -> dict[int, tuple[Array, Array]]:
        """World end points of every link axis of ``finger`` at the hand configuration ``q``."""
        A, B = self.segment_arrays(finger, q)
        return {k: (A[k], B[k]) for k in range(A.shape[0])}

    def lipschitz(self, finger: int) -> float:
        """Bound on the speed of any point of the finger per unit joint motion (``|dx| <= K |dq|``):
        ``K = sqrt(sum_j R_j^2)`` with ``R_j`` the reach of the finger beyond joint ``j``. A point
        ``x`` of link ``k`` is at most ``sum_{i=j}^{k-1} L_i + e_k`` from joint ``j <= k`` (``L_i``
        the link axes, ``e_k`` the farthest point of link ``k``'s URDF shapes from its joint), so
        each link counts ``max(L_k, e_k)``."""
        f = self.hand.fingers[finger]
        q = self.hand.q0[self.hand.finger_slice(finger)]
        extents = self._shape_extents(finger) if self.is_urdf(finger) else np.zeros(f.n_joints)
        lengths = []
        for k in range(f.n_joints):
            a, b = f.body_segment(k, q)
            lengths.append(max(float(np.linalg.norm(b - a)) + float(np.linalg.norm(a - f.body_pose(k, q)[1])),
                               float(extents[k])))
        reach = np.cumsum(lengths[::-1])[::-1] + self.min_radius
        return float(np.sqrt(np.sum(reach**2)))

    def _shape_extents(self, finger: int) -> Array:
        """``e_k`` ``(n,)``: the largest distance of a point of link ``k``'s URDF shapes (the last
        link: with the links fixed beyond it) from the link's joint, bounded per shape (a box or
        hull by its vertices, a sphere, cylinder or capsule by its bounding sphere); cached."""
        got = self._cache.get(("extents", finger))
        if got is None:
            got = self._cache[("extents", finger)] = self._compute_extents(finger)
        return np.asarray(got)

    def _compute_extents(self, finger: int) -> Array:
        f = self.hand.fingers[finger]
        q = self.hand.q0
        names = f.body_names()
        out = np.zeros(f.n_joints)
        for m in range(len(names)):
            k = min(m, f.n_joints - 1)
            local = self.geometry.local_shapes(finger, m)
            R_m, p_m = self.hand.body_pose(BodyRef(names[m], finger, m), q)
            o_k = self.hand.body_pose(BodyRef(names[k], finger, k), q)[1]
            for g, R, t in local or []:
                centre = np.asarray(p_m) + np.asarray(R_m) @ t  # (3,) world
                name = type(g).__name__
                if name == "Sphere":
                    e = float(np.linalg.norm(centre - o_k)) + float(g.radius)
                elif name == "Cylinder":
                    e = float(np.linalg.norm(centre - o_k)) + float(np.hypot(g.radius, g.halfLength))
                elif name == "Capsule":
                    e = float(np.linalg.norm(centre - o_k)) + float(g.halfLength + g.radius)
                else:  # a box (its corners) or a convex hull (its vertices)
                    if name == "Box":
                        h = np.asarray(g.halfSide, dtype=float)
                        V = np.array(list(itertools.product(*[(-x, x) for x in h])))  # (8, 3)
                    else:
                        V = np.asarray(g.points(), dtype=float)  # (k, 3)
                    W = centre + (V @ R.T) @ np.asarray(R_m).T  # (k, 3) world
                    e = float(np.linalg.norm(W - o_k, axis=1).max())
                out[k] = max(out[k], e)
        return out


def path_clearance_certified(
    model: CollisionModel,
    finger: int,
    q_full: Array,
    path: Array,  # (n, m) joint waypoints of the finger
    position: Array,
    rotation: Array,
    touching_last: Sequence[BodyRef] = (),
    touch_from: int | None = None,
    allowance: Array | None = None,
) -> tuple[bool, float, int]:
    """Check the whole polyline ``path`` (not only its samples). A configuration with clearance
    ``c >= 0`` is clear within ``c / K`` of it in joint space (``|dx| <= K |dq|``,
    :meth:`CollisionModel.lipschitz`), so two checked configurations ``h`` apart on a segment
    certify the part between them when ``c_a + c_b >= K h``, or when ``h <= DENSE_STEP`` (the
    floor of the dense check). Each segment is bisected from its two ends: every part not yet
    certified is halved and its middle checked, the middles of one round all at once
    (:meth:`CollisionModel.finger_clearances`), until every part is certified or a configuration
    collides. Segments from waypoint ``touch_from`` on may touch the object with the links
    ``touching_last``.

    Overlaps present at the first waypoint (``allowance``, by default
    :meth:`CollisionModel.start_allowance` there) may persist but not deepen: the clearance
    checked is ``min(term - allowance)`` over every (link, obstacle) term.

    Returns ``(collision_free, smallest clearance checked, configurations checked)``."""
    K = model.lipschitz(finger)
    sl = model.hand.finger_slice(finger)
    q = np.array(q_full, dtype=float)
    if allowance is None and len(path):
        q[sl] = path[0]
        allowance = model.start_allowance(finger, q, position, rotation)
    worst, checks = np.inf, 0
    for s in range(len(path) - 1):
        touching = touching_last if touch_from is not None and s >= touch_from else ()
        p0, p1 = np.asarray(path[s], dtype=float), np.asarray(path[s + 1], dtype=float)
        L = float(np.linalg.norm(p1 - p0))

        def clear(t: Array, p0: Array = p0, p1: Array = p1, L: float = L,
                  touching: Sequence[BodyRef] = touching, floors: Array | None = None) -> Array:
            X = p0[None, :] + (p1 - p0)[None, :] * (t / L if L > 0 else 0.0 * t)[:, None]  # (k, m)
            if floors is not None:
                return model.clearances_below(finger, q, X, floors, position, rotation, allowance, touching)
            return model.finger_clearances(finger, q, X, position, rotation, allowance, touching)

        ends = np.array([0.0, L]) if L > 0 else np.zeros(1)
        c = clear(ends)
        checks += len(c)
        worst = min(worst, float(c.min()))
        if worst < 0.0:
            return False, float(worst), checks
        if L == 0:
            continue
        ta, tb, ca, cb = ends[:1], ends[1:], c[:1], c[1:]  # the parts not yet certified
        while True:
            open_ = (ca + cb < K * (tb - ta)) & (tb - ta > DENSE_STEP)
            if not open_.any():
                break
            ta, tb, ca, cb = ta[open_], tb[open_], ca[open_], cb[open_]
            tm = 0.5 * (ta + tb)
            # a middle clearance at least `floor` leaves `worst` as it is and certifies both halves
            # (ca + cm >= K (tm - ta), cm + cb >= K (tb - tm), 1e-9 above the sums' rounding):
            # its exact value is needed only below it (CollisionModel.clearances_below)
            floor = np.maximum(np.maximum(K * (tm - ta) - ca, K * (tb - tm) - cb) + 1e-9, worst)
            cm = clear(tm, floors=floor)
            checks += len(cm)
            worst = min(worst, float(cm.min()))
            if worst < 0.0:
                return False, float(worst), checks
            ta, tb = np.concatenate([ta, tm]), np.concatenate([tm, tb])
            ca, cb = np.concatenate([ca, cm]), np.concatenate([cm, cb])
    return True, float(worst), checks
