"""Plans: the sequence of contact-state transitions from a scene's grasp to a goal (issue 3).

:func:`plan` is the entry point used by the command line (``ctp plan``) and the service. It
builds the contact-state graph lazily (:mod:`planner.graph`), searches it
(:func:`planner.search.best_first_search`, Dijkstra order with lazy motion-planning edges) and
returns a :class:`Plan`: ordered steps, each with its kind (``release``/``contact``, eq. 33;
``object_motion``, eq. 30-32), the combination in force, the joint-space and object paths, the
torques (``tau_st`` of (18), the chosen member of T (32) and a summary of T) and the analysis
figures that justify it. A plan that cannot be found is a :class:`Plan` with ``found = False`` and
a ``reason`` naming the constraint that blocked the search; malformed input raises
:class:`analysis.exceptions.SceneError`.
"""

from __future__ import annotations

import platform
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from planner.goals import Goal
from planner.graph import ContactStateGraph, PlannerOptions, Transition
from planner.search import best_first_search
from planner.state import GraspState, all_f, state_from_scene

Progress = Callable[[float, str], None]


def _list(a: Array | None) -> Any:
    return None if a is None else np.round(np.asarray(a, dtype=float), 10).tolist()


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
            "figures": t.figures,
            "cost": t.cost,
            "contact_points_after": [_list(self.after.world_point(i)) for i in range(self.after.L)],
        }


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
    def displacement(self) -> Array:
        """Planned object displacement (final pose vector minus start)."""
        return self.final_pose - self.start_pose

    def to_json(self) -> dict[str, Any]:
        return {
            "found": self.found,
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


def check_goal(scene: Scene, goal: Goal) -> None:
    """Raise :class:`SceneError` when the goal does not fit the scene."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an analysis.scene.Scene, got {type(scene).__name__}")
    if not isinstance(goal, Goal):
        raise TypeError(f"goal must be a planner.goals.Goal, got {type(goal).__name__}")
    if goal.pose is not None and len(goal.pose) != scene.D:
        raise SceneError(("goal", "pose"), f"must have {scene.D} values for a {scene.dim}-D scene")
    for i, w in enumerate(goal.wrenches or []):
        if len(w) != scene.D:
            raise SceneError(("goal", "wrenches", i), f"must have {scene.D} components")
    if goal.combination is not None and any(ch not in "FNSDfnsd" for ch in goal.combination):
        raise SceneError(("goal", "combination"), "letters must be F, N, S or D")


def plan(
    scene: Scene,
    goal: Goal,
    *,
    progress: Progress | None = None,
    time_limit: float | None = None,
    max_expansions: int = 200,
    options: PlannerOptions | None = None,
) -> Plan:
    """Plan contact-state transitions from the scene's grasp to ``goal``.

    ``progress(fraction, message)`` is called after every node expansion (fraction of the
    expansion budget, or of ``time_limit`` when that is larger) and at the end with 1.0.
    ``time_limit`` (seconds) bounds the search; reaching it gives ``found = False``.
    """
    check_goal(scene, goal)
    if time_limit is not None and not time_limit > 0:
        raise SceneError(("time_limit",), "must be positive")
    t0 = time.perf_counter()
    hand = HandKinematics.from_scene(scene)
    graph = ContactStateGraph(scene, hand, goal, options or PlannerOptions())
    start = state_from_scene(scene, hand)
    key = graph.add(start)

    def report(n: int, node: Any) -> None:
        if progress is None:
            return
        frac = n / max_expansions
        if time_limit is not None:
            frac = max(frac, (time.perf_counter() - t0) / time_limit)
        progress(min(0.99, frac), f"expanded {n}: contacts {graph.states[node].describe()}")

    sa0 = graph.analysis(start)
    if sa0.stationary(all_f(start)) is None:
        result = None
        reason = "the start grasp has no stationary grasp (18): the contacts cannot hold the object"
    else:
        result = best_first_search(key, graph.successors, graph.is_goal, rejections=graph.rejections,
                                   max_expansions=max_expansions, time_limit=time_limit, progress=report,
                                   heuristic=graph.heuristic)
        reason = "goal reached" if result.found else result.blocking_reason()
    total = time.perf_counter() - t0
    tm = graph.timing
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
