"""The URDF's own collision geometry (``"link_geometry": "urdf"``) and mesh objects (issue 10):
known answers on the Franka Panda (collision meshes) and the Allegro hand (boxes and fingertip
spheres) against a box, distances checked against pinocchio's own ``computeDistances``, what the
detector finds passes the scene validation, a mesh object behaves as the box it describes, bad
mesh files are clear errors."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin
import pytest
from mesh_files import write_box_stl

from analysis.detect import UnplacedScene, detect_contacts, link_distances
from analysis.exceptions import SceneError
from analysis.geometry import body_surface_distance, box_signed_distance, object_size
from analysis.kinematics import HandKinematics
from analysis.loader import GEOMETRY_TOL, check_geometry, scene_from_dict, with_detected_contacts
from analysis.mesh import hull_of, load_mesh
from analysis.placement import TOUCH_TOL, placed_scene_data
from analysis.scene import Box, Scene
from analysis.urdf import UrdfFinger, example_robot_data_dir, load_collision_model

ROOT = Path(__file__).resolve().parents[2]
PANDA_SOURCE = ROOT / "examples" / "unplaced" / "panda_forearm_box.json"
ALLEGRO_URDF = "example-robot-data:allegro_hand_description/urdf/allegro_right_hand.urdf"

pytestmark = pytest.mark.skipif(example_robot_data_dir() is None, reason="example-robot-data is not installed")


def _raw(path: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads(path.read_text())
    data.pop("contacts", None)
    return data


def _pinocchio_distances(finger: UrdfFinger, q: np.ndarray, box_size: list[float], box_centre: np.ndarray,
                         ) -> dict[str, float]:
    """Distance of each chain link's collision geometry to a box, by pinocchio's own
    ``computeDistances`` on the URDF's full model (the finger's base at the URDF's origin, other
    joints at 0), the box added to the collision model on the universe."""
    model = pin.buildModelFromUrdf(str(finger.path))
    geom = load_collision_model(finger.path, []).copy()
    box = pin.GeometryObject("box", 0, pin.SE3(np.eye(3), np.asarray(box_centre, dtype=float)),
                             coal.Box(*box_size))
    box_id = geom.addGeometryObject(box)
    qp = pin.neutral(model)
    for name, v in zip(finger.joint_names, q, strict=True):
        qp[model.joints[model.getJointId(name)].idx_q] = v
    links = set(finger.links)
    pairs = {}
    for i, o in enumerate(geom.geometryObjects):
        if i == box_id:
            continue
        link = model.frames[o.parentFrame].name
        if link in links:
            geom.addCollisionPair(pin.CollisionPair(i, box_id))
            pairs[len(geom.collisionPairs) - 1] = link
    data, gdata = model.createData(), pin.GeometryData(geom)
    pin.computeDistances(model, data, geom, gdata, qp)
    out: dict[str, float] = {}
    for k, link in pairs.items():
        d = float(gdata.distanceResults[k].min_distance)
        out[link] = min(d, out.get(link, np.inf))
    return out


def _convex_meshes(finger: UrdfFinger) -> bool:
    """Whether every collision mesh of the chain is convex (all its vertices on its hull), so
    that pinocchio's mesh distance equals the distance to the hull the detector uses."""
    geom = load_collision_model(finger.path, [])
    for o in geom.geometryObjects:
        g = o.geometry
        if hasattr(g, "buildConvexHull"):
            V = np.asarray(g.vertices(), dtype=float)
            hull = hull_of(g)
            if np.max(V @ hull.normals.T - hull.support) > 1e-9:
                return False
    return True


def test_panda_collision_meshes_against_the_box_agree_with_pinocchio() -> None:
    data = _raw(PANDA_SOURCE)
    data["fingers"][0]["link_geometry"] = "urdf"
    placed, placement = placed_scene_data(data, ["panda_link5"])  # link5's mesh is the forearm
    scene = UnplacedScene.model_validate(placed)
    hand = HandKinematics.from_scene(scene)
    finger = hand.fingers[0]
    assert isinstance(finger, UrdfFinger)
    ours = {p.link.name.split("/")[1]: p.distance for p in link_distances(scene, hand, hand.q0) if p.target == "object"}
    assert isinstance(scene.object.shape, Box)
    theirs = _pinocchio_distances(finger, hand.q0, scene.object.shape.size, np.asarray(scene.object.pose.position))
    assert set(theirs) == {lk for lk in finger.links if finger.collision_shapes(finger.links.index(lk))}
    for link, d in theirs.items():
        if d > 1e-6:  # pinocchio's mesh distance: exact where apart (touching pairs: its BVH gives ~0)
            assert _convex_meshes(finger)
            assert ours[link] == pytest.approx(d, abs=1e-6), link
        else:
            assert abs(ours[link]) <= TOUCH_TOL, link
    assert abs(ours["panda_link5"]) <= TOUCH_TOL
    full, detection = with_detected_contacts(placed)
    assert [c.body for c in detection.contacts] == ["arm/panda_link5"] + ["table"] * 4
    sc = Scene.model_validate(full)
    check_geometry(sc)  # what the detector finds on the mesh, the validation accepts
    c = sc.contacts[0]
    full_hand = HandKinematics.from_scene(sc)
    ref = full_hand.resolve_body(c.body)
    assert ref is not None
    on_link = body_surface_distance(sc, full_hand, ref, np.asarray(c.point))
    assert on_link is not None and abs(on_link) <= GEOMETRY_TOL
    assert placement.displacement < 0.2


def _allegro_index_scene(link_geometry: str) -> dict[str, Any]:
    """The Allegro index finger (base at the URDF origin) bent over a box below its fingertip."""
    return {
        "dim": 3,
        "object": {"pose": {"position": [0.12, 0.05, 0.07], "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
                   "shape": {"type": "box", "size": [0.04, 0.06, 0.06]}},
        "external_wrench": [0.0, 0.0, -0.5, 0.0, 0.0, 0.0],
        "fingers": [{"name": "index", "base": {"position": [0.0, 0.0, 0.0]},
                     "urdf": {"file": ALLEGRO_URDF, "root_link": "palm_link", "tip_link": "link_3.0_tip"},
                     "q": [0.0, 0.6, 0.6, 0.6], "link_radius": 0.01, "link_geometry": link_geometry}],
    }


def test_allegro_fingertip_sphere_against_a_box_agrees_with_pinocchio() -> None:
    placed, _ = placed_scene_data(_allegro_index_scene("urdf"), ["index/link_3.0_tip"])
    scene = UnplacedScene.model_validate(placed)
    hand = HandKinematics.from_scene(scene)
    finger = hand.fingers[0]
    assert isinstance(finger, UrdfFinger)
    kinds = [type(g).__name__ for k in range(len(finger.links)) for g, _, _ in finger.collision_shapes(k) or []]
    assert kinds == ["Box", "Box", "Box", "Box", "Sphere"]  # link_0.0 .. link_3.0, then the tip sphere
    ours = {p.link.name.split("/")[1]: p.distance for p in link_distances(scene, hand, hand.q0) if p.target == "object"}
    assert isinstance(scene.object.shape, Box)
    theirs = _pinocchio_distances(finger, hand.q0, scene.object.shape.size, np.asarray(scene.object.pose.position))
    for link, d in theirs.items():
        assert ours[link] == pytest.approx(d, abs=1e-7), link
    assert abs(ours["link_3.0_tip"]) <= TOUCH_TOL
    _, detection = with_detected_contacts(placed)
    assert {c.body for c in detection.contacts} <= {"index/link_3.0_tip", "index/link_3.0"}
    assert "index/link_3.0_tip" in {c.body for c in detection.contacts}
    scene_from_dict(with_detected_contacts(placed)[0])  # validates


def test_urdf_geometry_is_not_the_capsules() -> None:
    # the same configuration, two geometries: different distances (the capsules are a model)
    data = _allegro_index_scene("capsule")
    cap = UnplacedScene.model_validate(data)
    urdf = [data["fingers"][0] | {"link_geometry": "urdf"}]
    geo = UnplacedScene.model_validate(copy.deepcopy(data) | {"fingers": urdf})
    d_cap = [p.distance for p in link_distances(cap, HandKinematics.from_scene(cap), HandKinematics.from_scene(cap).q0)]
    hg = HandKinematics.from_scene(geo)
    d_geo = [p.distance for p in link_distances(geo, hg, hg.q0)]
    assert len(d_cap) == len(d_geo) == 5
    assert max(abs(a - b) for a, b in zip(d_cap, d_geo, strict=True)) > 1e-3


def _rod(name: str, a: Any, b: Any, radius: float) -> dict[str, Any]:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return {"name": name, "base": {"position": a.tolist()},
            "joints": [{"axis": [1.0, 0.0, 0.0], "origin": [0.0, 0.0, 0.0], "radius": radius}],
            "tip": (b - a).tolist(), "q": [0.0]}


def test_mesh_object_is_the_box_it_describes(tmp_path: Path) -> None:
    half = np.array([0.1, 0.15, 0.05])
    stl = tmp_path / "box.stl"
    write_box_stl(stl, half)
    hull = load_mesh(str(stl))
    assert len(hull.vertices) == 8
    rng = np.random.default_rng(3)
    P = rng.uniform(-0.3, 0.3, size=(200, 3))
    got = np.array([hull.signed_distance(p) for p in P])
    np.testing.assert_allclose(got, box_signed_distance(P, np.zeros(3), half), rtol=0, atol=1e-8)  # GJK: 6e-9

    def scene(shape: dict[str, Any]) -> dict[str, Any]:
        return {"dim": 3, "object": {"pose": {"position": [0.0, 0.0, 0.05],
                                              "quat_wxyz": [0.9238795325112867, 0.0, 0.0, 0.3826834323650898]},
                                     "shape": shape},
                "external_wrench": [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
                "fixed_bodies": [{"name": "table", "shape": {"type": "box", "size": [1.0, 1.0, 0.1],
                                                              "position": [0.0, 0.0, -0.05]}}],
                "fingers": [_rod("f", [-0.05, 0.0, 0.12], [0.05, 0.0, 0.12], 0.02)]}

    as_mesh = scene({"type": "mesh", "file": str(stl)})
    as_box = scene({"type": "box", "size": (2 * half).tolist()})
    full_mesh, _ = with_detected_contacts(as_mesh)
    full_box, _ = with_detected_contacts(as_box)
    assert [c["body"] for c in full_mesh["contacts"]] == ["f/0", "f/0"] + ["table"] * 4
    assert [c["body"] for c in full_mesh["contacts"]] == [c["body"] for c in full_box["contacts"]]
    for a, b in zip(full_mesh["contacts"], full_box["contacts"], strict=True):
        np.testing.assert_allclose(a["point"], b["point"], atol=1e-9)
        np.testing.assert_allclose(a["normal"], b["normal"], atol=1e-9)
    sc = scene_from_dict(full_mesh)  # the validation takes contacts on the mesh's hull
    assert object_size(sc) == pytest.approx(float(np.linalg.norm(half)))
    # a contact off the mesh's surface is refused, naming the field
    bad = copy.deepcopy(full_mesh)
    bad["contacts"][0]["point"][2] += 0.01
    with pytest.raises(SceneError) as e:
        scene_from_dict(bad)
    assert e.value.loc == ("contacts", 0, "point")


def test_bad_mesh_files_are_clear_errors(tmp_path: Path) -> None:
    pose = {"position": [0.0, 0.0, 0.0], "quat_wxyz": [1.0, 0.0, 0.0, 0.0]}
    base: dict[str, Any] = {"dim": 3, "object": {"pose": pose, "shape": {"type": "mesh", "file": ""}},
            "external_wrench": [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
            "fingers": [_rod("f", [0.0, 0.0, 0.2], [0.0, 0.0, 0.3], 0.01)]}
    text = tmp_path / "notes.stl"
    text.write_text("this is not a mesh\n")
    readme = tmp_path / "mesh.txt"
    readme.write_text("solid x\nendsolid x\n")
    flat = tmp_path / "flat.stl"
    flat.write_text("solid f\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                    "endloop\nendfacet\nendsolid f\n")
    for file, fragment in ((str(tmp_path / "missing.stl"), "not found"), (str(text), "cannot read the mesh"),
                           (str(readme), "is not a mesh file"), (str(flat), "")):
        data = copy.deepcopy(base)
        data["object"]["shape"]["file"] = file
        with pytest.raises(SceneError) as e:
            detect_contacts(UnplacedScene.model_validate(data))
        assert e.value.loc == ("object", "shape", "file"), file
        assert fragment in str(e.value) and str(tmp_path) not in str(e.value).replace(file, ""), str(e.value)
    two_d = {"dim": 2, "object": {"pose": {"position": [0.0, 0.0], "angle": 0.0},
                                  "shape": {"type": "mesh", "file": "x.stl"}},
             "external_wrench": [0.0, -1.0, 0.0], "contacts": []}
    with pytest.raises(SceneError) as e:
        scene_from_dict(two_d)
    assert e.value.loc == ("object", "shape", "type")


_TWO_LINKS = """<robot name="two">
  <link name="base"/>
  <link name="l1"><collision><origin xyz="0 0 0.05"/><geometry>{mesh}</geometry></collision></link>
  <link name="l2"><collision><origin xyz="0 0 0.05" rpy="0 0 0.3"/><geometry><box size="0.02 0.04 0.1"/></geometry>
  </collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.1"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""


def test_urdf_collision_shapes_are_placed_in_their_links_and_missing_meshes_are_errors(tmp_path: Path) -> None:
    urdf = tmp_path / "two.urdf"
    urdf.write_text(_TWO_LINKS.format(mesh='<cylinder radius="0.01" length="0.1"/>'))
    finger = UrdfFinger("f", urdf, "base", "l2", np.array([0.4, -0.7]), link_geometry="urdf")
    shapes = [finger.collision_shapes(k) for k in range(len(finger.links))]
    assert [[type(g).__name__ for g, _, _ in s or []] for s in shapes] == [["Cylinder"], ["Box"]]
    for k, s in enumerate(shapes):
        assert s is not None
        _, R, t = s[0]
        np.testing.assert_allclose(t, [0.0, 0.0, 0.05], atol=1e-15)  # the <origin> in the link frame
        yaw = 0.3 if k == 1 else 0.0
        np.testing.assert_allclose(R[:2, :2], [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]], atol=1e-12)
    capsules = UrdfFinger("f", urdf, "base", "l2", np.zeros(2))
    assert capsules.collision_shapes(0) is None  # link_geometry "capsule": no URDF shapes
    urdf.write_text(_TWO_LINKS.format(mesh='<mesh filename="package://nowhere/meshes/l1.stl"/>'))
    data = {"dim": 3, "object": {"pose": {"position": [0.0, 0.3, 0.0], "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
                                 "shape": {"type": "sphere", "radius": 0.05}},
            "external_wrench": [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
            "fingers": [{"name": "f", "base": {"position": [0.0, 0.0, 0.0]},
                         "urdf": {"file": str(urdf), "root_link": "base", "tip_link": "l2"},
                         "q": [0.0, 0.0], "link_geometry": "urdf"}]}
    with pytest.raises(SceneError) as e:
        detect_contacts(UnplacedScene.model_validate(data))
    assert e.value.loc == ("fingers", 0, "urdf", "file") and "could not be found" in str(e.value)
