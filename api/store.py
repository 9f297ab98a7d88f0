"""The job store: one table of jobs in SQLite (default, a file) or PostgreSQL, via SQLAlchemy Core.

A job is accepted by ``submit`` (committed before the HTTP 202 is sent, so nothing accepted is
lost), claimed by a runner with a lease (``claim``), kept alive by heartbeats, and finished once.
A runner that dies (server killed) stops heart-beating; after ``lease`` seconds any runner,
including the restarted server, claims the job again (``attempts`` counts the tries).
"""

from __future__ import annotations

import json
import time
import uuid
from dataclasses import dataclass
from typing import Any, Literal

from sqlalchemy import (
    Column,
    Float,
    Integer,
    MetaData,
    String,
    Table,
    Text,
    and_,
    create_engine,
    event,
    func,
    or_,
    select,
    update,
)
from sqlalchemy.engine import Engine

Status = Literal["queued", "running", "succeeded", "failed", "cancelled"]
FINAL: frozenset[str] = frozenset({"succeeded", "failed", "cancelled"})

metadata = MetaData()
jobs = Table(
    "jobs",
    metadata,
    Column("id", String(36), primary_key=True),
    Column("kind", String(32), nullable=False, index=True),
    Column("status", String(16), nullable=False, index=True),
    Column("request", Text, nullable=False),
    Column("result", Text),
    Column("error", Text),
    Column("progress", Float, nullable=False, default=0.0),
    Column("message", Text, nullable=False, default=""),
    Column("created_at", Float, nullable=False),
    Column("started_at", Float),
    Column("finished_at", Float),
    Column("heartbeat_at", Float),
    Column("owner", String(64)),
    Column("attempts", Integer, nullable=False, default=0),
    Column("cancel_requested", Integer, nullable=False, default=0),
)


@dataclass(frozen=True)
class Job:
    id: str
    kind: str
    status: str
    request: dict[str, Any]
    progress: float
    message: str
    error: str | None
    created_at: float
    started_at: float | None
    finished_at: float | None
    attempts: int
    cancel_requested: bool
    has_result: bool

    @property
    def elapsed(self) -> float | None:
        if self.started_at is None:
            return None
        return (self.finished_at or time.time()) - self.started_at


_SUMMARY_COLS = [c for c in jobs.c if c.name != "result"]


def _row_to_job(row: Any) -> Job:
    m = row._mapping
    return Job(
        id=m["id"], kind=m["kind"], status=m["status"], request=json.loads(m["request"]),
        progress=float(m["progress"] or 0.0), message=m["message"] or "", error=m["error"],
        created_at=m["created_at"], started_at=m["started_at"], finished_at=m["finished_at"],
        attempts=int(m["attempts"] or 0), cancel_requested=bool(m["cancel_requested"]),
        has_result=bool(m["has_result"]),
    )


def make_engine(url: str) -> Engine:
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30})

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn: Any, _record: Any) -> None:  # WAL: readers never block the writer
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=NORMAL")
            cur.close()

        return engine
    return create_engine(url, pool_pre_ping=True)


class JobStore:
    def __init__(self, url: str):
        self.url = url
        self.engine = make_engine(url)
        metadata.create_all(self.engine)

    def close(self) -> None:
        self.engine.dispose()

    # -- writes --------------------------------------------------------------------------------

    def submit(self, kind: str, request: dict[str, Any]) -> Job:
        job_id = uuid.uuid4().hex
        with self.engine.begin() as c:
            c.execute(jobs.insert().values(
                id=job_id, kind=kind, status="queued", request=json.dumps(request), progress=0.0, message="queued",
                created_at=time.time(), attempts=0, cancel_requested=0))
        job = self.get(job_id)
        assert job is not None
        return job

    def claim(self, owner: str, lease: float, max_attempts: int, kinds: tuple[str, ...] | None = None) -> Job | None:
        """Take the oldest queued job, or a running one whose owner stopped heart-beating."""
        now = time.time()
        stale = and_(jobs.c.status == "running", jobs.c.heartbeat_at < now - lease)
        cond = or_(jobs.c.status == "queued", stale)
        if kinds:
            cond = and_(cond, jobs.c.kind.in_(kinds))
        with self.engine.begin() as c:
            for _ in range(5):  # another runner may win the race for a row; try the next one
                row = c.execute(select(jobs.c.id, jobs.c.status, jobs.c.attempts, jobs.c.cancel_requested)
                                .where(cond).order_by(jobs.c.created_at).limit(1)).first()
                if row is None:
                    return None
                job_id, status, attempts, cancel = row
                if cancel:
                    c.execute(update(jobs).where(jobs.c.id == job_id).values(
                        status="cancelled", finished_at=now, message="cancelled"))
                    continue
                if attempts >= max_attempts:
                    c.execute(update(jobs).where(jobs.c.id == job_id).values(
                        status="failed", finished_at=now, message="failed",
                        error=f"interrupted {attempts} times (worker or server stopped); giving up"))
                    continue
                res = c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.status == status,
                                                        jobs.c.attempts == attempts)).values(
                    status="running", owner=owner, heartbeat_at=now, attempts=attempts + 1,
                    started_at=func.coalesce(jobs.c.started_at, now), progress=0.0,
                    message="started" if status == "queued" else f"resumed (attempt {attempts + 1})"))
                if res.rowcount == 1:
                    break
            else:
                return None
        return self.get(job_id)

    def heartbeat(self, owner: str, job_ids: list[str]) -> None:
        if not job_ids:
            return
        with self.engine.begin() as c:
            c.execute(update(jobs).where(and_(jobs.c.id.in_(job_ids), jobs.c.owner == owner,
                                              jobs.c.status == "running")).values(heartbeat_at=time.time()))

    def set_progress(self, owner: str, job_id: str, progress: float, message: str) -> None:
        with self.engine.begin() as c:
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.owner == owner,
                                              jobs.c.status == "running")).values(
                progress=max(0.0, min(1.0, progress)), message=message[:500], heartbeat_at=time.time()))

    def finish(self, owner: str, job_id: str, status: Status, *, result: dict[str, Any] | None = None,
               error: str | None = None) -> bool:
        """Final state of a job this runner owns; False when it was taken over or cancelled."""
        values: dict[str, Any] = {"status": status, "finished_at": time.time(), "error": error,
                                  "message": status}
        if status == "succeeded":
            values["progress"] = 1.0
            values["result"] = json.dumps(result)
        with self.engine.begin() as c:
            res = c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.owner == owner,
                                                    jobs.c.status == "running")).values(**values))
            return bool(res.rowcount == 1)

    def requeue(self, owner: str, job_id: str, message: str, refund: bool = False) -> None:
        """Back to the queue; ``refund``: the interruption was not the job's (a graceful server
        stop), so it does not count as an attempt."""
        values: dict[str, Any] = {"status": "queued", "owner": None, "message": message}
        if refund:
            values["attempts"] = jobs.c.attempts - 1
        with self.engine.begin() as c:
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.owner == owner,
                                              jobs.c.status == "running")).values(**values))

    def cancel(self, job_id: str) -> Job | None:
        """Queued: cancelled at once. Running: flagged; the runner stops the worker and marks it."""
        now = time.time()
        with self.engine.begin() as c:
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.status == "queued")).values(
                status="cancelled", finished_at=now, message="cancelled", cancel_requested=1))
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.status == "running")).values(
                cancel_requested=1, message="cancelling"))
        return self.get(job_id)

    def mark_cancelled(self, owner: str, job_id: str) -> None:
        with self.engine.begin() as c:
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.owner == owner,
                                              jobs.c.status == "running")).values(
                status="cancelled", finished_at=time.time(), message="cancelled"))

    # -- reads ---------------------------------------------------------------------------------

    def _select(self) -> Any:
        return select(*_SUMMARY_COLS, (jobs.c.result.is_not(None)).label("has_result"))

    def get(self, job_id: str) -> Job | None:
        with self.engine.connect() as c:
            row = c.execute(self._select().where(jobs.c.id == job_id)).first()
        return None if row is None else _row_to_job(row)

    def result(self, job_id: str) -> dict[str, Any] | None:
        with self.engine.connect() as c:
            text = c.execute(select(jobs.c.result).where(jobs.c.id == job_id)).scalar()
        return None if text is None else json.loads(text)

    def list_jobs(self, kind: str | None = None, status: str | None = None, limit: int = 100,
             offset: int = 0) -> list[Job]:
        q = self._select()
        if kind:
            q = q.where(jobs.c.kind == kind)
        if status:
            q = q.where(jobs.c.status == status)
        q = q.order_by(jobs.c.created_at.desc()).limit(limit).offset(offset)
        with self.engine.connect() as c:
            return [_row_to_job(r) for r in c.execute(q)]

    def cancel_requested(self, job_ids: list[str]) -> list[str]:
        if not job_ids:
            return []
        with self.engine.connect() as c:
            rows = c.execute(select(jobs.c.id).where(and_(jobs.c.id.in_(job_ids), jobs.c.cancel_requested == 1)))
            return [r[0] for r in rows]

    def counts(self) -> dict[str, int]:
        with self.engine.connect() as c:
            rows = c.execute(select(jobs.c.status, func.count()).group_by(jobs.c.status))
            return {r[0]: int(r[1]) for r in rows}
