"""Contact edges (paper eq. 33, D -> F): a free finger makes a new contact with its tip.

Candidate points of the object surface (:func:`surface_candidates`: rings on disks and spheres,
face grids on boxes, away from the existing contacts and facing the finger's base) are reached by
inverse kinematics (:mod:`planner.ik`, the last link pointing into the object). The edges are
lazy: their cost bound is the straight joint distance to the contact configuration plus the
effort term, and the OMPL transfer (:func:`planner.transfer.plan_transfer`, certified
collision-free) is planned only when the search needs the edge (:func:`validate_contact`); the
new grasp must have a stationary grasp (18).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.exceptions import CTPError
from analysis.kinematics import BodyRef, HandKinematics
from analysis.scene import Box, Disk, Sphere
from analysis.stationary import StationaryGrasp
from planner.ik import fingertip_ik
from planner.nodes import GraphNodes
from planner.search import Successor
from planner.state import GraspContact, GraspState, all_f
from planner.transfer import plan_transfer, transfer_key
from planner.transition import ContactFigures, Transition


def tip_body_name(hand: HandKinematics, finger: int) -> str:
    """The body name of a finger's last link (``"name/k"`` for scene chains, the URDF link name
    for URDF fingers)."""
    chain = hand.fingers[finger]
    return chain.body_names()[chain.n_joints - 1]


def surface_candidates(nodes: GraphNodes, state: GraspState, finger: int | None = None) -> list[tuple[Array, Array]]:
    """Candidate new contact points on the object surface: (point, inward normal), object
    frame; for a ``finger``, only those facing its base (outward normal towards the base)."""
    options, hand = nodes.options, nodes.hand
    shape = nodes.scene.object.shape
    n = options.surface_candidates
    d = state.dim
    pts: list[tuple[Array, Array]] = []
    if isinstance(shape, Disk):
        for k in range(n):
            a = 2 * np.pi * k / n
            u = np.array([np.cos(a), np.sin(a)])
            pts.append((shape.radius * u, -u))
    elif isinstance(shape, Sphere):  # rings about the object's equator (object frame)
        for lat in np.radians(options.sphere_latitudes):
            for k in range(n):
                az = 2 * np.pi * k / n
                u = np.array([np.cos(az) * np.cos(lat), np.sin(az) * np.cos(lat), np.sin(lat)])
                pts.append((shape.radius * u, -u))
    elif isinstance(shape, Box):
        c = np.asarray(shape.position if shape.position is not None else np.zeros(d), float)
        h = np.asarray(shape.size, float) / 2
        # every face: its centre and points halfway to its edges (a 3 x 3 grid in 3-D)
        for ax in range(d):
            others = [a for a in range(d) if a != ax]
            for sgn in (-1.0, 1.0):
                u = np.zeros(d)
                u[ax] = sgn
                for offs in itertools.product((0.0, -0.5, 0.5), repeat=len(others)):
                    p = c + h * u
                    for a, o in zip(others, offs, strict=True):
                        p[a] += o * h[a]
                    pts.append((p, -u))
    min_sp = options.min_contact_spacing * nodes.size
    out = [(p, nn) for p, nn in pts if all(np.linalg.norm(p - c.point_object) > min_sp for c in state.contacts)]
    if finger is None or isinstance(shape, Box):  # box faces: every face may be reached over
        return out
    R = state.rotation[:d, :d]
    chain = hand.fingers[finger]
    base = chain.body_pose(0, hand.q0[hand.finger_slice(finger)])[1][:d]
    to_base = R.T @ (base - state.position)  # object frame
    if d == 3:
        to_base[2] = 0.0  # horizontal direction to the base
    nb = float(np.linalg.norm(to_base))
    if nb < 1e-9:
        return out
    return [(p, nn) for p, nn in out if float(-nn @ to_base) / nb > options.facing]


def _finger_base(hand: HandKinematics, finger: int) -> Array:
    """World position ``(d,)`` of the finger's first joint (fixed on the palm)."""
    sl = hand.finger_slice(finger)
    return np.asarray(hand.fingers[finger].body_pose(0, hand.q0[sl])[1][: hand.dim])


def _finger_reach(hand: HandKinematics, finger: int) -> float:
    """Largest distance from the first joint to any point of the link axes: the sum of the
    link lengths (distances between consecutive joint origins do not depend on ``q``)."""
    sl = hand.finger_slice(finger)
    chain = hand.fingers[finger]
    q0 = hand.q0[sl]
    return float(sum(np.linalg.norm(np.subtract(*chain.body_segment(k, q0))) for k in range(chain.n_joints)))


def contact_edges(nodes: GraphNodes, state: GraspState) -> list[Successor]:
    """Eq. (33), D -> F: a free finger makes a new contact with its tip.

    Lazy edges: IK is solved here, the bound is the straight joint distance to the contact
    configuration plus the effort term; the OMPL transfer is planned (and certified) only
    when the search needs the edge (:func:`validate_contact`)."""
    hand, model, options = nodes.hand, nodes.model, nodes.options
    out: list[Successor] = []
    busy = {f for c in state.contacts if (f := hand.finger_of(c.body)) is not None}
    free = [f for f in range(len(hand.fingers)) if f not in busy]
    if not free:
        return out
    sa = nodes.analysis(state)
    grasp = sa.stationary(all_f(state))
    effort = 0.0 if grasp is None else options.effort_weight * float(np.linalg.norm(grasp.tau))
    R = state.rotation[: state.dim, : state.dim]
    for f in free:
        chain = hand.fingers[f]
        tip_ref = BodyRef(tip_body_name(hand, f), f, chain.n_joints - 1)
        r_tip = hand.body_radius(tip_ref)
        sl = hand.finger_slice(f)
        allow = model.start_allowance(f, state.q, state.position, state.rotation)
        for p_obj, n_obj in surface_candidates(nodes, state, f):
            s = state.position + R @ p_obj
            n = R @ n_obj
            with nodes.timings.measure("ik"):
                seeds: list[Array] = []
                for cand in (state.q[sl], hand.q0[sl], np.zeros(sl.stop - sl.start)):
                    if all(np.linalg.norm(cand - o) > 1e-9 for o in seeds):
                        seeds.append(cand)
                sols: list[Array] = []
                if float(np.linalg.norm(s - r_tip * n - _finger_base(hand, f))) > _finger_reach(hand, f):
                    seeds = []  # out of reach: no IK needed
                    nodes.reject("new contact point out of the finger's reach")
                for seed_q in seeds:
                    ck = (f, tuple(np.round(s, 6)), tuple(np.round(n, 6)), tuple(np.round(seed_q, 6)))
                    if ck not in nodes.ik_cache:
                        try:
                            nodes.ik_cache[ck] = fingertip_ik(hand, f, s - r_tip * n, n, [seed_q])
                        except CTPError:
                            nodes.ik_cache[ck] = []
                    sols.extend(x for x in nodes.ik_cache[ck] if all(np.linalg.norm(x - y) > 1e-6 for y in sols))
                valid = []
                for x in sols:  # the contact configuration itself must be collision-free
                    q_try = state.q.copy()
                    q_try[sl] = x
                    if model.is_clear(f, q_try, state.position, state.rotation, [tip_ref], allow):
                        valid.append(x)
            if not valid:
                nodes.reject("no collision-free inverse-kinematics solution for a new contact")
                continue
            qg = min(valid, key=lambda x: float(np.linalg.norm(x - state.q[sl])))
            q_new = state.q.copy()
            q_new[sl] = qg
            tip_local = hand.to_local(tip_ref, s, q_new)
            contact = GraspContact(tip_ref.name, tip_local, p_obj, n_obj, nodes.default_mu)
            new = GraspState((*state.contacts, contact), q_new, state.position, state.rotation, state.dim)
            key = nodes.add(new, validated=False)
            bound = float(np.linalg.norm(qg - state.q[sl])) + effort

            def validate(state: GraspState = state, new: GraspState = new, f: int = f,
                         qg: Array = qg, tip_ref: BodyRef = tip_ref, s: Array = s) -> tuple[float, Any] | None:
                return validate_contact(nodes, state, new, f, qg, tip_ref, s, grasp)

            out.append(Successor(key, max(bound, 1e-9), None, validate))
    return out


def validate_contact(nodes: GraphNodes, state: GraspState, new: GraspState, f: int, qg: Array, tip_ref: BodyRef,
                     s: Array, grasp: StationaryGrasp | None) -> tuple[float, Transition] | None:
    """The lazy check of a contact edge: the OMPL transfer of finger ``f`` to the touching
    configuration ``qg`` and the new grasp's stationary grasp (18); ``(cost, transition)`` or None."""
    hand, options = nodes.hand, nodes.options
    approach = options.approach * nodes.size
    key = transfer_key(nodes.model, state, f, qg, tip_ref, approach, options.seed, options.ompl_checks)
    if key not in nodes.transfers:  # the same transfer from another state: same answer (transfer_key)
        with nodes.timings.measure("ompl"):
            nodes.transfers[key] = plan_transfer(nodes.model, state, f, qg, tip_ref, approach, seed=options.seed,
                                                 time_limit=options.ompl_time, checks=options.ompl_checks)
    tp = nodes.transfers[key]
    if tp is None:
        nodes.reject("OMPL found no collision-free transfer to a new contact")
        return None
    if nodes.held(new) is None or not nodes.arrives(new):
        return None
    sl = hand.finger_slice(f)
    q_path = np.tile(state.q, (len(tp.waypoints), 1))
    q_path[:, sl] = tp.waypoints
    tau_st = None if grasp is None else grasp.tau
    effort = 0.0 if tau_st is None else options.effort_weight * float(np.linalg.norm(tau_st))
    figures = ContactFigures(hand.fingers[f].name, tuple(s.tolist()), tp.length, tp.clearance, tp.checks,
                             tp.ompl_seconds)
    t = Transition("contact", all_f(state) + "D", state.bodies(), new.bodies(), q_path,
                   np.tile(state.pose_vector(), (len(q_path), 1)), tau_st, tau_st, None, figures,
                   tp.length + effort)
    nodes.add(new)  # reached by a checked edge: validated
    return t.cost, t
