"""The one pose type: coordinates, displacements (the paper's dr) and scene fields, 2-D and 3-D."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.pose import Pose
from analysis.rotations import quat_wxyz_to_matrix, rotvec_to_matrix, rotz

TOL = 1e-12


def _random_pose(rng: np.random.Generator, dim: int) -> Pose:
    w = rng.normal(size=3 if dim == 3 else 1)
    w *= rng.uniform(0.1, 2.5) / np.linalg.norm(w)
    return Pose.from_vector(np.concatenate([rng.normal(size=dim), w]), dim)


@pytest.mark.parametrize("dim", [2, 3])
def test_vector_round_trip(dim: int) -> None:
    rng = np.random.default_rng(11)
    for _ in range(20):
        pose = _random_pose(rng, dim)
        again = Pose.from_vector(pose.vector(), dim)
        assert np.allclose(again.position, pose.position, atol=TOL)
        assert np.allclose(again.rotation, pose.rotation, atol=1e-10)


@pytest.mark.parametrize("dim", [2, 3])
def test_displacement_inverts_displaced(dim: int) -> None:
    rng = np.random.default_rng(12)
    for _ in range(20):
        start = _random_pose(rng, dim)
        s = rng.normal(size=3 * (dim - 1))
        s[dim:] *= 0.8 / max(1.0, float(np.linalg.norm(s[dim:])))  # rotation below pi
        moved = start.displaced(s)
        assert np.allclose(moved.displacement_from(start), s, atol=1e-10)
        assert np.allclose(moved.rotation @ moved.rotation.T, np.eye(3), atol=1e-12)


def test_displacement_rotates_in_the_world_frame() -> None:
    """``R = exp([w]x) R_0``: the rotation vector ``w`` of dr is a world axis (paper eq. 30-32)."""
    start = Pose(np.array([1.0, 2.0, 3.0]), rotvec_to_matrix(np.array([0.3, -0.2, 0.5])), 3)
    w = np.array([0.0, 0.0, 0.4])
    moved = start.displaced(np.array([0.1, 0.0, 0.0, *w]))
    assert np.allclose(moved.rotation, rotz(0.4) @ start.rotation, atol=TOL)
    assert np.allclose(moved.position, [1.1, 2.0, 3.0], atol=TOL)


def test_scene_fields_round_trip() -> None:
    p2 = Pose.from_fields([0.0, 0.5], 2, angle=0.3)
    assert p2.fields() == {"position": [0.0, 0.5], "angle": pytest.approx(0.3, abs=TOL)}
    q = np.array([0.9, 0.1, -0.3, 0.2])
    q /= np.linalg.norm(q)
    p3 = Pose.from_fields([1.0, 2.0, 3.0], 3, quat_wxyz=q)
    assert np.allclose(p3.rotation, quat_wxyz_to_matrix(q), atol=TOL)
    assert np.allclose(p3.fields()["quat_wxyz"], q, atol=1e-12)
    assert np.allclose(Pose.from_fields([0.0, 0.0, 0.0], 3).rotation, np.eye(3))


def test_frames_and_distance() -> None:
    pose = Pose.from_vector([1.0, 0.0, np.pi / 2], 2)
    assert np.allclose(pose.to_world([1.0, 0.0]), [1.0, 1.0], atol=TOL)
    assert np.allclose(pose.to_local([1.0, 1.0]), [1.0, 0.0], atol=TOL)
    other = Pose.from_vector([1.0, 0.0, np.pi / 2 + 2 * np.pi - 0.1], 2)
    assert pose.distance(other, size=2.0) == pytest.approx(0.2, abs=1e-12)  # wrapped angle


def test_bad_shapes_are_refused() -> None:
    with pytest.raises(ValueError, match="3 coordinates"):
        Pose.from_vector([0.0, 0.0], 2)
    with pytest.raises(ValueError, match="6 values"):
        Pose.identity(3).displaced(np.zeros(3))
    with pytest.raises(ValueError, match="dim must be 2 or 3"):
        Pose(np.zeros(4), np.eye(3), 4)
