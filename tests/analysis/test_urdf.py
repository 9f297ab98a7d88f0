"""URDF fingers (analysis/urdf.py): known answers against hand-written chains, finite
differences on the Allegro hand, the Allegro example scene, and error messages."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.optimize import linprog

from analysis.contacts import build_system, tangent_basis
from analysis.exceptions import SceneError
from analysis.kinematics import HandKinematics, SerialChain, chain_from_finger
from analysis.loader import load_scene, scene_from_dict
from analysis.rotations import axis_angle_matrix, matrix_to_quat_wxyz, quat_wxyz_to_matrix
from analysis.scene import Finger3D, FingerURDF
from analysis.urdf import UrdfFinger, example_robot_data_dir, resolve_urdf_path

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "allegro_right_box.json"
ALLEGRO = "example-robot-data:allegro_hand_description/urdf/allegro_right_hand.urdf"
ALLEGRO_CHAINS = {  # tip link of each finger, root palm_link
    "index": "link_3.0_tip",
    "middle": "link_7.0_tip",
    "ring": "link_11.0_tip",
    "thumb": "link_15.0_tip",  # its first joint has an unaligned axis
}

# --------------------------------------------------------------------------------------------
# A tiny URDF and the same chain written by hand

# Chain base -> j1 -> l1 -> j2 -> l2 -> j3 -> l3 -> (fixed) -> tip. j1's origin has a rotation
# (rpy), j2's axis is not a coordinate axis. Around the chain: a revolute "arm" joint above the
# root (world -> base, locked, and replaced by the finger's base pose), a revolute side branch
# off the root and a prismatic side branch off l1 (both locked, neither on the chain).
RPY1 = (0.3, -0.2, 0.5)
ORIGIN1 = np.array([0.03, -0.02, 0.1])
AXES = np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [0.0, 1.0, 0.0]])  # (3, 3)
ORIGINS = np.array([[0.0, 0.0, 0.0], [0.0, 0.01, 0.2], [0.02, 0.0, 0.15]])  # (3, 3); j1's is ORIGIN1
TIP = np.array([0.0, 0.0, 0.12])


def tiny_urdf(j2_type: str = "revolute") -> str:
    def vec(v: Any) -> str:
        return " ".join(repr(float(c)) for c in v)

    limit = '<limit lower="-2" upper="2" effort="1" velocity="1"/>'
    j2_limit = limit if j2_type == "revolute" else ""
    links = "".join(f'<link name="{n}"/>' for n in ("world", "base", "l1", "l2", "l3", "tip", "side", "sl"))
    return f"""<?xml version="1.0"?>
<robot name="tiny">{links}
  <joint name="arm" type="revolute"><parent link="world"/><child link="base"/>
    <origin xyz="0.5 0.1 0.2" rpy="0.4 0.1 -0.3"/><axis xyz="1 0 0"/>{limit}</joint>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="{vec(ORIGIN1)}" rpy="{vec(RPY1)}"/><axis xyz="{vec(AXES[0])}"/>{limit}</joint>
  <joint name="j2" type="{j2_type}"><parent link="l1"/><child link="l2"/>
    <origin xyz="{vec(ORIGINS[1])}"/><axis xyz="{vec(AXES[1])}"/>{j2_limit}</joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="{vec(ORIGINS[2])}"/><axis xyz="{vec(AXES[2])}"/>{limit}</joint>
  <joint name="tipj" type="fixed"><parent link="l3"/><child link="tip"/>
    <origin xyz="{vec(TIP)}"/></joint>
  <joint name="side_j" type="revolute"><parent link="base"/><child link="side"/>
    <origin xyz="0 0.3 0"/><axis xyz="0 0 1"/>{limit}</joint>
  <joint name="slide" type="prismatic"><parent link="l1"/><child link="sl"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 0 1"/>{limit}</joint>
</robot>
"""


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF convention: ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (fixed axes x, y, z)."""
    ex, ey, ez = np.eye(3)
    return axis_angle_matrix(ez, yaw) @ axis_angle_matrix(ey, pitch) @ axis_angle_matrix(ex, roll)


BASE_QUAT = [0.8, 0.2, -0.4, 0.4]  # normalised below
BASE_POS = [0.1, -0.2, 0.3]


def base_quat() -> list[float]:
    q = np.asarray(BASE_QUAT) / np.linalg.norm(BASE_QUAT)
    return [float(v) for v in q]


def urdf_finger_spec(file: str, tip_link: str = "tip", q: list[float] | None = None,
                     root_link: str = "base") -> FingerURDF:
    return FingerURDF(
        name="f",
        base={"position": BASE_POS, "quat_wxyz": base_quat()},
        urdf={"file": file, "root_link": root_link, "tip_link": tip_link},
        q=[0.1, -0.4, 0.7] if q is None else q,
        link_radius=0.01,
    )


def reference_chain(q: list[float]) -> SerialChain:
    """The tiny URDF's chain as a Finger3D: j1's origin (translation and rpy) is folded into the
    base pose, so joint 0 has origin 0."""
    R_b = quat_wxyz_to_matrix(base_quat())
    base_R = R_b @ rpy_matrix(*RPY1)
    base_p = np.asarray(BASE_POS) + R_b @ ORIGIN1
    finger = Finger3D(
        name="f",
        base={"position": [float(v) for v in base_p],
              "quat_wxyz": [float(v) for v in matrix_to_quat_wxyz(base_R)]},
        joints=[{"axis": [float(c) for c in AXES[j]], "origin": [float(c) for c in ORIGINS[j]],
                 "radius": 0.01} for j in range(3)],
        tip=[float(c) for c in TIP],
        q=q,
    )
    chain = chain_from_finger(finger)
    assert isinstance(chain, SerialChain)
    return chain


@pytest.mark.parametrize("j2_type", ["revolute", "continuous"])
def test_tiny_urdf_matches_hand_written_chain(tmp_path: Path, j2_type: str) -> None:
    path = tmp_path / "tiny.urdf"
    path.write_text(tiny_urdf(j2_type))
    rng = np.random.default_rng(7)
    f = chain_from_finger(urdf_finger_spec(str(path)))
    assert isinstance(f, UrdfFinger)
    assert f.joint_names == ["j1", "j2", "j3"]  # arm, side_j and slide are locked
    assert f.body_names() == ["f/l1", "f/l2", "f/l3", "f/tip"]
    assert [f.joints_moving(k) for k in range(4)] == [[0], [0, 1], [0, 1, 2], [0, 1, 2]]
    assert f.body_index("l2") == 1 and f.body_index("base") is None and f.body_index("1") is None
    assert f.body_radius(2) == 0.01
    np.testing.assert_allclose(f.q0, [0.1, -0.4, 0.7])

    for _ in range(5):
        q = rng.uniform(-1.5, 1.5, 3)  # (3,)
        ref = reference_chain([float(v) for v in q])
        for k in range(3):  # URDF links l1..l3 are the chain's bodies 0..2
            R, p = f.body_pose(k, q)
            R_ref, p_ref = ref.body_pose(k, q)
            np.testing.assert_allclose(R, R_ref, atol=1e-12)
            np.testing.assert_allclose(p, p_ref, atol=1e-12)
            a, b = f.body_segment(k, q)
            a_ref, b_ref = ref.body_segment(k, q)
            np.testing.assert_allclose(a, a_ref, atol=1e-12)
            np.testing.assert_allclose(b, b_ref, atol=1e-12)
            x = p_ref + rng.normal(scale=0.1, size=3)  # (3,) a point fixed on body k
            np.testing.assert_allclose(f.point_jacobian(k, x, q), ref.point_jacobian(k, x, q), atol=1e-12)
        # the tip link sits at TIP in l3's frame and is moved by all three joints
        R3, p3 = ref.body_pose(2, q)
        R_tip, p_tip = f.body_pose(3, q)
        np.testing.assert_allclose(R_tip, R3, atol=1e-12)
        np.testing.assert_allclose(p_tip, p3 + R3 @ TIP, atol=1e-12)
        x = p_tip + rng.normal(scale=0.05, size=3)
        np.testing.assert_allclose(f.point_jacobian(3, x, q), ref.point_jacobian(2, x, q), atol=1e-12)
        a, b = f.body_segment(3, q)  # the tip has no child link: a sphere about its origin
        np.testing.assert_allclose(a, p_tip, atol=1e-12)
        np.testing.assert_allclose(b, p_tip, atol=1e-12)


def test_tip_segment_reaches_the_tip_links_only_child(tmp_path: Path) -> None:
    """A chain ending at l3 (whose one child is ``tip``) gets l3's segment up to ``tip``."""
    path = tmp_path / "tiny.urdf"
    path.write_text(tiny_urdf())
    f = UrdfFinger.from_spec(urdf_finger_spec(str(path), tip_link="l3"))
    q = np.array([0.2, 0.3, -0.5])
    R, p = f.body_pose(2, q)
    a, b = f.body_segment(2, q)
    np.testing.assert_allclose(a, p, atol=1e-12)
    np.testing.assert_allclose(b, p + R @ TIP, atol=1e-12)


def test_relative_path_resolves_from_the_current_directory(tmp_path: Path, monkeypatch: Any) -> None:
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "tiny.urdf").write_text(tiny_urdf())
    monkeypatch.chdir(tmp_path)
    f = UrdfFinger.from_spec(urdf_finger_spec("robots/tiny.urdf"))
    assert f.path == tmp_path / "robots" / "tiny.urdf"


# --------------------------------------------------------------------------------------------
# The Allegro hand: Jacobians against finite differences of forward kinematics


def test_example_robot_data_prefix_resolves() -> None:
    root = example_robot_data_dir()
    assert root is not None and (root / "allegro_hand_description").is_dir()
    assert resolve_urdf_path(ALLEGRO) == root / "allegro_hand_description/urdf/allegro_right_hand.urdf"


@pytest.mark.parametrize("finger", sorted(ALLEGRO_CHAINS))
def test_allegro_point_jacobians_match_finite_differences(finger: str) -> None:
    """``J(q) e_j`` equals ``(x(q + h e_j) - x(q - h e_j)) / 2h`` for points ``x`` fixed on each
    link, with ``x(q) = p_k(q) + R_k(q) x_local`` from :meth:`body_pose`."""
    rng = np.random.default_rng(20240531)
    base_R = quat_wxyz_to_matrix([0.9, -0.1, 0.3, 0.2])  # a generic base pose
    f = UrdfFinger(finger, resolve_urdf_path(ALLEGRO), "palm_link", ALLEGRO_CHAINS[finger],
                   np.zeros(4) + 0.3, base_R=base_R, base_p=np.array([0.2, -0.1, 0.5]), link_radius=0.01)
    assert f.n_joints == 4 and len(f.links) == 5
    h, tol = 1e-6, 1e-8  # central differences: truncation ~h^2 |x'''|, round-off ~1e-16 / h
    for _ in range(4):
        q = rng.uniform(f.lower, f.upper)  # (4,) within the URDF's joint limits
        for k in range(len(f.links)):
            R, p = f.body_pose(k, q)
            x = p + R @ rng.normal(scale=0.02, size=3)  # (3,) world point fixed on link k
            x_local = R.T @ (x - p)
            J = f.point_jacobian(k, x, q)  # (3, 4)
            J_fd = np.zeros((3, 4))  # (3, 4)
            for j in range(4):
                e = np.zeros(4)
                e[j] = h
                Rp, pp = f.body_pose(k, q + e)
                Rm, pm = f.body_pose(k, q - e)
                J_fd[:, j] = ((pp + Rp @ x_local) - (pm + Rm @ x_local)) / (2 * h)
            np.testing.assert_allclose(J, J_fd, atol=tol, rtol=0)
            # joints that do not move link k have zero columns
            still = [j for j in range(4) if j not in f.joints_moving(k)]
            assert np.all(J[:, still] == 0.0)
            assert np.linalg.norm(J[:, f.joints_moving(k)]) > 1e-3


# --------------------------------------------------------------------------------------------
# The example scene


def test_allegro_example_scene_loads_and_builds_the_contact_system() -> None:
    scene = load_scene(EXAMPLE)
    assert scene.dim == 3 and len(scene.fingers) == 4
    assert all(isinstance(f, FingerURDF) for f in scene.fingers)
    hand = HandKinematics.from_scene(scene)
    assert hand.M == 16
    system = build_system(scene, hand)
    L = len(scene.contacts)
    assert system.J.shape == (3 * L, 16) and system.G.shape == (6, 3 * L)
    assert system.A.shape == (3 * L, 16 + 6)
    fingers_touching = {c.body.split("/")[0] for c in scene.contacts if "/" in c.body}
    assert len(fingers_touching) >= 3
    assert any(not c.body.endswith("_tip") for c in scene.contacts if "/" in c.body)
    for i, ref in enumerate(system.bodies):
        Ji = system.J_blocks[i]  # (3, 16)
        moving = hand.moving_joints(ref)
        others = [j for j in range(16) if j not in moving]
        assert np.all(Ji[:, others] == 0.0)
        if ref.is_fixed:
            assert not moving
        else:  # a contact on a finger link moves with the finger: J has full row rank 2 at least
            assert np.linalg.matrix_rank(Ji[:, moving]) >= 2
    # the normal of the thumb contact opposes the normals of some finger contacts
    thumb = [system.normals[i] for i, c in enumerate(scene.contacts) if c.body.startswith("thumb/")]
    others_n = [system.normals[i] for i, c in enumerate(scene.contacts) if not c.body.startswith("thumb/")]
    assert thumb and min(float(t @ n) for t in thumb for n in others_n) < -0.99


def pyramid_wrenches(scene_path: Path) -> tuple[Any, list[np.ndarray]]:
    """The contact system and, per contact, the wrenches ``(6, 16)`` at ``p_o`` of the edges of
    its inscribed 16-sided friction pyramid (each edge has normal component 1)."""
    system = build_system(load_scene(scene_path))
    th = 2 * np.pi * np.arange(16) / 16
    cols = []
    for i in range(system.L):
        t1, t2 = tangent_basis(system.normals[i])
        gens = system.normals[i] + system.mu[i] * (np.outer(np.cos(th), t1) + np.outer(np.sin(th), t2))
        cols.append(system.G_blocks[i] @ gens.T)  # (6, 16)
    return system, cols


def test_allegro_example_contacts_can_hold_the_bar() -> None:
    """The grasp is physically sensible: (1) forces in the friction pyramids with every normal
    force >= 0.1 N balance the weight, ``G f = -w_ex`` (an LP); (2) it is a force-closure grasp:
    the pyramid-edge wrenches span R^6 and a strictly positive combination of them is zero."""
    system, cols = pyramid_wrenches(EXAMPLE)
    W = np.hstack(cols)  # (6, 16 L); a force's normal component is the sum of its lambdas
    n = W.shape[1]
    A_ub = np.kron(np.eye(system.L), -np.ones((1, 16)))  # -sum_j lambda_ij <= -0.1
    res = linprog(np.ones(n), A_ub=A_ub, b_ub=-0.1 * np.ones(system.L), A_eq=W, b_eq=-system.w_ex,
                  bounds=(0, None), method="highs")
    assert res.status == 0, res.message
    assert np.linalg.matrix_rank(W) == 6
    res = linprog(np.zeros(n), A_eq=W, b_eq=np.zeros(6), bounds=(1, None), method="highs")
    assert res.status == 0, res.message


def test_example_validation_rejects_a_point_off_its_link() -> None:
    data = json.loads(EXAMPLE.read_text())
    i = next(i for i, c in enumerate(data["contacts"]) if c["body"] == "index/link_1.0")
    data["contacts"][i]["point"][0] += 1e-3
    with pytest.raises(SceneError) as e:
        scene_from_dict(data)
    assert e.value.loc == ("contacts", i, "point")
    assert "index/link_1.0" in e.value.reason


# --------------------------------------------------------------------------------------------
# Bad input


def scene_with_finger(**urdf: str) -> dict[str, Any]:
    data = json.loads(EXAMPLE.read_text())
    data["fingers"][1]["urdf"].update(urdf)
    return data


@pytest.mark.parametrize(
    ("change", "loc", "words"),
    [
        ({"tip_link": "link_99.0_tip"}, ("urdf", "tip_link"),
         ["unknown link 'link_99.0_tip'", "link_7.0_tip"]),
        ({"root_link": "hand_root"}, ("urdf", "root_link"), ["unknown link 'hand_root'"]),
        ({"root_link": "link_1.0"}, ("urdf", "tip_link"), ["not below root_link 'link_1.0'"]),
        ({"tip_link": "palm_link"}, ("urdf", "tip_link"), ["no revolute joint"]),
        ({"file": "no/such/hand.urdf"}, ("urdf", "file"), ["not found", "no/such/hand.urdf"]),
        ({"file": "example-robot-data:nothing_description/urdf/x.urdf"}, ("urdf", "file"), ["not found"]),
    ],
)
def test_bad_urdf_fields_raise_scene_errors_naming_the_field(
    change: dict[str, str], loc: tuple[str, ...], words: list[str]
) -> None:
    data = scene_with_finger(**change)
    spec = FingerURDF.model_validate(data["fingers"][1])
    with pytest.raises(SceneError) as e:
        UrdfFinger.from_spec(spec)
    assert e.value.loc == loc
    for w in words:
        assert w in e.value.reason
    # through the scene: the location is prefixed by the finger's index
    with pytest.raises(SceneError) as e2:
        scene_from_dict(data)
    assert e2.value.loc == ("fingers", 1, *loc)
    assert str(e2.value).startswith(f"fingers.1.{'.'.join(loc)}: ")


def test_wrong_q_length_raises_scene_error() -> None:
    data = json.loads(EXAMPLE.read_text())
    data["fingers"][2]["q"] = [0.0, 0.1, 0.2]
    with pytest.raises(SceneError) as e:
        scene_from_dict(data)
    assert e.value.loc == ("fingers", 2, "q")
    assert "has 3 values" in e.value.reason and "4 revolute joints" in e.value.reason
    f = UrdfFinger.from_spec(FingerURDF.model_validate(json.loads(EXAMPLE.read_text())["fingers"][0]))
    with pytest.raises(SceneError, match="has 5 values"):
        f.point_jacobian(0, np.zeros(3), np.zeros(5))
