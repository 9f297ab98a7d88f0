"""Contact kinematics and selection matrices (eq. 1-6).

Sign conventions are checked by finite differences of the real motions: for small motions
``(dq, dr)`` of hand and object, ``A [dq; dr]`` is the motion of the finger's material point
minus the motion of the object's material point (eq. 2: ``A [dq; dr] = dp_CF - dp_CO``).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from analysis.contacts import (
    GraspSystem,
    all_combinations,
    build_system,
    constrained_matrices,
    grasp_block,
    letter_codes,
    parse_combination,
    selection,
    tangent_basis,
)
from analysis.exceptions import CombinationError, SceneError
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene, scene_from_dict
from analysis.scene import Scene

Array = NDArray[np.float64]

EXAMPLES = Path(__file__).parents[2] / "examples"
PLANAR = EXAMPLES / "planar_disk_envelope.json"
PALM = EXAMPLES / "sphere_four_finger_palm.json"
WRAP = EXAMPLES / "sphere_four_finger_wrap.json"
EPS = 1e-5
FD_TOL = 1e-6

SETTINGS = settings(max_examples=200, deadline=None, derandomize=True)


CANONICAL = sorted(EXAMPLES.glob("*.json"))  # loaded inside the tests, not at collection


def object_point_displacement(p: Array, p_o: Array, dr: Array, t: float) -> Array:
    """Exact displacement of the object's material point at ``p`` when the object moves by the
    twist ``t * dr`` about ``p_o`` (2-D: ``(vx, vy, omega)``; 3-D: ``(v, rotation vector)``)."""
    d = p.shape[0]
    if d == 2:
        c, s = np.cos(t * dr[2]), np.sin(t * dr[2])
        R = np.array([[c, -s], [s, c]])
        v = dr[:2]
    else:
        R = Rotation.from_rotvec(t * dr[3:]).as_matrix()
        v = dr[:3]
    return t * v + R @ (p - p_o) - (p - p_o)


def relative_displacement(system: GraspSystem, hand: HandKinematics, dq: Array, dr: Array, t: float) -> Array:
    """(finger material point) - (object material point) displacement of every contact, (L, d)."""
    out = np.zeros((system.L, system.d))
    for i, (ref, p) in enumerate(zip(system.bodies, system.points, strict=True)):
        x_local = hand.to_local(ref, p, system.q)
        moved = hand.point_position(ref, x_local, system.q + t * dq)
        finger = moved - hand.point_position(ref, x_local, system.q)
        out[i] = finger - object_point_displacement(p, system.p_o, dr, t)
    return out


def randomized(scene: Scene, rng: np.random.Generator) -> Scene:
    """The scene with random contact points and object pose (not a valid grasp any more, but
    every quantity of eq. 1-2 is defined): exercises G with arbitrary lever arms."""
    d = scene.dim
    pose = scene.object.pose.model_copy(
        update={"position": (np.asarray(scene.object.pose.position) + rng.uniform(-0.5, 0.5, d)).tolist()}
    )
    contacts = [
        c.model_copy(update={"point": (np.asarray(c.point) + rng.uniform(-0.5, 0.5, d)).tolist()})
        for c in scene.contacts
    ]
    obj = scene.object.model_copy(update={"pose": pose})
    return scene.model_copy(update={"object": obj, "contacts": contacts})


# --------------------------------------------------------------------------------------------
# Eq. 1-2 by finite differences


@pytest.mark.parametrize("path", CANONICAL, ids=lambda p: p.stem)
@pytest.mark.parametrize("seed", range(4))
def test_A_is_finger_point_motion_minus_object_point_motion(path: Path, seed: int) -> None:
    scene = load_scene(path)
    rng = np.random.default_rng(seed)
    hand = HandKinematics.from_scene(scene)
    if seed == 0:
        system = build_system(scene, hand)  # the scene as given
    else:
        system = build_system(randomized(scene, rng), hand, q=hand.q0 + rng.uniform(-0.7, 0.7, hand.M))
    L, d, D, M = system.L, system.d, system.D, system.M
    assert system.A.shape == (L * d, M + D)
    for _ in range(5):
        dq = rng.normal(size=M)
        dr = rng.normal(size=D)
        predicted = (system.A @ np.concatenate([dq, dr])).reshape(L, d)
        central = (
            relative_displacement(system, hand, dq, dr, EPS)
            - relative_displacement(system, hand, dq, dr, -EPS)
        ) / (2 * EPS)
        np.testing.assert_allclose(predicted, central, rtol=0, atol=FD_TOL)
        # first order: the one-sided difference converges linearly
        one_sided = relative_displacement(system, hand, dq, dr, EPS) / EPS
        np.testing.assert_allclose(predicted, one_sided, rtol=0, atol=1e-3)
    # pure object motion: A [0; dr] = -G^T dr is minus the object point's motion
    dr = rng.normal(size=D)
    obj = np.array(
        [
            object_point_displacement(p, system.p_o, dr, EPS)
            - object_point_displacement(p, system.p_o, dr, -EPS)
            for p in system.points
        ]
    ) / (2 * EPS)
    np.testing.assert_allclose((system.A[:, M:] @ dr).reshape(L, d), -obj, rtol=0, atol=FD_TOL)


def test_A_signs_on_a_hand_checked_example() -> None:
    """Planar scene, palm contact at (0, 0) below the disk centre (0, 0.5): lifting the object
    by dr = (0, 1, 0) moves its point up, so the palm point moves -1 in y relative to it."""
    scene = load_scene(PLANAR)
    system = build_system(scene)
    palm = [c.body for c in scene.contacts].index("palm")
    A_palm = system.contact_A(palm)
    M = system.M
    assert np.all(A_palm[:, :M] == 0.0)  # a fixed body has J = 0
    np.testing.assert_allclose(A_palm[:, M:] @ [0.0, 1.0, 0.0], [0.0, -1.0], atol=1e-12)
    # turning the disk by +omega about its centre moves its bottom point by omega * (0.5, 0)
    np.testing.assert_allclose(A_palm[:, M:] @ [0.0, 0.0, 1.0], [-0.5, 0.0], atol=1e-12)
    # the normal component of A [0; dr] is -(approach of the object to the palm): lifting
    # the object away from the palm is a separation, n^T A [dq; dr] < 0
    n = system.normals[palm]
    assert n @ (A_palm[:, M:] @ [0.0, 1.0, 0.0]) == pytest.approx(-1.0, abs=1e-12)


@pytest.mark.parametrize("path", CANONICAL, ids=lambda p: p.stem)
def test_system_blocks_and_shapes(path: Path) -> None:
    scene = load_scene(path)
    system = build_system(scene)
    L, d, D, M = system.L, system.d, system.D, system.M
    assert (L, d, D) == (len(scene.contacts), scene.dim, 3 if scene.dim == 2 else 6)
    assert sum(len(f.q) for f in scene.fingers) == M
    assert system.J.shape == (L * d, M) and system.G.shape == (D, L * d)
    for i in range(L):
        np.testing.assert_array_equal(system.J[i * d : (i + 1) * d], system.J_blocks[i])
        np.testing.assert_array_equal(system.G[:, i * d : (i + 1) * d], system.G_blocks[i])
        np.testing.assert_array_equal(system.contact_A(i), system.A[i * d : (i + 1) * d])
    np.testing.assert_array_equal(system.A, np.hstack([system.J, -system.G.T]))
    np.testing.assert_array_equal(system.w_ex, scene.external_wrench)
    np.testing.assert_array_equal(system.mu, [c.mu for c in scene.contacts])
    assert system.friction_sides == scene.friction_cone_sides
    np.testing.assert_array_equal(system.frictional(), [c.mu > 0 for c in scene.contacts])
    assert system.contact_names == tuple(c.body for c in scene.contacts)
    # the object frame is where the wrench acts
    np.testing.assert_array_equal(system.p_o, scene.object.pose.position)


# --------------------------------------------------------------------------------------------
# G_ij


@given(
    p=st.lists(st.floats(-5, 5), min_size=3, max_size=3),
    o=st.lists(st.floats(-5, 5), min_size=3, max_size=3),
    f=st.lists(st.floats(-5, 5), min_size=3, max_size=3),
)
@SETTINGS
def test_G_gives_force_and_moment_about_p_o_3d(p: list[float], o: list[float], f: list[float]) -> None:
    G = grasp_block(np.array(p), np.array(o))
    assert G.shape == (6, 3)
    r = np.array(p) - np.array(o)
    expected = np.concatenate([f, np.cross(r, f)])
    np.testing.assert_allclose(G @ np.array(f), expected, rtol=0, atol=1e-9)


@given(
    p=st.lists(st.floats(-5, 5), min_size=2, max_size=2),
    o=st.lists(st.floats(-5, 5), min_size=2, max_size=2),
    f=st.lists(st.floats(-5, 5), min_size=2, max_size=2),
)
@SETTINGS
def test_G_gives_force_and_moment_about_p_o_2d(p: list[float], o: list[float], f: list[float]) -> None:
    G = grasp_block(np.array(p), np.array(o))
    assert G.shape == (3, 2)
    rx, ry = p[0] - o[0], p[1] - o[1]
    np.testing.assert_allclose(G @ np.array(f), [f[0], f[1], rx * f[1] - ry * f[0]], rtol=0, atol=1e-9)
    # the same as the z row of the 3-D block
    G3 = grasp_block(np.array([*p, 0.0]), np.array([*o, 0.0]))
    np.testing.assert_allclose(G, G3[[0, 1, 5]][:, :2], rtol=0, atol=0)


def test_G_known_answer() -> None:
    # a unit force along +x applied 1 above p_o turns the object clockwise (moment -z)
    G = grasp_block(np.array([0.0, 1.0, 0.0]), np.zeros(3))
    np.testing.assert_array_equal(G @ [1.0, 0.0, 0.0], [1, 0, 0, 0, 0, -1])
    G2 = grasp_block(np.array([0.0, 1.0]), np.zeros(2))
    np.testing.assert_array_equal(G2 @ [1.0, 0.0], [1, 0, -1])


# --------------------------------------------------------------------------------------------
# Tangent bases

unit3 = (
    st.lists(st.floats(-1, 1), min_size=3, max_size=3)
    .filter(lambda v: np.linalg.norm(v) > 1e-3)
    .map(lambda v: np.asarray(v) / np.linalg.norm(v))
)


@given(n=unit3)
@SETTINGS
def test_tangent_basis_3d_is_orthonormal_right_handed_and_orthogonal_to_n(n: Array) -> None:
    T = tangent_basis(n)
    assert T.shape == (2, 3)
    np.testing.assert_allclose(T @ T.T, np.eye(2), rtol=0, atol=1e-12)
    np.testing.assert_allclose(T @ n, 0.0, rtol=0, atol=1e-12)
    assert np.linalg.det(np.vstack([T, n])) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_tangent_basis_3d_on_axes(axis: int, sign: float) -> None:
    n = sign * np.eye(3)[axis]
    T = tangent_basis(n)
    np.testing.assert_allclose(T @ T.T, np.eye(2), rtol=0, atol=1e-15)
    np.testing.assert_allclose(T @ n, 0.0, rtol=0, atol=1e-15)


@given(angle=st.floats(-np.pi, np.pi))
@SETTINGS
def test_tangent_basis_2d_is_n_turned_by_plus_90_degrees(angle: float) -> None:
    n = np.array([np.cos(angle), np.sin(angle)])
    T = tangent_basis(n)
    assert T.shape == (1, 2)
    np.testing.assert_allclose(T[0], [np.cos(angle + np.pi / 2), np.sin(angle + np.pi / 2)], atol=1e-12)
    assert T[0] @ n == pytest.approx(0.0, abs=1e-15)
    assert np.linalg.det(np.vstack([n, T[0]])) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("path", CANONICAL, ids=lambda p: p.stem)
def test_system_tangents_and_normals(path: Path) -> None:
    scene = load_scene(path)
    system = build_system(scene)
    assert system.tangents.shape == (system.L, system.d - 1, system.d)
    for n, T in zip(system.normals, system.tangents, strict=True):
        assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(T @ T.T, np.eye(system.d - 1), rtol=0, atol=1e-12)
        np.testing.assert_allclose(T @ n, 0.0, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# Selection matrices (eq. 3-6)


def check_selection(system: GraspSystem, comb: str, rng: np.random.Generator) -> None:
    sel = selection(system, comb)
    L, d = system.L, system.d
    nF, nS, nN, nD = (comb.count(s) for s in "FSND")
    assert sel.combination == comb
    assert sel.H_c.shape == (d * nF + nS + nN, L * d) and sel.L_c == d * nF + nS + nN
    assert sel.H_s.shape == (d * nS, L * d)
    assert sel.H_d.shape == (nD, L * d)
    assert sel.f_index == tuple(i for i, s in enumerate(comb) if s == "F")
    assert sel.s_index == tuple(i for i, s in enumerate(comb) if s == "S")
    assert sel.n_index == tuple(i for i, s in enumerate(comb) if s == "N")
    assert sel.d_index == tuple(i for i, s in enumerate(comb) if s == "D")
    # f_c = H_c f stacks, in scene order, the full force (F) or its normal component (S, N)
    f = rng.normal(size=L * d)
    fi = f.reshape(L, d)
    n = system.normals
    fc = sel.H_c @ f
    expected_c: list[float] = []
    for i, s in enumerate(comb):
        part = fi[i] if s == "F" else [n[i] @ fi[i]] if s in "SN" else []
        np.testing.assert_allclose(fc[sel.c_slices[i]], part, rtol=0, atol=1e-12)
        expected_c.extend(part)
    np.testing.assert_allclose(fc, expected_c, rtol=0, atol=1e-12)
    # H_s picks the whole force of S-points only; H_d one normal row per D-point
    np.testing.assert_allclose(
        sel.H_s @ f, np.concatenate([fi[i] for i in sel.s_index] or [[]]), rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(sel.H_d @ f, [n[i] @ fi[i] for i in sel.d_index], rtol=0, atol=1e-12)
    A_c, A_s, A_d = constrained_matrices(system, sel)
    A = system.A
    np.testing.assert_array_equal(A_c, sel.H_c @ A)
    np.testing.assert_array_equal(A_s, sel.H_s @ A)
    np.testing.assert_array_equal(A_d, sel.H_d @ A)
    assert A_c.shape == (sel.L_c, system.M + system.D)
    # the rows of A_d are n_i^T A_i: the normal relative motion of the D-points
    for row, i in zip(A_d, sel.d_index, strict=True):
        np.testing.assert_allclose(row, n[i] @ system.contact_A(i), rtol=0, atol=1e-12)


def test_selection_for_every_planar_combination() -> None:
    system = build_system(load_scene(PLANAR))
    rng = np.random.default_rng(0)
    combos = all_combinations(system)
    assert len(combos) == 3**5
    for comb in combos:
        check_selection(system, comb, rng)


@pytest.mark.parametrize("path", [PALM, WRAP], ids=lambda p: p.stem)
def test_selection_for_sampled_spatial_combinations(path: Path) -> None:
    system = build_system(load_scene(path))
    rng = np.random.default_rng(1)
    for _ in range(60):
        comb = "".join(rng.choice(list("FSD"), size=system.L))
        check_selection(system, comb, rng)
    check_selection(system, "F" * system.L, rng)
    check_selection(system, "D" * system.L, rng)
    check_selection(system, "S" * system.L, rng)


def frictionless_planar(indices: tuple[int, ...]) -> GraspSystem:
    data = load_scene(PLANAR).model_dump()
    for i in indices:
        data["contacts"][i]["mu"] = 0.0
    return build_system(scene_from_dict(data))


def test_selection_with_frictionless_contacts() -> None:
    system = frictionless_planar((1, 4))
    rng = np.random.default_rng(2)
    combos = all_combinations(system)
    assert len(combos) == 3**3 * 2**2
    for comb in combos:
        assert comb[1] in "ND" and comb[4] in "ND"
        assert all(comb[i] in "FSD" for i in (0, 2, 3))
        check_selection(system, comb, rng)
    sel = selection(system, "FNSDN")
    assert sel.n_index == (1, 4) and sel.L_c == 2 + 1 + 1 + 1


# --------------------------------------------------------------------------------------------
# Combination strings


def _combination_error(system: GraspSystem, comb: str) -> CombinationError:
    with pytest.raises(CombinationError) as info:
        parse_combination(comb, system)
    assert isinstance(info.value, SceneError)
    return info.value


@pytest.mark.parametrize("comb", ["", "FFDD", "FFDDSS", "FFDDSSFFDD"])
def test_combination_of_wrong_length(comb: str) -> None:
    system = build_system(load_scene(PLANAR))
    e = _combination_error(system, comb)
    assert e.loc == ("combination",)
    assert str(e) == f"combination: has {len(comb)} letters but the scene has 5 contacts"
    with pytest.raises(CombinationError):
        selection(system, comb)


@pytest.mark.parametrize(
    ("comb", "index", "letter"), [("XFFFF", 0, "X"), ("FFQDD", 2, "Q"), ("FFDD1", 4, "1"), ("FF DD", 2, " ")]
)
def test_combination_with_a_bad_letter(comb: str, index: int, letter: str) -> None:
    e = _combination_error(build_system(load_scene(PLANAR)), comb)
    assert e.loc == ("combination", index)
    assert str(e).startswith(f"combination.{index}: '{letter}' is not a contact state")


def test_combination_letters_are_case_insensitive() -> None:
    system = build_system(load_scene(PLANAR))
    assert parse_combination("ffdsd", system) == "FFDSD"
    assert selection(system, "ffdsd").combination == "FFDSD"


def test_N_is_rejected_for_frictional_contacts() -> None:
    e = _combination_error(build_system(load_scene(PLANAR)), "FFNFF")
    assert e.loc == ("combination", 2)
    assert "mu=0.5" in str(e) and "N is for mu = 0" in str(e)


@pytest.mark.parametrize("letter", ["F", "S"])
def test_F_and_S_are_rejected_for_frictionless_contacts(letter: str) -> None:
    system = frictionless_planar((3,))
    e = _combination_error(system, f"FFF{letter}F")
    assert e.loc == ("combination", 3)
    assert "frictionless" in str(e)
    assert parse_combination("FFFNF", system) == "FFFNF"
    assert parse_combination("FFFDF", system) == "FFFDF"


@given(comb=st.text(alphabet="FNSDXfnsd", min_size=0, max_size=7))
@SETTINGS
def test_parse_combination_accepts_exactly_the_valid_strings(comb: str) -> None:
    system = frictionless_planar((1,))
    allowed = ["FSD", "ND", "FSD", "FSD", "FSD"]
    upper = comb.upper()
    valid = len(upper) == 5 and all(s in ok for s, ok in zip(upper, allowed, strict=True))
    if valid:
        assert parse_combination(comb, system) == upper
        assert upper in all_combinations(system)
    else:
        with pytest.raises(CombinationError) as info:
            parse_combination(comb, system)
        assert info.value.loc[0] == "combination"


@pytest.mark.parametrize("path", [PLANAR, PALM, WRAP], ids=lambda p: p.stem)
def test_all_combinations_count(path: Path) -> None:
    system = build_system(load_scene(path))
    assert np.all(system.mu > 0)
    combos = all_combinations(system)
    assert len(combos) == 3**system.L
    assert len(set(combos)) == len(combos)
    assert set(itertools.chain.from_iterable(combos)) == set("FSD")
    assert all(len(c) == system.L for c in combos)


def test_letter_codes_known_answer() -> None:
    """F 0, S/N 1, D 2 for every letter; a row of another length or with another letter is a
    ValueError naming it."""
    np.testing.assert_array_equal(letter_codes(["FSND", "DDFF"], 4), [[0, 1, 1, 2], [2, 2, 0, 0]])
    assert letter_codes([], 3).shape == (0, 3)
    with pytest.raises(ValueError, match="'FXDD' has a letter other than"):
        letter_codes(["FSDD", "FXDD"], 4)  # not a letter of a contact state
    with pytest.raises(ValueError, match="'FS' has 2 letters, not 3"):
        letter_codes(["FSD", "FS", "FSDF"], 3)  # the right total length, misaligned rows
