"""Fault injection on the worker processes: a worker killed mid-request or mid-job, and the
server killed alone (kill -9): its workers and the multiprocessing resource tracker must not
outlive it (parent-death signal and watchdog, api/workers.py)."""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient
from service_helpers import example, free_port, kill_tree, settings_for, start_server, wait_for

from api.main import create_app

PALM = example("sphere_four_finger_palm")
WRAP = example("sphere_four_finger_wrap")  # 19,683 combinations: keeps a worker busy


@pytest.fixture(scope="module")
def app_client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    app = create_app(settings_for(tmp_path_factory.mktemp("faults"), max_contacts=9, request_time_limit=60.0,
                                  job_max_attempts=2))
    with TestClient(app) as c:
        yield c


def _wait_busy(pool: Any, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while pool.idle() > 0:
        assert time.monotonic() < deadline, "the worker never became busy"
        time.sleep(0.02)


def test_a_killed_analysis_worker_is_a_json_503_and_is_replaced(app_client: TestClient) -> None:
    pool = app_client.app.state.analysis_pool  # type: ignore[attr-defined]
    out: list[Any] = []
    t = threading.Thread(target=lambda: out.append(app_client.post("/analyses", json={"scene": WRAP})))
    t.start()
    _wait_busy(pool)
    (pid,) = pool.pids()
    os.kill(pid, signal.SIGKILL)
    t.join(30)
    r = out[0]
    assert r.status_code == 503 and r.headers["content-type"] == "application/json", r.text
    assert "worker" in r.json()["detail"] and "Traceback" not in r.text
    # a fresh worker takes the next request
    r = app_client.post("/analyses", json={"scene": PALM})
    assert r.status_code == 200, r.text
    assert pool.alive() == pool.size and pid not in pool.pids()


def test_a_killed_job_worker_retries_the_job(app_client: TestClient) -> None:
    runner = app_client.app.state.runner  # type: ignore[attr-defined]
    jobs_pool = runner.executor
    r = app_client.post("/enumerations", json={"scene": PALM})
    assert r.status_code == 202, r.text
    url = r.json()["url"]
    deadline = time.monotonic() + 30
    while app_client.get(url).json()["status"] != "running":
        assert time.monotonic() < deadline
        time.sleep(0.02)
    _wait_busy(jobs_pool)
    for pid in jobs_pool.pids():
        os.kill(pid, signal.SIGKILL)
    done = wait_for(app_client, url, timeout=120)
    assert done["status"] == "succeeded" and done["attempts"] == 2, done  # retried once, on a new worker
    assert app_client.get(done["result_url"]).status_code == 200


# -- kill -9 of the server alone ------------------------------------------------------------------


def _children(pid: int) -> list[int]:
    """Every process whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        if int(fields[1]) == pid:
            out.append(int(entry))
    return out


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _alive(pid: int) -> bool:
    """Running (not gone, not a zombie waiting to be reaped)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc")
def test_kill_9_of_the_server_leaves_no_worker_alive(tmp_path: Path) -> None:
    port = free_port()
    server = start_server(tmp_path, port, CTP_LIGHT_WORKERS="1")
    base = f"http://127.0.0.1:{port}"
    try:
        # keep workers busy: a table in the analysis lane, an enumeration job
        def table() -> None:
            with contextlib.suppress(httpx.HTTPError):  # the server dies under it
                httpx.post(f"{base}/analyses", json={"scene": WRAP}, timeout=60)

        threading.Thread(target=table, daemon=True).start()
        assert httpx.post(f"{base}/enumerations", json={"scene": WRAP}, timeout=30).status_code == 202
        time.sleep(1.0)
        children = _children(server.pid)
        workers = [p for p in children if "spawn_main" in _cmdline(p)]
        tracker = [p for p in children if "resource_tracker" in _cmdline(p)]
        assert len(workers) == 3, children  # the analysis, light and job workers
        for p in workers:
            # busy and deaf: a worker in a long solver call reads neither its pipe nor a closed
            # socket; stopped, it can only be ended by the kernel (the parent-death signal)
            os.kill(p, signal.SIGSTOP)
        os.kill(server.pid, signal.SIGKILL)  # the server alone, not its process group
        workers += tracker
        server.wait(10)
        deadline = time.monotonic() + 5.0
        while any(_alive(p) for p in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        survivors = [p for p in workers if _alive(p)]
        assert not survivors, f"still alive 5 s after the server died: {survivors}"
    finally:
        kill_tree(server)  # whatever is left of its session
