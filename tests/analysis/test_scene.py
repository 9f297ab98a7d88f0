"""Scene format: canonical scenes load unchanged, JSON == YAML, the JSON Schema, and one clear
error naming the field for every kind of bad input (``SceneError.loc`` + "field.path: reason")."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from analysis.exceptions import SceneError
from analysis.loader import check_geometry, geometry_errors, load_scene, parse_scene_text, scene_from_dict
from analysis.scene import (
    MAX_CONTACTS,
    Finger2D,
    Finger3D,
    FingerURDF,
    Scene,
    check_enumerable,
    scene_json_schema,
)

REPO = Path(__file__).parents[2]
SHARED_SCENES = REPO.parent / "shared" / "scenes"
EXAMPLES = REPO / "examples"
SCENE_SUFFIXES = (".json", ".yaml", ".yml")


def _scene_files(folder: Path) -> list[Path]:
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in SCENE_SUFFIXES)


def _params(folder: Path) -> list[Any]:
    files = _scene_files(folder)
    if not files:
        return [pytest.param(None, marks=pytest.mark.skip(reason=f"no scene files in {folder}"))]
    return [pytest.param(p, id=p.name) for p in files]


def _raw(path: Path) -> dict[str, Any]:
    text = path.read_text()
    data = yaml.safe_load(text) if path.suffix.lower() in (".yaml", ".yml") else json.loads(text)
    assert isinstance(data, dict)
    return data


PLANAR = EXAMPLES / "planar_disk_envelope.json"
SPATIAL = EXAMPLES / "sphere_four_finger_palm.json"


@pytest.fixture
def planar() -> dict[str, Any]:
    return _raw(PLANAR)


@pytest.fixture
def spatial() -> dict[str, Any]:
    return _raw(SPATIAL)


# --------------------------------------------------------------------------------------------
# Canonical scenes


def _check_loads_unchanged(path: Path) -> None:
    raw = _raw(path)
    scene = load_scene(path)
    assert isinstance(scene, Scene)
    # the file's content is what the model holds (nothing dropped, renamed or rewritten)
    assert scene.dim == raw["dim"]
    assert scene.name == raw.get("name", "scene")
    assert scene.external_wrench == pytest.approx(raw["external_wrench"], abs=0.0)
    assert [c.body for c in scene.contacts] == [c["body"] for c in raw["contacts"]]
    for c, rc in zip(scene.contacts, raw["contacts"], strict=True):
        assert c.point == pytest.approx(rc["point"], abs=0.0)
        assert c.normal == pytest.approx(rc["normal"], abs=0.0)
        assert c.mu == rc["mu"]
    assert [f.name for f in scene.fingers] == [f["name"] for f in raw.get("fingers", [])]
    assert [f.q for f in scene.fingers] == [f["q"] for f in raw.get("fingers", [])]
    finger_types = (Finger2D,) if scene.dim == 2 else (Finger3D, FingerURDF)
    assert all(isinstance(f, finger_types) for f in scene.fingers)
    # the dumped model validates again to an equal scene
    assert scene_from_dict(scene.model_dump()) == scene
    assert scene_from_dict(json.loads(scene.model_dump_json())) == scene


@pytest.mark.parametrize("path", _params(SHARED_SCENES))
def test_shared_canonical_scene_loads_unchanged(path: Path) -> None:
    _check_loads_unchanged(path)


@pytest.mark.parametrize("path", _params(EXAMPLES))
def test_example_scene_loads_unchanged(path: Path) -> None:
    _check_loads_unchanged(path)


def test_examples_exist_and_cover_both_dimensions() -> None:
    files = _scene_files(EXAMPLES)
    assert len(files) >= 2, "examples/ must hold the canonical scenes"
    assert {load_scene(p).dim for p in files} == {2, 3}


@pytest.mark.parametrize("path", _params(SHARED_SCENES))
def test_example_copies_match_the_shared_scenes(path: Path) -> None:
    copy_ = EXAMPLES / path.name
    if not copy_.exists():
        pytest.skip(f"{path.name} has no copy in examples/")
    assert load_scene(copy_) == load_scene(path)


@pytest.mark.parametrize("path", _params(EXAMPLES))
def test_json_and_yaml_give_equal_scenes(path: Path, tmp_path: Path) -> None:
    raw = _raw(path)
    from_json = load_scene(path)
    for suffix in (".yaml", ".yml"):
        target = tmp_path / f"scene{suffix}"
        target.write_text(yaml.safe_dump(raw, sort_keys=False))
        assert load_scene(target) == from_json
    assert parse_scene_text(yaml.safe_dump(raw, default_flow_style=True), ".yaml") == from_json
    assert parse_scene_text(path.read_text(), ".json") == from_json


HANDWRITTEN_YAML = """\
# a disk resting on a table, held from the right by a one-link finger
dim: 2
object:
  pose: {position: [0.0, 0.5], angle: 0.0}
  shape: {type: disk, radius: 0.5}
external_wrench: [0.0, -1.0, 0.0]
fixed_bodies:
  - name: table
    shape:
      type: segment
      points: [[-1.0, 0.0], [1.0, 0.0]]
fingers:
  - name: right
    base: {position: [0.5, 0.0]}
    links: [{length: 1.0}]
    q: [1.5707963267948966]
contacts:
  - {body: table, point: [0.0, 0.0], normal: [0.0, 1.0], mu: 0.3}
  - {body: right/0, point: [0.5, 0.5], normal: [-1.0, 0.0], mu: 0.3}
"""


def test_handwritten_yaml_equals_its_json_twin() -> None:
    from_yaml = parse_scene_text(HANDWRITTEN_YAML, ".yaml")
    twin = json.dumps(yaml.safe_load(HANDWRITTEN_YAML))
    assert parse_scene_text(twin, ".json") == from_yaml
    right = from_yaml.fingers[0]
    assert isinstance(right, Finger2D)
    assert right.base.angle == 0.0  # default filled in
    assert from_yaml.friction_cone_sides == 16
    assert (from_yaml.D, from_yaml.d) == (3, 2)


def test_load_scene_reports_missing_file_and_bad_syntax(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="cannot read"):
        load_scene(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    with pytest.raises(SceneError, match="cannot parse JSON"):
        load_scene(bad)
    bad_yaml = tmp_path / "bad.yaml"
    bad_yaml.write_text("dim: [2\n")
    with pytest.raises(SceneError, match="cannot parse YAML"):
        load_scene(bad_yaml)


# --------------------------------------------------------------------------------------------
# JSON Schema

#: Keywords of JSON Schema (draft 2020-12) plus the annotations pydantic emits.
_SCHEMA_KEYWORDS = {
    "$defs",
    "$ref",
    "$schema",
    "$id",
    "additionalProperties",
    "allOf",
    "anyOf",
    "const",
    "default",
    "description",
    "discriminator",
    "enum",
    "examples",
    "exclusiveMaximum",
    "exclusiveMinimum",
    "format",
    "items",
    "maxItems",
    "maxLength",
    "maximum",
    "minItems",
    "minLength",
    "minimum",
    "oneOf",
    "pattern",
    "prefixItems",
    "properties",
    "required",
    "title",
    "type",
}
_JSON_TYPES = {"object", "array", "string", "number", "integer", "boolean", "null"}


def _walk_schema(node: Any, defs: dict[str, Any], refs: list[str]) -> None:
    assert isinstance(node, dict), node
    for key, value in node.items():
        assert key in _SCHEMA_KEYWORDS, f"unknown JSON-Schema keyword {key!r}"
        if key in ("properties", "$defs"):
            for sub in value.values():
                _walk_schema(sub, defs, refs)
        elif key in ("items", "additionalProperties") and isinstance(value, dict):
            _walk_schema(value, defs, refs)
        elif key in ("anyOf", "oneOf", "allOf", "prefixItems"):
            for sub in value:
                _walk_schema(sub, defs, refs)
        elif key == "$ref":
            assert value.startswith("#/$defs/")
            refs.append(value)
        elif key == "type":
            types = value if isinstance(value, list) else [value]
            assert set(types) <= _JSON_TYPES
        elif key == "required":
            assert set(value) <= set(node.get("properties", {}))


def test_scene_json_schema_is_a_valid_schema_mentioning_the_fields() -> None:
    schema = scene_json_schema()
    json.dumps(schema)  # serialisable
    assert schema["type"] == "object"
    refs: list[str] = []
    defs = schema.get("$defs", {})
    _walk_schema(schema, defs, refs)
    assert refs and all(r.removeprefix("#/$defs/") in defs for r in refs)
    props = schema["properties"]
    for field in (
        "dim",
        "object",
        "external_wrench",
        "fixed_bodies",
        "fingers",
        "contacts",
        "joint_torque_limits",
        "friction_cone_sides",
    ):
        assert field in props, field
    assert {"dim", "object", "external_wrench"} <= set(schema["required"])
    assert "contacts" not in schema["required"]  # omitted: found from the geometry
    assert set(defs["Contact"]["properties"]) == {"body", "point", "normal", "mu"}
    assert defs["Contact"]["properties"]["mu"]["minimum"] == 0
    assert set(defs["Finger2D"]["properties"]) >= {"name", "base", "links", "q"}
    assert set(defs["Finger3D"]["properties"]) >= {"name", "base", "joints", "tip", "q"}
    assert "urdf" in defs["FingerURDF"]["properties"]
    assert props["dim"]["enum"] == [2, 3]
    text = json.dumps(schema)
    for shape in ("disk", "sphere", "box", "polygon", "cylinder", "mesh", "segment"):
        assert f'"{shape}"' in text
    assert defs["FingerURDF"]["properties"]["link_geometry"]["enum"] == ["capsule", "urdf"]


def test_scene_json_schema_accepts_contacts_auto_and_refuses_other_strings() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(scene_json_schema())
    data = json.loads((EXAMPLES / "planar_disk_envelope.json").read_text())
    assert not list(validator.iter_errors(data))
    options: list[str | list[Any]] = ["auto", []]
    for contacts in options:
        assert not list(validator.iter_errors({**data, "contacts": contacts}))
    assert not list(validator.iter_errors({k: v for k, v in data.items() if k != "contacts"}))
    errors = list(validator.iter_errors({**data, "contacts": "manual"}))
    assert errors and errors[0].path[0] == "contacts"


# --------------------------------------------------------------------------------------------
# Bad input: one clear message naming the field


def _expect_error(data: dict[str, Any], loc: tuple[str | int, ...], *fragments: str) -> SceneError:
    with pytest.raises(SceneError) as info:
        scene_from_dict(data)
    e = info.value
    assert e.loc == loc, str(e)
    where = ".".join(str(p) for p in loc)
    assert str(e).startswith(f"{where}: "), str(e)
    for frag in fragments:
        assert frag in str(e), f"{frag!r} not in {e}"
    assert len(e.errors) == 1, f"expected one error, got {e.errors}"
    assert tuple(e.errors[0]["loc"]) == loc
    return e


def _mutated(base: dict[str, Any], change: Callable[[dict[str, Any]], None]) -> dict[str, Any]:
    data = copy.deepcopy(base)
    change(data)
    return data


def test_valid_bases_load(planar: dict[str, Any], spatial: dict[str, Any]) -> None:
    # every bad-input test below changes exactly one thing of these
    assert scene_from_dict(planar).dim == 2
    assert scene_from_dict(spatial).dim == 3


def test_non_unit_normal(planar: dict[str, Any], spatial: dict[str, Any]) -> None:
    planar["contacts"][1]["normal"] = [0.6, -1.2]
    _expect_error(planar, ("contacts", 1, "normal"), "unit vector", "1.34164")
    spatial["contacts"][0]["normal"] = [0.0, 0.0, -1.1]
    _expect_error(spatial, ("contacts", 0, "normal"), "unit vector", "1.1")


@pytest.mark.parametrize("scale", [1 + 5e-5, 1 - 9e-4, 1 + 9.9e-4])
def test_slightly_off_unit_normal_is_normalised_with_a_note(planar: dict[str, Any], scale: float) -> None:
    n = planar["contacts"][4]["normal"]  # (0, 1): the palm under the disk
    planar["contacts"][4]["normal"] = [n[0], n[1] * scale]
    scene = scene_from_dict(planar)
    assert scene.contacts[4].normal == [0.0, 1.0]
    assert scene.contacts[4].normalised_from == pytest.approx(scale, abs=1e-15)
    assert scene.notes == (f"contacts.4.normal: norm {scale:.9g} normalised to unit length",)
    again = scene_from_dict(scene.model_dump())  # unit now: no note, and an equal scene
    assert again.notes == () and again == scene
    assert scene_from_dict(_raw(PLANAR)).notes == ()  # unit to 1e-9 as given: kept, no note


def test_normal_off_unit_length_by_more_than_1e_3_is_refused(planar: dict[str, Any]) -> None:
    planar["contacts"][4]["normal"] = [0.0, 1.0 + 1.1e-3]
    _expect_error(planar, ("contacts", 4, "normal"), "unit vector", "1.0011")


def test_outward_normal(planar: dict[str, Any], spatial: dict[str, Any]) -> None:
    nx, ny = planar["contacts"][0]["normal"]
    planar["contacts"][0]["normal"] = [-nx, -ny]
    _expect_error(planar, ("contacts", 0, "normal"), "into the object", "outward")
    spatial["contacts"][4]["normal"] = [0.0, 0.0, -1.0]
    _expect_error(spatial, ("contacts", 4, "normal"), "into the object")


# --------------------------------------------------------------------------------------------
# Vertex, edge and face contacts: a normal is valid in the normal cones at its point


TABLE = {"name": "table", "shape": {"type": "box", "size": [4.0, 4.0, 0.1], "position": [0.0, 0.0, -0.05]}}


def _cube_scene(contacts: list[dict[str, Any]], quat: list[float] | None = None, z: float = 0.5,
                fingers: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """A unit cube centred at ``(0, 0, z)`` on a table (the box under ``z = 0``)."""
    return {
        "dim": 3,
        "object": {"pose": {"position": [0.0, 0.0, z], "quat_wxyz": quat or [1.0, 0.0, 0.0, 0.0]},
                   "shape": {"type": "box", "size": [1.0, 1.0, 1.0]}},
        "external_wrench": [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
        "fixed_bodies": [TABLE],
        "fingers": fingers or [],
        "contacts": contacts,
    }


def _table_contact(x: float, y: float, normal: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> dict[str, Any]:
    return {"body": "table", "point": [x, y, 0.0], "normal": list(normal), "mu": 0.5}


def test_face_face_contact_at_the_four_corners_is_accepted() -> None:
    scene = scene_from_dict(_cube_scene([_table_contact(x, y) for x in (-0.5, 0.5) for y in (-0.5, 0.5)]))
    assert len(scene.contacts) == 4 and scene.notes == ()


def test_cube_corner_with_the_tables_normal_is_accepted() -> None:
    # the case: the corner (-0.5, -0.5, -0.5) of a unit cube (here on the table at z = 0)
    corner = scene_from_dict(_cube_scene([_table_contact(-0.5, -0.5)]))
    assert corner.contacts[0].normal == [0.0, 0.0, 1.0]


def test_polygon_corner_and_cylinder_rim_on_a_table_are_accepted() -> None:
    # a square's corner on a table: the step along the normal would land on its left edge
    square = _polygon_scene([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    square["contacts"] = [{"body": "table", "point": [x, 0.0], "normal": [0.0, 1.0], "mu": 0.3} for x in (-0.5, 0.5)]
    assert len(scene_from_dict(square).contacts) == 2
    square["contacts"][0]["normal"] = [0.6, 0.8]  # in the corner's cone, but not the table's
    _expect_error(square, ("contacts", 0, "normal"), "36.9 deg off the normal cone of body 'table'")  # both sides
    can = _cube_scene([_table_contact(0.3, 0.4), _table_contact(-0.5, 0.0)], z=1.0)
    can["object"]["shape"] = {"type": "cylinder", "radius": 0.5, "height": 2.0}  # upright, on its rim
    assert len(scene_from_dict(can).contacts) == 2


def test_a_tilted_normal_is_refused_by_the_cone_it_misses() -> None:
    t = np.radians(2.0)
    tilted = (float(np.sin(t)), 0.0, float(np.cos(t)))
    # inside the corner's cone, outside the table's (its top face: one ray)
    _expect_error(_cube_scene([_table_contact(-0.5, -0.5, tilted)]), ("contacts", 0, "normal"),
                  "must point out of body 'table'", "2 deg off the surface normal of body 'table'")
    # at a face point of the cube it also misses the cube's face normal (checked first)
    _expect_error(_cube_scene([_table_contact(0.1, 0.2, tilted)]), ("contacts", 0, "normal"),
                  "must point into the object", "2 deg off the surface normal of the object")
    _expect_error(_cube_scene([_table_contact(0.1, 0.2, (0.0, 0.0, -1.0))]), ("contacts", 0, "normal"),
                  "into the object (it points outward)")


def test_box_on_a_table_on_one_edge() -> None:
    """The cube turned 45 deg about y stands on its edge (local x = +0.5, z = -0.5), centre at
    z = sqrt(1/2): the edge's cone, spanned by (c, 0, -c) and (-c, 0, -c), holds the table's
    -(0, 0, 1); the two ends of the edge are vertex contacts."""
    quat = [float(np.cos(np.pi / 8)), 0.0, float(np.sin(np.pi / 8)), 0.0]
    data = _cube_scene([_table_contact(0.0, y) for y in (-0.5, 0.2, 0.5)], quat=quat, z=float(np.sqrt(0.5)))
    assert len(scene_from_dict(data).contacts) == 3
    off = copy.deepcopy(data)
    off["contacts"][1]["point"] = [0.05, 0.2, 0.0]  # beside the edge: off the cube's surface
    _expect_error(off, ("contacts", 1, "point"), "away from the object's surface")


def _link(name: str, start: list[float], direction: list[float], radius: float) -> dict[str, Any]:
    """A one-joint finger whose link (a capsule of ``radius``) runs from ``start`` along the unit
    ``direction`` for length 1."""
    return {"name": name, "base": {"position": start, "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
            "joints": [{"axis": [0.0, 0.0, 1.0], "origin": [0.0, 0.0, 0.0], "radius": radius}],
            "tip": direction, "q": [0.0]}


@pytest.mark.parametrize(("corner", "radial"), [((0.5, 0.5, 1.0), (1, 1, 1)), ((-0.5, 0.5, 1.0), (-1, 1, 1))])
def test_box_corner_against_a_link(corner: tuple[float, ...], radial: tuple[int, ...]) -> None:
    """A capsule (radius 0.05) whose axis passes 0.05 from a top corner along the corner's
    diagonal ``radial``, perpendicular to it: the contact normal is the capsule's radial direction
    -radial/sqrt(3), inside the corner's cone (the three face normals). A normal along a face
    diagonal is in the corner's cone too but 35.26 deg off the capsule's: refused by the link."""
    r = 0.05
    d = np.asarray(radial, dtype=float) / np.sqrt(3)
    axis = np.array([d[1], -d[0], 0.0]) / np.linalg.norm(d[:2])  # perpendicular to the diagonal
    centre = np.asarray(corner) + r * d
    finger = _link("arm", (centre - 0.5 * axis).tolist(), axis.tolist(), r)
    contact = {"body": "arm/0", "point": list(corner), "normal": (-d).tolist(), "mu": 0.5}
    scene = scene_from_dict(_cube_scene([_table_contact(0.0, 0.0), contact], fingers=[finger]))
    assert scene.contacts[1].normal == pytest.approx((-d).tolist(), abs=1e-15)
    face_diagonal = -np.array([d[0], d[1], 0.0]) / np.linalg.norm(d[:2])
    contact["normal"] = face_diagonal.tolist()
    _expect_error(_cube_scene([_table_contact(0.0, 0.0), contact], fingers=[finger]), ("contacts", 1, "normal"),
                  "must point out of body 'arm/0'", "35.3 deg off the surface normal of body 'arm/0'")


def test_box_edge_across_a_link() -> None:
    """A forearm (capsule, radius 0.04) across the top edge x = 0.5, z = 1 of the cube, its axis
    along (1, 0, -1)/sqrt(2) and 0.04 from the edge along (1, 0, 1)/sqrt(2): an edge-link contact
    with the normal -(1, 0, 1)/sqrt(2). The same contact with the top face's normal is in the
    edge's cone but not the capsule's (45 deg off)."""
    r = 0.04
    n_out = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    axis = np.array([1.0, 0.0, -1.0]) / np.sqrt(2)
    edge_point = np.array([0.5, 0.1, 1.0])
    finger = _link("forearm", (edge_point + r * n_out - 0.5 * axis).tolist(), axis.tolist(), r)
    contact = {"body": "forearm/0", "point": edge_point.tolist(), "normal": (-n_out).tolist(), "mu": 0.5}
    assert len(scene_from_dict(_cube_scene([contact], fingers=[finger])).contacts) == 1
    contact["normal"] = [0.0, 0.0, -1.0]
    _expect_error(_cube_scene([contact], fingers=[finger]), ("contacts", 0, "normal"),
                  "45 deg off the surface normal of body 'forearm/0'")


def test_point_off_its_link(planar: dict[str, Any], spatial: dict[str, Any]) -> None:
    # 0.01 along the normal: off the link (and off the disk, but the link is checked first)
    c = planar["contacts"][0]
    c["point"] = [c["point"][0] + 0.01 * c["normal"][0], c["point"][1] + 0.01 * c["normal"][1]]
    _expect_error(planar, ("contacts", 0, "point"), "0.01 away from the surface of body 'left/0'")
    c = spatial["contacts"][2]
    c["point"] = [p - 0.02 * n for p, n in zip(c["point"], c["normal"], strict=True)]
    _expect_error(spatial, ("contacts", 2, "point"), "0.02 away from the surface of body 'f3/2'")


def test_point_on_link_but_off_the_object(planar: dict[str, Any], spatial: dict[str, Any]) -> None:
    # slide contact 0 by 0.1 along its link (0.6 from the base of a 0.9 link): still on the
    # link, but sqrt(0.5^2 + 0.1^2) - 0.5 = 0.009902 off the disk
    left = scene_from_dict(planar).fingers[0]
    assert isinstance(left, Finger2D)
    theta = left.base.angle + left.q[0]
    x, y = planar["contacts"][0]["point"]
    planar["contacts"][0]["point"] = [x + 0.1 * math.cos(theta), y + 0.1 * math.sin(theta)]
    _expect_error(planar, ("contacts", 0, "point"), "is 0.009902 away from the object's surface")
    # the palm is a box top z = 0; (0.3, 0, 0) is on it but 0.0831 below the sphere
    spatial["contacts"][4]["point"] = [0.3, 0.0, 0.0]
    _expect_error(spatial, ("contacts", 4, "point"), "0.0831 away from the object's surface")


@pytest.mark.parametrize(
    ("body", "dim"),
    [
        ("thumb/0", 2),
        ("left/9", 2),
        ("left/2", 2),
        ("left", 2),
        ("left/x", 2),
        ("left/\u00b2", 2),
        ("table", 2),
        ("f9/1", 3),
        ("f3/4", 3),
        ("f1/-1", 3),
    ],
)
def test_unknown_body(body: str, dim: int, planar: dict[str, Any], spatial: dict[str, Any]) -> None:
    data = planar if dim == 2 else spatial
    data["contacts"][2]["body"] = body
    e = _expect_error(data, ("contacts", 2, "body"), f"unknown body '{body}'", "known: palm")
    assert ("left/1" if dim == 2 else "f4/3") in str(e)


@pytest.mark.parametrize(
    ("dim", "path", "value", "message"),
    [
        (2, ("contacts", 3, "point"), [0.1, 0.9, 0.0], "must have 2 components for dim=2"),
        (2, ("contacts", 3, "normal"), [0.0, 1.0, 0.0], "must have 2 components for dim=2"),
        (2, ("external_wrench",), [0.0, -1.0], "must have 3 components for dim=2"),
        (2, ("external_wrench",), [0.0, -1.0, 0.0, 0.0, 0.0, 0.0], "must have 3 components"),
        (2, ("object", "pose", "position"), [0.0, 0.5, 0.0], "must have 2 components for dim=2"),
        (2, ("fingers", 1, "base", "position"), [0.6, 0.0, 0.0], "at most 2 items"),
        (3, ("contacts", 0, "point"), [0.0, 1.0], "must have 3 components for dim=3"),
        (3, ("contacts", 0, "normal"), [0.0, -1.0], "must have 3 components for dim=3"),
        (3, ("external_wrench",), [0.0, -1.0, 0.0], "must have 6 components for dim=3"),
        (3, ("object", "pose", "position"), [0.0, 0.5], "must have 3 components for dim=3"),
        (3, ("fingers", 2, "base", "position"), [0.6, 0.0], "at least 3 items"),
        (3, ("fingers", 2, "joints", 1, "axis"), [0.0, 1.0], "at least 3 items"),
        (3, ("fingers", 2, "tip"), [0.0, 0.0, 0.5, 0.0], "at most 3 items"),
    ],
)
def test_wrong_vector_length_for_dim(
    dim: int,
    path: tuple[str | int, ...],
    value: list[float],
    message: str,
    planar: dict[str, Any],
    spatial: dict[str, Any],
) -> None:
    data = planar if dim == 2 else spatial
    node: Any = data
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    _expect_error(data, path, message)


NON_FINITE = [math.nan, math.inf, -math.inf]


@pytest.mark.parametrize("bad", NON_FINITE, ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize(
    "path",
    [
        ("contacts", 1, "point", 0),
        ("contacts", 1, "normal", 1),
        ("contacts", 1, "mu"),
        ("external_wrench", 2),
        ("object", "pose", "position", 1),
        ("object", "pose", "angle"),
        ("object", "shape", "radius"),
        ("fingers", 0, "q", 1),
        ("fingers", 0, "links", 0, "length"),
        ("fingers", 1, "base", "angle"),
    ],
)
def test_nan_and_inf_in_a_dict(path: tuple[str | int, ...], bad: float, planar: dict[str, Any]) -> None:
    node: Any = planar
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = bad
    _expect_error(planar, path, "finite number")


@pytest.mark.parametrize("token", ["NaN", "Infinity", "-Infinity"])
def test_nan_and_inf_in_json_text(token: str) -> None:
    # Python's json module accepts these non-standard tokens: validation must still reject them
    text = PLANAR.read_text()
    parts = text.split('"mu": 0.5')  # the third contact's mu becomes the token
    bad = '"mu": 0.5'.join(parts[:3]) + f'"mu": {token}' + '"mu": 0.5'.join(parts[3:])
    assert len(parts) == 6 and bad.count(token) == 1
    with pytest.raises(SceneError) as info:
        parse_scene_text(bad, ".json")
    assert info.value.loc == ("contacts", 2, "mu")
    assert "finite number" in str(info.value)
    q_text = text.replace('"q": [1.3894765524, -1.0808390005]', f'"q": [1.3894765524, {token}]')
    assert q_text != text
    with pytest.raises(SceneError) as info:
        parse_scene_text(q_text, ".json")
    assert info.value.loc == ("fingers", 0, "q", 1)


@pytest.mark.parametrize("token", [".nan", ".inf", "-.inf"])
def test_nan_and_inf_in_yaml_text(token: str, spatial: dict[str, Any]) -> None:
    text = yaml.safe_dump(spatial, sort_keys=False).replace("- -1.0\n", f"- {token}\n", 1)
    assert token in text
    with pytest.raises(SceneError) as info:
        parse_scene_text(text, ".yaml")
    assert info.value.loc == ("external_wrench", 2)
    assert "finite number" in str(info.value)


@pytest.mark.parametrize("mu", [-0.1, -1e-9])
def test_negative_mu(mu: float, planar: dict[str, Any]) -> None:
    planar["contacts"][3]["mu"] = mu
    _expect_error(planar, ("contacts", 3, "mu"), "greater than or equal to 0")


def test_zero_mu_is_accepted(planar: dict[str, Any]) -> None:
    planar["contacts"][3]["mu"] = 0
    assert scene_from_dict(planar).contacts[3].mu == 0.0


def test_the_contact_cap_applies_to_full_enumeration_only(planar: dict[str, Any]) -> None:
    contacts = planar["contacts"]
    planar["contacts"] = [copy.deepcopy(contacts[i % len(contacts)]) for i in range(MAX_CONTACTS)]
    check_enumerable(scene_from_dict(planar))  # the limit itself is fine
    for L in (MAX_CONTACTS + 1, 32, 40):
        planar["contacts"] = [copy.deepcopy(contacts[i % len(contacts)]) for i in range(L)]
        scene = scene_from_dict(planar)  # any number of contacts loads
        assert len(scene.contacts) == L
        with pytest.raises(SceneError) as info:
            check_enumerable(scene)
        assert info.value.loc == ("contacts",)
        assert str(info.value).startswith(f"contacts: has {L} contacts")
        assert f"limited to {MAX_CONTACTS} contacts" in str(info.value)


def test_no_contacts(planar: dict[str, Any]) -> None:
    # an empty list leaves the contacts to the detector (issue 10): an object that touches
    # nothing is still an error at ``contacts``, saying so
    planar["contacts"] = []
    planar["object"]["pose"]["position"] = [0.0, 3.0]
    _expect_error(planar, ("contacts",), "touches nothing within")


def test_unknown_shape_type(planar: dict[str, Any]) -> None:
    planar["object"]["shape"] = {"type": "torus", "radius": 0.5}
    _expect_error(planar, ("object", "shape"), "'torus'", "'disk'")


@pytest.mark.parametrize(
    "shape", [{"type": "sphere", "radius": 0.5}, {"type": "cylinder", "radius": 0.5, "height": 1.0}]
)
def test_3d_shape_in_2d_scene(shape: dict[str, Any], planar: dict[str, Any]) -> None:
    planar["object"]["shape"] = shape
    _expect_error(planar, ("object", "shape", "type"), f"'{shape['type']}' is a 3-D shape")


@pytest.mark.parametrize(
    "shape", [{"type": "disk", "radius": 0.5}, {"type": "polygon", "vertices": [[0, 0], [1, 0], [0, 1]]}]
)
def test_2d_shape_in_3d_scene(shape: dict[str, Any], spatial: dict[str, Any]) -> None:
    spatial["object"]["shape"] = shape
    _expect_error(spatial, ("object", "shape", "type"), f"'{shape['type']}' is a 2-D shape")


def test_bad_shape_field_is_named_without_union_tag(planar: dict[str, Any]) -> None:
    planar["object"]["shape"]["radius"] = -0.5
    _expect_error(planar, ("object", "shape", "radius"), "greater than 0")
    planar["object"]["shape"] = {"type": "box", "size": [1.0, 1.0, 1.0]}
    _expect_error(planar, ("object", "shape", "size"), "must have 2 components")


def test_q_of_wrong_length(planar: dict[str, Any], spatial: dict[str, Any]) -> None:
    planar["fingers"][1]["q"] = [0.1]
    _expect_error(planar, ("fingers", 1, "q"), "has 1 values but the finger has 2 links")
    spatial["fingers"][3]["q"] = [0.0, 0.0, 1.0, 0.0, 0.0]
    _expect_error(spatial, ("fingers", 3, "q"), "has 5 values but the finger has 4 joints")


def test_error_inside_a_spatial_finger_names_that_field(spatial: dict[str, Any]) -> None:
    # regression: the untagged finger union used to report a 3-D finger's error as a
    # Finger2D one ("fingers.0.function-after[...Finger2D].base.position")
    spatial["fingers"][0]["joints"][2]["axis"] = [0.0, -2.0, 0.0]
    _expect_error(spatial, ("fingers", 0, "joints", 2, "axis"), "unit vector")


def test_finger_of_unknown_kind(spatial: dict[str, Any]) -> None:
    del spatial["fingers"][1]["joints"]
    _expect_error(spatial, ("fingers", 1), "'links' (planar), 'joints' (spatial) or 'urdf'")


def test_planar_finger_in_3d_scene(planar: dict[str, Any], spatial: dict[str, Any]) -> None:
    spatial["fingers"][0] = planar["fingers"][0]
    spatial["fingers"][0]["name"] = "f1"
    _expect_error(spatial, ("fingers", 0), "a 3-D scene needs spatial fingers")


def test_non_unit_quaternion(spatial: dict[str, Any]) -> None:
    spatial["object"]["pose"]["quat_wxyz"] = [1.0, 1.0, 0.0, 0.0]
    _expect_error(spatial, ("object", "pose", "quat_wxyz"), "unit norm", "1.41421")


def test_missing_angle_in_2d(planar: dict[str, Any]) -> None:
    del planar["object"]["pose"]["angle"]
    _expect_error(planar, ("object", "pose", "angle"), "is required for dim=2")


def test_duplicate_body_name(planar: dict[str, Any]) -> None:
    planar["fingers"][1]["name"] = "palm"
    _expect_error(planar, ("fingers", 1, "name"), "duplicate body name 'palm'")


def test_unknown_field(planar: dict[str, Any]) -> None:
    planar["contacts"][0]["friction"] = 0.3
    _expect_error(planar, ("contacts", 0, "friction"), "Extra inputs are not permitted")


def test_joint_torque_limits_count(planar: dict[str, Any]) -> None:
    planar["joint_torque_limits"] = [1.0, 1.0, 1.0, 1.0]
    assert scene_from_dict(planar).joint_torque_limits == [1.0] * 4
    planar["joint_torque_limits"] = [1.0, 1.0, 1.0]
    _expect_error(planar, ("joint_torque_limits",), "one entry per joint (4)")


def _polygon_scene(vertices: list[list[float]]) -> dict[str, Any]:
    return {
        "dim": 2,
        "object": {
            "pose": {"position": [0.0, 0.5], "angle": 0.0},
            "shape": {"type": "polygon", "vertices": vertices},
        },
        "external_wrench": [0.0, -1.0, 0.0],
        "fixed_bodies": [{"name": "table", "shape": {"type": "segment", "points": [[-1, 0], [1, 0]]}}],
        "contacts": [{"body": "table", "point": [0.0, 0.0], "normal": [0.0, 1.0], "mu": 0.3}],
    }


def test_polygon_must_be_convex_and_counter_clockwise() -> None:
    square = [[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]
    assert scene_from_dict(_polygon_scene(square)).object.shape.type == "polygon"
    # regression: clockwise vertices used to be accepted, and the (correct) contact normal
    # was then reported as pointing outward
    _expect_error(_polygon_scene(square[::-1]), ("object", "shape", "vertices"), "counter-clockwise")
    arrow = [[-0.5, -0.5], [0.0, -0.2], [0.5, -0.5], [0.0, 0.5]]  # CCW, reflex vertex at (0, -0.2)
    _expect_error(_polygon_scene(arrow), ("object", "shape", "vertices"), "convex")


def test_scene_error_is_a_value_error_with_structured_errors(planar: dict[str, Any]) -> None:
    planar["contacts"][0]["mu"] = -1
    with pytest.raises(ValueError, match=r"^contacts\.0\.mu: ") as info:
        scene_from_dict(planar)
    assert isinstance(info.value, SceneError)
    assert info.value.errors[0]["loc"] == ("contacts", 0, "mu")


@pytest.mark.parametrize(("text", "suffix"), [("", ".yaml"), ("[1, 2]", ".json"), ("just text", ".yml")])
def test_a_document_that_is_not_a_mapping(text: str, suffix: str) -> None:
    with pytest.raises(SceneError) as info:
        parse_scene_text(text, suffix)
    assert info.value.loc == ()
    assert str(info.value).startswith("scene: ") and "dictionary" in str(info.value)


# --------------------------------------------------------------------------------------------
# The model checks structure; the loader adds the geometric checks (one function for the service)


def test_the_model_alone_accepts_a_point_off_its_body_and_check_geometry_names_it(planar: dict[str, Any]) -> None:
    c = planar["contacts"][0]
    c["point"] = [c["point"][0] + 0.01 * c["normal"][0], c["point"][1] + 0.01 * c["normal"][1]]
    scene = Scene.model_validate(planar)  # structurally fine
    errors = geometry_errors(scene)
    assert [tuple(e["loc"]) for e in errors] == [("contacts", 0, "point")]
    assert errors[0]["type"] == "scene" and "0.01 away from the surface of body 'left/0'" in errors[0]["msg"]
    with pytest.raises(SceneError) as info:
        check_geometry(scene)
    from_dict = _expect_error(planar, ("contacts", 0, "point"), "0.01 away from the surface of body 'left/0'")
    assert str(info.value) == str(from_dict) and info.value.errors == from_dict.errors
    assert geometry_errors(scene_from_dict(_raw(PLANAR))) == []


def test_geometry_errors_list_every_contact_in_scene_order(planar: dict[str, Any]) -> None:
    planar["contacts"][3]["body"] = "thumb/0"
    planar["contacts"][1]["normal"] = [0.6, -1.2]
    nx, ny = planar["contacts"][0]["normal"]
    planar["contacts"][0]["normal"] = [-nx, -ny]
    errors = geometry_errors(Scene.model_validate(planar))
    assert [tuple(e["loc"]) for e in errors] == [("contacts", 0, "normal"), ("contacts", 1, "normal"),
                                                 ("contacts", 3, "body")]
    with pytest.raises(SceneError) as info:
        scene_from_dict(planar)
    assert info.value.loc == ("contacts", 0, "normal") and info.value.errors == errors
