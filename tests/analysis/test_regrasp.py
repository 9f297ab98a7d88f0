"""Finger motions that regrasp without moving the object (paper eq. 33)."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import example_system, parts_of, scipy_lp

from analysis.combination import CombinationParts
from analysis.regrasp import RegraspCone, regrasp_cone

TOL = 1e-9


def _cone(name: str, combination: str) -> tuple[CombinationParts, RegraspCone]:
    p = parts_of(name, combination)
    return p, regrasp_cone(p.system, p.sel, p.ms, p.st, p.fs)


def test_fingers_about_to_detach_palm_holding() -> None:
    """Fig. 5 (1) -> (2) in spirit: the sphere rests on the palm (F) and the four fingers are
    about to detach (D): A' = {dq : J_d dq <= 0} on the redundancy, here every joint (the palm
    has no joints, so J_c = 0 and Lambda~_qr spans the joint space). J_d holds the normal rows
    n_i^T J_i of the finger contacts, each on its own finger's joints."""
    system = example_system("sphere_four_finger_palm")
    p, rg = _cone("sphere_four_finger_palm", "DDDDF")
    M = system.M
    assert p.ms.n_redundant == M
    np.testing.assert_allclose(rg.Lambda_qr_t @ rg.Lambda_qr_t.T, np.eye(M), rtol=0, atol=TOL)
    expected_J_d = np.array([system.normals[i] @ system.J_blocks[i] for i in range(4)])
    np.testing.assert_allclose(rg.J_d, expected_J_d, rtol=0, atol=1e-12)
    for i in range(4):  # block diagonal: contact i moves with finger i's four joints only
        outside = np.ones(M, dtype=bool)
        outside[4 * i : 4 * i + 4] = False
        np.testing.assert_allclose(rg.J_d[i, outside], 0.0, rtol=0, atol=0)
    # four independent half-spaces in R^16: 4 rays and 12 lines, every generator admissible
    assert np.linalg.matrix_rank(rg.J_d) == 4
    assert rg.rays.shape == (4, M) and rg.lines.shape == (12, M)
    assert rg.exact and rg.feasible.all()
    _check_generators(p, rg)
    # contains() agrees with {J_d dq <= 0}
    rng = np.random.default_rng(0)
    for _ in range(200):
        dq = rng.normal(size=M)
        assert rg.contains(dq) == bool(np.all(rg.J_d @ dq <= TOL))
    # conic combinations of the generators are members; the lines in both signs
    for _ in range(50):
        dq = rng.random(4) @ rg.rays + rng.normal(size=12) @ rg.lines
        assert rg.contains(dq)


def _check_generators(p: CombinationParts, rg: RegraspCone) -> None:
    """Every generator: keeps the F/S/N contacts with the object still (A_c [dq; 0] = 0), does
    not penetrate a D-point (J_d dq <= 0); rays are unit, lines have J_d dq = 0."""
    M = p.system.M
    for dq in rg.directions():
        np.testing.assert_allclose(p.ms.A_c @ np.r_[dq, np.zeros(p.system.D)], 0.0, rtol=0, atol=TOL)
        assert np.all(rg.J_d @ dq <= TOL)
        assert rg.contains(dq)
    for ray in rg.rays:
        assert np.linalg.norm(ray) == pytest.approx(1.0, abs=1e-12)
    for line in rg.lines:
        np.testing.assert_allclose(rg.J_d @ line, 0.0, rtol=0, atol=TOL)
    assert rg.directions().shape[1] == M


@pytest.mark.parametrize(("name", "combination"), [
    ("planar_disk_envelope", "FDFDF"),
    ("planar_disk_envelope", "DDFFF"),
    ("sphere_four_finger_palm", "FDDDF"),
    ("sphere_four_finger_wrap", "DFDFDFDFF"),
])
def test_generators_keep_the_object_still(name: str, combination: str) -> None:
    p, rg = _cone(name, combination)
    _check_generators(p, rg)
    assert rg.exact and rg.feasible.all()  # no S-point: the stationary grasp (18) holds throughout
    # a motion that moves a sticking contact is not a regrasp motion
    rng = np.random.default_rng(1)
    dq = rng.normal(size=p.system.M)
    moving = dq - rg.Lambda_qr_t @ (rg.Lambda_qr_t.T @ dq)
    if np.linalg.norm(moving) > 1e-6:
        assert not rg.contains(moving)


@pytest.mark.parametrize("combination", ["FFDSF", "FDDSF", "SDFDF", "FFFDS"])
def test_sliding_regrasp_checks_equilibrium_per_generator(combination: str) -> None:
    """With an S-point a regrasp motion must slide it (the object is still, so its slip is
    -J_i dq; on the fixed palm it cannot slide at all), and the kinetic friction must be
    balanced together with the external wrench (33): re-checked per generator with scipy."""
    p, rg = _cone("planar_disk_envelope", combination)
    system, sel, st, fs = p.system, p.sel, p.st, p.fs
    assert not rg.exact
    _check_generators(p, rg)
    for dq, ok in zip(rg.directions(), rg.feasible, strict=True):
        slips = [-(system.J_blocks[i] @ dq) for i in sel.s_index]
        if min(np.linalg.norm(s) for s in slips) < 1e-9:
            assert not ok
            continue
        G = st.G_c.copy()
        for i, s in zip(sel.s_index, slips, strict=True):
            G[:, sel.c_slices[i].start] += system.G_blocks[i] @ (-system.mu[i] * s / np.linalg.norm(s))
        status, _, _ = scipy_lp(np.zeros(G.shape[1]), fs.C, np.zeros(fs.C.shape[0]), G, -system.w_ex)
        assert ok == (status == 0)


@pytest.mark.parametrize(("name", "combination", "held"), [
    ("planar_disk_envelope", "DDDFF", True),
    ("planar_disk_envelope", "FDDDD", False),
    ("sphere_four_finger_palm", "DDDDF", True),
    ("sphere_four_finger_palm", "FFDDD", False),
])
def test_without_sliding_every_generator_shares_the_stationary_grasp(name: str, combination: str, held: bool) -> None:
    """Without S-points the equilibrium of A' (33) does not depend on the motion: every generator is
    feasible exactly when the remaining contacts hold the object, ``G_c f_c = -w_ex`` with ``f_c``
    in the friction cones (one LP for all, here re-solved with scipy); both answers occur."""
    p, rg = _cone(name, combination)
    assert rg.exact and len(rg.directions()) > 0
    status, _, _ = scipy_lp(np.zeros(p.st.G_c.shape[1]), p.fs.C, np.zeros(p.fs.C.shape[0]), p.st.G_c,
                            -p.system.w_ex)
    assert (status == 0) == held
    np.testing.assert_array_equal(rg.feasible, np.full(len(rg.directions()), held))
