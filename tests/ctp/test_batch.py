"""``ctp batch``: local process pool (resumable, summary, bad scenes recorded) and Ray."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from service_helpers import EXAMPLES, scenes_folder
from typer.testing import CliRunner

from analysis.contacts import build_system
from analysis.enumerate import enumerate_combinations
from analysis.loader import load_scene
from ctp.cli import app

runner = CliRunner()


def _feasible(name: str) -> int:
    summaries, _ = enumerate_combinations(build_system(load_scene(EXAMPLES / f"{name}.json")), workers=1)
    return sum(s.feasible for s in summaries)



def test_batch_enumerate_locally_is_resumable(tmp_path: Path) -> None:
    scenes = scenes_folder(tmp_path, ("planar_disk_envelope", "sphere_four_finger_palm"))
    (scenes / "broken.json").write_text(json.dumps({"dim": 2, "contacts": []}))
    out = tmp_path / "results"
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(out), "--workers", "2"])
    assert r.exit_code == 1, r.output  # one scene failed
    assert "planar-disk-envelope" in r.output and "succeeded" in r.output and "failed" in r.output
    planar = json.loads((out / "planar_disk_envelope.json").read_text())
    assert planar["status"] == "succeeded" and planar["feasible"] == _feasible("planar_disk_envelope")
    assert len(planar["result"]["combinations"]) == 243
    broken = json.loads((out / "broken.json").read_text())
    assert broken["status"] == "failed" and broken["error"].startswith("object:")
    summary = json.loads((out / "summary.json").read_text())
    assert [s["file"] for s in summary["scenes"]] == ["broken.json", "planar_disk_envelope.json",
                                                      "sphere_four_finger_palm.json"]
    # resumed: nothing done is run again; a deleted result is
    stamp = (out / "sphere_four_finger_palm.json").stat().st_mtime_ns
    (out / "planar_disk_envelope.json").unlink()
    r = runner.invoke(app, ["batch", str(scenes), "--enumerate", "--out", str(out), "--workers", "1"])
    assert (out / "sphere_four_finger_palm.json").stat().st_mtime_ns == stamp
    assert json.loads((out / "planar_disk_envelope.json").read_text())["status"] == "succeeded"


def test_batch_bad_arguments_exit_2(tmp_path: Path) -> None:
    scenes = scenes_folder(tmp_path)
    r = runner.invoke(app, ["batch", str(scenes), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "goal" in r.output
    r = runner.invoke(app, ["batch", str(scenes), "--goal", "sideways", "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "goal" in r.output
    r = runner.invoke(app, ["batch", str(tmp_path / "nowhere"), "--enumerate"])
    assert r.exit_code == 2 and "SCENES_DIR" in r.output


@pytest.mark.slow
def test_batch_on_a_local_ray_instance(tmp_path: Path) -> None:
    ray = pytest.importorskip("ray")
    scenes = scenes_folder(tmp_path, ("planar_disk_envelope",))
    (scenes / "broken.json").write_text(json.dumps({"dim": 2, "contacts": []}))
    out = tmp_path / "results"
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        args = ["--goal", "active", "--time-limit", "60"]
        r = runner.invoke(app, ["batch", str(scenes), *args, "--out", str(out), "--ray", "local"])
        assert r.exit_code == 1, r.output  # the broken scene failed
        assert json.loads((out / "broken.json").read_text())["status"] == "failed"
        planar = json.loads((out / "planar_disk_envelope.json").read_text())
        assert planar["kind"] == "plan" and planar["status"] == "succeeded" and planar["steps"] > 0
        assert planar["result"]["steps"][0]["kind"]
    finally:
        ray.shutdown()
