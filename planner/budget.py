"""The end of an OMPL query counted in work, not in seconds (:class:`CheckBudget`).

A query that ends after a wall-clock time gives another answer on a slower or busier machine: an
RRTConnect that finds its path after 0.2 s on an idle machine fails at 0.15 s on a loaded one, the
planner takes another edge, and the plan changes (the CI runs on two shared cores). A budget of
state-validity checks ends every query at the same point of its (seeded) search on any machine, so
a plan is a function of the scene, the goal and the options only. The wall-clock limit stays as a
safety net far above what the check budget takes, for machines many times slower than this one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


class CheckBudget:
    """At most ``checks`` state-validity checks, and at most ``seconds`` of wall-clock time, for one
    OMPL query (``solve`` or ``simplifySolution``).

    :meth:`counted` wraps the validity checker so that every call is counted (motion validators
    call it too); :meth:`condition` starts a query (the count from zero) and returns the predicate
    for OMPL's ``PlannerTerminationCondition``, polled between iterations (the OMPL modules wrap
    it, so OMPL stays in ``planner.transfer`` and ``planner.object_motion``)."""

    def __init__(self, checks: int, seconds: float) -> None:
        if checks < 1:
            raise ValueError("checks must be at least 1")
        if not seconds > 0:
            raise ValueError("seconds must be positive")
        self.checks = int(checks)
        self.seconds = float(seconds)
        self.used = 0  # checks of the current query
        self.total = 0  # checks of every query so far
        self.timed_out = False  # the safety net ended a query
        self._start = time.perf_counter()

    def restart(self) -> None:
        self.used = 0
        self._start = time.perf_counter()

    def counted(self, valid: Callable[[Any], bool]) -> Callable[[Any], bool]:
        def check(state: Any) -> bool:
            self.used += 1
            self.total += 1
            return valid(state)

        return check

    def exhausted(self) -> bool:
        if self.used >= self.checks:
            return True
        if time.perf_counter() - self._start > self.seconds:
            self.timed_out = True
            return True
        return False

    def condition(self) -> Callable[[], bool]:
        self.restart()
        return self.exhausted
