"""``ctp batch --out``: an output folder that cannot hold the results is exit 2 with one line
naming the option, before any scene is run; a write that fails during the run is exit 2 too,
and the results written before it are kept for the next run."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from service_helpers import scenes_folder
from typer.testing import CliRunner

import ctp.batch
from ctp.cli import app

runner = CliRunner()



def _one_line_error(output: str, *words: str) -> None:
    lines = [ln for ln in output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), output
    assert "Traceback" not in output
    for w in words:
        assert w in lines[0], (w, output)


def test_out_that_is_a_file_exits_2(tmp_path: Path) -> None:
    scenes = scenes_folder(tmp_path)
    out = tmp_path / "results"
    out.write_text("not a folder")
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(out), "--workers", "1"])
    assert r.exit_code == 2
    _one_line_error(r.output, "out:", "is not a folder")
    assert out.read_text() == "not a folder"


def test_out_under_a_file_exits_2(tmp_path: Path) -> None:
    scenes = scenes_folder(tmp_path)
    (tmp_path / "plain").write_text("x")
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(tmp_path / "plain" / "results")])
    assert r.exit_code == 2
    _one_line_error(r.output, "out:", "cannot create the folder")


def test_out_equal_to_the_scenes_folder_exits_2(tmp_path: Path) -> None:
    scenes = scenes_folder(tmp_path)
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(scenes / ".")])
    assert r.exit_code == 2
    _one_line_error(r.output, "out:", "SCENES_DIR")
    assert sorted(p.name for p in scenes.iterdir()) == ["planar_disk_envelope.json"]  # nothing written


@pytest.mark.parametrize(("extra", "words"), [
    ("planar_disk_envelope.yaml", ("planar_disk_envelope.json", "planar_disk_envelope.yaml", "share")),
    ("summary.json", ("summary.json", "rename")),
])
def test_scene_files_that_would_share_a_result_file_exit_2(tmp_path: Path, extra: str,
                                                           words: tuple[str, ...]) -> None:
    scenes = scenes_folder(tmp_path)
    shutil.copy(scenes / "planar_disk_envelope.json", scenes / extra)
    out = tmp_path / "results"
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(out), "--workers", "1"])
    assert r.exit_code == 2
    _one_line_error(r.output, "SCENES_DIR:", *words)
    assert not out.exists() or not any(out.iterdir())  # refused before any work


def test_a_missing_out_folder_is_made_with_its_parents(tmp_path: Path) -> None:
    scenes = scenes_folder(tmp_path)
    out = tmp_path / "a" / "b" / "results"
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(out), "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert json.loads((out / "planar_disk_envelope.json").read_text())["status"] == "succeeded"
    assert json.loads((out / "summary.json").read_text())["scenes"][0]["status"] == "succeeded"


def test_a_write_that_fails_during_the_run_exits_2_and_keeps_what_was_written(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A full disk, simulated: the second result file cannot be written. Exit 2 naming the
    file and the reason; the first result stays, and the next run only does the rest."""
    scenes = scenes_folder(tmp_path, ("planar_disk_envelope", "sphere_four_finger_palm"))
    out = tmp_path / "results"
    real_write = ctp.batch._write
    written: list[str] = []

    def full_disk(path: Path, record: dict[str, object]) -> None:
        if written:
            raise OSError(28, "No space left on device", str(path))
        real_write(path, record)
        written.append(path.name)

    monkeypatch.setattr(ctp.batch, "_write", full_disk)
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(out), "--workers", "1"])
    assert r.exit_code == 2, r.output
    err = [ln for ln in r.output.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "out: cannot write" in err[0] and "No space left on device" in err[0], r.output
    assert "Traceback" not in r.output
    assert len(written) == 1 and (out / written[0]).exists()
    monkeypatch.setattr(ctp.batch, "_write", real_write)
    stamp = (out / written[0]).stat().st_mtime_ns
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(out), "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert (out / written[0]).stat().st_mtime_ns == stamp  # done before: not run again
    rows = json.loads((out / "summary.json").read_text())["scenes"]
    assert [row["status"] for row in rows] == ["succeeded", "succeeded"]
