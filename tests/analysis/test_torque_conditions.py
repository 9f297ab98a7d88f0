"""The torque set's conditions at a fixed motion (eq. 30-32), checked against the torque set and
an independent scipy LP."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import parts_of, scipy_lp

from analysis.combination import summarize
from analysis.dafc import DAFCOracle, dafc_set
from analysis.stationary import stationary_grasp
from analysis.torque_conditions import torque_conditions
from analysis.torques import torque_set

NAME = "planar_disk_envelope"
TOL = 1e-8


@pytest.mark.parametrize("combination", ["FDFDD", "FSFSS", "SDSSS", "DDSSS"])
def test_conditions_are_those_of_the_torque_set(combination: str) -> None:
    """The conditions built alone equal the ones the torque set (32) exports, and the
    recommended member satisfies them with positive work."""
    p = parts_of(NAME, combination)
    s = summarize(p)
    assert s.example_direction is not None
    g = stationary_grasp(p.system, p.sel, p.st, p.fs)
    oracle = DAFCOracle(p.system, p.sel, p.ms, p.st, p.fs)
    ts = torque_set(p.system, p.sel, p.ms, p.st, p.fs, g, s.example_direction, oracle=oracle)
    tc = torque_conditions(p.system, p.sel, p.ms, p.st, p.fs, ts.u,
                           oracle.slips_of(ts.zeta_c) if p.sel.s_index else None)
    for a, b in [(tc.A_ub, ts.A_ub), (tc.b_ub, ts.b_ub), (tc.A_eq, ts.A_eq), (tc.b_eq, ts.b_eq),
                 (tc.T_map, ts.T_map), (tc.W_map, ts.W_map)]:
        np.testing.assert_allclose(a, b, atol=1e-14)
    f = ts.f_c
    assert np.all(tc.A_ub @ f <= tc.b_ub + TOL)
    np.testing.assert_allclose(tc.A_eq @ f, tc.b_eq, atol=TOL)
    assert tc.work_row @ f + tc.work0 > 0
    np.testing.assert_allclose(tc.T_map @ f, ts.tau, atol=TOL)


def test_realisable_agrees_with_an_independent_lp() -> None:
    """For every sampled DAFC member of SSSSS, ``realisable`` says yes exactly when scipy finds
    forces meeting the conditions with work at least 1e-6 (the work scales with the forces)."""
    p = parts_of(NAME, "SSSSS")
    oracle = DAFCOracle(p.system, p.sel, p.ms, p.st, p.fs)
    answers = []
    for d in dafc_set(oracle, samples=36).members():
        t = oracle.test(d)
        tc = torque_conditions(p.system, p.sel, p.ms, p.st, p.fs, t.u, oracle.slips_of(t.zeta_c))
        A_ub = np.vstack([tc.A_ub[:-1], -tc.work_row[None, :]])
        b_ub = np.r_[tc.b_ub[:-1], tc.work0 - 1e-6]
        status, _, _ = scipy_lp(np.zeros(tc.L_c), A_ub, b_ub, tc.A_eq, tc.b_eq)
        answers.append((oracle.realisable(t), status == 0))
    assert answers and all(a == b for a, b in answers), answers
    assert {a for a, _ in answers} == {True, False}  # both kinds of member occur
