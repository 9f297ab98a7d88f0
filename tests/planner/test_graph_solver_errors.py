"""An undecided solver inside one edge's checks (planner/graph.py): the edge is refused with the
solver's message among the rejected transitions and the search goes on; the plan is not stopped.
Before, one 'Unknown' LP in a release check stopped ``ctp plan`` with "error: HiGHS: ..."."""

from __future__ import annotations

from typing import Any

import pytest
from closure_helpers import EXAMPLES

from analysis.exceptions import SolverError
from analysis.loader import load_scene
from planner import Goal, plan
from planner.graph import ContactStateGraph
from planner.search import Successor
from planner.verify import verify_plan

UNDECIDED = SolverError("HiGHS", "LP ended with status 'Unknown'")


def _raise(*_: Any, **__: Any) -> Any:
    raise UNDECIDED


def test_an_undecided_release_check_is_a_rejection_not_an_error(monkeypatch: pytest.MonkeyPatch) -> None:
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")
    reference = plan(scene, Goal(type="active"))
    assert reference.found and "release" in [s.transition.kind for s in reference.steps]
    monkeypatch.setattr(ContactStateGraph, "release_edges", _raise)
    p = plan(scene, Goal(type="active"))
    key = "release: a solver could not decide it (HiGHS: LP ended with status 'Unknown')"
    assert p.rejections.get(key, 0) >= 1
    # without releases the planar grasp reaches no active closure: a "no plan" that names the solver
    assert not p.found and p.steps == ()
    assert "expanded without reaching the goal" in p.reason and key in p.reason


def test_an_undecided_lazy_check_refuses_only_that_edge(monkeypatch: pytest.MonkeyPatch) -> None:
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")
    original = ContactStateGraph.object_motion_edges
    broken: list[int] = []

    def first_motion_undecided(self: ContactStateGraph, state: Any) -> list[Successor]:
        out = original(self, state)
        if out and not broken:  # the first lazy motion edge of the search ends undecided
            broken.append(1)
            out[0] = Successor(out[0].node, out[0].cost, out[0].data, validate=_raise)
        return out

    monkeypatch.setattr(ContactStateGraph, "object_motion_edges", first_motion_undecided)
    p = plan(scene, Goal(type="active"))
    assert broken
    key = "object motion: a solver could not decide it (HiGHS: LP ended with status 'Unknown')"
    assert p.rejections.get(key) == 1
    assert p.found, p.reason
    assert verify_plan(scene, p) == []
