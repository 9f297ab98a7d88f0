"""Helpers of the service tests (on the path through pytest's `pythonpath`: tests/helpers)."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from api.settings import Settings

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"


def scenes_folder(tmp: Path, names: tuple[str, ...] = ("planar_disk_envelope",)) -> Path:
    """``tmp/scenes`` holding copies of the named examples (the input folder of ``ctp batch``)."""
    d = tmp / "scenes"
    d.mkdir()
    for n in names:
        shutil.copy(EXAMPLES / f"{n}.json", d / f"{n}.json")
    return d


def example(name: str) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((EXAMPLES / f"{name}.json").read_text())
    return data


def wait_for(client: TestClient, url: str, statuses: tuple[str, ...] = ("succeeded", "failed", "cancelled"),
             timeout: float = 60.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        body: dict[str, Any] = client.get(url).json()
        if body["status"] in statuses:
            return body
        if time.monotonic() > deadline:
            raise AssertionError(f"{url} still {body['status']} after {timeout} s: {body}")
        time.sleep(0.1)


def settings_for(tmp: Path, **kw: Any) -> Settings:
    base: dict[str, Any] = {"database_url": f"sqlite:///{tmp / 'jobs.db'}", "analysis_workers": 1, "job_workers": 1,
                            "light_workers": 1,
                            "job_poll_seconds": 0.1, "max_contacts": 6, "max_body_bytes": 200_000,
                            "request_time_limit": 30.0}
    base.update(kw)
    return Settings(**base)


# -- a real server process (uvicorn), for the browser and restart tests ---------------------------


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(tmp: Path, port: int, **env: str) -> Any:
    """``uvicorn api.main:app`` on 127.0.0.1:port with a store in ``tmp``; waits for /health."""
    import os
    import subprocess
    import sys

    import httpx

    environ = {**os.environ, "CTP_DATABASE_URL": f"sqlite:///{tmp / 'jobs.db'}", "CTP_ANALYSIS_WORKERS": "1",
               "CTP_JOB_WORKERS": "1", "CTP_JOB_POLL_SECONDS": "0.1", **env}
    log = open(tmp / f"server-{port}.log", "ab")  # noqa: SIM115 - closed with the process
    proc = subprocess.Popen([sys.executable, "-m", "uvicorn", "api.main:app", "--host", "127.0.0.1", "--port",
                             str(port)], cwd=ROOT, env=environ, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AssertionError(f"server exited with {proc.returncode}: {(tmp / f'server-{port}.log').read_text()}")
        try:
            if httpx.get(f"http://127.0.0.1:{port}/health", timeout=2).status_code == 200:
                return proc
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    proc.kill()
    raise AssertionError("server did not start within 90 s")


def health_while_posting(base_url: str, posts: list[tuple[str, bytes]], polls: int = 10) -> tuple[list[Any], float]:
    """POST each ``(path, JSON bytes)`` of ``posts`` at once (a thread each) and meanwhile time
    ``polls`` requests of ``/health``: the answers (in their order of arrival) and the slowest
    /health in seconds (each must be 200)."""
    import threading

    import httpx

    answers: list[Any] = []
    headers = {"content-type": "application/json"}
    with httpx.Client(base_url=base_url, timeout=60) as c:
        assert c.get("/health").status_code == 200
        threads = [threading.Thread(target=lambda u=u, b=b: answers.append(c.post(u, content=b, headers=headers)))
                   for u, b in posts]
        for t in threads:
            t.start()
        time.sleep(0.05)
        worst = 0.0
        for _ in range(polls):
            t0 = time.perf_counter()
            assert c.get("/health").status_code == 200
            worst = max(worst, time.perf_counter() - t0)
        for t in threads:
            t.join(60)
    return answers, worst


def kill_tree(proc: Any) -> None:
    """SIGKILL the server and its worker processes (its own session), as a crash would."""
    import contextlib
    import os
    import signal

    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(10)


def stop_server(proc: Any) -> None:
    import signal

    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(20)
        except Exception:
            kill_tree(proc)
