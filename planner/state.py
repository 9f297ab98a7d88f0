"""Grasp states: which bodies touch the object where, the hand configuration and the object pose.

A :class:`GraspState` is a node of the contact-state graph. Each contact is stored twice, in the
frame of the hand body that carries it (``point_body``) and in the object frame
(``point_object``, ``normal_object``), so that after an object motion (paper eq. 30-32) an F-point
keeps both, and after a regrasp (33) the untouched contacts are unchanged.

:func:`state_scene` turns a state back into a validated :class:`analysis.scene.Scene` (contacts in
world coordinates at the state's ``q`` and object pose), and :class:`StateAnalysis` caches the
grasp system and the closure analysis of its combinations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.combination import CombinationParts, CombinationSummary, summarize
from analysis.contacts import GraspSystem, build_system
from analysis.exceptions import NoStationaryGrasp, SceneError
from analysis.geometry import object_origin, object_rotation
from analysis.kinematics import HandKinematics
from analysis.loader import scene_from_dict
from analysis.pose import Pose
from analysis.scene import Scene
from analysis.stationary import StationaryGrasp, stationary_grasp

#: Rounding (scene units / radians) of the node key: states closer than this are one node.
KEY_DECIMALS = 3


@dataclass(frozen=True)
class GraspContact:
    """One contact of a grasp state.

    ``point_body`` ``(3,)`` is the contact point in the frame of ``body`` (a finger link
    ``"finger/k"`` or a fixed body, whose frame is the world); ``point_object`` ``(d,)`` and
    ``normal_object`` ``(d,)`` (unit, into the object) are in the object frame.
    """

    body: str
    point_body: Array  # (3,)
    point_object: Array  # (d,)
    normal_object: Array  # (d,)
    mu: float
    #: index of the scene contact this one is (kept through releases of other fingers and object
    #: motions, moved along when it slides); None for a contact made during the plan, and in
    #: states rebuilt from a plan file (which does not store it). Not part of the node key.
    origin: int | None = None

    def key(self) -> tuple[Any, ...]:
        return (self.body, tuple(np.round(self.point_object, KEY_DECIMALS).tolist()))


@dataclass(frozen=True)
class GraspState:
    """A node of the contact-state graph.

    ``q`` ``(M,)`` is the whole hand's configuration (scene finger order), ``position`` ``(d,)``
    and ``rotation`` ``(3, 3)`` the object pose (``p_o`` and its frame), also as one
    :class:`~analysis.pose.Pose` (:attr:`pose`).
    """

    contacts: tuple[GraspContact, ...]
    q: Array  # (M,)
    position: Array  # (d,)
    rotation: Array  # (3, 3)
    dim: int

    def key(self) -> tuple[Any, ...]:
        """Identity of the node: the contact set (body and object-frame point) and the pose."""
        return self._key

    @cached_property
    def _key(self) -> tuple[Any, ...]:
        """:meth:`key`, computed once (the search asks for it about seven times per state; it reads
        the contacts and the pose, which a state never changes, as :attr:`pose` assumes)."""
        return (
            tuple(sorted(c.key() for c in self.contacts)),
            tuple(np.round(self.pose_vector(), KEY_DECIMALS).tolist()),
        )

    @property
    def L(self) -> int:
        return len(self.contacts)

    @cached_property
    def pose(self) -> Pose:
        """The object pose (``position``, ``rotation``) as one :class:`~analysis.pose.Pose`."""
        return Pose(self.position, self.rotation, self.dim)

    def pose_vector(self) -> Array:
        """2-D ``(x, y, theta)``; 3-D ``(x, y, z, rx, ry, rz)`` (rotation vector)."""
        return self.pose.vector()

    def world_point(self, i: int) -> Array:
        """World position ``(d,)`` of contact ``i`` (object side)."""
        R = self.rotation[: self.dim, : self.dim]
        return self.position + R @ self.contacts[i].point_object

    def world_normal(self, i: int) -> Array:
        R = self.rotation[: self.dim, : self.dim]
        n = R @ self.contacts[i].normal_object
        return n / np.linalg.norm(n)

    def bodies(self) -> tuple[str, ...]:
        return tuple(c.body for c in self.contacts)

    def with_contacts(self, contacts: tuple[GraspContact, ...], q: Array | None = None) -> GraspState:
        return GraspState(contacts, self.q if q is None else np.asarray(q, float), self.position,
                          self.rotation, self.dim)

    def with_pose(self, pose: Pose, q: Array | None = None) -> GraspState:
        """The same contacts with the object at ``pose`` (and the hand at ``q`` if given)."""
        return GraspState(self.contacts, self.q if q is None else q, pose.position, pose.rotation, self.dim)

    def describe(self) -> str:
        return "[" + ", ".join(c.body for c in self.contacts) + "]"


def state_from_scene(scene: Scene, hand: HandKinematics | None = None) -> GraspState:
    """The grasp state of a scene as given (its contacts, ``q`` and object pose)."""
    hand = hand or HandKinematics.from_scene(scene)
    d = scene.dim
    R = object_rotation(scene)
    p_o = object_origin(scene)
    contacts = []
    for i, c in enumerate(scene.contacts):
        ref = hand.resolve_body(c.body)
        assert ref is not None  # validated by Scene
        p = np.asarray(c.point, dtype=float)
        n = np.asarray(c.normal, dtype=float)
        contacts.append(
            GraspContact(
                body=c.body,
                point_body=hand.to_local(ref, p, hand.q0),
                point_object=R[:d, :d].T @ (p - p_o),
                normal_object=R[:d, :d].T @ (n / np.linalg.norm(n)),
                mu=float(c.mu),
                origin=i,
            )
        )
    return GraspState(tuple(contacts), hand.q0.copy(), p_o.copy(), R.copy(), d)


def state_scene_dict(base: Scene, state: GraspState, hand: HandKinematics) -> dict[str, Any]:
    """The scene dictionary of ``state``: ``base`` with the state's pose, ``q`` and contacts."""
    data = base.model_dump(mode="json", exclude_none=True)
    data["object"]["pose"] = state.pose.fields()
    for i, f in enumerate(data["fingers"]):
        f["q"] = [float(x) for x in state.q[hand.finger_slice(i)]]
    data["contacts"] = [
        {
            "body": c.body,
            "point": [float(x) for x in state.world_point(i)],
            "normal": [float(x) for x in state.world_normal(i)],
            "mu": c.mu,
        }
        for i, c in enumerate(state.contacts)
    ]
    return data


def state_scene(base: Scene, state: GraspState, hand: HandKinematics, geometry: bool = True) -> Scene:
    """A validated scene of the state (raises :class:`SceneError` if the state is inconsistent,
    e.g. a contact point no longer on its body's surface). ``geometry = False`` validates the
    model only, not the contacts' geometry (:func:`analysis.loader.check_geometry`): for a state
    whose contacts were all checked already in the same place (:func:`same_geometry`)."""
    if not state.contacts:
        raise SceneError(("contacts",), "a grasp state with no contacts has no scene")
    return scene_from_dict(state_scene_dict(base, state, hand), geometry)


def same_geometry(parent: GraspState, state: GraspState, hand: HandKinematics) -> bool:
    """Whether every contact of ``state`` is a contact of ``parent`` (the same record) on a body
    that is where it was in ``parent`` (a fixed body, or a finger whose joints are those of
    ``parent``), with the object where it was: the geometry of ``state``'s scene, each contact on
    both surfaces with its normal in both normal cones, is then ``parent``'s (a finger released
    and retreated, the others holding on). Exact comparisons: any change means no."""
    if not (np.array_equal(parent.position, state.position) and np.array_equal(parent.rotation, state.rotation)):
        return False
    own = {id(c) for c in parent.contacts}
    for c in state.contacts:
        if id(c) not in own:
            return False
        f = hand.finger_of(c.body)
        if f is not None and not np.array_equal(parent.q[hand.finger_slice(f)], state.q[hand.finger_slice(f)]):
            return False
    return True


@dataclass
class StateAnalysis:
    """The grasp system of one state and cached analyses of its combinations.

    Mutable only through its caches; every cached value is a frozen analysis result.
    """

    state: GraspState
    scene: Scene
    system: GraspSystem
    _parts: dict[str, CombinationParts] = field(default_factory=dict)
    _summaries: dict[str, CombinationSummary] = field(default_factory=dict)
    _grasps: dict[str, StationaryGrasp | None] = field(default_factory=dict)

    @classmethod
    def of(cls, base: Scene, state: GraspState, hand: HandKinematics, geometry: bool = True) -> StateAnalysis:
        """The analysis of ``state`` (its scene's geometry checked unless ``geometry = False``,
        :func:`state_scene`)."""
        scene = state_scene(base, state, hand, geometry)
        return cls(state, scene, build_system(scene, hand, state.q))

    def parts(self, combination: str) -> CombinationParts:
        if combination not in self._parts:
            self._parts[combination] = CombinationParts.build(self.system, combination)
        return self._parts[combination]

    def stationary(self, combination: str) -> StationaryGrasp | None:
        """Eq. (18) for the combination (the most interior solution), or None."""
        if combination not in self._grasps:
            p = self.parts(combination)
            try:
                g: StationaryGrasp | None = stationary_grasp(p.system, p.sel, p.st, p.fs, "interior")
            except NoStationaryGrasp:
                g = None
            self._grasps[combination] = g
        return self._grasps[combination]

    def summary(self, combination: str) -> CombinationSummary:
        """Feasibility (18) + (22) of the combination."""
        if combination not in self._summaries:
            self._summaries[combination] = summarize(
                self.parts(combination), stationary_known=self.stationary(combination) is not None
            )
        return self._summaries[combination]


class AnalysisCache:
    """``StateAnalysis`` per node key, so each state is analysed once per search."""

    def __init__(self, base: Scene, hand: HandKinematics):
        self.base, self.hand = base, hand
        self._cache: dict[tuple[Any, ...], StateAnalysis] = {}
        self.hits = 0
        self.misses = 0

    def __call__(self, state: GraspState, parent: GraspState | None = None) -> StateAnalysis:
        """The analysis of ``state``; with ``parent``, a state whose scene was built and checked in
        this cache, the contacts' geometry is not checked again where it is ``parent``'s
        (:func:`same_geometry`)."""
        k = state.key()
        got = self._cache.get(k)
        if got is None or not np.allclose(got.state.q, state.q):
            self.misses += 1
            known = parent is not None and self._cache.get(parent.key()) is not None and \
                self._cache[parent.key()].state is parent and same_geometry(parent, state, self.hand)
            got = StateAnalysis.of(self.base, state, self.hand, geometry=not known)
            self._cache[k] = got
        else:
            self.hits += 1
        return got


def all_f(state: GraspState) -> str:
    """The combination with every contact sticking (N for frictionless ones)."""
    return "".join("F" if c.mu > 0 else "N" for c in state.contacts)
