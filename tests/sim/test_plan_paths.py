"""The object's deviation from its planned path (continuous replay monitor): the vectorised
:func:`sim.plan_paths.path_deviation` equals the segment-by-segment definition with
:meth:`Pose.distance`, in 2-D and 3-D, on seeded random paths."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from analysis.pose import Pose
from sim.plan_paths import path_deviation, rotation_angles


def _reference(pose: Pose, path: np.ndarray, s: float) -> float:
    dim = pose.dim
    w = np.ones(path.shape[1])
    w[dim:] = s
    x = pose.vector() * w
    best = np.inf
    for a, b in itertools.pairwise(path):
        seg = (b - a) * w
        n2 = float(seg @ seg)
        u = 0.0 if n2 == 0 else float(np.clip((x - a * w) @ seg / n2, 0.0, 1.0))
        best = min(best, pose.distance(Pose.from_vector(a + u * (b - a), dim), s))
    return float(best)


@pytest.mark.parametrize("dim", [2, 3])
def test_path_deviation_matches_the_segment_definition(dim: int) -> None:
    rng = np.random.default_rng(21 + dim)
    D = 3 * (dim - 1)
    for _ in range(30):
        path = np.cumsum(rng.normal(scale=0.05, size=(int(rng.integers(2, 40)), D)), axis=0)
        path[:, dim:] *= 10.0  # rotations up to a few radians (wrapping, large rotation vectors)
        if rng.random() < 0.2:
            path[3:5] = path[2]  # repeated waypoints: zero-length segments
        pose = Pose.from_vector(path[int(rng.integers(len(path)))] + rng.normal(scale=0.1, size=D), dim)
        s = float(rng.uniform(0.05, 1.0))
        assert path_deviation(pose, path, s) == pytest.approx(_reference(pose, path, s), abs=1e-9)
    single = np.zeros((1, D))
    pose = Pose.from_vector(np.full(D, 0.1), dim)
    assert path_deviation(pose, single, 0.5) == pytest.approx(pose.distance(Pose.from_vector(single[0], dim), 0.5))


def test_rotation_angles_small_and_large() -> None:
    rng = np.random.default_rng(4)
    R = rng.normal(size=(50, 3)) * rng.choice([1e-9, 1e-3, 1.0, 3.0], size=(50, 1))
    pose = Pose.from_vector(np.r_[0.0, 0.0, 0.0, rng.normal(size=3)], 3)
    want = [pose.rotation_angle_to(Pose.from_vector(np.r_[0.0, 0.0, 0.0, r], 3)) for r in R]
    np.testing.assert_allclose(rotation_angles(pose, R), want, atol=1e-9)
