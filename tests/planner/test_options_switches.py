"""Every optional kind of planner edge (the switches of ``PlannerOptions`` that ``ctp plan``'s flags
and ``POST /plans`` ``options`` turn on) runs on every kind of scene: where its edges do not apply
(a disk, a sphere: the box-face edges) it adds none, and the search goes on as without it."""

from __future__ import annotations

from pathlib import Path

import pytest

from analysis.loader import load_scene
from planner import Goal, plan
from planner.options import PlannerOptions

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SWITCHES = ("contact_slides", "link_replacement", "link_sliding", "separate_finger_contacts", "sliding_motions")


@pytest.mark.parametrize("switch", [*SWITCHES, "all"])
def test_each_switch_plans_the_planar_disk(switch: str) -> None:
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")
    on = dict.fromkeys(SWITCHES if switch == "all" else (switch,), True)
    result = plan(scene, Goal(type="active"), options=PlannerOptions(**on), max_expansions=40)
    base = plan(scene, Goal(type="active"), max_expansions=40)
    assert base.found
    if switch in ("contact_slides", "link_replacement"):  # box-face edges: none for a disk
        assert result.found and result.cost == base.cost
    else:
        assert result.found or result.reason, result


@pytest.mark.slow
@pytest.mark.parametrize("switch", ["contact_slides", "link_replacement"])
def test_box_face_switches_add_nothing_for_a_sphere(switch: str) -> None:
    scene = load_scene(EXAMPLES / "sphere_four_finger_palm.json")
    result = plan(scene, Goal(type="active"), options=PlannerOptions(**{switch: True}))
    base = plan(scene, Goal(type="active"))
    assert result.found and base.found and result.cost == base.cost
