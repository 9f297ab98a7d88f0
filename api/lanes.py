"""Two lanes of analysis workers, so that a light request never waits behind heavy ones.

* The heavy lane (``analysis_workers``, CPU priority lowered by ``HEAVY_NICE``) runs what may
  take seconds: the table of every combination of a scene (``POST /analyses`` without a
  combination), one combination of a very large scene, the geometry of many configurations.
  Jobs (plans, enumerations) run at the same lower priority in their own pool.
* The light lane (``light_workers``) runs what is cheap by construction: one combination's
  report of a scene of ordinary size, the drawing geometry of a few configurations. A light
  request takes an idle light worker, else an idle heavy worker (lent for one request), else
  waits for the next light worker: two heavy requests occupying the heavy lane leave the light
  lane free, and on a busy machine the light workers get the CPU first.

:func:`analysis_lane` and :func:`geometry_lane` are the cost estimates: which lane a request goes
to. The lane that served a request is in its ``X-Lane`` header.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

from api.workers import ProcessPool

#: ``nice`` increment of the heavy lane's and the jobs' worker processes.
HEAVY_NICE = 10
#: One combination of a scene up to this size is light (a handful of LPs and one small NLP:
#: milliseconds to a fraction of a second).
LIGHT_MAX_CONTACTS = 12
LIGHT_MAX_JOINTS = 64
#: Geometry up to this many units is light: a configuration costs about the sum over the fingers
#: of their joints squared (each link's pose from the finger's base), some 12 microseconds a unit.
LIGHT_MAX_GEOMETRY = 20_000

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


async def run_in_lane(lane: Lane, light: ProcessPool, heavy: ProcessPool, kind: str, payload: dict[str, Any],
                      *, timeout: float) -> dict[str, Any]:
    """Run ``kind`` in ``lane`` (see the module docstring for how a light request finds a worker)."""
    if lane == "heavy":
        return await heavy.run(kind, payload, timeout=timeout)
    w = light.take_idle()
    if w is not None:
        return await light.run(kind, payload, timeout=timeout, worker=w)
    w = heavy.take_idle()
    if w is not None:
        return await heavy.run(kind, payload, timeout=timeout, worker=w)
    return await light.run(kind, payload, timeout=timeout)
