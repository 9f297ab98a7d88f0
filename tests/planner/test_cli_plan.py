"""``ctp plan``."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from analysis.cli import app

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_ctp_plan_writes_json(tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "plan.json"
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "active",
                                 "--out", str(out)])
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    assert data["found"] and data["steps"][-1]["kind"] == "object_motion"


def test_ctp_plan_bad_goal_exits_2() -> None:
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "combination"])
    assert r.exit_code == 2
