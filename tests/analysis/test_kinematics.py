"""Forward kinematics and point Jacobians (eq. 1): Jacobians equal central finite differences of
forward kinematics on random planar and spatial chains and on the canonical scenes; closed-form
answers for a planar 2-link arm; link end points; body names."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from analysis.geometry import body_surface_distance, link_shapes
from analysis.kinematics import (
    BodyRef,
    HandKinematics,
    SerialChain,
    chain_from_finger,
    joint_count,
    segment_distance,
)
from analysis.loader import load_scene
from analysis.scene import Base2D, Finger2D, Link2D

Array = NDArray[np.float64]

EXAMPLES = Path(__file__).parents[2] / "examples"
FD_STEP = 1e-5
FD_TOL = 1e-6  # central differences: truncation ~ h^2 |p'''| ~ 1e-10, rounding ~ 1e-16 / h


def finite_difference_jacobian(hand: HandKinematics, ref: BodyRef, x_local: Array, q: Array) -> Array:
    """Central differences of the world position of a body-fixed point, ``(d, M)``."""
    J = np.zeros((hand.dim, hand.M))
    for j in range(hand.M):
        dq = np.zeros(hand.M)
        dq[j] = FD_STEP
        J[:, j] = (hand.point_position(ref, x_local, q + dq) - hand.point_position(ref, x_local, q - dq)) / (
            2 * FD_STEP
        )
    return J


def random_planar_finger(rng: np.random.Generator, name: str) -> Finger2D:
    n = int(rng.integers(1, 6))
    return Finger2D(
        name=name,
        base=Base2D(position=rng.uniform(-1, 1, 2).tolist(), angle=float(rng.uniform(-np.pi, np.pi))),
        links=[
            Link2D(length=float(rng.uniform(0.2, 1.5)), radius=float(rng.uniform(0, 0.1))) for _ in range(n)
        ],
        q=rng.uniform(-np.pi, np.pi, n).tolist(),
    )


def random_unit(rng: np.random.Generator) -> Array:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def random_spatial_chain(rng: np.random.Generator, name: str) -> SerialChain:
    n = int(rng.integers(1, 7))
    return SerialChain(
        name,
        Rotation.random(random_state=rng).as_matrix(),
        rng.uniform(-1, 1, 3),
        np.array([random_unit(rng) for _ in range(n)]),
        rng.uniform(-0.8, 0.8, (n, 3)),
        rng.uniform(-0.8, 0.8, 3),
        rng.uniform(0, 0.1, n),
        rng.uniform(-np.pi, np.pi, n),
    )


def random_hand(rng: np.random.Generator, dim: int) -> HandKinematics:
    """One to three random fingers, so the q slicing of every finger is exercised."""
    n_fingers = int(rng.integers(1, 4))
    if dim == 2:
        fingers = [chain_from_finger(random_planar_finger(rng, f"f{i}")) for i in range(n_fingers)]
    else:
        fingers = [random_spatial_chain(rng, f"f{i}") for i in range(n_fingers)]
    return HandKinematics(dim, fingers, ["palm"])


def finger_bodies(hand: HandKinematics) -> list[BodyRef]:
    refs = [hand.resolve_body(name) for name in hand.body_names()]
    return [r for r in refs if r is not None and not r.is_fixed]


# --------------------------------------------------------------------------------------------
# Jacobians vs finite differences


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(25))
def test_point_jacobian_equals_finite_differences_on_random_chains(dim: int, seed: int) -> None:
    rng = np.random.default_rng(1000 * dim + seed)
    hand = random_hand(rng, dim)
    q = rng.uniform(-np.pi, np.pi, hand.M)
    for ref in finger_bodies(hand):
        x_local = rng.uniform(-1, 1, 3)
        if dim == 2:
            x_local[2] = 0.0
        x = hand.point_position(ref, x_local, q)
        assert x.shape == (dim,)
        J = hand.point_jacobian(ref, x, q)
        assert J.shape == (dim, hand.M)
        np.testing.assert_allclose(J, finite_difference_jacobian(hand, ref, x_local, q), rtol=0, atol=FD_TOL)
        # only the joints that move the body appear, and they are its finger's joints 0..k
        moving = hand.moving_joints(ref)
        assert ref.finger is not None
        sl = hand.finger_slice(ref.finger)
        assert moving == list(range(sl.start, sl.start + ref.link + 1))
        others = np.setdiff1d(np.arange(hand.M), moving)
        assert np.all(J[:, others] == 0.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_point_jacobians_equal_one_point_at_a_time(dim: int) -> None:
    """``point_jacobians`` of several points on a body is ``point_jacobian`` of each, exactly (the
    same products element by element), on random hands; zero for a fixed body."""
    rng = np.random.default_rng(77 + dim)
    for _ in range(10):
        hand = random_hand(rng, dim)
        q = rng.uniform(-np.pi, np.pi, hand.M)
        for ref in finger_bodies(hand):
            X = rng.uniform(-1, 1, (3, dim))
            many = hand.point_jacobians(ref, X, q)
            assert many.shape == (3, dim, hand.M)
            for x, J in zip(X, many, strict=True):
                assert np.array_equal(J, hand.point_jacobian(ref, x, q))
    palm = hand.resolve_body("palm")
    assert palm is not None
    assert not hand.point_jacobians(palm, np.zeros((2, dim)), q).any()


@pytest.mark.parametrize("seed", range(10))
def test_body_frames_match_an_independent_forward_kinematics(seed: int) -> None:
    """``T_k = T_base prod_j Trans(origin_j) Rot(axis_j, q_j)`` composed with scipy's rotations."""
    rng = np.random.default_rng(seed)
    chain = random_spatial_chain(rng, "f")
    q = rng.uniform(-np.pi, np.pi, chain.n_joints)
    R, p = chain.base_R, chain.base_p
    for k in range(chain.n_joints):
        p = p + R @ chain.origins[k]
        R = R @ Rotation.from_rotvec(chain.axes[k] * q[k]).as_matrix()
        Rk, pk = chain.body_pose(k, q)
        np.testing.assert_allclose(Rk, R, rtol=0, atol=1e-12)
        np.testing.assert_allclose(pk, p, rtol=0, atol=1e-12)
    a, b = chain.body_segment(chain.n_joints - 1, q)
    np.testing.assert_allclose(a, p, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b, p + R @ chain.tip, rtol=0, atol=1e-12)


CANONICAL = sorted(EXAMPLES.glob("*.json"))  # loaded inside the tests, not at collection


@pytest.mark.parametrize("path", CANONICAL, ids=lambda p: p.stem)
def test_contact_jacobians_of_canonical_scenes_equal_finite_differences(path: Path) -> None:
    scene = load_scene(path)
    hand = HandKinematics.from_scene(scene)
    assert joint_count(scene) == hand.M
    rng = np.random.default_rng(7)
    configurations = [hand.q0] + [hand.q0 + rng.uniform(-0.5, 0.5, hand.M) for _ in range(3)]
    n_finger_contacts = 0
    for c in scene.contacts:
        ref = hand.resolve_body(c.body)
        assert ref is not None
        x_local = hand.to_local(ref, np.asarray(c.point), hand.q0)  # the finger's material point
        for q in configurations:
            x = hand.point_position(ref, x_local, q)
            J = hand.point_jacobian(ref, x, q)
            if ref.is_fixed:
                assert np.all(J == 0.0)
                np.testing.assert_allclose(x, c.point, rtol=0, atol=1e-12)  # fixed bodies stay put
            else:
                fd = finite_difference_jacobian(hand, ref, x_local, q)
                np.testing.assert_allclose(J, fd, rtol=0, atol=FD_TOL)
                assert np.abs(J).max() > 1e-3  # a finger contact is moved by its joints
        n_finger_contacts += not ref.is_fixed
    assert n_finger_contacts >= 1  # the Panda presses the box with one forearm contact


@pytest.mark.parametrize("path", CANONICAL, ids=lambda p: p.stem)
def test_canonical_contact_points_lie_on_their_links(path: Path) -> None:
    scene = load_scene(path)
    hand = HandKinematics.from_scene(scene)
    for c in scene.contacts:
        ref = hand.resolve_body(c.body)
        assert ref is not None
        if ref.is_fixed:
            continue
        p = np.asarray(c.point)
        # on the link's surface: its capsule, or its URDF collision shapes (link_geometry "urdf")
        d = body_surface_distance(scene, hand, ref, p)
        assert d is not None
        assert d == pytest.approx(0.0, abs=1e-6)
        if link_shapes(hand, ref, hand.q0) is None:  # a capsule: the same by its segment
            a, b = hand.body_segment(ref, hand.q0)
            assert segment_distance(p, a, b) - hand.body_radius(ref) == pytest.approx(0.0, abs=1e-6)
        # the point round-trips through the body frame
        np.testing.assert_allclose(
            hand.point_position(ref, hand.to_local(ref, p, hand.q0), hand.q0), p, rtol=0, atol=1e-12
        )


# --------------------------------------------------------------------------------------------
# Known answers


def planar_two_link(
    base: tuple[float, float], angle: float, l1: float, l2: float, q: tuple[float, float]
) -> HandKinematics:
    finger = Finger2D(
        name="arm",
        base=Base2D(position=list(base), angle=angle),
        links=[Link2D(length=l1), Link2D(length=l2, radius=0.05)],
        q=list(q),
    )
    return HandKinematics(2, [chain_from_finger(finger)], [])


@pytest.mark.parametrize("seed", range(5))
def test_planar_two_link_jacobian_in_closed_form(seed: int) -> None:
    rng = np.random.default_rng(seed)
    bx, by = rng.uniform(-1, 1, 2)
    phi = float(rng.uniform(-np.pi, np.pi))
    l1, l2 = rng.uniform(0.3, 1.2, 2)
    q1, q2 = rng.uniform(-np.pi, np.pi, 2)
    hand = planar_two_link((bx, by), phi, l1, l2, (q1, q2))
    q = hand.q0
    t1, t12 = phi + q1, phi + q1 + q2
    elbow = np.array([bx + l1 * np.cos(t1), by + l1 * np.sin(t1)])
    tip = elbow + l2 * np.array([np.cos(t12), np.sin(t12)])

    link1 = hand.resolve_body("arm/1")
    assert link1 == BodyRef(name="arm/1", finger=0, link=1)
    np.testing.assert_allclose(hand.point_position(link1, np.array([l2, 0.0, 0.0]), q), tip, atol=1e-12)
    J_tip = np.array(
        [
            [-l1 * np.sin(t1) - l2 * np.sin(t12), -l2 * np.sin(t12)],
            [l1 * np.cos(t1) + l2 * np.cos(t12), l2 * np.cos(t12)],
        ]
    )
    np.testing.assert_allclose(hand.point_jacobian(link1, tip, q), J_tip, rtol=0, atol=1e-12)

    # a point at distance s along link 0 moves only with q1
    link0 = hand.resolve_body("arm/0")
    assert link0 is not None
    s = 0.4 * l1
    x = np.array([bx + s * np.cos(t1), by + s * np.sin(t1)])
    J0 = np.array([[-s * np.sin(t1), 0.0], [s * np.cos(t1), 0.0]])
    np.testing.assert_allclose(hand.point_jacobian(link0, x, q), J0, rtol=0, atol=1e-12)

    # link end points and radii
    a0, b0 = hand.body_segment(link0, q)
    a1, b1 = hand.body_segment(link1, q)
    np.testing.assert_allclose(a0, [bx, by], atol=1e-12)
    np.testing.assert_allclose(b0, elbow, atol=1e-12)
    np.testing.assert_allclose(a1, elbow, atol=1e-12)
    np.testing.assert_allclose(b1, tip, atol=1e-12)
    assert (hand.body_radius(link0), hand.body_radius(link1)) == (0.0, 0.05)


def test_spatial_two_joint_body_segments_by_hand() -> None:
    # joint 0 about z at the base, joint 1 about y one unit up, tip 0.5 along the last z axis
    chain = SerialChain(
        "f",
        np.eye(3),
        np.zeros(3),
        np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]),
        np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
        np.array([0.0, 0.0, 0.5]),
        np.zeros(2),
        np.array([np.pi / 2, np.pi / 2]),
    )
    hand = HandKinematics(3, [chain], [])
    q = hand.q0
    a0, b0 = hand.body_segment(BodyRef("f/0", 0, 0), q)
    a1, b1 = hand.body_segment(BodyRef("f/1", 0, 1), q)
    np.testing.assert_allclose(a0, [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(b0, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(a1, [0, 0, 1], atol=1e-12)
    # Ry(90) takes z to x, then Rz(90) takes x to y
    np.testing.assert_allclose(b1, [0, 0.5, 1], atol=1e-12)
    # at the tip: joint 0 (z through the origin) moves it along -x; joint 1 (world axis
    # Rz(90) y = -x through (0, 0, 1)) moves it along (-x) x (0, 0.5, 0) = -0.5 z
    J = hand.point_jacobian(BodyRef("f/1", 0, 1), b1, q)
    np.testing.assert_allclose(J, [[-0.5, 0.0], [0.0, 0.0], [0.0, -0.5]], atol=1e-12)


def test_body_names_and_resolution() -> None:
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")
    hand = HandKinematics.from_scene(scene)
    assert hand.body_names() == ["palm", "left/0", "left/1", "right/0", "right/1"]
    assert hand.resolve_body("palm") == BodyRef(name="palm")
    assert hand.resolve_body("right/1") == BodyRef(name="right/1", finger=1, link=1)
    for bad in ("left/2", "left/9", "left/-1", "left/x", "left/\u00b2", "left", "thumb/0", ""):
        assert hand.resolve_body(bad) is None, bad
    assert hand.finger_slice(1) == slice(2, 4)
    assert hand.moving_joints(BodyRef(name="right/0", finger=1, link=0)) == [2]
    assert hand.moving_joints(BodyRef(name="palm")) == []
    np.testing.assert_allclose(hand.q0, [1.3894765524, -1.0808390005, 1.7521161012, 1.0808390005])
    # a fixed body: identity frame, zero Jacobian
    R, p = hand.body_pose(BodyRef(name="palm"), hand.q0)
    assert np.array_equal(R, np.eye(3)) and np.array_equal(p, np.zeros(3))


def test_hand_without_fingers() -> None:
    hand = HandKinematics(2, [], ["table"])
    assert hand.M == 0 and hand.q0.shape == (0,)
    J = hand.point_jacobian(BodyRef(name="table"), np.array([0.3, 0.0]), hand.q0)
    assert J.shape == (2, 0)


@pytest.mark.parametrize(
    ("p", "expected"),
    [((0.5, 1.0), 1.0), ((-1.0, 0.0), 1.0), ((3.0, 4.0), np.hypot(2.0, 4.0)), ((0.25, 0.0), 0.0)],
)
def test_segment_distance(p: tuple[float, float], expected: float) -> None:
    a, b = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    assert segment_distance(np.array(p), a, b) == pytest.approx(expected, abs=1e-12)
    assert segment_distance(np.array(p), a, a) == pytest.approx(np.hypot(*p), abs=1e-12)


def test_frames_remembered_for_the_last_configuration_only() -> None:
    """``SerialChain.frames`` keeps the last configuration's frames (read-only), and answers a new
    configuration afresh: alternating configurations give each its own frames, equal to a chain
    that never saw the other."""
    chain = SerialChain("f", np.eye(3), np.zeros(3), np.array([[0, 0, 1.0], [0, 1.0, 0], [0, 1.0, 0]]),
                        np.array([[0, 0, 0.0], [0, 0, 0.5], [0, 0, 0.5]]), np.array([0, 0, 0.3]), np.zeros(3),
                        np.zeros(3))
    fresh = SerialChain("g", chain.base_R, chain.base_p, chain.axes, chain.origins, chain.tip, chain.radii, chain.q0)
    rng = np.random.default_rng(3)
    qs = [rng.uniform(-2, 2, 3) for _ in range(3)]
    for q in qs + qs[::-1] + qs:
        Rs, ps = chain.frames(q)
        Rf, pf = SerialChain("h", chain.base_R, chain.base_p, chain.axes, chain.origins, chain.tip, chain.radii,
                             chain.q0).frames(q)
        for a, b in zip(Rs + ps, Rf + pf, strict=True):
            np.testing.assert_array_equal(a, b)
        assert chain.frames(q.copy())[0][0] is Rs[0]  # the same configuration: remembered
        with pytest.raises(ValueError):
            Rs[0][0, 0] = 1.0  # read-only
    assert fresh.frames(qs[0])[1][2] is not chain.frames(qs[0])[1][2]


@pytest.mark.parametrize("seed", range(5))
def test_point_jacobian_is_the_cross_product_of_each_world_axis_and_lever(seed: int) -> None:
    """Column ``j`` of a body point's Jacobian is ``a_j x (x - p_j)`` (eq. 1) with the world axis
    ``a_j = R_j axis_j`` and the joint origin ``p_j``, exactly as ``np.cross`` gives it (the chain
    computes the three components itself), also when configurations alternate (its world axes are
    remembered with the frames of the last one only)."""
    rng = np.random.default_rng(50 + seed)
    chain = random_spatial_chain(rng, "f")
    qs = [rng.uniform(-np.pi, np.pi, chain.n_joints) for _ in range(3)]
    for q in qs + qs[::-1]:
        Rs, ps = chain.frames(q)
        for k in range(chain.n_joints):
            x = rng.uniform(-1, 1, 3)
            J = chain.point_jacobian(k, x, q)
            want = np.zeros((3, chain.n_joints))
            for j in range(k + 1):
                want[:, j] = np.cross(Rs[j] @ chain.axes[j], x - ps[j])
            np.testing.assert_array_equal(J, want)
