"""Direction of active force closure (paper eq. 22).

Known answers on two scenes derived by hand (a frictionless disk between two fingertips; a
block pushed along a table), then certificates: every member the oracle returns is re-checked
with forces, slips and penetration recomputed here, and non-members without S-points are
re-checked with an independent LP (scipy).
"""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import (
    BOX_B,
    BOX_C,
    box_scene,
    disk_scene,
    effective_grasp_matrix,
    example_system,
    parts_of,
    sample_combinations,
    scipy_lp,
    slip,
)

from analysis.combination import CombinationParts, summarize
from analysis.contacts import GraspSystem, all_combinations, build_system
from analysis.dafc import (
    ALLOW_TOL,
    SEMANTICS,
    DAFCOracle,
    DirectionTest,
    allowable_cone,
    dafc_nonempty,
    dafc_set,
    slip_sector_search,
)
from analysis.scales import GRIP_BOUND


def _oracle(system: GraspSystem, combination: str) -> DAFCOracle:
    return CombinationParts.build(system, combination).oracle()


def _unit(v: list[float] | np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


# --------------------------------------------------------------------------------------------
# Known answer 1: frictionless antipodal grasp of a disk, no external wrench


@pytest.mark.parametrize("links", [1, 2])
def test_frictionless_disk_by_hand(links: int) -> None:
    """Contacts at (-+0.5, 0) with normals +-x, mu = 0. The normals pass through the centre, so
    the fingers can only push along x: a force does work on dr = (vx, vy, w) only through vx.

    NN: both pushes n1, n2 >= 0 are free (J_c has full row rank, no internal force), work
        vx (n1 - n2): DAFC = {vx != 0} (unbounded work); rotation and vertical sliding are free
        motions no force can drive.
    ND: finger 2 may retreat (its redundancy keeps it from penetrating): DAFC = {vx > 0}.
    DN: DAFC = {vx < 0}.   DD: no force at all: DAFC is empty.
    """
    system = build_system(disk_scene(links))
    rules = {"NN": lambda v: v != 0.0, "ND": lambda v: v > 0.0, "DN": lambda v: v < 0.0, "DD": lambda v: False}
    rng = np.random.default_rng(links)
    dirs = [_unit(d) for d in rng.normal(size=(100, 3))]
    dirs += [np.eye(3)[k] * s for k in range(3) for s in (1.0, -1.0)] + [_unit([0, 1, 1]), _unit([0, -1, 2])]
    for combination, rule in rules.items():
        p = CombinationParts.build(system, combination)
        assert p.ms.a_bar == 3  # the object's motion is never constrained: a pushing contact can slide
        assert p.st.p == 0  # no internal forces: nothing is balanced passively
        oracle = p.oracle()
        assert oracle.exact
        for dr in dirs:
            t = oracle.test(dr)
            assert t.member == rule(dr[0]), (combination, dr, t.reason)
            if t.member:  # n1 + n2 <= GRIP_BOUND F0 (F0 = 1 N without a load): work GRIP_BOUND |vx|
                assert t.work == pytest.approx(GRIP_BOUND * abs(dr[0]), rel=1e-9)
            elif combination != "DD":
                assert t.work == pytest.approx(0.0, abs=1e-12)  # dr^T w = vx (n1 - n2) = 0 or <= 0 at best
        s = summarize(p)
        assert s.feasible == (combination != "DD")
        assert s.dim_dafc == (3 if s.feasible else 0)
        if s.feasible:
            assert s.example_direction is not None and rule(s.example_direction[0])
        else:
            assert s.reason == "DAFC is empty"


# --------------------------------------------------------------------------------------------
# Known answer 2: a block on a table pushed by a frictionless fingertip


def _n3_max_sliding(h: float, mu: float) -> float:
    """SSN moving +x: vertical balance n1 + n2 = 1, moments about the centre (0, b)

        c (n2 - n1) = mu b - (b - h) n3,   |n2 - n1| <= 1

    bound the push n3 (by the support on the far side unloading)."""
    b, c = BOX_B, BOX_C
    return (mu * b + c) / (b - h) if h < b else (c - mu * b) / (h - b)


@pytest.mark.parametrize("h", [0.2, 0.4, 0.6, 0.75, 0.9])
@pytest.mark.parametrize("mu", [0.2, 0.5, 0.9])
def test_block_slides_iff_push_can_exceed_friction(h: float, mu: float) -> None:
    """SSN (both supports slide): the object can only translate along x (a~ = 1). +x is in DAFC
    exactly when the largest push the moment balance allows exceeds the friction mu * weight,
    and the supremum of the work is that excess; -x never is (the tip can only push)."""
    system = build_system(box_scene(h, mu))
    p = CombinationParts.build(system, "SSN")
    assert p.ms.a_bar == 1
    np.testing.assert_allclose(np.abs(p.ms.Lambda_r_t[:, 0]), [1.0, 0.0, 0.0], rtol=0, atol=1e-12)
    oracle = p.oracle()
    n3_max = _n3_max_sliding(h, mu)
    t = oracle.test(np.array([1.0, 0.0, 0.0]))
    assert t.exact
    assert t.member == (n3_max > mu)
    if n3_max >= 0.0:
        assert t.work == pytest.approx(n3_max - mu, abs=1e-9)
    else:  # even without a push the friction moment cannot be balanced: no admissible force
        assert t.work == -np.inf
    if h > BOX_B:  # pushed above the centre this is the textbook "slides iff mu h < c"
        assert t.member == (mu * h < BOX_C)
    back = oracle.test(np.array([-1.0, 0.0, 0.0]))
    assert not back.member


def test_block_tips_about_the_front_support() -> None:
    """DFN (left support lifts, right support sticks): the block turns about (c, 0); allowable
    is only the clockwise turn dr = (b, c, -1)/|.| (the lifting side must not penetrate).

    With weight 1 at the centre, push n3 at height h and support force (fx, fy), the wrench is
    along dr iff fx = lam b - n3, fy = 1 + lam c, (1 + b^2 + c^2) lam = h n3 - c; the work is
    (h n3 - c)/|(b, c, -1)| and friction |fx| <= mu fy bounds n3 by
    n3_max = (mu K - c (b + mu c)) / (K - h (b + mu c)),  K = 1 + b^2 + c^2.
    """
    b, c = BOX_B, BOX_C
    K = 1.0 + b * b + c * c
    dr = np.array([b, c, -1.0]) / np.sqrt(K)
    for h, mu in [(0.9, 0.5), (0.9, 0.8), (0.7, 0.8), (0.6, 1.0)]:
        system = build_system(box_scene(h, mu))
        p = CombinationParts.build(system, "DFN")
        assert p.ms.a_bar == 1
        np.testing.assert_allclose(np.abs(p.ms.Lambda_r_t[:, 0]), np.abs(dr), rtol=0, atol=1e-12)
        oracle = p.oracle()
        n3_max = (mu * K - c * (b + mu * c)) / (K - h * (b + mu * c))
        t = oracle.test(dr)
        assert t.member
        assert t.work == pytest.approx((h * n3_max - c) / np.sqrt(K), abs=1e-9)
        assert t.forces is not None
        np.testing.assert_allclose(t.forces[2], n3_max, rtol=0, atol=1e-9)
        back = oracle.test(-dr)
        assert not back.member and back.reason.startswith("not allowable")
        s = summarize(p)
        assert s.feasible and s.dim_dafc == 1 and s.example_direction is not None
        np.testing.assert_allclose(s.example_direction, dr, rtol=0, atol=1e-9)


@pytest.mark.parametrize(("h", "feasible"), [(0.25, {"SSN"}), (0.9, {"DFN"})])
def test_block_feasible_combinations(h: float, feasible: set[str]) -> None:
    """All 18 combinations, mu = 0.5. Pushed low (mu h < c) the block slides and cannot tip
    (DFN has no stationary grasp: holding it on one support needs n3 = c/h > mu); pushed high
    it tips and cannot slide. Two sticking supports, or one sticking and one sliding, fix the
    block (a~ = 0); SSD: the block does not move by itself (friction only resists)."""
    system = build_system(box_scene(h, 0.5))
    summaries = {c: summarize(CombinationParts.build(system, c)) for c in all_combinations(system)}
    assert {c for c, s in summaries.items() if s.feasible} == feasible
    for c in ("FFN", "FFD", "FSN", "SFN", "FSD", "SFD"):
        assert summaries[c].reason == "object cannot move (a~ = 0)"
    assert summaries["SSD"].reason == "DAFC is empty"
    for c in ("FDN", "SDN", "DSN", "DDN", "DDD", "FDD", "SDD", "DFD", "DSD"):
        assert summaries[c].reason == "no stationary grasp (18)"
    other = "SSN" if "DFN" in feasible else "DFN"
    assert not summaries[other].feasible


# --------------------------------------------------------------------------------------------
# Certificates of the oracle's answers on the example scenes


def _certify_member(system: GraspSystem, p: CombinationParts, t: DirectionTest) -> None:
    """Re-check a member: the motion keeps the contacts (A_c), does not penetrate (A_d <= 0),
    really slides at S-points; its forces are admissible, balance the passive directions
    (Xi^T w = 0) and do positive work equal to the reported one."""
    ms, st, fs, sel = p.ms, p.st, p.fs, p.sel
    assert t.member and t.zeta_c is not None
    zc = t.zeta_c
    motion = ms.Phi_full @ zc
    size = float(np.linalg.norm(zc))
    np.testing.assert_allclose(np.linalg.norm(t.direction), 1.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ms.Lambda_r_t @ t.u, t.direction, rtol=0, atol=1e-9)
    np.testing.assert_allclose(motion[system.M :], t.direction, rtol=0, atol=1e-9)  # dr = Phi dzeta_c
    np.testing.assert_allclose(ms.A_c @ motion, 0.0, rtol=0, atol=1e-9)
    for i in sel.d_index:  # a D-point separates or stays in touch, never penetrates
        assert system.normals[i] @ (system.contact_A(i) @ motion) <= 1.000001e-7 * max(1.0, size)  # ALLOW_TOL
    for i in sel.s_index:  # an S-point really slides
        assert np.linalg.norm(slip(system, i, motion)) > 1e-7 * size
    G_eff = effective_grasp_matrix(system, sel, st.G_c, motion)
    dr = t.direction
    # every member carries its forces: admissible, within the grip bound, balancing the passive
    # directions and doing the reported (positive) work, all in newtons
    assert t.forces is not None and np.isfinite(t.work)
    f = t.forces
    F0 = system.scales.force
    w = G_eff @ f + system.w_ex
    assert fs.violation(f) <= 1e-7 * F0
    assert float(fs.N.sum(axis=0) @ f) <= GRIP_BOUND * F0 * (1 + 1e-9)
    np.testing.assert_allclose(st.Xi.T @ w, 0.0, rtol=0, atol=1e-6 * F0 * (1 + system.scales.length))
    assert dr @ w == pytest.approx(t.work, abs=1e-6 * F0)
    assert dr @ w > system.scales.work_tol(dr)


def _certify_non_member_without_s(system: GraspSystem, p: CombinationParts, t: DirectionTest) -> None:
    """Without S-points the oracle is exact: check the answer with scipy."""
    ms, st, fs = p.ms, p.st, p.fs
    u = t.u / np.linalg.norm(t.u)
    if t.reason.startswith("not allowable"):
        # min t s.t. B [u; z] <= t: positive for every redundancy z
        B_u, B_r = ms.B[:, : ms.a_bar], ms.B[:, ms.a_bar :]
        k, r = ms.B.shape[0], ms.n_redundant
        status, obj, _ = scipy_lp(np.r_[np.zeros(r), 1.0], np.hstack([B_r, -np.ones((k, 1))]), -(B_u @ u))
        assert status == 0 and obj is not None and obj > 1e-10
    else:
        assert t.reason == "the fingers cannot do positive work" or t.reason.startswith("degenerate")
        dr = ms.Lambda_r_t @ u
        sc = system.scales
        if st.G_c.shape[1] == 0:
            assert dr @ system.w_ex <= sc.work_tol(dr)
            return
        # the same question asked of scipy: the largest work of admissible forces whose total
        # normal force is within the grip bound
        A_ub = np.vstack([fs.C, fs.N.sum(axis=0)[None, :]])
        b_ub = np.r_[np.zeros(fs.C.shape[0]), sc.grip_bound]
        status, obj, _ = scipy_lp(st.G_c.T @ dr, A_ub, b_ub, st.Xi.T @ st.G_c,
                                  -(st.Xi.T @ system.w_ex), box=1e2 * sc.grip_bound, maximize=True)
        assert status == 2 or (obj is not None and obj + dr @ system.w_ex <= 1.01 * sc.work_tol(dr))


def _feasible_combinations(name: str, n: int, seed: int) -> list[str]:
    out = []
    for c in sample_combinations(example_system(name), n, seed):
        if summarize(parts_of(name, c)).feasible:
            out.append(c)
    return out


@pytest.mark.parametrize(("name", "n", "samples"), [("planar_disk_envelope", 120, 12),
                                                    ("sphere_four_finger_palm", 40, 10)])
def test_oracle_answers_are_certified(name: str, n: int, samples: int) -> None:
    system = example_system(name)
    members = non_members = 0
    for c in sample_combinations(system, n, seed=2):
        p = parts_of(name, c)
        if p.ms.a_bar == 0:
            continue
        ds = dafc_set(p.oracle(), samples=samples, refine=1)
        yes = [t for t in ds.tests if t.member]
        no = [t for t in ds.tests if not t.member] if not p.sel.s_index else []
        for t in yes[:: max(1, len(yes) // 4)]:  # a spread of at most ~4 of each per combination
            members += 1
            _certify_member(system, p, t)
        for t in no[:: max(1, len(no) // 4)]:
            non_members += 1
            _certify_non_member_without_s(system, p, t)
    assert members > 30 and non_members > 10


def test_relaxation_bounds_the_work() -> None:
    """With S-points, letting the friction take any direction (|t| <= mu n) can only add work:
    the relaxed supremum bounds the oracle's for every motion it tests."""
    name = "planar_disk_envelope"
    checked = 0
    for c in [c for c in all_combinations(example_system(name)) if "S" in c][::4]:
        p = parts_of(name, c)
        if p.ms.a_bar == 0:
            continue
        oracle = p.oracle()
        rng = np.random.default_rng(4)
        for u in rng.normal(size=(6, p.ms.a_bar)):
            dr = p.ms.Lambda_r_t @ _unit(u)
            t = oracle.test(dr, screen=False)
            if np.isnan(t.work):
                continue
            checked += 1
            assert oracle.relaxed_work_sup(dr) >= t.work - 1e-9 * (1 + abs(t.work) if np.isfinite(t.work) else 1)
    assert checked > 20


# --------------------------------------------------------------------------------------------
# Scale invariance and the motion space


@pytest.mark.parametrize("name", ["planar_disk_envelope", "sphere_four_finger_palm"])
def test_membership_is_scale_free_and_restricted_to_the_motion_space(name: str) -> None:
    system = example_system(name)
    rng = np.random.default_rng(6)
    compared = 0
    for c in sample_combinations(system, 30, seed=3):
        p = parts_of(name, c)
        ms = p.ms
        if ms.a_bar == 0:
            t = p.oracle().test(rng.normal(size=system.D))
            assert not t.member and "cannot move" in t.reason
            continue
        oracle = p.oracle()
        for _ in range(3):
            dr = ms.Lambda_r_t @ _unit(rng.normal(size=ms.a_bar))
            t1, t2, t3 = oracle.test(dr), oracle.test(2.0 * dr), oracle.test(0.01 * dr)
            assert t1.member == t2.member == t3.member
            for other in (t2, t3):
                np.testing.assert_allclose(other.direction, t1.direction, rtol=0, atol=1e-12)
                if np.isfinite(t1.work):
                    assert other.work == pytest.approx(t1.work, rel=1e-9, abs=1e-12)
                else:
                    assert str(other.work) == str(t1.work)  # inf, -inf or nan alike
            compared += 1
            if ms.a_bar < system.D:  # a direction with a component the contacts forbid
                off = rng.normal(size=system.D)
                off -= ms.Lambda_r_t @ (ms.Lambda_r_t.T @ off)
                t = oracle.test(dr + 0.1 * off / np.linalg.norm(off))
                assert not t.member and t.reason == "direction is outside the motion space"
    assert compared > 20


# --------------------------------------------------------------------------------------------
# dafc_nonempty against dense sampling


def _cone_samples(ms_dirs: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
    """Random non-negative combinations of the cone's generators (plus the generators)."""
    out = [ms_dirs]
    for _ in range(n):
        v = rng.random(len(ms_dirs)) ** 3 @ ms_dirs
        if np.linalg.norm(v) > 1e-9:
            out.append(v[None, :] / np.linalg.norm(v))
    return np.vstack(out)


@pytest.mark.parametrize("name", ["planar_disk_envelope", "sphere_four_finger_palm"])
def test_nonempty_agrees_with_sampling_without_s_points(name: str) -> None:
    """Without S-points DAFC = A_r minus a closed convex cone, so dafc_nonempty is exact: empty
    iff no sampled direction is a member, and otherwise dim DAFC = dim A_r = the rank of the
    sampled members."""
    system = example_system(name)
    rng = np.random.default_rng(8)
    nonempty = empty = 0
    for c in all_combinations(system):
        if "S" in c:
            continue
        p = parts_of(name, c)
        if p.ms.a_bar == 0:
            continue
        oracle = p.oracle()
        best, dim, exact = dafc_nonempty(oracle)
        assert exact
        gen = allowable_cone(p.ms).all_directions()
        U = _cone_samples(gen, rng, 40)
        member_u = [t.u for t in (oracle.test(p.ms.Lambda_r_t @ u) for u in U) if t.member]
        ds = dafc_set(oracle, samples=24, refine=0)
        assert ds.exact
        if best is None:
            empty += 1
            assert not member_u and ds.empty and dim == 0 and ds.dim == 0
        else:
            nonempty += 1
            assert best.member
            assert dim == int(np.linalg.matrix_rank(np.array(member_u), tol=1e-6))
            assert dim == int(np.linalg.matrix_rank(gen, tol=1e-9)) == ds.dim
    assert nonempty >= 2 and empty >= 2


def test_nonempty_emptiness_certificate_with_s_points() -> None:
    """With S-points, an 'empty, exact' answer comes from the relaxation (any friction
    direction) and must hold for every sampled direction."""
    name = "planar_disk_envelope"
    certified = 0
    for c in [c for c in all_combinations(example_system(name)) if "S" in c]:
        p = parts_of(name, c)
        if p.ms.a_bar == 0:
            continue
        best, dim, exact = dafc_nonempty(p.oracle())
        if best is None and exact:
            certified += 1
            ds = dafc_set(p.oracle(), samples=24, refine=0)
            assert ds.empty
        elif best is not None:
            assert best.member and dim >= 1
    assert certified >= 3


def test_semantics_are_stated() -> None:
    for key in ("dafc_unknowns", "dafc_scale", "dafc_redundancy", "s_point", "d_point", "n_point"):
        assert SEMANTICS[key]


@pytest.mark.xfail(strict=True, reason="eq. (22) identifies wrenches with twists (Xi^T w = 0 in the coordinates "
                   "of p_o): membership depends on the choice of the object frame origin p_o")
def test_membership_does_not_depend_on_the_object_frame_origin() -> None:
    """The same block, weight and push, with the object frame origin p_o (where wrenches and
    twists are expressed) at the centre of mass, at the bottom centre, or elsewhere: a physical
    motion is either realisable or not. Pushed at h = 0.45 with mu = 1 (mu h > c), sliding is
    in DAFC with p_o at the centre of mass (work 17) but not with p_o on the table (work -1/9)."""
    answers = []
    for p_o in ((0.0, BOX_B), (0.0, 0.0), (0.3, 0.2)):
        system = build_system(box_scene(0.45, 1.0, p_o=p_o))
        oracle = CombinationParts.build(system, "SSN").oracle()
        answers.append(oracle.test(np.array([1.0, 0.0, 0.0])).member)  # pure translation: same twist
    assert answers[0] == answers[1] == answers[2]


@pytest.mark.parametrize("name", ["planar_disk_envelope", "sphere_four_finger_palm"])
def test_exact_description_agrees_with_the_oracle(name):
    """Without S-points, DAFC = A_r minus the cone where no admissible force does work: the
    exact description must give the oracle's answer on random allowable directions."""
    from analysis.dafc import allowable_cone, dafc_exact

    system = example_system(name)
    rng = np.random.default_rng(11)
    combos = [c for c in all_combinations(system) if "S" not in c]
    checked = 0
    for c in rng.choice(combos, size=min(25, len(combos)), replace=False):
        parts = CombinationParts.build(system, str(c))
        if parts.ms.a_bar == 0:
            continue
        oracle = parts.oracle()
        exact = dafc_exact(oracle)
        if exact is None:
            continue
        dirs = allowable_cone(parts.ms).all_directions()
        if dirs.shape[0] == 0:
            continue
        for _ in range(10):
            u = rng.random(len(dirs)) @ dirs  # a direction of A_r
            if np.linalg.norm(u) < 1e-9:
                continue
            dr = parts.ms.Lambda_r_t @ u
            assert exact.contains(dr) == oracle.test(dr).member, (c, dr)
            checked += 1
    assert checked >= 30


def test_redundancy_search_does_not_depend_on_earlier_directions() -> None:
    """The friction-aligned redundancy LP is one model per oracle whose right-hand side changes
    per direction (solved cold): testing seeded directions of wrap combinations whose slips
    depend on the redundancy in one order and in the reverse order, each with a fresh oracle,
    gives the same answers (membership, work to 1e-9 relative, motion to 1e-9)."""
    rng = np.random.default_rng(11)
    checked = 0
    for c in ("FSDFSDDDF", "SSFDSDFSD", "FSSFDDSSF", "SDSDSFSFS"):
        p = parts_of("sphere_four_finger_wrap", c)
        if p.ms.a_bar == 0 or not p.oracle().slip_depends_on_redundancy:
            continue
        U = rng.standard_normal((6, p.ms.a_bar))
        dirs = [p.ms.Lambda_r_t @ (u / np.linalg.norm(u)) for u in U]
        forward = [p.oracle().test(d, screen=False, quick=False, witness=False) for d in dirs]
        o = p.oracle()
        backward = [o.test(d, screen=False, quick=False, witness=False) for d in dirs[::-1]][::-1]
        o2 = p.oracle()
        again = [o2.test(d, screen=False, quick=False, witness=False) for d in dirs]
        for a, b, e in zip(forward, backward, again, strict=True):
            for x in (b, e):
                assert a.member == x.member and a.reason == x.reason
                if np.isfinite(a.work):
                    assert abs(a.work - x.work) <= 1e-9 * max(1.0, abs(a.work))
                if a.zeta_c is not None:
                    assert x.zeta_c is not None
                    np.testing.assert_allclose(a.zeta_c, x.zeta_c, rtol=0, atol=1e-9)
        checked += 1
    assert checked >= 2


def _random_member(oracle: DAFCOracle, rng: np.random.Generator, draws: int) -> bool:
    """Is one of ``draws`` seeded motions (a random direction of the allowable cone, a random
    allowable redundancy at a random scale) a member for the exact oracle?"""
    ms = oracle.ms
    gen = allowable_cone(ms)
    R, L = gen.rays, gen.lines
    for _ in range(draws):
        u = (rng.random(len(R)) @ R if len(R) else np.zeros(ms.a_bar)) + (
            rng.standard_normal(len(L)) @ L if len(L) else np.zeros(ms.a_bar))
        if np.linalg.norm(u) < 1e-9:
            continue
        u /= np.linalg.norm(u)
        z0 = oracle.redundancy_for(u)
        if z0 is None:
            continue
        z = z0 + rng.choice([0.0, 0.1, 1.0, 10.0]) * rng.standard_normal(ms.n_redundant)
        if oracle.test(ms.Lambda_r_t @ u, zeta_r=z, screen=False, witness=False).member:
            return True
    return False


def test_slip_sector_search_is_complete_in_2d() -> None:
    """Issue 9: in 2-D the slip-sector search decides every S-combination of the planar example
    (no box left open), and agrees with a seeded random search of 150 motions per combination:
    where the random search finds a member so does the sector search, and where the sector search
    proves emptiness the random search finds none."""
    system = example_system("planar_disk_envelope")
    rng = np.random.default_rng(9)
    checked = 0
    for c in all_combinations(system):
        if "S" not in c:
            continue
        parts = CombinationParts.build(system, c)
        if parts.ms.a_bar == 0 or summarize(parts).reason.startswith("no stationary"):
            continue
        found = slip_sector_search(parts.oracle())
        assert found.decided, f"{c}: {found.open_boxes} boxes open"
        sampled = _random_member(parts.oracle(), rng, 150)
        assert not sampled or found.test is not None, f"{c}: the random search finds a member, the sector search none"
        if found.test is not None:
            zc = found.test.zeta_c
            assert found.test.member and zc is not None
            again = parts.oracle()
            assert again.certify(again.test(found.test.direction, zeta_r=zc[parts.ms.a_bar:], screen=False)), c
        checked += 1
    assert checked > 20


def test_slip_sector_bounds_reused_from_certified_optima_match_scipy() -> None:
    """Issue 9 (speed): a slip-sector box's bound for a direction may come from an earlier optimum
    of the same box's LP, certified the unique maximiser by non-negative multipliers
    (``_box_vertex``). On boxes of a 3-D wrap combination and seeded directions, every bound equals
    scipy's LP optimum, every certified point is scipy's maximiser (uniqueness), and the reuse
    does happen."""
    from scipy.optimize import linprog

    from analysis.dafc import _box_vertex, _relaxed_box_lp, _relaxed_box_model, split_sector

    system = example_system("sphere_four_finger_wrap")
    oracle = _oracle(system, "SFFFSSDFS")
    ms, sc = oracle.ms, system.scales
    nS = len(oracle.sel.s_index)
    dep = list(range(nS))
    quarters = split_sector(None, 3)
    boxes = [tuple(None for _ in dep), tuple(quarters[k % 4] for k in dep),
             tuple(split_sector(quarters[1], 3)[0] if k == 0 else quarters[(k + 2) % 4] for k in dep)]
    rng = np.random.default_rng(4)
    certified = 0
    for box in boxes:
        model, G, _ = _relaxed_box_model(oracle, oracle.st.G_c, dep, box)
        bounds = list(zip(np.where(np.isfinite(model.lb), model.lb, -np.inf),
                          np.where(np.isfinite(model.ub), model.ub, np.inf), strict=True))
        bounds = [(None if np.isinf(lo) else lo, None if np.isinf(up) else up) for lo, up in bounds]
        store: dict[str, object] = {}
        # a few directions near each other (the search's generators of one box) and random ones
        base = rng.normal(size=ms.a_bar)
        for k in range(30):
            u = base + (0.05 if k % 2 else 1.0) * rng.normal(size=ms.a_bar)
            dr = ms.Lambda_r_t @ (u / np.linalg.norm(u))
            c = G.T @ dr
            x_known = _box_vertex(store, c)
            ref = linprog(-c, A_ub=model.A_ub, b_ub=model.b_ub, A_eq=model.A_eq, b_eq=model.b_eq, bounds=bounds,
                          method="highs")
            assert ref.status == 0
            ref_bound = -ref.fun * sc.force + dr @ system.w_ex
            if x_known is not None:
                certified += 1
                assert float(c @ x_known) == pytest.approx(-ref.fun, abs=1e-7 * max(1.0, abs(ref.fun)))
                np.testing.assert_allclose(x_known, ref.x, atol=1e-6)
            bound, _ = _relaxed_box_lp(oracle, dr, oracle.st.G_c, dep, box, store)
            assert bound == pytest.approx(ref_bound, abs=1e-7 * sc.force * max(1.0, abs(ref_bound) / sc.force))
    assert certified > 5 and oracle.box_vertex_hits > 5


def test_a_free_s_points_relaxed_friction_is_the_polygon_circumscribing_its_disc() -> None:
    """Known gap 8 (fixed): the sector search's root box bounds a free S-point's friction by the
    k-gon whose sides touch the friction circle |t| = mu n (unit side normals c_j, c_j^T t <= mu n),
    not by one 1/cos(pi/k) larger. Every point of the circle is inside, and each side touches it."""
    from analysis.dafc import _relaxed_box_model

    system = example_system("sphere_four_finger_wrap")
    oracle = _oracle(system, "SFFFSSDFS")
    dep = list(range(len(oracle.sel.s_index)))
    model, _, slots = _relaxed_box_model(oracle, oracle.st.G_c, dep, tuple(None for _ in dep))
    for k, cols in enumerate(slots):
        i = oracle.sel.s_index[k]
        n_col, mu = oracle.sel.c_slices[i].start, float(system.mu[i])
        rows = model.A_ub[np.flatnonzero(np.abs(model.A_ub[:, list(cols)]).sum(axis=1) > 0)]
        C = rows[:, list(cols)]  # (k, 2) side normals in tangent coordinates
        assert len(C) == 8
        np.testing.assert_allclose(np.linalg.norm(C, axis=1), 1.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rows[:, n_col], -mu, rtol=0, atol=1e-15)  # c_j^T t <= mu n
        circle = mu * np.array([[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 721)])  # n = 1
        assert np.max(circle @ C.T) <= mu + 1e-12  # the disc is inside
        np.testing.assert_allclose(np.max((mu * C) @ C.T, axis=1), mu, rtol=0, atol=1e-12)  # each side touches it


def _cone_motions(oracle: DAFCOracle, box: tuple, draws: int, rng: np.random.Generator) -> np.ndarray:
    """Motions ``dzeta_c`` of a sector box's cone (``B dzeta_c <= 0``, every S-point's slip in its
    sector), found without cdd: maximisers of seeded random objectives over the cone cut by the
    cube ``|dzeta_c|_inf <= 1`` (scipy), and random convex combinations of them. ``(n, a)``."""
    from scipy.optimize import linprog

    from analysis.dafc import sector_rows

    sy, ms = oracle.system, oracle.ms
    d = sy.d
    rows = [oracle.B] if oracle.B.shape[0] else []
    for k, sec in enumerate(box):
        R, _ = sector_rows(sec, d, 0.0)
        if R.shape[0]:
            rows.append(-(R @ sy.tangents[oracle.sel.s_index[k]] @ oracle.Ps[k * d:(k + 1) * d]))
    A = np.vstack(rows) if rows else np.zeros((0, ms.a))
    pts = []
    for _ in range(draws):
        res = linprog(-rng.standard_normal(ms.a), A_ub=A if A.size else None, b_ub=np.zeros(len(A)) if A.size else None,
                      bounds=[(-1.0, 1.0)] * ms.a, method="highs")
        assert res.status == 0
        pts.append(res.x)
    P = np.array(pts)
    mix = rng.dirichlet(np.ones(len(P)) * 0.3, size=draws) @ P
    return np.vstack([P, mix])


@pytest.mark.parametrize("combination", ["FFDDDDDDS", "DDDSFFFSS", "SFDSSSFFS", "DSFFDSDDS"])
def test_tightened_sectors_hold_every_sliding_motion_of_the_box(combination: str) -> None:
    """Issue 9 (speed): the slip-sector search narrows a box's sectors to the slips its cone really
    has, and drops a box in which some S-point cannot slide (``_tighten``). On the root box, its
    quarter turns and seeded nested boxes of four wrap combinations: every motion of the box's cone
    (found by scipy LPs, without cdd) whose S-points slide has each slip inside the narrowed
    sector; where the box is dropped, no motion of its cone makes some S-point slide (the largest
    slip component over the cone cut by the unit cube, scipy, is at rounding level)."""
    from scipy.optimize import linprog

    from analysis.dafc import SLIP_TOL, _box_cone, _slip_maps, _tighten, sector_rows, split_sector

    system = example_system("sphere_four_finger_wrap")
    oracle = _oracle(system, combination)
    sy, ms = oracle.system, oracle.ms
    d, nS = sy.d, len(oracle.sel.s_index)
    P, S = _slip_maps(oracle)
    rng = np.random.default_rng(11)
    boxes: list[tuple] = [tuple(None for _ in range(nS))]
    for _ in range(10):  # nested boxes: split a random point of a random box, a few times
        box = boxes[int(rng.integers(len(boxes)))]
        k = int(rng.integers(nS))
        boxes.append((*box[:k], split_sector(box[k], d)[int(rng.integers(2))], *box[k + 1:]))
    boxes += [tuple(split_sector(None, d)[q] if k == 0 else None for k in range(nS)) for q in range(4)]
    dropped = narrowed = 0
    for box in boxes:
        Z = _box_cone(oracle, box)
        tight = _tighten(P, S, box, Z)
        if tight is None:
            dropped += 1
            rows = [oracle.B] if oracle.B.shape[0] else []
            for k, sec in enumerate(box):
                R, _ = sector_rows(sec, d, 0.0)
                if R.shape[0]:
                    rows.append(-(R @ S[k]))
            A = np.vstack(rows)
            stuck = []
            for k in range(nS):  # the largest |slip component| of point k over the cone in the cube
                top = 0.0
                for j in range(d):
                    for sign in (1.0, -1.0):
                        res = linprog(-sign * P[k][j], A_ub=A, b_ub=np.zeros(len(A)), bounds=[(-1.0, 1.0)] * ms.a,
                                      method="highs")
                        assert res.status == 0
                        top = max(top, -res.fun)
                stuck.append(top <= SLIP_TOL)
            assert any(stuck), (combination, box)
            continue
        narrowed += sum(t != b for t, b in zip(tight, box, strict=True))
        for zc in _cone_motions(oracle, box, 12, rng):
            n = float(np.linalg.norm(zc))
            for k, sec in enumerate(tight):
                sig = S[k] @ zc  # (2,) tangent slip
                if sec is None or np.linalg.norm(P[k] @ zc) <= SLIP_TOL * n:
                    continue
                a, b = sec
                theta = np.arctan2(sig[1], sig[0])
                phi = np.mod(theta - 0.5 * (a + b) + np.pi, 2 * np.pi) - np.pi  # from the bisector
                assert abs(phi) <= 0.5 * (b - a) + 1e-9, (combination, box, k, theta, sec)
    assert narrowed > 0
    if combination == "FFDDDDDDS":  # the palm's slip is one line of the object motions: boxes off it go
        assert dropped > 0


def test_slip_sector_search_finds_members_next_to_a_generator_that_does_not_slide() -> None:
    """Issue 9: in the wrap's FFDSDDDDS (a~ = 2) the palm's slip is one line of the object motions,
    so the generator of a box's cone with the largest bound has a palm that does not slide; a motion
    a step inside the cone with the relaxed maximiser's friction targets is a member (the search
    left this combination "not proven" before). The member is certified in newtons, and the
    independent scipy LP (tests/helpers/independent_dafc.py) agrees it is one."""
    import json

    from closure_helpers import EXAMPLES
    from independent_dafc import check_member

    system = example_system("sphere_four_finger_wrap")
    parts = CombinationParts.build(system, "FFDSDDDDS")
    oracle = parts.oracle()
    found = slip_sector_search(oracle)
    assert found.test is not None and found.test.member and oracle.certify(found.test)
    assert found.test.zeta_c is not None
    motion = parts.ms.Phi_full @ found.test.zeta_c  # (M + D,)
    data = json.loads((EXAMPLES / "sphere_four_finger_wrap.json").read_text())
    chk = check_member(data, "FFDSDDDDS", motion[:system.M], motion[system.M:])
    assert chk.member, (chk.motion_errors, chk.work, chk.work_min)
    assert chk.work == pytest.approx(found.test.work, rel=1e-6, abs=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("combination", ["DDDSFFFSS", "FFDDDDDDS", "SFFFDSSFS"])
def test_slip_sector_search_proves_emptiness_an_independent_search_agrees(combination: str) -> None:
    """Issue 9: wrap combinations the slip-sector search left "not proven" before its sectors were
    narrowed to their cones' slips (``_tighten``) are now decided empty (no box open); seeded
    allowable motions of the combination, built from the independent kinematics
    (tests/helpers/independent_dafc.py, scipy null space, D-points not penetrating), are never a
    member for the independent scipy LP."""
    import json

    from closure_helpers import EXAMPLES
    from independent_dafc import _skew, check_member, contact_jacobians
    from scipy.linalg import null_space

    system = example_system("sphere_four_finger_wrap")
    found = slip_sector_search(_oracle(system, combination))
    assert found.test is None and found.decided
    data = json.loads((EXAMPLES / "sphere_four_finger_wrap.json").read_text())
    Js = contact_jacobians(data)
    M = Js[0].shape[1]
    p_o = np.asarray(data["object"]["pose"]["position"], float)
    rows, d_rows = [], []
    for i, s in enumerate(combination):
        c = data["contacts"][i]
        n = np.asarray(c["normal"], float) / np.linalg.norm(c["normal"])
        A = np.hstack([Js[i], -np.vstack([np.eye(3), _skew(np.asarray(c["point"], float) - p_o)]).T])  # (3, M + 6)
        if s == "F":
            rows.extend(A)
        elif s == "S":
            rows.append(n @ A)
        else:
            d_rows.append(n @ A)
    N = null_space(np.array(rows))  # (M + 6, k)
    rng = np.random.default_rng(5)
    tried = 0
    for _ in range(600):
        x = N @ rng.standard_normal(N.shape[1])
        if np.any(np.array(d_rows) @ x > 0) or np.linalg.norm(x[M:]) < 1e-6 * np.linalg.norm(x):
            continue
        x /= np.linalg.norm(x)
        chk = check_member(data, combination, x[:M], x[M:])
        assert not chk.member, (combination, chk.work, chk.work_min)
        tried += 1
    assert tried > 20


_BATCH_PLANAR = ("DFDSS", "SSDSS", "SFSDD", "DFSDD", "FSSDD", "FFFSS", "DFFFS", "SDFFF", "FFFFF", "FDFFF", "DDSDS")


def _one_by_one_and_batched(system: GraspSystem, combination: str) -> tuple[list[DirectionTest], list[DirectionTest]]:
    """The sampled directions of ``dafc_set`` tested one at a time and with ``test_many``, each on a
    fresh oracle that has run ``dafc_nonempty`` first (as in a report)."""
    from analysis.dafc import default_samples, sample_directions

    parts = CombinationParts.build(system, combination)
    U = sample_directions(parts.ms, default_samples(parts.ms.a_bar))
    one = parts.oracle()
    dafc_nonempty(one)
    batch = parts.oracle()
    dafc_nonempty(batch)
    return ([one.test(parts.ms.Lambda_r_t @ u, witness=False) for u in U], batch.test_many(U))


@pytest.mark.parametrize("scene, combinations", [
    ("planar_disk_envelope",
     _BATCH_PLANAR + tuple(sample_combinations(example_system("planar_disk_envelope"), 20, 13))),
    ("sphere_four_finger_palm", ("FFSDF", "DSFFS", "FFDFF", "DFDDF")),
])
def test_test_many_answers_as_one_direction_at_a_time(scene: str, combinations: tuple[str, ...]) -> None:
    """Issue 13: ``DAFCOracle.test_many`` (the sampled directions decided together: the screen, the
    allowability, the slip patterns and the certified vertices for all rows at once, an LP only for
    the first open row) answers every direction as ``test`` does alone: the same membership, reason
    and exactness, the same direction and coordinates bit for bit, the work and motion to 1e-9.
    Planar combinations with and without S-points, with slips that depend on the redundancy
    (DFDSS, tested one by one inside), a~ = 3 (DFSDD); 3-D ones without S-points (a~ = 6, where
    the force LP's optima rarely recur) and with (one by one inside)."""
    system = example_system(scene)
    for combination in combinations:
        if CombinationParts.build(system, combination).ms.a_bar == 0:
            continue
        one, batch = _one_by_one_and_batched(system, combination)
        assert len(one) == len(batch)
        for a, b in zip(one, batch, strict=True):
            assert (a.member, a.reason, a.exact) == (b.member, b.reason, b.exact), combination
            assert np.array_equal(a.direction, b.direction) and np.array_equal(a.u, b.u), combination
            np.testing.assert_allclose(b.work, a.work, rtol=1e-9, atol=1e-9)
            assert (a.zeta_c is None) == (b.zeta_c is None)
            if a.zeta_c is not None and b.zeta_c is not None:
                np.testing.assert_allclose(b.zeta_c, a.zeta_c, rtol=0, atol=1e-12)


def test_test_many_verdicts_agree_with_an_independent_lp() -> None:
    """Issue 13: every seventh sampled direction that ``test_many`` decides with a motion (a member,
    or no positive work) strictly inside the allowable cone, in planar combinations with S-points
    whose slips do not depend on the redundancy and without S-points: the independent scipy LP of
    that motion
    (tests/helpers/independent_dafc.py: its own kinematics, friction cones and S-point friction)
    finds the motion admissible and gives the same verdict and the same work (1e-6)."""
    import json

    from closure_helpers import EXAMPLES
    from independent_dafc import check_member_planar

    from analysis.dafc import default_samples, sample_directions

    system = example_system("planar_disk_envelope")
    data = json.loads((EXAMPLES / "planar_disk_envelope.json").read_text())
    checked = {True: 0, False: 0}
    for combination in ("SSSDS", "SDDFS", "DFSSS", "SSSDD", "FSSDD", "SFSDD", "FDDDD", "DDFDD", "FFFFF"):
        parts = CombinationParts.build(system, combination)
        if parts.ms.a_bar == 0:
            continue
        oracle = parts.oracle()
        assert not oracle.slip_depends_on_redundancy
        tests = oracle.test_many(sample_directions(parts.ms, default_samples(parts.ms.a_bar)))
        for t in tests[::7]:
            if t.zeta_c is None or not (t.member or t.reason == "the fingers cannot do positive work"):
                continue
            if oracle.B.shape[0] and float(np.max(oracle.B @ t.zeta_c)) > -1e-6 * np.linalg.norm(t.zeta_c):
                continue  # on a face of the allowable cone (allowed to 1e-7, the independent check says 1e-9)
            motion = parts.ms.Phi_full @ t.zeta_c  # (M + D,)
            chk = check_member_planar(data, combination, motion[:system.M], motion[system.M:])
            assert not chk.motion_errors, (combination, chk.motion_errors)
            assert chk.member == t.member, (combination, t.u, chk.work, t.work)
            if np.isfinite(t.work):
                assert chk.work == pytest.approx(t.work, rel=1e-6, abs=1e-9)
            else:
                assert chk.work == -np.inf
            checked[t.member] += 1
    assert checked[True] >= 10 and checked[False] >= 10, checked


def test_table_decides_exact_one_direction_rows_without_the_relaxed_screen() -> None:
    """The table (``dafc_nonempty(..., realisable=False)``) decides a combination with S-points whose
    slips do not depend on the redundancy and whose object moves along one line (``a~ = 1``) by the
    force LPs at its (at most two) generators alone, without the relaxed screen's LP: the same
    verdict, dimension and exactness as the screened report path, the same membership at each
    generator, and the independent scipy LP (tests/helpers/independent_dafc.py) agrees at each
    generator's motion (a member where the table's test says so, none where it does not)."""
    import json

    from closure_helpers import EXAMPLES
    from independent_dafc import check_member

    system = example_system("sphere_four_finger_wrap")
    data = json.loads((EXAMPLES / "sphere_four_finger_wrap.json").read_text())
    rng = np.random.default_rng(17)
    members = non_members = rows = 0
    for _ in range(3000):
        c = "".join(rng.choice(list("FSD"), system.L))
        parts = CombinationParts.build(system, c)
        oracle = parts.oracle()
        if not oracle.sel.s_index or not oracle.exact or parts.ms.a_bar != 1:
            continue
        rows += 1
        table = dafc_nonempty(oracle, realisable=False)
        report = dafc_nonempty(parts.oracle(), realisable=True)
        assert (table[0] is None, table[1], table[2]) == (report[0] is None, report[1], report[2]), c
        ms = parts.ms
        for u in allowable_cone(ms).all_directions():
            u = u / np.linalg.norm(u)
            bare = oracle.test(ms.Lambda_r_t @ u, screen=False, witness=False)
            screened = parts.oracle().test(ms.Lambda_r_t @ u, screen=True, witness=False)
            assert bare.member == screened.member, (c, u)
            if bare.zeta_c is None:
                continue  # not allowable: no motion of the combination has this direction
            motion = ms.Phi_full @ bare.zeta_c  # (M + D,) the motion the force LP was solved at
            chk = check_member(data, c, motion[:system.M], motion[system.M:])
            # the kinematics hold (a D-point whose row vanishes on the motion space may move by the
            # product's allowability tolerance), and the independent force LP agrees on the work
            size = float(np.linalg.norm(motion))
            assert all("(D) penetrates" in e and float(e.rsplit(": ", 1)[1]) <= ALLOW_TOL * size
                       for e in chk.motion_errors), (c, chk.motion_errors)
            assert (chk.work > chk.work_min) == bare.member, (c, u, chk.work, chk.work_min, bare.reason)
            members += bare.member
            non_members += not bare.member
        if rows >= 16:
            break
    assert rows >= 16 and members > 0 and non_members > 0, (rows, members, non_members)
