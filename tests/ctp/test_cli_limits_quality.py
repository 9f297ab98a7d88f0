"""``ctp analyze`` with joint torque limits and with ``--quality`` (typer CliRunner)."""

from __future__ import annotations

import json
from pathlib import Path

from closure_helpers import PLANAR
from typer.testing import CliRunner

from analysis.combination import analyze_combination
from analysis.contacts import build_system
from analysis.loader import load_scene
from ctp.cli import app

runner = CliRunner()


def _limited(tmp_path: Path, limits: list[float]) -> Path:
    data = json.loads(PLANAR.read_text())
    data["joint_torque_limits"] = limits
    path = tmp_path / "limited.json"
    path.write_text(json.dumps(data))
    return path


def test_a_report_names_the_joint_a_motion_needs_more_of(tmp_path: Path) -> None:
    result = runner.invoke(app, ["analyze", str(_limited(tmp_path, [0.3, 10.0, 0.3, 10.0])), "--combination", "FSFSS"],
                           terminal_width=200)
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "empty within the joint torque limits" in text and "left/j0" in text and "(limit 0.3 N m" in text


def test_quality_columns_and_json_fields(tmp_path: Path) -> None:
    """--quality adds the two radii to every feasible row, equal to the full report's."""
    out = tmp_path / "q.json"
    result = runner.invoke(app, ["analyze", str(PLANAR), "--quality", "--json", str(out)], terminal_width=200)
    assert result.exit_code == 0, result.output
    assert "ball" in result.output and "eps" in result.output  # headers "ball [N]", "eps [N]" (wrapped)
    rows = json.loads(out.read_text())["combinations"]
    graded = [r for r in rows if "quality" in r]
    assert graded and all(r["feasible"] for r in graded)
    assert len(graded) == sum(r["feasible"] for r in rows)
    system = build_system(load_scene(PLANAR))
    for row in graded[:3]:
        rep = analyze_combination(system, row["combination"]).to_json()
        assert row["quality"]["epsilon"] == rep["quality"]["epsilon"]
        assert row["quality"]["wrench_ball"] == rep["quality"]["wrench_ball"]


def test_a_report_says_when_only_the_limits_stop_the_stationary_grasp(tmp_path: Path) -> None:
    result = runner.invoke(app, ["analyze", str(_limited(tmp_path, [0.5, 10.0, 0.5, 10.0])), "--combination",
                                 "FSFDD"], terminal_width=200)
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "not feasible (no stationary grasp (18))" in text
    assert "note: no stationary grasp (18) within the joint torque limits" in text and "left/j0" in text
