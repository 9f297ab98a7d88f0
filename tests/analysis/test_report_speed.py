"""Issue 13: the full report made cheaper without changing its answers.

* IPOPT (problem 31) is built once per combination and reused with the direction as a parameter:
  the answers equal those of a solver built for the one call.
* The boundary refinement of the sampled DAFC resolves a boundary on a face of the allowable cone
  with one test where the great circle leaves the cone: that point is on the face (``H u = 0``),
  allowable and a member, and just outside it the motion is not allowable.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from closure_helpers import scipy_lp

import analysis.solvers.casadi_nlp as nlp
from analysis.combination import NO_GRASP_DAFC, CombinationParts, analyze_combination
from analysis.contacts import build_system
from analysis.dafc import _allowable_faces, _face_crossing, dafc_set, default_samples, sample_directions
from analysis.loader import load_scene
from analysis.scales import GRIP_BOUND
from analysis.torques import _nlp_data

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def planar():
    return build_system(load_scene(ROOT / "examples" / "planar_disk_envelope.json"))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def test_reused_ipopt_solver_gives_the_answers_of_a_fresh_one(planar) -> None:
    # SSDSD: S-points whose slip depends on the redundancy, so (31) has the forces as unknowns
    parts = CombinationParts.build(planar, "SSDSD")
    sy, sel, ms, st, fs = parts.system, parts.sel, parts.ms, parts.st, parts.fs
    assert parts.oracle().slip_depends_on_redundancy
    rng = np.random.default_rng(7)
    dirs = [_unit(rng.standard_normal(ms.a_bar)) for _ in range(4)]
    problems = [_nlp_data(sy, sel, ms, st, fs, u, with_forces=True) for u in dirs]
    nlp._solvers().clear()
    reused = [nlp.solve_redundancy(p) for p in problems]
    assert len(nlp._solvers()) == 1  # one build for the four directions (no zero entries in u, N_u)
    for p, r in zip(problems, reused, strict=True):
        nlp._solvers().clear()
        fresh = nlp.solve_redundancy(p)
        assert fresh.status == r.status
        np.testing.assert_allclose(fresh.zeta_r, r.zeta_r, rtol=0, atol=1e-12)
        assert fresh.phi == pytest.approx(r.phi, abs=1e-12)
        # phi is the norm of the finger motion of the returned redundancy (eq. 31's objective)
        assert r.phi == pytest.approx(float(np.linalg.norm(p.Lambda_q_t @ p.u + p.Lambda_qr_t @ r.zeta_r)),
                                      abs=1e-12)


def test_direction_zero_pattern_is_part_of_the_solver_key(planar) -> None:
    parts = CombinationParts.build(planar, "SSDSD")
    sy, sel, ms, st, fs = parts.system, parts.sel, parts.ms, parts.st, parts.fs
    e0 = np.eye(ms.a_bar)[0]  # zero entries: structural zeros, another solver
    u = _unit(np.ones(ms.a_bar))
    nlp._solvers().clear()
    a = nlp.solve_redundancy(_nlp_data(sy, sel, ms, st, fs, e0, with_forces=True))
    nlp.solve_redundancy(_nlp_data(sy, sel, ms, st, fs, u, with_forces=True))
    assert len(nlp._solvers()) == 2
    nlp._solvers().clear()
    b = nlp.solve_redundancy(_nlp_data(sy, sel, ms, st, fs, e0, with_forces=True))
    assert a.status == b.status and np.allclose(a.zeta_r, b.zeta_r, rtol=0, atol=1e-12)


def test_face_crossing_lies_on_the_cone_boundary() -> None:
    rng = np.random.default_rng(11)
    for _ in range(50):
        # a pointed cone {u : H u <= 0} around +e2 in R^3
        H = np.column_stack([rng.standard_normal((5, 2)), -np.abs(rng.standard_normal(5)) - 0.5])
        H /= np.linalg.norm(H, axis=1, keepdims=True)
        inner = np.array([0.0, 0.0, 1.0])
        outer = _unit(rng.standard_normal(3))
        if np.max(H @ outer) <= 1e-6:
            continue
        m = _face_crossing(H, inner, outer)
        assert m is not None
        assert abs(np.linalg.norm(m) - 1.0) < 1e-12
        assert abs(float(np.max(H @ m))) < 1e-12  # on the boundary: one row active, none violated
        # on the arc: m = alpha inner + beta outer with alpha, beta > 0
        coef, *_ = np.linalg.lstsq(np.column_stack([inner, outer]), m, rcond=None)
        assert np.allclose(np.column_stack([inner, outer]) @ coef, m, atol=1e-12) and np.all(coef > 0)
        # just before it the arc is inside, just after it outside
        before, after = _unit(m + 1e-6 * (inner - m)), _unit(m + 1e-6 * (outer - m))
        assert np.max(H @ before) < 0 < np.max(H @ after)


def test_refinement_resolves_faces_of_the_allowable_cone_exactly(planar) -> None:
    parts = CombinationParts.build(planar, "SSDFD")
    ms = parts.ms
    assert ms.a_bar == 3
    H = _allowable_faces(ms)
    assert H is not None
    oracle = parts.oracle()
    samples = default_samples(ms.a_bar)
    n0 = len(sample_directions(ms, samples))
    ds = dafc_set(oracle, samples=samples)
    refined = ds.tests[n0:]
    on_face = [t for t in refined if t.member and float(np.max(H @ t.u)) > -1e-9]
    assert on_face, "expected boundaries on faces of A_r"
    fresh = parts.oracle()
    for t in on_face:
        assert float(np.max(H @ t.u)) < 1e-9  # allowable: inside or on A_r
        assert fresh.test(t.direction).member  # an independent oracle agrees
        # a step out of the cone through the active face is not allowable (eq. 20)
        out = _unit(t.u + 1e-4 * H[int(np.argmax(H @ t.u))])
        assert fresh.test(ms.Lambda_r_t @ out).reason.startswith("not allowable")
    # the sampled directions' verdicts are the oracle's, whatever the refinement
    for t in ds.tests[:n0]:
        assert fresh.test(t.direction, witness=False).member == t.member


def test_report_states_its_refinement(planar) -> None:
    out = analyze_combination(planar, "FSFSD").to_json()
    assert "allowable cone" in out["dafc"]["refinement"]
    assert len(out["dafc"]["directions"]) == len(out["dafc"]["member"]) == len(out["dafc"]["work"])


@pytest.mark.parametrize("combination", ["SSDFD", "FDSFD", "DFSSD"])
def test_report_does_not_sample_dafc_without_a_stationary_grasp(planar, combination: str) -> None:
    """Where (18) has no solution (scipy: no f in F with G_c f = -w_ex) the report has no sampled
    DAFC and says why: Theorem 1 defines DAFC for an object held by a stationary grasp."""
    parts = CombinationParts.build(planar, combination)
    st, fs, sy = parts.st, parts.fs, parts.system
    assert scipy_lp(np.zeros(st.G_c.shape[1]), fs.C, np.zeros(fs.C.shape[0]), st.G_c, -sy.w_ex)[0] == 2
    out = analyze_combination(planar, combination).to_json()
    assert out["feasible"] is False and out["reason"].startswith("no stationary grasp (18)")
    assert "dafc" not in out and "stationary" not in out and out["a_bar"] > 0
    assert NO_GRASP_DAFC in out["notes"]


# -- LP shortcuts of the DAFC oracle (issue 13): each decides exactly as the LP it replaces -------

_SHORTCUT_COMBINATIONS = ("SSDSD", "SDDSD", "FSDSD", "SFDDS", "DSSDD", "SSSDD", "FFSDS", "SDSDS")


def _seeded_directions(ms, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((n, ms.a_bar))
    return (U / np.linalg.norm(U, axis=1, keepdims=True)) @ ms.Lambda_r_t.T  # (n, D)


def test_relaxed_screen_without_lp_agrees_with_the_relaxed_lp(planar) -> None:
    # the lower bound from earlier maximisers may only say "positive" where the LP says so too
    shortcuts = 0
    for comb in _SHORTCUT_COMBINATIONS:
        parts = CombinationParts.build(planar, comb)
        if parts.ms.a_bar == 0 or not parts.sel.s_index:
            continue
        oracle, fresh = parts.oracle(), parts.oracle()
        for dr in _seeded_directions(parts.ms, 40, seed=3):
            before = oracle.lp_count
            fast = oracle.relaxed_positive(dr)
            shortcuts += oracle.lp_count == before
            sup = fresh.relaxed_work_sup(dr)
            assert fast == (sup > planar.scales.work_tol(dr)), (comb, dr, sup)
    assert shortcuts > 0  # the shortcut was taken at least once, so the comparison tested it


def test_farkas_certificates_decide_allowability_as_the_redundancy_lp(planar) -> None:
    proved = 0
    for comb in _SHORTCUT_COMBINATIONS:
        parts = CombinationParts.build(planar, comb)
        ms = parts.ms
        if ms.a_bar == 0 or not ms.n_redundant or parts.ms.B.shape[0] == 0:
            continue
        oracle = parts.oracle()
        for dr in _seeded_directions(ms, 60, seed=5):
            u = ms.coordinates(dr)
            before = oracle.lp_count
            z = oracle.redundancy_for(u)
            if oracle.lp_count == before and z is None:
                proved += 1
            fresh = parts.oracle().redundancy_for(u)  # no certificates: decided by its own LP
            assert (z is None) == (fresh is None), (comb, u)
            if z is not None:
                assert fresh is not None
                np.testing.assert_allclose(z, fresh, rtol=0, atol=1e-12)
        for y in oracle._farkas:  # each certificate: y >= 0, sum 1, y^T B_r = 0
            assert np.all(y >= 0) and abs(y.sum() - 1.0) < 1e-12
            assert np.max(np.abs(oracle._B_r.T @ y)) <= 1e-12
    assert proved > 0


def test_unchanged_coefficients_keep_the_model_and_its_answers() -> None:
    from analysis.solvers.highs import LPModel, solve_lp

    rng = np.random.default_rng(11)
    A_ub = rng.standard_normal((6, 3))
    b_ub = rng.random(6) + 0.5
    A_eq = rng.standard_normal((1, 3))
    model = LPModel(3, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=np.array([0.1]), lb=-2.0, ub=2.0)
    c = rng.standard_normal(3)
    model.solve(c, maximize=True)
    # row 6 is the equality row: one entry unchanged, one changed
    model.change_coefficients(np.array([6, 6, 0]), np.array([0, 1, 2]), np.array([A_eq[0, 0], 0.7, A_ub[0, 2]]))
    A_eq2 = A_eq.copy()
    A_eq2[0, 1] = 0.7
    np.testing.assert_array_equal(model.A_eq, A_eq2)
    np.testing.assert_array_equal(model.A_ub, A_ub)
    res = model.solve(c, maximize=True)
    ref = solve_lp(c, A_ub, b_ub, A_eq2, np.array([0.1]), -2.0, 2.0, maximize=True)
    assert res.found and ref.found and res.objective is not None and ref.objective is not None
    assert abs(res.objective - ref.objective) < 1e-9
    assert res.is_optimal(1e-8)


def test_work_threshold_is_the_weighted_euclidean_norm(planar) -> None:
    sc = planar.scales
    for dr in np.random.default_rng(2).standard_normal((20, planar.D)):
        expected = 1e-6 * sc.force * float(np.linalg.norm(dr * sc.motion_weights()))
        assert sc.work_tol(dr) == pytest.approx(expected, rel=1e-15, abs=0)


def test_certified_vertices_decide_as_the_force_lp(planar) -> None:
    # the sampled set (witness=False) may decide a direction from an earlier optimal vertex of the
    # same force-LP rows; every such answer must equal a fresh oracle's LP (verdict and supremum)
    hits = 0
    for comb in ("FFDFD", "SDDSD", "FSDSD", "SSDFD", "FFSDS", "DSSDD"):
        parts = CombinationParts.build(planar, comb)
        if parts.ms.a_bar == 0:
            continue
        oracle = parts.oracle()
        for dr in _seeded_directions(parts.ms, 60, seed=13):
            before = oracle.vertex_hits
            t = oracle.test(dr, witness=False)
            if oracle.vertex_hits == before:
                continue
            hits += 1
            ref = parts.oracle().test(dr, witness=False)  # no stored vertices: decided by the LP
            assert t.member == ref.member and t.reason == ref.reason, (comb, dr)
            if np.isfinite(ref.work):
                assert t.work == pytest.approx(ref.work, rel=1e-9, abs=1e-9 * planar.scales.force)
            else:
                assert not np.isfinite(t.work)
            if t.member:
                assert oracle.certify(t)  # the stored vertex's forces pass the newton-level check
    assert hits > 20  # the shortcut was taken, so the comparison tested it


def test_planar_force_lp_by_slip_signs_agrees_with_scipy(planar) -> None:
    # 2-D: the force LP of a motion depends on the S-points' slip signs only (the friction columns
    # of the exact +-t); its supremum must equal an independent LP with the motion's own slips
    from scipy.optimize import linprog

    from analysis.friction import kinetic_friction

    rng = np.random.default_rng(17)
    checked = 0
    for comb in _SHORTCUT_COMBINATIONS:
        parts = CombinationParts.build(planar, comb)
        sy, sel, ms, st, fs = parts.system, parts.sel, parts.ms, parts.st, parts.fs
        if ms.a_bar == 0 or not sel.s_index:
            continue
        oracle = parts.oracle()
        F0 = sy.scales.force
        for _ in range(40):
            zc = rng.standard_normal(ms.a)  # (a,) any motion of the motion space
            u = zc[:ms.a_bar]
            dr = ms.Lambda_r_t @ (u / np.linalg.norm(u))
            zc = zc / np.linalg.norm(u)
            sl = oracle.slips_of(zc)  # (#S, 2)
            if np.min(np.linalg.norm(sl, axis=1)) <= 1e-6:
                continue
            sup, _ = oracle.work_sup(dr, zc, witness=False)
            G_eff = st.G_c + kinetic_friction(sy, sel, sl).G_w  # (D, L_c) this motion's own slips
            res = linprog(-(G_eff.T @ dr), A_ub=np.vstack([fs.C, fs.N.sum(axis=0)]),
                          b_ub=np.r_[np.zeros(fs.C.shape[0]), GRIP_BOUND * F0],
                          A_eq=st.Xi.T @ G_eff, b_eq=-(st.Xi.T @ sy.w_ex), bounds=(None, None), method="highs")
            if res.status == 2:
                assert sup == -np.inf, (comb, zc)
                continue
            assert res.status == 0, (comb, res.message)
            ref = -res.fun + float(dr @ sy.w_ex)
            assert sup == pytest.approx(ref, rel=1e-7, abs=1e-7 * F0), (comb, zc)
            checked += 1
        assert len(oracle._pattern_G) <= 2 ** len(sel.s_index)
    assert checked > 100


def test_realisable_direction_nlp_only_when_the_example_direction_has_no_torque_set(planar, monkeypatch) -> None:
    # the IPOPT search for a realisable direction is the second fallback of the default torque
    # set: it runs only after the example direction and the certificate's wrench direction failed
    import analysis.combination as combination

    calls: list[str] = []
    real = combination.realisable_direction

    def counted(system, sel, *args, **kwargs):
        calls.append(sel.combination)
        return real(system, sel, *args, **kwargs)

    monkeypatch.setattr(combination, "realisable_direction", counted)
    for comb in ("FSFSS", "SFSFS"):  # S-points, and the example direction has a torque set
        rep = analyze_combination(planar, comb)
        assert rep.torque is not None and rep.torque_error is None
    assert calls == []
    rep = analyze_combination(planar, "DFDFS")  # no DAFC direction tried has a torque set
    assert calls == ["DFDFS"]
    assert rep.torque is None and rep.torque_error is not None
    assert rep.torque_error.endswith("(and 3 other DAFC directions tried)")


def _random_rhs_lp(rng: np.random.Generator, n: int = 4, m: int = 6):  # type: ignore[no-untyped-def]
    """``min c^T x, A x <= b, x >= 0`` of random data: ``(A, c, b0, bases, model)``, the
    certified bases of :class:`analysis.dafc._RhsBases` empty and a HiGHS model to harvest them."""
    from analysis.dafc import _RhsBases
    from analysis.solvers.highs import LPModel

    A = rng.standard_normal((m, n))  # (m, n)
    c = rng.random(n) + 0.1  # (n,)
    bases = _RhsBases(c, A, np.zeros(n), np.full(n, np.inf))
    model = LPModel(n, A_ub=A, b_ub=np.zeros(m), lb=0.0)
    return A, c, rng.standard_normal(m), bases, model


def test_certified_bases_give_the_cold_lp_optimum() -> None:
    # min c^T x, A x <= b, x >= 0 with b changing: a kept basis answers only when its point is the
    # LP's unique optimum; compare with scipy's LP on every right-hand side, reused or not
    from scipy.optimize import linprog

    rng = np.random.default_rng(23)
    reused = 0
    for _ in range(5):
        A, c, b0, bases, model = _random_rhs_lp(rng)
        m = A.shape[0]
        for _ in range(60):
            b = b0 + 0.3 * rng.standard_normal(m)
            ref = linprog(c, A_ub=A, b_ub=b, bounds=(0, None), method="highs")
            x = bases.solve(b)
            if x is not None:
                reused += 1
                assert ref.status == 0
                np.testing.assert_allclose(x, ref.x, rtol=0, atol=1e-9)
                continue
            model.set_ub_rhs(b)
            res = model.solve_cold(c)
            assert (res.status == "optimal") == (ref.status == 0)
            if res.status == "optimal":
                bases.harvest(res)
    assert reused > 50


def test_certified_bases_for_many_right_hand_sides_give_the_lp_optimum() -> None:
    # issue 13: solve_many (the batched DAFC tests' redundancies) answers a row only with scipy's
    # optimum for that right-hand side, and answers the rows solve() answers one at a time
    from scipy.optimize import linprog

    rng = np.random.default_rng(29)
    answered = 0
    for _ in range(5):
        A, c, b0, bases, model = _random_rhs_lp(rng)
        m = A.shape[0]
        for _ in range(20):  # harvest bases from cold solves
            model.set_ub_rhs(b0 + 0.3 * rng.standard_normal(m))
            res = model.solve_cold(c)
            if res.status == "optimal":
                bases.harvest(res)
        B = b0 + 0.3 * rng.standard_normal((40, m))  # (40, m)
        X, found = bases.solve_many(B)
        for b, x, ok in zip(B, X, found, strict=True):
            assert ok == (bases.solve(b) is not None)
            if ok:
                ref = linprog(c, A_ub=A, b_ub=b, bounds=(0, None), method="highs")
                assert ref.status == 0
                np.testing.assert_allclose(x, ref.x, rtol=0, atol=1e-9)
                answered += 1
    assert answered > 50


def test_degenerate_optimum_is_not_kept_as_a_basis() -> None:
    # min x1 + x2 s.t. x1 + x2 >= 1, x >= 0: every point of the segment is optimal (a zero
    # multiplier at the vertex), so no basis may answer for another right-hand side
    from analysis.dafc import _RhsBases
    from analysis.solvers.highs import LPModel

    A = np.array([[-1.0, -1.0]])
    c = np.ones(2)
    bases = _RhsBases(c, A, np.zeros(2), np.full(2, np.inf))
    model = LPModel(2, A_ub=A, b_ub=np.array([-1.0]), lb=0.0)
    res = model.solve_cold(c)
    assert res.status == "optimal"
    bases.harvest(res)
    assert bases.bases == [] and bases.solve(np.array([-2.0])) is None


def test_allowable_cone_is_kept_per_motion_space(planar) -> None:
    import gc

    from analysis.dafc import _ALLOWABLE, _allowable_cone, allowable_cone

    parts = CombinationParts.build(planar, "FDFDD")
    other = CombinationParts.build(planar, "FDFDD")  # an equal motion space, another object
    g = allowable_cone(parts.ms)
    assert allowable_cone(parts.ms) is g  # kept
    fresh = _allowable_cone(parts.ms)
    for a, b in ((g.vertices, fresh.vertices), (g.rays, fresh.rays), (g.lines, fresh.lines)):
        np.testing.assert_array_equal(a, b)
        assert not a.flags.writeable  # shared: nobody may change it in place
    assert allowable_cone(other.ms) is not g
    key = id(parts.ms)
    del parts
    gc.collect()
    assert key not in _ALLOWABLE  # dropped with its motion space
