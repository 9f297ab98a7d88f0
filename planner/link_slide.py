"""Slide edges (paper eq. 33 with an S-point and ``dr = 0``): one link's contact slides along a face.

An arm moves its contact point to a new place on the same face of a box without letting go: the
link lying flat on the face (Baxter's elbow, its forearm lifted off by a link release) slides along
it while the other contacts (the other arm, the table, the arm's own other contacts) hold the
object still. In the paper's terms the sliding contact is an S-point (5, 11-12) of a regrasp (33):
the object does not move, the finger motion keeps the F-points glued and the S-point touching, and
the object stays in equilibrium with the S-point's kinetic friction against its slip
(:func:`analysis.regrasp.sliding_equilibrium`; its normal force may be zero: then the others hold
the object alone, their stationary grasp 18 with the sliding contact ``D``).

**The path** (:func:`slide_path`). Only the sliding finger's joints ``q_f`` change. Waypoint ``k``
solves, by least-norm Gauss-Newton steps from waypoint ``k - 1``, the equations:

* the finger's other contacts kept (:func:`planner.link_replace.kept_contacts`: body point at its
  world point, 3 rows, and the kept link's axis ends that lie at the contact height stay there);
* the sliding link keeps its tilt: its axis ends at their heights over the face plane at the start,
  ``n . (e - x_0) = h_e`` (2 rows; ``n`` the face's outward normal, ``x_0`` the contact's start; a
  link flat on the face has both at its radius ``r``);
* the sliding contact's body point ``x(q)`` on the face plane, ``n . (x - x_0) = 0`` (1 row): with the axis
  at height ``r`` the point is the capsule's lowest, so the gap is zero and the link does not sink
  into the face;
* its progress along the slide direction ``u`` (in the face plane), ``u . (x - x_0) = s_k`` (1 row),
  ``s_k = k h``; the component across ``u`` is left free: a link whose tilt and gap take all but
  one of its arm's freedoms (Baxter's elbow: four joints move it) slides along a curve.

The contact advances ``h`` per waypoint, halved until every joint moves at most
:data:`planner.collision.DENSE_STEP` between waypoints. Directions: both ways along the face's
two in-plane axes, ``slide_length`` object sizes (:attr:`planner.options.PlannerOptions.slide_length`).

**Checks** (:func:`slide_edges`): every waypoint's residual below :data:`RESIDUAL_TOL` within the
joint limits; the path certified collision-free for the finger's links (those touching the object
may touch it, not penetrate it; overlaps of the start may deepen by a link release's slack); the
contact's end point inside one face by ``EDGE_MARGIN`` and away from the other contacts; at every
waypoint the state with the contact where it has slid is a valid scene (the point on both
surfaces), the holding contacts have a stationary grasp (18) and eq. (33) with the S-point holds
for the waypoint's motion; the state after the slide has a stationary grasp (18).

Off by default (:attr:`planner.options.PlannerOptions.contact_slides`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from analysis._types import Array
from analysis.exceptions import CTPError
from analysis.kinematics import BodyRef, HandKinematics
from analysis.regrasp import sliding_equilibrium
from analysis.scene import Box, Scene
from planner.collision import DENSE_STEP, path_clearance_certified
from planner.ik import joint_limits
from planner.link_replace import _equations, _inside_face, _Kept, kept_contacts, transfer_allowance
from planner.nodes import GraphNodes
from planner.search import Successor
from planner.state import GraspContact, GraspState, StateAnalysis, all_f
from planner.transition import SlideFigures, Transition

#: Gauss-Newton iterations per waypoint and the residual (scene units) at which one is accepted
ITERS = 30
RESIDUAL_TOL = 1e-9
#: first advance of the contact per waypoint (object sizes), halved while a joint moves more than DENSE_STEP
ADVANCE = 0.01
#: the sliding link's axis ends keep their heights over the face (a link flat on the face: both at its
#: radius); an end may lie at most this much (object sizes) below the radius at the start (Baxter's
#: elbow after its forearm's release is tilted 0.9 degrees, one end 1.4 mm lower, over the box's edge)
TILT = 0.01
#: least-squares residual (of a unit advance) above which a slide has no first-order motion
FIRST_ORDER_TOL = 1e-6


def sliding_combination(state: GraspState, i: int) -> str:
    """The combination of a slide of contact ``i``: ``S`` there, the others sticking (``F``, ``N``)."""
    comb = list(all_f(state))
    comb[i] = "S"
    return "".join(comb)


def holding_combination(state: GraspState, i: int) -> str:
    """The combination of the contacts that hold the object alone while contact ``i`` slides: ``D``
    there (its force zero), the others sticking."""
    comb = list(all_f(state))
    comb[i] = "D"
    return "".join(comb)


def slid_state(state: GraspState, i: int, q: Array, hand: HandKinematics) -> GraspState:
    """``state`` with the hand at ``q`` ``(M,)`` and contact ``i`` where its body point now is (the
    same body point, its object point and normal moved along the face: the normal is the face's)."""
    c = state.contacts[i]
    ref = hand.resolve_body(c.body)
    assert ref is not None
    x = hand.point_position(ref, c.point_body, q)  # (3,)
    R = state.rotation[:3, :3]
    moved = GraspContact(c.body, c.point_body, R.T @ (x - state.position), c.normal_object, c.mu, c.origin)
    contacts = tuple(moved if j == i else cc for j, cc in enumerate(state.contacts))
    return GraspState(contacts, np.asarray(q, dtype=float), state.position, state.rotation, state.dim)


def _face_frame(state: GraspState, i: int, scene: Scene) -> tuple[Array, list[Array]] | None:
    """The outward normal ``(3,)`` of the face contact ``i`` lies on (world) and the face's two
    in-plane unit axes (world), or None (not a box, not 3-D)."""
    if not isinstance(scene.object.shape, Box) or state.dim != 3:
        return None
    R = state.rotation[:3, :3]
    n_out = -(R @ np.asarray(state.contacts[i].normal_object, dtype=float))
    ax = int(np.argmax(np.abs(R.T @ n_out)))
    return n_out, [R[:, a] for a in range(3) if a != ax]


def _slide_rows(hand: HandKinematics, ref: BodyRef, point_body: Array, q: Array, x0: Array, n: Array, u: Array,
                s: float, heights: Array) -> tuple[Array, Array]:
    """The sliding contact's equations (module docstring) and their Jacobian: ``(4,)``, ``(4, M)``."""
    rows, errs = [], []
    for e, h in zip(hand.body_segment(ref, q), heights, strict=True):
        e = np.asarray(e, dtype=float)
        rows.append(n @ hand.point_jacobian(ref, e, q))
        errs.append(float(n @ (e - x0)) - float(h))
    x = hand.point_position(ref, point_body, q)  # (3,)
    Jx = hand.point_jacobian(ref, x, q)  # (3, M)
    errs += [float(n @ (x - x0)), float(u @ (x - x0)) - s]
    return np.array(errs), np.vstack([*rows, n @ Jx, u @ Jx])


def slide_path(nodes: GraphNodes, state: GraspState, i: int, u: Array, length: float) -> Array | None:
    """The finger's path ``(n, M)`` sliding contact ``i`` by ``length`` along ``u`` ``(3,)`` (a unit
    vector in its face's plane), the other contacts kept (module docstring), or None where
    Gauss-Newton does not converge, a joint limit is reached or a kept link does not lie flat."""
    hand, scene = nodes.hand, nodes.scene
    c = state.contacts[i]
    ref = hand.resolve_body(c.body)
    if ref is None or ref.finger is None:
        return None
    frame = _face_frame(state, i, scene)
    if frame is None:
        return None
    n = frame[0]
    x0 = state.world_point(i)
    r = hand.body_radius(ref)
    heights = np.array([float(n @ (np.asarray(e) - x0)) for e in hand.body_segment(ref, state.q)])  # (2,)
    if np.any(heights < r - TILT * nodes.size):
        return None  # the link lies across the face (not along it) or touches with its cap
    f = ref.finger
    sl = hand.finger_slice(f)
    lo, hi = joint_limits(hand, f)
    kept = [k for k in kept_contacts(nodes, state, f) if not (k.ref == ref and np.allclose(k.point_body, c.point_body))]

    def solve(q: Array, s: float) -> tuple[Array, float]:
        q = np.array(q, dtype=float)
        res = np.inf
        for _ in range(ITERS):
            e, J = _slide_rows(hand, ref, c.point_body, q, x0, n, u, s, heights)
            ek, Jk = _equations(hand, q, None, kept, sl)  # the arm's kept contacts, as a re-placement holds them
            err = np.concatenate([e, ek])
            rows = [J[:, sl], Jk]
            res = float(np.max(np.abs(err)))
            if res <= RESIDUAL_TOL:
                break
            q[sl] = np.clip(q[sl] + np.linalg.lstsq(np.vstack(rows), -err, rcond=1e-10)[0], lo, hi)
        return q, res

    if not first_order_slide(hand, ref, c.point_body, state.q, x0, n, u, heights, kept, sl):
        return None  # no motion of the finger advances the contact along u at first order
    path = [np.array(state.q, dtype=float)]
    s, h = 0.0, ADVANCE * nodes.size
    while s < length - 1e-12:
        step = min(h, length - s)
        q, res = solve(path[-1], s + step)
        if res > RESIDUAL_TOL or float(np.max(np.abs(q[sl] - path[-1][sl]))) > DENSE_STEP:
            if step <= 1e-6 * nodes.size:
                return None
            h = 0.5 * step
            continue
        if np.any(q[sl] <= lo + 1e-9) or np.any(q[sl] >= hi - 1e-9):
            return None  # at a joint limit the equations were met only by clipping
        path.append(q)
        s += step
    return np.array(path)


def first_order_slide(hand: HandKinematics, ref: BodyRef, point_body: Array, q: Array, x0: Array, n: Array,
                      u: Array, heights: Array, kept: list[_Kept], sl: slice) -> bool:
    """Whether the slide's equations (module docstring) have a first-order motion at ``q`` ``(M,)``:
    ``A dq = b``, ``A`` the Jacobian ``(k, m)`` of the sliding rows and the kept contacts' rows in the
    finger's joints ``sl``, ``b`` zero but a unit advance along ``u``, solvable (least-squares
    residual at most :data:`FIRST_ORDER_TOL`). Where it is not (Baxter's elbow while its forearm
    lies on the same face: the kept forearm's rows take the freedoms the advance needs), Gauss-Newton
    cannot advance the contact by any step and :func:`slide_path` would halve its step down to
    ``1e-6`` object sizes (0.3 s a direction) before giving up."""
    _, J = _slide_rows(hand, ref, point_body, q, x0, n, u, 0.0, heights)
    _, Jk = _equations(hand, q, None, kept, sl)
    A = np.vstack([J[:, sl], Jk])  # (k, m)
    b = np.zeros(A.shape[0])
    b[3] = 1.0  # the progress row u . dx = 1
    dq = np.linalg.lstsq(A, b, rcond=1e-10)[0]
    return float(np.linalg.norm(A @ dq - b)) <= FIRST_ORDER_TOL


def slide_problems(nodes: GraphNodes, state: GraspState, i: int, path: Array) -> tuple[str | None, float]:
    """The mechanics of a slide along ``path`` ``(n, M)`` (module docstring): the first problem (a
    rejection reason) or None, and the smallest margin of (18) of the holding contacts."""
    scene, hand = nodes.scene, nodes.hand
    comb_s, comb_d = sliding_combination(state, i), holding_combination(state, i)
    margin = np.inf
    for k in range(len(path)):
        dq = path[k + 1] - path[k] if k + 1 < len(path) else path[k] - path[k - 1]
        try:
            with nodes.timings.measure("analysis"):
                sa = StateAnalysis.of(scene, slid_state(state, i, path[k], hand), hand)
                held = sa.stationary(comb_d)
                p = sa.parts(comb_s)
                ok = sliding_equilibrium(p.system, p.sel, p.st, p.fs, dq)
        except CTPError:
            return "a sliding contact leaves its face (the waypoint is not a valid scene)", margin
        if held is None:
            return "no stationary grasp (18) of the holding contacts while a contact slides", margin
        if not ok:
            return "no equilibrium (33) with the sliding contact's kinetic friction", margin
        margin = min(margin, float(held.margin))
    return None, margin


def slide_candidates(nodes: GraphNodes, state: GraspState) -> list[tuple[int, Array, GraspState]]:
    """The slides of ``state`` before their costly checks: for every finger contact lying flat on a
    face of a box, slides of ``slide_length`` object sizes both ways along the face's two axes (module
    docstring) and, towards a ``contact`` goal for its body, the slide towards the goal's point (its
    progress the point's distance in the face's plane); those whose path exists (:func:`slide_path`)
    and ends inside one face away from the other finger contacts, as ``(contact, path (n, M), state
    after)``."""
    hand, options = nodes.hand, nodes.options
    out: list[tuple[int, Array, GraspState]] = []
    if not isinstance(nodes.scene.object.shape, Box) or state.dim != 3 or not state.contacts:
        return out
    length = options.slide_length * nodes.size
    for i, c in enumerate(state.contacts):
        ref = hand.resolve_body(c.body)
        if ref is None or ref.finger is None:
            continue
        frame = _face_frame(state, i, nodes.scene)
        assert frame is not None
        ways = [(sign * axis, length) for axis in frame[1] for sign in (1.0, -1.0)]
        goal = nodes.goal
        if goal.type == "contact" and goal.body == c.body and goal.point is not None:
            d = np.asarray(goal.point, dtype=float) - state.world_point(i)
            d -= float(frame[0] @ d) * frame[0]  # in the face's plane
            if float(np.linalg.norm(d)) > 1e-9 * nodes.size:
                ways.insert(0, (d / np.linalg.norm(d), float(np.linalg.norm(d))))  # towards the goal's point
        for u, dist in ways:
            with nodes.timings.measure("motion"):
                path = slide_path(nodes, state, i, u, dist)
            if path is None:
                nodes.reject("a link cannot slide along the face (kinematics)")
                continue
            new = slid_state(state, i, path[-1], hand)
            p_obj = new.contacts[i].point_object
            if not _inside_face(nodes, p_obj):
                nodes.reject("a sliding contact would leave its face")
                continue
            if any(np.linalg.norm(p_obj - cc.point_object) <= options.min_contact_spacing * nodes.size
                   for j, cc in enumerate(state.contacts) if j != i and hand.finger_of(cc.body) is not None):
                nodes.reject("a contact would slide next to another contact")
                continue
            out.append((i, path, new))
    return out


def check_slide(nodes: GraphNodes, state: GraspState, i: int, path: Array, new: GraspState) -> Transition | None:
    """The costly checks of a slide of contact ``i`` along ``path`` ``(n, M)`` to ``new`` (module
    docstring): the path certified collision-free, the mechanics at every waypoint
    (:func:`slide_problems`), the state after it holding the object (18) at its own configuration;
    the slide's transition or None (the reason counted in ``nodes``)."""
    hand, model = nodes.hand, nodes.model
    ref = hand.resolve_body(state.contacts[i].body)
    assert ref is not None and ref.finger is not None
    f = ref.finger
    sl = hand.finger_slice(f)
    kept_refs = [r for cc in state.contacts if (r := hand.resolve_body(cc.body)) is not None and r.finger == f]
    with nodes.timings.measure("motion"):
        ok, clearance, _ = path_clearance_certified(
            model, f, state.q, path[:, sl], state.position, state.rotation, touching_last=kept_refs,
            touch_from=0, allowance=transfer_allowance(nodes, state, f))
    if not ok:
        nodes.reject("a sliding link collides")
        return None
    problem, margin = slide_problems(nodes, state, i, path)
    if problem is not None:
        nodes.reject(problem)
        return None
    if nodes.held(new) is None or not nodes.arrives(new):
        return None
    return _transition(nodes, state, new, i, path, margin, clearance)


def slide_edges(nodes: GraphNodes, state: GraspState) -> list[tuple[Transition, GraspState]]:
    """Eq. (33) with an S-point: the slides of :func:`slide_candidates`, checked
    (:func:`check_slide`); the transitions and the states they lead to."""
    out: list[tuple[Transition, GraspState]] = []
    for i, path, new in slide_candidates(nodes, state):
        t = check_slide(nodes, state, i, path, new)
        if t is not None:
            out.append((t, new))
    return out


def lazy_slide_edges(nodes: GraphNodes, state: GraspState) -> list[Successor]:
    """The slides of :func:`slide_candidates` as lazy edges of the search: the path (which gives the
    state after the slide) is computed when the state is expanded, its cost (the path's joint length
    and the holding torque's effort) known then; :func:`check_slide` (the clearance certificate and
    the mechanics at every waypoint, most of a slide's time) runs when the search pops the edge."""
    out: list[Successor] = []
    for i, path, new in slide_candidates(nodes, state):
        grasp = nodes.analysis(state).stationary(holding_combination(state, i))
        if grasp is None:
            nodes.reject("no stationary grasp (18) of the holding contacts while a contact slides")
            continue
        cost = _cost(nodes, path, grasp.tau)
        key = nodes.add(new, validated=False)

        def validate(i: int = i, path: Array = path, new: GraspState = new) -> tuple[float, Any] | None:
            t = check_slide(nodes, state, i, path, new)
            if t is None:
                return None
            nodes.add(new)
            return t.cost, t

        out.append(Successor(key, max(cost, 1e-9), None, validate))
    return out


def _cost(nodes: GraphNodes, path: Array, tau: Array) -> float:
    """A slide's cost: the joint path's length plus ``effort_weight`` times the holding torque's norm."""
    length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    return length + nodes.options.effort_weight * float(np.linalg.norm(tau))


def _transition(nodes: GraphNodes, state: GraspState, new: GraspState, i: int, path: Array, margin: float,
                clearance: float) -> Transition | None:
    """The slide's :class:`Transition` (kind ``slide``), its torque the holding contacts' (18)."""
    hand = nodes.hand
    c = state.contacts[i]
    ref = hand.resolve_body(c.body)
    assert ref is not None and ref.finger is not None
    grasp = nodes.analysis(state).stationary(holding_combination(state, i))
    if grasp is None:  # pragma: no cover - slide_problems checked it at the first waypoint
        return None
    x0, x1 = state.world_point(i), new.world_point(i)
    drift = 0.0
    for j, cc in enumerate(state.contacts):
        r = hand.resolve_body(cc.body)
        if j != i and r is not None and r.finger == ref.finger:
            drift = max(drift, max(float(np.linalg.norm(hand.point_position(r, cc.point_body, q)
                                                        - state.world_point(j))) for q in path))
    n = -(state.rotation[:3, :3] @ np.asarray(c.normal_object, dtype=float))
    gap = max(abs(float(n @ (hand.point_position(ref, c.point_body, q) - x0))) for q in path)
    length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    figures = SlideFigures(hand.fingers[ref.finger].name, c.body, i, tuple(x0.tolist()), tuple(x1.tolist()),
                           tuple((x1 - x0).tolist()), gap, drift, margin, len(path), length, clearance)
    cost = _cost(nodes, path, grasp.tau)
    return Transition("slide", sliding_combination(state, i), state.bodies(), new.bodies(), path,
                      np.tile(state.pose_vector(), (len(path), 1)), grasp.tau, grasp.tau, None, figures, cost)

