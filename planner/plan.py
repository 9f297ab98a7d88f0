"""Plans: the sequence of contact-state transitions from a scene's grasp to a goal.

:func:`plan` is the entry point used by the command line (``ctp plan``) and the service. It
builds the contact-state graph lazily (:mod:`planner.graph`), searches it
(:func:`planner.search.best_first_search`, Dijkstra order with lazy motion-planning edges) and
returns a :class:`Plan`: ordered steps, each with its kind (``release``/``contact``, eq. 33;
``object_motion``, eq. 30-32), the combination in force, the joint-space and object paths, the
torques (``tau_st`` of (18), the chosen member of T (32) and a summary of T) and the analysis
figures that justify it. A plan that cannot be found is a :class:`Plan` with ``found = False`` and
a ``reason`` naming the constraint that blocked the search (first, a motion the planner does not
support for this object); a start that already meets the goal is a found plan
with no steps whose ``reason`` says so (:data:`START_MEETS_GOAL`); :attr:`Plan.outcome` (in the
JSON too) tells the three apart. Malformed input raises :class:`analysis.exceptions.SceneError`.
"""

from __future__ import annotations

import math
import platform
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from pydantic import ValidationError

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import object_size, shape_signed_distance
from analysis.kinematics import HandKinematics
from analysis.memo import scope as analysis_memo
from analysis.pose import Pose
from analysis.scene import Scene
from planner.goals import Goal, check_combination, goal_heuristic, goal_reached
from planner.graph import ContactStateGraph
from planner.motion_edges import UNSUPPORTED
from planner.object_motion import corner_normal
from planner.options import PlannerOptions
from planner.search import best_first_search
from planner.state import GraspContact, GraspState, all_f, state_from_scene
from planner.transition import Transition, figures_from_json

Progress = Callable[[float, str], None]

#: The kinds of plan steps: regrasps (eq. 33; ``slide``: with an S-point) and object motions (eq. 30-32).
KINDS = ("release", "contact", "object_motion", "slide")

#: The reason of a plan whose start already meets the goal (found, no steps).
START_MEETS_GOAL = "the start already meets the goal: nothing to do (0 steps)"


def _list(a: Array | None) -> Any:
    return None if a is None else np.round(np.asarray(a, dtype=float), 10).tolist()


def _array(value: Any, loc: tuple[str | int, ...], shape: tuple[int | None, ...]) -> Array:
    """``value`` as a finite float array of ``shape`` (``None``: any length >= 1), else SceneError."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(loc, "must be an array of numbers") from None
    want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
    if a.ndim != len(shape) or any(s is not None and a.shape[i] != s for i, s in enumerate(shape)):
        raise SceneError(loc, f"must have shape {want}, got {a.shape}")
    if a.size == 0 or not np.all(np.isfinite(a)):
        raise SceneError(loc, f"must be a non-empty {want} array of finite numbers")
    return a


def _inward_normal(scene: Scene, p_local: Array) -> Array:
    """The object's unit inward surface normal ``(d,)`` at ``p_local`` ``(d,)`` (object frame):
    central differences of its signed distance, step ``1e-6`` object sizes; NaN where the shape
    has no signed distance (meshes) or no gradient."""
    d = scene.dim
    step = 1e-6 * object_size(scene)
    grad = np.zeros(d)
    for k in range(d):
        e = np.zeros(d)
        e[k] = step
        hi = shape_signed_distance(scene.object.shape, p_local + e, d)
        lo = shape_signed_distance(scene.object.shape, p_local - e, d)
        if hi is None or lo is None:
            return np.full(d, np.nan)
        grad[k] = (hi - lo) / (2 * step)
    if not np.linalg.norm(grad) > 0:
        return np.full(d, np.nan)
    return np.asarray(-grad / np.linalg.norm(grad))


def _state_from_file(scene: Scene, hand: HandKinematics, bodies: tuple[str, ...], points: Array | None,
                     q: Array, pose_vector: Array) -> GraspState:
    """The grasp state after a step as the plan file gives it: hand at ``q`` ``(M,)``, object at
    ``pose_vector`` ``(D,)``, ``bodies`` touching at the world ``points`` ``(L, d)`` (NaN when the
    file has none). The file stores neither normals nor friction: each contact gets the object's
    inward surface normal there (on a vertex or an edge of the object, the touching body's normal:
    :func:`~planner.object_motion.corner_normal`) and the ``mu`` of the scene's contact on the same
    body, else the smallest scene ``mu``."""
    d = scene.dim
    pose = Pose.from_vector(pose_vector, d)
    mus = {c.body: float(c.mu) for c in scene.contacts}
    mu_default = min(mus.values()) if mus else 0.0
    pts = np.full((len(bodies), d), np.nan) if points is None else points  # (L, d)
    contacts = []
    for body, p in zip(bodies, pts, strict=True):
        ref = hand.resolve_body(body)
        assert ref is not None  # checked by Plan.from_json
        local = pose.to_local(p)  # (d,) object frame
        n = corner_normal(scene, hand, ref, q, pose, local) if np.all(np.isfinite(local)) else None
        contacts.append(GraspContact(body, hand.to_local(ref, p, q), local,
                                     _inward_normal(scene, local) if n is None else n, mus.get(body, mu_default)))
    return GraspState(tuple(contacts), q, pose.position, pose.rotation, d)


@dataclass(frozen=True)
class PlanStep:
    """One transition of a plan."""

    index: int
    transition: Transition
    before: GraspState
    after: GraspState

    def to_json(self) -> dict[str, Any]:
        t = self.transition
        return {
            "index": self.index,
            "kind": t.kind,
            "combination": t.combination,
            "contacts_before": list(t.contacts_before),
            "contacts_after": list(t.contacts_after),
            "joint_path": _list(t.q_path),
            "object_path": _list(t.object_path),
            "torques": {
                "stationary": _list(t.tau_stationary),
                "chosen": _list(t.tau),
                "set": t.torque_set,
            },
            "figures": t.figures.to_json(),
            "cost": t.cost,
            "contact_points_after": [_list(self.after.world_point(i)) for i in range(self.after.L)],
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any], index: int, before: GraspState, scene: Scene,
                  hand: HandKinematics) -> PlanStep:
        """Step ``index`` of a plan file (the inverse of :meth:`to_json`), starting from the state
        ``before``; the state after it is rebuilt from the file (see :meth:`Plan.from_json`). Raises
        :class:`SceneError` at ``("steps", index, field)``."""
        M, D = hand.M, scene.D
        loc: tuple[str | int, ...] = ("steps", index)
        if not isinstance(data, Mapping):
            raise SceneError(loc, "must be an object")
        kind = data.get("kind")
        if kind not in KINDS:
            raise SceneError((*loc, "kind"), f"must be one of {', '.join(KINDS)} (got {kind!r})")
        bodies: dict[str, tuple[str, ...]] = {}
        for key in ("contacts_before", "contacts_after"):
            names = data.get(key)
            if not isinstance(names, list) or not all(isinstance(b, str) for b in names):
                raise SceneError((*loc, key), "must be a list of body names")
            for j, b in enumerate(names):
                if hand.resolve_body(b) is None:
                    raise SceneError((*loc, key, j), f"unknown body '{b}' (known: {', '.join(hand.body_names())})")
            bodies[key] = tuple(names)
        comb = data.get("combination")
        if not isinstance(comb, str) or len(comb) != len(bodies["contacts_before"]) + (kind == "contact"):
            raise SceneError((*loc, "combination"), "must be a string with one letter per contact")
        q_path = _array(data.get("joint_path"), (*loc, "joint_path"), (None, M))  # (n, M)
        obj = _array(data.get("object_path"), (*loc, "object_path"), (None, D))  # (k, D)
        torques = data.get("torques")
        if not isinstance(torques, Mapping):
            raise SceneError((*loc, "torques"), "must be an object with 'stationary' and 'chosen'")
        tau_st = None if torques.get("stationary") is None else _array(
            torques["stationary"], (*loc, "torques", "stationary"), (M,))
        tau = None if torques.get("chosen") is None else _array(torques["chosen"], (*loc, "torques", "chosen"), (M,))
        if kind == "object_motion" and tau is None:
            raise SceneError((*loc, "torques", "chosen"), "an object motion needs its chosen torque (32)")
        if kind in ("release", "slide") and tau_st is None:
            raise SceneError((*loc, "torques", "stationary"), f"a {kind} needs the stationary torque (18)")
        pts = data.get("contact_points_after")
        points = None if pts is None else _array(pts, (*loc, "contact_points_after"),
                                                 (len(bodies["contacts_after"]), scene.dim))  # (L_after, d)
        try:
            figures = figures_from_json(kind, data["figures"])
        except (KeyError, TypeError, ValueError):
            raise SceneError((*loc, "figures"), f"must be the figures of a {kind} step (as Plan.to_json writes them)"
                             ) from None
        cost = data.get("cost")
        transition = Transition(
            kind=kind, combination=comb, contacts_before=bodies["contacts_before"],
            contacts_after=bodies["contacts_after"], q_path=q_path, object_path=obj, tau_stationary=tau_st,
            tau=tau, torque_set=torques.get("set"), figures=figures,
            cost=float(cost) if isinstance(cost, int | float) else math.nan,
        )
        after = _state_from_file(scene, hand, bodies["contacts_after"], points, q_path[-1], obj[-1])
        return cls(index, transition, before, after)


@dataclass(frozen=True)
class PlanStats:
    """Where the planning time went."""

    nodes_expanded: int
    nodes_generated: int
    lazy_edges_checked: int
    seconds_total: float
    seconds_analysis: float
    seconds_ompl: float
    seconds_ik: float
    seconds_motion: float
    seconds_search: float  # the rest: graph bookkeeping and search
    machine: str

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)

    @classmethod
    def from_json(cls, data: Any) -> PlanStats:
        """The inverse of :meth:`to_json`; raises :class:`SceneError` at ``("stats",)``."""
        names = [f.name for f in fields(cls)]
        if not isinstance(data, Mapping) or set(data) != set(names):
            raise SceneError(("stats",), f"must be an object with the fields {', '.join(names)}")
        return cls(**{k: data[k] for k in names})


@dataclass(frozen=True)
class Plan:
    """The answer of :func:`plan`."""

    found: bool
    reason: str
    goal: Goal
    steps: tuple[PlanStep, ...]
    start_pose: Array  # (D,) object pose vector
    final_pose: Array  # (D,)
    final_contacts: tuple[str, ...]
    final_combination: str
    cost: float
    stats: PlanStats
    rejections: dict[str, int] = field(default_factory=dict)
    #: ``tau_st`` (18) ``(M,)`` of the final grasp: the torque that holds the object once the plan is done
    final_tau: Array | None = None

    @property
    def outcome(self) -> str:
        """``"reached"`` (found, with steps), ``"start_meets_goal"`` (found, no steps: the scene's
        grasp already meets the goal) or ``"no_plan"`` (not found: ``reason`` says why)."""
        if not self.found:
            return "no_plan"
        return "reached" if self.steps else "start_meets_goal"

    @property
    def displacement(self) -> Array:
        """Planned object displacement ``s`` ``(D,)`` with ``start.displaced(s) == final`` (the
        displacement goal's meaning): ``dp`` and, in 3-D, the rotation vector of ``R R_0^T``, not the
        difference of the pose vectors (which, for an object that starts turned, is not the turn)."""
        dim = 2 if self.start_pose.size == 3 else 3
        return Pose.from_vector(self.final_pose, dim).displacement_from(Pose.from_vector(self.start_pose, dim))

    def to_json(self) -> dict[str, Any]:
        return {
            "found": self.found,
            "outcome": self.outcome,
            "reason": self.reason,
            "goal": self.goal.model_dump(exclude_none=True),
            "steps": [s.to_json() for s in self.steps],
            "start_pose": _list(self.start_pose),
            "final_pose": _list(self.final_pose),
            "displacement": _list(self.displacement),
            "final_contacts": list(self.final_contacts),
            "final_combination": self.final_combination,
            "final_holding_torque": _list(self.final_tau),
            "cost": self.cost if np.isfinite(self.cost) else None,
            "stats": self.stats.to_json(),
            "rejections": self.rejections,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any], scene: Scene, hand: HandKinematics | None = None) -> Plan:
        """The plan of its JSON form (:meth:`to_json`, a ``ctp plan --out`` file), for ``scene``, the
        scene it was planned from: ``Plan.from_json(p.to_json(), scene).to_json() == p.to_json()``.

        Checks the file against the scene (body names, array shapes ``(n, M)``, ``(k, D)``,
        ``(M,)``, step kinds, one combination letter per contact, the torques each kind needs)
        and raises :class:`SceneError` naming the first bad field. The grasp states are rebuilt:
        the one before the first step is the scene's, the one after each step has the hand at
        ``joint_path[-1]``, the object at ``object_path[-1]`` and the bodies ``contacts_after``
        at ``contact_points_after``, with the object's inward surface normal at each point and the
        scene's ``mu`` of that body (else the smallest; the file stores neither). A plan that was
        not found reads back with ``found = False`` and may have no steps, and so does a found plan
        whose ``outcome`` is ``"start_meets_goal"``.
        """
        hand = hand or HandKinematics.from_scene(scene)
        D = scene.D
        if not isinstance(data, Mapping) or "steps" not in data:
            raise SceneError(("steps",), "missing: this is not a plan (Plan.to_json / ctp plan --out)")
        found = data.get("found") is not False
        raw = data["steps"]
        at_goal = data.get("outcome") == "start_meets_goal"  # found with no steps
        if not isinstance(raw, list) or (found and not raw and not at_goal):
            raise SceneError(("steps",), "must be a non-empty list of steps")
        poses = {}
        for key in ("start_pose", "final_pose"):
            if key not in data:
                raise SceneError((key,), "missing")
            poses[key] = _array(data[key], (key,), (D,))  # (D,)
        steps: list[PlanStep] = []
        before = state_from_scene(scene, hand)
        for i, st in enumerate(raw):
            step = PlanStep.from_json(st, i, before, scene, hand)
            steps.append(step)
            before = step.after
        given = data.get("final_holding_torque")
        final_tau = None if given is None else _array(given, ("final_holding_torque",), (hand.M,))
        if "goal" not in data:
            raise SceneError(("goal",), "missing")
        try:
            goal = Goal.model_validate(data["goal"])
        except ValidationError as e:
            raise SceneError(("goal",), str(e.errors()[0]["msg"])) from None
        stats = PlanStats.from_json(data.get("stats"))
        last = steps[-1].transition.contacts_after if steps else before.bodies()
        cost = data.get("cost")
        return cls(
            found=found,
            reason=str(data.get("reason", "")),
            goal=goal,
            steps=tuple(steps),
            start_pose=poses["start_pose"],
            final_pose=poses["final_pose"],
            final_contacts=tuple(data.get("final_contacts", last)),
            final_combination=str(data.get("final_combination", "F" * len(last))),
            cost=float(cost) if isinstance(cost, int | float) else math.inf,
            stats=stats,
            rejections=dict(data.get("rejections") or {}),
            final_tau=final_tau,
        )


def check_goal(scene: Scene, goal: Goal) -> None:
    """Raise :class:`SceneError` when the goal does not fit the scene."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an analysis.scene.Scene, got {type(scene).__name__}")
    if not isinstance(goal, Goal):
        raise TypeError(f"goal must be a planner.goals.Goal, got {type(goal).__name__}")
    if goal.pose is not None and len(goal.pose) != scene.D:
        raise SceneError(("goal", "pose"), f"must have {scene.D} values for a {scene.dim}-D scene")
    if goal.displacement is not None and len(goal.displacement) != scene.D:
        raise SceneError(("goal", "displacement"), f"must have {scene.D} values for a {scene.dim}-D scene")
    for i, w in enumerate(goal.wrenches or []):
        if len(w) != scene.D:
            raise SceneError(("goal", "wrenches", i), f"must have {scene.D} components")
    check_combination(goal, scene)
    if goal.type == "contact":
        assert goal.body is not None and goal.point is not None  # Goal's validator
        ref = HandKinematics.from_scene(scene).resolve_body(goal.body)
        if ref is None or ref.finger is None:
            raise SceneError(("goal", "body"), f"'{goal.body}' is not a finger link of the scene")
        if len(goal.point) != scene.dim:
            raise SceneError(("goal", "point"), f"must have {scene.dim} values for a {scene.dim}-D scene")


def plan(
    scene: Scene,
    goal: Goal,
    *,
    progress: Progress | None = None,
    time_limit: float | None = None,
    max_expansions: int = 200,
    options: PlannerOptions | None = None,
) -> Plan:
    """Plan contact-state transitions from the scene's grasp to ``goal``; a ``displacement`` goal
    is planned (and recorded in the plan) as the pose goal it resolves to from the scene's pose.

    ``progress(fraction, message)`` is called after every node expansion (fraction of the
    expansion budget, or of ``time_limit`` when that is larger) and at the end with 1.0.
    ``time_limit`` (seconds) bounds the search; reaching it gives ``found = False``. The states
    of one search pose many of the same LPs and statics again; each is computed once
    (:mod:`analysis.memo`).
    """
    with analysis_memo():
        return _plan(scene, goal, progress, time_limit, max_expansions, options)


def _plan(scene: Scene, goal: Goal, progress: Progress | None, time_limit: float | None, max_expansions: int,
          options: PlannerOptions | None) -> Plan:
    check_goal(scene, goal)
    if time_limit is not None and not time_limit > 0:
        raise SceneError(("time_limit",), "must be positive")
    t0 = time.perf_counter()
    hand = HandKinematics.from_scene(scene)
    start = state_from_scene(scene, hand)
    goal = goal.resolved(start.pose)  # a displacement goal: the pose goal it asks for
    graph = ContactStateGraph(scene, hand, goal, options or PlannerOptions())
    key = graph.add(start)

    def report(n: int, node: Any) -> None:
        if progress is None:
            return
        frac = n / max_expansions
        if time_limit is not None:
            frac = max(frac, (time.perf_counter() - t0) / time_limit)
        progress(min(0.99, frac), f"expanded {n}: contacts {graph.states[node].describe()}")

    def is_goal(node: Any) -> bool:
        return goal_reached(goal, graph.states[node], hand, graph.analysis, graph.options.dafc_samples,
                            size=graph.size)

    def heuristic(node: Any) -> float:
        return goal_heuristic(goal, graph.states[node], hand, graph.options.heuristic_weight)

    sa0 = graph.analysis(start)
    if sa0.stationary(all_f(start)) is None:
        result = None
        reason = "the start grasp has no stationary grasp (18): the contacts cannot hold the object"
    else:
        result = best_first_search(key, graph.successors, is_goal, rejections=graph.rejections,
                                   max_expansions=max_expansions, time_limit=time_limit, progress=report,
                                   heuristic=heuristic)
        if not result.found:
            limits = sorted(k for k in result.rejections if k.startswith(UNSUPPORTED))
            others = {k: v for k, v in result.rejections.items() if k not in limits}
            reason = replace(result, rejections=others).blocking_reason()
            if limits:  # a limit of the planner, not of the grasp: said first
                reason = "; ".join(limits) + "; " + reason
        elif len(result.path) == 1:
            reason = START_MEETS_GOAL
        else:
            reason = "goal reached"
    total = time.perf_counter() - t0
    tm = graph.timings
    busy = tm["analysis"] + tm["ompl"] + tm["ik"] + tm["motion"]
    stats = PlanStats(
        nodes_expanded=0 if result is None else result.expanded,
        nodes_generated=len(graph.states),
        lazy_edges_checked=0 if result is None else result.lazy_checked,
        seconds_total=total,
        seconds_analysis=tm["analysis"],
        seconds_ompl=tm["ompl"],
        seconds_ik=tm["ik"],
        seconds_motion=tm["motion"],
        seconds_search=max(0.0, total - busy),
        machine=f"{platform.machine()} {platform.processor() or ''} {platform.system()} "
        f"python {platform.python_version()}".strip(),
    )
    steps: list[PlanStep] = []
    final: GraspState = start
    final_tau: Array | None = None
    cost = float("inf")
    if result is not None and result.found:
        for i, (a, b) in enumerate(zip(result.path, result.path[1:], strict=False)):
            steps.append(PlanStep(i, result.graph.edges[a, b]["data"], graph.states[a], graph.states[b]))
        final = graph.states[result.path[-1]]
        cost = result.cost
        held = graph.analysis(final).stationary(all_f(final))
        final_tau = None if held is None else np.asarray(held.tau, dtype=float)
    if progress is not None:
        progress(1.0, reason)
    return Plan(
        found=bool(result is not None and result.found),
        reason=reason,
        goal=goal,
        steps=tuple(steps),
        start_pose=start.pose_vector(),
        final_pose=final.pose_vector(),
        final_contacts=final.bodies(),
        final_combination=all_f(final),
        cost=cost,
        stats=stats,
        rejections=dict(graph.rejections),
        final_tau=final_tau,
    )
