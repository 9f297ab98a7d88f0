"""Enumeration of every contact-state combination; its pruning must not change any answer."""

from __future__ import annotations

import itertools
import json
from typing import Any

import numpy as np
import pytest
from closure_helpers import EXAMPLES, Array, example_system, sample_combinations
from independent_dafc import check_member, check_member_planar, contact_jacobians, planar_jacobians
from scipy.linalg import null_space

from analysis.combination import CombinationParts, CombinationSummary, summarize, summarize_with_member
from analysis.contacts import all_combinations
from analysis.dafc_family import FamilyKinematics, MemberCertificate, members_at
from analysis.enumerate import _order, enumerate_combinations


def _same(a: CombinationSummary, b: CombinationSummary) -> None:
    """Same verdict, reason, dimensions and exactness (the example directions may differ: both are
    members, see :func:`_certified`)."""
    assert (a.combination, a.feasible, a.reason, a.a, a.a_bar, a.dim_dafc, a.dim_dpfc, a.exact) == (
        b.combination, b.feasible, b.reason, b.a, b.a_bar, b.dim_dafc, b.dim_dpfc, b.exact)
    assert (a.example_direction is None) == (b.example_direction is None)


def _certified(parts: CombinationParts, s: CombinationSummary) -> None:
    """The row's example motion is a motion of its own combination, realises its example
    direction, and the combination's own oracle finds it a member with a certificate in newtons."""
    ms = parts.ms
    assert s.example_direction is not None and s.example_motion is not None
    m = s.example_motion  # (M + D,)
    np.testing.assert_allclose(m[ms.M:], s.example_direction, rtol=0, atol=1e-9)
    zeta, *_ = np.linalg.lstsq(ms.Phi_full, m, rcond=None)  # its coordinates in this motion space
    assert np.linalg.norm(ms.Phi_full @ zeta - m) <= 1e-9 * np.linalg.norm(m)
    oracle = parts.oracle()
    t = oracle.test(s.example_direction, zeta_r=zeta[ms.a_bar:], screen=False)
    assert t.member and oracle.certify(t), (s.combination, t.reason)


@pytest.mark.parametrize("name", ["planar_disk_envelope", "sphere_four_finger_palm"])
def test_pruning_is_exact(name: str) -> None:
    """Every one of the 243 combinations: the staged enumeration (motion dimensions in batches,
    stationary monotonicity, DAFC members shared along families) gives summarize()'s verdict,
    reason, dimensions and exactness for that combination alone; the member behind each
    feasible row, wherever it was found, is certified for that row."""
    system = example_system(name)
    pruned, stats = enumerate_combinations(system, workers=1)
    canonical = ["".join(p) for p in itertools.product(*["FSD" if m > 0 else "ND" for m in system.mu])]
    assert [s.combination for s in pruned] == canonical == all_combinations(system)
    assert len(pruned) == 3**system.L == stats.combinations
    assert stats.pruned_stationary > 0  # the pruning was exercised
    assert stats.dafc_shared > 0 and stats.dafc_searched > 0  # both ways of deciding DAFC
    assert stats.dafc_lps > 0 and stats.stationary_lps > 0  # both kinds of LP are counted
    for s in pruned:
        parts = CombinationParts.build(system, s.combination)
        _same(s, summarize(parts))
        if s.feasible:
            _certified(parts, s)


@pytest.mark.parametrize(("name", "symmetric_empty"), [("sphere_four_finger_palm", False),
                                                     ("planar_disk_envelope", False),
                                                     ("planar_disk_envelope", True)])
def test_the_table_does_not_depend_on_the_number_of_workers(name: str, symmetric_empty: bool) -> None:
    """Own DAFC searches run ahead in worker processes (speculatively: the rows sent straight to
    their search, those the probes leave, the orbit of a row found empty), but are committed
    strongest first: the table (example directions included) and the counts of searches and LPs
    are the one-process ones. The planar envelope has symmetric rows whose representative is
    empty (29 own searches, 8 rows decided at a symmetric row's member)."""
    system = example_system(name)
    one, st1 = enumerate_combinations(system, workers=1, symmetric_empty=symmetric_empty)
    two, st2 = enumerate_combinations(system, workers=2, symmetric_empty=symmetric_empty)
    assert st1 == st2
    for a, b in zip(one, two, strict=True):
        _same(a, b)
        if a.example_direction is not None:
            np.testing.assert_array_equal(a.example_direction, b.example_direction)


def test_planar_results() -> None:
    """All-F on the planar envelope grasp is passive closure: the object cannot move
    (a~ = 0), so not feasible; all-D cannot hold the disk against gravity."""
    system = example_system("planar_disk_envelope")
    result = {s.combination: s for s in enumerate_combinations(system, workers=1)[0]}
    assert not result["FFFFF"].feasible and result["FFFFF"].a_bar == 0
    assert result["FFFFF"].reason == "object cannot move (a~ = 0)"
    assert result["DDDDD"].reason == "no stationary grasp (18)"
    feasible = [c for c, s in result.items() if s.feasible]
    assert feasible
    for c in feasible:
        s = result[c]
        assert s.a_bar >= 1 and 1 <= s.dim_dafc <= s.a_bar and s.example_direction is not None
        assert np.linalg.norm(s.example_direction) == pytest.approx(1.0, abs=1e-9)
    # mirror symmetry of the scene (x -> -x swaps left and right fingers): the feasible set is
    # closed under swapping contacts 0 <-> 2 and 1 <-> 3
    mirrored = {c[2] + c[3] + c[0] + c[1] + c[4] for c in feasible}
    assert mirrored == set(feasible)


def test_subset_and_order_of_requested_combinations() -> None:
    """A requested list comes back in the requested order, whatever the evaluation order."""
    system = example_system("planar_disk_envelope")
    combos = sample_combinations(system, 20, seed=4)[::-1]
    out, stats = enumerate_combinations(system, combinations=combos, workers=1)
    assert [s.combination for s in out] == combos and stats.combinations == 20


def test_enumeration_raises_no_solver_error_on_the_allegro_scene() -> None:
    """Every combination of the Allegro scene (near-singular contact geometry) is decided; two
    of them (SFFDSF, SFSSFF) once ended in a HiGHS 'Solve error' under warm-started primal
    simplex."""
    system = example_system("allegro_right_box")
    out, _ = enumerate_combinations(system, workers=1)
    assert len(out) == 3**system.L
    assert any(s.feasible for s in out)


def _member_directions(data: dict[str, Any], combination: str, motion: Array, count: int, seed: int) -> Array:
    """Object directions of seeded small perturbations of ``motion`` inside the combination's
    motion space (scipy null space of its F/S/N rows) that keep every D-point from penetrating
    and are DAFC members by the independent LP (:mod:`independent_dafc`)."""
    planar = int(data["dim"]) == 2
    check = check_member_planar if planar else check_member
    Js = planar_jacobians(data) if planar else contact_jacobians(data)
    M = Js[0].shape[1]
    pts = np.array([c["point"] for c in data["contacts"]], float)
    nrm = np.array([c["normal"] for c in data["contacts"]], float)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    p_o = np.asarray(data["object"]["pose"]["position"], float)
    A = []
    for i, p in enumerate(pts):
        r = p - p_o
        G = (np.array([[1.0, 0.0], [0.0, 1.0], [-r[1], r[0]]]) if planar else
             np.vstack([np.eye(3), [[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]]]))
        A.append(np.hstack([Js[i], -G.T]))
    rows = [row for i, s in enumerate(combination) for row in
            (A[i] if s == "F" else [nrm[i] @ A[i]] if s in "SN" else [])]
    N = null_space(np.array(rows))  # (M + D, a)
    rng = np.random.default_rng(seed)
    size = float(np.linalg.norm(motion))
    out = []
    for _ in range(400):
        w = motion + 10.0 ** rng.uniform(-4, -2) * size * (N @ rng.standard_normal(N.shape[1]))
        if any(s == "D" and nrm[i] @ A[i] @ w > 1e-9 * np.linalg.norm(w) for i, s in enumerate(combination)):
            continue
        if check(data, combination, w[:M], w[M:]).member:
            out.append(w[M:] / np.linalg.norm(w[M:]))
            if len(out) == count:
                break
    return np.array(out)


@pytest.mark.parametrize(("name", "combination"), [
    ("planar_disk_envelope", "DDSDS"), ("sphere_four_finger_palm", "DDDFS"),
    ("sphere_four_finger_palm", "DDFFS"), ("sphere_four_finger_palm", "DSFDS")])
def test_dafc_has_the_dimension_of_its_allowable_cone(name: str, combination: str) -> None:
    """A member, wherever in A_r it was found, has a neighbourhood of members in A_r: these rows,
    whose members the search once found only on the boundary of A_r (reported with the rank of the
    members found, 1 to 3), have members spanning the whole motion space a~ by the independent LP
    (motion space, forces and work with scipy), as the table now reports."""
    system = example_system(name)
    row = next(s for s in enumerate_combinations(system, combinations=[combination], workers=1)[0])
    assert row.feasible and row.example_motion is not None and row.dim_dafc == row.a_bar
    data = json.loads((EXAMPLES / f"{name}.json").read_text())
    dirs = _member_directions(data, combination, row.example_motion, 3 * row.a_bar, seed=9)
    assert np.linalg.matrix_rank(dirs, tol=1e-7) == row.a_bar


@pytest.mark.parametrize(("name", "source"), [("planar_disk_envelope", "FSFSS"), ("sphere_four_finger_palm", "SFSFS"),
                                              ("sphere_four_finger_palm", "FSFSS")])
def test_batched_force_lps_agree_with_each_combinations_oracle(name: str, source: str) -> None:
    """The member motion of one combination is a motion of every combination that lets some of
    its contacts go; the force LPs of (22) of all of them at that motion, solved as one
    block-diagonal LP (members_at), give each one's own oracle answer at that motion, and each
    certificate passes the family re-check for its own combination."""
    system = example_system(name)
    parts = CombinationParts.build(system, source)
    _, member = summarize_with_member(parts, stationary_known=True, realisable=False)
    assert member is not None and member.zeta_c is not None
    cert = MemberCertificate.of(parts, member)
    assert cert is not None
    rows = list(cert.below())
    kin = FamilyKinematics(system)
    found = members_at(kin, [(c, cert.motion) for c in rows])
    both = 0
    for c, got in zip(rows, found, strict=True):
        p = CombinationParts.build(system, c)
        zeta, *_ = np.linalg.lstsq(p.ms.Phi_full, cert.motion, rcond=None)
        t = p.oracle().test(cert.motion[system.M:], zeta_r=zeta[p.ms.a_bar:], screen=False)
        assert (got is not None) == t.member, (c, t.reason)
        if got is not None:
            both += 1
            assert got.check(kin, list(got.family(system))).all() if list(got.family(system)) else True
    assert both > 0 and both < len(rows)  # members and non-members among them


def test_order_is_strongest_first_and_stable() -> None:
    """``_order`` (letters read as bytes) is the stable sort by the sum of the classes, strongest
    first, also for N letters and for rows of different lengths (the letter-by-letter path)."""
    rng = np.random.default_rng(3)
    rows = ["".join(rng.choice(list("FSND"), size=6)) for _ in range(500)]
    want = sorted(rows, key=lambda c: -sum({"F": 2, "S": 1, "N": 1, "D": 0}[s] for s in c))
    assert _order(rows) == want
    assert _order(["D", "FS", "SS", "F"]) == ["FS", "SS", "F", "D"]
    assert _order([]) == []
