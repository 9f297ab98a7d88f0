"""Configuration-space paths inside a contact state: finger transfers (OMPL) and object motions.

* **Collision model.** Every finger link is a capsule around its
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
* **Overlaps at the start of a motion.** A grasp given by the scene may have capsules that
  overlap slightly (the Allegro example: the middle and ring links 0.3 mm into the object with
  the inflated radius, two non-adjacent thumb links 3 mm into each other, because the link
  radius is a coarse stand-in for the real geometry). Every motion (retreat, transfer, object
  motion, and the certificate of :func:`path_clearance_certified`) takes the overlaps present at
  its first configuration as an allowance (:meth:`CollisionModel.start_allowance`, per pair):
  such a pair may keep its overlap or reduce it but never deepen it; every other pair must stay
  collision-free as before. Without overlaps at the start the check is unchanged.
* **Transfer** (regrasp D -> F, eq. 33 with ``dr = 0``): inverse kinematics for the fingertip at
  a contact point on the object surface, approaching along the normal (scene serial chains:
  CasADi/IPOPT; URDF fingers: :func:`numeric_ik`, damped least squares on the pinocchio point
  Jacobians within the URDF joint limits); OMPL (RRTConnect, seeded, bounded by the joint
  limits) plans from the finger's configuration to a pre-contact configuration ``clearance``
  outside the surface; the last approach is a joint-space segment on which only the tip may
  touch. :func:`path_clearance_certified` then checks every path with a Lipschitz certificate
  (every configuration, not only samples, is collision-free: the clearance at a sample bounds
  how far the joints may move before a capsule can touch), falling back to 1 mm steps where the
  clearance is tiny.
* **Object motion** (eq. 30-32) on ``A_c [dq; dr] = 0``: the analysis fixes the start, the
  direction (a DAFC member) and the finger motion ``dq`` chosen by (31);
  :func:`integrate_object_motion` follows them in small steps, each projected back onto the
  contact manifold (Gauss-Newton on ``q``: each F-point's body point coincides with its object
  point), which gives the end configuration (the D-contacts separated by the planned clearance).
  :func:`plan_object_motion` then plans the path between the two ends with OMPL's constrained
  planning: a ``ProjectedStateSpace`` over ``x = [q; s]`` (hand configuration and object
  displacement) with the constraint :class:`ContactManifold` (the F-points stay together, exactly,
  not only to first order), ``RRTConnect`` whose motions are manifold geodesics checked for joint
  limits and collisions, and the solution densified on the manifold until no joint moves more than
  :data:`DENSE_STEP` between checked states, each of which is checked again.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import shape_signed_distance
from analysis.kinematics import BodyRef, HandKinematics, SerialChain, segment_distance
from analysis.rotations import rotvec_to_matrix, skew
from analysis.scene import Box, Disk, Scene, Segment, Sphere
from planner.state import GraspContact, GraspState

#: Joint-space step (rad) of the dense collision check required by the issue: 1 mm of joint motion.
DENSE_STEP = 1e-3
#: Fraction of a link starting at the finger's base joint that is not checked against fixed bodies
#: (the joint housing is mounted on the palm).
BASE_TRIM = 0.15
_EYE3 = np.eye(3)


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
        qd = np.abs(P - c) - h
        sd = np.linalg.norm(np.maximum(qd, 0.0), axis=1) + np.minimum(qd.max(axis=1), 0.0)
        return float(sd.min())
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


def _shape_segments_distance(shape: object, A: Array, B: Array, dim: int, step: float) -> Array:
    """Signed distances ``(N,)`` from the segments ``[A[i], B[i]]`` (shape frame, ``(N, dim)``)
    to a shape: :func:`_shape_segment_distance` vectorised over the segments (boxes: sampled at
    most ``step`` apart along every segment)."""
    if isinstance(shape, Disk | Sphere):
        ab = B - A
        L2 = np.einsum("ij,ij->i", ab, ab)
        t = np.clip(-np.einsum("ij,ij->i", A, ab) / np.where(L2 > 0.0, L2, 1.0), 0.0, 1.0)
        t = np.where(L2 > 0.0, t, 0.0)
        return np.linalg.norm(A + t[:, None] * ab, axis=1) - shape.radius
    if isinstance(shape, Segment):
        p0, p1 = (np.broadcast_to(np.asarray(p, float)[:dim], A.shape) for p in shape.points)
        return segment_segment_distances(A, B, p0, p1)
    if isinstance(shape, Box):
        c = np.asarray(shape.position if shape.position is not None else np.zeros(dim), dtype=float)[:dim]
        h = np.asarray(shape.size, dtype=float)[:dim] / 2.0
        return _box_segments_distance(c, h, A, B, step)
    return np.array([_shape_segment_distance(shape, a, b, dim, step) for a, b in zip(A, B, strict=True)])


@functools.lru_cache(maxsize=256)
def _unit_samples(n: int) -> Array:
    """``linspace(0, 1, n)`` (cached; never modified)."""
    return np.linspace(0.0, 1.0, n)


def _box_sd(P: Array, c: Array, h: Array) -> Array:
    qd = np.abs(P - c) - h
    out = np.maximum(qd, 0.0)
    return np.sqrt((out * out).sum(axis=-1)) + np.minimum(qd.max(axis=-1), 0.0)


def _box_segments_distance(c: Array, h: Array, A: Array, B: Array, step: float, coarse: int = 17) -> Array:
    """Signed distances ``(N,)`` from the segments ``[A[i], B[i]]`` to the box of centre ``c`` and
    half-extents ``h``, sampled at most ``step`` apart near the minimum. The signed distance to a
    convex set is convex along a segment, so its minimum lies within one coarse interval of the
    best of ``coarse`` evenly spaced samples; only those two intervals are sampled finely."""
    D = B - A
    L = float(np.sqrt((D * D).sum(axis=1).max())) if len(A) else 0.0
    n = max(2, int(np.ceil(L / step)) + 1)
    if n <= 2 * coarse:  # short segments: sample them whole
        T = _unit_samples(n)
        return _box_sd(A[:, None, :] + T[None, :, None] * D[:, None, :], c, h).min(axis=1)
    T = _unit_samples(coarse)
    k = _box_sd(A[:, None, :] + T[None, :, None] * D[:, None, :], c, h).argmin(axis=1)
    lo, hi = T[np.maximum(k - 1, 0)], T[np.minimum(k + 1, coarse - 1)]
    nf = max(2, int(np.ceil(2.0 * L / (coarse - 1) / step)) + 1)
    tf = lo[:, None] + _unit_samples(nf)[None, :] * (hi - lo)[:, None]  # (N, nf)
    return _box_sd(A[:, None, :] + tf[:, :, None] * D[:, None, :], c, h).min(axis=1)


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
    rot_K: list[tuple[Array, Array]] | None  # serial chains: (K, K @ K) of every joint axis


@dataclass(frozen=True)
class CollisionModel:
    """Capsule model of the hand against the object, the fixed bodies and the other fingers."""

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
        from analysis.geometry import object_size

        r = 0.01 * object_size(scene) if min_radius is None else min_radius
        everyone = frozenset((i, j) for i in range(len(hand.fingers)) for j in range(i + 1, len(hand.fingers)))
        model = cls(scene, hand, r, r, everyone, frozenset())
        apart = frozenset((i, j) for (i, j) in everyone if model.fingers_distance(i, j, hand.q0) >= 0.0)
        mounted = frozenset(
            (f, k) for f in range(len(hand.fingers)) for k, (a, b) in model.segments(f, hand.q0).items()
            if scene.fixed_bodies and model._fixed_clearance(f, k, a, b) < 0.0
        )
        return cls(scene, hand, r, r, apart, mounted)

    def fingers_distance(self, i: int, j: int, q: Array) -> float:
        """Smallest clearance between the capsules of fingers ``i`` and ``j``."""
        best = np.inf
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
        r = max(self.hand.body_radius(ref), self.min_radius)
        return r + (self.sample_step / 2.0 if inflate else 0.0)

    def object_distance(self, a: Array, b: Array, position: Array, rotation: Array) -> float:
        """Signed distance from a world segment to the object at the given pose."""
        d = self.scene.dim
        R = rotation[:d, :d]
        la, lb = R.T @ (a[:d] - position), R.T @ (b[:d] - position)
        return _shape_segment_distance(self.scene.object.shape, la, lb, d, self.sample_step)

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
        term: an overlap that exists at the start of a motion may persist but not grow."""
        terms = self.clearance_terms(finger, q, position, rotation, touching)
        if allowance is not None:
            terms = terms - allowance
        return float(terms.min()) if terms.size else float(np.inf)

    def start_allowance(self, finger: int, q: Array, position: Array, rotation: Array) -> Array:
        """The overlaps ``min(0, term)`` of :meth:`clearance_terms` at the start ``q`` of a motion
        (no link touching): a motion may keep them but not deepen them (see the module notes)."""
        return np.minimum(0.0, self.clearance_terms(finger, q, position, rotation))

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
        od = _shape_segments_distance(self.scene.object.shape, (A - pos) @ R, (B - pos) @ R, d, self.sample_step)
        # a link beyond the last joint (a URDF tip link) is the end of the last capsule
        touch = np.zeros(n, dtype=bool)
        for t in touching:
            if t.finger == finger and t.link is not None:
                touch[min(int(t.link), n - 1)] = True
        parts = [np.where(touch, np.maximum(0.0, od - fd.r_true + 1e-9), od - fd.r_infl)]
        fixed = np.full(n, np.inf)
        if fd.any_fixed:
            D = B - A
            L = np.sqrt((D * D).sum(axis=1))
            Ab = A - fd.base
            at_base = (Ab * Ab).sum(axis=1) < 1e-18
            trim = np.maximum(3.0 * fd.r_infl, BASE_TRIM * L)
            skip = at_base & (2.0 * trim >= L)
            A2 = np.where(at_base[:, None], A + D * (trim / np.where(L > 0, L, 1.0))[:, None], A)
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
            parts.append(segment_segment_distances(S0[i], S1[i], S0[j], S1[j]) - fd.pair_radii)
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
            for j in range(len(self.hand.fingers)):
                if j != finger and (min(j, finger), max(j, finger)) in self.finger_pairs:
                    radii.append(np.array([self.radius(r) for r in self.links(j)]))
            stacked = np.concatenate(radii)
            pairs = [(i, j) for i in range(n) for j in range(i + 2, n)]
            pairs += [(i, j) for i in range(n) for j in range(n, len(stacked))]
            pa = np.array(pairs, dtype=int).reshape(-1, 2)
            fixed_checked = np.array([bool(self.scene.fixed_bodies) and (finger, k) not in self.mounted
                                      for k in range(n)], dtype=bool)
            got = _FingerData(
                refs,
                r_infl,
                np.array([self.hand.body_radius(r) for r in refs]),
                fixed_checked,
                bool(fixed_checked.any()),
                np.asarray(chain.body_pose(0, self.hand.q0[sl])[1][: self.scene.dim], dtype=float),
                pa,
                stacked[pa[:, 0]] + stacked[pa[:, 1]],
                rot_K,
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
                for k in [k for k in self._cache if k[0] == "segs"]:
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
        ``K = sqrt(sum_j R_j^2)`` with ``R_j`` the reach of the finger beyond joint ``j``."""
        f = self.hand.fingers[finger]
        q = self.hand.q0[self.hand.finger_slice(finger)]
        lengths = []
        for k in range(f.n_joints):
            a, b = f.body_segment(k, q)
            lengths.append(float(np.linalg.norm(b - a)) + float(np.linalg.norm(a - f.body_pose(k, q)[1])))
        reach = np.cumsum(lengths[::-1])[::-1] + self.min_radius
        return float(np.sqrt(np.sum(reach**2)))


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
    """Check the whole polyline ``path`` (not only its samples): from each checked configuration
    the next one is at most ``clearance / K`` away in joint space (so every configuration in
    between is collision-free), never less than :data:`DENSE_STEP`. Segments from waypoint
    ``touch_from`` on may touch the object with the links ``touching_last``.

    Overlaps present at the first waypoint (``allowance``, by default
    :meth:`CollisionModel.start_allowance` there) may persist but not deepen: the clearance
    checked is ``min(term - allowance)`` over every (link, obstacle) term.

    Returns ``(collision_free, smallest clearance, configurations checked)``."""
    K = model.lipschitz(finger)
    sl = model.hand.finger_slice(finger)
    q = np.array(q_full, dtype=float)
    if allowance is None and len(path):
        q[sl] = path[0]
        allowance = model.start_allowance(finger, q, position, rotation)
    worst, checks = np.inf, 0
    for s in range(len(path) - 1):
        touching = touching_last if touch_from is not None and s >= touch_from else ()
        p0, p1 = path[s], path[s + 1]
        L = float(np.linalg.norm(p1 - p0))
        t = 0.0
        while True:
            q[sl] = p0 + (p1 - p0) * (t / L if L > 0 else 0.0)
            c = model.finger_clearance(finger, q, position, rotation, touching, allowance)
            checks += 1
            worst = min(worst, c)
            if c < 0.0:
                return False, worst, checks
            if t >= L:
                break
            t = min(L, t + max(DENSE_STEP, c / K))
    return True, float(worst), checks


# --------------------------------------------------------------------------------------------
# Inverse kinematics (CasADi / IPOPT)


def _chain_tip_symbolic(chain: SerialChain, q: Any) -> tuple[Any, Any]:
    """World tip position and the direction of the last link, as CasADi expressions."""
    R: Any = ca.DM(chain.base_R)
    p: Any = ca.DM(chain.base_p)
    for j in range(chain.n_joints):
        p = p + R @ ca.DM(chain.origins[j])
        a = chain.axes[j]
        K = ca.DM([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        R = R @ (ca.DM.eye(3) + ca.sin(q[j]) * K + (1 - ca.cos(q[j])) * (K @ K))
    tip = p + R @ ca.DM(chain.tip)
    return tip, R @ ca.DM(chain.tip / max(float(np.linalg.norm(chain.tip)), 1e-12))


_IK_SOLVERS: dict[int, tuple[SerialChain, Any]] = {}


def _ik_solver(chain: SerialChain, dim: int) -> Any:
    """The CasADi/IPOPT problem of :func:`fingertip_ik` for one chain (built once, parametric in the
    seed, the target and the normal)."""
    got = _IK_SOLVERS.get(id(chain))
    if got is not None and got[0] is chain:
        return got[1]
    n = chain.n_joints
    q = ca.SX.sym("q", n)
    tip, axis = _chain_tip_symbolic(chain, q)
    q0 = ca.SX.sym("q0", n)
    target = ca.SX.sym("target", dim)
    normal = ca.SX.sym("normal", dim)
    g = ca.vertcat(tip[:dim] - target, ca.dot(axis[:dim], normal))
    nlp = {"x": q, "p": ca.vertcat(q0, target, normal), "f": ca.sumsqr(q - q0), "g": g}
    opts: dict[str, Any] = {"ipopt.print_level": 0, "print_time": False, "ipopt.max_iter": 200, "ipopt.tol": 1e-10,
            "ipopt.sb": "yes"}
    solver = ca.nlpsol("ik", "ipopt", nlp, opts)
    _IK_SOLVERS[id(chain)] = (chain, solver)
    return solver


def joint_limits(hand: HandKinematics, finger: int) -> tuple[Array, Array]:
    """Lower and upper joint limits ``(n,)`` of a finger (a URDF finger's ``lower``/``upper``;
    unbounded for scene serial chains)."""
    chain = hand.fingers[finger]
    n = chain.n_joints
    lo = getattr(chain, "lower", None)
    hi = getattr(chain, "upper", None)
    lo_a = np.full(n, -np.inf) if lo is None else np.asarray(lo, dtype=float)
    hi_a = np.full(n, np.inf) if hi is None else np.asarray(hi, dtype=float)
    return lo_a, hi_a


def numeric_ik(
    hand: HandKinematics,
    finger: int,
    target: Array,  # (d,)
    normal: Array,  # (d,) unit, into the object
    seed: Array,  # (n,)
    min_alignment: float = 0.5,
    iters: int = 200,
    damping: float = 1e-3,
) -> Array | None:
    """Inverse kinematics of any :class:`~analysis.kinematics.FingerModel` from its point
    Jacobians: damped least squares from ``seed`` on the tip position (the end of the last link's
    axis) at ``target``, with one more row raising the alignment ``u . normal`` of the last link
    (unit axis ``u``) while it is below ``min_alignment + 0.05``; every iterate is clipped to the
    joint limits (:func:`joint_limits`). Returns the joints ``(n,)`` or ``None`` if it does not
    converge (tip error above 1e-9 or alignment below ``min_alignment``)."""
    chain = hand.fingers[finger]
    d = hand.dim
    k = chain.n_joints - 1
    lo, hi = joint_limits(hand, finger)
    q = np.clip(np.asarray(seed, dtype=float), lo, hi)
    target = np.asarray(target, dtype=float)[:d]
    normal = np.asarray(normal, dtype=float)[:d]
    for _ in range(iters):
        a, b = chain.body_segment(k, q)
        a, b = a[:d], b[:d]
        L = float(np.linalg.norm(b - a))
        u = (b - a) / max(L, 1e-12)
        err = target - b
        align = float(u @ normal)
        if float(np.linalg.norm(err)) < 1e-9 and align >= min_alignment - 1e-9:
            return q
        Jb = chain.point_jacobian(k, np.r_[b, np.zeros(3 - d)] if d < 3 else b, q)[:d]
        rows, errs = [Jb], [err]
        if align < min_alignment + 0.05 and L > 1e-9:
            Ja = chain.point_jacobian(k, np.r_[a, np.zeros(3 - d)] if d < 3 else a, q)[:d]
            du = (np.eye(d) - np.outer(u, u)) @ (Jb - Ja) / L  # (d, n)
            rows.append((normal @ du)[None, :])
            errs.append(np.array([min_alignment + 0.1 - align]))
        J = np.vstack(rows)
        e = np.concatenate(errs)
        dq = J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(J.shape[0]), e)
        nrm = float(np.linalg.norm(dq))
        if nrm > 0.3:
            dq *= 0.3 / nrm
        q = np.clip(q + dq, lo, hi)
    a, b = chain.body_segment(k, q)
    u = (b[:d] - a[:d]) / max(float(np.linalg.norm(b[:d] - a[:d])), 1e-12)
    if float(np.linalg.norm(target - b[:d])) < 1e-9 and float(u @ normal) >= min_alignment - 1e-9:
        return q
    return None


def fingertip_ik(
    hand: HandKinematics,
    finger: int,
    target: Array,  # (d,) world point on the object surface
    normal: Array,  # (d,) unit, into the object
    seeds: Sequence[Array],
    min_alignment: float = 0.5,
) -> list[Array]:
    """Joint configurations ``(n,)`` of ``finger`` whose tip is at ``target`` with the last link
    pointing into the object (``link direction . normal >= min_alignment``), closest to each seed.

    Serial chains of the scene: CasADi/IPOPT, ``min |q - seed|^2`` subject to those constraints.
    Any other finger (URDF, evaluated by pinocchio): :func:`numeric_ik` (damped least squares on
    the point Jacobians, within the joint limits)."""
    chain = hand.fingers[finger]
    d = hand.dim
    out: list[Array] = []
    if not isinstance(chain, SerialChain):
        for s in seeds:
            x = numeric_ik(hand, finger, target, normal, np.asarray(s, dtype=float), min_alignment)
            if x is not None and all(np.linalg.norm(x - o) > 1e-6 for o in out):
                out.append(x)
        return out
    solver = _ik_solver(chain, d)
    lbg = np.r_[np.zeros(d), min_alignment]
    ubg = np.r_[np.zeros(d), np.inf]
    for s in seeds:
        s = np.asarray(s, dtype=float)
        sol = solver(x0=s, p=np.r_[s, target[:d], normal[:d]], lbg=lbg, ubg=ubg)
        if not solver.stats()["success"]:
            continue
        qs = np.asarray(sol["x"]).ravel()
        qs = s + ((qs - s + np.pi) % (2 * np.pi) - np.pi)  # nearest equivalent to the seed
        if all(np.linalg.norm(qs - o) > 1e-6 for o in out):
            out.append(qs)
    return out


# --------------------------------------------------------------------------------------------
# OMPL transfer


@dataclass(frozen=True)
class TransferPath:
    """A finger's collision-free transfer to a new contact."""

    finger: int
    waypoints: Array  # (n, m) joint configurations of the finger, last one touching
    length: float  # joint-space length
    clearance: float  # smallest clearance along the free part
    checks: int
    ompl_seconds: float


def plan_transfer(
    model: CollisionModel,
    state: GraspState,
    finger: int,
    q_goal: Array,  # (m,) touching configuration of the finger
    tip_ref: BodyRef,
    approach: float,
    seed: int = 0,
    time_limit: float = 1.0,
) -> TransferPath | None:
    """Plan a collision-free joint path (OMPL RRTConnect, seeded) from the finger's configuration
    in ``state`` to ``q_goal``, through a pre-contact configuration backed off by ``approach``
    (scene units) along the normal. ``None`` when no certified path is found."""
    import time

    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    hand = model.hand
    sl = hand.finger_slice(finger)
    m = sl.stop - sl.start
    q_full = state.q.copy()
    pos, rot = state.position, state.rotation
    allow = model.start_allowance(finger, q_full, pos, rot)  # overlaps at the start may not deepen
    # pre-contact: back the joints off along the last link until the clearance is positive
    q_pre = _back_off(model, finger, q_full, q_goal, tip_ref, approach, pos, rot, allow)
    if q_pre is None:
        return None
    start = state.q[sl]
    j_lo, j_hi = joint_limits(hand, finger)

    def valid_q(x: Array) -> bool:
        if np.any(x < j_lo - 1e-9) or np.any(x > j_hi + 1e-9):
            return False
        qq = q_full.copy()
        qq[sl] = x
        return model.finger_clearance(finger, qq, pos, rot, (), allow) >= 0.0

    if not valid_q(start):
        return None
    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)
    space = ob.RealVectorStateSpace(m)
    bounds = ob.RealVectorBounds(m)
    lo = np.maximum(np.minimum(start, q_pre) - np.pi, np.minimum(j_lo, np.minimum(start, q_pre)))
    hi = np.minimum(np.maximum(start, q_pre) + np.pi, np.maximum(j_hi, np.maximum(start, q_pre)))
    for j in range(m):
        bounds.setLow(j, float(lo[j]))
        bounds.setHigh(j, float(hi[j]))
    space.setBounds(bounds)
    s0, s1 = space.allocState(), space.allocState()
    for j in range(m):
        s0[j] = float(start[j])
        s1[j] = float(q_pre[j])
    extent = max(1e-9, float(np.linalg.norm(hi - lo)))
    t0 = time.perf_counter()
    # coarse collision checks while planning (0.05 rad), then the certificate; once more with
    # fine checks (0.01 rad) if the certificate rejects the coarse path
    for resolution in (0.05, 0.01):
        ss = og.SimpleSetup(space)
        ss.setStateValidityChecker(lambda s: valid_q(np.array([s[j] for j in range(m)])))
        si = ss.getSpaceInformation()
        si.setStateValidityCheckingResolution(resolution / extent)
        ss.setStartAndGoalStates(s0, s1)
        ss.setPlanner(og.RRTConnect(si))
        status = ss.solve(time_limit)
        if not bool(status) or not ss.haveExactSolutionPath():
            return None
        ss.simplifySolution(min(0.5, time_limit))
        p = ss.getSolutionPath()
        free = np.array([[p.getState(i)[j] for j in range(m)] for i in range(p.getStateCount())])
        waypoints = np.vstack([free, q_goal[None, :]])
        ok, clear, checks = path_clearance_certified(
            model, finger, q_full, waypoints, pos, rot, touching_last=[tip_ref], touch_from=len(free) - 1,
            allowance=allow,
        )
        if ok:
            break
    else:
        return None
    dt = time.perf_counter() - t0
    length = float(np.sum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1)))
    return TransferPath(finger, waypoints, length, clear, checks, dt)


def _back_off(
    model: CollisionModel,
    finger: int,
    q_full: Array,
    q_goal: Array,
    tip_ref: BodyRef,
    approach: float,
    pos: Array,
    rot: Array,
    allowance: Array | None = None,
) -> Array | None:
    """A configuration near ``q_goal`` whose tip is ``approach`` back along the tip's velocity
    that leaves the surface (least-squares step on the tip Jacobian) and that is collision-free."""
    hand = model.hand
    sl = hand.finger_slice(finger)
    qq = q_full.copy()
    qq[sl] = q_goal
    a, b = hand.body_segment(tip_ref, qq)
    u = (b - a) / max(float(np.linalg.norm(b - a)), 1e-12)  # last link direction, into the object
    for scale in (1.0, 2.0, 4.0):
        x = qq.copy()
        for _ in range(20):  # move the tip back along -u by `approach * scale`
            tip = hand.body_segment(tip_ref, x)[1]
            err = (b - approach * scale * u) - tip
            if np.linalg.norm(err) < 1e-9:
                break
            J = hand.point_jacobian(tip_ref, tip, x)[:, sl]
            x[sl] = np.clip(x[sl] + np.linalg.lstsq(J, err, rcond=None)[0], *joint_limits(hand, finger))
        if model.finger_clearance(finger, x, pos, rot, (), allowance) > 0.0:
            return np.asarray(x[sl])
    return None


# --------------------------------------------------------------------------------------------
# Object motion on the contact manifold


@dataclass(frozen=True)
class ObjectMotion:
    """An integrated object motion: hand and object paths, the final contacts."""

    q_path: Array  # (n, M)
    pose_path: Array  # (n, D) pose vectors
    separations: Array  # (#D,) final gap of each separating contact
    length: float  # object path length (pose-vector norm)
    max_residual: float  # largest contact-constraint residual after projection


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
    d = state.dim
    pos = state.position + pose_step[:d]
    if d == 2:
        from analysis.rotations import rotz

        R = rotz(float(pose_step[2])) @ state.rotation
    else:
        R = rotvec_to_matrix(pose_step[3:]) @ state.rotation
    return GraspState(state.contacts, state.q, pos, R, d)


@dataclass(frozen=True)
class _MotionCheck:
    """Validity of hand configurations during an object motion that starts at ``state``: joint
    limits, and collisions with the contact links (``busy``) allowed to touch the object and the
    overlaps present at the start allowed to persist (:meth:`CollisionModel.start_allowance`)."""

    model: CollisionModel
    touching: list[list[BodyRef]]  # per finger
    allow: list[Array]  # per finger
    limits: list[tuple[Array, Array]]  # per finger

    @classmethod
    def of(cls, model: CollisionModel, state: GraspState, busy: Sequence[int]) -> _MotionCheck:
        hand = model.hand
        refs = [hand.resolve_body(state.contacts[i].body) for i in busy]
        F = range(len(hand.fingers))
        return cls(model, [[b for b in refs if b is not None and b.finger == f] for f in F],
                   [model.start_allowance(f, state.q, state.position, state.rotation) for f in F],
                   [joint_limits(hand, f) for f in F])

    def __call__(self, q: Array, position: Array, rotation: Array) -> bool:
        hand = self.model.hand
        for f in range(len(hand.fingers)):
            qf = q[hand.finger_slice(f)]
            if np.any(qf < self.limits[f][0] - 1e-9) or np.any(qf > self.limits[f][1] + 1e-9):
                return False
            if self.model.finger_clearance(f, q, position, rotation, self.touching[f], self.allow[f]) < -1e-9:
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
) -> ObjectMotion | None:
    """Move the object by ``distance`` along ``dr`` with the fingers along ``dq``, projecting on
    the sticking contacts after every step; ``None`` if a link would penetrate the object or a
    separating contact would not separate. With ``check_path = False`` only the end configuration
    is checked for collisions (the path is then planned by :func:`plan_object_motion`).

    ``sliding`` contacts (S or N; disk and sphere objects) keep touching while they slide: the
    object then follows the projection of ``[q; s] + h [dq; dr]`` onto :class:`ContactManifold`
    (minimum-norm Newton steps on hand and object together), not exactly the straight line."""
    hand = model.hand
    man = ContactManifold(hand, state, sticking, sliding, model.scene) if sliding else None
    x = np.concatenate([state.q, np.zeros(len(dr))])
    h = distance / steps
    cur = state
    q = state.q.copy()
    qs, poses = [q.copy()], [state.pose_vector()]
    worst_res = 0.0
    valid = _MotionCheck.of(model, state, (*sticking, *separating, *sliding))
    for _ in range(steps):
        if man is None:
            cur = moved(cur, h * dr)
            q, res = project_contacts(hand, cur, q + h * dq, sticking)
        else:
            x, res = project_manifold(man, x + h * np.concatenate([dq, dr]))
            q = x[: hand.M]
            pos, R = man.pose(x[hand.M:])
            cur = GraspState(cur.contacts, q, pos, R, cur.dim)
        worst_res = max(worst_res, res)
        if res > 1e-6:
            return None
        cur = GraspState(cur.contacts, q, cur.position, cur.rotation, cur.dim)
        qs.append(q.copy())
        poses.append(cur.pose_vector())
        if not check_path and len(qs) <= steps:
            continue
        if not valid(q, cur.position, cur.rotation):
            return None
    seps = []
    for i in separating:
        c = state.contacts[i]
        ref = hand.resolve_body(c.body)
        assert ref is not None
        x = hand.point_position(ref, c.point_body, q)
        local = cur.rotation[: cur.dim, : cur.dim].T @ (x - cur.position)
        sd = shape_signed_distance(model.scene.object.shape, local, cur.dim)
        seps.append(np.inf if sd is None else sd)
    seps_a = np.array(seps, dtype=float)
    if len(seps_a) and np.any(seps_a <= 0.0):
        return None
    length = float(np.sum(np.linalg.norm(np.diff(np.array(poses), axis=0), axis=1)))
    return ObjectMotion(np.array(qs), np.array(poses), seps_a, length, worst_res)


def project_manifold(man: ContactManifold, x: Array, tolerance: float = 1e-11, iters: int = 50) -> tuple[Array, float]:
    """Newton projection of ``x`` ``(M + D,)`` onto ``F(x) = 0`` with minimum-norm steps (the
    pseudo-inverse of ``F'``, as OMPL's ``ProjectedStateSpace`` projects); returns the point and
    ``|F|`` there."""
    x = np.array(x, dtype=float)
    res = 0.0
    for _ in range(iters):
        F = man.function(x)
        res = float(np.linalg.norm(F))
        if res <= tolerance:
            break
        x = x - np.linalg.lstsq(man.jacobian(x), F, rcond=None)[0]
    return x, res


def keep_contacts(state: GraspState, keep: Sequence[int], q: Array, pose: GraspState) -> GraspState:
    """The state after a motion: only the contacts ``keep``, configuration ``q``, pose of ``pose``."""
    contacts: tuple[GraspContact, ...] = tuple(state.contacts[i] for i in keep)
    return GraspState(contacts, np.asarray(q, float), pose.position, pose.rotation, state.dim)


# --------------------------------------------------------------------------------------------
# Object motion: OMPL constrained planning on the contact manifold


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
    of eq. 7 do not move relative to each other), and for every sliding contact (S or N, disks and
    spheres only) the gap between the body's surface and the object's, which is zero while it
    slides (eq. 5: only the normal component is constrained). The Jacobian is ``[J_c, -G^T]`` in
    these coordinates, so ``F'(x) [dq; ds] = 0`` at ``s = 0`` is ``A_c [dq; dr] = 0`` (eq. 7, 19)."""

    def __init__(self, hand: HandKinematics, state: GraspState, sticking: Sequence[int],
                 sliding: Sequence[int] = (), scene: Scene | None = None):
        self.hand, self.state, self.dim = hand, state, state.dim
        self.M, self.D = hand.M, 3 if state.dim == 2 else 6
        self.items: list[tuple[BodyRef | None, Array, Array]] = []  # (finger body or None, point_body, point_obj)
        for i in sticking:
            c = state.contacts[i]
            ref = hand.resolve_body(c.body)
            assert ref is not None
            if ref.finger is None:  # a fixed body: its (world) point stays where it is
                self.items.append((None, state.world_point(i), np.asarray(c.point_object, float)))
            else:
                self.items.append((ref, np.asarray(c.point_body, float), np.asarray(c.point_object, float)))
        self.sliding: list[BodyRef] = []
        if sliding:
            if scene is None or not isinstance(scene.object.shape, Disk | Sphere):
                raise SceneError(("object", "shape"), "sliding contacts are followed for disks and spheres only")
            self.scene, self.radius = scene, float(scene.object.shape.radius)
        for i in sliding:
            ref = hand.resolve_body(state.contacts[i].body)
            assert ref is not None
            self.sliding.append(ref)
        self.rows = self.dim * len(self.items) + len(self.sliding)

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

    def sliding_contact(self, k: int, x: Array) -> tuple[Array, Array, Array]:
        """Sliding contact ``k`` at ``x``: body point (world ``(d,)``), object point and inward normal
        (object frame ``(d,)``) where the body touches the disk or sphere."""
        q, s = x[: self.M], x[self.M:]
        pos, R = self.pose(s)
        d = self.dim
        _, u, _ = self.body_distance(self.sliding[k], pos, q)
        y = pos - self.radius * u  # the touching point, on both surfaces when the gap is zero
        Rt = R[:d, :d].T
        return y, Rt @ (y - pos), Rt @ u

    def pose(self, s: Array) -> tuple[Array, Array]:
        """Object position ``(d,)`` and rotation ``(3, 3)`` at displacement ``s``."""
        d = self.dim
        if d == 2:
            from analysis.rotations import rotz

            return self.state.position + s[:2], rotz(float(s[2])) @ self.state.rotation
        return self.state.position + s[:3], rotvec_to_matrix(s[3:]) @ self.state.rotation

    def function(self, x: Array) -> Array:
        q, s = x[: self.M], x[self.M:]
        pos, R = self.pose(s)
        d = self.dim
        out = np.empty(self.rows)
        for k, (ref, pb, po) in enumerate(self.items):
            xb = pb[:d] if ref is None else self.hand.point_position(ref, pb, q)
            out[d * k: d * k + d] = xb - (pos + (R[:d, :d] @ po))
        for k, ref in enumerate(self.sliding):  # S-points: the gap to the disk/sphere is zero
            out[d * len(self.items) + k] = self.body_distance(ref, pos, q)[0] - self.radius
        return out

    def jacobian(self, x: Array) -> Array:
        q, s = x[: self.M], x[self.M:]
        pos_, R = self.pose(s)
        d = self.dim
        J = np.zeros((self.rows, self.M + self.D))  # (d n, M + D)
        for k, (ref, pb, po) in enumerate(self.items):
            r = slice(d * k, d * k + d)
            if ref is not None:
                J[r, : self.M] = self.hand.point_jacobian(ref, self.hand.point_position(ref, pb, q), q)
            J[r, self.M: self.M + d] = -np.eye(d)
            y = R[:d, :d] @ po  # object point relative to p_o, world frame
            if d == 2:
                J[r, self.M + 2] = -np.array([-y[1], y[0]])
            else:
                J[r, self.M + 3:] = skew(y) @ _left_jacobian_so3(s[3:])
        for k, ref in enumerate(self.sliding):  # d gap = u^T (d p_o - J(y) dq); the centre is p_o
            row = d * len(self.items) + k
            _, u, yb = self.body_distance(ref, pos_, q)
            if ref.finger is not None:
                J[row, : self.M] = -u @ self.hand.point_jacobian(ref, yb, q)
            J[row, self.M: self.M + d] = u
        return J


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
    planner_states: int  # states of the solution path before densification
    ompl_seconds: float


def plan_object_motion(
    model: CollisionModel,
    state: GraspState,
    goal: ObjectMotion,
    sticking: Sequence[int],
    separating: Sequence[int],
    seed: int = 0,
    time_limit: float = 1.0,
    tolerance: float = 1e-8,
    sliding: Sequence[int] = (),
) -> ConstrainedObjectMotion | None:
    """Plan the motion of hand and object from ``state`` to the end of ``goal`` (the configuration
    reached along the DAFC direction, :func:`integrate_object_motion`) with OMPL's constrained
    planning: a ``ProjectedStateSpace`` over ``[q; s]`` with the constraint
    :class:`ContactManifold` of the sticking and ``sliding`` contacts (``A_c [dq; dr] = 0``, eq. 7
    and 19, to every order), ``RRTConnect`` (seeded) whose motions are geodesics of the manifold, a validity
    checker for joint limits and collisions (:meth:`CollisionModel.finger_clearance`; the contact
    links may touch the object, overlaps present at the start may not deepen), and the solution
    densified on the manifold until no joint moves more than :data:`DENSE_STEP` between two
    checked states, every one of which is re-checked (constraint residual below
    ``100 * tolerance`` and collision-free). ``None`` if OMPL finds no path or the check fails."""
    import time

    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    hand = model.hand
    man = ContactManifold(hand, state, sticking, sliding, model.scene)
    M, D = man.M, man.D
    n = M + D
    q0, q1 = state.q, goal.q_path[-1]
    s1 = pose_displacement(state, goal.pose_path[-1])
    x0, x1 = np.concatenate([q0, np.zeros(D)]), np.concatenate([q1, s1])
    check = _MotionCheck.of(model, state, (*sticking, *separating, *sliding))
    limits = check.limits

    def valid(x: Array) -> bool:
        return check(x[:M], *man.pose(x[M:]))

    if man.rows == 0 or not valid(x0) or not valid(x1):
        return None
    if float(np.linalg.norm(man.function(x1))) > 100 * tolerance:
        return None

    class _Constraint(ob.Constraint):
        def __init__(self) -> None:
            super().__init__(n, man.rows)

        def function(self, x: Any, out: Any) -> None:
            out[:] = man.function(np.asarray(x))

        def jacobian(self, x: Any, out: Any) -> None:
            out[:, :] = man.jacobian(np.asarray(x))

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)
    constraint = _Constraint()
    constraint.setTolerance(tolerance)
    constraint.setMaxIterations(100)
    rank = int(np.linalg.matrix_rank(man.jacobian(x0), tol=1e-9))
    constraint.setManifoldDimension(n - rank)
    span = np.abs(x1 - x0)
    margin = np.maximum(span, 1e-3)
    lo, hi = np.minimum(x0, x1) - margin, np.maximum(x0, x1) + margin
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
    ss.setStateValidityChecker(lambda st: valid(read(st)))
    a, b = space.allocState(), space.allocState()
    a.copy([float(v) for v in x0])
    b.copy([float(v) for v in x1])
    ss.setStartAndGoalStates(a, b, 1e-9)
    planner = og.RRTConnect(si)
    planner.setRange(max(total, 1e-6))  # try the direct geodesic first
    ss.setPlanner(planner)
    t0 = time.perf_counter()
    status = ss.solve(time_limit)
    if not bool(status) or not ss.haveExactSolutionPath():
        return None
    path = ss.getSolutionPath()
    planner_states = int(path.getStateCount())
    X = np.array([read(path.getState(i)) for i in range(path.getStateCount())])  # (k, n)
    X = _densify(man, X, DENSE_STEP, tolerance)
    dt = time.perf_counter() - t0
    step = float(np.max(np.abs(np.diff(X[:, :M], axis=0)))) if len(X) > 1 else 0.0
    residual = max(float(np.linalg.norm(man.function(x))) for x in X)
    if step > DENSE_STEP or residual > 100 * tolerance or not all(valid(x) for x in X):
        return None
    if float(np.max(np.abs(X[-1] - x1))) > 1e-6:
        return None
    poses = np.array([_pose_vector(man, x[M:]) for x in X])  # (k, D)
    length = float(np.sum(np.linalg.norm(np.diff(poses, axis=0), axis=1)))
    return ConstrainedObjectMotion(X[:, :M], poses, X[:, M:], goal.separations, length, residual, step, len(X),
                                   planner_states, dt)


def _densify(man: ContactManifold, X: Array, max_step: float, tolerance: float) -> Array:
    """Insert states between consecutive states of ``X`` ``(k, M + D)`` so that no joint moves more
    than ``max_step``: points of the ambient segment projected back onto the manifold (Newton steps
    with the pseudo-inverse of ``F'``, as OMPL's projection does)."""
    M = man.M
    out = [X[0]]
    for a, b in itertools.pairwise(X):
        k = int(np.ceil(float(np.max(np.abs(b[:M] - a[:M]))) / max_step * 1.02))
        for t in np.arange(1, k) / max(k, 1):
            out.append(project_manifold(man, a + t * (b - a), tolerance)[0])
        out.append(b)
    return np.array(out)


def pose_displacement(state: GraspState, pose: Array) -> Array:
    """The ambient object coordinates ``s`` of :class:`ContactManifold` of a pose vector."""
    from analysis.rotations import matrix_to_rotvec

    d = state.dim
    if d == 2:
        theta0 = float(np.arctan2(state.rotation[1, 0], state.rotation[0, 0]))
        return np.array([pose[0] - state.position[0], pose[1] - state.position[1], pose[2] - theta0])
    R = rotvec_to_matrix(np.asarray(pose[3:], float))
    return np.concatenate([np.asarray(pose[:3], float) - state.position, matrix_to_rotvec(R @ state.rotation.T)])


def _pose_vector(man: ContactManifold, s: Array) -> Array:
    from analysis.rotations import matrix_to_rotvec

    pos, R = man.pose(s)
    if man.dim == 2:
        return np.array([*pos, float(np.arctan2(R[1, 0], R[0, 0]))])
    return np.concatenate([pos, matrix_to_rotvec(R)])
