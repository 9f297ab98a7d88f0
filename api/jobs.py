"""The job runner: claims jobs from the store and runs them on the workers.

One runner per server process. It claims queued jobs (and running jobs whose owner stopped
heart-beating: a server that was killed), up to the number of job workers, heart-beats the jobs
it runs, writes progress, stops a job whose cancellation was requested, and records the final
state. A job that overruns its time limit fails with that reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
import uuid
from typing import Any, Protocol

from api.store import Job, JobStore
from api.workers import TaskCancelled, TaskError, TaskTimeout

log = logging.getLogger("ctp.jobs")


class Executor(Protocol):
    size: int

    async def run(self, kind: str, payload: dict[str, Any], *, timeout: float, on_progress: Any = None,
                  cancelled: asyncio.Event | None = None) -> dict[str, Any]: ...


class JobRunner:
    def __init__(self, store: JobStore, executor: Executor, *, slots: int, lease: float, poll: float,
                 default_time_limit: float, max_attempts: int):
        self.store = store
        self.executor = executor
        self.slots = slots
        self.lease = lease
        self.poll = poll
        self.default_time_limit = default_time_limit
        self.max_attempts = max_attempts
        self.owner = f"runner-{uuid.uuid4().hex[:12]}"
        self.running: dict[str, tuple[asyncio.Task[None], asyncio.Event]] = {}
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._last_beat = 0.0

    def start(self) -> None:
        self._task = asyncio.create_task(self._loop(), name="ctp-job-runner")

    def wake(self) -> None:
        """A job was submitted or cancelled: look now rather than at the next poll."""
        self._wake.set()

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        interrupted = list(self.running)
        for task, _ in list(self.running.values()):
            task.cancel()
        for task, _ in list(self.running.values()):
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        # a graceful stop puts its jobs back in the queue at once (a crash leaves them running;
        # they are taken over when their lease expires)
        for job_id in interrupted:
            with contextlib.suppress(Exception):
                await asyncio.to_thread(self.store.requeue, self.owner, job_id, "requeued: the server stopped",
                                        True)

    async def _loop(self) -> None:
        while True:
            try:
                await self._tick()
            except asyncio.CancelledError:
                raise
            except Exception:  # a store hiccup must not kill the runner
                log.exception("job runner tick failed")
            self._wake.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._wake.wait(), timeout=self.poll)

    async def _tick(self) -> None:
        ids = list(self.running)
        now = time.monotonic()
        if ids and now - self._last_beat >= self.lease / 4:
            await asyncio.to_thread(self.store.heartbeat, self.owner, ids)
            self._last_beat = now
        for job_id in await asyncio.to_thread(self.store.cancel_requested, ids):
            self.running[job_id][1].set()
        while len(self.running) < self.slots:
            job = await asyncio.to_thread(self.store.claim, self.owner, self.lease, self.max_attempts)
            if job is None:
                break
            cancel = asyncio.Event()
            task = asyncio.create_task(self._execute(job, cancel), name=f"job-{job.id}")
            self.running[job.id] = (task, cancel)

    async def _execute(self, job: Job, cancel: asyncio.Event) -> None:
        store, owner = self.store, self.owner
        limit = float(job.request.get("time_limit") or self.default_time_limit)
        last = [0.0]

        def on_progress(frac: float, message: str) -> None:
            now = time.monotonic()
            if now - last[0] >= 0.25 or frac >= 1.0:
                last[0] = now
                store.set_progress(owner, job.id, frac, message)

        try:
            result = await self.executor.run(job.kind, job.request, timeout=limit, on_progress=on_progress,
                                             cancelled=cancel)
        except TaskCancelled:
            await asyncio.to_thread(store.mark_cancelled, owner, job.id)
        except TaskTimeout as e:
            await asyncio.to_thread(store.finish, owner, job.id, "failed",
                                    error=f"time limit: the job {e} (time_limit)")
        except TaskError as e:
            if e.type == "worker_died":
                # a crash is not the job's fault (or is it? retried up to max_attempts, then failed)
                if job.attempts >= self.max_attempts:
                    await asyncio.to_thread(store.finish, owner, job.id, "failed", error=e.message)
                else:
                    await asyncio.to_thread(store.requeue, owner, job.id, "requeued after a worker crash")
            else:
                await asyncio.to_thread(store.finish, owner, job.id, "failed", error=_reason(e))
        except asyncio.CancelledError:
            raise  # server shutting down: the job stays running and is resumed after a restart
        except Exception as e:  # never leave a job without a final state
            log.exception("job %s", job.id)
            await asyncio.to_thread(store.finish, owner, job.id, "failed", error=f"internal error: {e}")
        else:
            await asyncio.to_thread(store.finish, owner, job.id, "succeeded", result=result)
        finally:
            self.running.pop(job.id, None)
            self.wake()


def _reason(e: TaskError) -> str:
    prefix = {"scene": "invalid input", "analysis": "analysis", "solver_time_limit": "solver time limit",
              "internal": "internal error"}.get(e.type, e.type)
    return f"{prefix}: {e.message}"

