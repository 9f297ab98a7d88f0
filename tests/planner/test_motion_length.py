"""How far one torque holds (planner/motion_length.py): the length over which the friction margin,
taken as linear between its values at the start and the end of a motion, keeps KEPT_MARGIN of its
start value. The wrap's lift, where it matters, is in tests/sim/test_wrap_replay.py (slow)."""

from __future__ import annotations

import numpy as np
import pytest

from planner.motion_length import KEPT_MARGIN, held_length


def test_a_motion_that_keeps_its_margin_keeps_its_length() -> None:
    assert held_length(0.04, 0.36, 0.30) == 0.04
    assert held_length(0.04, 0.36, KEPT_MARGIN * 0.36) == 0.04


@pytest.mark.parametrize(("m0", "m_end"), [(0.36, -0.012), (0.36, 0.1), (2.0, -50.0)])
def test_the_cut_is_where_the_linear_margin_reaches_the_kept_fraction(m0: float, m_end: float) -> None:
    d = 0.042
    cut = held_length(d, m0, m_end)
    assert 0.0 < cut < d
    margin_at_cut = m0 + (m_end - m0) * cut / d  # the linear model
    assert margin_at_cut == pytest.approx(KEPT_MARGIN * m0, rel=1e-12)


def test_no_margin_at_the_start_gives_no_motion_and_no_force_halves_it() -> None:
    assert held_length(0.04, 0.0, 0.1) == 0.0
    assert held_length(0.04, -0.1, 0.1) == 0.0
    assert held_length(0.04, 0.36, -np.inf) == 0.02
