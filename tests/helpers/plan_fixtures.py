"""Session fixtures shared by the planner, sim and ctp tests (loaded with ``-p plan_fixtures``): the
planar example scene and its plans, computed once per run."""

from __future__ import annotations

from pathlib import Path

import pytest

from analysis.loader import load_scene
from analysis.scene import Scene

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="session")
def planar_scene() -> Scene:
    return load_scene(EXAMPLES / "planar_disk_envelope.json")


@pytest.fixture(scope="session")
def planar_plan(planar_scene: Scene):  # type: ignore[no-untyped-def]
    from planner import Goal, plan

    return plan(planar_scene, Goal(type="active"))
