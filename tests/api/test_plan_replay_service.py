"""``POST /plans`` with ``"replay": true``: the plan job replays its plan in MuJoCo after planning
and the result carries the replay (object path, per-step planned and simulated displacements,
position and rotation errors with units, dropped or not), checked against
:func:`sim.plan_replay.simulate_plan` run here on the same plan; bad values are a 422 naming
``replay``; a replay that cannot run is the replay's failure, not the plan's."""

from __future__ import annotations

import copy
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from service_helpers import example, settings_for, wait_for

from analysis.loader import scene_from_dict
from api.main import create_app
from api.tasks import _replay, run_plan
from sim.plan_replay import simulate_plan

PLANAR = example("planar_disk_envelope")


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    app = create_app(settings_for(tmp_path_factory.mktemp("replay"), job_time_limit=120.0))
    with TestClient(app) as c:
        yield c


@pytest.fixture(scope="module")
def replayed(client: TestClient) -> dict:
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}, "replay": True})
    assert r.status_code == 202, r.text
    done = wait_for(client, r.json()["url"], timeout=120)
    assert done["status"] == "succeeded", done
    res = client.get(done["result_url"])
    assert res.status_code == 200
    data: dict = res.json()
    return data


def test_plan_result_carries_the_replay_of_simulate_plan(replayed: dict) -> None:
    plan = replayed
    assert plan["found"] is True and plan["outcome"] == "reached" and len(plan["steps"]) == 5
    rep = plan["replay"]
    assert rep["status"] == "done" and rep["error"] is None, rep.get("error")
    # the same replay, run here on the plan as the client received it
    direct = simulate_plan(scene_from_dict(PLANAR), plan)
    want = direct.to_json()
    for key in ("ok", "dropped", "drop_reason", "tolerance"):
        assert rep[key] == want[key], key
    for key in ("position_error", "rotation_error", "relative_position_error", "relative_rotation_error",
                "planned_translation", "planned_rotation", "duration"):
        assert rep[key] == pytest.approx(want[key], rel=1e-9, abs=1e-12), key
    np.testing.assert_allclose(rep["simulated_final_pose"], direct.simulated_final_pose, atol=1e-12)
    np.testing.assert_allclose(rep["planned_final_pose"], plan["final_pose"], atol=1e-12)
    assert len(rep["steps"]) == len(plan["steps"])
    for s_rep, s_dir, s_plan in zip(rep["steps"], direct.steps, plan["steps"], strict=True):
        assert s_rep["kind"] == s_plan["kind"] and s_rep["index"] == s_dir.index
        op = np.asarray(s_plan["object_path"])
        np.testing.assert_allclose(s_rep["planned"], op[-1] - op[0], atol=1e-9)  # planned, from the plan itself
        np.testing.assert_allclose(s_rep["simulated"], s_dir.simulated, atol=1e-12)
    # the sampled object path, from the start pose to the simulated final pose
    path = rep["object_path"]
    poses = np.asarray(path["poses"])
    np.testing.assert_allclose(poses, direct.object_path.poses, atol=1e-12)
    assert path["steps"] == [int(k) for k in direct.object_path.steps]
    np.testing.assert_allclose(poses[0], plan["start_pose"], atol=1e-6)
    np.testing.assert_allclose(poses[-1], rep["simulated_final_pose"], atol=0.0)
    # the outcome in words and units: the lift lands within 5 % of the plan, nothing dropped
    assert rep["ok"] and not rep["dropped"] and rep["relative_error"] <= 0.05
    assert rep["units"]["position_error"] == "m" and rep["units"]["rotation_error"] == "rad"
    assert f"position error {rep['position_error']:.3g} m" in rep["summary"]
    assert f"rotation error {rep['rotation_error']:.3g} rad" in rep["summary"]


def test_a_plan_without_replay_has_none(client: TestClient) -> None:
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "combination", "combination": "DDFFF"}})
    assert r.status_code == 202, r.text
    done = wait_for(client, r.json()["url"], timeout=120)
    assert done["status"] == "succeeded", done
    plan = client.get(done["result_url"]).json()
    assert plan["found"] is True and len(plan["steps"]) == 1, plan.get("reason")
    assert "replay" not in plan


@pytest.mark.parametrize("value", ["yes", 1, None, [True], {"on": True}])
def test_a_bad_replay_value_is_422_naming_the_field(client: TestClient, value: object) -> None:
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}, "replay": value})
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["detail"].startswith("replay:"), body
    assert body["errors"][0]["loc"][-1] == "replay"


def test_no_plan_means_the_replay_is_skipped_not_failed(client: TestClient) -> None:
    scene = copy.deepcopy(PLANAR)
    scene["contacts"] = [c for c in scene["contacts"] if c["body"] == "palm"]
    scene["external_wrench"] = [1.0, 0.0, 0.0]  # pushed sideways off the palm: nothing holds it
    r = client.post("/plans", json={"scene": scene, "goal": {"type": "active"}, "replay": True})
    assert r.status_code == 202, r.text
    done = wait_for(client, r.json()["url"], timeout=120)
    assert done["status"] == "succeeded", done
    plan = client.get(done["result_url"]).json()
    assert plan["found"] is False and plan["replay"]["status"] == "skipped"
    assert "no plan" in plan["replay"]["reason"]


def test_a_replay_out_of_time_is_the_replays_failure(replayed: dict) -> None:
    """The replay stops at its wall-clock limit (here 1 ms, far below the ~2 s it needs) and says
    so in the result; the plan is untouched."""
    rep = _replay(scene_from_dict(PLANAR), replayed, time_limit=1e-3)
    assert rep["status"] == "failed" and "time limit" in rep["error"], rep
    assert "object_path" not in rep and "ok" not in rep
    none_left = _replay(scene_from_dict(PLANAR), replayed, time_limit=-0.5)
    assert none_left["status"] == "failed" and "none was left for the replay" in none_left["error"]


def test_a_replay_of_a_plan_that_does_not_fit_its_scene_fails_in_words(replayed: dict) -> None:
    other = copy.deepcopy(replayed)
    other["start_pose"][1] += 0.05  # a plan made for another start pose than the scene's
    rep = _replay(scene_from_dict(PLANAR), other, time_limit=30.0)
    assert rep["status"] == "failed" and "start_pose" in rep["error"], rep


def test_run_plan_reports_the_replay_stage(tmp_path: Path) -> None:
    """The worker's task: the search reports up to 3/4 of the progress, then the replay stage."""
    seen: list[tuple[float, str]] = []
    out = run_plan({"scene": PLANAR, "goal": {"type": "combination", "combination": "DDFFF"},
                    "time_limit": 60.0, "replay": True}, lambda f, m: seen.append((f, m)))
    assert out["found"] and out["replay"]["status"] == "done", out["replay"].get("error")
    assert seen[-1] == (0.75, "replaying the plan in MuJoCo")
    assert all(f <= 0.75 + 1e-12 for f, _ in seen)
    assert not out["replay"]["dropped"] and len(out["replay"]["steps"]) == len(out["steps"])
