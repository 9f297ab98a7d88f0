"""Two lanes of analysis workers, so that a light request never waits behind heavy ones.

* The heavy lane (``analysis_workers``, at the lowest CPU priority: ``nice`` 19 and Linux's
  ``SCHED_IDLE``, api/workers.py) runs what may take seconds: the table of every combination of
  a scene (``POST /analyses`` without a combination), one combination of a very large scene, the
  geometry of many configurations. Jobs (plans, enumerations) run at the same priority in their
  own pool.
* The light lane (``light_workers``, normal priority) runs what is cheap by construction: one
  combination's report of a scene of ordinary size, the drawing geometry of a few
  configurations, contact detection. Light requests queue for a light worker in their order of
  arrival (first come, first served, which keeps the tail of their latencies short), never for a
  heavy one: a heavy worker runs on CPU time no light worker wants, so a light request lent to it
  would wait for the whole light lane to fall idle. Two heavy requests occupying the heavy lane
  leave the light lane free and take almost none of its CPU.

:func:`analysis_lane` and :func:`geometry_lane` are the cost estimates: which lane a request goes
to. The lane that served a request is in its ``X-Lane`` header, on its errors as well
(:func:`use_lane` and :class:`LaneHeader`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

from starlette.requests import Request

from api.workers import LOWEST_NICE, ProcessPool

#: ``nice`` increment of the heavy lane's and the jobs' worker processes: the lowest priority, at
#: which they also take ``SCHED_IDLE`` (api/workers.py ``lower_priority``).
HEAVY_NICE = LOWEST_NICE
#: One combination of a scene up to this size is light (a handful of LPs and one small NLP:
#: milliseconds to a fraction of a second).
LIGHT_MAX_CONTACTS = 12
LIGHT_MAX_JOINTS = 64
#: Geometry up to this many units is light: a configuration costs about the sum over the fingers
#: of their joints squared (each link's pose from the finger's base), some 12 microseconds a unit.
LIGHT_MAX_GEOMETRY = 20_000

#: An upload up to this size is light: a scene file of ordinary size parses and validates in
#: milliseconds (libyaml reads some 250 kB of YAML a second, JSON far more).
LIGHT_MAX_UPLOAD_BYTES = 64_000

Lane = Literal["light", "heavy"]


def analysis_lane(combination: str | None, contacts: int, joints: int) -> Lane:
    """One combination of a scene of ordinary size: light. Every combination (up to ``3**L``
    of them), or one combination of a very large scene: heavy."""
    if combination and contacts <= LIGHT_MAX_CONTACTS and joints <= LIGHT_MAX_JOINTS:
        return "light"
    return "heavy"


def geometry_lane(configurations: int, finger_joints: Sequence[int]) -> Lane:
    """The drawing geometry of ``configurations`` joint vectors of fingers of these sizes."""
    return "light" if configurations * sum(n * n for n in finger_joints) <= LIGHT_MAX_GEOMETRY else "heavy"


def upload_lane(size: int) -> Lane:
    """The parse and validation of an uploaded scene file of ``size`` bytes."""
    return "light" if size <= LIGHT_MAX_UPLOAD_BYTES else "heavy"


async def run_in_lane(lane: Lane, light: ProcessPool, heavy: ProcessPool, kind: str, payload: dict[str, Any],
                      *, timeout: float) -> dict[str, Any]:
    """Run ``kind`` on the next free worker of ``lane`` (see the module docstring)."""
    pool = heavy if lane == "heavy" else light
    return await pool.run(kind, payload, timeout=timeout)


def use_lane(request: Request, lane: Lane) -> Lane:
    """Record that ``request`` is served by ``lane``: its response carries ``X-Lane``, whether
    the route returns or raises (an error answered by an exception handler included)."""
    request.state.lane = lane
    return lane


class LaneHeader:
    """ASGI middleware: ``X-Lane`` on the response of a request that :func:`use_lane` recorded,
    added when the response starts (so errors built by exception handlers carry it too)."""

    def __init__(self, app: Any):
        self.app = app

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_lane(msg: Any) -> None:
            lane = (scope.get("state") or {}).get("lane")
            if msg["type"] == "http.response.start" and lane is not None:
                headers = [(k, v) for k, v in msg.get("headers", []) if k.lower() != b"x-lane"]
                msg = {**msg, "headers": [*headers, (b"x-lane", str(lane).encode())]}
            await send(msg)

        await self.app(scope, receive, send_with_lane)
