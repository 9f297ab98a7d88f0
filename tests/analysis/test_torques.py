"""Joint torques realising a DAFC motion (paper eq. 29-32) and the friction-uncertainty
combination (end of section IV-C), re-checked with forces and torques recomputed here."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from closure_helpers import disk_scene, effective_grasp_matrix, full_forces, parts_of, scipy_lp, slip

from analysis.combination import CombinationParts, summarize
from analysis.contacts import build_system
from analysis.dafc import DAFCOracle, dafc_set
from analysis.exceptions import EmptyTorqueSet, NotInDAFC
from analysis.solvers.casadi_nlp import RedundancyNLP, solve_redundancy
from analysis.stationary import stationary_grasp
from analysis.torques import TorqueSet, _nlp_data, friction_uncertainty, planar_slip_patterns, torque_set

NAME = "planar_disk_envelope"
#: feasible combinations of the planar example whose example direction has a torque set:
#: F/D only, and with S-points on the fingers and on the palm
COMBINATIONS = ["FDFDD", "DDDFF", "FSFSD", "FSFSS", "SSDDF", "SDSSS", "DDSSS"]
TOL = 1e-8


def _torque_set(combination: str) -> tuple[CombinationParts, TorqueSet]:
    p = parts_of(NAME, combination)
    s = summarize(p)
    assert s.feasible and s.example_direction is not None
    g = stationary_grasp(p.system, p.sel, p.st, p.fs)
    return p, torque_set(p.system, p.sel, p.ms, p.st, p.fs, g, s.example_direction)


def _preimage(ts: TorqueSet, tau: np.ndarray | None, ray: bool) -> np.ndarray | None:
    """Contact forces f in P (or its recession cone) with T_map f = tau, by scipy."""
    n = ts.A_ub.shape[1]
    b_ub = np.zeros_like(ts.b_ub) if ray else ts.b_ub
    b_eq = np.zeros_like(ts.b_eq) if ray else ts.b_eq
    A_eq, rhs = ts.A_eq, b_eq
    if tau is not None:
        A_eq = np.vstack([ts.A_eq, ts.T_map])
        rhs = np.concatenate([b_eq, tau])
    status, _, f = scipy_lp(np.zeros(n), ts.A_ub, b_ub + TOL, A_eq, rhs)
    return f if status == 0 else None


@pytest.mark.parametrize("combination", COMBINATIONS)
def test_recommended_member_and_generators_are_certified(combination: str) -> None:
    p, ts = _torque_set(combination)
    system, sel, ms, st = p.system, p.sel, p.ms, p.st
    M = system.M
    # the recommended member: its forces satisfy (30) and do positive work
    res = ts.residuals(ts.f_c)
    assert res["inequality"] <= TOL and res["equality"] <= TOL
    assert res["work"] > 0.0 and ts.work == pytest.approx(res["work"], abs=1e-12)
    np.testing.assert_allclose(ts.tau, ts.T_map @ ts.f_c, rtol=0, atol=1e-12)
    # the chosen motion keeps the F/S/N constraints, does not penetrate, and S-points slide
    motion = ms.Phi_full @ ts.zeta_c
    dr = motion[M:]
    np.testing.assert_allclose(dr, ts.direction, rtol=0, atol=1e-9)
    np.testing.assert_allclose(motion[:M], ts.dq, rtol=0, atol=1e-12)
    assert ts.phi == pytest.approx(float(np.linalg.norm(ts.dq)), rel=1e-6)
    np.testing.assert_allclose(st.J_c @ ts.dq - st.G_c.T @ dr, 0.0, rtol=0, atol=1e-9)  # A_c [dq; dr] = 0
    for i in sel.d_index:
        assert system.normals[i] @ (system.contact_A(i) @ motion) <= 1e-8
    for i in sel.s_index:
        assert np.linalg.norm(slip(system, i, motion)) > 1e-6
    # independently: the contact forces (kinetic friction included) give a net wrench exactly
    # along the motion (W_2 and W_3 rows of 30) with work ts.work, and the joint torque that
    # balances them on the fingers is tau = J^T f
    F = full_forces(system, sel, ts.f_c, motion)
    w = sum(system.G_blocks[i] @ F[i] for i in range(system.L)) + system.w_ex
    np.testing.assert_allclose(w, (dr @ w) * dr, rtol=0, atol=1e-8)
    assert dr @ w == pytest.approx(ts.work, abs=1e-9)
    tau = sum(system.J_blocks[i].T @ F[i] for i in range(system.L))
    np.testing.assert_allclose(ts.tau, tau, rtol=0, atol=1e-9)
    np.testing.assert_allclose(effective_grasp_matrix(system, sel, st.G_c, motion), ts.W_map, rtol=0, atol=1e-12)
    # every vertex and ray of T comes from admissible contact forces of P
    assert ts.generators is not None and ts.vertices is not None and ts.rays is not None
    assert len(ts.vertices) >= 1
    for v in ts.vertices:
        f = _preimage(ts, v, ray=False)
        assert f is not None, v
        r = ts.residuals(f)
        assert r["inequality"] <= 1e-7 and r["equality"] <= 1e-7 and r["work"] >= -1e-7
    for ray in ts.rays:
        assert _preimage(ts, ray, ray=True) is not None, ray


@pytest.mark.parametrize("combination", ["FDFDD", "DDDFF"])
def test_stationary_torque_lies_on_the_closure_of_T(combination: str) -> None:
    """Without S-points the stationary forces are in P with zero work: tau_st is on the face
    work = 0 of T; and tau has no component in the finger redundancy beyond tau_st's
    (Lambda~_qr^T tau_ad = 0 of eq. 30)."""
    p, ts = _torque_set(combination)
    g = stationary_grasp(p.system, p.sel, p.st, p.fs)
    r = ts.residuals(g.f_c)
    assert r["inequality"] <= 1e-9 and r["equality"] <= 1e-9 and r["work"] == pytest.approx(0.0, abs=1e-9)
    assert _preimage(ts, g.tau, ray=False) is not None
    np.testing.assert_allclose(p.ms.Lambda_qr_t.T @ (ts.tau - g.tau), 0.0, rtol=0, atol=1e-9)


def test_directions_outside_dafc_raise() -> None:
    """Non-members of every kind: not allowable (a D-point would penetrate), outside the motion
    space, and allowable but without positive work."""
    p = parts_of(NAME, "DDDFF")
    g = stationary_grasp(p.system, p.sel, p.st, p.fs)
    ds = dafc_set(p.oracle(), samples=36, refine=0)
    outside = [t.direction for t in ds.tests if not t.member]
    assert outside
    for dr in outside:
        with pytest.raises(NotInDAFC, match="not allowable"):
            torque_set(p.system, p.sel, p.ms, p.st, p.fs, g, dr)
    off = np.ones(3) - p.ms.Lambda_r_t @ (p.ms.Lambda_r_t.T @ np.ones(3))
    with pytest.raises(NotInDAFC, match="outside the motion space"):
        torque_set(p.system, p.sel, p.ms, p.st, p.fs, g, p.ms.Lambda_r_t[:, 0] + off)
    disk = build_system(disk_scene(2))
    q = CombinationParts.build(disk, "ND")
    g = stationary_grasp(disk, q.sel, q.st, q.fs)
    for d in ([-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]):
        with pytest.raises(NotInDAFC, match="positive work"):
            torque_set(disk, q.sel, q.ms, q.st, q.fs, g, np.array(d))


def test_empty_torque_set_is_really_empty() -> None:
    """SSSSS (no redundancy, so the motion is fixed by the direction): DAFC (positive work,
    eq. 22) has members for which no contact forces put the net wrench exactly along the motion
    (W_3 of eq. 30): there T is empty. Checked with scipy at the same motion. The example
    direction of the combination is a member with a torque set."""
    p = parts_of(NAME, "SSSSS")
    assert p.ms.n_redundant == 0
    s = summarize(p)
    assert s.feasible and s.example_direction is not None
    g = stationary_grasp(p.system, p.sel, p.st, p.fs)
    torque_set(p.system, p.sel, p.ms, p.st, p.fs, g, s.example_direction)  # realisable: no raise
    oracle = DAFCOracle(p.system, p.sel, p.ms, p.st, p.fs)
    empty = [t for t in map(oracle.test, dafc_set(oracle, samples=72).members()) if not oracle.realisable(t)]
    assert empty, "SSSSS has DAFC members without a torque set"
    direction = empty[0].direction
    with pytest.raises(EmptyTorqueSet):
        torque_set(p.system, p.sel, p.ms, p.st, p.fs, g, direction)
    u = p.ms.coordinates(direction)
    u /= np.linalg.norm(u)
    motion = p.ms.Phi_full @ u
    G = effective_grasp_matrix(p.system, p.sel, p.st.G_c, motion)
    dr = motion[p.system.M :]
    Q = np.eye(3) - np.outer(dr, dr)  # w - (dr.w) dr = 0
    A_ub = np.vstack([p.fs.C, -(dr @ G)[None, :]])
    b_ub = np.r_[np.zeros(p.fs.C.shape[0]), dr @ p.system.w_ex]
    status, _, _ = scipy_lp(np.zeros(G.shape[1]), A_ub, b_ub, Q @ G, -(Q @ p.system.w_ex))
    assert status == 2


def test_frictionless_disk_push() -> None:
    """ND on the frictionless disk, pushing along +x: the torque set is the ray of pushes
    n1 > 0 through tau = J_c^T n1 = (-n1,) (the tip moves -x for q > 0), with tau_st = 0 at its
    apex (a cone: cdd must report its apex)."""
    system = build_system(disk_scene(1))
    p = CombinationParts.build(system, "ND")
    g = stationary_grasp(system, p.sel, p.st, p.fs)
    ts = torque_set(system, p.sel, p.ms, p.st, p.fs, g, np.array([1.0, 0.0, 0.0]))
    assert ts.generators is not None
    np.testing.assert_allclose(ts.generators.vertices, [[0.0, 0.0]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ts.generators.rays, [[-1.0, 0.0]], rtol=0, atol=1e-12)
    assert ts.tau[0] < 0.0 and ts.work == pytest.approx(-ts.tau[0], rel=1e-9)


@pytest.mark.parametrize("combination", ["FSFSD", "FSFSS", "SSDDF", "SDSSS", "DDSSS"])
def test_friction_uncertainty_at_nu_one_is_tau_mu(combination: str) -> None:
    """nu = 1: lambda = e_0 solves the paper's system (its first column vanishes above the last
    row), also when the system is singular (SSDDF, SDSSS, DDSSS: the stationary grasps load the
    S-points in proportion); the torque is tau_mu itself."""
    p, ts = _torque_set(combination)
    fu = friction_uncertainty(p.system, p.sel, p.st, p.fs, ts, 1.0)
    assert fu.nu == 1.0 and fu.feasible, fu.reason
    np.testing.assert_allclose(fu.lambdas, np.eye(len(fu.lambdas))[0], rtol=0, atol=1e-9)
    assert fu.tau is not None
    np.testing.assert_allclose(fu.tau, ts.tau, rtol=0, atol=1e-9)


def test_friction_uncertainty_solves_the_paper_system() -> None:
    """The lambdas sum to one; 'feasible' means lambda_0 > 0, lambda_i >= 0; nu outside [0, 1]
    is refused. FSFSD (regular) stays feasible at nu = 0.8 and 0.5 with lambda_0 < 1."""
    for combination in ["FSFSD", "FSFSS", "SSDDF", "SDSSS", "DDSSS"]:
        p, ts = _torque_set(combination)
        for nu in (0.8, 0.5):
            fu = friction_uncertainty(p.system, p.sel, p.st, p.fs, ts, nu)
            assert (fu.tau is not None) == fu.feasible
            if fu.feasible or fu.reason.startswith("lambda violates"):
                assert fu.lambdas.sum() == pytest.approx(1.0, abs=1e-9)
                assert fu.feasible == bool(fu.lambdas[0] > 1e-12 and np.all(fu.lambdas[1:] >= -1e-12))
            if combination == "FSFSD":
                assert fu.feasible and 0.0 < fu.lambdas[0] < 1.0
        with pytest.raises(ValueError, match="nu"):
            friction_uncertainty(p.system, p.sel, p.st, p.fs, ts, 1.5)


def test_example_direction_prefers_a_realisable_member_ddsss() -> None:
    """DDSSS: DAFC (22) has no W_3 condition, so some members have an empty torque set (32).
    Realisability is checked against scipy, independently of the (LAPACK-chosen) signs of the
    basis Lambda~_r: directions are built in the world frame. dr0 = (-0.985, 0, -0.171) is a
    DAFC member (unbounded work: a recession ray of the force LP does work 1) whose T is
    empty (no forces put the net wrench along dr0); (-0.985, 0, +0.171) has a T. The example
    direction of the summary must be a member with a non-empty T, re-checked by scipy."""
    p = parts_of(NAME, "DDSSS")
    sy, ms, st, fs = p.system, p.ms, p.st, p.fs
    oracle = p.oracle()

    def scipy_t_status(dr: np.ndarray) -> tuple[int, int]:
        """(DAFC sup status, T max-work status) by scipy for the motion the oracle tests."""
        t = oracle.test(dr)
        assert t.zeta_c is not None
        motion = ms.Phi_full @ t.zeta_c
        G = effective_grasp_matrix(sy, p.sel, st.G_c, motion)
        d = motion[sy.M :]
        Xi = st.Xi
        dafc, _, _ = scipy_lp(d @ G, fs.C, np.zeros(fs.C.shape[0]), Xi.T @ G, -(Xi.T @ sy.w_ex), maximize=True)
        Q = np.eye(sy.D) - np.outer(d, d)  # W_2 and W_3 of (30): w parallel to d
        A_ub = np.vstack([fs.C, -(d @ G)[None, :]])
        b_ub = np.r_[np.zeros(fs.C.shape[0]), d @ sy.w_ex]
        tset, _, _ = scipy_lp(d @ G, A_ub, b_ub, Q @ G, -(Q @ sy.w_ex), maximize=True)
        return dafc, tset

    th = np.arctan2(0.1713667098442060, 0.9852073135930183)
    for sign, realisable in ((-1.0, False), (1.0, True)):
        dr = np.array([-np.cos(th), 0.0, sign * np.sin(th)])
        t = oracle.test(dr)
        assert t.member and t.work > 0.0 and oracle.certify(t)  # positive work (at the grip bound)
        dafc, tset = scipy_t_status(dr)
        assert dafc == 3  # unbounded positive work: a DAFC member
        assert (tset in (0, 3)) == realisable and oracle.realisable(t) == realisable
        if not realisable:
            with pytest.raises(EmptyTorqueSet):
                torque_set(sy, p.sel, ms, st, fs, stationary_grasp(sy, p.sel, st, fs), dr)
    s = summarize(p)
    assert s.feasible and s.example_direction is not None
    assert scipy_t_status(s.example_direction)[1] in (0, 3)
    _, ts = _torque_set("DDSSS")
    res = ts.residuals(ts.f_c)
    assert res["inequality"] <= TOL and res["equality"] <= TOL and res["work"] > 0.0



def _independent_slip_directions(p: RedundancyNLP) -> set[tuple[float, ...]]:
    """Problem (31) in the plane written out again with scipy, each S-point's tangent taken from
    the range of its slip rows (SVD) rather than from the contact frame: the unit slips
    ``(#S x 2)`` for which it is feasible, rounded."""
    a_bar, r, L_c, n_s = p.u.shape[0], p.Lambda_qr_t.shape[1], p.C.shape[1], len(p.s_cols)
    found: set[tuple[float, ...]] = set()
    for sigma in itertools.product((1.0, -1.0), repeat=n_s):
        A_ub = [np.hstack([np.zeros((p.C.shape[0], r)), p.C])]
        b_ub = [np.zeros(p.C.shape[0])]
        if p.B.shape[0]:
            A_ub.append(np.hstack([p.B[:, a_bar:], np.zeros((p.B.shape[0], L_c))]))
            b_ub.append(-p.B[:, :a_bar] @ p.u)
        G = p.G_c.copy()
        units = []
        for k, col in enumerate(p.s_cols):
            P_k = p.P_s[2 * k : 2 * k + 2]  # (2, a)
            t = sigma[k] * np.linalg.svd(P_k)[0][:, 0]  # a unit slip direction
            units.append(t)
            A_ub.append(np.concatenate([-(t @ P_k)[a_bar:], np.zeros(L_c)])[None, :])  # t . slip >= delta
            b_ub.append(np.array([-p.slip_min + (t @ P_k)[:a_bar] @ p.u]))
            G[:, col] = G[:, col] - p.mu_s[k] * (p.G_s_blocks[k] @ t)  # friction against the slip
        W = np.hstack([np.zeros((G.shape[0], r)), G])
        LrT = p.Lambda_r_t.T
        A_ub.append(-(p.u @ LrT @ W)[None, :])
        b_ub.append(np.array([p.u @ LrT @ p.w_ex - p.w_min]))
        A_eq = np.vstack([p.Xi.T @ W, p.N_u.T @ LrT @ W])
        b_eq = np.concatenate([-p.Xi.T @ p.w_ex, -p.N_u.T @ LrT @ p.w_ex])
        status, _, _ = scipy_lp(np.zeros(r + L_c), np.vstack(A_ub), np.concatenate(b_ub), A_eq, b_eq)
        assert status in (0, 2), status
        if status == 0:
            found.add(tuple(np.round(np.concatenate(units), 6) + 0.0))
    return found


@pytest.mark.parametrize("combination", ["DFDSS", "SDDSS", "FSFSS", "SDSSS", "DDSSS", "SSDDF"])
def test_planar_slip_patterns_decide_problem_31(combination: str) -> None:
    """In the plane, problem (31) is feasible exactly for the slip-sign patterns
    :func:`planar_slip_patterns` returns: the same as an independent scipy formulation, every
    IPOPT solution's slip signs among them, and no IPOPT solution where there is none."""
    q = parts_of(NAME, combination)
    oracle = q.oracle()
    T_s = np.array([q.system.tangents[i][0] for i in q.sel.s_index]).reshape(-1, 2)
    members = [t for t in dafc_set(oracle, samples=24, refine=0).tests if t.member]
    assert members, combination
    empty = solved = 0
    for t in members[:6]:
        p = _nlp_data(q.system, q.sel, q.ms, q.st, q.fs, t.u, with_forces=True)
        patterns = planar_slip_patterns(p, T_s)
        ours = {tuple(np.round((sigma[:, None] * T_s).ravel(), 6) + 0.0) for sigma in patterns}
        assert ours == _independent_slip_directions(p), (combination, t.u)
        res = solve_redundancy(p, zeta0=oracle.redundancy_for(t.u))
        if res.found:
            solved += 1
            slip = (p.P_s @ np.concatenate([t.u, res.zeta_r])).reshape(-1, 2)  # (#S, 2)
            signs = np.sign((slip * T_s).sum(axis=1))
            assert any(np.array_equal(signs, sigma) for sigma in patterns), (combination, signs, patterns)
        if not patterns:
            empty += 1
            assert not res.found, (combination, t.u)
    assert empty + solved > 0, combination  # (each combination has one or both)
