"""The job resources on both stores (``store_client``: the service on SQLite, then on
PostgreSQL): submit, poll, result, list, cancel a queued and a running job."""

from __future__ import annotations

from fastapi.testclient import TestClient
from service_helpers import example, wait_for

PLANAR = example("planar_disk_envelope")


def test_health_names_the_store(store_client: TestClient) -> None:
    r = store_client.get("/health")
    assert r.status_code == 200
    body = r.json()
    assert body["store"] == "ok" and body["database"] in ("sqlite", "postgresql")


def test_submit_poll_result_list(store_client: TestClient) -> None:
    c = store_client
    r = c.post("/enumerations", json={"scene": PLANAR})
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["status"] in ("queued", "running") and r.headers["location"] == f"/enumerations/{job['id']}"
    done = wait_for(c, job["url"])
    assert done["status"] == "succeeded" and done["attempts"] == 1 and done["progress"] == 1.0, done
    result = c.get(done["result_url"])
    assert result.status_code == 200
    rows = result.json()["combinations"]
    assert len(rows) == 3 ** len(PLANAR["contacts"]) and result.json()["feasible"] == sum(x["feasible"] for x in rows)
    plan = c.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}})
    assert plan.status_code == 202
    listed = [j["id"] for j in c.get("/enumerations").json()["items"]]
    assert job["id"] in listed and plan.json()["id"] not in listed
    assert c.get("/plans").json()["items"][0]["id"] == plan.json()["id"]  # newest first
    ok = c.get("/enumerations", params={"status": "succeeded"}).json()["items"]
    assert ok and all(j["status"] == "succeeded" for j in ok)
    assert wait_for(c, plan.json()["url"], timeout=120)["status"] in ("succeeded", "failed")
    assert c.get("/health").json()["jobs"].get("succeeded", 0) >= 1


def test_cancel_queued_and_running(store_client: TestClient) -> None:
    c = store_client
    running = c.post("/enumerations", json={"scene": example("sphere_four_finger_wrap")}).json()  # 19,683 rows
    queued = c.post("/enumerations", json={"scene": PLANAR}).json()  # one job worker: it waits
    wait_for(c, running["url"], statuses=("running",))
    assert c.get(f"{queued['url']}/result").status_code == 409
    assert c.delete(queued["url"]).json()["status"] == "cancelled"
    r = c.delete(running["url"])
    assert r.status_code == 200 and r.json()["status"] in ("running", "cancelled")
    assert wait_for(c, running["url"], timeout=20)["status"] == "cancelled"
    assert wait_for(c, queued["url"])["status"] == "cancelled"
    nxt = c.post("/enumerations", json={"scene": PLANAR}).json()
    assert wait_for(c, nxt["url"])["status"] == "succeeded"
    assert c.get("/plans/nope").status_code == 404 and c.delete("/enumerations/nope").status_code == 404
