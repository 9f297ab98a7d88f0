"""Fault injection on the job store (run by ``make test``): a damaged SQLite file (valid header,
garbage pages), a database locked by another process, a PostgreSQL server that cannot be reached,
and a full disk (a store that raises). Every route that needs the store answers JSON 503 with
``Retry-After`` and ``"store": "unavailable"`` (never a 500, never text, never SQL, a driver's
message or a URL); the job runner retries its writes, so no job fails because the store was away;
a job's time limit is a total over its attempts."""

from __future__ import annotations

import asyncio
import copy
import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from service_helpers import example, free_port, settings_for, wait_for
from store_faults import (
    FaultyStore,
    PostgresOutage,
    assert_no_leak,
    assert_store_503,
    damage_sqlite,
    sqlite_locked,
)

from api.jobs import JobRunner
from api.main import create_app
from api.store import JobStore
from api.workers import TaskTimeout

PLANAR = example("planar_disk_envelope")
PLAN = {"scene": PLANAR, "goal": {"type": "active"}}


def _store_routes(c: TestClient) -> list[Any]:
    """One request of each kind to every route that reads or writes the store."""
    return [c.get("/health"), c.get("/plans"), c.post("/plans", json=PLAN), c.get("/plans/abc"),
            c.get("/plans/abc/result"), c.delete("/plans/abc"), c.get("/enumerations"),
            c.post("/enumerations", json={"scene": PLANAR}), c.get("/enumerations/abc"),
            c.delete("/enumerations/abc")]


@pytest.mark.parametrize("keep", [100, 4096], ids=["header-only", "first-page"])
def test_a_damaged_sqlite_file_is_503_on_every_route(tmp_path: Path, keep: int) -> None:
    db = tmp_path / "jobs.db"
    store = JobStore(f"sqlite:///{db}")
    for i in range(40):
        store.submit("plan", {"i": i, "pad": "x" * 200})
    store.close()
    damage_sqlite(db, keep)
    with TestClient(create_app(settings_for(tmp_path, store_retry_after_seconds=7))) as c:  # the server starts
        for r in _store_routes(c):
            assert_store_503(r, "damaged")
            assert r.headers["retry-after"] == "7"
        health = c.get("/health").json()
        assert health["status"] == "unavailable" and health["database"] == "sqlite"
        assert c.get("/").status_code == 200  # what needs no store still works


def test_an_unreachable_postgresql_is_503_on_every_route_and_shows_no_url(tmp_path: Path) -> None:
    url = f"postgresql+psycopg://ctp:secret@127.0.0.1:{free_port()}/nowhere"  # nothing listens there
    with TestClient(create_app(settings_for(tmp_path, database_url=url, store_timeout_seconds=1.0))) as c:
        for r in _store_routes(c):
            assert_store_503(r, "unreachable")
            assert "nowhere" not in r.text and "127.0.0.1" not in r.text
        assert c.get("/health").json()["database"] == "postgresql"


def test_a_sqlite_lock_is_503_for_writes_and_health_then_gone(tmp_path: Path) -> None:
    db = tmp_path / "jobs.db"
    settings = settings_for(tmp_path, store_timeout_seconds=0.5, run_jobs=False)
    with TestClient(create_app(settings)) as c:
        before = c.post("/plans", json=PLAN)
        assert before.status_code == 202
        with sqlite_locked(db):
            t0 = time.monotonic()
            r = c.post("/plans", json=PLAN)
            assert time.monotonic() - t0 < 5  # the store's timeout, not 30 s
            assert_store_503(r, "locked")
            assert_store_503(c.delete(before.json()["url"]), "locked")
            assert_store_503(c.get("/health"), "locked")
            # WAL: readers read the last committed state meanwhile
            assert c.get(before.json()["url"]).json()["status"] == "queued"
            assert c.get("/plans").json()["count"] == 1
        assert c.post("/plans", json=PLAN).status_code == 202
        assert c.get("/health").status_code == 200 and c.get("/health").json()["store"] == "ok"
        assert c.get("/plans").json()["count"] == 2  # the refused request stored nothing


def test_a_postgresql_table_lock_is_503_after_the_timeout(tmp_path: Path, pg_store_url: str) -> None:
    """Another session holds the jobs table (LOCK TABLE): statements give up after the store's
    timeout (lock_timeout) and answer 503 "locked"; once it lets go, the same requests work."""
    from sqlalchemy import create_engine, text

    settings = settings_for(tmp_path, database_url=pg_store_url, store_timeout_seconds=1.0, run_jobs=False)
    with TestClient(create_app(settings)) as c:
        assert c.post("/plans", json=PLAN).status_code == 202
        other = create_engine(pg_store_url)
        try:
            with other.begin() as conn:
                conn.execute(text("LOCK TABLE jobs IN ACCESS EXCLUSIVE MODE"))
                t0 = time.monotonic()
                for r in (c.post("/plans", json=PLAN), c.get("/plans"), c.get("/health")):
                    assert_store_503(r, "locked")
                assert time.monotonic() - t0 < 10
        finally:
            other.dispose()
        assert c.get("/plans").json()["count"] == 1
        assert c.post("/plans", json=PLAN).status_code == 202 and c.get("/health").status_code == 200


def test_a_postgresql_away_at_start_up_is_used_once_it_is_back(tmp_path: Path, pg_store_url: str) -> None:
    """The server starts while PostgreSQL is away (here: the proxy in front of it is cut), answers
    503, and makes its table and runs jobs as soon as the server is reachable: no restart."""
    pg = PostgresOutage(pg_store_url, None)
    pg.stop()
    try:
        settings = settings_for(tmp_path, database_url=pg.url, store_timeout_seconds=1.0)
        with TestClient(create_app(settings)) as c:
            assert_store_503(c.get("/health"), "unreachable")
            assert_store_503(c.post("/enumerations", json={"scene": PLANAR}), "unreachable")
            pg.start()
            r = c.post("/enumerations", json={"scene": PLANAR})
            assert r.status_code == 202, r.text
            assert wait_for(c, r.json()["url"])["status"] == "succeeded"
            assert c.get("/health").json()["jobs"] == {"succeeded": 1}
    finally:
        pg.stop()


def test_a_full_disk_is_503_for_writes(tmp_path: Path) -> None:
    with TestClient(create_app(settings_for(tmp_path, run_jobs=False))) as c:
        app: Any = c.app
        faulty = FaultyStore(settings_for(tmp_path).database_url)
        app.state.store = faulty
        assert c.post("/plans", json=PLAN).status_code == 202
        faulty.fault = "full"
        assert_store_503(c.post("/plans", json=PLAN), "full")
        assert_store_503(c.get("/health"), "full")
        assert c.get("/plans").json()["count"] == 1
        faulty.fault = "unreachable"  # the driver's error carries SQL, a parameter and a URL
        for r in _store_routes(c):
            assert_store_503(r, "unreachable")
        faulty.fault = None
        assert c.post("/plans", json=PLAN).status_code == 202 and c.get("/plans").json()["count"] == 2


# -- the job runner against a store that comes and goes (a fake executor: no processes) -------


class FakeExecutor:
    """Runs a job as ``steps`` sleeps of ``step`` s with progress after each; honours the timeout."""

    size = 1

    def __init__(self) -> None:
        self.runs: list[tuple[str, float]] = []

    async def run(self, kind: str, payload: dict[str, Any], *, timeout: float, on_progress: Any = None,
                  cancelled: asyncio.Event | None = None) -> dict[str, Any]:
        self.runs.append((payload.get("name", ""), timeout))

        async def work() -> dict[str, Any]:
            steps = int(payload.get("steps", 10))
            for k in range(steps):
                await asyncio.sleep(float(payload.get("step", 0.05)))
                if on_progress is not None:
                    on_progress((k + 1) / steps, f"step {k + 1}")
            if payload.get("boom"):
                raise RuntimeError(payload["boom"])
            return {"name": payload.get("name"), "done": True}

        try:
            return await asyncio.wait_for(work(), timeout)
        except TimeoutError:
            raise TaskTimeout(timeout) from None


def _runner(store: JobStore, executor: FakeExecutor, lease: float = 0.5) -> JobRunner:
    return JobRunner(store, executor, slots=1, lease=lease, poll=0.05, default_time_limit=30.0, max_attempts=2,
                     retry_max=0.2)


async def _until(cond: Any, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        await asyncio.sleep(0.02)


@pytest.mark.parametrize("fault", ["full", "unreachable"])
def test_jobs_survive_a_store_outage_longer_than_the_lease(tmp_path: Path, fault: str) -> None:
    """The store fails for 2 s (four leases) while a job runs and two wait: the running job
    finishes during the outage, its final write is retried; all three end succeeded, once each."""
    store = FaultyStore(f"sqlite:///{tmp_path / 'jobs.db'}")
    ids = [store.submit("plan", {"name": n, "steps": 10, "step": 0.1}).id for n in "abc"]

    async def scenario() -> float:
        runner = _runner(store, FakeExecutor())
        runner.start()
        try:
            await _until(lambda: store.get(ids[0]).status == "running"  # type: ignore[union-attr]
                         and store.get(ids[0]).progress > 0.2, 10)  # type: ignore[union-attr]
            store.fault = fault
            await asyncio.sleep(2.0)
            store.fault = None
            back = time.time()
            await _until(lambda: all(store.get(i).status in ("succeeded", "failed") for i in ids), 20)  # type: ignore[union-attr]
            return back
        finally:
            await runner.stop()

    back = asyncio.run(scenario())
    jobs = [store.get(i) for i in ids]
    for job in jobs:
        assert job is not None and job.status == "succeeded" and job.error is None, job
        assert job.attempts == 1 and job.progress == 1.0, job  # never taken over, never retried
        assert store.result(job.id) == {"name": job.request["name"], "done": True}
    assert jobs[0].finished_at is not None and jobs[0].finished_at >= back  # written after the store returned
    store.close()


def test_an_internal_error_shows_no_details(tmp_path: Path) -> None:
    store = JobStore(f"sqlite:///{tmp_path / 'jobs.db'}")
    job = store.submit("plan", {"steps": 1, "boom": "SELECT * FROM jobs WHERE password = 'secret'"})

    async def scenario() -> None:
        runner = _runner(store, FakeExecutor())
        runner.start()
        try:
            await _until(lambda: store.get(job.id).status == "failed", 10)  # type: ignore[union-attr]
        finally:
            await runner.stop()

    asyncio.run(scenario())
    failed = store.get(job.id)
    assert failed is not None and failed.error is not None and failed.error.startswith("internal error")
    assert "RuntimeError" in failed.error
    assert_no_leak(failed.error)


def test_the_time_limit_is_a_total_over_attempts(tmp_path: Path) -> None:
    """A job limited to 1.5 s whose first attempt ran 1 s before its server died gets 0.5 s more,
    not another 1.5 s; a job that used its whole limit fails at once, without running."""
    store = JobStore(f"sqlite:///{tmp_path / 'jobs.db'}")
    slow = store.submit("plan", {"name": "slow", "steps": 100, "step": 0.1, "time_limit": 1.5})
    assert store.claim("dead", lease=0.3, max_attempts=3) is not None
    time.sleep(1.0)
    store.heartbeat("dead", [slow.id])  # its last sign of life, after 1 s of work
    time.sleep(0.4)  # the lease runs out
    executor = FakeExecutor()

    async def scenario() -> float:
        runner = _runner(store, executor, lease=0.3)
        t0 = time.monotonic()
        runner.start()
        try:
            await _until(lambda: store.get(slow.id).status == "failed", 10)  # type: ignore[union-attr]
            return time.monotonic() - t0
        finally:
            await runner.stop()

    took = asyncio.run(scenario())
    failed = store.get(slow.id)
    assert failed is not None and failed.attempts == 2
    assert failed.error == "time limit: the job was stopped after 1.5 s of work in 2 attempts (time_limit)"
    assert executor.runs and 0 < executor.runs[0][1] < 0.55  # the time left, not the whole limit
    assert took < 1.4
    assert failed.used_seconds >= 1.4

    spent = store.submit("plan", {"name": "spent", "time_limit": 0.5})
    assert store.claim("dead", lease=0.2, max_attempts=3) is not None
    time.sleep(0.6)
    store.heartbeat("dead", [spent.id])
    time.sleep(0.3)
    executor.runs.clear()

    async def again() -> None:
        runner = _runner(store, executor, lease=0.2)
        runner.start()
        try:
            await _until(lambda: store.get(spent.id).status == "failed", 10)  # type: ignore[union-attr]
        finally:
            await runner.stop()

    asyncio.run(again())
    assert executor.runs == []  # never started again
    assert "time limit" in (store.get(spent.id).error or "")  # type: ignore[union-attr]


def test_a_bad_scene_is_not_a_store_error(tmp_path: Path) -> None:
    """The mapping is for store errors only: a bad request is still a 422 while the store is away."""
    with TestClient(create_app(settings_for(tmp_path, run_jobs=False))) as c:
        app: Any = c.app
        faulty = FaultyStore(settings_for(tmp_path).database_url)
        faulty.fault = "unreachable"
        app.state.store = faulty
        bad = copy.deepcopy(PLAN)
        bad["scene"]["contacts"][0]["mu"] = -1
        r = c.post("/plans", json=bad)
        assert r.status_code == 422 and r.json()["detail"].startswith("scene.contacts.0.mu")
