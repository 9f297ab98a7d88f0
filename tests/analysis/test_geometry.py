"""Signed distances to the scene's shapes (known answers) and the object's pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from analysis.geometry import (
    body_surface_distance,
    object_origin,
    object_rotation,
    object_signed_distance,
    shape_signed_distance,
)
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Box, Cylinder, Disk, Mesh, Polygon, Segment, Sphere

EXAMPLES = Path(__file__).parents[2] / "examples"
TOL = 1e-12


@pytest.mark.parametrize(
    ("p", "expected"), [((0.0, 0.0), -1.0), ((2.0, 0.0), 1.0), ((0.6, 0.8), 0.0), ((-3.0, 4.0), 4.0)]
)
def test_disk(p: tuple[float, float], expected: float) -> None:
    assert shape_signed_distance(Disk(type="disk", radius=1.0), np.array(p), 2) == pytest.approx(
        expected, abs=TOL
    )


def test_sphere() -> None:
    s = Sphere(type="sphere", radius=0.5)
    assert shape_signed_distance(s, np.array([0.0, 0.0, 1.5]), 3) == pytest.approx(1.0, abs=TOL)
    assert shape_signed_distance(s, np.array([0.1, 0.0, 0.0]), 3) == pytest.approx(-0.4, abs=TOL)


@pytest.mark.parametrize(
    ("p", "expected"),
    [
        ((0.0, 0.0), -1.0),  # centre: half the extent inside
        ((1.5, 0.0), 0.5),  # beside a face
        ((2.0, 1.5), np.hypot(1.0, 0.5)),  # beyond a corner
        ((1.0, 0.3), 0.0),  # on a face
        ((0.9, 0.0), -0.1),
    ],
)
def test_box_2d(p: tuple[float, float], expected: float) -> None:
    box = Box(type="box", size=[2.0, 2.0])
    assert shape_signed_distance(box, np.array(p), 2) == pytest.approx(expected, abs=TOL)
    # an offset box is the same box moved
    moved = Box(type="box", size=[2.0, 2.0], position=[0.5, -1.0])
    q = np.add(p, [0.5, -1.0])
    assert shape_signed_distance(moved, q, 2) == pytest.approx(expected, abs=TOL)


def test_box_3d_palm() -> None:
    palm = Box(type="box", size=[1.4, 1.4, 0.02], position=[0.0, 0.0, -0.01])
    assert shape_signed_distance(palm, np.zeros(3), 3) == pytest.approx(0.0, abs=TOL)
    assert shape_signed_distance(palm, np.array([0.0, 0.0, 0.3]), 3) == pytest.approx(0.3, abs=TOL)
    assert shape_signed_distance(palm, np.array([0.0, 0.0, -0.01]), 3) == pytest.approx(-0.01, abs=TOL)


@pytest.mark.parametrize(
    ("p", "expected"),
    [
        ((0.25, 0.25), -0.25),
        ((0.5, 0.5), -0.5),
        ((0.5, 1.0), 0.0),
        ((0.5, -1.0), 1.0),
        ((2.0, 2.0), np.hypot(1.0, 1.0)),
    ],
)
def test_polygon(p: tuple[float, float], expected: float) -> None:
    square = Polygon(type="polygon", vertices=[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert shape_signed_distance(square, np.array(p), 2) == pytest.approx(expected, abs=TOL)


def test_cylinder() -> None:
    cyl = Cylinder(type="cylinder", radius=1.0, height=2.0)
    assert shape_signed_distance(cyl, np.zeros(3), 3) == pytest.approx(-1.0, abs=TOL)
    assert shape_signed_distance(cyl, np.array([0.0, 0.0, 1.5]), 3) == pytest.approx(0.5, abs=TOL)
    assert shape_signed_distance(cyl, np.array([3.0, 0.0, 0.0]), 3) == pytest.approx(2.0, abs=TOL)
    assert shape_signed_distance(cyl, np.array([2.0, 0.0, 2.0]), 3) == pytest.approx(np.sqrt(2.0), abs=TOL)
    assert shape_signed_distance(cyl, np.array([0.0, 0.8, 0.5]), 3) == pytest.approx(-0.2, abs=TOL)


def test_segment_and_mesh() -> None:
    seg = Segment(type="segment", points=[[-1.0, 0.0], [1.0, 0.0]])
    assert shape_signed_distance(seg, np.array([0.0, 0.2]), 2) == pytest.approx(0.2, abs=TOL)
    assert shape_signed_distance(seg, np.array([2.0, 0.0]), 2) == pytest.approx(1.0, abs=TOL)
    assert shape_signed_distance(Mesh(type="mesh", file="x.stl"), np.zeros(3), 3) is None


def test_object_pose_is_applied() -> None:
    scene = load_scene(EXAMPLES / "sphere_four_finger_palm.json")
    np.testing.assert_array_equal(object_origin(scene), [0.0, 0.0, 0.5])
    np.testing.assert_allclose(object_rotation(scene), np.eye(3), atol=TOL)
    # a rotated, shifted box: a world point maps through the pose
    rot = Rotation.from_euler("zyx", [0.3, -0.2, 0.5])
    w, x, y, z = np.roll(rot.as_quat(), 1)
    box_scene = scene.model_copy(
        update={
            "object": scene.object.model_copy(
                update={
                    "pose": scene.object.pose.model_copy(update={"quat_wxyz": [w, x, y, z]}),
                    "shape": Box(type="box", size=[0.4, 0.6, 0.8]),
                }
            )
        }
    )
    np.testing.assert_allclose(object_rotation(box_scene), rot.as_matrix(), atol=TOL)
    face_point = np.array([0.0, 0.0, 0.5]) + rot.apply([0.2, 0.1, -0.1])  # on the +x face
    assert object_signed_distance(box_scene, face_point) == pytest.approx(0.0, abs=TOL)
    outside = np.array([0.0, 0.0, 0.5]) + rot.apply([0.0, 0.5, 0.0])  # 0.2 beyond the +y face
    assert object_signed_distance(box_scene, outside) == pytest.approx(0.2, abs=TOL)


def test_object_rotation_2d() -> None:
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")
    turned = scene.model_copy(
        update={
            "object": scene.object.model_copy(
                update={"pose": scene.object.pose.model_copy(update={"angle": 0.7})}
            )
        }
    )
    R = object_rotation(turned)
    np.testing.assert_allclose(R[:2, :2], [[np.cos(0.7), -np.sin(0.7)], [np.sin(0.7), np.cos(0.7)]], atol=TOL)


@pytest.mark.parametrize(
    "name", ["planar_disk_envelope", "sphere_four_finger_palm", "sphere_four_finger_wrap"]
)
def test_canonical_contacts_are_on_both_surfaces(name: str) -> None:
    scene = load_scene(EXAMPLES / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    for c in scene.contacts:
        ref = hand.resolve_body(c.body)
        assert ref is not None
        p = np.asarray(c.point)
        assert body_surface_distance(scene, hand, ref, p) == pytest.approx(0.0, abs=1e-6)
        assert object_signed_distance(scene, p) == pytest.approx(0.0, abs=1e-6)
        # the normal points into the object: a step along it goes inside
        dist = object_signed_distance(scene, p + 0.01 * np.asarray(c.normal))
        assert dist is not None and dist < -0.005
