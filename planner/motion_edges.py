"""Object-motion edges (paper eq. 30-32): the object moves along a DAFC direction.

With the contacts of a set ``S_D`` in state D (by default the contacts on fixed bodies: the palm
lets go; towards a goal pose also the fixed-body contacts the straight motion to the goal lifts
off, when that is some of them only: a box tipped about an edge, :func:`_goal_lifted_contacts`),
possibly the fixed-body contacts sliding (S: a disk or sphere on the palm, a box's
corners along the table; with ``PlannerOptions.link_sliding`` also the contacts of a whole arm's
distal link along the object's faces) and the others F, the
combination is feasible (18 and 22), the direction is a DAFC member, and the torque set T (32) is
not empty; its recommended torque and the motion ``dzeta_c`` chosen by (31) move the object until
the D-contacts have separated by ``clearance`` (towards a goal pose: at most ``motion_step``).
The path of hand and object on the contact manifold ``A_c [dq; dr] = 0`` (for a 2-D disk the
contacts on a link's side rolling, for a 3-D sphere the F contacts on a fixed body's face:
:func:`~planner.object_motion.motion_manifold`) is integrated
(:func:`~planner.object_motion.integrate_object_motion`) and then planned by OMPL's constrained
planning (:func:`~planner.object_motion.plan_object_motion`); the state after it has the sliding
and the rolling contacts where the motion left them (new points on the body and the object).
Grasps with line contacts (a link touching with two or more points of one normal, a forearm lying
along a box's side) and motions with sliding links move at most ``motion_step`` at a time; any
motion of F- and D-points ends where its one torque's forces keep half of their friction margin
(:mod:`planner.motion_length`), and the next is analysed from there.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from analysis._types import Array
from analysis.exceptions import CTPError, SceneError
from analysis.pose import Pose
from analysis.scene import Box, Polygon
from analysis.torques import torque_set
from planner.goals import pose_goal_remaining, position_mask
from planner.manifold import ContactManifold, pose_displacement
from planner.motion_length import held_length, line_contacts, torque_margins, turned_normals
from planner.nodes import GraphNodes
from planner.object_motion import (
    integrate_object_motion,
    keep_contacts,
    plan_object_motion,
    rolled_contacts,
)
from planner.search import Successor
from planner.state import GraspContact, GraspState
from planner.transition import ObjectMotionFigures, Transition

#: prefix of a rejection that is a limit of the planner, not of the grasp (lifted into the
#: reason of a plan that was not found, :func:`planner.plan.plan`)
UNSUPPORTED = "not supported: "


def object_motion_edges(nodes: GraphNodes, state: GraspState) -> list[Successor]:
    """Eq. (30)-(32): move the object along a DAFC direction; the D-contacts separate.

    Lazy edges, as the contact edges: the analysis (the combination, the direction, the torque set
    T) and the integration of the motion (its end: the next state and the node) are done here;
    the bound is the straight joint distance plus the straight object distance (over the object
    size) to that end, plus the effort term; OMPL's constrained planning of the path between the
    two ends, and the new grasp's stationary grasp (18), only when the search needs the edge
    (:func:`validate_motion`)."""
    hand, goal, options, size = nodes.hand, nodes.goal, nodes.options, nodes.size
    out = []
    sa = nodes.analysis(state)
    L = state.L
    fixed = tuple(i for i, c in enumerate(state.contacts) if hand.finger_of(c.body) is None)
    if options.separate_finger_contacts:
        subsets: list[tuple[int, ...]] = [(i,) for i in range(L)] if L > 1 else []
        if len(fixed) > 1 and len(fixed) < L:
            subsets.append(fixed)
    else:  # fingers let go by regrasp edges; an object motion separates the fixed bodies
        subsets = [fixed] if fixed and len(fixed) < L else []
    if goal.type == "pose":
        subsets.append(())
        lifted = _goal_lifted_contacts(state, fixed, pose_goal_remaining(goal, state))
        if lifted and lifted not in subsets:  # a pivot: the fixed contacts the goal lifts separate
            subsets.append(lifted)
    plans: list[tuple[tuple[int, ...], tuple[int, ...]]] = [(dset, ()) for dset in subsets]  # (D-set, S-set)
    slide = options.sliding_motions
    if (goal.type == "pose" if slide is None else slide) and fixed and len(fixed) < L:
        # the contacts on fixed bodies slide (a disk or sphere rolling its contact point along, any
        # other object keeping its corners on the body's surface: ContactManifold), the fingers stick
        plans.append(((), fixed))
    if goal.type == "pose" and options.link_sliding:
        # a whole arm lying on the object's faces with several links (line contacts) cannot turn them
        # on the faces: the object follows the arms (a~ shrinks to a swing about the shoulders); the
        # contacts of one link of every such arm slide along their faces instead (S at links)
        for sset in _link_slide_sets(nodes, state):
            for dset in [d for d in subsets if d] or [()]:
                if not set(dset) & set(sset):
                    plans.append((dset, sset))
    for dset, sset in plans:
        comb = _letters(state, dset, sset)
        best = None
        with nodes.timings.measure("analysis"):
            summ = sa.summary(comb)
            if summ.feasible:
                p = sa.parts(comb)
                oracle = p.oracle()
                grasp = sa.stationary(comb)
                assert grasp is not None
                cands = _direction_candidates(nodes, state, p, dset, summ.example_direction)
                for dr in cands:
                    if not oracle.test(dr).member:
                        continue
                    ts = _torque_set(nodes, p, grasp, oracle, dr)
                    if ts is None:
                        nodes.reject("torque set (32) empty for a DAFC direction")
                        continue
                    motion = np.concatenate([ts.dq, ts.direction])  # (M + D,) per unit object motion
                    rates = -(p.ms.A_d @ motion) if dset else np.zeros(0)
                    if dset and float(np.min(rates)) <= 1e-6:
                        continue
                    best = (ts, rates, grasp)
                    break
        if not summ.feasible:
            nodes.reject(f"object motion: {summ.reason}")
            continue
        if best is None:
            nodes.reject("object motion: no DAFC direction with a torque set that separates the D-contacts"
                         if dset else "object motion: no DAFC direction towards the goal with a torque set")
            continue
        ts, rates, grasp = best
        if dset:
            dist = options.clearance * size / float(np.min(rates))
            if goal.type == "pose":  # towards a goal pose: on to the closest point of the line
                dist = max(dist, _goal_distance(nodes, state, ts.direction))
            dist = min(dist, 0.5 * size)
        elif goal.type == "pose":
            assert goal.pose is not None
            dist = min(float(np.linalg.norm(pose_goal_remaining(goal, state))), options.motion_step * size)
        else:
            dist = options.motion_step * size
        if _line_contacts(nodes, state) or any(nodes.hand.finger_of(state.contacts[i].body) is not None
                                               for i in sset):
            # links lying along the object (line contacts) or sliding on it: the torque of T holds
            # for the start of the motion (first order), and the object motions such grasps allow
            # are curved (two arms holding a box with two links each swing it about their
            # shoulders), so the object leaves the torque's direction faster; such motions are
            # motion_step long, each re-analysed (Baxter's swing: one motion of 8.6 cm replays 8 %
            # off in MuJoCo, motions of 1 cm 2.7 %; under one torque the forearms' slide lifts the
            # elbow joints off the box after 3 cm); D-contacts then separate by less than the
            # clearance
            dist = min(dist, options.motion_step * size)
        keep = [i for i in range(L) if i not in dset and i not in sset]
        with nodes.timings.measure("motion"):
            straight = integrate_object_motion(nodes.model, state, ts.direction, ts.dq, keep, list(dset), dist,
                                               check_path=False, sliding=sset, motion_space=p.ms.Lambda_r_t)
        # the one torque holds the sticking contacts only so far (planner.motion_length): the
        # motion ends where its forces keep KEPT_MARGIN of their friction margin, re-analysed there
        if straight is not None:
            with nodes.timings.measure("analysis"):
                margins = torque_margins(nodes, state, comb, keep, straight.q_path[-1], straight.pose_path[-1],
                                         ts.tau)
            held = dist if margins is None else held_length(dist, *margins)
            if held < dist:
                dist = held
                with nodes.timings.measure("motion"):
                    straight = None if not dist > 0 else integrate_object_motion(
                        nodes.model, state, ts.direction, ts.dq, keep, list(dset), dist, check_path=False,
                        sliding=sset, motion_space=p.ms.Lambda_r_t)
        if straight is None:
            nodes.reject("object motion leaves the contact manifold or its end collides")
            continue
        # the end of the motion is the integration's (OMPL plans between the two ends): the state
        # there, its node and the lower bound of the edge's cost are known before OMPL plans it
        q1 = straight.q_path[-1]  # (M,)
        s1 = pose_displacement(state, straight.pose_path[-1])  # (D,)
        new = _state_after(nodes, state, keep, sset, q1, s1, state.pose.displaced(s1).vector())
        if not nodes.arrives(new):
            continue
        effort = options.effort_weight * float(np.linalg.norm(ts.tau))
        # the joint path and the object path each at least as long as the straight line between their ends
        bound = (float(np.linalg.norm(q1 - state.q))
                 + float(np.linalg.norm(state.pose.displaced(s1).vector() - state.pose_vector())) / size)
        bound = max(bound * (1.0 - BOUND_SLACK) + effort, 1e-9)
        key = nodes.add(new, validated=False)

        def validate(state: GraspState = state, new: GraspState = new, key: Any = key, straight: Any = straight,
                     keep: list[int] = keep, dset: tuple[int, ...] = dset, sset: tuple[int, ...] = sset,
                     comb: str = comb, ts: Any = ts, rates: Array = rates, grasp: Any = grasp, summ: Any = summ,
                     effort: float = effort, bound: float = bound) -> tuple[float, Any] | None:
            return validate_motion(nodes, state, new, key, straight, keep, dset, sset, comb, ts, rates, grasp, summ,
                                   effort, bound)

        out.append(Successor(key, bound, None, validate))
    return out


#: relative slack of the lower bound of an object-motion edge (the path lengths are sums of
#: segment lengths, each at least the straight distance between its ends, up to round-off)
BOUND_SLACK = 1e-9


def _state_after(nodes: GraphNodes, state: GraspState, keep: list[int], sset: tuple[int, ...], q1: Array, s1: Array,
                 pose1: Array) -> GraspState:
    """The state at the end of an object motion from ``state``: the hand at ``q1`` ``(M,)``, the
    object at the displacement ``s1`` ``(D,)`` (pose vector ``pose1``), the contacts ``keep`` and
    ``sset``: sliding contacts where they slid, rolling ones (a disk on a link's side) where they
    rolled, the normals of contacts on the object's vertices and edges turned."""
    slid = _slid_contacts(nodes, state, sset, q1, s1)
    end = state.with_contacts(rolled_contacts(nodes.hand, nodes.scene, state, keep, q1, s1, slid), q1)
    final = end.with_pose(Pose.from_vector(pose1, state.dim))
    return _turned_normals(nodes, keep_contacts(final, sorted(keep + list(sset)), q1))


def validate_motion(nodes: GraphNodes, state: GraspState, new: GraspState, key: Any, straight: Any, keep: list[int],
                    dset: tuple[int, ...], sset: tuple[int, ...], comb: str, ts: Any, rates: Array, grasp: Any,
                    summ: Any, effort: float, bound: float) -> tuple[float, Transition] | None:
    """The lazy check of an object-motion edge to ``new`` (node ``key``): OMPL's constrained planning
    of the path from ``state`` to the integration's end ``straight``
    (:func:`~planner.object_motion.plan_object_motion`) and the new grasp's stationary grasp (18);
    ``(cost, transition)`` or None (``bound``: the edge's lower bound in the search)."""
    options, size = nodes.options, nodes.size
    with nodes.timings.measure("ompl"):
        om = plan_object_motion(nodes.model, state, straight, keep, list(dset), seed=options.seed,
                                time_limit=options.ompl_time, sliding=sset, checks=options.ompl_checks)
    if om is None:
        nodes.reject("OMPL found no collision-free object motion on the contact manifold")
        return None
    jl = float(np.sum(np.linalg.norm(np.diff(om.q_path, axis=0), axis=1)))
    cost = jl + om.length / size + effort
    if not (np.array_equal(om.q_path[-1], straight.q_path[-1])
            and np.array_equal(om.displacement_path[-1], pose_displacement(state, straight.pose_path[-1]))):
        # OMPL's path ends at the integration's end, the goal state it was given (its checks allow
        # 1e-6): should it end elsewhere, the state there, in the same node and at no less than
        # the bound the search holds for the edge, else the edge is refused
        new = _state_after(nodes, state, keep, sset, om.q_path[-1], om.displacement_path[-1], om.pose_path[-1])
        if new.key() != key or cost < bound:
            nodes.reject("OMPL's object motion ends away from its integration's end")
            return None
    if nodes.held(new) is None or not nodes.arrives(new):
        return None
    torques = {"direction": ts.direction.tolist(), "dq": ts.dq.tolist(), "phi": ts.phi,
               "vertices": None if ts.generators is None else int(ts.generators.vertices.shape[0]),
               "rays": None if ts.generators is None else int(ts.generators.all_directions().shape[0]),
               "dim_force_polyhedron": ts.dim_P, "work": ts.work, "nlp_status": ts.nlp_status}
    figures = ObjectMotionFigures(
        summ.dim_dafc, summ.a_bar, tuple(rates.tolist()), tuple(om.separations.tolist()), tuple(sset),
        om.length, om.max_residual, om.planner_states, om.states_checked, om.max_joint_step, om.ompl_seconds)
    t = Transition("object_motion", comb, state.bodies(), new.bodies(), om.q_path, om.pose_path, grasp.tau,
                   ts.tau, torques, figures, cost)
    nodes.add(new)  # reached by a checked edge: validated
    return cost, t


#: relative sizes of the nudges of a direction whose torque set the vertex enumeration (cdd, in
#: floating point) cannot compute: a direction exactly on a symmetry of the grasp (the two-arm hug
#: lifting straight up) makes its polyhedron degenerate ("numerical inconsistency")
NUDGES = (1e-5, 1e-4, 1e-3)


def _torque_set(nodes: GraphNodes, p: Any, grasp: Any, oracle: Any, dr: Array) -> Any:
    """The torque set (32) for the DAFC direction ``dr`` ``(D,)``; where the analysis fails on it
    (a solver error or an empty set), again for ``dr`` nudged by each of :data:`NUDGES` in turn along
    a fixed (seeded) direction of the motion space, while that is still a DAFC member; ``None`` if
    every try fails. The step then records the nudged direction, which is what it follows and what
    verify checks (cosine above 1 - 1e-6 with ``dr``)."""
    try:
        return torque_set(p.system, p.sel, p.ms, p.st, p.fs, grasp, dr, oracle=oracle)
    except CTPError:
        pass
    Lr = p.ms.Lambda_r_t  # (D, a~)
    v = Lr @ np.random.default_rng(nodes.options.seed).standard_normal(Lr.shape[1])
    v /= max(float(np.linalg.norm(v)), 1e-300)
    for eps in NUDGES:
        nudged = (dr + eps * v) / np.linalg.norm(dr + eps * v)
        if not oracle.test(nudged).member:
            return None
        try:
            return torque_set(p.system, p.sel, p.ms, p.st, p.fs, grasp, nudged, oracle=oracle)
        except CTPError:
            continue
    return None


def _line_contacts(nodes: GraphNodes, state: GraspState) -> bool:
    """Whether a finger link touches the object with two or more contacts of one normal (a line
    contact: the detector's end points of a link lying along a face)."""
    return line_contacts(nodes.hand, state.contacts)


def _link_slide_sets(nodes: GraphNodes, state: GraspState) -> list[tuple[int, ...]]:
    """Sets of link contacts that slide on the object's faces in an object motion towards a pose
    (:class:`~planner.manifold.ContactManifold` follows a capsule link on a face of a box or
    polygon): for the fingers that touch the object with two or more links, the contacts of the
    link farthest from the root of each (a forearm; the link nearer the root, an elbow, keeps its
    contacts and carries the arm's other links). Empty for other objects, and where a finger
    touches with one link only.

    Only the distal links slide: on Baxter's hug (examples/baxter_hug_box_lines.json) the lift
    with the forearms sliding (FFSSFFSSDDDD) replays in MuJoCo as analysed (direction cosine 0.996
    under its torque from T, 32; the forearms' far ends slide, everything else sticks), while the
    same lift with the elbows sliding and the forearms sticking (SSFFSSFFDDDD), also feasible to
    the analysis and cheaper to the search, does not: under its torque MuJoCo lifts the arms off
    the box at the elbow joints and slides the forearms' far ends (cosine 0.955, the replay 200 %
    off)."""
    shape = nodes.scene.object.shape
    if not isinstance(shape, Box | Polygon):
        return []
    by_finger: dict[int, dict[int, list[int]]] = {}
    for i, c in enumerate(state.contacts):
        ref = nodes.hand.resolve_body(c.body)
        if ref is None or ref.finger is None or ref.link is None:
            continue
        by_finger.setdefault(ref.finger, {}).setdefault(int(ref.link), []).append(i)
    arms = [links for links in by_finger.values() if len(links) >= 2]
    if not arms:
        return []
    sset = tuple(sorted(i for links in arms for i in links[max(links)]))
    try:
        ContactManifold(nodes.hand, state, [], sset, nodes.scene)
    except SceneError:
        return []  # a link of URDF shapes, an edge contact: not followed
    return [sset]


def _slid_contacts(nodes: GraphNodes, state: GraspState, sset: tuple[int, ...], q: Array,
                   s: Array) -> tuple[GraspContact, ...]:
    """The contacts after an object motion that ends with the hand at ``q`` ``(M,)`` and the object
    at the displacement ``s`` ``(D,)``: sliding ones (``sset``) where their bodies touch the object
    at the end (new points on the body and the object), the others unchanged."""
    if not sset:
        return state.contacts
    man = ContactManifold(nodes.hand, state, [], sset, nodes.scene)
    x = np.concatenate([q, s])
    out = list(state.contacts)
    for k, i in enumerate(sset):
        y, p_obj, n_obj = man.sliding_contact(k, x)
        ref = man.sliding[k]
        c = state.contacts[i]
        out[i] = GraspContact(c.body, nodes.hand.to_local(ref, y, q), p_obj, n_obj, c.mu, c.origin)
    return tuple(out)


def _turned_normals(nodes: GraphNodes, state: GraspState) -> GraspState:
    """The state with the normal of every contact on a vertex or an edge of the object turned to
    the touching body's surface normal (:func:`~planner.object_motion.corner_normal`): a sticking
    contact keeps its point on the link and on the object (eq. 7), not the link's orientation, so
    a forearm across a box's edge rolls about it while the box moves; the normal stays valid while
    it lies in the object's normal cone there, which the new state's scene check decides."""
    return turned_normals(nodes.scene, nodes.hand, state)


def _direction_candidates(nodes: GraphNodes, state: GraspState, p: Any, dset: tuple[int, ...],
                          example: Array | None) -> list[Array]:
    """Unit object directions ``(D,)`` to try, in the motion space: towards the goal pose, away
    from the D-contacts (the sum of their inward normals), the analysis' example direction."""
    D = p.system.D
    Lr = p.ms.Lambda_r_t
    cands: list[Array] = []
    goal = nodes.goal
    if goal.type == "pose" and goal.pose is not None:
        rest = pose_goal_remaining(goal, state)
        # the motion-space direction that brings the pose closest to the goal, each error measured
        # in its tolerance (a box the arms can lift only while it tips a little: the position
        # first, the rotation within its looser tolerance), then the plain projection
        rot_tol = goal.rotation_tol()
        w = np.r_[position_mask(goal, state.dim) / goal.position_tol(nodes.size),
                  np.full(D - state.dim, 0.0 if rot_tol is None else 1.0 / rot_tol)]
        c = np.linalg.lstsq(w[:, None] * Lr, w * rest, rcond=None)[0]
        cands.append(Lr @ c)
        cands.append(rest)
    if dset:
        # the object moves away from the D-contacts: along the sum of their inward normals
        v = np.zeros(D)
        v[: state.dim] = sum(state.world_normal(i) for i in dset)
        cands.append(v)
    if example is not None:
        cands.append(example)
    out = []
    for c in cands:
        c = Lr @ (Lr.T @ c)
        if np.linalg.norm(c) > 1e-9:
            out.append(c / np.linalg.norm(c))
    return out


#: a fixed contact separates towards the goal when its normal rate (per unit of the remaining
#: displacement's norm) exceeds this; the contacts on the axis of a pivot have rate 0
LIFT_RATE = 1e-3


def _goal_lifted_contacts(state: GraspState, fixed: tuple[int, ...], rest: Array) -> tuple[int, ...]:
    """The fixed-body contacts that the straight motion towards the goal, the twist ``rest`` ``(D,)``
    (velocity of ``p_o`` and, in 3-D, the world angular velocity), lifts off their bodies: normal
    rate ``n_i . (v + w x (x_i - p_o))`` (eq. 7 for a fixed body) above :data:`LIFT_RATE` times
    ``|rest|``. For a box tipped about an edge, the corners off the pivot edge; ``()`` unless it is
    a proper, non-empty subset of ``fixed`` (no pivot: all of them, or none, separate)."""
    scale = float(np.linalg.norm(rest))
    if scale <= 0 or len(fixed) < 2:
        return ()
    d = state.dim
    v = rest[:d]  # (d,)
    lifted = []
    for i in fixed:
        r = state.world_point(i) - state.position  # (d,)
        # (d,) the point's velocity; planar: w x r = theta_dot (-r_y, r_x)
        u = v + np.cross(rest[3:], r) if d == 3 else v + rest[2] * np.array([-r[1], r[0]])
        if float(state.world_normal(i) @ u) > LIFT_RATE * scale:
            lifted.append(i)
    return tuple(lifted) if 0 < len(lifted) < len(fixed) else ()


def _goal_distance(nodes: GraphNodes, state: GraspState, dr: Array) -> float:
    """How far along the unit direction ``dr`` ``(D,)`` the pose comes closest to the goal pose
    (errors in units of their tolerances, the rotation and the free axes not counted); 0 when
    ``dr`` leads away."""
    goal = nodes.goal
    rest = pose_goal_remaining(goal, state)
    rot_tol = goal.rotation_tol()
    d = state.dim
    w = np.r_[position_mask(goal, d) / goal.position_tol(nodes.size),
              np.full(len(dr) - d, 0.0 if rot_tol is None else 1.0 / rot_tol)]
    den = float(np.sum((w * dr) ** 2))
    return max(0.0, float(np.sum(w * w * dr * rest)) / den) if den > 0 else 0.0


def _letters(state: GraspState, dset: tuple[int, ...], sset: tuple[int, ...]) -> str:
    """The combination of an object motion: D for ``dset``, S (N without friction) for ``sset``,
    F (N) for the others."""
    out = []
    for i, c in enumerate(state.contacts):
        if i in dset:
            out.append("D")
        elif c.mu <= 0:
            out.append("N")
        else:
            out.append("S" if i in sset else "F")
    return "".join(out)
