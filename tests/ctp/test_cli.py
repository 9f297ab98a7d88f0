"""``ctp analyze`` and ``ctp schema`` (typer CliRunner on ctp.cli.app)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from closure_helpers import PLANAR, example_system
from cube_planes import cube_in_planes
from typer.testing import CliRunner

from analysis.combination import CombinationParts, summarize
from analysis.enumerate import enumerate_combinations
from ctp.cli import app

runner = CliRunner()


def test_analyze_writes_every_combination(tmp_path: Path) -> None:
    """The default (mode-pruned) table agrees with the unpruned enumeration."""
    out = tmp_path / "out.json"
    result = runner.invoke(app, ["analyze", str(PLANAR), "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    rows = data["combinations"]
    assert len(rows) == 243 and data["semantics"]
    for row in rows:
        assert isinstance(row["combination"], str) and len(row["combination"]) == 5
        assert isinstance(row["feasible"], bool)
    expected, _ = enumerate_combinations(example_system("planar_disk_envelope"), workers=1)
    assert [(r["combination"], r["feasible"]) for r in rows] == [(s.combination, s.feasible) for s in expected]
    assert "combinations feasible" in result.output


def test_analyze_one_combination_full_report(tmp_path: Path) -> None:
    out = tmp_path / "fdfdd.json"
    png = tmp_path / "fdfdd.png"
    result = runner.invoke(app, ["analyze", str(PLANAR), "--combination", "FDFDD", "--json", str(out),
                                 "--plot", str(png)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["combination"] == "FDFDD" and data["feasible"] is True
    assert set(data["semantics"]) >= {"dafc_unknowns", "dafc_scale", "s_point", "d_point"}
    ts = data["torque_set"]
    assert ts["vertices"] and len(ts["recommended"]) == 4
    assert ts["residuals"]["inequality"] <= 1e-8 and ts["residuals"]["work"] > 0
    for key in ("stationary", "dafc", "dpfc", "regrasp", "motion_space", "statics"):
        assert key in data
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_analyze_direction_and_nu(tmp_path: Path) -> None:
    """A DAFC direction given on the command line gets its torque set and, with --nu, the
    friction-uncertainty combination."""
    direction = summarize(CombinationParts.build(example_system("planar_disk_envelope"), "FSFSD")).example_direction
    assert direction is not None
    out = tmp_path / "r.json"
    result = runner.invoke(app, ["analyze", str(PLANAR), "--combination", "FSFSD", "--nu", "0.8",
                                 "--direction", ",".join(f"{v:.12f}" for v in direction), "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["direction_test"]["member"] is True
    assert data["torque_set"]["residuals"]["work"] > 0
    assert data["friction_uncertainty"]["nu"] == 0.8 and data["friction_uncertainty"]["feasible"] is True


def _stderr(result: object) -> str:
    return str(getattr(result, "stderr", "") or getattr(result, "output", ""))


@pytest.mark.parametrize(("combination", "field"), [("FDFD", "combination"), ("FDFDDD", "combination"),
                                                    ("FDFDX", "combination.4"), ("FNFDD", "combination.1")])
def test_bad_combination_exits_2_naming_the_field(combination: str, field: str) -> None:
    result = runner.invoke(app, ["analyze", str(PLANAR), "--combination", combination])
    assert result.exit_code == 2
    lines = [ln for ln in _stderr(result).splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and f"{field}:" in lines[0], lines


@pytest.mark.parametrize(("edit", "field"), [
    (lambda d: d["contacts"][0].update(normal=[1.0, 1.0]), "contacts.0.normal"),
    (lambda d: d["contacts"][2].update(mu=-0.5), "contacts.2.mu"),
    (lambda d: d.update(external_wrench=[0.0, -1.0]), "external_wrench"),
    (lambda d: d["contacts"][1].update(body="thumb/0"), "contacts.1.body"),
])
def test_malformed_scene_exits_2_with_one_line(tmp_path: Path, edit: object, field: str) -> None:
    data = json.loads(PLANAR.read_text())
    edit(data)  # type: ignore[operator]
    # a long path must not wrap the message over several lines
    path = tmp_path / ("a_rather_long_directory_name_" * 3) / "bad.json"
    path.parent.mkdir()
    path.write_text(json.dumps(data))
    result = runner.invoke(app, ["analyze", str(path)])
    assert result.exit_code == 2
    lines = [ln for ln in _stderr(result).splitlines() if ln.strip()]
    assert len(lines) == 1 and f"{field}:" in lines[0], lines


def test_unparsable_scene_and_bad_options_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert runner.invoke(app, ["analyze", str(bad)]).exit_code == 2
    assert runner.invoke(app, ["analyze", str(PLANAR), "--combination", "FDFDD", "--nu", "2"]).exit_code == 2
    assert runner.invoke(app, ["analyze", str(PLANAR), "--combination", "FDFDD", "--direction", "1,0"]).exit_code == 2
    assert runner.invoke(app, ["analyze", str(PLANAR), "--direction", "1,0,0"]).exit_code == 2


def test_modes_takes_twenty_contacts_and_full_enumeration_refuses_them(tmp_path: Path) -> None:
    """The cube in a corner of five planes (20 vertex-face contacts): 2 contacting/separating
    modes (Huang, Cheng & Mason 2020); one combination is analysed; the table of all 3^20 is
    refused naming ``contacts``."""
    path = tmp_path / "cube5.json"
    path.write_text(json.dumps(cube_in_planes(5)))
    result = runner.invoke(app, ["modes", str(path), "--json", str(tmp_path / "modes.json")])
    assert result.exit_code == 0, result.output
    assert "2 contacting/separating modes" in result.stdout
    assert json.loads((tmp_path / "modes.json").read_text())["contacting_separating"] == 2
    result = runner.invoke(app, ["analyze", str(path), "--combination", "F" * 4 + "D" * 16])
    assert result.exit_code == 0, result.output
    assert "not feasible" in result.stdout and "motion space a = 0, object part a~ = 0" in result.stdout
    result = runner.invoke(app, ["analyze", str(path)])
    assert result.exit_code == 2
    assert "contacts: has 20 contacts" in _stderr(result) and "limited to 16" in _stderr(result)


def test_a_normal_off_unit_length_is_normalised_with_a_note(tmp_path: Path) -> None:
    data = json.loads(PLANAR.read_text())
    data["contacts"][4]["normal"] = [0.0, 1.0005]
    path = tmp_path / "off.json"
    path.write_text(json.dumps(data))
    result = runner.invoke(app, ["analyze", str(path), "--combination", "FDFDD"])
    assert result.exit_code == 0, result.output
    assert "note:" in _stderr(result) and "contacts.4.normal: norm 1.0005 normalised to unit length" in _stderr(result)


def test_schema_prints_json_schema(tmp_path: Path) -> None:
    result = runner.invoke(app, ["schema"])
    assert result.exit_code == 0
    schema = json.loads(result.stdout)
    assert schema["type"] == "object"
    assert {"dim", "object", "contacts", "external_wrench"} <= set(schema["properties"])
    out = tmp_path / "schema.json"
    assert runner.invoke(app, ["schema", "--out", str(out)]).exit_code == 0
    assert json.loads(out.read_text()) == schema


def test_analyze_where_and_limit_filter_the_table(tmp_path: Path) -> None:
    out = tmp_path / "some.json"
    result = runner.invoke(app, ["analyze", str(PLANAR), "--where", "D>=3", "--json", str(out)])
    assert result.exit_code == 0, result.output
    rows = json.loads(out.read_text())["combinations"]
    expected = {c.combination for c in enumerate_combinations(example_system("planar_disk_envelope"))[0]
                if c.combination.count("D") >= 3}
    assert {r["combination"] for r in rows} == expected
    result = runner.invoke(app, ["analyze", str(PLANAR), "--limit", "2", "--json", str(out)])
    assert result.exit_code == 0 and "stopped after 2 feasible combinations" in result.output
    assert sum(r["feasible"] for r in json.loads(out.read_text())["combinations"]) == 2
    for args, message in ((["--where", "X>=1"], "where: 'X>=1' is not a condition"),
                          (["--limit", "0"], "limit: 0 must be at least 1"),
                          (["--combination", "FDFDD", "--limit", "3"], "where/limit")):
        result = runner.invoke(app, ["analyze", str(PLANAR), *args])
        assert result.exit_code == 2 and message in result.output, result.output
