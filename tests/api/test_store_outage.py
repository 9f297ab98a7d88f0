"""The store goes away while a job runs, on both stores: PostgreSQL is stopped and started again
(``pg_ctlcluster``, or a proxy in front of it when the test may not control the server); SQLite
is held by another process with an exclusive lock. The outage lasts ``CTP_TEST_OUTAGE_SECONDS``
(default 8 s, well over the 3 s lease here; 40 s reproduces issue 13's probe). Every response
that needs the store is JSON 503 with Retry-After meanwhile (on SQLite, reads still see the last
committed state), and every accepted job ends ``succeeded`` after the store returns, once."""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from service_helpers import example, settings_for, wait_for
from store_faults import PostgresOutage, assert_store_503, sqlite_locked

from api.main import create_app

PG_CTL = os.environ.get("CTP_TEST_POSTGRES_CTL")  # .ci/run: how to stop and start its cluster
OUTAGE = float(os.environ.get("CTP_TEST_OUTAGE_SECONDS", "8"))
PALM, PLANAR = example("sphere_four_finger_palm"), example("planar_disk_envelope")


@pytest.mark.slow
def test_jobs_survive_a_store_outage(store_url: str, tmp_path: Path) -> None:
    postgres = store_url.startswith("postgresql")
    pg = PostgresOutage(store_url, PG_CTL) if postgres else None
    url = pg.url if pg is not None else store_url
    settings = settings_for(tmp_path, database_url=url, job_lease_seconds=3.0, store_timeout_seconds=1.0,
                            store_retry_max_seconds=1.0, store_retry_after_seconds=2)
    with TestClient(create_app(settings)) as c:
        urls = []
        for _ in range(3):
            r = c.post("/enumerations", json={"scene": PALM})
            assert r.status_code == 202, r.text
            urls.append(r.json()["url"])
        wait_for(c, urls[0], statuses=("running",))
        during: list[tuple[str, Any]] = []
        began = time.time()
        with contextlib.ExitStack() as outage:
            if pg is not None:
                pg.stop()
                outage.callback(pg.start)
            else:
                outage.enter_context(sqlite_locked(Path(store_url.removeprefix("sqlite:///"))))
            t_end = time.monotonic() + OUTAGE
            while time.monotonic() < t_end:
                during += [("write", c.post("/enumerations", json={"scene": PLANAR})),
                           ("write", c.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}})),
                           ("write", c.delete(urls[2])),  # would cancel a queued job: must not happen
                           ("health", c.get("/health")),
                           ("read", c.get(urls[0])), ("read", c.get("/enumerations"))]
                time.sleep(0.5)
            ending = time.time()  # the lock is released / the server started from here
        assert len(during) >= 6
        for what, r in during:
            if postgres or what != "read":
                assert_store_503(r)
                if what == "health":
                    assert r.json()["status"] == "unavailable"
            else:  # SQLite in WAL mode: readers read the last committed state while a writer holds the lock
                assert r.status_code == 200, r.text
        done = [wait_for(c, u, timeout=120) for u in urls]
        for job in done:
            assert job["status"] == "succeeded" and job["error"] is None, job
            assert job["attempts"] == 1, job  # kept its lease: never taken over, never re-run
            assert c.get(job["result_url"]).status_code == 200
        # the first job ended during the outage: its final state was written once the store was back
        # (finished_at is taken when the write starts, which may wait for the lock up to the store's timeout)
        assert done[0]["finished_at"] >= ending - settings.store_timeout_seconds - 0.2, (done[0], ending)
        assert done[0]["started_at"] < began < done[0]["finished_at"]
        listed = c.get("/enumerations").json()
        assert listed["count"] == 3 and c.get("/plans").json()["count"] == 0  # no refused request was stored
        health = c.get("/health")
        assert health.status_code == 200 and health.json()["store"] == "ok"
