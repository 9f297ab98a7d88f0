"""Contacts found from the geometry (analysis.detect, issue 10): known answers, patches, the
loader hook (``"contacts": "auto"``), distances against independent formulas, bad input."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mesh_files import write_box_stl

from analysis.detect import FEATURE_TOL, Detection, UnplacedScene, detect_contacts
from analysis.exceptions import SceneError
from analysis.geometry import box_signed_distance
from analysis.kinematics import segment_distance
from analysis.loader import GEOMETRY_TOL, check_geometry, load_scene, scene_from_dict, with_detected_contacts
from analysis.rotations import axis_angle_matrix, matrix_to_quat_wxyz
from analysis.scene import Scene

ROOT = Path(__file__).resolve().parents[2]
PLANAR = ROOT / "examples" / "planar_disk_envelope.json"
EXAMPLES = ROOT / "examples"


def _rod(name: str, a: Any, b: Any, radius: float) -> dict[str, Any]:
    """A one-joint spatial finger whose single link is the capsule ``[a, b]`` of ``radius``."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return {"name": name, "base": {"position": a.tolist()},
            "joints": [{"axis": [1.0, 0.0, 0.0], "origin": [0.0, 0.0, 0.0], "radius": radius}],
            "tip": (b - a).tolist(), "q": [0.0]}


def _scene3(shape: dict[str, Any], fingers: list[dict[str, Any]], fixed: list[dict[str, Any]] | None = None,
            position: Any = (0.0, 0.0, 0.0), quat: Any = (1.0, 0.0, 0.0, 0.0)) -> dict[str, Any]:
    return {"dim": 3, "object": {"pose": {"position": list(position), "quat_wxyz": list(quat)}, "shape": shape},
            "external_wrench": [0.0, 0.0, -1.0, 0.0, 0.0, 0.0], "fixed_bodies": fixed or [], "fingers": fingers}


def _full_scene(data: dict[str, Any], **kw: Any) -> Scene:
    """The scene with the detected contacts, through the model and the geometric validation."""
    full, _ = with_detected_contacts(data, **kw)
    scene = Scene.model_validate(full)
    check_geometry(scene)  # every detected contact passes the scene validation
    return scene


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    axis = rng.normal(size=3)
    return axis_angle_matrix(axis / np.linalg.norm(axis), float(rng.uniform(0.0, np.pi)))


def test_feature_tolerance_is_the_validations() -> None:
    assert FEATURE_TOL == GEOMETRY_TOL


def test_sphere_between_two_capsules_randomly_turned() -> None:
    rng = np.random.default_rng(10)
    for _ in range(5):
        R = _random_rotation(rng)
        c = rng.uniform(-1.0, 1.0, size=3)
        fingers = [_rod("left", c + R @ [-0.6, 0.0, -0.5], c + R @ [-0.6, 0.0, 0.5], 0.1),
                   _rod("right", c + R @ [0.6, 0.3, -0.5], c + R @ [0.6, -0.3, 0.5], 0.1)]
        data = _scene3({"type": "sphere", "radius": 0.5}, fingers, position=c)
        det = detect_contacts(UnplacedScene.model_validate(data))
        assert [k.body for k in det.contacts] == ["left/0", "right/0"]
        assert det.near_misses == ()
        np.testing.assert_allclose(det.contacts[0].point, c + R @ [-0.5, 0.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(det.contacts[0].normal, R @ [1.0, 0.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(det.contacts[1].point, c + R @ [0.5, 0.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(det.contacts[1].normal, R @ [-1.0, 0.0, 0.0], atol=1e-9)
        assert all(k.mu == 0.5 and k.gap <= 1e-9 for k in det.contacts)
        _full_scene(data)


def _table(size: Any = (1.0, 1.0, 0.1), top: float = 0.0, x: float = 0.0, mu: float | None = None) -> dict[str, Any]:
    body: dict[str, Any] = {"name": "table", "shape": {"type": "box", "size": list(size),
                                                      "position": [x, 0.0, top - size[2] / 2]}}
    if mu is not None:
        body["mu"] = mu
    return body


def test_box_on_a_table_gives_its_four_corners_with_normal_up() -> None:
    rng = np.random.default_rng(3)
    for _ in range(4):
        yaw = float(rng.uniform(-np.pi, np.pi))
        c = np.array([*rng.uniform(-0.2, 0.2, size=2), 0.05])
        quat = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
        data = _scene3({"type": "box", "size": [0.2, 0.3, 0.1]}, [], [_table()], position=c, quat=quat)
        scene = _full_scene(data, mu=0.7)
        R = axis_angle_matrix(np.array([0.0, 0.0, 1.0]), yaw)
        corners = [c + R @ [sx * 0.1, sy * 0.15, -0.05] for sx in (-1, 1) for sy in (-1, 1)]
        got = np.array([k.point for k in scene.contacts])
        assert len(got) == 4 and {k.body for k in scene.contacts} == {"table"}
        for corner in corners:
            assert np.min(np.linalg.norm(got - corner, axis=1)) < 1e-9
        for k in scene.contacts:
            np.testing.assert_allclose(k.normal, [0.0, 0.0, 1.0], atol=1e-12)
            assert k.mu == 0.7


def test_box_overhanging_the_table_gives_the_corners_of_the_overlap() -> None:
    # table top x in [-0.5, 0.5]; box bottom x in [0.4, 0.6]: the patch is x in [0.4, 0.5]
    data = _scene3({"type": "box", "size": [0.2, 0.3, 0.1]}, [], [_table(mu=0.3)], position=(0.5, 0.0, 0.05))
    scene = _full_scene(data)
    got = sorted(tuple(np.round(k.point, 12)) for k in scene.contacts)
    assert got == sorted((x, y, 0.0) for x in (0.4, 0.5) for y in (-0.15, 0.15))
    assert all(k.mu == 0.3 for k in scene.contacts)  # the table's own friction


def test_square_turned_on_a_square_gives_the_octagon_of_their_overlap() -> None:
    s45 = np.sin(np.pi / 8)
    data = _scene3({"type": "box", "size": [0.2, 0.2, 0.1]}, [], [_table(size=(0.2, 0.2, 0.1))],
                   position=(0.0, 0.0, 0.05), quat=(np.cos(np.pi / 8), 0.0, 0.0, s45))
    scene = _full_scene(data)
    a = 0.1 * (np.sqrt(2.0) - 1.0)  # |x|, |y| <= 0.1 and |x +- y| <= 0.1 sqrt(2)
    expected = {(sx * 0.1, sy * a) for sx in (-1, 1) for sy in (-1, 1)} | {
        (sx * a, sy * 0.1) for sx in (-1, 1) for sy in (-1, 1)}
    P = np.array([c.point for c in scene.contacts])
    assert len(P) == 8
    np.testing.assert_allclose(P[:, 2], 0.0, atol=1e-12)
    for e in expected:
        assert np.min(np.linalg.norm(P[:, :2] - np.array(e), axis=1)) < 1e-9


def test_box_edge_along_a_capsule_gives_the_end_points_of_the_overlap() -> None:
    r = 0.05
    off = 0.1 + r / np.sqrt(2.0)  # the axis parallel to x, touching the box's +y +z edge at 45 deg
    data = _scene3({"type": "box", "size": [0.2, 0.2, 0.2]}, [_rod("arm", [-0.3, off, off], [0.05, off, off], r)])
    scene = _full_scene(data)
    got = sorted(tuple(np.round(k.point, 12)) for k in scene.contacts)
    assert got == [(-0.1, 0.1, 0.1), (0.05, 0.1, 0.1)]
    for k in scene.contacts:
        assert k.body == "arm/0"
        np.testing.assert_allclose(k.normal, [0.0, -np.sqrt(0.5), -np.sqrt(0.5)], atol=1e-9)


def test_capsule_on_a_face_is_a_line_contact_only_while_flat_to_the_validation_tolerance() -> None:
    r = 0.02
    for rise, expected in ((5e-5, 2), (5e-4, 1)):  # the far end of the axis lifted by ``rise``
        data = _scene3({"type": "box", "size": [0.2, 0.2, 0.2]},
                       [_rod("arm", [-0.05, 0.0, 0.1 + r], [0.05, 0.0, 0.1 + r + rise], r)])
        scene = _full_scene(data)
        assert len(scene.contacts) == expected, rise
        np.testing.assert_allclose(scene.contacts[0].point, [-0.05, 0.0, 0.1], atol=1e-9)
        for c in scene.contacts:
            np.testing.assert_allclose(c.normal, [0.0, 0.0, -1.0], atol=1e-9)


def test_capsule_across_a_box_edge_touches_at_one_point() -> None:
    r = 0.05
    n = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)  # the normal of the +x +z edge (which runs along y)
    d = np.array([1.0, 0.0, -1.0]) / np.sqrt(2.0)  # the axis crosses the edge at right angles
    q = np.array([0.1, 0.0, 0.1]) + r * n
    data = _scene3({"type": "box", "size": [0.2, 0.2, 0.2]}, [_rod("arm", q - 0.3 * d, q + 0.3 * d, r)])
    scene = _full_scene(data)
    assert len(scene.contacts) == 1
    np.testing.assert_allclose(scene.contacts[0].point, [0.1, 0.0, 0.1], atol=1e-9)
    np.testing.assert_allclose(scene.contacts[0].normal, -n, atol=1e-9)


def test_cylinder_standing_on_a_table_gives_its_rim_polygon() -> None:
    data = _scene3({"type": "cylinder", "radius": 0.1, "height": 0.2}, [], [_table()], position=(0.0, 0.0, 0.1))
    scene = _full_scene(data)
    P = np.array([k.point for k in scene.contacts])
    assert len(P) == 8
    np.testing.assert_allclose(P[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(P[:, :2], axis=1), 0.1, atol=1e-12)
    # tilted about x: its rim level to 4e-5 (< 1e-4) still stands on 8 points, level to 4e-4 on one
    for tilt, count in ((2e-4, 8), (2e-3, 1)):
        z = 0.1 * np.cos(tilt) + 0.1 * np.sin(tilt)  # the lowest rim point on the table
        tilted = _scene3({"type": "cylinder", "radius": 0.1, "height": 0.2}, [], [_table()], position=(0.0, 0.0, z),
                         quat=(np.cos(tilt / 2), np.sin(tilt / 2), 0.0, 0.0))
        contacts = _full_scene(tilted).contacts
        assert len(contacts) == count
        # on the rim, no lower than the table and no higher than the rim's rise 2 r sin(tilt)
        assert all(-1e-9 <= c.point[2] <= 0.2 * np.sin(tilt) + 1e-9 for c in contacts)
        P = np.array([c.point for c in contacts])
        assert np.all(np.abs(box_signed_distance(P, np.array([0.0, 0.0, -0.05]), np.array([0.5, 0.5, 0.05]))) < 1e-4)
    # lying on its side along y: the line between the rims, x = 0 on the table
    lying = _scene3({"type": "cylinder", "radius": 0.1, "height": 0.2}, [], [_table()], position=(0.0, 0.0, 0.1),
                    quat=(np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0))
    # (within 1e-8: coal's witness points move by a few 1e-9 with what it computed before in the process)
    got = np.array(sorted((c.point for c in _full_scene(lying).contacts), key=lambda p: p[1]))
    np.testing.assert_allclose(got, [[0.0, -0.1, 0.0], [0.0, 0.1, 0.0]], atol=1e-8)


def _found_back(path: Path) -> tuple[dict[str, Any], list[dict[str, Any]], Detection]:
    """The scene at ``path`` without its contacts, its bundled contacts, and what the detector finds:
    the same bodies in the same order, points and normals within 1e-9 (the bundled contacts are
    written to 10 decimals)."""
    data = json.loads(path.read_text())
    bundled = data.pop("contacts")
    det = detect_contacts(UnplacedScene.model_validate(data))
    assert [k.body for k in det.contacts] == [c["body"] for c in bundled]
    for k, c in zip(det.contacts, bundled, strict=True):
        np.testing.assert_allclose(k.point, c["point"], atol=1e-9)
        np.testing.assert_allclose(k.normal, c["normal"], atol=1e-9)
    return data, bundled, det


def test_planar_example_contacts_are_found_back() -> None:
    data, bundled, det = _found_back(PLANAR)
    for k, c in zip(det.contacts, bundled, strict=True):
        assert k.mu == c["mu"] and k.gap < 1e-9
    value: object
    for value in ("auto", []):
        scene = scene_from_dict({**data, "contacts": value})
        assert [c.body for c in scene.contacts] == [c["body"] for c in bundled]
    assert [c.body for c in scene_from_dict(data).contacts] == [c["body"] for c in bundled]


def test_friction_of_a_finger_overrides_the_default() -> None:
    data = json.loads(PLANAR.read_text())
    del data["contacts"]
    data["fingers"][1]["mu"] = 0.9
    data["fixed_bodies"][0]["mu"] = 0.0
    scene = _full_scene(data, mu=0.3)
    assert {c.body: c.mu for c in scene.contacts} == {"left/0": 0.3, "left/1": 0.3, "right/0": 0.9,
                                                      "right/1": 0.9, "palm": 0.0}


def test_planar_polygon_on_the_palm_gives_the_edge_end_points() -> None:
    data = json.loads(PLANAR.read_text())
    del data["contacts"]
    data["fingers"] = []
    data["object"] = {"pose": {"position": [0.1, 0.2], "angle": 0.0},
                      "shape": {"type": "polygon", "vertices": [[-0.2, -0.2], [0.2, -0.2], [0.0, 0.3]]}}
    scene = _full_scene(data)
    got = sorted(tuple(np.round(k.point, 12)) for k in scene.contacts)
    assert got == [(-0.1, 0.0), (0.3, 0.0)]
    assert all(k.body == "palm" and list(k.normal) == [0.0, 1.0] for k in scene.contacts)


def test_scene_files_with_contacts_load_unchanged() -> None:
    files = sorted((ROOT.parent / "shared" / "scenes").glob("*.json")) + sorted((ROOT / "examples").glob("*.json"))
    assert files
    for f in files:
        raw = json.loads(f.read_text())
        scene = load_scene(f)
        assert [c.model_dump() for c in scene.contacts] == [Scene.model_validate(raw).contacts[i].model_dump()
                                                           for i in range(len(raw["contacts"]))]


def test_distances_of_near_misses_against_independent_formulas() -> None:
    rng = np.random.default_rng(7)
    half = np.array([0.1, 0.15, 0.2])
    ts = np.linspace(0.0, 1.0, 20001)[:, None]
    compared = [0, 0]
    for _ in range(12):
        a = rng.uniform(-0.4, 0.4, size=3)
        b = rng.uniform(-0.4, 0.4, size=3)
        radius = float(rng.uniform(0.0, 0.02))
        # sphere: |axis - centre| - R - r (analysis.kinematics.segment_distance)
        data = _scene3({"type": "sphere", "radius": 0.05}, [_rod("f", a, b, radius)])
        det = detect_contacts(UnplacedScene.model_validate(data))
        exact = segment_distance(np.zeros(3), a, b) - 0.05 - radius
        assert det.nearest is not None and det.nearest[0] == "f/0"
        if exact > 0:
            assert det.nearest[1] == pytest.approx(exact, abs=1e-9)
            compared[0] += 1
        # box: the exact signed distance of 20001 points along the axis, minus the radius
        data = _scene3({"type": "box", "size": (2 * half).tolist()}, [_rod("f", a, b, radius)])
        det = detect_contacts(UnplacedScene.model_validate(data))
        sampled = float(box_signed_distance(a + ts * (b - a), np.zeros(3), half).min()) - radius
        assert det.nearest is not None
        if sampled > 1e-4:
            assert det.nearest[1] == pytest.approx(sampled, abs=1e-4 * float(np.linalg.norm(b - a)))
            compared[1] += 1
    assert compared[0] >= 10 and compared[1] >= 5  # the seeded draws compare 12 and 7 pairs


def test_near_misses_are_listed_with_their_distance() -> None:
    fingers = [_rod("a", [-0.6, 0.0, -0.5], [-0.6, 0.0, 0.5], 0.1),  # touching
               _rod("b", [0.605, 0.0, -0.5], [0.605, 0.0, 0.5], 0.1),  # 5e-3 off: a near miss
               _rod("c", [0.0, 0.7, -0.5], [0.0, 0.7, 0.5], 0.1)]  # 0.1 off: neither
    det = detect_contacts(UnplacedScene.model_validate(_scene3({"type": "sphere", "radius": 0.5}, fingers)))
    assert [k.body for k in det.contacts] == ["a/0"]
    assert [m.body for m in det.near_misses] == ["b/0"]
    assert det.near_misses[0].distance == pytest.approx(5e-3, abs=1e-9)
    np.testing.assert_allclose(det.near_misses[0].object_point, [0.5, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(det.near_misses[0].body_point, [0.505, 0.0, 0.0], atol=1e-9)
    # a larger tolerance takes the near miss as a contact
    assert [k.body for k in detect_contacts(UnplacedScene.model_validate(
        _scene3({"type": "sphere", "radius": 0.5}, fingers)), tolerance=6e-3).contacts] == ["a/0", "b/0"]


def test_an_object_touching_nothing_is_a_clear_error() -> None:
    data = json.loads(PLANAR.read_text())
    data["object"]["pose"]["position"] = [0.0, 3.0]
    value: object
    for value in ("auto", []):
        with pytest.raises(SceneError) as e:
            scene_from_dict({**data, "contacts": value})
        assert e.value.loc == ("contacts",)
        assert "touches nothing within 0.001" in e.value.reason and "nearest body" in e.value.reason


def test_bad_input_names_the_field() -> None:
    data = json.loads(PLANAR.read_text())
    del data["contacts"]
    bad = copy.deepcopy(data)
    bad["fixed_bodies"][0]["mu"] = -1.0
    with pytest.raises(SceneError) as e:
        scene_from_dict(bad)
    assert e.value.loc == ("fixed_bodies", 0, "mu")
    bad = copy.deepcopy(data)
    bad["unknown"] = 1
    with pytest.raises(SceneError) as e:
        scene_from_dict(bad)
    assert e.value.loc == ("unknown",)
    mesh = _scene3({"type": "mesh", "file": "no-such-file.stl"}, [_rod("f", [0, 0, 0], [0, 0, 1], 0.1)])
    with pytest.raises(SceneError) as e:
        scene_from_dict(mesh)
    assert e.value.loc == ("object", "shape", "file") and "not found" in str(e.value)
    sc = UnplacedScene.model_validate(data)
    for kw, loc in (({"tolerance": 0.0}, ("tolerance",)), ({"mu": -0.1}, ("mu",))):
        with pytest.raises(SceneError) as e:
            detect_contacts(sc, **kw)
        assert e.value.loc == loc


def _hull_distance(x: np.ndarray, P: np.ndarray) -> float:
    """Distance of ``x`` to the convex hull of the rows of ``P`` (non-negative weights summing
    to one, by NNLS with the sum as a heavily weighted extra row)."""
    from scipy.optimize import nnls

    A = np.vstack([P.T, 1e6 * np.ones(len(P))])
    w, _ = nnls(A, np.append(x, 1e6))
    return float(np.linalg.norm(P.T @ w - x))


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "sphere_four_finger_wrap", "sphere_wrap_three_link"])
def test_spatial_examples_contacts_are_found_back(name: str) -> None:
    _found_back(ROOT / "examples" / f"{name}.json")


@pytest.mark.parametrize("name", ["baxter_hug_box_chains", "baxter_hug_box", "allegro_right_box"])
def test_hand_written_contacts_lie_in_the_detected_patches(name: str) -> None:
    # these scenes give one contact per line or face contact; the detector gives the patch's
    # corners: each bundled contact lies in the patch of its body, with the same normal
    data = json.loads((ROOT / "examples" / f"{name}.json").read_text())
    bundled = data.pop("contacts")
    scene = _full_scene(data)
    for c in bundled:
        mine = [k for k in scene.contacts if k.body == c["body"]]
        assert mine, c["body"]
        P = np.array([k.point for k in mine])
        assert _hull_distance(np.asarray(c["point"]), P) < 1e-9, c["body"]  # measured: 1.2e-10
        for k in mine:
            np.testing.assert_allclose(k.normal, c["normal"], atol=1e-9)


def test_capsules_lying_on_faces_of_turned_boxes() -> None:
    # a box of random orientation; a capsule lying on a random face, inside it, along a random
    # tangent: the contacts are the two ends of its axis lowered onto the face
    rng = np.random.default_rng(11)
    size = np.array([0.2, 0.3, 0.4])
    for _ in range(20):
        R = _random_rotation(rng)
        c = rng.uniform(-0.5, 0.5, size=3)
        k, side = int(rng.integers(3)), float(rng.choice([-1.0, 1.0]))
        n_local = side * np.eye(3)[k]
        others = [j for j in range(3) if j != k]
        p_local = n_local * size[k] / 2
        for j in others:
            p_local[j] = rng.uniform(-0.3, 0.3) * size[j]
        angle = rng.uniform(0.0, np.pi)
        t_local = np.cos(angle) * np.eye(3)[others[0]] + np.sin(angle) * np.eye(3)[others[1]]
        r, half = float(rng.uniform(0.005, 0.03)), 0.02
        p, n, t = c + R @ p_local, R @ n_local, R @ t_local
        data = _scene3({"type": "box", "size": size.tolist()},
                       [_rod("f", p + r * n - half * t, p + r * n + half * t, r)], position=c,
                       quat=matrix_to_quat_wxyz(R).tolist())
        scene = _full_scene(data)
        got = np.array([k_.point for k_ in scene.contacts])
        assert len(got) == 2
        for end in (p - half * t, p + half * t):
            assert np.min(np.linalg.norm(got - end, axis=1)) < 1e-9
        for k_ in scene.contacts:
            np.testing.assert_allclose(k_.normal, -n, atol=1e-9)



# --------------------------------------------------------------------------------------------
# SceneGeometry: the same geometry for repeated queries (the planner's collision checks)


def test_scene_geometry_sphere_object_at_any_pose_is_exact() -> None:
    from analysis.detect import SceneGeometry
    from analysis.kinematics import BodyRef, HandKinematics

    data = _scene3({"type": "sphere", "radius": 0.1},
                   [_rod("f", [-0.2, 0.0, 0.05], [0.2, 0.0, 0.05], 0.02)],
                   [{"name": "table",
                     "shape": {"type": "box", "size": [1.0, 1.0, 0.1], "position": [0.0, 0.0, -0.15]}}])
    scene = UnplacedScene.model_validate(data)
    hand = HandKinematics.from_scene(scene)
    geo = SceneGeometry(scene, hand)
    ref = BodyRef("f/0", 0, 0)
    rng = np.random.default_rng(12)
    for _ in range(30):
        q = rng.uniform(-np.pi, np.pi, size=1)
        c = rng.normal(scale=0.1, size=3)
        R = _random_rotation(rng)
        a, b = hand.body_segment(ref, q)
        for radius in (0.0, 0.02):  # the bare axis and the capsule: penetrating or apart, exact
            d = geo.distance(geo.link_bodies(ref, q, radius), [geo.object_at(c, R)])
            assert d == pytest.approx(segment_distance(c, a, b) - 0.1 - radius, abs=1e-9)
        # the link against the table (a box): its lowest point, where apart
        low = min(float(a[2]), float(b[2])) - 0.02
        if low > -0.1 + 1e-6:
            assert geo.distance(geo.link_bodies(ref, q, 0.02), geo.fixed) == pytest.approx(low + 0.1, abs=1e-9)


def test_scene_geometry_mesh_queries_do_not_keep_an_earlier_penetration(tmp_path: Path) -> None:
    # coal keeps the smaller of a reused DistanceResult's distance and the new one on convex
    # hulls: a penetrating query followed by one far apart must still give the far distance
    from analysis.detect import SceneGeometry
    from analysis.kinematics import HandKinematics

    stl = tmp_path / "box.stl"
    half = np.array([0.1, 0.15, 0.05])
    write_box_stl(stl, half)
    data = _scene3({"type": "mesh", "file": str(stl)}, [_rod("f", [0.0, 0.0, 0.2], [0.0, 0.0, 0.3], 0.01)])
    scene = UnplacedScene.model_validate(data)
    geo = SceneGeometry(scene, HandKinematics.from_scene(scene))
    obj = [geo.object_at(np.zeros(3), np.eye(3))]
    for z in (0.0, 0.5, 0.02, 0.3):  # the segment from z to z + 0.1 above the centre
        d = geo.distance([geo.segment_body(np.array([0.0, 0.0, z]), np.array([0.0, 0.0, z + 0.1]))], obj)
        # apart: the gap above the top face; through it: the translation that pushes it out (up)
        assert d == pytest.approx(z - half[2], abs=1e-6)


def test_links_lying_flat_with_one_listed_point_are_reported() -> None:
    """Baxter's point-contact hug lists one point per elbow and forearm capsule and two of the box's
    four bottom corners, while each capsule lies flat on a side (a line: its two end points) and
    the bottom face on the table (a patch): each such body is reported, with the line's length
    (independently: the capsule's segment clipped to the box side, at most its length); the line
    contact scene lists them all and nothing is reported; nor for the fingertip wrap."""
    from analysis.detect import unlisted_points
    from analysis.kinematics import HandKinematics

    points = load_scene(EXAMPLES / "baxter_hug_box.json")
    got = {u.body: u for u in unlisted_points(points)}
    arms = {"left/left_lower_elbow", "left/left_upper_forearm", "right/right_lower_elbow", "right/right_upper_forearm"}
    assert set(got) == arms | {"table"}
    hand = HandKinematics.from_scene(points)
    for b in arms:
        assert (got[b].listed, got[b].found) == (1, 2)
        ref = hand.resolve_body(b)
        assert ref is not None
        a, e = hand.body_segment(ref, hand.q0)
        assert 0.0 < got[b].extent <= float(np.linalg.norm(np.asarray(e) - np.asarray(a))) + 1e-9
        assert "line" in got[b].describe() and "ctp contacts" in got[b].describe()
    assert (got["table"].listed, got["table"].found) == (2, 4) and "patch" in got["table"].describe()
    assert unlisted_points(load_scene(EXAMPLES / "baxter_hug_box_lines.json")) == ()
    assert unlisted_points(load_scene(EXAMPLES / "sphere_four_finger_wrap.json")) == ()


def test_ctp_notes_the_unlisted_line_points() -> None:
    from typer.testing import CliRunner

    from ctp.cli import app

    r = CliRunner().invoke(app, ["analyze", str(EXAMPLES / "baxter_hug_box.json"), "--combination", "FFFFDD"])
    assert "note:" in r.output and "left/left_upper_forearm lies on the object along a line" in r.output
