"""Rotation helpers against scipy's reference implementation, and round trips."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from analysis.rotations import (
    axis_angle_matrix,
    matrix_to_quat_wxyz,
    matrix_to_rotvec,
    quat_wxyz_to_matrix,
    rotvec_to_matrix,
    rotz,
    skew,
)

TOL = 1e-12


def test_quaternion_conversions_match_scipy() -> None:
    rng = np.random.default_rng(0)
    for rot in Rotation.random(200, random_state=rng):
        x, y, z, w = rot.as_quat()
        R = rot.as_matrix()
        np.testing.assert_allclose(quat_wxyz_to_matrix([w, x, y, z]), R, rtol=0, atol=TOL)
        q = matrix_to_quat_wxyz(R)
        assert q[0] >= 0 and np.linalg.norm(q) == pytest.approx(1.0, abs=TOL)
        np.testing.assert_allclose(q, np.sign(w) * np.array([w, x, y, z]), rtol=0, atol=1e-10)


@pytest.mark.parametrize(
    "R",
    [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])],
    ids=["identity", "pi-x", "pi-y", "pi-z"],
)
def test_matrix_to_quat_on_half_turns(R: np.ndarray) -> None:
    np.testing.assert_allclose(quat_wxyz_to_matrix(matrix_to_quat_wxyz(R)), R, rtol=0, atol=TOL)


def test_quat_is_normalised_before_use() -> None:
    np.testing.assert_allclose(quat_wxyz_to_matrix([2.0, 0.0, 0.0, 0.0]), np.eye(3), atol=TOL)


def test_axis_angle_and_rotvec_match_scipy() -> None:
    rng = np.random.default_rng(1)
    for _ in range(200):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = float(rng.uniform(-np.pi, np.pi))
        R = Rotation.from_rotvec(axis * angle).as_matrix()
        np.testing.assert_allclose(axis_angle_matrix(axis, angle), R, rtol=0, atol=TOL)
        np.testing.assert_allclose(rotvec_to_matrix(axis * angle), R, rtol=0, atol=TOL)
        np.testing.assert_allclose(matrix_to_rotvec(R), Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=TOL)


@pytest.mark.parametrize("gap", [0.0, 1e-9, 1e-7, 5e-7, 2e-6, 1e-5, 1e-3, 0.5, 1.0, 2.0, 3.0])
def test_matrix_to_rotvec_near_a_half_turn(gap: float) -> None:
    # regression: within 1e-6 of pi the axis came from (R + I) / 2 without its sign, so the
    # rotation vector could come out as -axis * angle (a different rotation by 2 * gap); just
    # outside, th / sin(th) with th = arccos(.) lost up to 1e-4 of accuracy
    axis = np.array([-0.8, 0.36, 0.48])
    angle = np.pi - gap
    w = matrix_to_rotvec(rotvec_to_matrix(axis * angle))
    if gap == 0.0:  # +-axis * pi are the same rotation
        w = w if w @ axis > 0 else -w
    np.testing.assert_allclose(w, axis * angle, rtol=0, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-16, 1e-12, 1e-8, 1e-4])
def test_small_rotation_vectors_round_trip(angle: float) -> None:
    w = angle * np.array([0.6, 0.0, -0.8])
    np.testing.assert_allclose(matrix_to_rotvec(rotvec_to_matrix(w)), w, rtol=1e-6, atol=1e-20)


def test_skew_and_rotz() -> None:
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(2, 3))
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b), rtol=0, atol=TOL)
    np.testing.assert_allclose(skew(a).T, -skew(a), rtol=0, atol=0)
    np.testing.assert_allclose(rotz(np.pi / 2) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=TOL)
    np.testing.assert_allclose(rotz(0.3), axis_angle_matrix(np.array([0.0, 0.0, 1.0]), 0.3), atol=TOL)
