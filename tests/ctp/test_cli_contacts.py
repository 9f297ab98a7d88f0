"""``ctp contacts`` and ``"contacts": "auto"`` on the command line (issue 10)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from typer.testing import CliRunner

from analysis.loader import load_scene
from ctp.cli import app

runner = CliRunner()
PLANAR = Path(__file__).resolve().parents[2] / "examples" / "planar_disk_envelope.json"


def _without_contacts(tmp_path: Path, **changes: Any) -> tuple[Path, list[dict[str, Any]]]:
    data = json.loads(PLANAR.read_text())
    bundled = data.pop("contacts")
    data.update(changes)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(data))
    return path, bundled


def test_contacts_writes_the_complete_scene(tmp_path: Path) -> None:
    src, bundled = _without_contacts(tmp_path)
    out = tmp_path / "full.json"
    r = runner.invoke(app, ["contacts", str(src), "--out", str(out), "--mu", "0.6"])
    assert r.exit_code == 0, r.output
    assert "5 contacts within 0.001" in r.output and "no near misses" in r.output
    scene = load_scene(out)  # the written scene loads as it is
    assert [c.body for c in scene.contacts] == [c["body"] for c in bundled]
    for got, want in zip(scene.contacts, bundled, strict=True):
        np.testing.assert_allclose(got.point, want["point"], atol=1e-9)
        np.testing.assert_allclose(got.normal, want["normal"], atol=1e-9)
        assert got.mu == 0.6
    written = json.loads(out.read_text())
    assert written["name"] == "planar-disk-envelope" and "fixed_bodies" in written


def test_near_misses_and_gaps(tmp_path: Path) -> None:
    data = json.loads(PLANAR.read_text())
    data["object"]["pose"]["position"] = [0.0, 0.505]  # lifted 5 mm off the palm: a near miss only
    src, _ = _without_contacts(tmp_path, object=data["object"], fingers=[])
    r = runner.invoke(app, ["contacts", str(src)])
    assert r.exit_code == 2 and "touches nothing within 0.001" in r.output and "'palm' at 0.005" in r.output
    # within the tolerance but farther than the validation's 1e-4 from the palm: a clear error
    r = runner.invoke(app, ["contacts", str(src), "--tolerance", "0.01"])
    assert r.exit_code == 2, r.output
    assert "'palm' is within the tolerance 0.01 of the object but 0.005 away" in r.output
    data["object"]["pose"]["position"] = [0.0, 0.5 + 5e-5]  # 0.05 mm: a contact on the object's surface
    src, _ = _without_contacts(tmp_path, object=data["object"], fingers=[])
    r = runner.invoke(app, ["contacts", str(src), "--out", str(tmp_path / "full.json")])
    assert r.exit_code == 0 and "1 contacts within 0.001" in r.output and "5e-05" in r.output, r.output
    (c,) = load_scene(tmp_path / "full.json").contacts
    np.testing.assert_allclose(c.point, [0.0, 5e-5], atol=1e-12)
    # a finger link 5 mm from the object is listed as a near miss beside the contact
    data = json.loads(PLANAR.read_text())
    data["fingers"][0]["base"]["position"] = [-0.6, 0.05]  # moves left/0 0.05 * 0.180 away from the disk
    src, _ = _without_contacts(tmp_path, fingers=data["fingers"][:1])
    r = runner.invoke(app, ["contacts", str(src)])
    assert r.exit_code == 0 and "near miss: left/0 at 0.009016" in r.output, r.output
    # moved the other way, left/1 (the deeper) penetrates the disk by 0.005 * 0.953
    data["fingers"][0]["base"]["position"] = [-0.6, -0.005]
    src, _ = _without_contacts(tmp_path, fingers=data["fingers"][:1])
    r = runner.invoke(app, ["contacts", str(src)])
    assert r.exit_code == 2 and "'left/1' penetrates the object by 0.004764" in r.output, r.output


def test_auto_contacts_are_analysed(tmp_path: Path) -> None:
    src, _ = _without_contacts(tmp_path, contacts="auto")
    r = runner.invoke(app, ["analyze", str(src), "--combination", "FDFDD"])
    assert r.exit_code == 0, r.output
    assert "planar-disk-envelope combination FDFDD: feasible" in r.output


def test_bad_input_is_one_line_and_exit_2(tmp_path: Path) -> None:
    src, _ = _without_contacts(tmp_path)
    for args, text in ((["--tolerance", "0"], "tolerance:"), (["--mu", "-1"], "mu:"),
                       (["--out", str(tmp_path / "no" / "x.json")], "--out:")):
        r = runner.invoke(app, ["contacts", str(src), *args])
        assert r.exit_code == 2 and text in r.output, r.output
    bad, _ = _without_contacts(tmp_path, colour="red")
    r = runner.invoke(app, ["contacts", str(bad)])
    assert r.exit_code == 2 and "colour" in r.output
