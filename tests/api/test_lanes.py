"""The light and heavy lanes (api/lanes.py): heavy workers at the lowest CPU priority, light ones
at normal priority; the quick report (``samples``); a worker keeps the systems of its last scenes."""

from __future__ import annotations

import copy
import os
import sys

import pytest
from fastapi.testclient import TestClient
from service_helpers import example

from api import tasks
from api.workers import LOWEST_NICE

PLANAR = example("planar_disk_envelope")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SCHED_IDLE is Linux's")
def test_heavy_workers_run_under_sched_idle_and_light_ones_normally(client: TestClient) -> None:
    app = client.app
    heavy = app.state.analysis_pool.pids()  # type: ignore[attr-defined]
    light = app.state.light_pool.pids()  # type: ignore[attr-defined]
    assert heavy and light
    for pid in heavy:
        assert os.sched_getscheduler(pid) == os.SCHED_IDLE, pid
        assert os.getpriority(os.PRIO_PROCESS, pid) == LOWEST_NICE
    for pid in light:
        assert os.sched_getscheduler(pid) == os.SCHED_OTHER, pid
        assert os.getpriority(os.PRIO_PROCESS, pid) == os.getpriority(os.PRIO_PROCESS, 0)


def test_a_quick_report_samples_fewer_directions_with_the_same_verdict(client: TestClient) -> None:
    scene = {**PLANAR, "name": "quick"}
    full = client.post("/analyses", json={"scene": scene, "combination": "DDDSS"})
    quick = client.post("/analyses", json={"scene": scene, "combination": "DDDSS", "samples": 16})
    assert full.status_code == quick.status_code == 200, (full.text[:300], quick.text[:300])
    assert quick.headers["x-cache"] == "miss"  # another request than the full report
    f, q = full.json()["report"], quick.json()["report"]
    assert f["feasible"] is q["feasible"] is True and f["dim_dafc"] == q["dim_dafc"]
    assert len(q["dafc"]["directions"]) < len(f["dafc"]["directions"]) / 2, (
        len(q["dafc"]["directions"]), len(f["dafc"]["directions"]))


@pytest.mark.parametrize(("body", "detail"), [
    ({"samples": 16}, "samples: needs combination"),
    ({"combination": "FSFSS", "samples": 4}, "samples:"),
    ({"combination": "FSFSS", "samples": 100_000}, "samples:"),
    ({"combination": "FSFSS", "samples": "many"}, "samples:"),
])
def test_bad_samples_are_422_naming_the_field(client: TestClient, body: dict[str, object], detail: str) -> None:
    r = client.post("/analyses", json={"scene": PLANAR, **body})
    assert r.status_code == 422 and r.json()["detail"].startswith(detail), r.text


def test_a_geometry_error_found_by_the_worker_names_the_field(client: TestClient) -> None:
    """The server no longer checks the geometry itself: the worker's check answers the same 422."""
    scene = copy.deepcopy(PLANAR)
    scene["contacts"][1]["point"] = [p + 0.05 for p in scene["contacts"][1]["point"]]
    r = client.post("/analyses", json={"scene": scene, "combination": "FDFDD"})
    assert r.status_code == 422, r.text
    assert r.json()["detail"].startswith("scene.contacts.1"), r.text
    assert r.headers.get("x-cache") is None


def test_a_worker_keeps_the_systems_of_its_last_scenes() -> None:
    tasks._systems.clear()
    payload = {"scene": PLANAR, "combination": "FDFDD"}
    first = tasks.run_analysis(payload)
    kept = dict(tasks._systems)
    assert len(kept) == 1
    again = tasks.run_analysis(copy.deepcopy(payload))
    assert tasks._systems == kept  # the same entry, not a new one
    assert again["report"] == first["report"]
    for k in range(tasks.SYSTEMS_KEPT + 2):
        tasks.run_analysis({"scene": {**PLANAR, "name": f"s{k}"}, "combination": "FDFDD"})
    assert len(tasks._systems) == tasks.SYSTEMS_KEPT
    bad = copy.deepcopy(PLANAR)
    bad["contacts"][0]["mu"] = -1
    before = list(tasks._systems)
    with pytest.raises(Exception, match="mu"):
        tasks.run_analysis({"scene": bad, "combination": "FDFDD"})
    assert list(tasks._systems) == before  # a scene that failed validation is not kept
    tasks._systems.clear()
