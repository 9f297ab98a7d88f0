"""Loopback load test of the service. Prints latency percentiles, errors and the machine.

Starts ``uvicorn api.main:app`` on 127.0.0.1 with a fresh SQLite store, runs the scenarios and
stops it. Every request loop is bounded (a fixed number of requests, a time-out each).

* ``report`` (the original figure): N ``POST /analyses`` of the full report of the first feasible
  combination of the planar example from C concurrent clients (``--table``: the table of all 243
  combinations instead). The same request repeats, so after the first it is a cache hit.
* ``mixed`` (issue 13, fairness): C clients x R light requests, each a different combination of the
  planar example (all 243 in turn: each is computed, none is in the cache), while 2 heavy clients
  keep sending tables of every combination of ``sphere_four_finger_palm`` (each under another
  scene name, so none is a cache hit). Target: light p95 under 400 ms, 0 errors. This one is
  bound by capacity as much as by fairness: C clients always waiting for analyses of c ms of CPU
  each on 2 cores wait about C x c / 2 on average (Little's law); ``benchmarks/analysis.py
  --planar-reports`` prints c for these combinations (the first 200 of the table).
* ``mixed-repeat``: the same with the light requests drawn from 20 combinations (the first
  request of each is computed, the others are cache hits), as when several people look at the
  same scenes.
* ``cached`` (issue 13, the content-addressed cache): C clients x R requests that each repeat one
  of 20 analyses made before. Target: p95 under 20 ms.
* ``bodies`` (issue 13, the event loop): 4 clients each send 5 bodies of about 1 MB (a planar scene
  with 8,900 contacts: two tables, an enumeration, one combination whose letters do not match: all
  refused) while one client asks ``GET /health`` every 20 ms. Target: the slowest /health under
  150 ms, every body refused with its 413/422 (bodies over ``inline_body_bytes`` are decoded and
  checked in a light worker, api/bodies.py).

``--samples N`` makes the light requests quick reports (``samples``: N DAFC directions instead of
the server's 120), as a dashboard that wants an answer while the user clicks may ask. Each
scenario prints how busy the machine was meanwhile and how much of it was other processes (the
figures are only comparable on a quiet machine: on 2 cores every other busy process takes CPU
from the light workers). Each scenario sends its own scene name, so none is answered from
another's cache. An answer is an error when it is neither 200 nor a 422 in which the analysis
says no (one combination of the planar scene is refused by cdd as numerically inconsistent: the
answer, not a fault); the heavy
requests' own errors (a table stopped at ``request_time_limit`` while the light ones had the CPU)
are listed but are not a target. The clients are a minimal keep-alive HTTP client (``Client``),
so that the load generator does not take the CPU it measures. The exit code is 1 when a scenario
misses its target.

    .venv/bin/python benchmarks/service.py [--scenario all|report|mixed|mixed-repeat|cached|bodies] [--clients 20]
        [--requests-per-client 10] [--workers 2] [--light-workers 2] [--requests 200] [--table] [--samples N]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import copy
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]
from machine import machine  # noqa: E402

LIGHT_P95_TARGET = 0.400
CACHED_P95_TARGET = 0.020
HEALTH_MAX_TARGET = 0.150


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start(port: int, workers: int, light_workers: int, tmp: Path) -> subprocess.Popen[bytes]:
    env = {**os.environ, "CTP_DATABASE_URL": f"sqlite:///{tmp / 'jobs.db'}", "CTP_ANALYSIS_WORKERS": str(workers),
           "CTP_LIGHT_WORKERS": str(light_workers)}
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


def light_workers_cpu(server_pid: int) -> float:
    """CPU seconds of the server's light-lane workers (its worker processes at nice 0)."""
    total = 0.0
    for entry in os.listdir("/proc") if Path("/proc").is_dir() else []:
        try:
            fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) != server_pid or int(fields[16]) != 0:
                continue
            if b"spawn_main" in Path(f"/proc/{entry}/cmdline").read_bytes():
                total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except (OSError, ValueError, IndexError):
            continue
    return total


def tree_cpu_seconds(root: int) -> float:
    """User + system CPU seconds of a process and its descendants (Linux /proc): the live ones'
    own, plus what the ended children the process has reaped spent (workers replaced after a
    time limit)."""
    parent: dict[int, int] = {}
    cpu: dict[int, float] = {}
    reaped = 0.0
    tick = os.sysconf("SC_CLK_TCK")
    for entry in os.listdir("/proc") if Path("/proc").is_dir() else []:
        if not entry.isdigit():
            continue
        try:
            fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(entry)] = int(fields[1])
        cpu[int(entry)] = (int(fields[11]) + int(fields[12])) / tick
        if int(entry) == root:
            reaped = (int(fields[13]) + int(fields[14])) / tick
    total = reaped
    for pid, c in cpu.items():
        p = pid
        while p > 1 and p != root:
            p = parent.get(p, 0)
        total += c if p == root else 0.0
    return total


def machine_busy_seconds() -> float:
    """CPU seconds the whole machine spent busy (not idle nor waiting for I/O), all cores."""
    try:
        values = [int(v) for v in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    except (OSError, ValueError):
        return 0.0
    return (sum(values[:8]) - values[3] - values[4]) / os.sysconf("SC_CLK_TCK")


class Load:
    """How busy the machine was during a scenario, and how much of it was not this benchmark
    (the server and its workers, and this process: the clients)."""

    def __init__(self, server_pid: int):
        self.server_pid = server_pid
        self.t0 = time.perf_counter()
        self.busy0 = machine_busy_seconds()
        self.ours0 = tree_cpu_seconds(server_pid) + sum(os.times()[:2])

    def line(self) -> str:
        wall = time.perf_counter() - self.t0
        busy = machine_busy_seconds() - self.busy0
        ours = tree_cpu_seconds(self.server_pid) + sum(os.times()[:2]) - self.ours0
        return (f"    machine during the scenario ({wall:.1f} s): {busy / wall:.2f} of {os.cpu_count()} cores busy, "
                f"{ours / wall:.2f} by the server, its workers and the clients, "
                f"{max(0.0, busy - ours) / wall:.2f} by other processes")


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of a process (Linux /proc; 0 elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@dataclass
class Run:
    latencies: list[float] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    refused: int = 0  # 422: the analysis says no (an answer)
    hits: int = 0
    wall: float = 0.0

    def p(self, q: int) -> float:
        if len(self.latencies) < 2:
            return self.latencies[0] if self.latencies else float("nan")
        return statistics.quantiles(self.latencies, n=100, method="inclusive")[q - 1]

    def line(self, what: str) -> str:
        if not self.latencies:
            return f"  {what}: no answers; errors {len(self.errors)}"
        n = len(self.latencies)
        return (f"  {what}: {n} answers ({self.refused} '422: the analysis says no', "
                f"{self.hits} from the cache or shared); "
                f"latency p50 {1000 * self.p(50):.1f} ms   p95 {1000 * self.p(95):.1f} ms   "
                f"max {1000 * max(self.latencies):.1f} ms; errors {len(self.errors)}; "
                f"throughput {n / self.wall:.1f} requests/s")


class Client:
    """A minimal HTTP/1.1 keep-alive client on one connection: a load generator that costs a few
    tens of microseconds a request (an httpx client costs about 1.5 ms of CPU a request, and on
    2 cores the client's CPU is taken from the server's). Only what this service answers:
    ``Content-Length`` bodies."""

    def __init__(self, base: str):
        host, port = base.removeprefix("http://").split(":")
        self.host, self.port = host, int(port)
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None

    async def open(self) -> None:
        self.reader, self.writer = await asyncio.open_connection(self.host, self.port)

    async def post(self, path: str, body: bytes, timeout: float = 120) -> tuple[int, dict[str, str], bytes]:
        return await asyncio.wait_for(self._request("POST", path, body), timeout)

    async def get(self, path: str, timeout: float = 120) -> tuple[int, dict[str, str], bytes]:
        return await asyncio.wait_for(self._request("GET", path, b""), timeout)

    async def _request(self, method: str, path: str, body: bytes) -> tuple[int, dict[str, str], bytes]:
        if self.writer is None:
            await self.open()
        assert self.reader is not None and self.writer is not None
        head = (f"{method} {path} HTTP/1.1\r\nHost: {self.host}\r\nContent-Type: application/json\r\n"
                f"Content-Length: {len(body)}\r\n\r\n")
        self.writer.write(head.encode() + body)
        await self.writer.drain()
        status = int((await self.reader.readline()).split()[1])
        headers: dict[str, str] = {}
        while (line := await self.reader.readline()) not in (b"\r\n", b""):
            k, _, v = line.decode("latin-1").partition(":")
            headers[k.strip().lower()] = v.strip()
        data = await self.reader.readexactly(int(headers.get("content-length", "0")))
        if headers.get("connection", "").lower() == "close":
            await self.close()
        return status, headers, data

    async def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            with contextlib.suppress(OSError):
                await self.writer.wait_closed()
        self.reader = self.writer = None


async def _send(c: Client, body: dict[str, Any], run: Run) -> None:
    raw = json.dumps(body).encode()
    t0 = time.perf_counter()
    try:
        status, headers, data = await c.post("/analyses", raw)
    except (OSError, ValueError, IndexError, asyncio.IncompleteReadError, TimeoutError) as e:
        run.errors.append(f"{type(e).__name__}: {e}")
        await c.close()
        return
    dt = time.perf_counter() - t0
    refused = status == 422 and json.loads(data).get("errors", [{}])[0].get("type") == "analysis"
    if status == 200 or refused:
        run.latencies.append(dt)
        run.refused += refused
        run.hits += headers.get("x-cache") in ("hit", "shared")  # shared: an identical request's answer
    else:
        run.errors.append(f"{status}: {data[:200].decode(errors='replace')}")


async def clients_run(base: str, bodies: list[list[dict[str, Any]]]) -> Run:
    """One client (one connection) per list of bodies, each sending its bodies in turn; the
    connections are opened before the clock starts."""
    run = Run()
    clients = [Client(base) for _ in bodies]
    await asyncio.gather(*(c.open() for c in clients))

    async def client(c: Client, mine: list[dict[str, Any]]) -> None:
        for body in mine:
            await _send(c, body, run)

    try:
        t0 = time.perf_counter()
        await asyncio.gather(*(client(c, b) for c, b in zip(clients, bodies, strict=True)))
        run.wall = time.perf_counter() - t0
    finally:
        for c in clients:
            await c.close()
    return run


async def mixed(base: str, light: list[list[dict[str, Any]]], heavy_scene: dict[str, Any], tag: str,
                heavy_clients: int = 2) -> tuple[Run, Run]:
    """The light clients' run while ``heavy_clients`` send tables until the light ones are done
    (each heavy client at most 100 tables)."""
    heavy = Run()
    stop = asyncio.Event()

    async def heavy_client(k: int) -> None:
        c = Client(base)
        try:
            for i in range(100):
                if stop.is_set():
                    return
                scene = {**copy.deepcopy(heavy_scene), "name": f"heavy-{tag}-{k}-{i}"}  # never a cache hit
                await _send(c, {"scene": scene}, heavy)
        finally:
            await c.close()

    t0 = time.perf_counter()
    tasks = [asyncio.create_task(heavy_client(k)) for k in range(heavy_clients)]
    await asyncio.sleep(0.5)  # both heavy requests are running when the light ones start
    run = await clients_run(base, light)
    stop.set()
    await asyncio.gather(*tasks)
    heavy.wall = time.perf_counter() - t0
    return run, heavy


async def bodies_run(base: str, posts: list[tuple[str, bytes]], rounds: int = 5) -> tuple[Run, Run, list[int]]:
    """Each of ``posts`` from its own client ``rounds`` times while one client polls /health every
    20 ms: (the posts' run, the health run, the posts' status codes)."""
    sent, health, codes = Run(), Run(), []
    done = asyncio.Event()

    async def poster(path: str, body: bytes) -> None:
        c = Client(base)
        try:
            for _ in range(rounds):
                t0 = time.perf_counter()
                status, _, data = await c.post(path, body)
                sent.latencies.append(time.perf_counter() - t0)
                codes.append(status)
                if status not in (413, 422):
                    sent.errors.append(f"{status}: {data[:200].decode(errors='replace')}")
        finally:
            await c.close()

    async def poller() -> None:
        c = Client(base)
        try:
            while not done.is_set():
                t0 = time.perf_counter()
                status, _, data = await c.get("/health")
                health.latencies.append(time.perf_counter() - t0)
                if status != 200:
                    health.errors.append(f"{status}: {data[:200].decode(errors='replace')}")
                await asyncio.sleep(0.02)
        finally:
            await c.close()

    t0 = time.perf_counter()
    polling = asyncio.create_task(poller())
    await asyncio.gather(*(poster(p, b) for p, b in posts))
    done.set()
    await polling
    sent.wall = health.wall = time.perf_counter() - t0
    return sent, health, codes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", choices=("all", "report", "mixed", "mixed-repeat", "cached", "bodies"),
                    default="all")
    ap.add_argument("--requests", type=int, default=200, help="report: requests in all")
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--requests-per-client", type=int, default=10, help="mixed, cached")
    ap.add_argument("--workers", type=int, default=2, help="analysis (heavy lane) worker processes of the server")
    ap.add_argument("--light-workers", type=int, default=2, help="light lane worker processes of the server")
    ap.add_argument("--table", action="store_true", help="report: request the table of all combinations")
    ap.add_argument("--samples", type=int, default=None,
                    help="mixed, mixed-repeat: the light requests' 'samples' (DAFC directions; default: the server's)")
    args = ap.parse_args()
    quick = {"samples": args.samples} if args.samples else {}
    planar = json.loads((ROOT / "examples" / "planar_disk_envelope.json").read_text())
    palm = json.loads((ROOT / "examples" / "sphere_four_finger_palm.json").read_text())
    C, R = args.clients, args.requests_per_client
    load_before = " ".join(f"{x:.2f}" for x in os.getloadavg())
    missed: list[str] = []
    out: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        proc = start(port, args.workers, args.light_workers, Path(tmp))
        try:
            base = f"http://127.0.0.1:{port}"
            table = httpx.post(f"{base}/analyses", json={"scene": planar}, timeout=120)  # warm-up
            table.raise_for_status()
            combos = [r["combination"] for r in table.json()["combinations"]]
            feasible = [r["combination"] for r in table.json()["combinations"] if r["feasible"]]
            for scenario, pool in (("mixed", combos), ("mixed-repeat", combos[::12][:20])):
                if args.scenario not in ("all", scenario):
                    continue
                own = {**planar, "name": f"planar-{scenario}"}  # no answer cached by another scenario
                light = [[{"scene": own, "combination": pool[(k * R + j) % len(pool)], **quick} for j in range(R)]
                         for k in range(C)]
                cpu0, server0 = light_workers_cpu(proc.pid), cpu_seconds(proc.pid)
                load = Load(proc.pid)
                run, heavy = asyncio.run(mixed(f"{base}", light, palm, scenario))
                load_line = load.line()
                work_ms = 1000 * (light_workers_cpu(proc.pid) - cpu0) / max(1, len(run.latencies))
                server_ms = 1000 * (cpu_seconds(proc.pid) - server0) / max(1, len(run.latencies) + len(heavy.latencies))
                which = "all different, none cached" if pool is combos else f"drawn from {len(pool)}"
                which += f", samples {args.samples}" if args.samples else ", default samples"
                out.append(f"{scenario}: {C} clients x {R} light POST /analyses (one combination each, {which}) "
                           "while 2 clients send tables of every combination (sphere_four_finger_palm, 243 "
                           f"combinations, never cached); {args.light_workers} light + {args.workers} heavy workers")
                out.append(run.line("light"))
                out.append(f"    light workers' CPU {work_ms:.1f} ms a light request (server {server_ms:.1f} ms a "
                           f"request): with {C} clients always "
                           f"waiting on {args.light_workers} workers, the mean latency cannot be below "
                           f"{C * work_ms / args.light_workers:.0f} ms (Little's law)")
                out.append(heavy.line("heavy"))
                out.append(load_line)
                if run.errors or not run.latencies or run.p(95) >= LIGHT_P95_TARGET:
                    missed.append(f"{scenario}: light p95 {1000 * run.p(95):.0f} ms (target < "
                                  f"{1000 * LIGHT_P95_TARGET:.0f}), {len(run.errors)} errors")
                out.extend(f"    {e[:160]}" for e in run.errors[:5])
                out.extend(f"    heavy: {e[:160]}" for e in heavy.errors[:2])
            if args.scenario in ("all", "cached"):
                own = {**planar, "name": "planar-cached"}
                distinct = [{"scene": own, "combination": c} for c in (feasible + combos)[:20]]
                warm = asyncio.run(clients_run(base, [distinct]))  # computed once: the cache holds them
                bodies = [[distinct[(k + j) % len(distinct)] for j in range(R)] for k in range(C)]
                cpu0 = cpu_seconds(proc.pid)
                load = Load(proc.pid)
                run = asyncio.run(clients_run(base, bodies))
                load_line = load.line()
                server_ms = 1000 * (cpu_seconds(proc.pid) - cpu0) / max(1, len(run.latencies))
                out.append(f"cached: {C} clients x {R} POST /analyses, each repeating one of {len(distinct)} "
                           f"analyses made before (warm-up: {len(warm.latencies)} answers); server CPU "
                           f"{server_ms:.2f} ms a request")
                out.append(run.line("repeats"))
                out.append(load_line)
                if run.errors or not run.latencies or run.p(95) >= CACHED_P95_TARGET or run.hits < len(run.latencies):
                    missed.append(f"cached: p95 {1000 * run.p(95):.1f} ms (target < {1000 * CACHED_P95_TARGET:.0f}), "
                                  f"{run.hits} hits of {len(run.latencies)}, {len(run.errors)} errors")
            if args.scenario in ("all", "bodies"):
                big = copy.deepcopy(planar)
                big["contacts"] = [dict(planar["contacts"][0]) for _ in range(8900)]
                table_body = json.dumps({"scene": big}).encode()
                wrong = json.dumps({"scene": big, "combination": "FDFDD"}).encode()
                posts = [("/analyses", table_body), ("/analyses", table_body), ("/analyses", wrong),
                         ("/enumerations", table_body)]
                load = Load(proc.pid)
                sent, health, codes = asyncio.run(bodies_run(base, posts))
                out.append(f"bodies: 4 clients x 5 bodies of {len(table_body) / 1e6:.2f} MB (8,900 contacts: tables, "
                           "an enumeration, a combination of 5 letters) while one client asks GET /health every "
                           f"20 ms; answers {sorted(set(codes))}")
                out.append(sent.line("bodies"))
                out.append(health.line("health"))
                out.append(load.line())
                worst = max(health.latencies, default=float("inf"))
                if sent.errors or health.errors or worst >= HEALTH_MAX_TARGET:
                    missed.append(f"bodies: slowest /health {1000 * worst:.0f} ms (target < "
                                  f"{1000 * HEALTH_MAX_TARGET:.0f}), {len(sent.errors) + len(health.errors)} errors")
                out.extend(f"    {e[:160]}" for e in (sent.errors + health.errors)[:5])
            if args.scenario in ("all", "report"):
                combo = feasible[0]
                own = {**planar, "name": "planar-report"}
                body: dict[str, Any] = {"scene": own} if args.table else {"scene": own, "combination": combo}
                n, c = args.requests, args.clients
                bodies = [[body] * (n // c + (1 if k < n % c else 0)) for k in range(c)]
                run = asyncio.run(clients_run(base, bodies))
                what = "table of 243 combinations" if args.table else f"full report of the feasible combination {combo}"
                out.append(f"report: {n} POST /analyses ({what}, planar_disk_envelope), {c} concurrent clients "
                           "(the same request: cache hits after the first)")
                out.append(run.line("report"))
                if run.errors:
                    missed.append(f"report: {len(run.errors)} errors")
        finally:
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(30)
    print(f"service load test, loopback; load average before: {load_before}")
    for line in out:
        print(line)
    print(f"  machine: {machine()}")
    for m in missed:
        print(f"  MISSED {m}")
    if missed:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
