"""Capsule collision model: segment distances (scalar, vectorised, boxes) and penetration."""

from __future__ import annotations

import numpy as np

from planner.collision import (
    CollisionModel,
    _box_segments_distance,
    segment_segment_distance,
    segment_segment_distances,
)


def test_segment_distance_matches_sampling() -> None:
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, 401)
    for _ in range(30):
        a0, a1, b0, b1 = rng.normal(size=(4, 3))
        P = a0 + t[:, None] * (a1 - a0)
        Q = b0 + t[:, None] * (b1 - b0)
        brute = np.min(np.linalg.norm(P[:, None] - Q[None], axis=2))
        d = segment_segment_distance(a0, a1, b0, b1)
        assert d <= brute + 1e-12 and d >= brute - 1e-2


def test_vectorised_distances_match_the_scalar_and_dense_ones() -> None:
    rng = np.random.default_rng(1)
    A0, A1, B0, B1 = rng.normal(size=(4, 50, 3))
    A1[:5] = A0[:5]  # degenerate segments (points) on either side
    B1[5:10] = B0[5:10]
    B1[10] = B0[10] = A0[10] = A1[10]
    B0[11], B1[11] = A0[11] + 1.0, A1[11] + 1.0  # parallel
    vec = segment_segment_distances(A0, A1, B0, B1)
    ref = [segment_segment_distance(*x) for x in zip(A0, A1, B0, B1, strict=True)]
    np.testing.assert_allclose(vec, ref, atol=1e-12)
    # box: within step / 2 of the distance sampled every step / 100 (convexity bracket)
    c, h, step = np.array([0.1, -0.2, 0.0]), np.array([0.5, 0.3, 0.05]), 0.01
    got = _box_segments_distance(c, h, A0, A1 * 2.0, step)
    t = np.linspace(0, 1, 20001)
    for i in range(50):
        P = A0[i] + t[:, None] * (A1[i] * 2.0 - A0[i])
        qd = np.abs(P - c) - h
        dense = float(np.min(np.linalg.norm(np.maximum(qd, 0), axis=1) + np.minimum(qd.max(axis=1), 0)))
        assert dense - 1e-12 <= got[i] <= dense + step / 2


def test_clearance_detects_penetration(planar_scene, free_left) -> None:  # type: ignore[no-untyped-def]
    hand, st = free_left
    model = CollisionModel.of(planar_scene, hand)
    q = st.q.copy()
    q[:2] = [1.0, 0.0]  # link 0 through the disk
    assert model.finger_clearance(0, q, st.position, st.rotation) < 0.0
    q[:2] = [0.0, 0.0]  # the finger lies on the palm
    assert model.finger_clearance(0, q, st.position, st.rotation) < 0.0

