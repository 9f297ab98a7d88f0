"""Collision-free finger transfers (the regrasp D -> F of eq. 33 with ``dr = 0``), planned by OMPL.

A free finger moves from its configuration to a new contact whose touching configuration
``q_goal`` comes from :mod:`planner.ik`: OMPL (RRTConnect, seeded, bounded by the joint limits)
plans to a pre-contact configuration backed off by ``approach`` along the last link
(:func:`_back_off`); the last approach is a joint-space segment on which only the tip may touch.
:func:`~planner.collision.path_clearance_certified` then checks the whole path (every
configuration, not only samples, is collision-free; overlaps present at the start may persist but
not deepen).

A transfer depends on the finger's own joints, the joints of the fingers it is checked against
(:attr:`~planner.collision.CollisionModel.finger_pairs`), the object pose and the query's
settings, and on nothing else (:func:`transfer_key`): the search asks for the same transfer from
many grasp states that differ only in the other fingers (a finger released, another re-placed),
and :class:`planner.nodes.GraphNodes` keeps each answer under its key.
"""

from __future__ import annotations

import functools
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from analysis._types import Array
from analysis.kinematics import BodyRef
from planner.budget import CheckBudget
from planner.collision import CollisionModel, path_clearance_certified
from planner.ik import joint_limits
from planner.state import GraspState


@dataclass(frozen=True)
class TransferPath:
    """A finger's collision-free transfer to a new contact."""

    finger: int
    waypoints: Array  # (n, m) joint configurations of the finger, last one touching
    length: float  # joint-space length
    clearance: float  # smallest clearance along the free part
    checks: int
    ompl_seconds: float


def transfer_key(
    model: CollisionModel,
    state: GraspState,
    finger: int,
    q_goal: Array,
    tip_ref: BodyRef,
    approach: float,
    seed: int,
    checks: int,
) -> tuple[Any, ...]:
    """Everything :func:`plan_transfer` depends on, exactly (as bytes): the finger, its joints and
    those of the fingers it is checked against in ``state.q``, the object pose, the goal
    configuration, the touching link, the approach and the OMPL seed and check budget. The
    validity checker, the start allowance, the back-off and the certificate read nothing else,
    so two queries with one key get the same answer (OMPL is seeded, its end counted in checks)."""
    hand = model.hand
    partners = [j for j in range(len(hand.fingers))
                if j == finger or (min(j, finger), max(j, finger)) in model.finger_pairs]
    q = np.asarray(state.q, dtype=float)
    joints = tuple(q[hand.finger_slice(j)].tobytes() for j in partners)
    return (finger, tuple(partners), joints, np.asarray(state.position, dtype=float).tobytes(),
            np.asarray(state.rotation, dtype=float).tobytes(), np.asarray(q_goal, dtype=float).tobytes(),
            tip_ref.name, float(approach), int(seed), int(checks))


def plan_transfer(
    model: CollisionModel,
    state: GraspState,
    finger: int,
    q_goal: Array,  # (m,) touching configuration of the finger
    tip_ref: BodyRef,
    approach: float,
    seed: int = 0,
    time_limit: float = 2.0,
    checks: int = 300,
) -> TransferPath | None:
    """Plan a collision-free joint path (OMPL RRTConnect, seeded) from the finger's configuration
    in ``state`` to ``q_goal``, through a pre-contact configuration backed off by ``approach``
    (scene units) along the normal. Each OMPL query (the search, the shortcutting) ends after
    ``checks`` validity checks, or ``time_limit`` seconds as a safety net (:class:`CheckBudget`).
    ``None`` when no certified path is found."""
    hand = model.hand
    sl = hand.finger_slice(finger)
    m = sl.stop - sl.start
    q_full = state.q.copy()
    pos, rot = state.position, state.rotation
    allow = model.start_allowance(finger, q_full, pos, rot)  # overlaps at the start may not deepen
    # pre-contact: back the joints off along the last link until the clearance is positive
    q_pre = _back_off(model, finger, q_full, q_goal, tip_ref, approach, pos, rot, allow)
    if q_pre is None:
        return None
    start = state.q[sl]
    j_lo, j_hi = joint_limits(hand, finger)

    def valid_q(x: Array) -> bool:
        if np.any(x < j_lo - 1e-9) or np.any(x > j_hi + 1e-9):
            return False
        qq = q_full.copy()
        qq[sl] = x
        return model.is_clear(finger, qq, pos, rot, (), allow)

    lo_tol, hi_tol = j_lo - 1e-9, j_hi + 1e-9

    bounded = bool(np.isfinite(j_lo).any() or np.isfinite(j_hi).any())

    def evaluate_many(rows: Array) -> Array:  # (N, m) -> (N,) bool: valid_q of each row
        if not bounded:  # a scene chain without limits: every row is inside (a NaN row fails the clearance, NaN >= 0)
            return np.asarray(model.clear_many(finger, q_full, rows, pos, rot, allow))
        inside = np.all((rows >= lo_tol) & (rows <= hi_tol), axis=1)
        out = np.zeros(len(rows), dtype=bool)
        if inside.any():
            out[inside] = model.clear_many(finger, q_full, rows[inside], pos, rot, allow)
        return out

    # the answers of valid_many by row (its bytes): within one transfer everything else the check
    # reads is fixed, and a row's answer does not depend on the rows checked with it (clear_many
    # culls and ends each configuration on its own), so a motion the path simplifier or
    # RRTConnect checks again (about half the rows of the planar plan's transfers) is not
    # evaluated again; the checks are still counted on the budget by the motion validator
    known: dict[bytes, bool] = {}

    def valid_many(rows: Array) -> Array:  # (N, m) -> (N,) bool
        keys = [r.tobytes() for r in rows]
        new = [i for i, k in enumerate(keys) if k not in known]
        if new:
            for i, ok in zip(new, evaluate_many(rows[new]), strict=True):
                known[keys[i]] = bool(ok)
        return np.array([known[k] for k in keys], dtype=bool)

    if not valid_q(start):
        return None
    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)
    space = ob.RealVectorStateSpace(m)
    bounds = ob.RealVectorBounds(m)
    lo = np.maximum(np.minimum(start, q_pre) - np.pi, np.minimum(j_lo, np.minimum(start, q_pre)))
    hi = np.minimum(np.maximum(start, q_pre) + np.pi, np.maximum(j_hi, np.maximum(start, q_pre)))
    for j in range(m):
        bounds.setLow(j, float(lo[j]))
        bounds.setHigh(j, float(hi[j]))
    space.setBounds(bounds)
    s0, s1 = space.allocState(), space.allocState()
    for j in range(m):
        s0[j] = float(start[j])
        s1[j] = float(q_pre[j])
    extent = max(1e-9, float(np.linalg.norm(hi - lo)))
    t0 = time.perf_counter()
    # coarse collision checks while planning (0.05 rad), then the certificate; once more with
    # fine checks (0.01 rad) if the certificate rejects the coarse path
    for resolution in (0.05, 0.01):
        ss = og.SimpleSetup(space)
        budget = CheckBudget(checks, time_limit)
        ss.setStateValidityChecker(budget.counted(lambda s: valid_q(np.array([s[j] for j in range(m)]))))
        si = ss.getSpaceInformation()
        si.setStateValidityCheckingResolution(resolution / extent)
        validator = _SegmentValidator(si, space, m, valid_many, budget)
        si.setMotionValidator(validator)
        ss.setStartAndGoalStates(s0, s1)
        ss.setPlanner(og.RRTConnect(si))
        status = ss.solve(ob.PlannerTerminationCondition(budget.condition()))
        if not bool(status) or not ss.haveExactSolutionPath():
            return None
        ss.simplifySolution(ob.PlannerTerminationCondition(budget.condition()))
        p = ss.getSolutionPath()
        free = np.array([[p.getState(i)[j] for j in range(m)] for i in range(p.getStateCount())])
        waypoints = np.vstack([free, q_goal[None, :]])
        ok, clear, checks = path_clearance_certified(
            model, finger, q_full, waypoints, pos, rot, touching_last=[tip_ref], touch_from=len(free) - 1,
            allowance=allow,
        )
        if ok:
            break
    else:
        return None
    dt = time.perf_counter() - t0
    length = float(np.sum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1)))
    return TransferPath(finger, waypoints, length, clear, checks, dt)


@functools.lru_cache(maxsize=1024)
def _bisection_order(nd: int) -> Array:
    """The order in which OMPL's ``DiscreteMotionValidator`` checks the inner states ``1 .. nd-1``
    of a motion cut into ``nd`` segments: the middle of the range, then the middles of the two
    halves, breadth first (a queue of index ranges). Returns the indices ``(nd - 1,)``."""
    out: list[int] = []
    ranges: deque[tuple[int, int]] = deque([(1, nd - 1)] if nd >= 2 else [])
    while ranges:
        lo, hi = ranges.popleft()
        mid = (lo + hi) // 2
        out.append(mid)
        if lo < mid:
            ranges.append((lo, mid - 1))
        if hi > mid:
            ranges.append((mid + 1, hi))
    return np.array(out, dtype=float)


class _SegmentValidator(ob.MotionValidator):
    """OMPL's ``DiscreteMotionValidator`` with the states of a motion checked at once.

    The same states (the end, then the inner states ``s1 + (s2 - s1) * k / nd`` in
    :func:`_bisection_order`, ``nd`` from the space's ``validSegmentCount``), the same answer,
    and the same number of checks counted on the budget (up to the first invalid state in that
    order, as the discrete validator stops there): RRTConnect and the path simplifier take the
    same steps and end at the same check as with the default validator, only the checks are
    evaluated in one vectorised pass (:meth:`CollisionModel.finger_clearances`)."""

    def __init__(self, si: Any, space: Any, m: int, valid_many: Callable[[Array], Array],
                 budget: CheckBudget) -> None:
        super().__init__(si)
        self._space, self._m, self._valid_many, self._budget = space, m, valid_many, budget

    def checkMotion(self, s1: Any, s2: Any) -> bool:
        # OMPL's bindings expose only this overload to Python (``ob.MotionValidator.checkMotion``
        # takes two states); the one that reports the last valid state is called by planners this
        # module does not use (not RRTConnect, not the path simplifier)
        m = self._m
        a = np.array([s1[j] for j in range(m)])
        b = np.array([s2[j] for j in range(m)])
        nd = int(self._space.validSegmentCount(s1, s2))
        T = _bisection_order(nd) / float(nd)  # (nd - 1,)
        X = np.empty((nd, m))  # end first
        X[0] = b
        X[1:] = a[None, :] + (b - a)[None, :] * T[:, None]
        ok = self._valid_many(X)
        bad = np.flatnonzero(~ok)
        used = len(X) if not len(bad) else int(bad[0]) + 1
        self._budget.used += used
        self._budget.total += used
        return not len(bad)


def _back_off(
    model: CollisionModel,
    finger: int,
    q_full: Array,
    q_goal: Array,
    tip_ref: BodyRef,
    approach: float,
    pos: Array,
    rot: Array,
    allowance: Array | None = None,
) -> Array | None:
    """A configuration near ``q_goal`` whose tip is ``approach`` back along the tip's velocity
    that leaves the surface (least-squares step on the tip Jacobian) and that is collision-free."""
    hand = model.hand
    sl = hand.finger_slice(finger)
    qq = q_full.copy()
    qq[sl] = q_goal
    a, b = hand.body_segment(tip_ref, qq)
    u = (b - a) / max(float(np.linalg.norm(b - a)), 1e-12)  # last link direction, into the object
    for scale in (1.0, 2.0, 4.0):
        x = qq.copy()
        for _ in range(20):  # move the tip back along -u by `approach * scale`
            tip = hand.body_segment(tip_ref, x)[1]
            err = (b - approach * scale * u) - tip
            if np.linalg.norm(err) < 1e-9:
                break
            J = hand.point_jacobian(tip_ref, tip, x)[:, sl]
            x[sl] = np.clip(x[sl] + np.linalg.lstsq(J, err, rcond=None)[0], *joint_limits(hand, finger))
        if model.finger_clearance(finger, x, pos, rot, (), allowance) > 0.0:
            return np.asarray(x[sl])
    return None

