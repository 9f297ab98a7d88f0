"""Configuration-space paths inside a contact state: finger transfers (OMPL) and object motions.

* **Collision model.** Every finger link is a capsule around its
  :meth:`~analysis.kinematics.HandKinematics.body_segment` of radius
  ``max(link radius, min_radius)`` (``min_radius``: 1 % of the object size by default, as scene
  links may have radius 0). A configuration of a moving finger is valid when none of its capsules
  penetrates the object, a fixed body (palm, table: link 0 is trimmed near its base joint, which
  is mounted on the palm) or a link of another finger, and its non-adjacent links keep apart.
  Distances to disks and spheres are exact; to boxes and polygons they are evaluated at points
  along the link at most ``min_radius`` apart (so the error is below ``min_radius / 2``, and
  the capsule radius is inflated by that amount). A link starting at its finger's base joint is
  not checked against fixed bodies over its first ``BASE_TRIM`` (15 %) of length (the joint is
  mounted on the palm), and a link that already overlaps a fixed body in the scene as given is
  taken to be mounted on it and not checked against fixed bodies.
* **Transfer** (regrasp D -> F, eq. 33 with ``dr = 0``): inverse kinematics by CasADi/IPOPT for
  the fingertip at a contact point on the object surface, approaching along the normal; OMPL
  (RRTConnect, seeded) plans from the finger's configuration to a pre-contact configuration
  ``clearance`` outside the surface; the last approach is a joint-space segment on which only
  the tip may touch. :func:`path_clearance_certified` then checks every path with a Lipschitz
  certificate (every configuration, not only samples, is collision-free: the clearance at a
  sample bounds how far the joints may move before a capsule can touch), falling back to 1 mm
  steps where the clearance is tiny.
* **Object motion** (eq. 30-32) on ``A_c [dq; dr] = 0``: the motion is prescribed (the DAFC
  direction and the finger motion ``dq`` chosen by (31)), so it is integrated in small steps and
  each step projected back onto the contact manifold (Gauss-Newton on ``q`` for the F-points:
  the body point coincides with the object point). This is the projection OMPL's
  ``ProjectedStateSpace`` performs; a constrained *planner* (a search between two given
  states) has nothing to search here, because the direction and both ends are fixed by the
  analysis.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from analysis._types import Array
from analysis.exceptions import SolverError
from analysis.geometry import shape_signed_distance
from analysis.kinematics import BodyRef, HandKinematics, SerialChain, segment_distance
from analysis.rotations import rotvec_to_matrix
from analysis.scene import Box, Disk, Scene, Segment, Sphere
from planner.state import GraspContact, GraspState

#: Joint-space step (rad) of the dense collision check required by the issue: 1 mm of joint motion.
DENSE_STEP = 1e-3
#: Fraction of a link starting at the finger's base joint that is not checked against fixed bodies
#: (the joint housing is mounted on the palm).
BASE_TRIM = 0.15


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


@dataclass(frozen=True)
class CollisionModel:
    """Capsule model of the hand against the object, the fixed bodies and the other fingers."""

    scene: Scene
    hand: HandKinematics
    min_radius: float
    sample_step: float
    finger_pairs: frozenset[tuple[int, int]]  # (i, j), i < j: pairs of fingers checked against each other
    mounted: frozenset[tuple[int, int]]  # (finger, link) overlapping a fixed body in the scene: not checked

    @classmethod
    def of(cls, scene: Scene, hand: HandKinematics, min_radius: float | None = None) -> CollisionModel:
        """The model of a scene. Fingers whose capsules already overlap in the scene as given are
        taken to move in different layers (a planar hand's fingers stacked in depth, as in the
        paper's Fig. 1) and are not checked against each other; all other pairs are."""
        from analysis.simulate import object_size

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
    ) -> float:
        """Smallest clearance (distance minus capsule radii) of the links of ``finger`` at the hand
        configuration ``q`` ``(M,)``; negative means collision. Links in ``touching`` may touch
        the object with their true radius (their clearance to the object is not counted)."""
        best = np.inf
        touch = {(t.finger, t.link) for t in touching}
        own = self.links(finger)
        segs = self.segments(finger, q)
        for ref in own:
            a, b = segs[ref.link]
            r = self.radius(ref)
            if (ref.finger, ref.link) not in touch:
                best = min(best, self.object_distance(a, b, position, rotation) - r)
            else:  # touching: the link axis may not sink deeper than the true radius
                best = min(best, max(0.0, self.object_distance(a, b, position, rotation)
                                     - self.hand.body_radius(ref) + 1e-9))
            if self.scene.fixed_bodies and (finger, ref.link) not in self.mounted:
                best = min(best, self._fixed_clearance(finger, ref.link, a, b))
        for k1 in own:  # non-adjacent links of the same finger
            for k2 in own:
                if k2.link >= k1.link + 2:
                    a1, b1 = segs[k1.link]
                    a2, b2 = segs[k2.link]
                    best = min(best, segment_segment_distance(a1, b1, a2, b2) - self.radius(k1) - self.radius(k2))
        for j in range(len(self.hand.fingers)):
            if j == finger or (min(j, finger), max(j, finger)) not in self.finger_pairs:
                continue
            for other in self.links(j):
                c, e = self.hand.body_segment(other, q)
                for ref in own:
                    a, b = segs[ref.link]
                    best = min(best, segment_segment_distance(a, b, c, e) - self.radius(ref) - self.radius(other))
        return float(best)

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
        """World end points of every link axis of ``finger`` at the hand configuration ``q``
        (one forward-kinematics pass for serial chains)."""
        chain = self.hand.fingers[finger]
        d = self.scene.dim
        if isinstance(chain, SerialChain):
            Rs, ps = chain.frames(q[self.hand.finger_slice(finger)])
            out = {}
            for k in range(chain.n_joints):
                end = chain.origins[k + 1] if k + 1 < chain.n_joints else chain.tip
                out[k] = (ps[k][:d], (ps[k] + Rs[k] @ end)[:d])
            return out
        return {k.link: self.hand.body_segment(k, q) for k in self.links(finger)}

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
) -> tuple[bool, float, int]:
    """Check the whole polyline ``path`` (not only its samples): from each checked configuration
    the next one is at most ``clearance / K`` away in joint space (so every configuration in
    between is collision-free), never less than :data:`DENSE_STEP`. Segments from waypoint
    ``touch_from`` on may touch the object with the links ``touching_last``.

    Returns ``(collision_free, smallest clearance, configurations checked)``."""
    K = model.lipschitz(finger)
    sl = model.hand.finger_slice(finger)
    q = np.array(q_full, dtype=float)
    worst, checks = np.inf, 0
    for s in range(len(path) - 1):
        touching = touching_last if touch_from is not None and s >= touch_from else ()
        p0, p1 = path[s], path[s + 1]
        L = float(np.linalg.norm(p1 - p0))
        t = 0.0
        while True:
            q[sl] = p0 + (p1 - p0) * (t / L if L > 0 else 0.0)
            c = model.finger_clearance(finger, q, position, rotation, touching)
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


def fingertip_ik(
    hand: HandKinematics,
    finger: int,
    target: Array,  # (d,) world point on the object surface
    normal: Array,  # (d,) unit, into the object
    seeds: Sequence[Array],
    min_alignment: float = 0.5,
) -> list[Array]:
    """Joint configurations ``(n,)`` of ``finger`` whose tip is at ``target`` with the last link
    pointing into the object (``link direction . normal >= min_alignment``), closest to each seed
    (CasADi/IPOPT: ``min |q - seed|^2`` subject to those constraints).

    Only serial-chain fingers (2-D links, 3-D axis/origin joints) have a symbolic model; a URDF
    finger raises :class:`SolverError`."""
    chain = hand.fingers[finger]
    if not isinstance(chain, SerialChain):
        raise SolverError("CasADi", f"no symbolic kinematics for finger '{chain.name}' (URDF): no IK")
    d = hand.dim
    solver = _ik_solver(chain, d)
    lbg = np.r_[np.zeros(d), min_alignment]
    ubg = np.r_[np.zeros(d), np.inf]
    out: list[Array] = []
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
    # pre-contact: back the joints off along the last link until the clearance is positive
    q_pre = _back_off(model, finger, q_full, q_goal, tip_ref, approach, pos, rot)
    if q_pre is None:
        return None
    start = state.q[sl]

    def valid_q(x: Array) -> bool:
        qq = q_full.copy()
        qq[sl] = x
        return model.finger_clearance(finger, qq, pos, rot) >= 0.0

    if not valid_q(start):
        return None
    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)
    space = ob.RealVectorStateSpace(m)
    bounds = ob.RealVectorBounds(m)
    lo = np.minimum(start, q_pre) - np.pi
    hi = np.maximum(start, q_pre) + np.pi
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
            model, finger, q_full, waypoints, pos, rot, touching_last=[tip_ref], touch_from=len(free) - 1
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
            x[sl] = x[sl] + np.linalg.lstsq(J, err, rcond=None)[0]
        if model.finger_clearance(finger, x, pos, rot) > 0.0:
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


def integrate_object_motion(
    model: CollisionModel,
    state: GraspState,
    dr: Array,  # (D,) unit object direction
    dq: Array,  # (M,) finger motion per unit object motion (eq. 31)
    sticking: Sequence[int],
    separating: Sequence[int],
    distance: float,
    steps: int = 20,
) -> ObjectMotion | None:
    """Move the object by ``distance`` along ``dr`` with the fingers along ``dq``, projecting on
    the sticking contacts after every step; ``None`` if a link would penetrate the object or a
    separating contact would not separate."""
    hand = model.hand
    h = distance / steps
    cur = state
    q = state.q.copy()
    qs, poses = [q.copy()], [state.pose_vector()]
    worst_res = 0.0
    busy = [hand.resolve_body(state.contacts[i].body) for i in (*sticking, *separating)]
    for _ in range(steps):
        cur = moved(cur, h * dr)
        q, res = project_contacts(hand, cur, q + h * dq, sticking)
        worst_res = max(worst_res, res)
        if res > 1e-6:
            return None
        cur = GraspState(cur.contacts, q, cur.position, cur.rotation, cur.dim)
        qs.append(q.copy())
        poses.append(cur.pose_vector())
        for f in range(len(hand.fingers)):
            touching = [b for b in busy if b is not None and b.finger == f]
            if model.finger_clearance(f, q, cur.position, cur.rotation, touching) < -1e-9:
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


def keep_contacts(state: GraspState, keep: Sequence[int], q: Array, pose: GraspState) -> GraspState:
    """The state after a motion: only the contacts ``keep``, configuration ``q``, pose of ``pose``."""
    contacts: tuple[GraspContact, ...] = tuple(state.contacts[i] for i in keep)
    return GraspState(contacts, np.asarray(q, float), pose.position, pose.rotation, state.dim)
