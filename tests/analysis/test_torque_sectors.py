"""The slip-sector screen of problem (31) in 3-D (:mod:`analysis.torque_sectors`): its band and
narrowing lemmas checked exactly, and its proofs against IPOPT and an independent scipy LP of
(31) with the motion fixed."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import parts_of, scipy_lp

import analysis.torques as torques
from analysis.dafc import dafc_set, sector_half, unit_angle
from analysis.exceptions import EmptyTorqueSet
from analysis.solvers.casadi_nlp import CONSTR_VIOL_TOL, RedundancyNLP, solve_redundancy
from analysis.solvers.cdd import polyhedron_generators
from analysis.torque_sectors import _narrow, slip_sector_screen
from analysis.torques import _chosen_motion, _nlp_data

#: (scene, combination, least number of the first 12 sampled DAFC members the screen proves
#: infeasible): two wrap combinations and Baxter's hug with sliding forearms
CASES = [("sphere_four_finger_wrap", "DFDDSSDSS", 12), ("sphere_four_finger_wrap", "DDDSSSFSS", 2),
         ("baxter_hug_box", "FDSDSS", 4)]
SLACK = CONSTR_VIOL_TOL


def test_band_holds_every_point_of_the_arc_and_nothing_outside() -> None:
    """A unit vector at angle theta in [a, b] is ``alpha_a e(a) + alpha_b e(b)`` with
    ``alpha >= 0`` and ``1 <= alpha_a + alpha_b <= 1 / cos h`` (the force LP's band); outside
    the arc a coefficient is negative."""
    rng = np.random.default_rng(3)
    for _ in range(500):
        h = rng.uniform(1e-4, 0.5 * np.pi - 0.05)
        a = rng.uniform(-np.pi, np.pi)
        b = a + 2 * h
        E = np.column_stack([unit_angle(a, 3), unit_angle(b, 3)])  # (2, 2)
        theta = rng.uniform(a, b)
        alpha = np.linalg.solve(E, unit_angle(theta, 3))
        assert alpha.min() >= -1e-12
        assert 1.0 - 1e-12 <= alpha.sum() <= 1.0 / np.cos(h) + 1e-12
        assert sector_half((a, b)) == pytest.approx(h)
        out = rng.uniform(b + 1e-3, a + 2 * np.pi - 1e-3)
        assert np.linalg.solve(E, unit_angle(out, 3)).min() < 0.0


def test_narrowed_sector_holds_every_slip_of_the_polyhedron() -> None:
    """The arc :func:`_narrow` keeps holds the angle of every point of a random polyhedron's
    image of length at least 1e-4 (points drawn as convex combinations of its vertices plus
    non-negative multiples of its rays and lines)."""
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(60):
        r = 3
        A = rng.standard_normal((5, r))
        b = rng.uniform(0.1, 1.0, 5)
        g = polyhedron_generators(A, b)
        S0, Sz = rng.standard_normal(2) * rng.uniform(0, 2), rng.standard_normal((2, r))
        images = np.vstack([S0 + g.vertices @ Sz.T, g.rays @ Sz.T, g.lines @ Sz.T, -(g.lines @ Sz.T)])
        for sec in (None, (-0.25 * np.pi, 0.25 * np.pi), (0.5, 2.0)):
            new, gone = _narrow(images, sec)
            for _ in range(40):
                lam = rng.dirichlet(np.ones(len(g.vertices)))
                z = lam @ g.vertices
                if len(g.rays):
                    z = z + rng.exponential(size=len(g.rays)) @ g.rays
                if len(g.lines):
                    z = z + rng.standard_normal(len(g.lines)) @ g.lines
                s = S0 + Sz @ z
                if np.linalg.norm(s) < 1e-4:
                    continue
                th = np.arctan2(s[1], s[0])
                if sec is not None and not _in(th, sec):
                    continue  # not a slip of this box
                assert not gone
                assert new is None or _in(th, new), (sec, new, th)
                checked += 1
    assert checked > 1000


def _in(theta: float, sec: tuple[float, float]) -> bool:
    a, b = sec
    return bool(np.mod(theta - a + 1e-9, 2 * np.pi) <= (b - a) + 2e-9)


def _fixed_motion_lp(p: RedundancyNLP, z: np.ndarray) -> int:
    """Problem (31) with the redundancy fixed to ``z``, written out again with scipy: with the
    slips known the friction is linear in the normal forces. Returns linprog's status (0
    feasible, 2 infeasible); 2 as well when the motion breaks a row of (31) by more than IPOPT's
    slack (a D-point penetrates or an S-point slides less than slip_min)."""
    a_bar = p.u.shape[0]
    zc = np.concatenate([p.u, z])
    if p.B.shape[0] and float(np.max(p.B @ zc)) > SLACK:
        return 2
    slips = (p.P_s @ zc).reshape(len(p.s_cols), 3)
    if np.any((slips * slips).sum(axis=1) < p.slip_min**2 - SLACK):
        return 2
    G = p.G_c.copy()
    for k, col in enumerate(p.s_cols):
        s = slips[k]
        G[:, col] = G[:, col] - p.mu_s[k] * (p.G_s_blocks[k] @ (s / np.sqrt(s @ s + 1e-12)))
    LrT = p.Lambda_r_t.T
    E = np.vstack([p.Xi.T @ G, p.N_u.T @ LrT @ G])
    e = np.concatenate([-p.Xi.T @ p.w_ex, -p.N_u.T @ LrT @ p.w_ex])
    A_ub = np.vstack([p.C, -(p.u @ LrT @ G)[None, :], E, -E])
    b_ub = np.concatenate([np.full(p.C.shape[0], SLACK), [p.u @ LrT @ p.w_ex - p.w_min + SLACK], e + SLACK,
                           -e + SLACK])
    assert a_bar == p.Lambda_r_t.shape[1]
    return scipy_lp(np.zeros(p.C.shape[1]), A_ub, b_ub)[0]


@pytest.mark.parametrize(("scene", "combination", "least"), CASES)
def test_screen_proofs_agree_with_ipopt_and_a_fixed_motion_lp(scene: str, combination: str, least: int) -> None:
    """For the first 12 sampled DAFC members: where the screen proves (31) infeasible, IPOPT finds
    no solution from the least-L1 redundancy nor from the DAFC certificate, and the independent
    scipy LP of (31) at 60 seeded allowable redundancies (the certificate's, IPOPT's last iterates,
    random ones) finds no forces; where IPOPT solves (31), the screen proves nothing."""
    q = parts_of(scene, combination)
    oracle = q.oracle()
    members = [t for t in dafc_set(oracle, samples=24, refine=0).tests if t.member][:12]
    T = np.array([q.system.tangents[i] for i in q.sel.s_index])
    rng = np.random.default_rng(11)
    proved = 0
    for t in members:
        p = _nlp_data(q.system, q.sel, q.ms, q.st, q.fs, t.u, with_forces=True)
        screen = slip_sector_screen(p, T)
        z0 = oracle.redundancy_for(t.u)
        assert z0 is not None and t.zeta_c is not None
        runs = [solve_redundancy(p, zeta0=z0), solve_redundancy(p, zeta0=t.zeta_c[q.ms.a_bar:], f0=t.forces)]
        if not screen.infeasible:
            continue
        proved += 1
        assert not any(r.found for r in runs), (combination, t.u, [r.status for r in runs])
        zs = [t.zeta_c[q.ms.a_bar:], z0] + [r.zeta_r for r in runs]
        scale = max(1.0, float(np.linalg.norm(z0)))
        zs += [z0 + scale * rng.standard_normal(z0.shape) for _ in range(56)]
        assert all(_fixed_motion_lp(p, z) == 2 for z in zs), (combination, t.u)
    assert proved >= least, (combination, proved)


def test_torque_problem_skips_ipopt_where_the_screen_proves_it_infeasible(monkeypatch: pytest.MonkeyPatch) -> None:
    """(31) for a proved direction raises EmptyTorqueSet with the screen's reason; IPOPT is not run."""
    q = parts_of("sphere_four_finger_wrap", "DFDDSSDSS")
    oracle = q.oracle()
    t = next(t for t in dafc_set(oracle, samples=24, refine=0).tests if t.member)

    def no_ipopt(*args: object, **kwargs: object) -> None:
        raise AssertionError("IPOPT ran")

    monkeypatch.setattr(torques, "solve_redundancy", no_ipopt)
    with pytest.raises(EmptyTorqueSet, match="no slip-sector box admits a solution"):
        _chosen_motion(oracle, q.system, q.sel, q.ms, q.st, q.fs, t.u, start=t)
