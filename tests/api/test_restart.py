"""Jobs survive a server crash: submit jobs, SIGKILL the server and its workers mid-job, start it
again on the same store, and every accepted job completes."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path

import httpx
import pytest
from service_helpers import example, free_port, kill_tree, start_server, stop_server


def wait_until_running(url: str, timeout: float = 60.0) -> None:
    """Poll the job at ``url`` until it runs; a job that ends first fails the test at once, by name
    (the interruption the test is about cannot happen to it)."""
    deadline = time.monotonic() + timeout
    while (body := httpx.get(url, timeout=10).json())["status"] != "running":
        assert body["status"] == "queued", f"the job ended before it was seen running: {body}"
        assert time.monotonic() < deadline, f"the job did not start in {timeout:.0f} s: {body}"
        time.sleep(0.05)


@pytest.mark.slow
def test_jobs_survive_a_killed_server(tmp_path: Path, store_url: str) -> None:
    """On both stores (``store_url``: SQLite, and PostgreSQL when CTP_TEST_POSTGRES_URL is set)."""
    env = {"CTP_JOB_LEASE_SECONDS": "2", "CTP_DATABASE_URL": store_url}
    port = free_port()
    server = start_server(tmp_path, port, **env)
    base = f"http://127.0.0.1:{port}"
    planar, palm = example("planar_disk_envelope"), example("sphere_four_finger_palm")
    # the first job, the one the crash interrupts, is the wrap's 19,683 combinations (seconds): the
    # palm's 243 ran in 0.2 s and could finish before the poll saw it running (it did in a CI run)
    wrap = example("sphere_four_finger_wrap")
    ids: list[str] = []
    try:
        for scene in (wrap, planar, palm, planar):
            r = httpx.post(f"{base}/enumerations", json={"scene": scene}, timeout=30)
            assert r.status_code == 202, r.text
            ids.append(r.json()["url"])
        r = httpx.post(f"{base}/plans", json={"scene": planar, "goal": {"type": "active"}}, timeout=30)
        assert r.status_code == 202, r.text
        ids.append(r.json()["url"])
        wait_until_running(base + ids[0])  # then crash everything
    finally:
        kill_tree(server)
    with pytest.raises(httpx.HTTPError):
        httpx.get(f"{base}/health", timeout=2)

    server = start_server(tmp_path, port, **env)
    try:
        deadline = time.monotonic() + 240
        final: dict[str, dict] = {}
        while len(final) < len(ids):
            assert time.monotonic() < deadline, f"not all jobs finished: {final}"
            for url in ids:
                body = httpx.get(base + url, timeout=10).json()
                if body["status"] in ("succeeded", "failed", "cancelled"):
                    final[url] = body
            time.sleep(0.2)
        assert all(b["status"] == "succeeded" for b in final.values()), final
        first = final[ids[0]]
        assert first["attempts"] == 2, first  # interrupted once, resumed once
        for url in ids:
            assert httpx.get(base + url + "/result", timeout=10).status_code == 200
        counts = httpx.get(f"{base}/health", timeout=10).json()["jobs"]
        assert counts.get("succeeded", 0) >= len(ids)
    finally:
        stop_server(server)


@pytest.mark.slow
def test_a_graceful_stop_requeues_at_once(tmp_path: Path) -> None:
    """SIGINT (a deploy, Ctrl-C): the running job goes back to the queue without waiting for its
    lease (30 s here) and without counting as an attempt; the restarted server finishes it."""
    port = free_port()
    server = start_server(tmp_path, port, CTP_JOB_LEASE_SECONDS="30")
    base = f"http://127.0.0.1:{port}"
    # the wrap's 19,683 combinations (seconds): the palm's 243 could finish between the poll that saw
    # the job running and the stop (it did on a fast machine: 'succeeded' before the stop took effect)
    wrap = example("sphere_four_finger_wrap")
    urls = [httpx.post(f"{base}/enumerations", json={"scene": wrap}, timeout=30).json()["url"] for _ in range(2)]
    wait_until_running(base + urls[0])
    stop_server(server)
    assert server.returncode is not None
    stopped_at = time.time()
    # back in the queue the moment the server stopped, not held by its lease until it runs out (a
    # crashed server's job stays "running" with its owner): read the store while no server runs
    with sqlite3.connect(tmp_path / "jobs.db") as db:
        status, owner, attempts = db.execute("SELECT status, owner, attempts FROM jobs WHERE id = ?",
                                             (urls[0].rsplit("/", 1)[-1],)).fetchone()
    assert (status, owner, attempts) == ("queued", None, 0), (status, owner, attempts)
    server = start_server(tmp_path, port, CTP_JOB_LEASE_SECONDS="30")
    try:
        deadline = time.monotonic() + 240  # generous: the time the two enumerations take on a busy machine
        for url in urls:
            while (body := httpx.get(base + url, timeout=10).json())["status"] in ("queued", "running"):
                assert time.monotonic() < deadline, body
                time.sleep(0.1)
            assert body["status"] == "succeeded" and body["attempts"] == 1, body
        first = httpx.get(base + urls[0], timeout=10).json()
        assert first["started_at"] < stopped_at < first["finished_at"], first  # interrupted, then resumed
    finally:
        stop_server(server)
