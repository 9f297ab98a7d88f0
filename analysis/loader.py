"""Loading a scene (JSON or YAML) and its geometric validation.

:mod:`analysis.scene` checks a scene's structure (types, lengths, counts, names). What needs the
hand's kinematics (:mod:`analysis.kinematics`) and the shapes' signed distances
(:mod:`analysis.geometry`) is checked here, after the model, contact by contact in scene order;
the first failing check of a contact is reported and the next contact is checked:

* the normal ``n`` has unit length (within ``UNIT_TOL``; the model normalised those off by at most
  ``NORMALISE_TOL``, with a note in ``Scene.notes``);
* the body names a fixed body or a body ``"<finger>/<k>"`` (``"<finger>/<link>"`` for URDF);
* the point ``p_C`` lies on the surface of its body (a link's axis inflated by its radius, the
  link's URDF collision shapes where its finger says ``"link_geometry": "urdf"``, or a fixed
  body's shape) and on the object's surface (a mesh: its convex hull), within ``GEOMETRY_TOL``;
* the normal lies in the normal cones at ``p_C`` (:mod:`analysis.geometry`), within
  ``NORMAL_CONE_TOL`` (the sine of the angle to the cone): ``-n`` in the object's, and ``n`` in
  a link's within ``BODY_NORMAL_CONE_TOL`` (3 deg: link capsules model real links). At a smooth
  point that is the surface normal; at a box vertex or edge, a polygon corner or a cylinder rim,
  any direction between the faces' normals (a cube's corner on a table takes the table's
  normal). The cones take every feature within ``GEOMETRY_TOL`` of the point.

A finger that cannot be built (a URDF that does not load) is reported instead of every contact
check. Errors are :class:`SceneError` whose ``loc`` names the field (``contacts.2.point``) and
whose ``errors`` list every failure with pydantic's keys (``type``, ``loc``, ``msg``, ``input``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np
import yaml
from pydantic import ValidationError
from pydantic_core import InitErrorDetails

from analysis._types import Array
from analysis.detect import DEFAULT_MU, DEFAULT_TOLERANCE, Detection, UnplacedScene, detect_contacts
from analysis.exceptions import SceneError
from analysis.geometry import (
    NormalCone,
    body_normal_cone,
    body_surface_distance,
    object_normal_cone,
    object_signed_distance,
)
from analysis.kinematics import HandKinematics
from analysis.scene import NORMALISE_TOL, UNIT_TOL, Scene, clean_loc, scene_error_details

#: Absolute tolerance (scene length units) for "a point lies on a surface".
GEOMETRY_TOL = 1e-4
#: Largest distance of a unit contact normal to a normal cone (about the angle, in radians).
NORMAL_CONE_TOL = 1e-3
#: ... to a link's normal cone (a fixed body's: ``NORMAL_CONE_TOL``): sin 3 deg, as the link is a
#: capsule model of a real link and the planner places fingertips by inverse kinematics to
#: GEOMETRY_TOL. The object's normal defines the contact frame.
BODY_NORMAL_CONE_TOL = float(np.sin(np.radians(3.0)))

__all__ = [
    "BODY_NORMAL_CONE_TOL",
    "FILE_ERROR",
    "GEOMETRY_TOL",
    "MAX_SCENE_BYTES",
    "MAX_SCENE_DEPTH",
    "MAX_YAML_ALIASES",
    "MAX_YAML_NODES",
    "NORMAL_CONE_TOL",
    "YAML_LOADERS",
    "check_geometry",
    "geometry_errors",
    "load_scene",
    "parse_scene_data",
    "parse_scene_text",
    "read_scene_data",
    "scene_from_dict",
    "wants_detection",
    "with_detected_contacts",
]


def _contact_errors(scene: Scene) -> list[InitErrorDetails]:
    errors: list[InitErrorDetails] = []

    def err(loc: tuple[str | int, ...], msg: str, value: Any) -> None:
        errors.append(scene_error_details(loc, msg, value))

    try:
        hand = HandKinematics.from_scene(scene)
    except SceneError as e:
        err(tuple(e.loc), e.reason, None)
        return errors
    for i, c in enumerate(scene.contacts):
        n = np.asarray(c.normal, dtype=float)
        p = np.asarray(c.point, dtype=float)
        norm = float(np.linalg.norm(n))
        if abs(norm - 1.0) > UNIT_TOL:
            err(("contacts", i, "normal"), f"must be a unit vector (norm {norm:.6g}; normals within "
                f"{NORMALISE_TOL:g} of unit length are normalised)", c.normal)
            continue
        ref = hand.resolve_body(c.body)
        if ref is None:
            err(("contacts", i, "body"), f"unknown body '{c.body}' (known: {', '.join(hand.body_names())})",
                c.body)
            continue
        dist = body_surface_distance(scene, hand, ref, p)
        if dist is not None and abs(dist) > GEOMETRY_TOL:
            err(("contacts", i, "point"), f"is {abs(dist):.4g} away from the surface of body '{c.body}'",
                c.point)
            continue
        sd = object_signed_distance(scene, p)
        if sd is not None and abs(sd) > GEOMETRY_TOL:
            err(("contacts", i, "point"), f"is {abs(sd):.4g} away from the object's surface", c.point)
            continue
        u = n / norm  # unit: outward of the body, into the object
        cone = object_normal_cone(scene, p, GEOMETRY_TOL)
        if cone is not None and not cone.contains(-u, NORMAL_CONE_TOL):
            why = _cone_message(cone, -u, "into the object", "of the object", "outward")
            err(("contacts", i, "normal"), why, c.normal)
            continue
        cone = body_normal_cone(scene, hand, ref, p, GEOMETRY_TOL)
        if cone is not None and not cone.contains(u, NORMAL_CONE_TOL if ref.is_fixed else BODY_NORMAL_CONE_TOL):
            why = _cone_message(cone, u, f"out of body '{c.body}'", f"of body '{c.body}'", "into the body")
            err(("contacts", i, "normal"), why, c.normal)
    return errors


def _cone_message(cone: NormalCone, u: Array, into: str, of: str, wrong_way: str) -> str:
    """Why the outward direction ``u`` ``(d,)`` is not in ``cone``: it points the wrong way (no
    positive component along any face normal), or by how many degrees it misses the cone."""
    if cone.generators.shape[0] == 0 or float(np.max(cone.generators @ u)) <= 0.0:
        return f"must point {into} (it points {wrong_way})"
    angle = float(np.degrees(np.arcsin(min(cone.distance(u), 1.0))))
    kind = "surface normal" if cone.generators.shape[0] == 1 else "normal cone"
    return f"must point {into}: it is {angle:.3g} deg off the {kind} {of} at the point"


def _as_errors(e: ValidationError) -> list[dict[str, Any]]:
    """pydantic's error dicts with the union tags dropped from every ``loc``."""
    return [{**err, "loc": clean_loc(tuple(err["loc"]))} for err in e.errors()]


def _first_error(errors: list[dict[str, Any]]) -> SceneError:
    first = errors[0]
    return SceneError(tuple(first["loc"]), first["msg"], errors=errors)


def geometry_errors(scene: Scene) -> list[dict[str, Any]]:
    """Every geometric error of a structurally valid scene (see the module docstring), as
    pydantic-style dicts (``type`` ``"scene"``, ``loc`` relative to the scene, ``msg``,
    ``input``); empty when the scene is valid."""
    details = _contact_errors(scene)
    if not details:
        return []
    return _as_errors(ValidationError.from_exception_data("Scene", details))


def check_geometry(scene: Scene) -> None:
    """Raise :class:`SceneError` naming the first geometric error (``errors`` lists them all)."""
    errors = geometry_errors(scene)
    if errors:
        raise _first_error(errors) from None


def wants_detection(data: Any) -> TypeGuard[dict[str, Any]]:
    """Whether a parsed scene leaves its contacts to the detector (:mod:`analysis.detect`):
    ``contacts`` omitted, ``[]`` or ``"auto"``."""
    return isinstance(data, dict) and ("contacts" not in data or data["contacts"] == [] or data["contacts"] == "auto")


def with_detected_contacts(data: dict[str, Any], *, tolerance: float = DEFAULT_TOLERANCE,
                           mu: float = DEFAULT_MU) -> tuple[dict[str, Any], Detection]:
    """The parsed scene ``data`` with its ``contacts`` replaced by those the detector finds at its
    configuration, and the detection (near misses included). The rest of the scene is validated
    first (SceneError naming its first bad field); SceneError at ``contacts`` when the object
    touches nothing within ``tolerance``, and when a body within ``tolerance`` is farther than
    ``GEOMETRY_TOL`` from the object or penetrates it deeper than that (its contact would fail the
    check that a point lies on both surfaces). The result is not yet geometrically checked."""
    try:
        draft = UnplacedScene.model_validate({**data, "contacts": []})
    except ValidationError as e:
        raise _first_error(_as_errors(e)) from None
    detection = detect_contacts(draft, tolerance=tolerance, mu=mu)
    if not detection.contacts:
        given = "omitted" if "contacts" not in data else f"{data['contacts']!r}"
        nearest = ("" if detection.nearest is None else
                   f"; the nearest body is '{detection.nearest[0]}' at {detection.nearest[1]:.4g}")
        raise SceneError(("contacts",), f"{given}, so contacts are found from the geometry, but the object "
                         f"touches nothing within {tolerance:g}{nearest}")
    apart = [c for c in detection.contacts if abs(c.gap) > GEOMETRY_TOL]
    if apart:
        c = max(apart, key=lambda c: abs(c.gap))
        if c.gap < 0:
            raise SceneError(("contacts",), f"'{c.body}' penetrates the object by {-c.gap:.4g}; a contact must "
                             f"lie on both surfaces within {GEOMETRY_TOL:g}: move the body out of the object")
        raise SceneError(("contacts",), f"'{c.body}' is within the tolerance {tolerance:g} of the object but "
                         f"{c.gap:.4g} away from it; a contact must lie on both surfaces within "
                         f"{GEOMETRY_TOL:g}: move the body onto the object, or give a tolerance below "
                         f"{c.gap:.4g} to list it as a near miss")
    return {**data, "contacts": [c.to_json() for c in detection.contacts]}, detection


def scene_from_dict(data: Any, geometry: bool = True) -> Scene:
    """Validate a parsed scene (the model, then :func:`check_geometry`); raise
    :class:`SceneError` naming the first bad field. Contacts omitted, ``[]`` or ``"auto"`` are
    found from the geometry first (:func:`with_detected_contacts`, default tolerance and ``mu``).
    ``geometry = False`` validates the model only: for a caller that knows the contacts' geometry
    holds (the planner's grasp states whose contacts were all checked in the same place)."""
    if isinstance(data, Scene):
        return data  # pydantic does not validate a model instance again; neither does this
    if wants_detection(data):
        data, _ = with_detected_contacts(data)
    try:
        scene = Scene.model_validate(data)
    except ValidationError as e:
        raise _first_error(_as_errors(e)) from None
    if geometry:
        check_geometry(scene)
    return scene


# --------------------------------------------------------------------------------------------
# Scene text: the one parser every entry point uses (CLI commands, batch, the service's upload)

#: Largest scene file read (bytes); the service passes its own ``max_body_bytes``.
MAX_SCENE_BYTES = 10_000_000
#: Deepest nesting of lists and mappings in a scene file (a scene needs about 6).
MAX_SCENE_DEPTH = 64
#: Most YAML aliases (``*name``) in one file: a scene has little to repeat, and each alias
#: multiplies what is built (an "alias bomb" of 9 levels of 6 aliases is 10 million nodes).
MAX_YAML_ALIASES = 32
#: Most nodes of a YAML document once its aliases are counted as copies.
MAX_YAML_NODES = 200_000

#: ``SceneError.errors`` type of a file that cannot be read as a scene file (size, encoding,
#: syntax, nesting, YAML aliases, a value JSON does not have), as opposed to a bad scene field
FILE_ERROR = "scene_file"

#: Readable names of the YAML values that have no JSON counterpart.
_NON_JSON = {"date": "a YAML date", "datetime": "a YAML timestamp", "bytes": "YAML !!binary data",
             "set": "a YAML !!set", "tuple": "a YAML pair (!!omap or !!pairs)"}


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _number_message(e: Exception) -> str:
    text = _one_line(str(e))
    return "a number of more than 4300 digits" if "digits" in text else text


def _yaml_message(e: yaml.YAMLError) -> str:
    """A YAML error on one line: what is wrong and where (line and column, 1-based)."""
    if isinstance(e, yaml.MarkedYAMLError):
        mark = e.problem_mark or e.context_mark
        what = e.problem or e.context or "invalid YAML"
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        return _one_line(f"{where}{what}")
    return _one_line(str(e))


class _ComposeLimits:
    """Depth and alias limits checked while a YAML node graph is composed, before any Python
    object is built (aliases are shared nodes until then, so the check is cheap whatever they
    would expand to). Composition pulls the parser's events one at a time, so a document nested
    too deeply is refused after ``MAX_SCENE_DEPTH`` levels, whatever follows."""

    _depth = 0
    _aliases = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):  # type: ignore[attr-defined]
            self._aliases += 1
            if self._aliases > MAX_YAML_ALIASES:
                mark = self.peek_event().start_mark  # type: ignore[attr-defined]
                raise SceneError((), f"cannot parse YAML: line {mark.line + 1}: more than {MAX_YAML_ALIASES} "
                                     "aliases (*name); write the values out")
        self._depth += 1
        try:
            if self._depth > MAX_SCENE_DEPTH:
                mark = self.peek_event().start_mark  # type: ignore[attr-defined]
                raise SceneError((), f"cannot parse YAML: line {mark.line + 1}: nested more than "
                                     f"{MAX_SCENE_DEPTH} levels deep")
            return super().compose_node(parent, index)  # type: ignore[misc]
        finally:
            self._depth -= 1


class _LimitedLoader(_ComposeLimits, yaml.SafeLoader):
    """PyYAML's pure-Python safe loader with the limits above; its scanner also refuses deep
    flow nesting while it scans (it looks ahead through every open ``[`` or ``{`` for each token)."""

    def fetch_flow_collection_start(self, TokenClass: Any) -> None:
        if self.flow_level >= MAX_SCENE_DEPTH:
            mark = self.get_mark()
            raise SceneError((), f"cannot parse YAML: line {mark.line + 1}: nested more than "
                                 f"{MAX_SCENE_DEPTH} levels deep")
        super().fetch_flow_collection_start(TokenClass)

    def add_indent(self, column: int) -> bool:
        if len(self.indents) >= MAX_SCENE_DEPTH:
            mark = self.get_mark()
            raise SceneError((), f"cannot parse YAML: line {mark.line + 1}: nested more than "
                                 f"{MAX_SCENE_DEPTH} levels deep")
        return bool(super().add_indent(column))


if yaml.__with_libyaml__:
    from yaml._yaml import CParser
    from yaml.composer import Composer
    from yaml.constructor import SafeConstructor
    from yaml.resolver import Resolver

    class _FastLimitedLoader(_ComposeLimits, Composer, CParser, SafeConstructor, Resolver):
        """libyaml's scanner and parser (C: some six times faster than PyYAML's own, which
        holds the GIL for 10 s on a 480 kB file) under the same Python composer and limits
        (Composer's ``get_single_node`` comes before CParser's in the method order, so the
        events are composed here, one at a time, with :class:`_ComposeLimits`)."""

        def __init__(self, stream: str):
            CParser.__init__(self, stream)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)
            Composer.__init__(self)

    YAML_LOADERS: tuple[type, ...] = (_FastLimitedLoader, _LimitedLoader)
else:  # pragma: no cover - PyYAML built without libyaml
    YAML_LOADERS = (_LimitedLoader,)


def _check_unique_keys(node: yaml.MappingNode) -> None:
    """SceneError naming the line of a key written twice in one YAML mapping (PyYAML keeps the
    last one silently, so a scene's first ``contacts:`` would be lost without a word). Merge
    keys (``<<``) are left to the constructor."""
    seen: dict[tuple[str, str], int] = {}
    for key, _ in node.value:
        if not isinstance(key, yaml.ScalarNode) or key.tag == "tag:yaml.org,2002:merge":
            continue
        line = key.start_mark.line + 1
        if (key.tag, key.value) in seen:
            raise SceneError((), f"cannot parse YAML: line {line}, column {key.start_mark.column + 1}: "
                                 f"duplicate key {key.value!r} "
                                 f"(first written at line {seen[key.tag, key.value]}); write each key once")
        seen[key.tag, key.value] = line


def _unique_json_object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """``object_pairs_hook`` for :func:`json.loads`: SceneError for a key written twice in one
    object (the standard library keeps the last one silently)."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise SceneError((), f"cannot parse JSON: duplicate key {key!r} in one object; write each key once")
        out[key] = value
    return out


def _expanded_size(root: yaml.Node) -> int:
    """Nodes of a composed YAML graph with every alias counted as a copy (iterative, memoised
    per node: linear in the graph, not in its expansion); SceneError for a recursive alias."""
    sizes: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    open_: set[int] = set()
    while stack:
        node, done = stack.pop()
        key = id(node)
        if key in sizes:
            continue
        children: list[yaml.Node] = []
        if isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        elif isinstance(node, yaml.MappingNode):
            if not done:
                _check_unique_keys(node)
            children = [n for pair in node.value for n in pair]
        if done:
            open_.discard(key)
            sizes[key] = 1 + sum(sizes[id(c)] for c in children)
            if sizes[key] > MAX_YAML_NODES:
                raise SceneError((), f"cannot parse YAML: its aliases expand to more than {MAX_YAML_NODES} values")
            continue
        if key in open_:
            raise SceneError((), "cannot parse YAML: an alias refers to a node that contains it (recursive)")
        open_.add(key)
        stack.append((node, True))
        for c in children:
            if id(c) in open_:
                raise SceneError((), "cannot parse YAML: an alias refers to a node that contains it (recursive)")
            if id(c) not in sizes:
                stack.append((c, False))
    return sizes[id(root)]


def _check_json_values(data: Any) -> None:
    """Raise SceneError naming the first value that is not JSON (a YAML date, binary, set, a
    mapping key that is not a string) or the place nested deeper than ``MAX_SCENE_DEPTH``."""
    stack: list[tuple[Any, tuple[str | int, ...]]] = [(data, ())]
    while stack:
        value, loc = stack.pop()
        if len(loc) > MAX_SCENE_DEPTH:
            raise SceneError((), f"nested more than {MAX_SCENE_DEPTH} levels deep")
        if isinstance(value, dict):
            for k, v in value.items():
                if not isinstance(k, str):
                    raise SceneError(loc, f"mapping key {k!r} is not a string (quote it)")
                stack.append((v, (*loc, k)))
        elif isinstance(value, list):
            stack.extend((v, (*loc, i)) for i, v in enumerate(value))
        elif value is None or isinstance(value, str | bool | int | float):
            continue
        else:
            kind = _NON_JSON.get(type(value).__name__, f"a {type(value).__name__}")
            raise SceneError(loc, f"{kind} is not a JSON value (quote it, or write it as a number, string or list)")


def parse_scene_data(source: str | bytes, suffix: str = ".json", *, max_bytes: int = MAX_SCENE_BYTES,
                     yaml_loader: type | None = None) -> Any:
    """The parsed content of a scene file (JSON, or YAML for ``.yaml``/``.yml``), JSON types
    only, without validating it as a scene. Raises :class:`SceneError` (one line) for: more
    than ``max_bytes``, bytes that are not UTF-8, a syntax error (with line and column),
    nesting deeper than ``MAX_SCENE_DEPTH``, more than ``MAX_YAML_ALIASES`` aliases or an
    expansion over ``MAX_YAML_NODES``, a value JSON does not have (a YAML date, ``!!binary``,
    ``!!set``; ``loc`` names it; the error's item ``type`` is :data:`FILE_ERROR`). Bounded in
    time and memory by the size of ``source``. YAML is read by libyaml where PyYAML has it
    (``yaml_loader`` picks one of :data:`YAML_LOADERS`)."""
    try:
        return _parse(source, suffix, max_bytes, yaml_loader)
    except SceneError as e:
        raise SceneError(e.loc, e.reason, [{"loc": list(e.loc), "msg": e.reason, "type": FILE_ERROR}]) from None


def _parse(source: str | bytes, suffix: str, max_bytes: int, yaml_loader: type | None) -> Any:
    kind = "YAML" if suffix.lower() in (".yaml", ".yml") else "JSON"
    size = len(source) if isinstance(source, bytes) else len(source.encode("utf-8", "surrogatepass"))
    if size > max_bytes:
        raise SceneError((), f"file too large: {size} bytes; the limit is {max_bytes} bytes")
    if isinstance(source, bytes):
        try:
            text = source.decode("utf-8")
        except UnicodeDecodeError as e:
            raise SceneError((), f"cannot parse {kind}: not UTF-8 text (byte {e.start})") from None
    else:
        text = source
    if "\x00" in text:
        raise SceneError((), f"cannot parse {kind}: binary data (a NUL character), not a text file")
    if kind == "JSON":
        try:
            data = json.loads(text, object_pairs_hook=_unique_json_object)
        except SceneError:
            raise
        except json.JSONDecodeError as e:
            raise SceneError((), f"cannot parse JSON: line {e.lineno}, column {e.colno}: {e.msg}") from None
        except RecursionError:
            raise SceneError((), f"cannot parse JSON: nested more than {MAX_SCENE_DEPTH} levels deep") from None
        except ValueError as e:  # an integer of more than 4300 digits
            raise SceneError((), f"cannot parse JSON: {_number_message(e)}") from None
    else:
        loader = (yaml_loader or YAML_LOADERS[0])(text)
        try:
            node = loader.get_single_node()
            if node is None:
                data = None
            else:
                _expanded_size(node)
                data = loader.construct_document(node)
        except SceneError:
            raise
        except yaml.YAMLError as e:
            raise SceneError((), f"cannot parse YAML: {_yaml_message(e)}") from None
        except (ValueError, OverflowError, TypeError) as e:  # a value the constructor cannot build
            raise SceneError((), f"cannot parse YAML: {_number_message(e)}") from None
        except RecursionError:
            raise SceneError((), f"cannot parse YAML: nested more than {MAX_SCENE_DEPTH} levels deep") from None
        finally:
            loader.dispose()
    _check_json_values(data)
    return data


def parse_scene_text(text: str | bytes, suffix: str = ".json", *, max_bytes: int = MAX_SCENE_BYTES) -> Scene:
    """A validated scene from the text of a scene file (:func:`parse_scene_data`, then
    :func:`scene_from_dict`); :class:`SceneError` names the bad field."""
    return scene_from_dict(parse_scene_data(text, suffix, max_bytes=max_bytes))


def read_scene_data(path: str | Path, *, max_bytes: int = MAX_SCENE_BYTES) -> Any:
    """:func:`parse_scene_data` of a file; SceneError when it cannot be read (no traceback)."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise SceneError((), f"file too large: {size} bytes; the limit is {max_bytes} bytes")
        raw = path.read_bytes()
    except OSError as e:
        raise SceneError((), f"cannot read {path}: {e.strerror or e}") from None
    return parse_scene_data(raw, path.suffix.lower(), max_bytes=max_bytes)


def load_scene(path: str | Path, *, max_bytes: int = MAX_SCENE_BYTES) -> Scene:
    """Load a scene from a ``.json``, ``.yaml`` or ``.yml`` file."""
    return scene_from_dict(read_scene_data(path, max_bytes=max_bytes))
