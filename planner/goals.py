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

from analysis._types import Array
from analysis.dafc import dafc_set
from analysis.dpfc import dpfc
from analysis.exceptions import CTPError, SceneError
from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.pose import Pose
from analysis.scene import Scene
from planner.state import GraspContact, GraspState, StateAnalysis, all_f

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class Goal(BaseModel):
    """Where the search stops.

    * ``active``: the object can be moved in every direction (motion space of dimension D and
      DAFC the whole sphere);
    * ``passive``: DPFC balances every wrench of ``wrenches`` (default: the external wrench and
      its negative) without changing the joint torques;
    * ``combination``: the scene's contacts in the states of ``combination``, one letter per contact
      of the *scene* (its order), see :func:`combination_reached`: every ``D`` contact released
      (no longer touching), every other one still touching (sticking contacts at the same point,
      sliding ones where they slid), no contact made during the plan, and the remaining contacts
      hold the object with those letters (the stationary grasp, 18; with ``S`` letters also a
      non-empty DAFC, 22: they can slide). The scene's own grasp reaches ``FF...F``;
    * ``fingertips``: every finger touches the object, each only with the tip of its last link
      (contacts on fixed bodies such as the palm may remain), and the contacts hold the object
      (a stationary grasp, 18): a regrasp from an enveloping grasp to a fingertip grasp (the
      paper's Fig. 5, steps 1 to 3, the palm still holding);
    * ``displacement``: the object moved by ``displacement`` from its pose in the scene (2-D
      ``[dx, dy, dtheta]``, 3-D ``[dx, dy, dz, wx, wy, wz]``, ``w`` a world rotation vector:
      :meth:`analysis.pose.Pose.displaced`), "push by dx" ``[-0.1, 0, 0, 0, 0, 0]``, "lift by dz"
      ``[0, 0, 0.03, 0, 0, 0]``; the planner turns it into the ``pose`` goal of that pose
      (:meth:`Goal.resolved`), with the same tolerances;
    * ``pose``: the object pose ``pose`` (2-D ``[x, y, theta]``, 3-D ``[x, y, z, rx, ry, rz]`` with
      a rotation vector): the position within ``position_tolerance`` (scene units, metres for
      robot scenes; default :data:`DEFAULT_POSITION_TOLERANCE` object sizes,
      :func:`analysis.geometry.object_size`) and the rotation within ``rotation_tolerance``
      (radians, the angle of the rotation between the two poses; default
      :data:`DEFAULT_ROTATION_TOLERANCE`; ``"free"``: any rotation). ``tolerance`` is the older
      single field: when given it is the default of both (scene units and radians), so goals
      written with it keep working (each error is now compared with it on its own, no longer
      their Euclidean norm). ``free_axes`` (pose and displacement goals) leaves the object's
      position free along those world axes (``["x", "y"]``: "lift by dz" wherever the lift swings
      the box sideways, as two arms hugging it do): the position error and the displacement still
      to go count the other axes only;
    * ``contact``: the finger link ``body`` touches the object at the world point ``point`` (within
      ``position_tolerance``, default as for a pose) and the contacts hold the object (18): an arm
      moves its contact to a new place, e.g. by sliding it along a face
      (:mod:`planner.link_slide`, with ``contact_slides``).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    type: Literal["active", "passive", "combination", "pose", "fingertips", "displacement", "contact"]
    combination: Annotated[str, Field(min_length=1, pattern=r"^[FNSDfnsd]+$")] | None = None
    pose: list[FiniteFloat] | None = None
    displacement: list[FiniteFloat] | None = None
    tolerance: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    position_tolerance: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    rotation_tolerance: Annotated[float, Field(gt=0, allow_inf_nan=False)] | Literal["free"] | None = None
    wrenches: list[list[FiniteFloat]] | None = None
    body: str | None = None
    point: list[FiniteFloat] | None = None
    free_axes: list[Literal["x", "y", "z"]] | None = None

    @model_validator(mode="after")
    def _fields_for_type(self) -> Goal:
        if self.free_axes is not None:
            if self.type not in ("pose", "displacement"):
                raise ValueError("free_axes is for goal types 'pose' and 'displacement'")
            if len(set(self.free_axes)) != len(self.free_axes):
                raise ValueError(f"free_axes {self.free_axes} names an axis twice")
            values = self.pose if self.pose is not None else self.displacement
            if values is not None and len(values) == 3 and "z" in self.free_axes:
                raise ValueError("free_axes: a 2-D goal has the axes 'x' and 'y' only")
        if self.type == "combination" and self.combination is None:
            raise ValueError("goal type 'combination' needs the field 'combination' (e.g. \"FSDD\")")
        if self.type == "pose" and self.pose is None:
            raise ValueError("goal type 'pose' needs the field 'pose'")
        if self.pose is not None and len(self.pose) not in (3, 6):
            raise ValueError("pose must have 3 (2-D: x, y, theta) or 6 (3-D: x, y, z, rotation vector) values")
        if self.type == "displacement" and self.displacement is None:
            raise ValueError("goal type 'displacement' needs the field 'displacement' (e.g. [-0.1, 0, 0, 0, 0, 0])")
        if self.type == "contact" and (self.body is None or self.point is None):
            raise ValueError("goal type 'contact' needs the fields 'body' (a finger link) and 'point' (world)")
        if self.displacement is not None and len(self.displacement) not in (3, 6):
            raise ValueError("displacement must have 3 (2-D: dx, dy, dtheta) or 6 (3-D: dx, dy, dz, rotation "
                             "vector) values")
        return self

    def resolved(self, start: Pose) -> Goal:
        """The goal for an object that starts at ``start``: a ``displacement`` goal becomes the
        ``pose`` goal of ``start`` displaced by it (:meth:`analysis.pose.Pose.displaced`), the same
        tolerances; any other goal is returned as it is."""
        if self.type != "displacement":
            return self
        assert self.displacement is not None
        target = start.displaced(np.asarray(self.displacement, dtype=float))
        return self.model_copy(update={"type": "pose", "pose": [float(v) for v in target.vector()],
                                       "displacement": None})

    def position_tol(self, size: float) -> float:
        """The position tolerance in scene units, for an object of size ``size``."""
        if self.position_tolerance is not None:
            return float(self.position_tolerance)
        if self.tolerance is not None:
            return float(self.tolerance)
        return DEFAULT_POSITION_TOLERANCE * float(size)

    def rotation_tol(self) -> float | None:
        """The rotation tolerance in radians, ``None`` when the rotation is free."""
        if self.rotation_tolerance == "free":
            return None
        if self.rotation_tolerance is not None:
            return float(self.rotation_tolerance)
        if self.tolerance is not None:
            return float(self.tolerance)
        return DEFAULT_ROTATION_TOLERANCE


#: default position tolerance of a pose goal, in object sizes (:func:`analysis.geometry.object_size`):
#: 1 % (3.2 mm for the 0.3 x 0.4 x 0.4 m box, whose 3 cm lift the start does not meet)
DEFAULT_POSITION_TOLERANCE = 0.01
#: default rotation tolerance of a pose goal, radians (about 2.9 degrees)
DEFAULT_ROTATION_TOLERANCE = 0.05


def pose_errors(goal: Goal, state: GraspState) -> tuple[float, float]:
    """Position error (scene units) and rotation error (radians, the angle of the rotation from
    the goal's orientation to the state's) of ``state`` against a pose goal."""
    assert goal.pose is not None
    target = Pose.from_vector(goal.pose, state.dim)
    off = (state.pose.position - target.position) * position_mask(goal, state.dim)  # (dim,)
    return float(np.linalg.norm(off)), state.pose.rotation_angle_to(target)


def position_mask(goal: Goal, dim: int) -> Array:
    """``(dim,)`` 1 for the world axes whose position the goal fixes, 0 for its ``free_axes``."""
    free = set(goal.free_axes or ())
    return np.array([0.0 if a in free else 1.0 for a in "xyz"[:dim]])


def pose_goal_remaining(goal: Goal, state: GraspState) -> Array:
    """The displacement ``(D,)`` still to go to a pose goal (pose-vector difference; the rotation
    part zero when the goal leaves the rotation free, the position along its ``free_axes`` zero)."""
    assert goal.pose is not None
    rest = np.asarray(goal.pose, float) - state.pose_vector()
    if state.dim == 2:
        rest[2] = (rest[2] + np.pi) % (2 * np.pi) - np.pi
    if goal.rotation_tol() is None:
        rest[state.dim:] = 0.0
    rest[: state.dim] *= position_mask(goal, state.dim)
    return rest


def check_combination(goal: Goal, scene: Scene) -> None:
    """A combination goal that fits the scene: one letter per scene contact, ``F``/``S``/``D`` for a
    contact with friction and ``N``/``D`` for a frictionless one; else :class:`SceneError` at
    ``("goal", "combination")``."""
    if goal.combination is None:
        return
    comb = goal.combination
    if any(ch not in "FNSDfnsd" for ch in comb):
        raise SceneError(("goal", "combination"), "letters must be F, N, S or D")
    if len(comb) != len(scene.contacts):
        raise SceneError(("goal", "combination"), f"'{comb}' has {len(comb)} letters; the scene has "
                         f"{len(scene.contacts)} contacts (one letter per contact, in the scene's order)")
    for i, (ch, c) in enumerate(zip(comb.upper(), scene.contacts, strict=True)):
        if c.mu > 0 and ch == "N":
            raise SceneError(("goal", "combination"), f"letter {i} is N but contact {i} ({c.body}) has friction "
                             f"(mu = {c.mu:g}): use F, S or D")
        if c.mu <= 0 and ch in "FS":
            raise SceneError(("goal", "combination"), f"letter {i} is {ch} but contact {i} ({c.body}) is "
                             "frictionless (mu = 0): use N or D")


def combination_reached(goal: Goal, state: GraspState, analysis: Callable[[GraspState], StateAnalysis]) -> bool:
    """A combination goal (one letter per contact of the scene) in ``state``: the contacts of the
    state are exactly the scene's contacts whose letter is not ``D`` (followed through the plan by
    :attr:`~planner.state.GraspContact.origin`: kept by releases of other fingers, by object
    motions, moved along when they slide); a contact made during the plan, or a scene contact
    marked ``D`` that still touches, does not match. The remaining contacts, with their letters,
    must hold the object (18); with ``S`` letters the combination must also be feasible (22
    non-empty: those contacts can slide)."""
    assert goal.combination is not None
    comb = goal.combination.upper()
    origins = [c.origin for c in state.contacts]
    if any(o is None or o >= len(comb) for o in origins):
        return False
    kept = [i for i, ch in enumerate(comb) if ch != "D"]
    if sorted(o for o in origins if o is not None) != kept:
        return False
    letters = "".join(comb[o] for o in origins if o is not None)
    if not letters:
        return False
    try:
        sa = analysis(state)
        if sa.stationary(letters) is None:
            return False
        return "S" not in letters or sa.summary(letters).feasible
    except CTPError:
        return False


def contact_reached(goal: Goal, state: GraspState, analysis: Callable[[GraspState], StateAnalysis],
                    size: float | None = None) -> bool:
    """A contact goal in ``state``: a contact of ``goal.body`` within the position tolerance of
    ``goal.point`` (world) and a stationary grasp (18) of all the contacts."""
    assert goal.body is not None and goal.point is not None
    target = np.asarray(goal.point, dtype=float)
    near = [i for i, c in enumerate(state.contacts) if c.body == goal.body]
    if not near:
        return False
    if size is None:
        size = object_size(analysis(state).scene)
    if min(float(np.linalg.norm(state.world_point(i) - target)) for i in near) > goal.position_tol(size):
        return False
    try:
        return analysis(state).stationary(all_f(state)) is not None
    except CTPError:
        return False


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
                 analysis: Callable[[GraspState], StateAnalysis], dafc_samples: int = 64,
                 size: float | None = None) -> bool:
    """Is the goal satisfied in ``state``? (active: a~ = D and every sampled direction in DAFC of
    the all-F combination; passive: DPFC (28) of the all-F combination contains every wrench;
    fingertips: every finger touches with its tip only and (18) holds;
    combination: :func:`combination_reached`; pose: position and rotation each within its
    tolerance). ``analysis`` gives the (cached) analysis of a state; ``size`` is the object size
    (:func:`analysis.geometry.object_size`) of the default position tolerance (default: from the
    state's analysis). A ``displacement`` goal is first resolved against the start pose
    (:meth:`Goal.resolved`, as :func:`planner.plan.plan` does); testing it unresolved is an error."""
    if goal.type == "displacement":
        raise SceneError(("goal", "type"), "a displacement goal is tested after Goal.resolved(start pose) turns it "
                         "into a pose goal")
    if goal.type == "pose":
        if size is None:
            size = object_size(analysis(state).scene)
        pos, rot = pose_errors(goal, state)
        rot_tol = goal.rotation_tol()
        return pos <= goal.position_tol(size) and (rot_tol is None or rot <= rot_tol)
    if goal.type == "fingertips":
        fingers = {hand.finger_of(c.body) for c in state.contacts} - {None}
        if len(fingers) < len(hand.fingers):
            return False
        if not all(is_fingertip(hand, c) for c in state.contacts if hand.finger_of(c.body) is not None):
            return False
        return analysis(state).stationary(all_f(state)) is not None
    if goal.type == "combination":
        return combination_reached(goal, state, analysis)
    if goal.type == "contact":
        return contact_reached(goal, state, analysis, size)
    sa = analysis(state)
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
