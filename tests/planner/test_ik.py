"""Inverse kinematics of a fingertip at a target with the last link along the normal."""

from __future__ import annotations

import numpy as np

from analysis.kinematics import BodyRef
from planner.ik import fingertip_ik


def test_ik_puts_the_tip_on_the_target(free_left) -> None:  # type: ignore[no-untyped-def]
    hand, st = free_left
    target, normal = np.array([-0.5, 0.5]), np.array([1.0, 0.0])
    sols = fingertip_ik(hand, 0, target, normal, [st.q[:2]])
    assert sols
    q = st.q.copy()
    q[:2] = sols[0]
    a, b = hand.body_segment(BodyRef("left/1", 0, 1), q)
    np.testing.assert_allclose(b, target, atol=1e-7)
    assert (b - a) @ normal / np.linalg.norm(b - a) >= 0.5 - 1e-9

