"""Scene format: the pydantic models and their structural checks.

A scene is the input of every analysis: the object, the fixed bodies (palm, table), the
fingers (serial chains or URDF), the contacts (order = letters of a combination string) and
the external wrench. The models check what needs no kinematics: types, finite numbers, unit
quaternions and joint axes, vector lengths for ``dim``, shapes that fit ``dim``, unique body
names, counts (``q`` per finger, contacts, joint torque limits). Every check that can fail names
the field it concerns through pydantic's error location, e.g. ``contacts.2.point``.

The geometric checks (contact normals of unit length in the normal cones of the object and of
the body, contact bodies that exist, contact points on the surfaces of their body and of the
object) and loading from JSON/YAML live in :mod:`analysis.loader`. A contact normal off unit
length by at most ``NORMALISE_TOL`` is normalised here and the scene keeps a note of it
(:attr:`Scene.notes`); the loader refuses the others.

Any number of contacts is accepted; only the full enumeration of every combination (``3**L``)
is limited, to ``MAX_CONTACTS``, by :func:`check_enumerable` at its entry points.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    ModelWrapValidatorHandler,
    PrivateAttr,
    Tag,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from analysis.exceptions import SceneError

#: Most contacts a full enumeration takes (it tests up to 3**L combinations); one combination,
#: the kinematic modes and the planner take any number (:func:`check_enumerable`).
MAX_CONTACTS = 16
#: Tolerance on the norm of unit vectors (quaternions, axes; normals after normalisation).
UNIT_TOL = 1e-4
#: Contact normals off unit length by at most this are normalised, with a note (``Scene.notes``).
NORMALISE_TOL = 1e-3
#: Normals off unit length by at most this are unit to the precision of the input: kept as given.
_UNIT_EXACT = 1e-9


def _finite(values: list[float]) -> list[float]:
    for v in values:
        if not math.isfinite(v):
            raise ValueError("must contain finite numbers only (no NaN or inf)")
    return values


#: Largest magnitude of a scene coordinate, angle or wrench component: physically generous
#: (a million metres or newtons), and far inside what the LP solvers take as finite (1e20).
MAX_MAGNITUDE = 1e6
FiniteFloat = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_MAGNITUDE, le=MAX_MAGNITUDE)]
Vec = Annotated[list[FiniteFloat], Field(min_length=1)]
Vec2 = Annotated[list[FiniteFloat], Field(min_length=2, max_length=2)]
Vec3 = Annotated[list[FiniteFloat], Field(min_length=3, max_length=3)]
Quat = Annotated[list[FiniteFloat], Field(min_length=4, max_length=4)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Pose(_Model):
    """Object pose: ``position`` and ``angle`` (2-D) or ``quat_wxyz`` (3-D)."""

    position: Vec
    angle: FiniteFloat | None = None
    quat_wxyz: Quat | None = None

    @field_validator("quat_wxyz")
    @classmethod
    def _unit_quat(cls, q: list[float] | None) -> list[float] | None:
        if q is not None and abs(np.linalg.norm(q) - 1.0) > UNIT_TOL:
            raise ValueError(f"quaternion must have unit norm (norm {np.linalg.norm(q):.6g})")
        return q


class Disk(_Model):
    type: Literal["disk"]
    radius: Annotated[float, Field(gt=0, allow_inf_nan=False)]


class Sphere(_Model):
    type: Literal["sphere"]
    radius: Annotated[float, Field(gt=0, allow_inf_nan=False)]


class Box(_Model):
    """Axis-aligned box (in its own frame) of full extents ``size``, centred at ``position``."""

    type: Literal["box"]
    size: Vec
    position: Vec | None = None

    @field_validator("size")
    @classmethod
    def _positive(cls, s: list[float]) -> list[float]:
        if any(v <= 0 for v in s):
            raise ValueError("box extents must be positive")
        return s


class Polygon(_Model):
    """Convex polygon (2-D), vertices counter-clockwise in the body frame."""

    type: Literal["polygon"]
    vertices: Annotated[list[Vec2], Field(min_length=3)]

    @field_validator("vertices")
    @classmethod
    def _convex_ccw(cls, v: list[list[float]]) -> list[list[float]]:
        # every turn must be to the left: the signed distances assume a convex CCW polygon
        def cross(a: Any, b: Any) -> Any:
            return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]

        V = np.asarray(v, dtype=float)
        e = np.roll(V, -1, axis=0) - V  # edge i: vertex i -> i+1
        turns = cross(e, np.roll(e, -1, axis=0))
        area2 = float(np.sum(cross(V, np.roll(V, -1, axis=0))))
        if np.any(turns < 0.0) or area2 <= 0.0 or np.any(np.linalg.norm(e, axis=1) == 0.0):
            raise ValueError("vertices must form a convex polygon in counter-clockwise order")
        return v


class Cylinder(_Model):
    """Cylinder about the body z axis (3-D)."""

    type: Literal["cylinder"]
    radius: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    height: Annotated[float, Field(gt=0, allow_inf_nan=False)]


class Mesh(_Model):
    """A convex body given by a mesh file (STL or OBJ; its convex hull is the object), 3-D:
    ``file`` is a path (absolute or relative to the current folder) or
    ``"example-robot-data:<path inside robots/>"``; read when the geometry is needed
    (:mod:`analysis.mesh`), which names this field when the file is missing or not a mesh."""

    type: Literal["mesh"]
    file: Annotated[str, Field(min_length=1)]


class Segment(_Model):
    """A segment from ``points[0]`` to ``points[1]`` (fixed bodies only)."""

    type: Literal["segment"]
    points: Annotated[list[Vec], Field(min_length=2, max_length=2)]


ObjectShape = Annotated[Disk | Sphere | Box | Polygon | Cylinder | Mesh, Field(discriminator="type")]
FixedShape = Annotated[Segment | Box | Disk | Sphere | Polygon, Field(discriminator="type")]


class SceneObject(_Model):
    pose: Pose
    shape: ObjectShape


class FixedBody(_Model):
    name: Annotated[str, Field(min_length=1, pattern=r"^[^/]+$")]
    shape: FixedShape
    #: friction coefficient of contacts found on this body (``"contacts": "auto"``); default: the detector's
    mu: Annotated[float, Field(ge=0, le=MAX_MAGNITUDE, allow_inf_nan=False)] | None = None


class Base2D(_Model):
    position: Vec2
    angle: FiniteFloat = 0.0


class Base3D(_Model):
    position: Vec3
    quat_wxyz: Quat = [1.0, 0.0, 0.0, 0.0]

    @field_validator("quat_wxyz")
    @classmethod
    def _unit_quat(cls, q: list[float]) -> list[float]:
        if abs(np.linalg.norm(q) - 1.0) > UNIT_TOL:
            raise ValueError(f"quaternion must have unit norm (norm {np.linalg.norm(q):.6g})")
        return q


class Link2D(_Model):
    length: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    radius: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0


class Joint3D(_Model):
    """Revolute joint: ``origin`` in the previous joint's frame, rotation about ``axis``."""

    axis: Vec3
    origin: Vec3
    radius: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0

    @field_validator("axis")
    @classmethod
    def _unit_axis(cls, a: list[float]) -> list[float]:
        if abs(np.linalg.norm(a) - 1.0) > UNIT_TOL:
            raise ValueError(f"joint axis must be a unit vector (norm {np.linalg.norm(a):.6g})")
        return a


class Finger2D(_Model):
    """Planar serial chain: link k turns by ``q[k]`` relative to link k-1."""

    name: Annotated[str, Field(min_length=1, pattern=r"^[^/]+$")]
    base: Base2D
    links: Annotated[list[Link2D], Field(min_length=1)]
    q: list[FiniteFloat]
    #: friction coefficient of contacts found on this body (``"contacts": "auto"``); default: the detector's
    mu: Annotated[float, Field(ge=0, le=MAX_MAGNITUDE, allow_inf_nan=False)] | None = None

    @model_validator(mode="after")
    def _q_length(self) -> Finger2D:
        if len(self.q) != len(self.links):
            _raise(("q",), f"has {len(self.q)} values but the finger has {len(self.links)} links", self.q)
        return self


class Finger3D(_Model):
    """Spatial serial chain of revolute joints ending at ``tip`` (in the last joint's frame)."""

    name: Annotated[str, Field(min_length=1, pattern=r"^[^/]+$")]
    base: Base3D
    joints: Annotated[list[Joint3D], Field(min_length=1)]
    tip: Vec3
    q: list[FiniteFloat]
    #: friction coefficient of contacts found on this body (``"contacts": "auto"``); default: the detector's
    mu: Annotated[float, Field(ge=0, le=MAX_MAGNITUDE, allow_inf_nan=False)] | None = None

    @model_validator(mode="after")
    def _q_length(self) -> Finger3D:
        if len(self.q) != len(self.joints):
            _raise(("q",), f"has {len(self.q)} values but the finger has {len(self.joints)} joints", self.q)
        return self


class UrdfSpec(_Model):
    file: str
    root_link: str
    tip_link: str
    package_dirs: list[str] = []


class FingerURDF(_Model):
    """A serial chain read from a URDF (root link to tip link), loaded with pinocchio.

    Contacts on it name a link: ``"<finger>/<link name>"``.
    """

    name: Annotated[str, Field(min_length=1, pattern=r"^[^/]+$")]
    base: Base3D
    urdf: UrdfSpec
    q: list[FiniteFloat]
    link_radius: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0
    #: friction coefficient of contacts found on this body (``"contacts": "auto"``); default: the detector's
    mu: Annotated[float, Field(ge=0, le=MAX_MAGNITUDE, allow_inf_nan=False)] | None = None
    #: the links' geometry: capsules of ``link_radius`` about their axes, or the URDF's own
    #: ``<collision>`` shapes (meshes as their convex hulls, boxes, cylinders, spheres)
    link_geometry: Literal["capsule", "urdf"] = "capsule"


def _finger_kind(value: Any) -> str | None:
    """Which finger model a (raw or validated) finger is, from the keys it has, so that an error
    in a finger is reported against that model only (not against every member of the union)."""
    if isinstance(value, BaseModel):
        return type(value).__name__
    if isinstance(value, dict):
        if "urdf" in value:
            return "FingerURDF"
        if "joints" in value:
            return "Finger3D"
        if "links" in value:
            return "Finger2D"
    return None


Finger = Annotated[
    Annotated[Finger2D, Tag("Finger2D")]
    | Annotated[Finger3D, Tag("Finger3D")]
    | Annotated[FingerURDF, Tag("FingerURDF")],
    Discriminator(
        _finger_kind,
        custom_error_type="finger_kind",
        custom_error_message="a finger needs 'links' (planar), 'joints' (spatial) or 'urdf'",
    ),
]
#: Union tags that pydantic inserts into error locations; :func:`clean_loc` drops them.
_UNION_TAGS = {
    *("Finger2D", "Finger3D", "FingerURDF"),
    *("disk", "sphere", "box", "polygon", "cylinder", "mesh", "segment"),
}


class Contact(_Model):
    """A contact: ``point`` (world) on ``body`` and on the object, unit ``normal`` (world) into the
    object, friction coefficient ``mu``. A normal off unit length by ``1e-9 < |norm - 1| <=
    NORMALISE_TOL`` is divided by its norm (``normalised_from`` keeps the norm given)."""

    body: Annotated[str, Field(min_length=1)]
    point: Vec
    normal: Vec
    mu: Annotated[float, Field(ge=0, le=MAX_MAGNITUDE, allow_inf_nan=False)]
    _normalised_from: float | None = PrivateAttr(default=None)

    @model_validator(mode="wrap")
    @classmethod
    def _normalise(cls, data: Any, handler: ModelWrapValidatorHandler[Contact]) -> Contact:
        contact = handler(data)
        norm = math.sqrt(sum(x * x for x in contact.normal))
        if _UNIT_EXACT < abs(norm - 1.0) <= NORMALISE_TOL:
            contact = contact.model_copy(update={"normal": [x / norm for x in contact.normal]})
            contact._normalised_from = norm
        return contact

    @property
    def normalised_from(self) -> float | None:
        """The norm of the normal as given, when it was normalised; else ``None``."""
        return self._normalised_from

    def __eq__(self, other: object) -> bool:
        """Equal fields: the note of a normalisation is not part of the contact (a scene dumped
        and validated again is equal to the scene)."""
        if not isinstance(other, Contact):
            return NotImplemented
        return self.__dict__ == other.__dict__


class Scene(_Model):
    """A hand holding an object: the input of the closure analysis."""

    name: str = "scene"
    description: str = ""
    dim: Literal[2, 3]
    object: SceneObject
    external_wrench: Vec
    fixed_bodies: list[FixedBody] = []
    fingers: list[Finger] = []
    contacts: Annotated[list[Contact], Field(min_length=1)]
    joint_torque_limits: list[Annotated[float, Field(gt=0, allow_inf_nan=False)]] | None = None
    friction_cone_sides: Annotated[int, Field(ge=3, le=64)] = 16

    @property
    def D(self) -> int:
        """Object coordinates: 3 in 2-D, 6 in 3-D."""
        return 3 if self.dim == 2 else 6

    @property
    def d(self) -> int:
        """Force components per contact: 2 in 2-D, 3 in 3-D."""
        return self.dim

    @property
    def M(self) -> int:
        """Total number of joints of the hand (the length of ``q = col[q_i]``)."""
        return int(sum(len(f.q) for f in self.fingers))

    @property
    def notes(self) -> tuple[str, ...]:
        """Corrections made to the input, one line each naming the field (normals normalised)."""
        return tuple(
            f"contacts.{i}.normal: norm {c.normalised_from:.9g} normalised to unit length"
            for i, c in enumerate(self.contacts)
            if c.normalised_from is not None
        )

    @model_validator(mode="after")
    def _check_structure(self) -> Scene:
        errors: list[InitErrorDetails] = []

        def err(loc: tuple[str | int, ...], msg: str, value: Any) -> None:
            errors.append(scene_error_details(loc, msg, value))

        _check_shapes_and_lengths(self, err)
        if errors:
            raise ValidationError.from_exception_data("Scene", errors)
        return self


def check_enumerable(scene: Scene) -> None:
    """Raise :class:`SceneError` at ``contacts`` when the scene has more than ``MAX_CONTACTS``
    contacts: the full enumeration tests up to ``3**L`` combinations. One combination, the
    kinematic contact modes and the planner take any number of contacts."""
    L = len(scene.contacts)
    if L > MAX_CONTACTS:
        raise SceneError(("contacts",), f"has {L} contacts; enumerating every combination (3^{L}) is limited to "
                         f"{MAX_CONTACTS} contacts: analyse one combination, or list the modes (ctp modes)")


def scene_error_details(loc: tuple[str | int, ...], msg: str, value: Any) -> InitErrorDetails:
    """One error of type ``scene`` at ``loc`` (a pydantic error location) with message ``msg``."""
    return InitErrorDetails(type=PydanticCustomError("scene", msg), loc=loc, input=value)


def _raise(loc: tuple[str | int, ...], msg: str, value: Any) -> None:
    raise ValidationError.from_exception_data("Scene", [scene_error_details(loc, msg, value)])


def _check_shapes_and_lengths(scene: Scene, err: Any) -> None:
    dim, D = scene.dim, scene.D
    pose = scene.object.pose
    if len(pose.position) != dim:
        err(("object", "pose", "position"), f"must have {dim} components for dim={dim}", pose.position)
    if dim == 2 and pose.angle is None:
        err(("object", "pose", "angle"), "is required for dim=2", None)
    if dim == 3 and pose.quat_wxyz is None:
        err(("object", "pose", "quat_wxyz"), "is required for dim=3", None)
    shape = scene.object.shape
    if dim == 2 and shape.type in ("sphere", "cylinder"):
        err(("object", "shape", "type"), f"'{shape.type}' is a 3-D shape; use disk/box/polygon", shape.type)
    if dim == 2 and shape.type == "mesh":
        err(("object", "shape", "type"), "'mesh' is a 3-D shape; use disk/box/polygon", shape.type)
    if dim == 3 and shape.type in ("disk", "polygon"):
        err(("object", "shape", "type"), f"'{shape.type}' is a 2-D shape; use sphere/box/cylinder",
            shape.type)
    if isinstance(shape, Box) and len(shape.size) != dim:
        err(("object", "shape", "size"), f"must have {dim} components for dim={dim}", shape.size)
    if len(scene.external_wrench) != D:
        err(("external_wrench",), f"must have {D} components for dim={dim} (force and moment)",
            scene.external_wrench)
    names: set[str] = set()
    for i, fb in enumerate(scene.fixed_bodies):
        if fb.name in names:
            err(("fixed_bodies", i, "name"), f"duplicate body name '{fb.name}'", fb.name)
        names.add(fb.name)
        s = fb.shape
        if isinstance(s, Segment):
            for j, p in enumerate(s.points):
                if len(p) != dim:
                    err(("fixed_bodies", i, "shape", "points", j), f"must have {dim} components", p)
        if isinstance(s, Box):
            if len(s.size) != dim:
                err(("fixed_bodies", i, "shape", "size"), f"must have {dim} components", s.size)
            if s.position is not None and len(s.position) != dim:
                err(("fixed_bodies", i, "shape", "position"), f"must have {dim} components", s.position)
    for i, f in enumerate(scene.fingers):
        if f.name in names:
            err(("fingers", i, "name"), f"duplicate body name '{f.name}'", f.name)
        names.add(f.name)
        if dim == 2 and not isinstance(f, Finger2D):
            err(("fingers", i), "a 2-D scene needs planar fingers (base, links, q)", f.name)
        if dim == 3 and isinstance(f, Finger2D):
            err(("fingers", i), "a 3-D scene needs spatial fingers (joints, tip, q) or urdf", f.name)
    for i, c in enumerate(scene.contacts):
        if len(c.point) != dim:
            err(("contacts", i, "point"), f"must have {dim} components for dim={dim}", c.point)
        if len(c.normal) != dim:
            err(("contacts", i, "normal"), f"must have {dim} components for dim={dim}", c.normal)
    if scene.joint_torque_limits is not None:
        M = scene.M
        if len(scene.joint_torque_limits) != M:
            err(("joint_torque_limits",), f"must have one entry per joint ({M})", scene.joint_torque_limits)


# --------------------------------------------------------------------------------------------
# Error locations


def _format_loc(loc: tuple[str | int, ...]) -> str:
    return ".".join(str(part) for part in loc) if loc else "scene"


def clean_loc(loc: tuple[str | int, ...]) -> tuple[str | int, ...]:
    """Drop the union tags pydantic puts after ``...shape`` and ``fingers.<i>`` in a location."""
    out: list[str | int] = []
    for i, part in enumerate(loc):
        after_shape = i >= 1 and loc[i - 1] == "shape"
        after_finger = i >= 2 and loc[i - 2] == "fingers" and isinstance(loc[i - 1], int)
        if part in _UNION_TAGS and (after_shape or after_finger):
            continue
        out.append(part)
    return tuple(out)


#: The former private name, still imported by the service's error handlers.
_clean_loc = clean_loc


def scene_json_schema() -> dict[str, Any]:
    """The JSON Schema of the scene format (``ctp schema``): ``contacts`` is the list of contacts,
    or ``"auto"`` (also ``[]`` or omitted) to find them from the geometry (``ctp contacts``)."""
    schema = Scene.model_json_schema()
    listed = schema["properties"]["contacts"]
    schema["properties"]["contacts"] = {
        "title": listed.get("title", "Contacts"),
        "description": "the contacts (order = letters of a combination string), or \"auto\" (or [], or omitted): "
                       "found from the geometry at the scene's configuration",
        "anyOf": [{k: v for k, v in listed.items() if k != "title"} | {"minItems": 0},
                  {"const": "auto", "type": "string"}],
    }
    schema["required"] = [r for r in schema.get("required", []) if r != "contacts"]
    return schema


__all__ = [
    "MAX_CONTACTS",
    "NORMALISE_TOL",
    "UNIT_TOL",
    "Contact",
    "Finger2D",
    "Finger3D",
    "FingerURDF",
    "FixedBody",
    "Scene",
    "_format_loc",
    "check_enumerable",
    "clean_loc",
    "scene_error_details",
    "scene_json_schema",
]
