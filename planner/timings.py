"""Where the planning time goes: seconds per activity, measured with a context manager.

The planner reports four activities (:class:`planner.plan.PlanStats`): ``analysis`` (closure
analysis of states and combinations), ``ik`` (inverse kinematics of new contacts), ``motion``
(retreats and integrated object motions) and ``ompl`` (OMPL transfers and constrained object
motions); the rest of the search is bookkeeping.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field


@dataclass
class Timings:
    """Accumulated wall-clock seconds per activity name (0 for an activity never measured)."""

    seconds: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))

    @contextmanager
    def measure(self, activity: str) -> Iterator[None]:
        """Add the time spent in the ``with`` block (also when it returns or raises) to ``activity``."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[activity] += time.perf_counter() - t0

    def __getitem__(self, activity: str) -> float:
        return self.seconds[activity]
