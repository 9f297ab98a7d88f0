"""Loopback load test of the service. Prints latency percentiles, errors and the machine.

Starts ``uvicorn api.main:app`` on 127.0.0.1 with a fresh SQLite store, then sends N
``POST /analyses`` requests from C concurrent clients and reports p50/p95/max latency, the
error count and throughput. Default: 200 requests, 20 clients, the full report of the first feasible
combination of the planar example (stationary grasp, DAFC set, DPFC, torque set, regrasp
cone); ``--table`` sends the table of all 243 combinations instead.

    .venv/bin/python benchmarks/service.py [--requests 200] [--clients 20] [--workers 2] [--table]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
from machine import machine  # noqa: E402


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start(port: int, workers: int, tmp: Path) -> subprocess.Popen[bytes]:
    env = {**os.environ, "CTP_DATABASE_URL": f"sqlite:///{tmp / 'jobs.db'}", "CTP_ANALYSIS_WORKERS": str(workers)}
    proc = subprocess.Popen([sys.executable, "-m", "uvicorn", "api.main:app", "--host", "127.0.0.1", "--port",
                             str(port), "--log-level", "warning"], cwd=ROOT, env=env, start_new_session=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/health", timeout=2).status_code == 200:
                return proc
        except httpx.HTTPError:
            time.sleep(0.2)
    proc.kill()
    raise SystemExit("the server did not start")


async def load(base: str, body: dict[str, object], n: int, clients: int) -> tuple[list[float], list[str], float]:
    latencies: list[float] = []
    errors: list[str] = []
    queue: asyncio.Queue[int] = asyncio.Queue()
    for k in range(n):
        queue.put_nowait(k)

    async def client() -> None:
        async with httpx.AsyncClient(base_url=base, timeout=120) as c:
            while True:
                try:
                    queue.get_nowait()
                except asyncio.QueueEmpty:
                    return
                t0 = time.perf_counter()
                try:
                    r = await c.post("/analyses", json=body)
                    ok = r.status_code == 200
                    if not ok:
                        errors.append(f"{r.status_code}: {r.text[:200]}")
                except httpx.HTTPError as e:
                    errors.append(f"{type(e).__name__}: {e}")
                    ok = False
                if ok:
                    latencies.append(time.perf_counter() - t0)

    t0 = time.perf_counter()
    await asyncio.gather(*(client() for _ in range(clients)))
    return latencies, errors, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=200)
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2, help="analysis worker processes of the server")
    ap.add_argument("--table", action="store_true", help="request the table of all combinations")
    args = ap.parse_args()
    scene = json.loads((ROOT / "examples" / "planar_disk_envelope.json").read_text())
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        proc = start(port, args.workers, Path(tmp))
        try:
            base = f"http://127.0.0.1:{port}"
            table = httpx.post(f"{base}/analyses", json={"scene": scene}, timeout=120)  # warm-up
            table.raise_for_status()
            combo = next(r["combination"] for r in table.json()["combinations"] if r["feasible"])
            body: dict[str, object] = {"scene": scene} if args.table else {"scene": scene, "combination": combo}
            lat, errors, wall = asyncio.run(load(base, body, args.requests, args.clients))
        finally:
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(30)
    what = "table of 243 combinations" if args.table else f"full report of the feasible combination {combo}"
    print(f"service load test: {args.requests} POST /analyses ({what}, planar_disk_envelope), "
          f"{args.clients} concurrent clients, {args.workers} analysis workers, loopback")
    if lat:
        q = statistics.quantiles(lat, n=100, method="inclusive")
        print(f"  latency p50 {1000 * q[49]:.1f} ms   p95 {1000 * q[94]:.1f} ms   max {1000 * max(lat):.1f} ms")
    print(f"  errors {len(errors)} of {args.requests}; throughput {len(lat) / wall:.1f} requests/s; wall {wall:.2f} s")
    for e in errors[:5]:
        print(f"    {e}")
    print(f"  machine: {machine()}")
    if errors:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
