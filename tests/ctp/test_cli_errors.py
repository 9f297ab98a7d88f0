"""Bad files and bad output paths: one line on stderr naming the problem and exit code 2, never
a traceback (issue 13's CLI misuse cases)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from closure_helpers import PLANAR
from typer.testing import CliRunner

from ctp.cli import app

runner = CliRunner()


def _one_error_line(result: Any) -> str:
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit), result.exception
    text = str(getattr(result, "stderr", "") or result.output)
    assert "Traceback" not in text, text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), lines
    return lines[0]


COMMANDS = [["analyze"], ["modes"], ["simulate", "--combination", "DDDFF"], ["plan"]]


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
@pytest.mark.parametrize(("name", "content", "reason"), [
    ("binary.json", bytes(range(256)) * 4, "not UTF-8 text"),
    ("latin1.json", '{"name": "caf\xe9"}'.encode("latin-1"), "not UTF-8 text"),
    ("nul.yaml", b"dim: 2\x00\x00", "binary data"),
    ("image.yaml", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "not UTF-8 text"),
    ("deep.json", ("[" * 100_000 + "]" * 100_000).encode(), "nested more than 64 levels deep"),
    ("deep.yaml", ("[" * 5_000 + "]" * 5_000).encode(), "nested more than 64 levels deep"),
    ("tab.yaml", b"dim: 2\n\tname: x\n", "line 2, column 1: found a tab character"),
    ("bomb.yaml", ("a: &a [x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [" + ", ".join([f"*{p}"] * 6) + "]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=True))
    ).encode(), "aliases"),
    ("date.yaml", b"name: 2020-01-01\n", "name: a YAML date is not a JSON value"),
    ("twice.yaml", b"dim: 2\nname: a\nname: b\n", "line 3, column 1: duplicate key 'name'"),
])
def test_bad_scene_files_exit_2_with_one_line(tmp_path: Path, command: list[str], name: str, content: bytes,
                                              reason: str) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    line = _one_error_line(runner.invoke(app, [command[0], str(path), *command[1:]]))
    assert str(path) in line and reason in line, line


@pytest.mark.parametrize(("args", "option"), [
    (["analyze", str(PLANAR), "--json", "{missing}/out.json"], "--json"),
    (["analyze", str(PLANAR), "--combination", "FDFDD", "--plot", "{missing}/out.png"], "--plot"),
    (["analyze", str(PLANAR), "--combination", "FDFDD", "--json", "{missing}/out.json"], "--json"),
    (["modes", str(PLANAR), "--json", "{missing}/modes.json"], "--json"),
    (["simulate", str(PLANAR), "--combination", "DDDFF", "--json", "{missing}/sim.json"], "--json"),
    (["plan", str(PLANAR), "--out", "{missing}/plan.json"], "--out"),
    (["schema", "--out", "{missing}/schema.json"], "--out"),
])
def test_output_into_a_missing_folder_exits_2_before_any_work(tmp_path: Path, args: list[str], option: str) -> None:
    missing = tmp_path / "no" / "such" / "folder"
    line = _one_error_line(runner.invoke(app, [a.replace("{missing}", str(missing)) for a in args]))
    assert line.startswith(f"error: {option}:") and "does not exist" in line and str(missing) in line, line
    assert not missing.exists()


def test_output_onto_a_folder_exits_2(tmp_path: Path) -> None:
    line = _one_error_line(runner.invoke(app, ["schema", "--out", str(tmp_path)]))
    assert "it is a folder" in line


def test_schema_out_still_writes(tmp_path: Path) -> None:
    out = tmp_path / "schema.json"
    result = runner.invoke(app, ["schema", "--out", str(out)])
    assert result.exit_code == 0 and json.loads(out.read_text())["title"] == "Scene"


def test_a_plan_file_that_is_not_text_exits_2(tmp_path: Path) -> None:
    """``ctp simulate PLAN.json`` reads plan files through the same parser."""
    path = tmp_path / "plan.json"
    path.write_bytes(b"\xff" * 64)
    line = _one_error_line(runner.invoke(app, ["simulate", str(path)]))
    assert "not UTF-8 text" in line


@pytest.mark.parametrize("bad", ["-1", "nan", "inf", "-inf"])
def test_a_bad_effort_weight_exits_2_naming_the_flag(bad: str) -> None:
    """``ctp plan --effort-weight`` takes a finite weight >= 0, checked before the scene is read."""
    line = _one_error_line(runner.invoke(app, ["plan", str(PLANAR), "--effort-weight", bad]))
    assert line.startswith("error: --effort-weight:") and "finite number >= 0" in line, line
