"""Symmetries of a grasp (analysis.symmetry) and the enumeration's use of them: member motions
carried to the symmetric combinations, certified there; the shared rows' dimensions decided in
batches (FamilyKinematics.separates, slip_depends) as one by one."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from closure_helpers import EXAMPLES, example_system, sample_combinations
from independent_dafc import check_member

import analysis.enumerate as enumerate_module
from analysis.combination import CombinationParts, summarize_with_member
from analysis.contacts import system_from_arrays
from analysis.dafc_family import FamilyKinematics, members_at, slip_depends_on_redundancy
from analysis.enumerate import enumerate_combinations, parse_where
from analysis.symmetry import Symmetry, symmetries, twist_map

#: test_emptiness_carried_on_the_twelve_contact_wrap: the rows with at least this many D-points
WHERE_D12 = 6


@pytest.mark.parametrize(("name", "count"), [("sphere_four_finger_wrap", 7), ("sphere_four_finger_palm", 7),
                                             ("planar_disk_envelope", 1), ("allegro_right_box", 0)])
def test_symmetries_map_the_contact_kinematics(name: str, count: int) -> None:
    """The four fingers 90 degrees apart give the rotations by 90, 180, 270 degrees and four
    reflections; the planar envelope its mirror; the Allegro hand none. Each map turns every
    contact's point, normal and rows of A = [J, -G^T] (eq. 2) into those of its image, fixes the
    weight, and the maps with the identity form a group."""
    sy = example_system(name)
    gs = symmetries(sy)
    assert len(gs) == count
    n = sy.M + sy.D
    for g in gs:
        R = g.R
        np.testing.assert_allclose(R.T @ R, np.eye(sy.d), atol=1e-9)
        np.testing.assert_allclose(g.T.T @ g.T, np.eye(n), atol=1e-9)  # a signed permutation and T_r
        np.testing.assert_allclose(g.T[sy.M:, sy.M:], twist_map(R), atol=1e-12)
        np.testing.assert_allclose((sy.points - sy.p_o) @ R.T, sy.points[g.perm] - sy.p_o, atol=1e-8)
        np.testing.assert_allclose(sy.normals @ R.T, sy.normals[g.perm], atol=1e-8)
        np.testing.assert_allclose(twist_map(R) @ sy.w_ex, sy.w_ex, atol=1e-12)
        for i in range(sy.L):
            np.testing.assert_allclose(sy.contact_A(int(g.perm[i])) @ g.T, R @ sy.contact_A(i), atol=1e-8)
    # closed under composition: the image of the image is an image (or the identity)
    group = [(np.arange(sy.L), np.eye(n))] + [(g.perm, g.T) for g in gs]
    for (p1, T1), (p2, T2) in itertools.product(group, repeat=2):
        p, T = p2[p1], T2 @ T1
        assert any(np.array_equal(p, q) and np.allclose(T, U, atol=1e-9) for q, U in group)


def test_symmetry_maps_letters_onto_the_image_contacts() -> None:
    g = Symmetry(np.array([2, 0, 1]), np.eye(3), np.eye(6))
    assert g.combination("FSD") == "SDF"  # contact 0 (F) on 2, 1 (S) on 0, 2 (D) on 1


@pytest.mark.parametrize("source", ["DDDDDSFFS", "DSFFDSDDS", "FFDSDDDSS"])
def test_image_of_a_member_is_a_member_of_the_image(source: str) -> None:
    """Wrap rows whose members only the slip-sector search found: the image of the member motion
    under each of the seven maps is certified for the image combination by the force LPs of
    (22) (members_at), and the independent scipy LP (its own Jacobians, null spaces and pyramids)
    finds it a member too."""
    sy = example_system("sphere_four_finger_wrap")
    data = json.loads((EXAMPLES / "sphere_four_finger_wrap.json").read_text())
    summary, _ = summarize_with_member(CombinationParts.build(sy, source), stationary_known=True,
                                       realisable=False)
    assert summary.feasible and summary.example_motion is not None
    kin = FamilyKinematics(sy)
    gs = symmetries(sy)
    pairs = [(g.combination(source), g.motion(summary.example_motion)) for g in gs]
    certs = members_at(kin, pairs)
    assert len({c for c, _ in pairs}) >= 4  # the images are other combinations
    for (c, v), cert in zip(pairs, certs, strict=True):
        assert cert is not None, c
        ind = check_member(data, c, v[: sy.M], v[sy.M:])
        assert ind.member, (c, ind.motion_errors, ind.work, ind.work_min)


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "baxter_hug_box"])
def test_enumeration_with_symmetries_gives_the_same_table(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole table (verdict, reason, dimensions, exactness) is the same with the member
    images and without them (no symmetries), while the images decide rows without a search."""
    sy = example_system(name)
    with_maps, st = enumerate_combinations(sy, workers=1)
    assert st.dafc_mirrored > 0
    monkeypatch.setattr(enumerate_module, "symmetries", lambda system: [])
    without, st0 = enumerate_combinations(sy, workers=1)
    assert st0.dafc_mirrored == 0 and st0.dafc_searched > st.dafc_searched
    key = [(r.combination, r.feasible, r.reason, r.a, r.a_bar, r.dim_dafc, r.dim_dpfc, r.exact) for r in with_maps]
    assert key == [(r.combination, r.feasible, r.reason, r.a, r.a_bar, r.dim_dafc, r.dim_dpfc, r.exact)
                   for r in without]


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "baxter_hug_box", "planar_disk_envelope"])
def test_separates_in_batches_as_one_by_one(name: str) -> None:
    """FamilyKinematics.separates (the group pushes and the whole motion space, batched) answers
    as separating() row by row, on every feasible row's member motion and on those motions with
    every D-point pushed onto the contact (n^T A_j v = 0 made stuck by subtracting its separation
    along the least-norm motion that moves it), where both of its steps are needed."""
    sy = example_system(name)
    rows, _ = enumerate_combinations(sy, workers=1)
    kin = FamilyKinematics(sy)
    combos, motions = [], []
    for r in rows:
        if not r.feasible or r.example_motion is None:
            continue
        combos.append(r.combination)
        motions.append(r.example_motion)
        # the same combination at a motion of its space whose D-points do not all separate strictly
        p = CombinationParts.build(sy, r.combination)
        Lam = p.ms.Lambda  # (M + D, a)
        d_pts = [i for i, s in enumerate(r.combination) if s == "D"]
        if d_pts:
            coords = Lam.T @ r.example_motion
            rows_d = kin.normal_rows[d_pts] @ Lam  # (#D, a)
            j = int(np.argmax(kin.normal_rows[d_pts] @ r.example_motion))
            nj = rows_d[j]
            if np.linalg.norm(nj) > 1e-6:
                v = Lam @ (coords - (nj @ coords) / (nj @ nj) * nj)  # D-point j exactly on the contact
                combos.append(r.combination)
                motions.append(v)
    got = kin.separates(combos, np.array(motions))
    want = np.array([FamilyKinematics(sy).separating(c, m) is not None for c, m in zip(combos, motions, strict=True)])
    assert np.array_equal(got, want)
    assert got.any() and len(combos) > len([r for r in rows if r.feasible])


@pytest.mark.parametrize("name", ["sphere_four_finger_wrap", "baxter_hug_box", "planar_disk_envelope"])
def test_slip_depends_group_by_group(name: str) -> None:
    """Whether an S-point's slip depends on the finger redundancy, group by group (kept per
    group and letters) as from the whole null(J_c) (seeded sample of combinations)."""
    sy = example_system(name)
    kin = FamilyKinematics(sy)
    combos = [c for c in sample_combinations(sy, 1500, seed=4) if "S" in c]
    got = [kin.slip_depends(c) for c in combos]
    assert got == [slip_depends_on_redundancy(sy, c) for c in combos]
    assert any(got) and not all(got)


@pytest.mark.parametrize("name", ["planar_disk_envelope", "baxter_hug_box"])
def test_emptiness_carried_by_symmetries_is_each_rows_own_verdict(name: str) -> None:
    """symmetric_empty=True: rows decided empty as the image of a proven-empty row under a map
    whose data residual is at most 1e-9 have the verdict, reason, dimensions and exactness of
    their own search (the table without the option), and some rows were decided that way."""
    sy = example_system(name)
    carried, st = enumerate_combinations(sy, workers=1, symmetric_empty=True)
    own, st0 = enumerate_combinations(sy, workers=1, symmetric_empty=False)
    assert st.dafc_mirrored_empty > 0 and st0.dafc_mirrored_empty == 0
    assert st.dafc_searched + st.dafc_mirrored_empty <= st0.dafc_searched
    assert all(g.residual <= 1e-9 for g in symmetries(sy))
    key = [(r.combination, r.feasible, r.reason, r.a, r.a_bar, r.dim_dafc, r.dim_dpfc, r.exact) for r in carried]
    assert key == [(r.combination, r.feasible, r.reason, r.a, r.a_bar, r.dim_dafc, r.dim_dpfc, r.exact) for r in own]


@pytest.mark.slow
def test_emptiness_carried_by_symmetries_on_the_wrap() -> None:
    """The same on the nine-contact wrap (19,683 rows, about 240 carried)."""
    sy = example_system("sphere_four_finger_wrap")
    carried, st = enumerate_combinations(sy, workers=1, symmetric_empty=True)
    own, _ = enumerate_combinations(sy, workers=1, symmetric_empty=False)
    assert st.dafc_mirrored_empty > 100
    assert [(r.combination, r.feasible, r.reason, r.dim_dafc, r.exact) for r in carried] == [
        (r.combination, r.feasible, r.reason, r.dim_dafc, r.exact) for r in own]


@pytest.mark.slow
def test_emptiness_carried_on_the_twelve_contact_wrap() -> None:
    """The same on the 12-contact wrap, on its rows with at least WHERE_D12 D-points (a set the
    symmetries map onto itself, so whole orbits): carrying emptiness (the default) gives the
    table of every row's own search, example motions included."""
    sy = example_system("sphere_wrap_three_link")
    where = parse_where(f"D>={WHERE_D12}")
    carried, st = enumerate_combinations(sy, workers=2, where=where)
    own, st0 = enumerate_combinations(sy, workers=2, where=where, symmetric_empty=False)
    assert st.dafc_mirrored_empty > 300 and st0.dafc_mirrored_empty == 0  # 413 of its 94,449 rows
    assert st.dafc_searched + st.dafc_mirrored_empty <= st0.dafc_searched
    for a, b in zip(carried, own, strict=True):
        assert (a.combination, a.feasible, a.reason, a.a, a.a_bar, a.dim_dafc, a.dim_dpfc, a.exact) == (
            b.combination, b.feasible, b.reason, b.a, b.a_bar, b.dim_dafc, b.dim_dpfc, b.exact)
        if a.example_motion is not None:
            np.testing.assert_array_equal(a.example_motion, b.example_motion)


def test_a_broken_symmetry_carries_motions_but_no_emptiness() -> None:
    """A contact normal of the planar envelope turned by 1e-7 rad: the mirror is still found
    (member motions are re-certified anyway), with a residual above 1e-9, so no emptiness is
    carried; turned by 1e-3 rad, no map is found."""
    base = example_system("planar_disk_envelope")
    for angle, found in ((1e-7, True), (1e-3, False)):
        c, s = np.cos(angle), np.sin(angle)
        normals = base.normals.copy()
        normals[0] = np.array([[c, -s], [s, c]]) @ normals[0]
        sy = system_from_arrays(base.points, normals, base.p_o, base.J_blocks, base.mu, base.w_ex, base.q,
                                base.bodies, base.friction_sides, base.contact_names, base.object_size)
        gs = symmetries(sy)
        assert bool(gs) == found
        if found:
            assert all(1e-9 < g.residual <= 1e-6 for g in gs)
            _, st = enumerate_combinations(sy, workers=1, symmetric_empty=True)
            assert st.dafc_mirrored_empty == 0


@pytest.mark.parametrize(("row", "mate"), [("DSSSSFDSSSFF", "DSSSFFDSSSSF"), ("DDSSSFDSSSFF", "DDSSFFDSSSSF")])
def test_unproven_twelve_contact_rows_are_members_at_their_mirrors_member(row: str, mate: str) -> None:
    """Two rows of the 12-contact wrap whose own slip-sector search leaves boxes open ("DAFC is
    empty; not proven", exact False, before the member images) are the mirror images of feasible
    rows: the image of the mate's member motion is certified for the row by members_at and is a
    member for the independent scipy LP, so the table now calls them feasible (4 such rows in
    the full list: 287,196 -> 287,200 feasible)."""
    sy = example_system("sphere_wrap_three_link")
    data = json.loads((EXAMPLES / "sphere_wrap_three_link.json").read_text())
    summary, _ = summarize_with_member(CombinationParts.build(sy, mate), stationary_known=True, realisable=False)
    assert summary.feasible and summary.example_motion is not None
    maps = [g for g in symmetries(sy) if g.combination(mate) == row]
    assert maps
    v = maps[0].motion(summary.example_motion)
    assert members_at(FamilyKinematics(sy), [(row, v)])[0] is not None
    ind = check_member(data, row, v[: sy.M], v[sy.M:])
    assert ind.member, (ind.motion_errors, ind.work, ind.work_min)
