"""Motion space, object motions and finger redundancy (paper eq. 7, 19-21).

The invariants are checked on a seeded sample of combinations of every example scene, with
dimensions recomputed by independent ranks (numpy SVD), not by the code's own helpers.
"""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import EXAMPLE_NAMES, example_system, parts_of, sample_combinations, slip

TOL = 1e-9  # absolute, on quantities of order one (orthonormal bases, unit-scale Jacobians)
RANK_TOL = 1e-8


def _rank(A: np.ndarray) -> int:
    return int(np.linalg.matrix_rank(A, tol=RANK_TOL)) if A.size else 0


N_SAMPLE = 12
#: (scene, index into a seeded sample of its combinations); scenes are loaded in the tests
CASES = [(name, k) for name in EXAMPLE_NAMES for k in range(N_SAMPLE)]


def _combination(name: str, k: int) -> str:
    return sample_combinations(example_system(name), N_SAMPLE, seed=7)[k]


@pytest.mark.parametrize(("name", "k"), CASES)
def test_motion_space_invariants(name: str, k: int) -> None:
    system = example_system(name)
    p = parts_of(name, _combination(name, k))
    ms, sel = p.ms, p.sel
    M, D = system.M, system.D
    A_c = sel.H_c @ system.A
    J_c = A_c[:, :M]
    np.testing.assert_allclose(ms.A_c, A_c, rtol=0, atol=0)
    # eq. 7: Lambda is an orthonormal basis of null(A_c)
    a = M + D - _rank(A_c)
    assert ms.a == a
    np.testing.assert_allclose(ms.Lambda.T @ ms.Lambda, np.eye(a), rtol=0, atol=TOL)
    np.testing.assert_allclose(A_c @ ms.Lambda, 0.0, rtol=0, atol=TOL)
    # eq. 19: Lambda~_r is an orthonormal basis of range(Lambda_r)
    Lr = ms.Lambda_r_t
    assert ms.a_bar == _rank(ms.Lambda[M:])
    np.testing.assert_allclose(Lr.T @ Lr, np.eye(ms.a_bar), rtol=0, atol=TOL)
    np.testing.assert_allclose(Lr @ (Lr.T @ ms.Lambda[M:]), ms.Lambda[M:], rtol=0, atol=TOL)
    # redundancy: Lambda~_qr is an orthonormal basis of null(J_c), and a = a_bar + redundancy
    assert ms.n_redundant == M - _rank(J_c)
    assert ms.a == ms.a_bar + ms.n_redundant
    np.testing.assert_allclose(J_c @ ms.Lambda_qr_t, 0.0, rtol=0, atol=TOL)
    np.testing.assert_allclose(ms.Lambda_qr_t.T @ ms.Lambda_qr_t, np.eye(ms.n_redundant), rtol=0, atol=TOL)
    # [dq; dr] = Phi_full dzeta_c keeps every F/S/N constraint (eq. 4) and spans null(A_c)
    Phi = ms.Phi_full
    assert Phi.shape == (M + D, a)
    np.testing.assert_allclose(A_c @ Phi, 0.0, rtol=0, atol=TOL)
    assert _rank(Phi) == a
    np.testing.assert_allclose(ms.Phi, np.hstack([Lr, np.zeros((D, ms.n_redundant))]), rtol=0, atol=0)
    # the finger part of the object motion: J_c Lambda~_q = G_c^T Lambda~_r
    np.testing.assert_allclose(J_c @ ms.Lambda_q_t, -A_c[:, M:] @ Lr, rtol=0, atol=TOL)


@pytest.mark.parametrize(("name", "k"), CASES[::3])
def test_allowable_and_sliding_maps(name: str, k: int) -> None:
    """B = A_d Phi_full (eq. 20) and P_s = -A_s Phi_full (eq. 21), checked contact by contact:
    the D rows are the normal approach of finger to object, the S rows the slip, whose normal
    component is zero (the note after eq. 12)."""
    system = example_system(name)
    p = parts_of(name, _combination(name, k))
    ms, sel = p.ms, p.sel
    rng = np.random.default_rng(3)
    for _ in range(5):
        zc = rng.normal(size=ms.a)
        motion = ms.Phi_full @ zc
        expected_B = [system.normals[i] @ (system.contact_A(i) @ motion) for i in sel.d_index]
        np.testing.assert_allclose(ms.B @ zc, expected_B, rtol=0, atol=TOL)
        slips = (ms.P_s @ zc).reshape(len(sel.s_index), system.d)
        for k, i in enumerate(sel.s_index):
            np.testing.assert_allclose(slips[k], slip(system, i, motion), rtol=0, atol=TOL)
            assert abs(system.normals[i] @ slips[k]) <= TOL
        # the object part of the motion is Phi dzeta_c, the coordinates invert it
        dr = ms.Phi @ zc
        np.testing.assert_allclose(ms.coordinates(dr), zc[: ms.a_bar], rtol=0, atol=TOL)
        np.testing.assert_allclose(ms.zeta_c(zc[: ms.a_bar], zc[ms.a_bar :]), zc, rtol=0, atol=0)


def test_fully_constrained_grasp_has_no_object_motion() -> None:
    """All-F on the planar envelope grasp: passive closure, the object cannot move (a~ = 0),
    while all-D leaves the object free (a~ = D) with every finger joint redundant."""
    system = example_system("planar_disk_envelope")
    full = parts_of("planar_disk_envelope", "FFFFF").ms
    assert full.a_bar == 0
    free = parts_of("planar_disk_envelope", "DDDDD").ms
    assert (free.a_bar, free.n_redundant, free.a) == (system.D, system.M, system.M + system.D)


@pytest.mark.parametrize("name", EXAMPLE_NAMES)
def test_motion_dims_match_independent_ranks(name: str) -> None:
    """``motion_dims`` (the J_c ranks from the finger groups' blocks, :func:`analysis.motion._group_ranks`)
    against ranks of each combination's whole A_c and J_c by numpy, on every combination (at most
    the seeded 300 of the wrap): ``a = M + D - rank(A_c)``, ``a_bar = a - dim null(J_c)``."""
    from analysis.contacts import constrained_matrices, selection
    from analysis.motion import motion_dims

    sy = example_system(name)
    combos = sample_combinations(sy, 300, seed=11)
    a, a_bar = motion_dims(sy, combos)
    for c, ak, abk in zip(combos, a, a_bar, strict=True):
        A_c = constrained_matrices(sy, selection(sy, c))[0]  # (L_c, M + D)
        r_A, r_J = _rank(A_c), _rank(A_c[:, : sy.M])
        assert ak == sy.M + sy.D - r_A, c
        assert abk == ak - (sy.M - r_J), c
