"""The job store: one table of jobs in SQLite (default, a file) or PostgreSQL, via SQLAlchemy Core.

A job is accepted by ``submit`` (committed before the HTTP 202 is sent, so nothing accepted is
lost), claimed by a runner with a lease (``claim``), kept alive by heartbeats, and finished once.
A runner that dies (server killed) stops heart-beating; after ``lease`` seconds any runner,
including the restarted server, claims the job again (``attempts`` counts the tries, and
``used_seconds`` the running time of the attempts before, so a job's time limit is a total).

Every failure of the database itself (unreachable, locked past ``timeout``, damaged pages, disk
full) leaves this module as one exception, :class:`StoreUnavailable`, whose text names only the
kind of failure: never the SQL, its parameters, the driver's message or the URL (those go to the
server log). The HTTP layer answers it with 503 + ``Retry-After``; the job runner retries.
"""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
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
    inspect,
    or_,
    select,
    text,
    update,
)
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.exc import SQLAlchemyError

Status = Literal["queued", "running", "succeeded", "failed", "cancelled"]
FINAL: frozenset[str] = frozenset({"succeeded", "failed", "cancelled"})

log = logging.getLogger("ctp.store")

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
    # added after the first release: stores made before get them by ALTER TABLE (_migrate)
    Column("attempt_started_at", Float),
    Column("used_seconds", Float, nullable=False, default=0.0, server_default="0"),
)
_ADDED = {"attempt_started_at": "FLOAT", "used_seconds": "FLOAT NOT NULL DEFAULT 0"}


class StoreUnavailable(Exception):
    """The job store cannot be used now; ``reason``: unreachable, locked, damaged, full or read-only.
    A state of the database, not of the request or the job: retry later."""

    def __init__(self, reason: str):
        super().__init__(f"the job store is unavailable ({reason})")
        self.reason = reason


def _is_store_error(e: BaseException) -> bool:
    # psycopg's own errors (raised outside SQLAlchemy's wrapping, e.g. in a connect hook) too
    return isinstance(e, SQLAlchemyError | sqlite3.Error | OSError) or type(e).__module__.startswith("psycopg")


def failure_kind(e: BaseException) -> str:
    """What kind of store failure a driver error is (the word shown to users, never its text)."""
    msg = str(getattr(e, "orig", None) or e).lower()
    if "locked" in msg or "lock timeout" in msg or "busy" in msg:
        return "locked"
    if "disk is full" in msg or "disk full" in msg or "no space" in msg or "could not extend file" in msg:
        return "full"
    if "malformed" in msg or "not a database" in msg or "corrupt" in msg or "disk i/o" in msg:
        return "damaged"
    if "readonly" in msg or "read-only" in msg:
        return "read-only"
    return "unreachable"


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
    used_seconds: float = 0.0  # running time of the attempts before this one

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
        has_result=bool(m["has_result"]), used_seconds=float(m["used_seconds"] or 0.0),
    )


def make_engine(url: str, timeout: float = 5.0) -> Engine:
    """``timeout``: how long one statement waits for a lock (SQLite's busy timeout, PostgreSQL's
    lock_timeout) or for a connection (PostgreSQL's connect_timeout) before it fails."""
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": timeout})

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn: Any, _record: Any) -> None:  # WAL: readers never block the writer
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=NORMAL")
            cur.close()

        return engine
    connect_args: dict[str, Any] = {}
    if url.startswith(("postgresql", "postgres")):
        connect_args["connect_timeout"] = max(2, round(timeout))
    engine = create_engine(url, pool_pre_ping=True, connect_args=connect_args)
    if engine.dialect.name == "postgresql":

        @event.listens_for(engine, "connect")
        def _lock_timeout(dbapi_conn: Any, _record: Any) -> None:
            cur = dbapi_conn.cursor()
            cur.execute(f"SET lock_timeout = {int(timeout * 1000)}")
            cur.close()
            dbapi_conn.commit()

    return engine


class JobStore:
    def __init__(self, url: str, timeout: float = 5.0):
        self.url = url
        self.engine = make_engine(url, timeout)
        self._schema_ready = False
        self._schema_lock = threading.Lock()
        self._last_failure: tuple[str, type, float] = ("", type(None), 0.0)
        try:  # a store that is away at start-up is not fatal: the server answers 503 until it is back
            with self._guard():
                self._ensure_schema()
        except StoreUnavailable as e:
            log.warning("job store not ready at start-up: %s", e)

    def close(self) -> None:
        self.engine.dispose()

    @property
    def backend(self) -> str:
        return self.engine.url.get_backend_name()

    # -- the one place database errors are translated ------------------------------------------

    @contextmanager
    def _guard(self) -> Iterator[None]:
        try:
            yield
        except Exception as e:
            if not _is_store_error(e):
                raise
            reason = failure_kind(e)
            now = time.monotonic()
            if (reason, type(e)) != self._last_failure[:2] or now - self._last_failure[2] > 10:
                self._last_failure = (reason, type(e), now)  # one log line per kind of failure a 10 s
                first = (str(getattr(e, "orig", None) or e).strip().splitlines() or [""])[0]
                log.warning("job store %s: %s: %s", reason, type(e).__name__, first[:300])
            raise StoreUnavailable(reason) from None

    def _ensure_schema(self) -> None:
        if self._schema_ready:
            return
        with self._schema_lock:
            if self._schema_ready:
                return
            metadata.create_all(self.engine)
            with self.engine.begin() as c:
                _migrate(c)
            self._schema_ready = True

    @contextmanager
    def _tx(self, write: bool = True) -> Iterator[Connection]:
        """A transaction (``write``) or a read-only connection; store errors -> StoreUnavailable."""
        with self._guard():
            self._ensure_schema()
            with (self.engine.begin() if write else self.engine.connect()) as c:
                yield c

    def ping(self) -> None:
        """Raise StoreUnavailable unless the store answers and can be written: a write that
        changes no row still takes the write lock, so a database held by another process shows."""
        with self._tx() as c:
            c.execute(update(jobs).where(jobs.c.id == "").values(message=""))

    # -- writes --------------------------------------------------------------------------------

    def submit(self, kind: str, request: dict[str, Any]) -> Job:
        job_id, now = uuid.uuid4().hex, time.time()
        with self._tx() as c:
            c.execute(jobs.insert().values(
                id=job_id, kind=kind, status="queued", request=json.dumps(request), progress=0.0, message="queued",
                created_at=now, attempts=0, cancel_requested=0, used_seconds=0.0))
        # built from what was written: a failed read-back must not turn an accepted job into a 503
        return Job(id=job_id, kind=kind, status="queued", request=request, progress=0.0, message="queued",
                   error=None, created_at=now, started_at=None, finished_at=None, attempts=0,
                   cancel_requested=False, has_result=False)

    def claim(self, owner: str, lease: float, max_attempts: int, kinds: tuple[str, ...] | None = None, *,
              exclude: list[str] | tuple[str, ...] = (), take_over: bool = True) -> Job | None:
        """Take the oldest queued job, or (``take_over``) a running one whose owner stopped
        heart-beating; never one of ``exclude`` (the jobs this runner is running)."""
        now = time.time()
        stale = and_(jobs.c.status == "running", jobs.c.heartbeat_at < now - lease)
        cond = or_(jobs.c.status == "queued", stale) if take_over else jobs.c.status == "queued"
        if kinds:
            cond = and_(cond, jobs.c.kind.in_(kinds))
        if exclude:
            cond = and_(cond, jobs.c.id.not_in(list(exclude)))
        with self._tx() as c:
            for _ in range(5):  # another runner may win the race for a row; try the next one
                row = c.execute(select(jobs.c.id, jobs.c.status, jobs.c.attempts, jobs.c.cancel_requested,
                                       jobs.c.used_seconds, jobs.c.heartbeat_at, jobs.c.attempt_started_at)
                                .where(cond).order_by(jobs.c.created_at).limit(1)).first()
                if row is None:
                    return None
                job_id, status, attempts, cancel, used, beat, attempt_start = row
                used = float(used or 0.0)
                if status == "running" and beat is not None and attempt_start is not None:
                    used += max(0.0, beat - attempt_start)  # the dead attempt ran until its last heartbeat
                if cancel:
                    c.execute(update(jobs).where(jobs.c.id == job_id).values(
                        status="cancelled", finished_at=now, message="cancelled", used_seconds=used))
                    continue
                if attempts >= max_attempts:
                    c.execute(update(jobs).where(jobs.c.id == job_id).values(
                        status="failed", finished_at=now, message="failed", used_seconds=used,
                        error=f"interrupted {attempts} times (worker or server stopped); giving up"))
                    continue
                res = c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.status == status,
                                                        jobs.c.attempts == attempts)).values(
                    status="running", owner=owner, heartbeat_at=now, attempts=attempts + 1,
                    started_at=func.coalesce(jobs.c.started_at, now), progress=0.0, attempt_started_at=now,
                    used_seconds=used,
                    message="started" if status == "queued" else f"resumed (attempt {attempts + 1})"))
                if res.rowcount == 1:
                    got = c.execute(self._select().where(jobs.c.id == job_id)).first()
                    return None if got is None else _row_to_job(got)
            return None

    def heartbeat(self, owner: str, job_ids: list[str],
                  progress: dict[str, tuple[float, str]] | None = None) -> None:
        """Keep the leases of ``job_ids``; write the latest ``progress`` (job id -> fraction,
        message) in the same transaction."""
        if not job_ids and not progress:
            return
        now = time.time()
        with self._tx() as c:
            if job_ids:
                c.execute(update(jobs).where(and_(jobs.c.id.in_(job_ids), jobs.c.owner == owner,
                                                  jobs.c.status == "running")).values(heartbeat_at=now))
            for job_id, (frac, message) in (progress or {}).items():
                c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.owner == owner,
                                                  jobs.c.status == "running")).values(
                    progress=max(0.0, min(1.0, frac)), message=message[:500], heartbeat_at=now))

    def set_progress(self, owner: str, job_id: str, progress: float, message: str) -> None:
        self.heartbeat(owner, [], {job_id: (progress, message)})

    def finish(self, owner: str, job_id: str, status: Status, *, result: dict[str, Any] | None = None,
               error: str | None = None) -> bool:
        """Final state of a job this runner owns; False when it was taken over or cancelled."""
        now = time.time()
        values: dict[str, Any] = {"status": status, "finished_at": now, "error": error, "message": status,
                                  "used_seconds": jobs.c.used_seconds + func.coalesce(
                                      now - jobs.c.attempt_started_at, 0.0)}
        if status == "succeeded":
            values["progress"] = 1.0
            values["result"] = json.dumps(result)
        with self._tx() as c:
            res = c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.owner == owner,
                                                    jobs.c.status == "running")).values(**values))
            return bool(res.rowcount == 1)

    def requeue(self, owner: str, job_id: str, message: str, refund: bool = False) -> None:
        """Back to the queue; ``refund``: the interruption was not the job's (a graceful server
        stop), so it does not count as an attempt. The time it ran counts towards its limit."""
        now = time.time()
        values: dict[str, Any] = {"status": "queued", "owner": None, "message": message,
                                  "used_seconds": jobs.c.used_seconds + func.coalesce(
                                      now - jobs.c.attempt_started_at, 0.0)}
        if refund:
            values["attempts"] = jobs.c.attempts - 1
        with self._tx() as c:
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.owner == owner,
                                              jobs.c.status == "running")).values(**values))

    def cancel(self, job_id: str) -> Job | None:
        """Queued: cancelled at once. Running: flagged; the runner stops the worker and marks it."""
        now = time.time()
        with self._tx() as c:
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.status == "queued")).values(
                status="cancelled", finished_at=now, message="cancelled", cancel_requested=1))
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.status == "running")).values(
                cancel_requested=1, message="cancelling"))
            row = c.execute(self._select().where(jobs.c.id == job_id)).first()
        return None if row is None else _row_to_job(row)

    def mark_cancelled(self, owner: str, job_id: str) -> None:
        with self._tx() as c:
            c.execute(update(jobs).where(and_(jobs.c.id == job_id, jobs.c.owner == owner,
                                              jobs.c.status == "running")).values(
                status="cancelled", finished_at=time.time(), message="cancelled"))

    # -- reads ---------------------------------------------------------------------------------

    def _select(self) -> Any:
        return select(*_SUMMARY_COLS, (jobs.c.result.is_not(None)).label("has_result"))

    def get(self, job_id: str) -> Job | None:
        with self._tx(write=False) as c:
            row = c.execute(self._select().where(jobs.c.id == job_id)).first()
        return None if row is None else _row_to_job(row)

    def result(self, job_id: str) -> dict[str, Any] | None:
        with self._tx(write=False) as c:
            data = c.execute(select(jobs.c.result).where(jobs.c.id == job_id)).scalar()
        return None if data is None else json.loads(data)

    def list_jobs(self, kind: str | None = None, status: str | None = None, limit: int = 100,
                  offset: int = 0) -> list[Job]:
        q = self._select()
        if kind:
            q = q.where(jobs.c.kind == kind)
        if status:
            q = q.where(jobs.c.status == status)
        q = q.order_by(jobs.c.created_at.desc()).limit(limit).offset(offset)
        with self._tx(write=False) as c:
            return [_row_to_job(r) for r in c.execute(q)]

    def cancel_requested(self, job_ids: list[str]) -> list[str]:
        if not job_ids:
            return []
        with self._tx(write=False) as c:
            rows = c.execute(select(jobs.c.id).where(and_(jobs.c.id.in_(job_ids), jobs.c.cancel_requested == 1)))
            return [r[0] for r in rows]

    def counts(self) -> dict[str, int]:
        with self._tx(write=False) as c:
            rows = c.execute(select(jobs.c.status, func.count()).group_by(jobs.c.status))
            return {r[0]: int(r[1]) for r in rows}


def _migrate(c: Connection) -> None:
    """Columns added since a store was made (create_all makes missing tables, not columns)."""
    have = {col["name"] for col in inspect(c).get_columns("jobs")}
    for name, ddl in _ADDED.items():
        if name not in have:
            c.execute(text(f"ALTER TABLE jobs ADD COLUMN {name} {ddl}"))
