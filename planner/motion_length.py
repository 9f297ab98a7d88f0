"""How far an object motion may go under its one torque (eq. 32 held over a finite motion).

The torque set (32) is computed at the grasp where a motion starts: its recommended member keeps
the sticking contacts' forces as deep inside their friction cones as it can (the margin ``m_0``,
newtons to the nearest facet of the friction set 16). A plan holds that torque constant while the
object moves, and the grasp changes under it: the contact normals turn with the object, the
lever arms with the fingers, so the forces the same torque produces drift towards a facet. In the
nine-contact wrap's lift (examples/sphere_four_finger_wrap.json, FFDFFF, 4.2 cm) the thumb-side
tip f2/3 starts at ``|t|/n = 0.432`` (mu 0.5, ``m_0 = 0.36 N``) and the planned path ends outside
its cone (margin ``-0.012 N``, ``|t|/n = 0.502``); MuJoCo's tip slips about half way, since any
deviation of the hand from the planned path (a finite posture stiffness, soft contacts) moves it
faster towards the facet, and the sphere slides along ``-y`` instead of lifting.

:func:`torque_margins` evaluates the margin with :func:`analysis.torque_forces.torque_forces` (the
forces the torque produces, eq. 29 with ``W_2`` of 22) at the start and the end of an integrated
motion; :func:`held_length` gives the length over which the margin, taken as linear along the
path, stays at least :data:`KEPT_MARGIN` of ``m_0``. The planner ends an object motion there and
re-analyses from the state it reaches (:func:`planner.motion_edges.object_motion_edges`), as it does
for line contacts every ``motion_step``. Only combinations of F- and D-points are measured (an
S-point's kinetic friction depends on its slip at the end of the motion, which the integrated path
does not give), and no line contacts (two or more contacts of one link on one face, Baxter's arms
lying on the box): their forces are ill-conditioned in the rigid model, a link's end points trade
large internal forces, and the margin of the swing's constant torque falls 13.7 N per millimetre
(5.1 N at the start, -118 N after the 1 cm the planner moves such grasps, ``motion_step``), while
MuJoCo's soft contacts replay that swing within 3.1 %; such grasps are re-analysed every
``motion_step`` instead. For the others :func:`torque_margins` returns ``None`` and the motion keeps
its length.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from analysis._types import Array
from analysis.exceptions import CTPError
from analysis.kinematics import HandKinematics
from analysis.pose import Pose
from analysis.scene import Scene
from analysis.torque_forces import torque_forces
from planner.manifold import pose_displacement
from planner.nodes import GraphNodes
from planner.object_motion import corner_normal, keep_contacts, rolled_contacts
from planner.state import GraspContact, GraspState, StateAnalysis

#: an object motion ends where its torque's forces keep at least this fraction of the friction
#: margin they start with (the rest is the room a replay's deviations from the planned hand path
#: use up: on the wrap's lift MuJoCo's tip slipped at about half of the planned path, where the
#: analysis still left 0.16 N of the 0.36 N margin)
KEPT_MARGIN = 0.5


def line_contacts(hand: HandKinematics, contacts: Sequence[GraspContact]) -> bool:
    """Whether a finger link touches the object with two or more of ``contacts`` of one normal (a
    line contact: the detector's end points of a link lying along a face)."""
    seen: dict[tuple[str, tuple[float, ...]], int] = {}
    for c in contacts:
        if hand.finger_of(c.body) is None:
            continue
        key = (c.body, tuple(np.round(np.asarray(c.normal_object, dtype=float), 6)))
        seen[key] = seen.get(key, 0) + 1
    return any(n >= 2 for n in seen.values())


def turned_normals(scene: Scene, hand: HandKinematics, state: GraspState) -> GraspState:
    """The state with the normal of every contact on a vertex or an edge of the object turned to
    the touching body's surface normal (:func:`~planner.object_motion.corner_normal`; the state after
    an object motion, :func:`planner.motion_edges.object_motion_edges`)."""
    out = list(state.contacts)
    for i, c in enumerate(state.contacts):
        ref = hand.resolve_body(c.body)
        if ref is None:
            continue
        n = corner_normal(scene, hand, ref, state.q, state.pose, c.point_object)
        if n is not None:
            out[i] = replace(c, normal_object=n)
    return state.with_contacts(tuple(out))


def waypoint_state(scene: Scene, hand: HandKinematics, state: GraspState, keep: Sequence[int], q: Array,
                   pose: Array) -> GraspState:
    """The grasp reached from ``state`` at a waypoint of an object motion: the hand at ``q``
    ``(M,)``, the object at the pose vector ``pose`` ``(D,)``, only the contacts ``keep`` (sticking:
    glued, or rolled where a disk rolls on a link's side, :func:`planner.object_motion.rolled_contacts`;
    corners' normals turned to the body's face, :func:`turned_normals`), as the planner builds the
    state after a motion."""
    s = pose_displacement(state, pose)  # (D,) the manifold's object coordinates
    moved = state.with_contacts(rolled_contacts(hand, scene, state, keep, q, s), q)
    return turned_normals(scene, hand, keep_contacts(moved.with_pose(Pose.from_vector(pose, state.dim)), keep, q))


def torque_margin(analyse: Callable[[GraspState], StateAnalysis], state: GraspState, combination: str,
                  tau: Array) -> float:
    """The friction margin (newtons, :class:`analysis.torque_forces.TorqueForces`) of the torque
    ``tau`` ``(M,)`` at ``state`` with ``combination`` (``-inf`` where no force produces ``tau``)."""
    p = analyse(state).parts(combination)
    return torque_forces(p.system, p.sel, p.st, p.fs, tau).margin


def torque_margins(nodes: GraphNodes, state: GraspState, combination: str, keep: Sequence[int], q_end: Array,
                   pose_end: Array, tau: Array) -> tuple[float, float] | None:
    """The friction margins ``(m_0, m_end)`` of the torque ``tau`` ``(M,)`` at ``state`` with
    ``combination`` and at the end of a motion (the hand at ``q_end`` ``(M,)``, the object at the pose
    vector ``pose_end`` ``(D,)``, the contacts ``keep`` sticking, :func:`waypoint_state`); ``None``
    for a combination with S- or N-points, for line contacts (:func:`line_contacts`), or an end grasp
    the analysis cannot build (the planner's own checks reject it)."""
    if set(combination) - {"F", "D"} or line_contacts(nodes.hand, [state.contacts[i] for i in keep]):
        return None
    try:
        m0 = torque_margin(nodes.analysis, state, combination, tau)
        end = waypoint_state(nodes.scene, nodes.hand, state, keep, q_end, pose_end)
        return m0, torque_margin(nodes.analysis, end, "F" * len(keep), tau)
    except CTPError:
        return None


def held_length(distance: float, m0: float, m_end: float) -> float:
    """The length ``(0, distance]`` of a motion over which the margin, ``m0`` at the start and
    ``m_end`` after ``distance`` and taken as linear in between, stays at least ``KEPT_MARGIN m0``
    (``distance`` itself when it does all along; ``0`` when ``m0 <= 0``)."""
    if not m0 > 0.0:
        return 0.0
    floor = KEPT_MARGIN * m0
    if m_end >= floor or not np.isfinite(distance):
        return distance
    if not np.isfinite(m_end):
        return 0.5 * distance
    return distance * (m0 - floor) / (m0 - m_end)


__all__ = ["KEPT_MARGIN", "held_length", "line_contacts", "torque_margin", "torque_margins", "turned_normals",
           "waypoint_state"]
