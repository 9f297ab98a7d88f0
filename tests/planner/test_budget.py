"""The OMPL queries end after a number of validity checks (:class:`CheckBudget`), so a plan does not
depend on the machine's speed."""

from __future__ import annotations

import time

import numpy as np
import pytest

from analysis.scene import Scene
from planner import Goal, plan
from planner.budget import CheckBudget
from planner.collision import CollisionModel


def test_budget_counts_checks_and_ends_the_query() -> None:
    b = CheckBudget(checks=3, seconds=60.0)
    check = b.counted(lambda s: s > 0)
    cond = b.condition()
    assert [check(v) for v in (1, -1)] == [True, False]
    assert not cond() and not b.exhausted()
    check(2)
    assert cond() and b.exhausted() and not b.timed_out
    b.condition()  # the next query of the same problem starts from zero
    assert b.used == 0 and b.total == 3 and not b.exhausted()


def test_budget_safety_net_is_wall_clock() -> None:
    b = CheckBudget(checks=10**9, seconds=0.01)
    cond = b.condition()
    time.sleep(0.02)
    assert cond() and b.timed_out


@pytest.mark.parametrize(("checks", "seconds"), [(0, 1.0), (5, 0.0), (5, float("nan"))])
def test_budget_rejects_bad_limits(checks: int, seconds: float) -> None:
    with pytest.raises(ValueError):
        CheckBudget(checks, seconds)


def _paths(p) -> list[np.ndarray]:  # type: ignore[no-untyped-def]
    return [np.hstack([s.transition.q_path, s.transition.object_path]) for s in p.steps]


def test_a_slower_machine_gives_the_same_plan(planar_scene: Scene, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every collision query 1 ms slower (an OMPL query then takes several times as long as on an
    idle machine): the same steps, the same paths to the last bit. With a wall-clock end of the
    queries this plan changed on a busy machine (found by sliding on one, by lifting on another)."""
    goal = Goal(type="pose", pose=[0.0, 0.55, 0.0], tolerance=0.01)
    fast = plan(planar_scene, goal)
    assert fast.found, fast.reason
    real = CollisionModel.finger_clearance

    def slow(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        time.sleep(1e-3)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(CollisionModel, "finger_clearance", slow)
    slowed = plan(planar_scene, goal)
    assert [s.transition.combination for s in slowed.steps] == [s.transition.combination for s in fast.steps]
    for a, b in zip(_paths(slowed), _paths(fast), strict=True):
        np.testing.assert_array_equal(a, b)
