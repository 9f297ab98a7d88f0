"""The job store's contract, on SQLite (always) and PostgreSQL (when ``CTP_TEST_POSTGRES_URL``
names a database, e.g. ``postgresql+psycopg://ctp:ctp@127.0.0.1/ctp_test``; see conftest)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from sqlalchemy import Column, Float, Integer, MetaData, String, Table, Text, create_engine, inspect

from api.store import JobStore


@pytest.fixture
def store(store_url: str) -> Iterator[JobStore]:
    s = JobStore(store_url)
    yield s
    s.close()


def test_submit_claim_finish(store: JobStore) -> None:
    a = store.submit("enumeration", {"scene": {"name": "a"}})
    time.sleep(0.01)
    b = store.submit("plan", {"scene": {"name": "b"}})
    assert a.status == b.status == "queued" and a.request == {"scene": {"name": "a"}}
    assert store.get(a.id) == a  # what submit returned is what was stored
    got = store.claim("r1", lease=30, max_attempts=3)
    assert got is not None and got.id == a.id and got.status == "running" and got.attempts == 1  # oldest first
    assert store.claim("r2", lease=30, max_attempts=3).id == b.id  # type: ignore[union-attr]
    assert store.claim("r2", lease=30, max_attempts=3) is None  # nothing left; a's lease is fresh
    store.set_progress("r1", a.id, 0.5, "half")
    assert store.get(a.id).progress == 0.5  # type: ignore[union-attr]
    store.heartbeat("r1", [a.id], {a.id: (0.75, "three quarters")})
    assert (store.get(a.id).progress, store.get(a.id).message) == (0.75, "three quarters")  # type: ignore[union-attr]
    store.heartbeat("r2", [a.id], {a.id: (0.9, "not mine")})  # another owner's write changes nothing
    assert store.get(a.id).progress == 0.75  # type: ignore[union-attr]
    assert not store.finish("r2", a.id, "succeeded", result={"x": 1})  # not the owner
    assert store.finish("r1", a.id, "succeeded", result={"x": 1})
    done = store.get(a.id)
    assert done is not None and done.status == "succeeded" and done.progress == 1.0 and done.has_result
    assert store.result(a.id) == {"x": 1}
    assert store.finish("r2", b.id, "failed", error="analysis: no stationary grasp")
    assert store.get(b.id).error == "analysis: no stationary grasp"  # type: ignore[union-attr]
    assert [j.id for j in store.list_jobs()] == [b.id, a.id]
    assert [j.id for j in store.list_jobs(kind="plan")] == [b.id]
    assert store.counts() == {"succeeded": 1, "failed": 1}


def test_stale_lease_is_taken_over_and_attempts_are_bounded(store: JobStore) -> None:
    a = store.submit("enumeration", {})
    assert store.claim("dead", lease=0.2, max_attempts=2) is not None
    assert store.claim("r2", lease=0.2, max_attempts=2) is None  # still leased
    time.sleep(0.3)
    again = store.claim("r2", lease=0.2, max_attempts=2)
    assert again is not None and again.id == a.id and again.attempts == 2
    assert not store.finish("dead", a.id, "succeeded", result={})  # the old owner lost it
    time.sleep(0.3)
    assert store.claim("r3", lease=0.2, max_attempts=2) is None  # out of attempts: failed
    failed = store.get(a.id)
    assert failed is not None and failed.status == "failed" and "interrupted 2 times" in (failed.error or "")


def test_claim_skips_own_jobs_and_can_leave_stale_ones(store: JobStore) -> None:
    a = store.submit("plan", {})
    assert store.claim("r1", lease=0.1, max_attempts=3) is not None
    time.sleep(0.2)  # stale now
    assert store.claim("r1", lease=0.1, max_attempts=3, exclude=[a.id]) is None  # r1 still runs it
    assert store.claim("r2", lease=0.1, max_attempts=3, take_over=False) is None  # after an outage: wait
    taken = store.claim("r2", lease=0.1, max_attempts=3)
    assert taken is not None and taken.id == a.id and taken.attempts == 2


def test_used_time_adds_up_over_attempts(store: JobStore) -> None:
    """A job's time limit is a total: each attempt's running time is kept in ``used_seconds``."""
    a = store.submit("plan", {})
    t0 = time.time()
    assert store.claim("r1", lease=30, max_attempts=5).used_seconds == 0.0  # type: ignore[union-attr]
    time.sleep(0.3)
    store.requeue("r1", a.id, "worker crash")  # ran 0.3 s
    t1 = time.time()
    second = store.claim("r1", lease=0.2, max_attempts=5)
    assert second is not None and 0.3 <= second.used_seconds <= t1 - t0, second
    time.sleep(0.15)
    store.heartbeat("r1", [a.id])  # alive until here (0.15 s more), then killed
    t2 = time.time()
    time.sleep(0.5)  # not counted: nobody worked on it after the last heartbeat
    third = store.claim("r2", lease=0.2, max_attempts=5)  # taken over: counts up to the last heartbeat
    assert third is not None and third.attempts == 3
    assert second.used_seconds + 0.15 <= third.used_seconds <= second.used_seconds + (t2 - t1), third
    time.sleep(0.1)
    assert store.finish("r2", a.id, "succeeded", result={})
    assert store.get(a.id).used_seconds >= third.used_seconds + 0.1  # type: ignore[union-attr]


def test_cancel(store: JobStore) -> None:
    q = store.submit("plan", {})
    assert store.cancel(q.id).status == "cancelled"  # type: ignore[union-attr]
    r = store.submit("plan", {})
    assert store.claim("r1", lease=30, max_attempts=3) is not None
    flagged = store.cancel(r.id)
    assert flagged is not None and flagged.status == "running" and flagged.cancel_requested
    assert set(store.cancel_requested([r.id, q.id])) == {r.id, q.id}  # flags stay on cancelled jobs
    store.mark_cancelled("r1", r.id)
    assert store.get(r.id).status == "cancelled"  # type: ignore[union-attr]
    assert store.claim("r1", lease=30, max_attempts=3) is None


def test_a_store_made_before_the_time_columns_is_migrated(store_url: str) -> None:
    """Stores made by the first release have no ``attempt_started_at``/``used_seconds``: added on open."""
    old = MetaData()
    Table("jobs", old, Column("id", String(36), primary_key=True), Column("kind", String(32), nullable=False),
          Column("status", String(16), nullable=False), Column("request", Text, nullable=False),
          Column("result", Text), Column("error", Text), Column("progress", Float, nullable=False),
          Column("message", Text, nullable=False), Column("created_at", Float, nullable=False),
          Column("started_at", Float), Column("finished_at", Float), Column("heartbeat_at", Float),
          Column("owner", String(64)), Column("attempts", Integer, nullable=False),
          Column("cancel_requested", Integer, nullable=False))
    engine = create_engine(store_url)
    old.create_all(engine)
    with engine.begin() as c:
        c.execute(old.tables["jobs"].insert().values(id="old", kind="plan", status="queued", request="{}",
                                                      progress=0.0, message="queued", created_at=1.0, attempts=0,
                                                      cancel_requested=0))
    s = JobStore(store_url)
    try:
        with s.engine.connect() as c:
            assert {"attempt_started_at", "used_seconds"} <= {col["name"] for col in inspect(c).get_columns("jobs")}
        job = s.claim("r1", lease=30, max_attempts=3)
        assert job is not None and job.id == "old" and job.used_seconds == 0.0
        assert s.finish("r1", "old", "succeeded", result={"ok": True}) and s.result("old") == {"ok": True}
    finally:
        s.close()
        engine.dispose()
