"""``ctp plan``."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from analysis.loader import load_scene, scene_from_dict
from ctp.cli import app

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_ctp_plan_writes_json(tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "plan.json"
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "active",
                                 "--out", str(out)])
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    assert data["found"] and data["steps"][-1]["kind"] == "object_motion"
    # the scene it was planned from, so that 'ctp simulate plan.json' can replay it
    assert scene_from_dict(data["scene"]) == load_scene(EXAMPLES / "planar_disk_envelope.json")


def test_ctp_plan_replay_writes_the_continuous_replay(tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "plan.json"
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "active",
                                 "--out", str(out), "--replay"])
    assert r.exit_code == 0, r.output
    rep = json.loads(out.read_text())["replay"]
    assert rep["ok"] and not rep["dropped"] and rep["relative_error"] <= 0.05
    assert len(rep["simulated"]) == len(rep["planned"]) == 3 and len(rep["steps"]) == 5


def test_ctp_plan_bad_goal_exits_2() -> None:
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "combination"])
    assert r.exit_code == 2
