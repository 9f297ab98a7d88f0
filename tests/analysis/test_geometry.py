"""Signed distances to the scene's shapes (known answers) and the object's pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from analysis.geometry import (
    NormalCone,
    body_normal_cone,
    body_surface_distance,
    object_normal_cone,
    object_origin,
    object_rotation,
    object_signed_distance,
    segment_normal_cone,
    shape_normal_cone,
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


# --------------------------------------------------------------------------------------------
# Normal cones: N(p) = {g : g^T (x - p) <= 0 for all x in the body}


UNIT_CUBE = Box(type="box", size=[1.0, 1.0, 1.0])
EX, EY, EZ = np.eye(3)


def _u(*v: float) -> np.ndarray:
    a = np.array(v, dtype=float)
    return a / np.linalg.norm(a)


@pytest.mark.parametrize(
    ("p", "n_generators"),
    [((-0.5, -0.5, -0.5), 3), ((-0.5, 0.1, -0.5), 2), ((0.2, 0.1, -0.5), 1), ((-0.5 + 5e-5, 0.1, -0.5), 2)],
)
def test_box_normal_cone_has_one_generator_per_face_at_the_point(p: tuple[float, ...], n_generators: int) -> None:
    # a vertex (3 faces), an edge (2), a face (1), and a face point within tol = 1e-4 of an edge
    cone = shape_normal_cone(UNIT_CUBE, np.array(p), 3, 1e-4)
    assert cone is not None and cone.generators.shape == (n_generators, 3)


@pytest.mark.parametrize(
    ("u", "expected"),
    [
        (-EZ, 0.0),  # the table's normal at the corner: inside
        (_u(-1, -1, -1), 0.0),  # the corner's diagonal: inside
        (_u(-1, -2, -0.5), 0.0),
        (EZ, 1.0),  # into the cube: the projection onto the cone is 0
        (_u(0.6, 0, -0.8), 0.6),  # off the x-face by its x part
        (_u(0.6, 0.8, 0), 1.0),
    ],
)
def test_box_corner_cone_distances(u: np.ndarray, expected: float) -> None:
    cone = shape_normal_cone(UNIT_CUBE, np.array([-0.5, -0.5, -0.5]), 3, 1e-4)
    assert cone is not None and cone.distance(u) == pytest.approx(expected, abs=1e-12)


def test_box_face_cone_is_the_face_normal() -> None:
    cone = shape_normal_cone(UNIT_CUBE, np.array([0.2, 0.1, -0.5]), 3, 1e-4)
    assert cone is not None
    for theta in (1e-4, 0.01, 0.3):  # a tilt by theta is sin(theta) off the ray
        assert cone.distance(np.array([np.sin(theta), 0.0, -np.cos(theta)])) == pytest.approx(np.sin(theta))
    assert cone.contains(-EZ, 1e-12) and not cone.contains(_u(0.01, 0, -1), 1e-3)


def test_polygon_corner_and_cylinder_rim_cones() -> None:
    square = Polygon(type="polygon", vertices=[[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    cone = shape_normal_cone(square, np.array([0.5, 0.5]), 2, 1e-4)
    assert cone is not None and cone.generators.shape == (2, 2)
    a = np.radians(30)
    assert cone.distance(np.array([np.cos(a), np.sin(a)])) == pytest.approx(0.0, abs=1e-12)
    assert cone.distance(np.array([np.cos(a), -np.sin(a)])) == pytest.approx(np.sin(a))  # 30 deg below
    can = Cylinder(type="cylinder", radius=0.5, height=2.0)
    rim = shape_normal_cone(can, np.array([0.0, 0.5, 1.0]), 3, 1e-4)
    assert rim is not None and rim.generators.shape == (2, 3)
    assert rim.distance(_u(0, 1, 1)) == pytest.approx(0.0, abs=1e-12)
    assert rim.distance(_u(1, 1, 1)) == pytest.approx(1 / np.sqrt(3))  # the x part is off
    side = shape_normal_cone(can, np.array([0.0, 0.5, 0.3]), 3, 1e-4)
    assert side is not None and side.distance(EY) == pytest.approx(0.0, abs=1e-12)
    sphere = shape_normal_cone(Sphere(type="sphere", radius=2.0), np.array([0.0, 1.2, 1.6]), 3, 1e-4)
    assert sphere is not None and sphere.distance(_u(0, 0.6, 0.8)) == pytest.approx(0.0, abs=1e-12)
    assert shape_normal_cone(Mesh(type="mesh", file="x.stl"), np.zeros(3), 3, 1e-4) is None


def test_segment_and_capsule_cones() -> None:
    a, b = np.zeros(3), EX
    capsule = segment_normal_cone(np.array([0.5, 0.1, 0.0]), a, b, 0.1, 1e-4)
    assert capsule.generators.shape == (1, 3) and capsule.distance(EY) == pytest.approx(0.0, abs=1e-12)
    cap = segment_normal_cone(np.array([1.1, 0.0, 0.0]), a, b, 0.1, 1e-4)  # the spherical end
    assert cap.distance(EX) == pytest.approx(0.0, abs=1e-12)
    bare = segment_normal_cone(np.array([0.5, 0.0, 0.0]), a, b, 0.0, 1e-4)  # every perpendicular
    assert bare.distance(_u(0, 0.6, 0.8)) == pytest.approx(0.0, abs=1e-12)
    assert bare.distance(_u(0.6, 0.8, 0)) == pytest.approx(0.6)
    end = segment_normal_cone(b, a, b, 0.0, 1e-4)  # the half-space g . e >= 0
    assert end.distance(EX) == pytest.approx(0.0, abs=1e-12)
    assert end.distance(_u(-0.6, 0.8, 0)) == pytest.approx(0.6)
    table = Segment(type="segment", points=[[-1.0, 0.0], [1.0, 0.0]])
    cone = shape_normal_cone(table, np.array([0.3, 0.0]), 2, 1e-4)
    assert cone is not None and cone.distance(np.array([0.0, 1.0])) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_box_cone_membership_equals_the_support_function(seed: int) -> None:
    """``u in N(p)`` iff ``p`` maximises ``u^T x`` over the box: ``h(u) = u^T c + sum |u_k| h_k``
    equals ``u^T p``; and the distance equals scipy's non-negative least squares residual."""
    from scipy.optimize import nnls

    rng = np.random.default_rng(seed)
    half = rng.uniform(0.2, 2.0, 3)
    box = Box(type="box", size=(2 * half).tolist())
    for _ in range(40):
        p = rng.uniform(-half, half)
        active = rng.random(3) < 0.6
        p[active] = np.sign(rng.normal(size=int(active.sum()))) * half[active]  # a vertex, edge or face
        if not active.any():
            p[0] = half[0]
        cone = shape_normal_cone(box, p, 3, 1e-9)
        assert cone is not None
        for _ in range(10):
            u = _u(*rng.normal(size=3))
            if rng.random() < 0.5:  # a member: a non-negative combination of the generators
                u = _u(*(rng.uniform(0, 1, len(cone.generators)) @ cone.generators))
            gap = float(np.abs(u) @ half - u @ p)
            assert (cone.distance(u) <= 1e-9) == (gap <= 1e-9)
            assert cone.distance(u) == pytest.approx(nnls(cone.generators.T, u)[1], abs=1e-9)


def test_object_and_body_cones_are_in_world_coordinates() -> None:
    """A cube turned 45 deg about y stands on its edge x = +0.5, z = -0.5 (local): there the
    cone of the object is spanned by R e_x and -R e_z, which contains the table's (0, 0, -1)."""
    from analysis.loader import scene_from_dict

    c = np.sqrt(0.5)
    scene = scene_from_dict({
        "dim": 3,
        "object": {"pose": {"position": [0, 0, c], "quat_wxyz": [np.cos(np.pi / 8), 0, np.sin(np.pi / 8), 0]},
                   "shape": {"type": "box", "size": [1, 1, 1]}},
        "external_wrench": [0, 0, -1, 0, 0, 0],
        "fixed_bodies": [{"name": "table", "shape": {"type": "box", "size": [4, 4, 0.1], "position": [0, 0, -0.05]}}],
        "contacts": [{"body": "table", "point": [0, y, 0], "normal": [0, 0, 1], "mu": 0.5} for y in (-0.5, 0.5)],
    })
    cone = object_normal_cone(scene, np.array([0.0, 0.5, 0.0]), 1e-4)
    assert cone is not None and cone.generators.shape == (3, 3)  # the corner (y = 0.5) of that edge
    edge = object_normal_cone(scene, np.array([0.0, 0.2, 0.0]), 1e-4)
    assert edge is not None
    np.testing.assert_allclose(sorted(map(tuple, edge.generators)), [(-c, 0, -c), (c, 0, -c)], atol=1e-12)
    assert edge.distance(-EZ) == pytest.approx(0.0, abs=1e-12)
    assert edge.distance(_u(np.tan(np.radians(50)), 0, -1)) == pytest.approx(np.sin(np.radians(5)))
    hand = HandKinematics.from_scene(scene)
    table = body_normal_cone(scene, hand, hand.resolve_body("table"), np.array([0.0, 0.2, 0.0]), 1e-4)
    assert table is not None and isinstance(table, NormalCone) and table.distance(EZ) == 0.0


def test_cone_membership_agrees_with_the_distance_over_every_face() -> None:
    """``NormalCone.contains`` (a ray or a plane of opposite rays first, then every face) answers
    ``distance(u) <= tol`` on seeded cones: bare segments' perpendicular pairs (with and without
    an end ray), random cones of 1-3 rays, near-plane directions."""
    rng = np.random.default_rng(0)
    seen = set()
    for trial in range(600):
        if trial % 3 == 0:
            e = rng.normal(size=3)
            e /= np.linalg.norm(e)
            B = np.linalg.svd(e[None])[2][1:]  # (2, 3) perpendiculars of the segment
            G = np.vstack([B[0], -B[0], B[1], -B[1]] + ([e] if trial % 2 else []))
        else:
            G = rng.normal(size=(int(rng.integers(1, 4)), 3))
            G /= np.linalg.norm(G, axis=1)[:, None]
        cone = NormalCone(G)
        for _ in range(4):
            u = rng.normal(size=3)
            if trial % 3 == 0 and rng.random() < 0.5:
                u -= 0.999 * (u @ e) * e  # close to the plane
            u /= np.linalg.norm(u)
            for tol in (0.01, 0.1, 0.5):
                want = cone.distance(u) <= tol
                assert cone.contains(u, tol) == want
                seen.add(want)
    assert seen == {True, False}
