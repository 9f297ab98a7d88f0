"""Friction sets (paper eq. 11-17): exact cones in 2-D, inscribed pyramids in 3-D, normal-only
N/S points, and kinetic friction at S-points."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import example_system, parts_of

from analysis.contacts import Selection, selection
from analysis.friction import friction_set, kinetic_friction, slips

TOL = 1e-12


def _f_block(sel: Selection, i: int, f_i: np.ndarray) -> np.ndarray:
    """``f_c`` with contact ``i``'s force set to ``f_i`` and zeros elsewhere."""
    f = np.zeros(sel.L_c)
    f[sel.c_slices[i]] = f_i
    return f


def test_2d_rows_are_the_exact_cone() -> None:
    """2-D: the rows of an F-point are (+-t - mu n)/|.|, so C f <= 0 iff |t.f| <= mu n.f."""
    system = example_system("planar_disk_envelope")
    sel = selection(system, "FFFFF")
    fs = friction_set(system, sel)
    rng = np.random.default_rng(0)
    for i in range(system.L):
        n, t, mu = system.normals[i], system.tangents[i][0], system.mu[i]
        rows = fs.C[fs.row_contact == i][:, sel.c_slices[i]]
        expected = np.array([t - mu * n, -t - mu * n]) / np.sqrt(1 + mu**2)
        np.testing.assert_allclose(rows, expected, rtol=0, atol=TOL)
        outside = np.ones(sel.L_c, dtype=bool)
        outside[sel.c_slices[i]] = False
        np.testing.assert_allclose(fs.C[fs.row_contact == i][:, outside], 0.0, rtol=0, atol=0)
        for _ in range(200):
            f_i = rng.normal(size=2)
            margin = mu * (n @ f_i) - abs(t @ f_i)
            if abs(margin) < 1e-6:
                continue
            assert fs.contains(_f_block(sel, i, f_i), tol=0.0) == (margin > 0)
    # generators: the two edges n +- mu t, on the cone
    for g in fs.E.T:
        assert fs.violation(g) <= TOL


@pytest.mark.parametrize("combination", ["FFFFF", "FFFFD", "DFDFF"])
def test_3d_pyramid_is_inscribed(combination: str) -> None:
    """3-D: every generator lies on the exact cone and satisfies every facet; each facet holds
    two adjacent generators (the pyramid is inscribed, not circumscribed); points just outside
    the pyramid violate a row; points inside the inscribed radius mu cos(pi/k) satisfy all."""
    system = example_system("sphere_four_finger_palm")
    sel = selection(system, combination)
    fs = friction_set(system, sel)
    k = system.friction_sides
    for i in sel.f_index:
        n, T, mu = system.normals[i], system.tangents[i], system.mu[i]
        rows = fs.C[fs.row_contact == i]
        assert rows.shape[0] == k
        np.testing.assert_allclose(np.linalg.norm(rows, axis=1), 1.0, rtol=0, atol=TOL)
        gens = [g for g in fs.E.T if np.any(g[sel.c_slices[i]] != 0.0)]
        assert len(gens) == k
        for g in gens:
            g_i = g[sel.c_slices[i]]
            normal = n @ g_i
            assert np.linalg.norm(g_i - normal * n) == pytest.approx(mu * normal, abs=1e-12)
            assert np.max(rows @ g) <= 1e-12
            assert np.sum(np.abs(rows @ g) <= 1e-12) == 2  # on exactly two facets
        for j in range(k):
            psi = (2 * j + 1) * np.pi / k  # facet direction between generators j and j + 1
            radial = np.cos(psi) * T[0] + np.sin(psi) * T[1]
            inside = n + 0.999 * mu * np.cos(np.pi / k) * radial
            outside = n + 1.001 * mu * np.cos(np.pi / k) * radial
            on_cone = n + mu * radial  # on the exact cone, outside the inscribed pyramid
            assert fs.contains(_f_block(sel, i, inside), tol=0.0)
            assert not fs.contains(_f_block(sel, i, outside), tol=0.0)
            assert not fs.contains(_f_block(sel, i, on_cone), tol=0.0)
            # in any direction, inside the inscribed circle is inside the pyramid
            phi = 2 * np.pi * (j + 0.37) / k
            any_dir = np.cos(phi) * T[0] + np.sin(phi) * T[1]
            assert fs.contains(_f_block(sel, i, 5.0 * (n + 0.999 * mu * np.cos(np.pi / k) * any_dir)), tol=0.0)
        assert not fs.contains(_f_block(sel, i, -n), tol=0.0)  # pulling is not allowed


def test_normal_only_points_and_normal_readout() -> None:
    """S- and N-points contribute one row n_f >= 0 (eq. 14); D-points nothing; N reads the
    normal force of every loaded contact."""
    system = example_system("planar_disk_envelope")
    sel = selection(system, "FSDSF")
    fs = friction_set(system, sel)
    assert sel.L_c == 2 + 1 + 0 + 1 + 2
    for i in sel.s_index:
        rows = fs.C[fs.row_contact == i]
        assert rows.shape[0] == 1
        np.testing.assert_allclose(rows[0][sel.c_slices[i]], [-1.0], rtol=0, atol=0)
    assert not np.any(fs.row_contact == 2)
    rng = np.random.default_rng(1)
    f_c = rng.normal(size=sel.L_c)
    normals = fs.N @ f_c
    for i, s in enumerate(sel.combination):
        if s == "F":
            expected = float(system.normals[i] @ f_c[sel.c_slices[i]])
        else:
            expected = float(f_c[sel.c_slices[i]][0]) if s == "S" else 0.0
        assert normals[i] == pytest.approx(expected, abs=1e-12)
    # every generator is in the set, and conic combinations of generators too
    assert np.max(fs.C @ fs.E) <= 1e-12
    lam = rng.random(fs.E.shape[1])
    assert fs.contains(fs.E @ lam, tol=1e-12)


def test_mu_scale_zero_keeps_only_normal_force() -> None:
    """nu = 0 (end of IV-C): an F-point can take only a normal force."""
    system = example_system("planar_disk_envelope")
    sel = selection(system, "FDDDD")
    fs = friction_set(system, sel, mu_scale=0.0)
    n, t = system.normals[0], system.tangents[0][0]
    assert fs.contains(_f_block(sel, 0, 2.0 * n), tol=1e-12)
    assert not fs.contains(_f_block(sel, 0, 2.0 * n + 1e-6 * t), tol=0.0)
    assert not fs.contains(_f_block(sel, 0, 2.0 * n - 1e-6 * t), tol=0.0)


@pytest.mark.parametrize(("name", "combination"),
                         [("planar_disk_envelope", "FSFSS"), ("planar_disk_envelope", "SSDDS"),
                          ("sphere_four_finger_palm", "SFSDS")])
def test_kinetic_friction_columns(name: str, combination: str) -> None:
    """The friction column of S-point i is -mu G_i s (wrench) and -mu J_i^T s (torque) with s the
    unit slip of the object relative to the finger (eq. 11-12); other columns are zero."""
    system = example_system(name)
    p = parts_of(name, combination)
    sel, ms = p.sel, p.ms
    rng = np.random.default_rng(2)
    motion = ms.Phi_full @ rng.normal(size=ms.a)
    sl = slips(system, sel, motion)
    for k, i in enumerate(sel.s_index):
        np.testing.assert_allclose(sl[k], -(system.contact_A(i) @ motion), rtol=0, atol=0)
    kf = kinetic_friction(system, sel, sl, mu_scale=0.5)
    s_cols = [sel.c_slices[i].start for i in sel.s_index]
    for k, i in enumerate(sel.s_index):
        s = sl[k] / np.linalg.norm(sl[k])
        np.testing.assert_allclose(kf.slips[k], s, rtol=0, atol=1e-12)
        mu = 0.5 * system.mu[i]
        np.testing.assert_allclose(kf.G_w[:, s_cols[k]], -mu * system.G_blocks[i] @ s, rtol=0, atol=1e-12)
        np.testing.assert_allclose(kf.J_w[:, s_cols[k]], -mu * system.J_blocks[i].T @ s, rtol=0, atol=1e-12)
    others = [c for c in range(sel.L_c) if c not in s_cols]
    np.testing.assert_allclose(kf.G_w[:, others], 0.0, rtol=0, atol=0)
    np.testing.assert_allclose(kf.J_w[:, others], 0.0, rtol=0, atol=0)
    # |t| = mu n exactly, opposite to the slip (eq. 15)
    f_c = np.abs(rng.normal(size=sel.L_c))
    t = kf.forces(system, sel, f_c)
    for k, i in enumerate(sel.s_index):
        n_f = f_c[sel.c_slices[i]][0]
        assert np.linalg.norm(t[k]) == pytest.approx(0.5 * system.mu[i] * n_f, rel=1e-12)
        assert t[k] @ sl[k] < 0.0
    with pytest.raises(ValueError, match="zero slip"):
        kinetic_friction(system, sel, np.zeros_like(sl))
