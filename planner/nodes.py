"""The nodes of the contact-state graph and what its edge generators share.

:class:`GraphNodes` holds the grasp states found so far (by node key; a state reached by a
checked edge is *validated* and never replaced), their cached closure analysis, the collision
model of the scene, the counts of every reason a transition was rejected and the time spent per
activity. The edge generators (:mod:`planner.release_edges`, :mod:`planner.contact_edges`,
:mod:`planner.motion_edges`) take it as their first argument; :class:`planner.graph.ContactStateGraph`
is a :class:`GraphNodes` with those edges.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from planner.collision import CollisionModel
from planner.goals import Goal
from planner.options import PlannerOptions
from planner.state import AnalysisCache, GraspState, StateAnalysis, all_f
from planner.timings import Timings
from planner.transfer import TransferPath

#: joints (rad) within which two configurations of one node are the same (a plan's steps chain)
Q_MATCH = 1e-6


@dataclass
class GraphNodes:
    """Grasp states by node key, their analyses, rejections and timings (one search)."""

    scene: Scene
    hand: HandKinematics
    goal: Goal
    options: PlannerOptions = field(default_factory=PlannerOptions)
    states: dict[Any, GraspState] = field(default_factory=dict)
    rejections: Counter[str] = field(default_factory=Counter)
    timings: Timings = field(default_factory=Timings)
    validated: set[Any] = field(default_factory=set)

    def __post_init__(self) -> None:
        self.size = object_size(self.scene)  # lengths of the options are in units of this size
        self.model = CollisionModel.of(self.scene, self.hand)
        self.cache = AnalysisCache(self.scene, self.hand)
        mus = [c.mu for c in self.scene.contacts if c.mu > 0]
        self.default_mu = float(min(mus)) if mus else 0.0  # friction of new contacts
        self.ik_cache: dict[tuple[Any, ...], list[Array]] = {}  # IK solutions of new contacts
        #: OMPL transfers (None: none found) by :func:`planner.transfer.transfer_key`
        self.transfers: dict[tuple[Any, ...], TransferPath | None] = {}

    def add(self, state: GraspState, validated: bool = True) -> Any:
        """Register a state; a validated one (reached by a checked edge) is never replaced."""
        k = state.key()
        if k not in self.validated:
            self.states[k] = state
            if validated:
                self.validated.add(k)
        return k

    def arrives(self, state: GraspState) -> bool:
        """Whether an edge that ends in ``state`` may enter its node: the node is new, not yet
        validated, or validated with the same hand configuration (within :data:`Q_MATCH`). The node
        key holds the contacts and the object pose, not the joints; a redundant finger touching at
        the same point, or a free finger retreated elsewhere, gives another configuration of the
        same node, and the next step starts from the configuration registered first: an edge that
        ends elsewhere would make the plan's joint path jump between two steps."""
        k = state.key()
        if k not in self.validated:
            return True
        if float(np.max(np.abs(self.states[k].q - state.q), initial=0.0)) <= Q_MATCH:
            return True
        self.reject("the same grasp is already reached with another hand configuration")
        return False

    def analysis(self, state: GraspState, parent: GraspState | None = None) -> StateAnalysis:
        """The (cached) closure analysis of a state (``parent``: the state it was derived from, see
        :class:`~planner.state.AnalysisCache`)."""
        with self.timings.measure("analysis"):
            return self.cache(state, parent)

    def reject(self, reason: str) -> None:
        """Count a transition refused for ``reason``."""
        self.rejections[reason] += 1

    def held(self, state: GraspState, parent: GraspState | None = None) -> StateAnalysis | None:
        """The analysis of a state whose contacts hold the object (18 for all-F), else None
        (``parent``: the state it was derived from, see :class:`~planner.state.AnalysisCache`)."""
        try:
            sa = self.analysis(state, parent)
        except SceneError:
            self.reject("new grasp is geometrically inconsistent")
            return None
        if sa.stationary(all_f(state)) is None:
            self.reject("no stationary grasp (18) of the new contacts")
            return None
        return sa
