"""Link re-placement edges (paper eq. 33, D -> F with any link): whole-arm regrasps.

An arm that has let go of a link (:mod:`planner.link_release`) lays that link down again, flat on
a face of a box object: Baxter's forearm, lifted off the box while its elbow stays on it, comes
back to the side of the box. :mod:`planner.contact_edges` makes new contacts with fingertips
only; this module makes them with any link that touched the object in the scene and touches
nothing now (:func:`replace_links`), at the face points of :func:`face_targets` (a 3 x 3 grid on
each face, away from the other contacts and the face's edges) and, towards a ``contact`` goal for
the link, at the goal's point (:func:`goal_target`).

**The pinned placement** (:func:`place_link_pinned`). Only the moving finger's joints ``q_f``
change; every other finger keeps its joints (the holding chains are pinned), the object stays
where it is. ``q_f`` solves, by Gauss-Newton steps of least norm from the state's joints (so the
answer is near them), the equations ``e(q_f) = 0``:

* both ends ``a(q)``, ``b(q)`` of the new link's axis at height ``r + g`` over the face plane,
  ``n . (a - p) = r + g`` (2 rows; ``n`` the face's outward normal, ``p`` the target face point,
  ``r`` the link radius, ``g`` the height: 0 on the face, ``approach`` for the pre-contact): the
  link lies flat on the face, touching it along its side;
* ``p`` under the axis line, ``(n x u) . (p - a) = 0`` (1 row, ``u`` the axis direction);
* each contact the finger keeps (sticking, eq. 5): its body point at its world point (3 rows), and
  the ends of its link that lie at the contact height at the start stay there (the kept link does
  not tilt into the face about its contact point).

Where no solution puts the link over ``p`` (the kept contacts leave it no other way to lie on the
face: Baxter's forearm turns relative to its kept elbow only about its own axis), the row for
``p`` is dropped and the contact is the point of the link's side nearest ``p``. The contact made
is at the link's side point ``x = a + t (b - a) - r n`` over the face (``t`` within ``EDGE_MARGIN``
of the axis' ends), with the inward normal ``-n`` in the object frame; ``x`` must lie inside one
face, away from its edges, so the face's normal cone is ``-n`` alone (:func:`_inside_face`).

**The transfer** (:func:`validate_replace`): from the state's joints to the pre-contact (where
one exists: a link laid flat beside a kept contact cannot rise parallel to the face) and then to
the contact, joint-space straight lines cut into steps of :data:`STEP` rad, each step projected
back onto the kept contacts' equations (the kept contacts do not move, to :data:`KEPT_TOL`), the
whole path certified collision-free by :func:`~planner.collision.path_clearance_certified` for
every link of the finger against the object, the fixed bodies and the other fingers (the kept
links may touch the object throughout, the new link on the last segment only). The grasp before
holds the object while the finger moves (its stationary grasp (18) exists: the state is a node of
the search) and the new grasp must have one too.

Off by default (:attr:`planner.options.PlannerOptions.link_replacement`): the edges add states to
every search on an object with faces.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.kinematics import BodyRef, HandKinematics
from analysis.scene import Box
from planner.collision import path_clearance_certified
from planner.contact_edges import surface_candidates
from planner.ik import joint_limits
from planner.link_release import OVERLAP_SLACK, ROUNDING
from planner.nodes import GraphNodes
from planner.search import Successor
from planner.state import GraspContact, GraspState, all_f
from planner.transition import ContactFigures, Transition

#: joint-space step (rad) of the transfer's straight lines, each step projected on the kept contacts
STEP = 0.02
#: Gauss-Newton iterations of one placement or projection, and the largest step (rad) of one
ITERS = 60
MAX_STEP = 0.3
#: Gauss-Newton gives up when its residual has not halved over this many steps
STALL = 10
#: residual (scene units) of the equations at which a placement or a projection is accepted
RESIDUAL_TOL = 1e-9
#: a kept contact point may move this much (scene units) along the transfer
KEPT_TOL = 1e-8
#: the new contact stays this fraction of the face's half-size away from the face's edges
EDGE_MARGIN = 0.1


@dataclass(frozen=True)
class FaceTarget:
    """Where a link is laid: the face point ``p`` ``(3,)`` (world), the face's outward unit normal
    ``n`` ``(3,)`` (world) and the height ``g`` of the link's contact point over the face."""

    p: Array  # (3,)
    n: Array  # (3,)
    g: float = 0.0


@dataclass(frozen=True)
class PinnedPlacement:
    """A configuration found by :func:`place_link_pinned`: the hand ``q`` ``(M,)`` (only the finger's
    joints differ from the state's), the contact point on the link (its frame) and where along the
    link's axis it is, the largest equation residual and the Gauss-Newton iterations."""

    finger: int
    link: BodyRef
    q: Array  # (M,)
    point_body: Array  # (3,) the contact point on the link, its frame
    t: float  # where along the link's axis (0 at its start, 1 at its end)
    over_point: bool  # the link was laid over the target point (else anywhere on its plane)
    residual: float
    iterations: int


def _flat_rows(hand: HandKinematics, ref: BodyRef, point_body: Array | None, q: Array, target: FaceTarget,
               ends: tuple[bool, bool] = (True, True), over_point: bool = True) -> tuple[Array, Array]:
    """The equations of a link lying on ``target`` and their Jacobian in every joint: residual
    ``(k,)`` and ``(k, M)``. Both axis ends (those of ``ends``) at height ``r + g`` over the face
    plane; with ``point_body`` the body point at ``p + g n`` (3 rows, a kept contact), without it
    ``p`` under the axis line: ``w . (p - a) = 0``, ``w = n x u``, ``u`` the axis direction (1 row, a
    new contact: the link touches the face along its side, over ``p``; none without ``over_point``)."""
    a, b = (np.asarray(e, dtype=float) for e in hand.body_segment(ref, q))
    Ja, Jb = hand.point_jacobian(ref, a, q), hand.point_jacobian(ref, b, q)  # (3, M) each
    n, p, g = target.n, target.p, target.g
    r = hand.body_radius(ref)
    rows: list[Array] = []
    errs: list[Array] = []
    if point_body is not None:
        x = hand.point_position(ref, point_body, q)  # (3,)
        rows.append(hand.point_jacobian(ref, x, q))
        errs.append(x - (p + g * n))
    elif over_point:
        L = float(np.linalg.norm(b - a))
        u = (b - a) / L
        w = np.cross(n, u)
        du = (np.eye(3) - np.outer(u, u)) @ (Jb - Ja) / L  # (3, M)
        rows.append((np.cross(p - a, n) @ du - w @ Ja)[None, :])  # d[(n x u) . (p - a)]
        errs.append(np.array([float(w @ (p - a))]))
    for e, J, use in ((a, Ja, ends[0]), (b, Jb, ends[1])):
        if use:
            rows.append((n @ J)[None, :])  # (1, M)
            errs.append(np.array([float(n @ (e - p)) - r - g]))
    return np.concatenate(errs), np.vstack(rows)


@dataclass(frozen=True)
class _Kept:
    """A contact the moving finger keeps: its link, body point, target and which axis ends stay."""

    ref: BodyRef
    point_body: Array
    target: FaceTarget
    ends: tuple[bool, bool]


def kept_contacts(nodes: GraphNodes, state: GraspState, finger: int) -> list[_Kept]:
    """The contacts of ``finger`` in ``state`` as equations that keep them: the body point at its
    world point, and the axis ends that lie at the contact height (``r`` over the tangent plane,
    within ``1e-6`` object sizes) stay at it."""
    hand = nodes.hand
    out = []
    for i, c in enumerate(state.contacts):
        ref = hand.resolve_body(c.body)
        if ref is None or ref.finger != finger:
            continue
        x = state.world_point(i)  # (3,)
        n = -(state.rotation[:3, :3] @ np.asarray(c.normal_object, dtype=float))  # outward
        r = hand.body_radius(ref)
        ends = tuple(abs(float(n @ (np.asarray(e) - x)) - r) <= 1e-6 * nodes.size
                     for e in hand.body_segment(ref, state.q))
        out.append(_Kept(ref, np.asarray(c.point_body, dtype=float), FaceTarget(x, n), (bool(ends[0]), bool(ends[1]))))
    return out


def _equations(hand: HandKinematics, q: Array, new: tuple[BodyRef, None, FaceTarget, bool] | None,
               kept: list[_Kept], sl: slice) -> tuple[Array, Array]:
    """The stacked residual ``(k,)`` and its Jacobian ``(k, m)`` in the finger's joints ``sl``."""
    errs, rows = [], []
    if new is not None:
        e, J = _flat_rows(hand, new[0], new[1], q, new[2], over_point=new[3])
        errs.append(e)
        rows.append(J[:, sl])
    for k in kept:
        e, J = _flat_rows(hand, k.ref, k.point_body, q, k.target, k.ends)
        errs.append(e)
        rows.append(J[:, sl])
    if not errs:
        return np.zeros(0), np.zeros((0, sl.stop - sl.start))
    return np.concatenate(errs), np.vstack(rows)


def _gauss_newton(hand: HandKinematics, finger: int, q: Array, new: tuple[BodyRef, None, FaceTarget, bool] | None,
                  kept: list[_Kept]) -> tuple[Array, float, int]:
    """Least-norm Gauss-Newton steps on the finger's joints (clipped to its limits, each at most
    :data:`MAX_STEP`) until the residual is below :data:`RESIDUAL_TOL` (or has not halved over
    :data:`STALL` steps); ``(q, residual, iterations)``."""
    sl = hand.finger_slice(finger)
    lo, hi = joint_limits(hand, finger)
    q = np.array(q, dtype=float)
    res = np.inf
    history: list[float] = []
    for it in range(ITERS):
        e, J = _equations(hand, q, new, kept, sl)
        res = float(np.max(np.abs(e), initial=0.0))
        if res <= RESIDUAL_TOL:
            return q, res, it
        history.append(res)
        if len(history) > STALL and res > 0.5 * history[-1 - STALL]:
            return q, res, it  # stalled: not halved in STALL steps (no solution near, or a joint limit)
        dq = np.linalg.lstsq(J, -e, rcond=1e-10)[0]
        nrm = float(np.linalg.norm(dq))
        if nrm > MAX_STEP:
            dq *= MAX_STEP / nrm
        q[sl] = np.clip(q[sl] + dq, lo, hi)
    return q, res, ITERS


def place_link_pinned(nodes: GraphNodes, state: GraspState, finger: int, link: BodyRef, target: FaceTarget,
                      seed: Array | None = None, over_point: bool = True) -> PinnedPlacement | None:
    """The pinned placement of ``link`` (of ``finger``) flat on ``target``, the finger's other
    contacts in ``state`` kept, every other joint as in ``state`` (module docstring). With
    ``over_point`` the link touches the face over ``p``; without, anywhere on the face's plane, the
    contact at the point of the link's side nearest ``p`` (where the kept contacts leave the link
    no other way to lie on the face: Baxter's forearm beside its kept elbow). None when
    Gauss-Newton does not reach :data:`RESIDUAL_TOL`, the contact is within ``EDGE_MARGIN`` of an
    end of the link's axis, or not inside a face (:func:`_inside_face`)."""
    hand = nodes.hand
    kept = kept_contacts(nodes, state, finger)
    q0 = np.array(state.q if seed is None else seed, dtype=float)
    q, res, it = _gauss_newton(hand, finger, q0, (link, None, target, over_point), kept)
    if res > RESIDUAL_TOL:
        return None
    a, b = (np.asarray(e, dtype=float) for e in hand.body_segment(link, q))
    L = float(np.linalg.norm(b - a))
    t = float((target.p - a) @ (b - a)) / L**2
    if not over_point:
        t = float(np.clip(t, EDGE_MARGIN, 1.0 - EDGE_MARGIN))
    if not EDGE_MARGIN <= t <= 1.0 - EDGE_MARGIN:
        return None
    x = a + t * (b - a) - (hand.body_radius(link) + target.g) * target.n  # (3,) the link's side over the face
    p_obj = state.rotation[:3, :3].T @ (x - target.g * target.n - state.position)  # (3,) its foot on the plane
    if not _inside_face(nodes, p_obj):
        return None
    return PinnedPlacement(finger, link, q, hand.to_local(link, x, q), t, over_point, res, it)


def face_targets(nodes: GraphNodes, state: GraspState, finger: int) -> list[FaceTarget]:
    """Candidate face points of a box object (:func:`planner.contact_edges.surface_candidates`: a 3 x 3
    grid on each face, away from the existing contacts), world frame, those inside their face by
    :data:`EDGE_MARGIN` of its half-size (the face normal is then the only normal there)."""
    shape = nodes.scene.object.shape
    if not isinstance(shape, Box) or state.dim != 3:
        return []
    h = np.asarray(shape.size, float) / 2
    c = np.asarray(shape.position if shape.position is not None else np.zeros(3), float)
    R = state.rotation[:3, :3]
    out = []
    for p_obj, n_obj in surface_candidates(nodes, state, finger):
        u = -np.asarray(n_obj, dtype=float)  # outward, object frame
        ax = int(np.argmax(np.abs(u)))
        off = np.abs(np.asarray(p_obj) - c)  # (3,)
        if any(off[a] > (1.0 - EDGE_MARGIN) * h[a] for a in range(3) if a != ax):
            continue
        out.append(FaceTarget(state.position + R @ p_obj, R @ u))
    return out


def goal_target(nodes: GraphNodes, state: GraspState, link: BodyRef) -> FaceTarget | None:
    """Towards a ``contact`` goal for ``link`` (:func:`planner.goals.contact_reached`), the goal's
    point as a face target: projected on the plane of the box face nearest it (world, the face's
    outward normal), where it lies within the goal's position tolerance of that plane; else None.
    The placement lays the link over it, or, where its kept contacts leave it one line on the face
    (``over_point=False``), makes the contact at the point of its side nearest it."""
    goal = nodes.goal
    shape = nodes.scene.object.shape
    if goal.type != "contact" or goal.body != link.name or goal.point is None or not isinstance(shape, Box):
        return None
    R = state.rotation[:3, :3]
    h = np.asarray(shape.size, float) / 2
    c = np.asarray(shape.position if shape.position is not None else np.zeros(3), float)
    p_obj = R.T @ (np.asarray(goal.point, dtype=float) - state.position) - c  # (3,) from the box's centre
    ax = int(np.argmax(np.abs(p_obj) / h))  # the face whose plane is nearest, in half-sizes
    n_obj = np.zeros(3)
    n_obj[ax] = np.sign(p_obj[ax]) if p_obj[ax] != 0.0 else 1.0
    if abs(abs(float(p_obj[ax])) - h[ax]) > goal.position_tol(nodes.size):
        return None
    p_obj[ax] = n_obj[ax] * h[ax]
    return FaceTarget(state.position + R @ (p_obj + c), R @ n_obj)


def _inside_face(nodes: GraphNodes, p_obj: Array) -> bool:
    """Whether the object-frame point ``p_obj`` ``(3,)`` of a box's surface lies inside one face by
    :data:`EDGE_MARGIN` of its half-sizes (the face normal is then the only normal there)."""
    shape = nodes.scene.object.shape
    assert isinstance(shape, Box)
    h = np.asarray(shape.size, float) / 2
    c = np.asarray(shape.position if shape.position is not None else np.zeros(3), float)
    off = np.abs(np.asarray(p_obj, dtype=float) - c) / h  # (3,) 1 on a face
    on = np.flatnonzero(np.abs(off - 1.0) <= 1e-6)
    return len(on) == 1 and bool(np.all(np.delete(off, on) <= 1.0 - EDGE_MARGIN))


def replace_links(nodes: GraphNodes, state: GraspState, finger: int) -> list[BodyRef]:
    """The links of ``finger`` that may be laid on a face: those that touch the object in the scene
    and touch nothing in ``state``."""
    hand = nodes.hand
    busy = {c.body for c in state.contacts}
    out: list[BodyRef] = []
    for c in nodes.scene.contacts:
        ref = hand.resolve_body(c.body)
        if ref is not None and ref.finger == finger and c.body not in busy and ref not in out:
            out.append(ref)
    return out


def replace_edges(nodes: GraphNodes, state: GraspState) -> list[Successor]:
    """Eq. (33), D -> F with any link (module docstring): for every finger with a link of
    :func:`replace_links`, every face target the link can be laid on by the pinned placement (the
    goal's point first, :func:`goal_target`; a configuration reached from several targets once), the
    placement collision-free (the finger's contacts and the new link touching). Lazy: the
    transfer is planned by :func:`validate_replace` when the search needs the edge."""
    hand, model, options = nodes.hand, nodes.model, nodes.options
    out: list[Successor] = []
    if not state.contacts or state.dim != 3 or not isinstance(nodes.scene.object.shape, Box):
        return out  # faces of a box object only (face_targets): nothing to lay a link on
    sa = nodes.analysis(state)
    grasp = sa.stationary(all_f(state))
    if grasp is None:
        return out
    effort = options.effort_weight * float(np.linalg.norm(grasp.tau))
    for f in range(len(hand.fingers)):
        links = replace_links(nodes, state, f)
        if not links:
            continue
        kept_refs = [k.ref for k in kept_contacts(nodes, state, f)]
        allow = transfer_allowance(nodes, state, f)
        sl = hand.finger_slice(f)
        placed: list[Array] = []
        for ref in links:
            towards = goal_target(nodes, state, ref)
            targets = face_targets(nodes, state, f)
            if towards is not None:  # first: the grid's placements of the same configuration are dropped
                targets.insert(0, towards)
            for target in targets:
                with nodes.timings.measure("ik"):
                    pl = place_link_pinned(nodes, state, f, ref, target)
                    if pl is None:
                        pl = place_link_pinned(nodes, state, f, ref, target, over_point=False)
                    if pl is not None and any(float(np.max(np.abs(pl.q - o))) <= 1e-9 for o in placed):
                        continue  # the same configuration from another target (anywhere on the plane)
                if pl is None:
                    nodes.reject("no pinned placement of a link on a face")
                    continue
                if not model.is_clear(f, pl.q, state.position, state.rotation, [*kept_refs, ref], allow):
                    nodes.reject("the link placed on a face collides")
                    continue
                placed.append(pl.q)
                R = state.rotation[:3, :3]
                x = hand.point_position(ref, pl.point_body, pl.q)  # (3,) on the face
                p_obj = R.T @ (x - state.position)
                if any(np.linalg.norm(p_obj - c.point_object) <= options.min_contact_spacing * nodes.size
                       for c in state.contacts):
                    nodes.reject("a link placed on a face touches it next to a contact")
                    continue
                contact = GraspContact(ref.name, pl.point_body, p_obj, -(R.T @ target.n),
                                       nodes.default_mu)
                new = GraspState((*state.contacts, contact), pl.q, state.position, state.rotation, state.dim)
                key = nodes.add(new, validated=False)
                bound = float(np.linalg.norm(pl.q[sl] - state.q[sl])) + effort

                def validate(state: GraspState = state, new: GraspState = new, pl: PinnedPlacement = pl,
                             target: FaceTarget = FaceTarget(x, target.n)) -> tuple[float, Any] | None:
                    return validate_replace(nodes, state, new, pl, target)

                out.append(Successor(key, max(bound, 1e-9), None, validate))
    return out


def transfer_allowance(nodes: GraphNodes, state: GraspState, finger: int) -> Array:
    """The overlaps the finger's transfer may have: those at its start, each allowed to deepen by
    :data:`planner.link_release.OVERLAP_SLACK` of ``min_radius`` (as a link release: the capsules
    of an arm's neighbouring links overlap at the scene's configuration, the release eases the
    overlap and laying the link back brings it back), and rounding."""
    model = nodes.model
    allow = model.start_allowance(finger, state.q, state.position, state.rotation)
    return np.where(allow < 0.0, allow - OVERLAP_SLACK * model.min_radius, allow) - ROUNDING


def _line(hand: HandKinematics, finger: int, q_a: Array, q_b: Array, kept: list[_Kept]) -> list[Array] | None:
    """The straight line ``q_a -> q_b`` in steps of at most :data:`STEP` rad, every inner point
    projected back onto the kept contacts; None where a projection fails."""
    sl = hand.finger_slice(finger)
    n = max(1, int(np.ceil(float(np.linalg.norm(q_b[sl] - q_a[sl])) / STEP)))
    out = []
    prev = q_a
    for k in range(1, n + 1):
        q = q_a + (q_b - q_a) * (k / n)
        if k < n and kept:
            q, res, _ = _gauss_newton(hand, finger, q, None, kept)
            if res > RESIDUAL_TOL:
                return None
        if float(np.linalg.norm(q[sl] - prev[sl])) > 2.0 * STEP + 1e-12:
            return None  # the projection jumped
        out.append(q)
        prev = q
    return out


def transfer_path(nodes: GraphNodes, state: GraspState, new: GraspState, pl: PinnedPlacement,
                  target: FaceTarget) -> tuple[Array, float, int] | None:
    """The finger's path ``(n, M)`` from ``state`` to the placement of ``new`` through the pre-contact
    ``approach`` over the face (module docstring), certified; with its smallest clearance and the
    configurations checked, or None (the reason counted in ``nodes``)."""
    hand, model = nodes.hand, nodes.model
    f, ref = pl.finger, pl.link
    sl = hand.finger_slice(f)
    kept = kept_contacts(nodes, state, f)
    g = nodes.options.approach * nodes.size
    pre = place_link_pinned(nodes, state, f, ref, FaceTarget(target.p, target.n, g), seed=new.q,
                            over_point=pl.over_point)
    legs = [(state.q, new.q)] if pre is None else [(state.q, pre.q), (pre.q, new.q)]
    lines = [_line(hand, f, a, b, kept) for a, b in legs]
    if any(line is None for line in lines):
        nodes.reject("the kept contacts cannot be followed to a link placed on a face")
        return None
    path = np.array([state.q, *(q for line in lines if line is not None for q in line)])  # (n, M)
    for q in path:
        e, _ = _equations(hand, q, None, kept, sl)
        if e.size and float(np.max(np.abs(e))) > KEPT_TOL:
            nodes.reject("the kept contacts cannot be followed to a link placed on a face")
            return None
    allow = transfer_allowance(nodes, state, f)
    kept_refs = [k.ref for k in kept]
    n_free = len(path) - 1  # the last segment may touch with the new link
    ok, c1, n1 = path_clearance_certified(model, f, state.q, path[:n_free, sl], state.position, state.rotation,
                                          touching_last=kept_refs, touch_from=0, allowance=allow)
    if not ok:
        nodes.reject("no collision-free path to lay a link on a face")
        return None
    ok, c2, n2 = path_clearance_certified(model, f, state.q, path[n_free - 1:, sl], state.position, state.rotation,
                                          touching_last=[*kept_refs, ref], touch_from=0, allowance=allow)
    if not ok:
        nodes.reject("no collision-free path to lay a link on a face")
        return None
    return path, min(c1, c2), n1 + n2


def validate_replace(nodes: GraphNodes, state: GraspState, new: GraspState, pl: PinnedPlacement,
                     target: FaceTarget) -> tuple[float, Transition] | None:
    """The lazy check of a re-placement edge: the certified transfer (:func:`transfer_path`), and
    the new grasp's stationary grasp (18); ``(cost, transition)`` or None."""
    hand, options = nodes.hand, nodes.options
    with nodes.timings.measure("motion"):
        got = transfer_path(nodes, state, new, pl, target)
    if got is None:
        return None
    path, clearance, checks = got
    try:
        held = nodes.held(new)
    except SceneError:  # pragma: no cover - held() counts geometry errors itself
        held = None
    if held is None or not nodes.arrives(new):
        return None
    grasp = nodes.analysis(state).stationary(all_f(state))
    assert grasp is not None  # replace_edges made the edge only where it exists
    f = pl.finger
    sl = hand.finger_slice(f)
    length = float(np.sum(np.linalg.norm(np.diff(path[:, sl], axis=0), axis=1)))
    effort = options.effort_weight * float(np.linalg.norm(grasp.tau))
    figures = ContactFigures(hand.fingers[f].name, tuple(target.p.tolist()), length, clearance, checks, 0.0)
    t = Transition("contact", all_f(state) + "D", state.bodies(), new.bodies(), path,
                   np.tile(state.pose_vector(), (len(path), 1)), grasp.tau, grasp.tau, None, figures,
                   length + effort)
    nodes.add(new)
    return t.cost, t


def first_valid(edges: list[Successor]) -> tuple[Successor, tuple[float, Transition]] | None:
    """The first of ``edges`` (of :func:`replace_edges`) whose lazy check holds, with its
    ``(cost, transition)``; None when none does (the reasons are in the graph's rejections)."""
    for edge in edges:
        assert edge.validate is not None  # re-placement edges are lazy
        got = edge.validate()
        if got is not None:
            return edge, got
    return None
