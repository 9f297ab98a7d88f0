"""The job store's contract, on SQLite (always) and PostgreSQL (when ``CTP_TEST_POSTGRES_URL``
names a database, e.g. ``postgresql+psycopg://ctp:ctp@127.0.0.1/ctp_test``)."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from api.store import JobStore, jobs

PG = os.environ.get("CTP_TEST_POSTGRES_URL")


@pytest.fixture(params=["sqlite", "postgresql"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[JobStore]:
    if request.param == "sqlite":
        s = JobStore(f"sqlite:///{tmp_path / 'jobs.db'}")
    else:
        if not PG:
            pytest.skip("set CTP_TEST_POSTGRES_URL=postgresql+psycopg://... to test the store on PostgreSQL")
        s = JobStore(PG)
        with s.engine.begin() as c:
            c.execute(jobs.delete())
    yield s
    s.close()


def test_submit_claim_finish(store: JobStore) -> None:
    a = store.submit("enumeration", {"scene": {"name": "a"}})
    time.sleep(0.01)
    b = store.submit("plan", {"scene": {"name": "b"}})
    assert a.status == b.status == "queued" and a.request == {"scene": {"name": "a"}}
    got = store.claim("r1", lease=30, max_attempts=3)
    assert got is not None and got.id == a.id and got.status == "running" and got.attempts == 1  # oldest first
    assert store.claim("r2", lease=30, max_attempts=3).id == b.id  # type: ignore[union-attr]
    assert store.claim("r2", lease=30, max_attempts=3) is None  # nothing left; a's lease is fresh
    store.set_progress("r1", a.id, 0.5, "half")
    assert store.get(a.id).progress == 0.5  # type: ignore[union-attr]
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
