"""Statics of a combination (paper eq. 8-10) and the orthogonality of active and passive
directions (section IV-A: ``Lambda~_r^T Xi = O``, ``rank([Xi, Lambda~_r]) = D``)."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import EXAMPLE_NAMES, example_system, parts_of, sample_combinations

TOL = 1e-9
RANK_TOL = 1e-8
N_SAMPLE = 12
CASES = [(name, k) for name in EXAMPLE_NAMES for k in range(N_SAMPLE)]


def _rank(A: np.ndarray) -> int:
    return int(np.linalg.matrix_rank(A, tol=RANK_TOL)) if A.size else 0


def _combination(name: str, k: int) -> str:
    return sample_combinations(example_system(name), N_SAMPLE, seed=11)[k]


@pytest.mark.parametrize(("name", "k"), CASES)
def test_statics_invariants(name: str, k: int) -> None:
    system = example_system(name)
    p = parts_of(name, _combination(name, k))
    sel, st, ms = p.sel, p.st, p.ms
    L_c, M, D = sel.L_c, system.M, system.D
    # eq. 8: J_c = H_c J, G_c = G H_c^T (tau = J_c^T f_c, w = G_c f_c)
    np.testing.assert_allclose(st.J_c, sel.H_c @ system.J, rtol=0, atol=0)
    np.testing.assert_allclose(st.G_c, system.G @ sel.H_c.T, rtol=0, atol=0)
    # eq. 9: (J_c^T)^+ and Gamma = orthonormal basis of null(J_c^T)
    np.testing.assert_allclose(st.JcT_pinv, np.linalg.pinv(st.J_c.T, rcond=1e-10), rtol=0, atol=1e-8)
    p_bar = L_c - _rank(st.J_c)
    assert st.Gamma.shape == (L_c, p_bar)
    np.testing.assert_allclose(st.Gamma.T @ st.Gamma, np.eye(p_bar), rtol=0, atol=TOL)
    np.testing.assert_allclose(st.J_c.T @ st.Gamma, 0.0, rtol=0, atol=TOL)
    # W_f = [(J_c^T)^+, Gamma] spans the force space: every f_c has coordinates x = [tau; xi~]
    assert st.W_f.shape == (L_c, M + p_bar)
    assert _rank(st.W_f) == L_c
    rng = np.random.default_rng(k)
    f_c = rng.normal(size=L_c)
    np.testing.assert_allclose(st.W_f @ st.x_of(f_c), f_c, rtol=0, atol=1e-8)
    # eq. 10: D = G_c (J_c^T)^+, Xi = orthonormal basis of range(G_c Gamma)
    np.testing.assert_allclose(st.D, st.G_c @ st.JcT_pinv, rtol=0, atol=TOL)
    GG = st.G_c @ st.Gamma
    assert st.p == _rank(GG)
    np.testing.assert_allclose(st.Xi.T @ st.Xi, np.eye(st.p), rtol=0, atol=TOL)
    np.testing.assert_allclose(st.Xi @ (st.Xi.T @ GG), GG, rtol=0, atol=1e-8)
    # for random tau and xi~: w = G_c W_f x = D tau + G_c Gamma xi~, and the passive part is Xi xi
    for _ in range(3):
        tau, xi_t = rng.normal(size=M), rng.normal(size=p_bar)
        x = np.concatenate([tau, xi_t])
        w = st.G_c @ (st.W_f @ x)
        xi = st.Xi.T @ (GG @ xi_t)
        np.testing.assert_allclose(w, st.D @ tau + st.Xi @ xi, rtol=0, atol=1e-8)
        # the joint torque of these forces is tau projected on range(J_c^T) (eq. 29 without tau~)
        f = st.W_f @ x
        np.testing.assert_allclose(st.J_c.T @ f, st.J_c.T @ np.linalg.pinv(st.J_c.T) @ tau, rtol=0, atol=1e-8)
    # section IV-A: active and passive directions are orthogonal and complete
    np.testing.assert_allclose(ms.Lambda_r_t.T @ st.Xi, 0.0, rtol=0, atol=TOL)
    assert _rank(np.hstack([st.Xi, ms.Lambda_r_t])) == D
    assert st.p + ms.a_bar == D


def test_internal_forces_of_fixed_contacts() -> None:
    """Contacts on fixed bodies (J = 0) take any force without joint torque: on the planar
    example the palm's force columns are internal forces (in range(Gamma))."""
    p = parts_of("planar_disk_envelope", "DDDDF")
    st = p.st
    np.testing.assert_allclose(st.J_c, 0.0, rtol=0, atol=0)
    assert st.Gamma.shape == (2, 2)
    assert st.p == 2  # the palm's two force components make a 2-D wrench space
    np.testing.assert_allclose(st.D, 0.0, rtol=0, atol=0)
