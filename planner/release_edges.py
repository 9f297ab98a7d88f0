"""Release edges (paper eq. 33, F -> D): one finger lets go of all its contacts.

The object stays still. Checked: the stationary grasp (18) of the remaining contacts exists, and
the regrasp cone ``A'`` (33) of that combination contains a finger motion that separates every
released contact (``J_d dq < 0``, :func:`separating_motion`); the finger retreats along it, kept
on the remaining contacts, until it is clear of the object (:func:`retreat`, certified by
:func:`~planner.collision.path_clearance_certified`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.kinematics import BodyRef
from analysis.regrasp import RegraspCone, regrasp_cone
from analysis.solvers.highs import solve_lp
from analysis.stationary import StationaryGrasp
from planner.collision import path_clearance_certified
from planner.ik import joint_limits
from planner.nodes import GraphNodes
from planner.object_motion import keep_contacts, project_contacts
from planner.state import GraspState, StateAnalysis
from planner.transition import ReleaseFigures, Transition


def release_edges(nodes: GraphNodes, state: GraspState) -> list[tuple[Transition, GraspState]]:
    """Eq. (33), F -> D: one finger lets go of all its contacts (at most
    ``max_free_fingers`` fingers are free at a time)."""
    hand, options = nodes.hand, nodes.options
    out: list[tuple[Transition, GraspState]] = []
    fingers = sorted({f for c in state.contacts if (f := hand.finger_of(c.body)) is not None})
    if len(hand.fingers) - len(fingers) >= options.max_free_fingers:
        return out
    sa = nodes.analysis(state)
    for f in fingers:
        released = [i for i, c in enumerate(state.contacts) if hand.finger_of(c.body) == f]
        if len(released) == state.L:
            nodes.reject("releasing a finger would leave no contact")
            continue
        checked = release_check(nodes, sa, state, released)
        if checked is None:
            continue
        keep = [i for i in range(state.L) if i not in released]
        path = retreat(nodes, state, f, checked.dq, keep)
        if path is None:
            nodes.reject("finger cannot retreat from the object without collision")
            continue
        edge = release_edge(nodes, state, f, checked, keep, path)
        if edge is not None:
            out.append(edge)
    return out


@dataclass(frozen=True)
class ReleaseCheck:
    """What eq. (33) gives a release: the combination (released contacts ``D``), its stationary
    grasp (18), the regrasp cone and the separating motion ``dq`` ``(M,)`` in it, at ``rate``."""

    combination: str
    grasp: StationaryGrasp
    cone: RegraspCone
    dq: Array  # (M,)
    rate: float


def release_check(nodes: GraphNodes, sa: StateAnalysis, state: GraspState, released: list[int]) -> ReleaseCheck | None:
    """The checks of eq. (18) and (33) for letting go of the contacts ``released`` (the others
    stick, or are frictionless), or None with the reason counted in ``nodes``."""
    comb = "".join("D" if i in released else ("F" if c.mu > 0 else "N") for i, c in enumerate(state.contacts))
    with nodes.timings.measure("analysis"):
        grasp = sa.stationary(comb)
        if grasp is not None:
            p = sa.parts(comb)
            cone = regrasp_cone(p.system, p.sel, p.ms, p.st, p.fs)
            dq, rate = separating_motion(cone.rays, cone.lines, cone.J_d, cone.feasible)
    if grasp is None:
        nodes.reject("no stationary grasp (18) of the remaining contacts")
        return None
    if dq is None or not cone.contains(dq):
        nodes.reject("regrasp cone (33) has no motion separating the released contacts")
        return None
    return ReleaseCheck(comb, grasp, cone, dq, rate)


def release_edge(nodes: GraphNodes, state: GraspState, finger: int, checked: ReleaseCheck, keep: list[int],
                 path: Array) -> tuple[Transition, GraspState] | None:
    """The release transition along the finger's ``path`` ``(n, M)`` and the state it leads to
    (the contacts ``keep``), or None when that state does not hold the object."""
    new = keep_contacts(state, keep, path[-1])
    if nodes.held(new, parent=state) is None:  # a whole finger let go: the others' contacts as they were
        return None
    grasp, cone = checked.grasp, checked.cone
    length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    cost = length + nodes.options.effort_weight * float(np.linalg.norm(grasp.tau))
    figures = ReleaseFigures(grasp.margin, checked.rate, int(cone.rays.shape[0]), int(cone.lines.shape[0]),
                             nodes.hand.fingers[finger].name, length)
    t = Transition("release", checked.combination, state.bodies(), new.bodies(), path,
                   np.tile(state.pose_vector(), (len(path), 1)), grasp.tau, grasp.tau, None, figures, cost)
    return t, new


def retreat(nodes: GraphNodes, state: GraspState, finger: int, dq: Array, keep: list[int]) -> Array | None:
    """Move along the separating regrasp motion ``dq`` ``(M,)`` (the finger's part, kept on the
    contacts ``keep``) until the finger is clear; the certified path ``(n, M)`` or None."""
    with nodes.timings.measure("motion"):
        hand, model = nodes.hand, nodes.model
        sl = hand.finger_slice(finger)
        u = np.zeros_like(dq)
        u[sl] = dq[sl]
        if np.linalg.norm(u) < 1e-9:
            return None
        u /= np.linalg.norm(u)
        q = state.q.copy()
        path = [q.copy()]
        # overlaps at the start (a link modelled slightly into the palm or a neighbour) may
        # persist but not deepen; "clear" is measured on the other terms
        allow = model.start_allowance(finger, q, state.position, state.rotation)
        free_terms = allow == 0.0
        j_lo, j_hi = joint_limits(hand, finger)
        h = 0.02
        free, first_free = False, 0  # clear of the object by half the minimum radius
        target = 4.0 * model.min_radius  # retreat this far when possible
        for _ in range(100):
            q_next, res = project_contacts(hand, state, q + h * u, keep)
            if res > 1e-6:
                return None
            if np.any(q_next[sl] < j_lo - 1e-9) or np.any(q_next[sl] > j_hi + 1e-9):
                break  # joint limit: stop here
            terms = model.clearance_terms(finger, q_next, state.position, state.rotation)
            if np.any(terms < allow - 1e-12) and free:
                break
            clear = float(terms[free_terms].min()) if free_terms.any() else np.inf
            if free and clear < 0.5 * model.min_radius:
                break  # going further would approach something again: stop where it was clear
            q = q_next
            path.append(q.copy())
            if not free and clear > 0.5 * model.min_radius:
                free, first_free = True, len(path) - 1
            if clear > target:
                break
        if not free:
            return None
        arr = np.array(path)
        touching = [BodyRef(b.name, finger, b.link) for b in model.links(finger)]
        # leaving the contact, the links may touch (not penetrate); once free, full clearance
        ok, _, _ = path_clearance_certified(model, finger, state.q, arr[: first_free + 1, sl],
                                            state.position, state.rotation, touching_last=touching,
                                            touch_from=0, allowance=allow)
        if ok and first_free < len(arr) - 1:
            ok, _, _ = path_clearance_certified(model, finger, state.q, arr[first_free:, sl],
                                                state.position, state.rotation, allowance=allow)
        return arr if ok else None


def separating_motion(rays: Array, lines: Array, J_d: Array, feasible: Array) -> tuple[Array | None, float]:
    """A unit finger motion in the regrasp cone (33) (non-negative combination of its rays plus
    its lines, generators that keep the equilibrium only) maximising the smallest separation
    rate ``-J_d dq`` of the released contacts (an LP)."""
    M = J_d.shape[1]
    nr = rays.shape[0]
    ok_rays = rays[feasible[:nr]] if nr else rays
    gens = np.vstack([ok_rays, lines]).reshape(-1, M)
    k_r, k_l = ok_rays.shape[0], lines.shape[0]
    if gens.shape[0] == 0:
        return None, 0.0
    # variables [lambda (k_r) >= 0, mu (k_l) free, s]: max s, -J_d G^T c >= s, sum|c| <= 1 (box)
    m = J_d.shape[0]
    JG = J_d @ gens.T  # (m, k)
    k = gens.shape[0]
    A_ub = np.hstack([JG, np.ones((m, 1))])
    b_ub = np.zeros(m)
    lb = np.r_[np.zeros(k_r), -np.ones(k_l), -np.inf]
    ub = np.r_[np.ones(k_r), np.ones(k_l), np.inf]
    res = solve_lp(np.r_[np.zeros(k), 1.0], A_ub=A_ub, b_ub=b_ub, lb=lb, ub=ub, maximize=True)
    if res.status != "optimal" or res.x is None or res.x[-1] <= 1e-9:
        return None, 0.0
    dq = gens.T @ res.x[:k]
    nrm = float(np.linalg.norm(dq))
    if nrm < 1e-12:
        return None, 0.0
    return dq / nrm, float(res.x[-1]) / nrm
