"""Goals of a plan: the closure the grasp should reach, and the tests of a state against it.

:class:`Goal` is the request (active or passive closure, a combination, a fingertip grasp, an
object pose); :func:`goal_reached` tests a grasp state against it with the closure analysis
(active: eq. 22 over a sample of directions, :func:`closure_is_active`; passive: DPFC, eq. 28;
fingertips: the stationary grasp, eq. 18), and :func:`goal_heuristic` is the search's lower
bound of the cost still to go.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from analysis.dafc import dafc_set
from analysis.dpfc import dpfc
from analysis.exceptions import CTPError
from analysis.kinematics import HandKinematics
from planner.state import GraspContact, GraspState, StateAnalysis, all_f

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class Goal(BaseModel):
    """Where the search stops.

    * ``active``: the object can be moved in every direction (motion space of dimension D and
      DAFC the whole sphere);
    * ``passive``: DPFC balances every wrench of ``wrenches`` (default: the external wrench and
      its negative) without changing the joint torques;
    * ``combination``: a named contact-state combination (one letter per contact of the scene
      the search reached), ``combination`` field;
    * ``fingertips``: every finger touches the object, each only with the tip of its last link
      (contacts on fixed bodies such as the palm may remain), and the contacts hold the object
      (a stationary grasp, 18): a regrasp from an enveloping grasp to a fingertip grasp (the
      paper's Fig. 5, steps 1 to 3, the palm still holding);
    * ``pose``: the object pose ``pose`` (2-D ``[x, y, theta]``, 3-D ``[x, y, z, rx, ry, rz]`` with
      a rotation vector) within ``tolerance`` (Euclidean, scene units and radians).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    type: Literal["active", "passive", "combination", "pose", "fingertips"]
    combination: Annotated[str, Field(min_length=1, pattern=r"^[FNSDfnsd]+$")] | None = None
    pose: list[FiniteFloat] | None = None
    tolerance: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 0.05
    wrenches: list[list[FiniteFloat]] | None = None

    @model_validator(mode="after")
    def _fields_for_type(self) -> Goal:
        if self.type == "combination" and self.combination is None:
            raise ValueError("goal type 'combination' needs the field 'combination' (e.g. \"FSDD\")")
        if self.type == "pose" and self.pose is None:
            raise ValueError("goal type 'pose' needs the field 'pose'")
        if self.pose is not None and len(self.pose) not in (3, 6):
            raise ValueError("pose must have 3 (2-D: x, y, theta) or 6 (3-D: x, y, z, rotation vector) values")
        return self


def is_fingertip(hand: HandKinematics, c: GraspContact) -> bool:
    """A contact near the distal end of the last link of its finger."""
    ref = hand.resolve_body(c.body)
    if ref is None or ref.finger is None:
        return False
    chain = hand.fingers[ref.finger]
    if ref.link >= chain.n_joints:
        return True  # a link beyond the last joint (a URDF tip link) is the tip
    if ref.link != chain.n_joints - 1:
        return False
    a, b = chain.body_segment(ref.link, hand.q0[hand.finger_slice(ref.finger)])
    R, o = chain.body_pose(ref.link, hand.q0[hand.finger_slice(ref.finger)])
    tip_local = R.T @ (b - o)
    length = float(np.linalg.norm(b - a))
    return float(np.linalg.norm(c.point_body - tip_local)) <= 0.1 * length + hand.body_radius(ref) + 1e-9


def goal_reached(goal: Goal, state: GraspState, hand: HandKinematics,
                 analysis: Callable[[GraspState], StateAnalysis], dafc_samples: int = 64) -> bool:
    """Is the goal satisfied in ``state``? (active: a~ = D and every sampled direction in DAFC of
    the all-F combination; passive: DPFC (28) of the all-F combination contains every wrench;
    fingertips: every finger touches with its tip only and (18) holds;
    combination: that combination is feasible; pose: within tolerance). ``analysis`` gives the
    (cached) analysis of a state."""
    if goal.type == "pose":
        assert goal.pose is not None
        diff = np.asarray(goal.pose, float) - state.pose_vector()
        if state.dim == 2:
            diff[2] = (diff[2] + np.pi) % (2 * np.pi) - np.pi
        return float(np.linalg.norm(diff)) <= goal.tolerance
    if goal.type == "fingertips":
        fingers = {hand.finger_of(c.body) for c in state.contacts} - {None}
        if len(fingers) < len(hand.fingers):
            return False
        if not all(is_fingertip(hand, c) for c in state.contacts if hand.finger_of(c.body) is not None):
            return False
        return analysis(state).stationary(all_f(state)) is not None
    sa = analysis(state)
    if goal.type == "combination":
        assert goal.combination is not None
        comb = goal.combination.upper()
        if len(comb) != state.L:
            return False
        try:
            return sa.summary(comb).feasible
        except CTPError:
            return False
    comb = all_f(state)
    if goal.type == "active":
        return closure_is_active(sa, comb, dafc_samples)
    grasp = sa.stationary(comb)
    if grasp is None:
        return False
    p = sa.parts(comb)
    region = dpfc(p.st, p.fs, grasp)
    ws = goal.wrenches or [list(sa.system.w_ex), list(-sa.system.w_ex)]
    return all(region.contains(np.asarray(w, float), p.st, p.fs, grasp) for w in ws)


def closure_is_active(sa: StateAnalysis, comb: str, samples: int = 64) -> bool:
    """Active closure of a combination: motion space of dimension D (``a~ = D``), a stationary
    grasp, and every direction of a seeded sample of the unit sphere (plus the axes) in DAFC."""
    p = sa.parts(comb)
    if p.ms.a_bar != p.system.D or sa.stationary(comb) is None:
        return False
    oracle = p.oracle()
    ds = dafc_set(oracle, samples=samples, refine=0)
    if ds.directions.shape[0] == 0 or not bool(np.all(ds.member)):
        return False
    axes = np.vstack([np.eye(p.system.D), -np.eye(p.system.D)])
    return all(oracle.test(a).member for a in axes)


def goal_heuristic(goal: Goal, state: GraspState, hand: HandKinematics, weight: float) -> float:
    """A* lower bound of the cost from ``state`` to the goal (see
    :attr:`planner.options.PlannerOptions.heuristic_weight`): ``active``, ``weight`` per fingertip
    contact still missing (2 in 2-D, 3 in 3-D) plus one if a fixed body still touches;
    ``fingertips``, ``weight`` per finger not yet touching with its tip only; 0 otherwise."""
    if goal.type not in ("active", "fingertips") or weight == 0.0:
        return 0.0
    if goal.type == "fingertips":  # fingers still to (re)grasp with their tip
        done = {f for f in range(len(hand.fingers))
                if (cs := [c for c in state.contacts if hand.finger_of(c.body) == f])
                and all(is_fingertip(hand, c) for c in cs)}
        return weight * (len(hand.fingers) - len(done))
    need = 2 if state.dim == 2 else 3
    tips = sum(is_fingertip(hand, c) for c in state.contacts)
    fixed = any(hand.finger_of(c.body) is None for c in state.contacts)
    return weight * (max(0, need - tips) + int(fixed))
