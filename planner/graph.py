"""The contact-state graph: grasp states and the transitions between them.

Nodes are :class:`~planner.state.GraspState` keys; the graph itself is a ``networkx.DiGraph``
built by :func:`planner.search.best_first_search` from :meth:`ContactStateGraph.successors`.
Every edge is a :class:`Transition` checked by the closure analysis:

* ``release`` (eq. 33, F -> D): every contact of one finger becomes D while the object stays
  still. Checked: the stationary grasp (18) of the remaining contacts exists, and the regrasp
  cone A' (33) of that combination contains a finger motion that separates every released
  contact (``J_d dq < 0``); the finger retreats along it until it is clear of the object.
* ``contact`` (eq. 33, D -> F): a free finger (no contact) moves to a new contact at a
  candidate point of the object surface with its tip: IK (CasADi) and an OMPL path that is
  collision-free (certified densely); the new grasp's stationary grasp (18) exists.
* ``object_motion`` (eq. 30-32): with the contacts of a set ``S_D`` in state D and the others F,
  the combination is feasible (18 and 22), the direction is a DAFC member, the torque set T (32)
  is not empty; its recommended torque and the motion ``dzeta_c`` chosen by (31) move the object
  until the D-contacts have separated by ``clearance``; the path of hand and object on the contact
  manifold ``A_c [dq; dr] = 0`` is planned by OMPL's constrained planning
  (:func:`planner.ompl_paths.plan_object_motion`).

Costs: joint-path length + object-path length / object size + ``effort_weight`` * |tau|.
"""

from __future__ import annotations

import itertools
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.dafc import dafc_set
from analysis.exceptions import CTPError, SceneError
from analysis.kinematics import BodyRef, HandKinematics
from analysis.regrasp import regrasp_cone
from analysis.scene import Box, Disk, Scene, Sphere
from analysis.solvers.highs import solve_lp
from analysis.torques import torque_set
from planner.goals import Goal
from planner.ompl_paths import (
    CollisionModel,
    ContactManifold,
    fingertip_ik,
    integrate_object_motion,
    joint_limits,
    keep_contacts,
    path_clearance_certified,
    plan_object_motion,
    plan_transfer,
    project_contacts,
)
from planner.search import Successor
from planner.state import AnalysisCache, GraspContact, GraspState, StateAnalysis, all_f


@dataclass(frozen=True)
class Transition:
    """One edge of the contact-state graph (a step of a plan)."""

    kind: str  # "release" | "contact" | "object_motion"
    combination: str  # the combination of the source state's contacts during the step
    contacts_before: tuple[str, ...]
    contacts_after: tuple[str, ...]
    q_path: Array  # (n, M) joint waypoints of the whole hand
    object_path: Array  # (n, D) object pose vectors
    tau_stationary: Array | None  # (M,) tau_st of (18) during the step
    tau: Array | None  # (M,) the chosen torque (object motion: a member of T, eq. 32)
    torque_set: dict[str, Any] | None  # summary of T: number of vertices/rays, dim of P, work
    figures: dict[str, Any]  # the analysis numbers that justify the step
    cost: float


@dataclass(frozen=True)
class PlannerOptions:
    """Tuning of the graph expansion (lengths in units of the object size)."""

    surface_candidates: int = 8  # candidate new-contact points on the object surface
    min_contact_spacing: float = 0.3  # new contacts stay this far from existing ones
    approach: float = 0.06  # pre-contact back-off distance
    clearance: float = 0.04  # separation reached by an object motion
    effort_weight: float = 0.1
    ompl_time: float = 0.15
    dafc_samples: int = 64
    seed: int = 0
    #: object motions may also separate single finger contacts (more edges, slower); by default
    #: they separate the contacts on fixed bodies (the palm lets go, Fig. 5 (3) -> (4))
    separate_finger_contacts: bool = False
    #: object motions in which the contacts on fixed bodies slide (S, eq. 5, 11-12) while the
    #: fingers stick: ``None`` for pose goals only (where the object must get somewhere), or
    #: always / never. Followed for disk and sphere objects (the sliding contact keeps touching).
    sliding_motions: bool | None = None
    #: longest object motion towards a goal pose, and length of a sliding motion (object sizes):
    #: the torque of T is chosen for the start of the motion (first order), so a longer way is
    #: taken in several motions, each re-analysed
    motion_step: float = 0.03
    #: A* heuristic for the ``active`` goal: ``heuristic_weight`` per fingertip contact still
    #: missing (2 in 2-D, 3 in 3-D: the fewest point contacts with friction that can give active
    #: closure) plus one if a fixed body still touches; for the ``fingertips`` goal,
    #: ``heuristic_weight`` per finger not yet touching with its tip only. It never overestimates
    #: when every contact and object-motion edge costs at least ``heuristic_weight``; 0 gives plain
    #: Dijkstra.
    heuristic_weight: float = 1.0
    #: latitudes (degrees) of the candidate rings on a sphere
    sphere_latitudes: tuple[float, ...] = (-10.0, 0.0, 15.0)
    #: a candidate faces a finger when cos(outward normal, direction to its base) exceeds this
    facing: float = 0.3
    #: at most this many fingers are free (without contact) at a time: a finger is released only
    #: while fewer are in transit (regrasping one finger at a time prunes the graph)
    max_free_fingers: int = 1


@dataclass
class ContactStateGraph:
    """Expansion of grasp states for the search (the graph is held by the search)."""

    scene: Scene
    hand: HandKinematics
    goal: Goal
    options: PlannerOptions = field(default_factory=PlannerOptions)
    states: dict[Any, GraspState] = field(default_factory=dict)
    rejections: Counter[str] = field(default_factory=Counter)
    timing: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    validated: set[Any] = field(default_factory=set)

    def __post_init__(self) -> None:
        from analysis.geometry import object_size

        self.size = object_size(self.scene)
        self.model = CollisionModel.of(self.scene, self.hand)
        self.cache = AnalysisCache(self.scene, self.hand)
        mus = [c.mu for c in self.scene.contacts if c.mu > 0]
        self.default_mu = float(min(mus)) if mus else 0.0
        self._ik_cache: dict[tuple[Any, ...], list[Array]] = {}

    # -- nodes ----------------------------------------------------------------------------------

    def add(self, state: GraspState, validated: bool = True) -> Any:
        """Register a state; a validated one (reached by a checked edge) is never replaced."""
        k = state.key()
        if k not in self.validated:
            self.states[k] = state
            if validated:
                self.validated.add(k)
        return k

    def analysis(self, state: GraspState) -> StateAnalysis:
        import time

        t0 = time.perf_counter()
        try:
            return self.cache(state)
        finally:
            self.timing["analysis"] += time.perf_counter() - t0

    def _reject(self, reason: str) -> None:
        self.rejections[reason] += 1

    def held(self, state: GraspState) -> StateAnalysis | None:
        """The analysis of a state whose contacts hold the object (18 for all-F), else None."""
        try:
            sa = self.analysis(state)
        except SceneError:
            self._reject("new grasp is geometrically inconsistent")
            return None
        if sa.stationary(all_f(state)) is None:
            self._reject("no stationary grasp (18) of the new contacts")
            return None
        return sa

    # -- goals ----------------------------------------------------------------------------------

    def is_goal(self, key: Any) -> bool:
        return goal_reached(self, self.states[key], self.goal)

    def is_fingertip(self, c: GraspContact) -> bool:
        """A contact near the distal end of the last link of its finger."""
        ref = self.hand.resolve_body(c.body)
        if ref is None or ref.finger is None:
            return False
        chain = self.hand.fingers[ref.finger]
        if ref.link >= chain.n_joints:
            return True  # a link beyond the last joint (a URDF tip link) is the tip
        if ref.link != chain.n_joints - 1:
            return False
        a, b = chain.body_segment(ref.link, self.hand.q0[self.hand.finger_slice(ref.finger)])
        R, o = chain.body_pose(ref.link, self.hand.q0[self.hand.finger_slice(ref.finger)])
        tip_local = R.T @ (b - o)
        length = float(np.linalg.norm(b - a))
        return float(np.linalg.norm(c.point_body - tip_local)) <= 0.1 * length + self.hand.body_radius(ref) + 1e-9

    def heuristic(self, key: Any) -> float:
        """See :attr:`PlannerOptions.heuristic_weight`."""
        w = self.options.heuristic_weight
        if self.goal.type not in ("active", "fingertips") or w == 0.0:
            return 0.0
        st = self.states[key]
        if self.goal.type == "fingertips":  # fingers still to (re)grasp with their tip
            done = {f for f in range(len(self.hand.fingers))
                    if (cs := [c for c in st.contacts if self._finger_of(c.body) == f])
                    and all(self.is_fingertip(c) for c in cs)}
            return w * (len(self.hand.fingers) - len(done))
        need = 2 if st.dim == 2 else 3
        tips = sum(self.is_fingertip(c) for c in st.contacts)
        fixed = any(self._finger_of(c.body) is None for c in st.contacts)
        return w * (max(0, need - tips) + int(fixed))

    # -- expansion ------------------------------------------------------------------------------

    def successors(self, key: Any) -> list[Successor]:
        state = self.states[key]
        out: list[Successor] = []
        for t, new in self.release_edges(state) + self.object_motion_edges(state):
            out.append(Successor(self.add(new), t.cost, t))
        out.extend(self.contact_edges(state))
        return out

    def _finger_of(self, body: str) -> int | None:
        ref = self.hand.resolve_body(body)
        return None if ref is None else ref.finger

    def release_edges(self, state: GraspState) -> list[tuple[Transition, GraspState]]:
        """Eq. (33), F -> D: one finger lets go of all its contacts."""
        import time

        out: list[tuple[Transition, GraspState]] = []
        fingers = sorted({f for c in state.contacts if (f := self._finger_of(c.body)) is not None})
        if len(self.hand.fingers) - len(fingers) >= self.options.max_free_fingers:
            return out
        sa = self.analysis(state)
        for f in fingers:
            released = [i for i, c in enumerate(state.contacts) if self._finger_of(c.body) == f]
            if len(released) == state.L:
                self._reject("releasing a finger would leave no contact")
                continue
            comb = "".join("D" if i in released else ("F" if c.mu > 0 else "N")
                           for i, c in enumerate(state.contacts))
            t0 = time.perf_counter()
            grasp = sa.stationary(comb)
            if grasp is None:
                self._reject("no stationary grasp (18) of the remaining contacts")
                self.timing["analysis"] += time.perf_counter() - t0
                continue
            p = sa.parts(comb)
            cone = regrasp_cone(p.system, p.sel, p.ms, p.st, p.fs)
            dq, rate = _separating_motion(cone.rays, cone.lines, cone.J_d, cone.feasible)
            self.timing["analysis"] += time.perf_counter() - t0
            if dq is None or not cone.contains(dq):
                self._reject("regrasp cone (33) has no motion separating the released contacts")
                continue
            keep = [i for i in range(state.L) if i not in released]
            path = self._retreat(state, f, dq, keep)
            if path is None:
                self._reject("finger cannot retreat from the object without collision")
                continue
            q_new = path[-1]
            new = keep_contacts(state, keep, q_new, state)
            if self.held(new) is None:
                continue
            length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
            cost = length + self.options.effort_weight * float(np.linalg.norm(grasp.tau))
            t = Transition(
                "release", comb, state.bodies(), new.bodies(), path,
                np.tile(state.pose_vector(), (len(path), 1)), grasp.tau, grasp.tau, None,
                {"equation": "33", "stationary_margin": grasp.margin, "separation_rate": rate,
                 "regrasp_rays": int(cone.rays.shape[0]), "regrasp_lines": int(cone.lines.shape[0]),
                 "finger": self.hand.fingers[f].name, "joint_path_length": length},
                cost,
            )
            out.append((t, new))
        return out

    def _retreat(self, state: GraspState, finger: int, dq: Array, keep: list[int]) -> Array | None:
        """Move along the separating regrasp motion until the finger is clear; certified path."""
        import time

        t0 = time.perf_counter()
        try:
            sl = self.hand.finger_slice(finger)
            u = np.zeros_like(dq)
            u[sl] = dq[sl]
            if np.linalg.norm(u) < 1e-9:
                return None
            u /= np.linalg.norm(u)
            q = state.q.copy()
            path = [q.copy()]
            # overlaps at the start (a link modelled slightly into the palm or a neighbour) may
            # persist but not deepen; "clear" is measured on the other terms
            allow = self.model.start_allowance(finger, q, state.position, state.rotation)
            free_terms = allow == 0.0
            j_lo, j_hi = joint_limits(self.hand, finger)
            h = 0.02
            free, first_free = False, 0  # clear of the object by half the minimum radius
            target = 4.0 * self.model.min_radius  # retreat this far when possible
            for _ in range(100):
                q_next, res = project_contacts(self.hand, state, q + h * u, keep)
                if res > 1e-6:
                    return None
                if np.any(q_next[sl] < j_lo - 1e-9) or np.any(q_next[sl] > j_hi + 1e-9):
                    break  # joint limit: stop here
                terms = self.model.clearance_terms(finger, q_next, state.position, state.rotation)
                if np.any(terms < allow - 1e-12) and free:
                    break
                clear = float(terms[free_terms].min()) if free_terms.any() else np.inf
                if free and clear < 0.5 * self.model.min_radius:
                    break  # going further would approach something again: stop where it was clear
                q = q_next
                path.append(q.copy())
                if not free and clear > 0.5 * self.model.min_radius:
                    free, first_free = True, len(path) - 1
                if clear > target:
                    break
            if not free:
                return None
            arr = np.array(path)
            touching = [BodyRef(b.name, finger, b.link) for b in self.model.links(finger)]
            # leaving the contact, the links may touch (not penetrate); once free, full clearance
            ok, _, _ = path_clearance_certified(self.model, finger, state.q, arr[: first_free + 1, sl],
                                                state.position, state.rotation, touching_last=touching,
                                                touch_from=0, allowance=allow)
            if ok and first_free < len(arr) - 1:
                ok, _, _ = path_clearance_certified(self.model, finger, state.q, arr[first_free:, sl],
                                                    state.position, state.rotation, allowance=allow)
            return arr if ok else None
        finally:
            self.timing["motion"] += time.perf_counter() - t0

    def surface_candidates(self, state: GraspState, finger: int | None = None) -> list[tuple[Array, Array]]:
        """Candidate new contact points on the object surface: (point, inward normal), object
        frame; for a ``finger``, only those facing its base (outward normal towards the base)."""
        shape = self.scene.object.shape
        n = self.options.surface_candidates
        d = state.dim
        pts: list[tuple[Array, Array]] = []
        if isinstance(shape, Disk):
            for k in range(n):
                a = 2 * np.pi * k / n
                u = np.array([np.cos(a), np.sin(a)])
                pts.append((shape.radius * u, -u))
        elif isinstance(shape, Sphere):  # rings about the object's equator (object frame)
            for lat in np.radians(self.options.sphere_latitudes):
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
        min_sp = self.options.min_contact_spacing * self.size
        out = [(p, nn) for p, nn in pts if all(np.linalg.norm(p - c.point_object) > min_sp for c in state.contacts)]
        if finger is None or isinstance(shape, Box):  # box faces: every face may be reached over
            return out
        R = state.rotation[:d, :d]
        chain = self.hand.fingers[finger]
        base = chain.body_pose(0, self.hand.q0[self.hand.finger_slice(finger)])[1][:d]
        to_base = R.T @ (base - state.position)  # object frame
        if d == 3:
            to_base[2] = 0.0  # horizontal direction to the base
        nb = float(np.linalg.norm(to_base))
        if nb < 1e-9:
            return out
        return [(p, nn) for p, nn in out if float(-nn @ to_base) / nb > self.options.facing]

    def _finger_base(self, finger: int) -> Array:
        """World position ``(d,)`` of the finger's first joint (fixed on the palm)."""
        sl = self.hand.finger_slice(finger)
        return np.asarray(self.hand.fingers[finger].body_pose(0, self.hand.q0[sl])[1][: self.hand.dim])

    def _finger_reach(self, finger: int) -> float:
        """Largest distance from the first joint to any point of the link axes: the sum of the
        link lengths (distances between consecutive joint origins do not depend on ``q``)."""
        sl = self.hand.finger_slice(finger)
        chain = self.hand.fingers[finger]
        q0 = self.hand.q0[sl]
        return float(sum(np.linalg.norm(np.subtract(*chain.body_segment(k, q0))) for k in range(chain.n_joints)))

    def contact_edges(self, state: GraspState) -> list[Successor]:
        """Eq. (33), D -> F: a free finger makes a new contact with its tip.

        Lazy edges: IK is solved here, the bound is the straight joint distance to the contact
        configuration plus the effort term; the OMPL transfer is planned (and certified) only
        when the search needs the edge (:meth:`_validate_contact`)."""
        import time

        out: list[Successor] = []
        busy = {f for c in state.contacts if (f := self._finger_of(c.body)) is not None}
        free = [f for f in range(len(self.hand.fingers)) if f not in busy]
        if not free:
            return out
        sa = self.analysis(state)
        grasp = sa.stationary(all_f(state))
        effort = 0.0 if grasp is None else self.options.effort_weight * float(np.linalg.norm(grasp.tau))
        R = state.rotation[: state.dim, : state.dim]
        for f in free:
            chain = self.hand.fingers[f]
            tip_ref = BodyRef(tip_body_name(self.hand, f), f, chain.n_joints - 1)
            r_tip = self.hand.body_radius(tip_ref)
            sl = self.hand.finger_slice(f)
            allow = self.model.start_allowance(f, state.q, state.position, state.rotation)
            for p_obj, n_obj in self.surface_candidates(state, f):
                s = state.position + R @ p_obj
                n = R @ n_obj
                t0 = time.perf_counter()
                seeds: list[Array] = []
                for cand in (state.q[sl], self.hand.q0[sl], np.zeros(sl.stop - sl.start)):
                    if all(np.linalg.norm(cand - o) > 1e-9 for o in seeds):
                        seeds.append(cand)
                sols: list[Array] = []
                if float(np.linalg.norm(s - r_tip * n - self._finger_base(f))) > self._finger_reach(f):
                    seeds = []  # out of reach: no IK needed
                    self._reject("new contact point out of the finger's reach")
                for seed_q in seeds:
                    ck = (f, tuple(np.round(s, 6)), tuple(np.round(n, 6)), tuple(np.round(seed_q, 6)))
                    if ck not in self._ik_cache:
                        try:
                            self._ik_cache[ck] = fingertip_ik(self.hand, f, s - r_tip * n, n, [seed_q])
                        except CTPError:
                            self._ik_cache[ck] = []
                    sols.extend(x for x in self._ik_cache[ck] if all(np.linalg.norm(x - y) > 1e-6 for y in sols))
                valid = []
                for x in sols:  # the contact configuration itself must be collision-free
                    q_try = state.q.copy()
                    q_try[sl] = x
                    if self.model.finger_clearance(f, q_try, state.position, state.rotation, [tip_ref],
                                                   allow) >= 0.0:
                        valid.append(x)
                self.timing["ik"] += time.perf_counter() - t0
                if not valid:
                    self._reject("no collision-free inverse-kinematics solution for a new contact")
                    continue
                qg = min(valid, key=lambda x: float(np.linalg.norm(x - state.q[sl])))
                q_new = state.q.copy()
                q_new[sl] = qg
                tip_local = self.hand.to_local(tip_ref, s, q_new)
                contact = GraspContact(tip_ref.name, tip_local, p_obj, n_obj, self.default_mu)
                new = GraspState((*state.contacts, contact), q_new, state.position, state.rotation, state.dim)
                key = self.add(new, validated=False)
                bound = float(np.linalg.norm(qg - state.q[sl])) + effort

                def validate(state: GraspState = state, new: GraspState = new, f: int = f,
                             qg: Array = qg, tip_ref: BodyRef = tip_ref, s: Array = s) -> tuple[float, Any] | None:
                    return self._validate_contact(state, new, f, qg, tip_ref, s, grasp)

                out.append(Successor(key, max(bound, 1e-9), None, validate))
        return out

    def _validate_contact(self, state: GraspState, new: GraspState, f: int, qg: Array, tip_ref: BodyRef,
                          s: Array, grasp: Any) -> tuple[float, Transition] | None:
        import time

        t0 = time.perf_counter()
        tp = plan_transfer(self.model, state, f, qg, tip_ref, self.options.approach * self.size,
                           seed=self.options.seed, time_limit=self.options.ompl_time)
        self.timing["ompl"] += time.perf_counter() - t0
        if tp is None:
            self._reject("OMPL found no collision-free transfer to a new contact")
            return None
        if self.held(new) is None:
            return None
        sl = self.hand.finger_slice(f)
        q_path = np.tile(state.q, (len(tp.waypoints), 1))
        q_path[:, sl] = tp.waypoints
        tau_st = None if grasp is None else grasp.tau
        effort = 0.0 if tau_st is None else self.options.effort_weight * float(np.linalg.norm(tau_st))
        t = Transition(
            "contact", all_f(state) + "D", state.bodies(), new.bodies(), q_path,
            np.tile(state.pose_vector(), (len(q_path), 1)), tau_st, tau_st, None,
            {"equation": "33", "finger": self.hand.fingers[f].name, "contact_point": s.tolist(),
             "joint_path_length": tp.length, "min_clearance": tp.clearance,
             "configurations_checked": tp.checks, "ompl_seconds": tp.ompl_seconds},
            tp.length + effort,
        )
        k = new.key()
        if k not in self.validated:
            self.states[k] = new
            self.validated.add(k)
        return t.cost, t

    def object_motion_edges(self, state: GraspState) -> list[tuple[Transition, GraspState]]:
        """Eq. (30)-(32): move the object along a DAFC direction; the D-contacts separate."""
        import time

        out = []
        sa = self.analysis(state)
        L = state.L
        fixed = tuple(i for i, c in enumerate(state.contacts) if self._finger_of(c.body) is None)
        if self.options.separate_finger_contacts:
            subsets: list[tuple[int, ...]] = [(i,) for i in range(L)] if L > 1 else []
            if len(fixed) > 1 and len(fixed) < L:
                subsets.append(fixed)
        else:  # fingers let go by regrasp edges; an object motion separates the fixed bodies
            subsets = [fixed] if fixed and len(fixed) < L else []
        if self.goal.type == "pose":
            subsets.append(())
        plans: list[tuple[tuple[int, ...], tuple[int, ...]]] = [(dset, ()) for dset in subsets]  # (D-set, S-set)
        slide = self.options.sliding_motions
        if (self.goal.type == "pose" if slide is None else slide) and fixed and len(fixed) < L \
                and isinstance(self.scene.object.shape, Disk | Sphere):
            plans.append(((), fixed))
        for dset, sset in plans:
            comb = _letters(state, dset, sset)
            t0 = time.perf_counter()
            summ = sa.summary(comb)
            if not summ.feasible:
                self.timing["analysis"] += time.perf_counter() - t0
                self._reject(f"object motion: {summ.reason}")
                continue
            p = sa.parts(comb)
            oracle = p.oracle()
            grasp = sa.stationary(comb)
            assert grasp is not None
            cands = self._direction_candidates(state, p, dset, summ.example_direction)
            best = None
            for dr in cands:
                if not oracle.test(dr).member:
                    continue
                try:
                    ts = torque_set(p.system, p.sel, p.ms, p.st, p.fs, grasp, dr, oracle=oracle)
                except CTPError:
                    self._reject("torque set (32) empty for a DAFC direction")
                    continue
                motion = np.concatenate([ts.dq, ts.direction])  # (M + D,) per unit object motion
                rates = -(p.ms.A_d @ motion) if dset else np.zeros(0)
                if dset and float(np.min(rates)) <= 1e-6:
                    continue
                best = (ts, rates)
                break
            self.timing["analysis"] += time.perf_counter() - t0
            if best is None:
                self._reject("object motion: no DAFC direction with a torque set that separates the D-contacts"
                             if dset else "object motion: no DAFC direction towards the goal with a torque set")
                continue
            ts, rates = best
            if dset:
                dist = min(self.options.clearance * self.size / float(np.min(rates)), 0.5 * self.size)
            elif self.goal.type == "pose":
                assert self.goal.pose is not None
                dist = min(float(np.linalg.norm(np.asarray(self.goal.pose) - state.pose_vector())),
                           self.options.motion_step * self.size)
            else:
                dist = self.options.motion_step * self.size
            keep = [i for i in range(L) if i not in dset and i not in sset]
            t0 = time.perf_counter()
            straight = integrate_object_motion(self.model, state, ts.direction, ts.dq, keep, list(dset), dist,
                                               check_path=False, sliding=sset)
            self.timing["motion"] += time.perf_counter() - t0
            if straight is None:
                self._reject("object motion leaves the contact manifold or its end collides")
                continue
            t0 = time.perf_counter()
            om = plan_object_motion(self.model, state, straight, keep, list(dset), seed=self.options.seed,
                                    time_limit=self.options.ompl_time, sliding=sset)
            self.timing["ompl"] += time.perf_counter() - t0
            if om is None:
                self._reject("OMPL found no collision-free object motion on the contact manifold")
                continue
            end = GraspState(self._slid_contacts(state, sset, om), om.q_path[-1], state.position, state.rotation,
                             state.dim)
            final = _pose_state(end, om.pose_path[-1])
            new = keep_contacts(final, sorted(keep + list(sset)), om.q_path[-1], final)
            if self.held(new) is None:
                continue
            jl = float(np.sum(np.linalg.norm(np.diff(om.q_path, axis=0), axis=1)))
            cost = jl + om.length / self.size + self.options.effort_weight * float(np.linalg.norm(ts.tau))
            t = Transition(
                "object_motion", comb, state.bodies(), new.bodies(), om.q_path, om.pose_path, grasp.tau, ts.tau,
                {"direction": ts.direction.tolist(), "dq": ts.dq.tolist(), "phi": ts.phi,
                 "vertices": None if ts.generators is None else int(ts.generators.vertices.shape[0]),
                 "rays": None if ts.generators is None else int(ts.generators.all_directions().shape[0]),
                 "dim_force_polyhedron": ts.dim_P, "work": ts.work, "nlp_status": ts.nlp_status},
                {"equation": "30-32", "dafc_dim": summ.dim_dafc, "a_bar": summ.a_bar,
                 "separation_rates": rates.tolist(), "separations": om.separations.tolist(),
                 "sliding_contacts": list(sset),
                 "object_path_length": om.length, "manifold_residual": om.max_residual,
                 "ompl_planner_states": om.planner_states, "states_checked": om.states_checked,
                 "max_joint_step": om.max_joint_step, "ompl_seconds": om.ompl_seconds},
                cost,
            )
            out.append((t, new))
        return out

    def _slid_contacts(self, state: GraspState, sset: tuple[int, ...], om: Any) -> tuple[GraspContact, ...]:
        """The contacts after an object motion: sliding ones (``sset``) where their bodies touch the
        object at the end (new points on the body and the object), the others unchanged."""
        if not sset:
            return state.contacts
        man = ContactManifold(self.hand, state, [], sset, self.scene)
        x = np.concatenate([om.q_path[-1], om.displacement_path[-1]])
        out = list(state.contacts)
        for k, i in enumerate(sset):
            y, p_obj, n_obj = man.sliding_contact(k, x)
            ref = man.sliding[k]
            c = state.contacts[i]
            out[i] = GraspContact(c.body, self.hand.to_local(ref, y, om.q_path[-1]), p_obj, n_obj, c.mu)
        return tuple(out)

    def _direction_candidates(self, state: GraspState, p: Any, dset: tuple[int, ...],
                              example: Array | None) -> list[Array]:
        D = p.system.D
        Lr = p.ms.Lambda_r_t
        cands: list[Array] = []
        if self.goal.type == "pose" and self.goal.pose is not None:
            cands.append(np.asarray(self.goal.pose, float) - state.pose_vector())
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


def tip_body_name(hand: HandKinematics, finger: int) -> str:
    """The body name of a finger's last link (``"name/k"`` for scene chains, the URDF link name
    for URDF fingers)."""
    chain = hand.fingers[finger]
    return chain.body_names()[chain.n_joints - 1]


def _pose_state(state: GraspState, pose: Array) -> GraspState:
    from analysis.rotations import rotvec_to_matrix, rotz

    d = state.dim
    R = rotz(float(pose[2])) if d == 2 else rotvec_to_matrix(pose[3:])
    return GraspState(state.contacts, state.q, np.asarray(pose[:d], float), R, d)


def _separating_motion(rays: Array, lines: Array, J_d: Array, feasible: Array) -> tuple[Array | None, float]:
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


def goal_reached(graph: ContactStateGraph, state: GraspState, goal: Goal) -> bool:
    """Is the goal satisfied in ``state``? (active: a~ = D and every sampled direction in DAFC of
    the all-F combination; passive: DPFC (28) of the all-F combination contains every wrench;
    fingertips: every finger touches with its tip only and (18) holds;
    combination: that combination is feasible; pose: within tolerance)."""
    if goal.type == "pose":
        assert goal.pose is not None
        diff = np.asarray(goal.pose, float) - state.pose_vector()
        if state.dim == 2:
            diff[2] = (diff[2] + np.pi) % (2 * np.pi) - np.pi
        return float(np.linalg.norm(diff)) <= goal.tolerance
    if goal.type == "fingertips":
        fingers = {graph._finger_of(c.body) for c in state.contacts} - {None}
        if len(fingers) < len(graph.hand.fingers):
            return False
        if not all(graph.is_fingertip(c) for c in state.contacts if graph._finger_of(c.body) is not None):
            return False
        return graph.analysis(state).stationary(all_f(state)) is not None
    sa = graph.analysis(state)
    if goal.type == "combination":
        assert goal.combination is not None
        comb = goal.combination.upper()
        if len(comb) != state.L:
            return False
        try:
            return sa.summary(comb).feasible
        except CTPError:
            return False
    comb = all_f(state)
    if goal.type == "active":
        return closure_is_active(sa, comb, graph.options.dafc_samples)
    grasp = sa.stationary(comb)
    if grasp is None:
        return False
    p = sa.parts(comb)
    from analysis.dpfc import dpfc

    region = dpfc(p.st, p.fs, grasp)
    ws = goal.wrenches or [list(sa.system.w_ex), list(-sa.system.w_ex)]
    return all(region.contains(np.asarray(w, float), p.st, p.fs, grasp) for w in ws)


def closure_is_active(sa: StateAnalysis, comb: str, samples: int = 64) -> bool:
    """Active closure of a combination: motion space of dimension D (``a~ = D``), a stationary
    grasp, and every direction of a seeded sample of the unit sphere (plus the axes) in DAFC."""
    p = sa.parts(comb)
    if p.ms.a_bar != p.system.D or sa.stationary(comb) is None:
        return False
    oracle = p.oracle()
    ds = dafc_set(oracle, samples=samples, refine=0)
    if ds.directions.shape[0] == 0 or not bool(np.all(ds.member)):
        return False
    axes = np.vstack([np.eye(p.system.D), -np.eye(p.system.D)])
    return all(oracle.test(a).member for a in axes)
