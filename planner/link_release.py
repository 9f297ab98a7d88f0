"""Link release edges (paper eq. 33, F -> D for some links of a finger): whole-arm regrasps.

A finger (an arm) that touches the object with several links, or with several bodies of one
link (a URDF link and its tip), lets go of the contacts of one body and keeps the others: an arm
lifts its forearm off the box and keeps its elbow on it, a thumb rolls off its pad onto its tip.
:mod:`planner.release_edges` releases whole fingers only; a finger with a single contacting body
gets no edge here. Towards a combination goal, a scene contact the goal keeps is not released
(it would never come back); searches towards a pose or a displacement goal get no link releases
(:data:`planner.graph.MOTION_GOALS`).

The object stays still. Checked, as for a whole finger:

* the stationary grasp (18) of the remaining contacts exists;
* the regrasp cone ``A'`` (33) of that combination contains a finger motion ``dq`` that separates
  every released contact (``J_d dq < 0``) and keeps every other contact in place
  (:func:`planner.release_edges.separating_motion`);
* the finger moves along it, projected back onto its kept contacts at every step
  (:func:`planner.object_motion.project_contacts`), until every released contact point is
  ``separation`` away from the object surface (its signed distance, measured at the contact's
  body point), within the joint limits;
* the path is certified collision-free (:func:`planner.collision.path_clearance_certified`)
  for every link, fixed body and other finger, the links that keep a contact being allowed to
  touch the object (not penetrate it): a released body on its own link must come clear as any
  link does; a released body on a link that keeps another contact (the pad and the tip of one
  URDF link) is judged by its contact point's separation, as the link as a whole still touches.
"""

from __future__ import annotations

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import shape_signed_distance
from analysis.kinematics import BodyRef
from analysis.mesh import load_mesh
from analysis.scene import Mesh
from planner.collision import path_clearance_certified
from planner.goals import is_fingertip
from planner.ik import joint_limits
from planner.nodes import GraphNodes
from planner.object_motion import keep_contacts, project_contacts
from planner.release_edges import release_check, release_edge
from planner.state import GraspState
from planner.transition import Transition

#: joint-space step (rad) of the release motion, as the whole-finger retreat
STEP = 0.02
#: the first step (rad), see :func:`release_link`
FIRST_STEP = 0.001
#: most steps of one release motion
MAX_STEPS = 100
#: an overlap present at the start (the capsules of an arm's neighbouring links, a link modelled
#: slightly into a body) may deepen by this fraction of ``min_radius`` over the release (the
#: whole-finger retreat allows none: on Baxter's 0.06 m capsules the overlap of two wrist links
#: grows by 3e-7 m a step as the elbow comes off), and any term by rounding (1e-12)
OVERLAP_SLACK = 0.1
ROUNDING = 1e-12


def link_release_edges(nodes: GraphNodes, state: GraspState, keep_tips: bool = False
                       ) -> list[tuple[Transition, GraspState]]:
    """Eq. (33), F -> D for the contacts of one body of a finger that touches with several bodies
    (see the module docstring); one edge per (finger, body). With ``keep_tips`` only the releases
    after which the finger still touches with its tip (:func:`planner.goals.is_fingertip`)."""
    hand = nodes.hand
    out: list[tuple[Transition, GraspState]] = []
    by_finger: dict[int, dict[str, list[int]]] = {}
    for i, c in enumerate(state.contacts):
        f = hand.finger_of(c.body)
        if f is not None:
            by_finger.setdefault(f, {}).setdefault(c.body, []).append(i)
    sa = None
    for f, bodies in sorted(by_finger.items()):
        if len(bodies) < 2:
            continue
        for body, released in bodies.items():
            if keep_tips and not any(is_fingertip(hand, state.contacts[i]) for b, idx in bodies.items()
                                     if b != body for i in idx):
                continue  # the finger would be left without its tip on the object
            if not _goal_lets_go(nodes, state, released):
                nodes.reject("combination goal keeps the contact")
                continue
            if sa is None:
                sa = nodes.analysis(state)
            checked = release_check(nodes, sa, state, released)
            if checked is None:
                continue
            keep = [i for i in range(state.L) if i not in released]
            path = release_link(nodes, state, f, checked.dq, keep, released)
            if path is None:
                nodes.reject(f"link cannot come off the object without collision ({body})")
                continue
            edge = release_edge(nodes, state, f, checked, keep, path)
            if edge is not None:
                out.append(edge)
    return out


def _goal_lets_go(nodes: GraphNodes, state: GraspState, released: list[int]) -> bool:
    """False where a combination goal keeps one of the ``released`` scene contacts (its letter
    is not ``D``): a released scene contact never comes back (a contact made again is a new one,
    :func:`planner.goals.combination_reached`), so the goal is out of reach from there."""
    goal = nodes.goal
    if goal.type != "combination" or goal.combination is None:
        return True
    comb = goal.combination.upper()
    for i in released:
        o = state.contacts[i].origin
        if o is not None and o < len(comb) and comb[o] != "D":
            return False
    return True


def minimal_motion(nodes: GraphNodes, state: GraspState, finger: int, dq: Array) -> Array:
    """The finger's part of ``dq`` ``(M,)`` with the same motion of every contact point of the
    finger and least norm: ``J^+ J dq_f``, ``J`` ``(3 k, m)`` the finger's stacked contact point
    Jacobians. The regrasp cone's lines include joints that move none of the contacts (Baxter's
    wrist beyond the forearm); they would take most of the step and none of the separation."""
    hand = nodes.hand
    sl = hand.finger_slice(finger)
    rows = []
    for c in state.contacts:
        ref = hand.resolve_body(c.body)
        if ref is not None and ref.finger == finger:
            x = hand.point_position(ref, c.point_body, state.q)
            rows.append(hand.point_jacobian(ref, x, state.q)[:, sl])
    J = np.vstack(rows)  # (3 k, m)
    return np.asarray(np.linalg.pinv(J, rcond=1e-10) @ (J @ dq[sl]))


def _longest_valid(nodes: GraphNodes, state: GraspState, keep: list[int], path: list[Array]) -> int:
    """How many waypoints of ``path`` (each ``(M,)``) from the start leave the kept contacts a valid
    scene (:func:`analysis.loader.check_geometry`, through the state's analysis); the tilt of a
    kept link grows along the motion, so the valid waypoints are a prefix (bisection)."""
    def valid(k: int) -> bool:
        try:
            nodes.analysis(keep_contacts(state, keep, path[k]))
        except SceneError:
            return False
        return True

    if valid(len(path) - 1):
        return len(path)
    lo, hi = 0, len(path) - 1  # valid(lo) (the start), not valid(hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if valid(mid) else (lo, mid)
    return lo + 1


def contact_separation(nodes: GraphNodes, state: GraspState, i: int, q: Array) -> float:
    """Signed distance of contact ``i``'s body point at the hand configuration ``q`` ``(M,)`` from
    the object's surface at the state's pose (scene units; 0 at the start of a release)."""
    hand, scene = nodes.hand, nodes.scene
    c = state.contacts[i]
    ref = hand.resolve_body(c.body)
    assert ref is not None
    x = hand.point_position(ref, c.point_body, q)  # (d,)
    d = scene.dim
    local = state.rotation[:d, :d].T @ (x - state.position[:d])  # (d,)
    shape = scene.object.shape
    if isinstance(shape, Mesh):
        return float(load_mesh(shape.file).signed_distance(local))
    sd = shape_signed_distance(shape, local, d)
    assert sd is not None
    return float(sd)


def release_link(nodes: GraphNodes, state: GraspState, finger: int, dq: Array, keep: list[int],
                 released: list[int]) -> Array | None:
    """Move ``finger`` along its part of the separating regrasp motion ``dq`` ``(M,)``, kept on
    its contacts in ``keep``, until every contact in ``released`` is ``2 min_radius`` off the
    object; the certified path ``(n, M)`` or None (see the module docstring)."""
    with nodes.timings.measure("motion"):
        hand, model = nodes.hand, nodes.model
        sl = hand.finger_slice(finger)
        u = np.zeros_like(dq)
        u[sl] = minimal_motion(nodes, state, finger, dq)
        if np.linalg.norm(u) < 1e-9:
            return None
        u /= np.linalg.norm(u)
        kept_links: list[BodyRef] = []
        for i in keep:
            ref = hand.resolve_body(state.contacts[i].body)
            if ref is not None and ref.finger == finger:
                kept_links.append(ref)
        allow = model.start_allowance(finger, state.q, state.position, state.rotation)
        allow = np.where(allow < 0.0, allow - OVERLAP_SLACK * model.min_radius, allow) - ROUNDING
        j_lo, j_hi = joint_limits(hand, finger)
        target, enough = 2.0 * model.min_radius, 0.5 * model.min_radius
        q = state.q.copy()
        path = [q.copy()]
        prev = min(contact_separation(nodes, state, i, q) for i in released)
        for k in range(MAX_STEPS):
            # the first step is short: it is the motion of eq. (33) (first order), which
            # planner.verify checks on the path's first segment; the projection's second-order
            # correction of the kept contacts stays below its tolerance there
            h = FIRST_STEP if k == 0 else STEP
            q_next, res = project_contacts(hand, state, q + h * u, keep)
            if res > 1e-6:
                return None
            if np.any(q_next[sl] < j_lo - 1e-9) or np.any(q_next[sl] > j_hi + 1e-9):
                break  # joint limit: stop here
            gap = min(contact_separation(nodes, state, i, q_next) for i in released)
            if gap <= prev:
                break  # no longer separating: stop where it was
            q, prev = q_next, gap
            path.append(q.copy())
            if gap >= target:
                break
        # the kept contacts must stay contacts: a link lying on a face that tilts about its
        # contact point leaves the contact (its surface normal turns off the object's, and the
        # scene check refuses it beyond a few degrees); keep the longest valid part of the path
        n = _longest_valid(nodes, state, keep, path)
        path = path[:n]
        if len(path) < 2 or min(contact_separation(nodes, state, i, path[-1]) for i in released) < enough:
            return None
        arr = np.array(path)
        ok, _, _ = path_clearance_certified(model, finger, state.q, arr[:, sl], state.position, state.rotation,
                                            touching_last=kept_links, touch_from=0, allowance=allow)
        return arr if ok else None

