"""The job runner: claims jobs from the store and runs them on the workers.

One runner per server process. It claims queued jobs (and running jobs whose owner stopped
heart-beating: a server that was killed), up to the number of job workers, heart-beats the jobs
it runs, writes progress, stops a job whose cancellation was requested, and records the final
state. A job's time limit is a total over its attempts: a resumed job gets what the attempts
before it left (``used_seconds``); a job over it fails with that reason.

The store may go away (PostgreSQL restarted, SQLite locked by another process, a full disk):
the workers go on, progress is kept in memory, and every store write (heartbeat, progress, a
job's final state) is retried with a back-off (0.2 s doubling up to ``retry_max``) until the
store is back. A job is never failed because the store was away. After an outage the runner
waits one lease before it takes over other runners' stale jobs, so that they can heart-beat
theirs first.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
import uuid
from collections.abc import Callable
from typing import Any, Protocol, TypeVar

from api.store import Job, JobStore, StoreUnavailable
from api.workers import TaskCancelled, TaskError, TaskTimeout

log = logging.getLogger("ctp.jobs")
T = TypeVar("T")


class Executor(Protocol):
    size: int

    async def run(self, kind: str, payload: dict[str, Any], *, timeout: float, on_progress: Any = None,
                  cancelled: asyncio.Event | None = None) -> dict[str, Any]: ...


class JobRunner:
    def __init__(self, store: JobStore, executor: Executor, *, slots: int, lease: float, poll: float,
                 default_time_limit: float, max_attempts: int, retry_max: float = 5.0):
        self.store = store
        self.executor = executor
        self.slots = slots
        self.lease = lease
        self.poll = poll
        self.default_time_limit = default_time_limit
        self.max_attempts = max_attempts
        self.retry_max = retry_max
        self.owner = f"runner-{uuid.uuid4().hex[:12]}"
        self.running: dict[str, tuple[asyncio.Task[None], asyncio.Event]] = {}
        self._progress: dict[str, tuple[float, str]] = {}  # the latest of each job, not yet written
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._stopping = False
        self._last_beat = 0.0
        self._backoff = 0.0
        self._outage_since: float | None = None
        self._take_over_after = 0.0  # monotonic: stale jobs of other runners are claimed only after it

    def start(self) -> None:
        self._task = asyncio.create_task(self._loop(), name="ctp-job-runner")

    def wake(self) -> None:
        """A job was submitted or cancelled: look now rather than at the next poll."""
        self._wake.set()

    async def stop(self) -> None:
        self._stopping = True  # ends the loop even if a cancellation were lost in a wait
        if self._task is not None:
            self._task.cancel()
            self.wake()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        interrupted = list(self.running)
        for task, _ in list(self.running.values()):
            task.cancel()
        for task, _ in list(self.running.values()):
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        # a graceful stop puts its jobs back in the queue at once (a crash leaves them running;
        # they are taken over when their lease expires, as they are when the store is away now)
        for job_id in interrupted:
            with contextlib.suppress(Exception):
                await asyncio.to_thread(self.store.requeue, self.owner, job_id, "requeued: the server stopped",
                                        True)

    # -- the loop ------------------------------------------------------------------------------

    async def _loop(self) -> None:
        while not self._stopping:
            delay = self.poll
            try:
                await self._tick()
                self._store_back()
            except asyncio.CancelledError:
                raise
            except StoreUnavailable as e:
                delay = self._store_away(e)
            except Exception:  # a bug in a tick must not kill the runner
                log.exception("job runner tick failed")
            self._wake.clear()
            # asyncio.timeout, not wait_for: on Python 3.11 wait_for can swallow a cancellation that
            # arrives as the event is set (a job ending as the server stops), and stop() then hangs
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(delay):
                    await self._wake.wait()

    def _store_away(self, e: StoreUnavailable) -> float:
        if self._outage_since is None:
            self._outage_since = time.monotonic()
            log.warning("%s: running jobs go on, store writes are retried", e)
        self._backoff = min(self.retry_max, self._backoff * 2 or 0.2)
        return self._backoff

    def _store_back(self) -> None:
        if self._outage_since is not None:
            log.warning("job store back after %.1f s", time.monotonic() - self._outage_since)
            self._outage_since = None
            self._take_over_after = time.monotonic() + self.lease
        self._backoff = 0.0

    async def _tick(self) -> None:
        ids = list(self.running)
        now = time.monotonic()
        progress, self._progress = self._progress, {}
        if progress or (ids and now - self._last_beat >= self.lease / 4):
            try:
                await asyncio.to_thread(self.store.heartbeat, self.owner, ids, progress)
            except StoreUnavailable:
                for job_id, p in progress.items():  # written with the next beat, unless newer came
                    self._progress.setdefault(job_id, p)
                raise
            self._last_beat = now
        for job_id in await asyncio.to_thread(self.store.cancel_requested, ids):
            self.running[job_id][1].set()
        take_over = time.monotonic() >= self._take_over_after
        while len(self.running) < self.slots:
            job = await asyncio.to_thread(self.store.claim, self.owner, self.lease, self.max_attempts,
                                          exclude=list(self.running), take_over=take_over)
            if job is None:
                break
            cancel = asyncio.Event()
            task = asyncio.create_task(self._execute(job, cancel), name=f"job-{job.id}")
            self.running[job.id] = (task, cancel)

    async def _write(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """A store write that must happen (a job's final state): retried until the store is back.
        The job stays in ``running`` meanwhile, so its lease is kept by the heartbeats."""
        delay = 0.2
        while True:
            try:
                return await asyncio.to_thread(fn, *args, **kwargs)
            except StoreUnavailable as e:
                log.info("%s: retrying %s in %.1f s", e, getattr(fn, "__name__", "a write"), delay)
                await asyncio.sleep(delay)
                delay = min(self.retry_max, delay * 2)

    async def _execute(self, job: Job, cancel: asyncio.Event) -> None:
        store, owner = self.store, self.owner
        limit = float(job.request.get("time_limit") or self.default_time_limit)
        remaining = limit - job.used_seconds  # the limit is a total over the attempts

        def on_progress(frac: float, message: str) -> None:  # on the event loop: no store I/O here
            self._progress[job.id] = (frac, message)

        over = (f"time limit: the job was stopped after {limit:g} s of work in {job.attempts} "
                f"attempt{'s' if job.attempts != 1 else ''} (time_limit)")
        try:
            if remaining <= 0:
                raise TaskTimeout(limit)
            result = await self.executor.run(job.kind, job.request, timeout=remaining, on_progress=on_progress,
                                             cancelled=cancel)
        except TaskCancelled:
            await self._write(store.mark_cancelled, owner, job.id)
        except TaskTimeout:
            await self._write(store.finish, owner, job.id, "failed", error=over)
        except TaskError as e:
            if e.type == "worker_died":
                # a crash is not the job's fault (or is it? retried up to max_attempts, then failed)
                if job.attempts >= self.max_attempts:
                    await self._write(store.finish, owner, job.id, "failed", error=e.message)
                else:
                    await self._write(store.requeue, owner, job.id, "requeued after a worker crash")
            else:
                await self._write(store.finish, owner, job.id, "failed", error=_reason(e))
        except asyncio.CancelledError:
            raise  # server shutting down: the job stays running and is resumed after a restart
        except Exception as e:  # never leave a job without a final state; the details go to the log only
            log.exception("job %s", job.id)
            await self._write(store.finish, owner, job.id, "failed",
                              error=f"internal error: the job runner failed ({type(e).__name__}); see the server log")
        else:
            await self._write(store.finish, owner, job.id, "succeeded", result=result)
        finally:
            self.running.pop(job.id, None)
            self._progress.pop(job.id, None)
            self.wake()


def _reason(e: TaskError) -> str:
    prefix = {"scene": "invalid input", "analysis": "analysis", "solver_time_limit": "solver time limit",
              "internal": "internal error"}.get(e.type, e.type)
    return f"{prefix}: {e.message}"
