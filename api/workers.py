"""Workers: a pool of long-lived processes that can be stopped mid-task, or Ray tasks.

Each local worker is a process that imports the analysis once and then runs tasks sent over a
pipe, sending back progress messages and one final ``ok``/``error`` message. A task that
overruns its time limit, or is cancelled, gets its process terminated and replaced: a runaway
solve cannot hold the server. The event loop watches the pipes with ``add_reader`` (no thread
per waiting request). A worker dies with its server, even one killed with SIGKILL
(:func:`die_with_parent`), so no orphan keeps computing; a pool may run its workers at a lower
CPU priority (``nice``, down to ``SCHED_IDLE``: :func:`lower_priority`, api/lanes.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.reduction import ForkingPickler
from typing import Any

log = logging.getLogger("ctp.workers")

ProgressCallback = Callable[[float, str], None]


class TaskError(Exception):
    """A task ended with an error. ``type`` is one of: ``scene`` (bad input, ``loc`` names the
    field), ``analysis`` (the mathematics says no, e.g. no stationary grasp), ``solver_time_limit``,
    ``worker_died``, ``internal``."""

    def __init__(self, type: str, message: str, loc: list[Any] | None = None,
                 errors: list[dict[str, Any]] | None = None):
        super().__init__(message)
        self.type = type
        self.message = message
        self.loc = loc
        self.errors = errors


class TaskTimeout(Exception):
    def __init__(self, limit: float):
        super().__init__(f"stopped after the time limit of {limit:g} s")
        self.limit = limit


class TaskCancelled(Exception):
    pass


def classify(e: BaseException) -> tuple[str, str, list[Any] | None, list[dict[str, Any]] | None]:
    """The transportable form of an exception raised by a task."""
    from analysis.exceptions import CTPError, SceneError, SolverTimeLimit

    if isinstance(e, SceneError):
        errors = [{"loc": list(err.get("loc", [])), "msg": str(err.get("msg", "")), "type": str(err.get("type", ""))}
                  for err in e.errors]
        return "scene", str(e), list(e.loc), errors
    if isinstance(e, SolverTimeLimit):
        return "solver_time_limit", str(e), None, None
    if isinstance(e, CTPError):
        return "analysis", str(e), None, None
    if e.__class__.__name__ == "ValidationError":  # pydantic (a goal re-validated in the worker)
        errs = e.errors()  # type: ignore[attr-defined]
        first = errs[0] if errs else {"loc": (), "msg": str(e)}
        return "scene", f"{'.'.join(map(str, first['loc']))}: {first['msg']}", list(first["loc"]), None
    return "internal", f"{type(e).__name__}: {e}", None, None


# -- the worker process ---------------------------------------------------------------------------


#: How often a worker's watchdog checks that its server is still alive (seconds).
WATCHDOG_SECONDS = 0.5


def die_with_parent(parent_pid: int) -> None:  # pragma: no cover - runs in the child process
    """End this process when the server that started it dies, even by SIGKILL (no orphan keeps
    computing): the kernel's parent-death signal (Linux ``prctl(PR_SET_PDEATHSIG, SIGKILL)``),
    and a watchdog thread that polls ``os.getppid()`` where there is no prctl or in case the
    process was reparented before the signal was armed."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(Exception):
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    if os.getppid() != parent_pid:  # the server died before the signal was armed
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(WATCHDOG_SECONDS)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="ctp-parent-watchdog", daemon=True).start()


#: Task messages up to this size (bytes) are written to the worker's pipe from the event loop; a
#: larger one from a thread, since the pipe holds 64 kB and a worker still importing reads nothing.
INLINE_SEND_BYTES = 32_000

#: The lowest ``nice`` value, at which a worker also asks for Linux's ``SCHED_IDLE`` policy.
LOWEST_NICE = 19


def lower_priority(nice: int) -> str:  # pragma: no cover - runs in the child process
    """Lower this process's CPU priority by ``nice``; at :data:`LOWEST_NICE` also take the
    ``SCHED_IDLE`` policy where there is one (Linux), under which the process runs only on CPU
    time no normal process wants (weight 3 against a normal process's 1,024; nice 19 alone still
    takes 1.5 % of a core beside each busy one). Unprivileged processes may lower but not raise
    their priority, so a worker keeps it for its lifetime. Returns the policy taken."""
    with contextlib.suppress(OSError):
        os.nice(nice)
    if nice >= LOWEST_NICE and hasattr(os, "SCHED_IDLE"):
        try:
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        except OSError:
            return f"nice {nice}"
        return "SCHED_IDLE"
    return f"nice {nice}"


def _worker_main(conn: Connection, parent_pid: int | None = None,
                 nice: int = 0) -> None:  # pragma: no cover - runs in the child process
    if parent_pid is not None:
        die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C stops the server, which stops us
    if nice:
        lower_priority(nice)  # a background lane: the light requests' workers get the CPU first
    from api.tasks import run_task  # loads the analysis before the worker says it is ready

    conn.send(("ready",))
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        kind, payload = msg
        progress = _Throttled(conn)

        try:
            result = run_task(kind, payload, progress)
        except Exception as e:
            t, m, loc, errs = classify(e)
            if t == "internal":
                traceback.print_exc()
            conn.send(("error", t, m, loc, errs))
        else:
            conn.send(("ok", result))


class _Throttled:
    """Progress messages to the parent, at most ten a second."""

    def __init__(self, conn: Connection):
        self.conn = conn
        self.last = 0.0

    def __call__(self, frac: float, text: str) -> None:
        now = time.monotonic()
        if now - self.last >= 0.1 or frac >= 1.0:
            self.last = now
            self.conn.send(("progress", float(frac), str(text)))


class _Worker:
    def __init__(self, ctx: Any, nice: int = 0):
        parent, child = ctx.Pipe(duplex=True)
        self.conn: Connection = parent
        self.proc = ctx.Process(target=_worker_main, args=(child, os.getpid(), nice), daemon=True,
                                name="ctp-worker")
        self.proc.start()
        child.close()
        self.ready = False

    def stop(self, hard: bool = True) -> None:
        with contextlib.suppress(Exception):
            if not hard:
                self.conn.send(None)
        if hard and self.proc.is_alive():
            self.proc.terminate()
            self.proc.join(2)
            if self.proc.is_alive() and self.proc.pid is not None:
                os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.join(2)
        with contextlib.suppress(Exception):
            self.conn.close()


def _await_ready(w: _Worker, limit: float = 120.0) -> None:
    if w.conn.poll(limit):
        with contextlib.suppress(EOFError, OSError):
            msg = w.conn.recv()
            w.ready = msg == ("ready",)


class ProcessPool:
    """``size`` worker processes; ``await run(...)`` takes an idle one (waits for one if none).

    ``nice`` lowers the workers' CPU priority (a lane for heavy or background work, so that the
    workers of light requests get the CPU first when both run)."""

    def __init__(self, size: int, name: str = "workers", nice: int = 0):
        self.size = size
        self.name = name
        self.nice = nice
        self._ctx = mp.get_context("spawn")  # never fork a process that runs an event loop and threads
        self._idle: asyncio.Queue[_Worker] | None = None
        self._all: set[_Worker] = set()
        self.started = False
        self.closing = False  # no replacement workers once the server is stopping

    async def start(self, wait: bool = True) -> None:
        """Spawn the workers; with ``wait``, return once each has imported the analysis."""
        self._idle = asyncio.Queue()
        workers = [self._spawn() for _ in range(self.size)]
        if wait:
            await asyncio.gather(*(asyncio.to_thread(_await_ready, w) for w in workers))
        for w in workers:
            self._idle.put_nowait(w)
        self.started = True

    def _spawn(self) -> _Worker:
        w = _Worker(self._ctx, self.nice)
        self._all.add(w)
        return w

    async def close(self) -> None:
        for w in list(self._all):
            await asyncio.to_thread(w.stop, True)
        self._all.clear()
        self.started = False

    def alive(self) -> int:
        return sum(1 for w in self._all if w.proc.is_alive())

    def idle(self) -> int:
        return 0 if self._idle is None else self._idle.qsize()

    def pids(self) -> list[int]:
        """The worker processes' ids (fault-injection tests, diagnostics)."""
        return [w.proc.pid for w in self._all if w.proc.pid is not None]

    async def _replace(self, w: _Worker) -> None:
        self._all.discard(w)
        await asyncio.to_thread(w.stop, True)
        if self.closing:
            return
        assert self._idle is not None
        self._idle.put_nowait(self._spawn())

    async def run(self, kind: str, payload: dict[str, Any], *, timeout: float,
                  on_progress: ProgressCallback | None = None,
                  cancelled: asyncio.Event | None = None) -> dict[str, Any]:
        """Run a task; TaskTimeout after ``timeout`` s of work (the wait for a free worker counts
        too, so a request never outlives its limit), TaskCancelled when ``cancelled`` is set.
        Waiting tasks get the next free worker in their order of arrival."""
        assert self._idle is not None, "pool not started"
        deadline = time.monotonic() + timeout
        try:
            w = await asyncio.wait_for(self._idle.get(), timeout=timeout)
        except TimeoutError:
            raise TaskTimeout(timeout) from None
        healthy = False  # a timeout, a cancellation or a dead worker: the process is replaced
        try:
            result = await self._talk(w, kind, payload, deadline, timeout, on_progress, cancelled)
            healthy = True
            return result
        except TaskError as e:
            healthy = e.type != "worker_died"
            raise
        finally:
            if healthy:
                self._idle.put_nowait(w)
            else:
                await self._replace(w)

    async def _talk(self, w: _Worker, kind: str, payload: dict[str, Any], deadline: float, timeout: float,
                    on_progress: ProgressCallback | None, cancelled: asyncio.Event | None) -> dict[str, Any]:
        loop = asyncio.get_running_loop()
        readable = asyncio.Event()
        fd = w.conn.fileno()
        loop.add_reader(fd, readable.set)
        try:
            try:
                message = ForkingPickler.dumps((kind, payload))  # what Connection.send writes
                if len(message) <= INLINE_SEND_BYTES:
                    w.conn.send_bytes(message)
                else:  # a worker still importing reads nothing: a full pipe would block the event loop
                    await asyncio.to_thread(w.conn.send_bytes, message)
            except (OSError, ValueError) as e:
                raise TaskError("worker_died", f"worker process unavailable: {e}") from None
            while True:
                while not w.conn.poll():
                    readable.clear()
                    if w.conn.poll():
                        break
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        raise TaskTimeout(timeout)
                    waits: list[asyncio.Future[Any]] = [asyncio.ensure_future(readable.wait())]
                    if cancelled is not None:
                        waits.append(asyncio.ensure_future(cancelled.wait()))
                    _, pending = await asyncio.wait(waits, timeout=min(remaining, 1.0),
                                                       return_when=asyncio.FIRST_COMPLETED)
                    for p in pending:
                        p.cancel()
                    if cancelled is not None and cancelled.is_set():
                        raise TaskCancelled()
                    if not w.proc.is_alive() and not w.conn.poll():
                        raise TaskError("worker_died", f"the worker process died (exit code {w.proc.exitcode})")
                try:
                    msg = w.conn.recv()
                except (EOFError, OSError):
                    raise TaskError("worker_died",
                                    f"the worker process died (exit code {w.proc.exitcode})") from None
                if msg[0] == "ready":
                    w.ready = True
                elif msg[0] == "progress":
                    if on_progress is not None:
                        on_progress(msg[1], msg[2])
                elif msg[0] == "ok":
                    return dict(msg[1])
                elif msg[0] == "error":
                    raise TaskError(msg[1], msg[2], msg[3], msg[4])
        finally:
            loop.remove_reader(fd)


class RayExecutor:
    """Jobs as Ray tasks on a cluster (``ray_address``). Same interface as :class:`ProcessPool`;
    progress is not streamed back from Ray tasks (a job reports 0 until it ends), a timeout or a
    cancellation force-cancels the task."""

    def __init__(self, address: str, size: int = 0, name: str = "ray"):
        self.address = address
        self.size = size
        self.name = name
        self.started = False
        self.closing = False
        self._remote: Any = None

    async def start(self, wait: bool = True) -> None:
        import ray

        if not ray.is_initialized():
            kwargs: dict[str, Any] = {"ignore_reinit_error": True, "log_to_driver": False}
            if self.address != "local":
                kwargs["address"] = self.address
            await asyncio.to_thread(ray.init, **kwargs)
        self._remote = ray.remote(max_retries=0)(_ray_task)
        self.started = True

    async def close(self) -> None:
        self.started = False

    def alive(self) -> int:
        return self.size

    def idle(self) -> int:
        return self.size

    async def run(self, kind: str, payload: dict[str, Any], *, timeout: float,
                  on_progress: ProgressCallback | None = None,
                  cancelled: asyncio.Event | None = None) -> dict[str, Any]:
        import ray

        ref = self._remote.remote(kind, payload)
        fut = asyncio.ensure_future(_await_ref(ref))
        waits: list[asyncio.Future[Any]] = [fut]
        if cancelled is not None:
            waits.append(asyncio.ensure_future(cancelled.wait()))
        try:
            done, pending = await asyncio.wait(waits, timeout=timeout, return_when=asyncio.FIRST_COMPLETED)
        except asyncio.CancelledError:
            ray.cancel(ref, force=True)
            raise
        for p in pending:
            if p is not fut:
                p.cancel()
        if fut not in done:
            ray.cancel(ref, force=True)
            fut.cancel()
            if cancelled is not None and cancelled.is_set():
                raise TaskCancelled()
            raise TaskTimeout(timeout)
        status, *rest = fut.result()
        if status == "ok":
            return dict(rest[0])
        raise TaskError(rest[0], rest[1], rest[2], rest[3])


async def _await_ref(ref: Any) -> Any:
    try:
        return await ref
    except Exception as e:  # the task died (node lost, worker killed)
        return ("error", "worker_died", f"the Ray task failed: {type(e).__name__}: {e}", None, None)


def _ray_task(kind: str, payload: dict[str, Any]) -> tuple[Any, ...]:  # pragma: no cover - on Ray workers
    from api.tasks import run_task

    try:
        return ("ok", run_task(kind, payload, None))
    except Exception as e:
        t, m, loc, errs = classify(e)
        return ("error", t, m, loc, errs)
