"""Kinematic contact-mode enumeration (analysis/modes.py).

Known answers derived by hand on tiny systems (planar box and disk on a table, a cube on a table),
and a property test: on random small systems the output-sensitive enumeration equals brute-force
enumeration over every sign vector, each checked by its own max-margin LP (a fresh HiGHS model,
a different formulation from the enumeration's warm-started feasibility LPs).
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import highspy
import numpy as np
import pytest
from cube_planes import PUBLISHED_CS_COUNTS, cube_in_planes
from numpy.typing import ArrayLike, NDArray

from analysis.combination import analyze_combination
from analysis.contacts import GraspSystem, build_system, system_from_arrays
from analysis.exceptions import CombinationError
from analysis.loader import load_scene, scene_from_dict
from analysis.modes import ModeTolerances, combination_admissible, contacting_separating_modes, enumerate_modes

Array = NDArray[np.float64]

EXAMPLES = Path(__file__).parents[2] / "examples"
MARGIN = ModeTolerances().margin
MOVE_TOL = 1e-7  # |c^T dr| above which a brute-force LP says the object moves (box |v| <= 1)
RNG_MOVES = np.random.default_rng(12345)
BRUTE_LP = highspy.Highs()
BRUTE_LP.setOptionValue("output_flag", False)
BRUTE_LP.setOptionValue("presolve", "off")


# --------------------------------------------------------------------------------------------
# Systems


def make_system(
    points: ArrayLike, normals: ArrayLike, p_o: ArrayLike, J_blocks: Array | None = None
) -> GraspSystem:
    """A ``GraspSystem`` built directly: contacts on fixed bodies unless ``J_blocks`` is given."""
    return system_from_arrays(np.asarray(points, dtype=float), np.asarray(normals, dtype=float),
                              np.asarray(p_o, dtype=float), J_blocks)


def table_scene_2d(shape: dict, position: list[float], xs: list[float]) -> GraspSystem:
    """A planar object resting on a fixed table (no fingers) at the points ``(x, 0)``."""
    return build_system(
        scene_from_dict(
            {
                "dim": 2,
                "object": {"pose": {"position": position, "angle": 0.0}, "shape": shape},
                "external_wrench": [0.0, -1.0, 0.0],
                "fixed_bodies": [{"name": "table", "shape": {"type": "segment", "points": [[-9, 0], [9, 0]]}}],
                "fingers": [],
                "contacts": [{"body": "table", "point": [x, 0.0], "normal": [0.0, 1.0], "mu": 0.5} for x in xs],
            }
        )
    )


def cube_on_table() -> GraspSystem:
    """A box (1.2 x 1.2 x 1, centre at z = 0.5) on a table, contacts at (+-0.5, +-0.5, 0)."""
    return build_system(
        scene_from_dict(
            {
                "dim": 3,
                "object": {
                    "pose": {"position": [0, 0, 0.5], "quat_wxyz": [1, 0, 0, 0]},
                    "shape": {"type": "box", "size": [1.2, 1.2, 1.0]},
                },
                "external_wrench": [0, 0, -1, 0, 0, 0],
                "fixed_bodies": [
                    {"name": "table", "shape": {"type": "box", "size": [4, 4, 0.1], "position": [0, 0, -0.05]}}
                ],
                "fingers": [],
                "contacts": [
                    {"body": "table", "point": [x, y, 0.0], "normal": [0, 0, 1], "mu": 0.5}
                    for x in (-0.5, 0.5)
                    for y in (-0.5, 0.5)
                ],
            }
        )
    )


def random_system(rng: np.random.Generator, dim: int, L: int) -> GraspSystem:
    """Random contacts on fixed bodies and on random fingers (joint groups), with degenerate
    geometry half of the time (grid points, axis-aligned normals, rank-deficient Jacobians)."""
    d = dim
    degenerate = rng.random() < 0.5
    points = rng.normal(size=(L, d))
    normals = rng.normal(size=(L, d))
    if degenerate:
        points = np.round(points * 2) / 2
        axes = np.vstack([np.eye(d), -np.eye(d)])
        normals = axes[rng.integers(0, 2 * d, L)]
    p_o = np.round(rng.normal(size=d), 1)
    n_fingers = int(rng.integers(0, 3))
    sizes = [int(rng.integers(1, d + 2)) for _ in range(n_fingers)]
    M = sum(sizes)
    starts = np.cumsum([0, *sizes])
    J = np.zeros((L, d, M))
    for i in range(L):
        f = int(rng.integers(-1, n_fingers))  # -1: a fixed body
        if f < 0:
            continue
        cols = slice(starts[f], starts[f + 1])
        block = rng.normal(size=(d, sizes[f]))
        if rng.random() < 0.3:  # rank one
            block = np.outer(rng.normal(size=d), rng.normal(size=sizes[f]))
        J[i, :, cols] = block
    return make_system(points, normals, p_o, J)


# --------------------------------------------------------------------------------------------
# Brute force: every sign vector, one max-margin LP each


def _rows(system: GraspSystem) -> tuple[Array, Array]:
    """Unit rows ``n_i^T A_i`` ``(L, n)`` and ``T_i A_i`` ``(L, d-1, n)`` computed from ``A``."""
    nr = np.array([system.normals[i] @ system.contact_A(i) for i in range(system.L)])
    tr = np.array([system.tangents[i] @ system.contact_A(i) for i in range(system.L)])
    nr = nr.reshape(system.L, system.M + system.D)
    tr = tr.reshape(system.L, system.d - 1, system.M + system.D)
    return nr / np.linalg.norm(nr, axis=-1, keepdims=True), tr / np.linalg.norm(tr, axis=-1, keepdims=True)


def _max_margin(n: int, eq: list[Array], strict: list[Array], r_cols: range) -> tuple[bool, bool]:
    """Realised: max t s.t. ``E v = 0``, ``g v >= t``, ``|v| <= 1``, ``t <= 1`` has ``t* > margin/2``.
    Object motion: keeping ``g v >= t*/2``, ``c^T dr`` is not identically 0 for a random ``c``
    (max or min nonzero; the set of ``dr`` is convex, so a random ``c`` is orthogonal to it only
    if it is ``{0}``, with probability one)."""
    inf = highspy.kHighsInf
    rows = np.zeros((len(eq) + len(strict), n + 1))  # (rows, n + 1): [v, t]
    for k, row in enumerate(eq):
        rows[k, :n] = row
    for k, g in enumerate(strict):  # g v - t >= 0
        rows[len(eq) + k, :n] = g
        rows[len(eq) + k, n] = -1.0
    lower = np.zeros(rows.shape[0])
    upper = np.r_[np.zeros(len(eq)), np.full(len(strict), inf)]

    def solve(cost: Array, t_lo: float, t_hi: float) -> float:
        lp = highspy.HighsLp()
        lp.num_col_, lp.num_row_ = n + 1, rows.shape[0]
        lp.col_cost_ = cost
        lp.col_lower_ = np.r_[-np.ones(n), t_lo]
        lp.col_upper_ = np.r_[np.ones(n), t_hi]
        lp.row_lower_, lp.row_upper_ = lower, upper
        r, c = np.nonzero(rows)
        lp.a_matrix_.format_ = highspy.MatrixFormat.kRowwise
        lp.a_matrix_.start_ = np.r_[0, np.cumsum(np.bincount(r, minlength=rows.shape[0]))]
        lp.a_matrix_.index_, lp.a_matrix_.value_ = c, rows[r, c]
        h = BRUTE_LP
        h.passModel(lp)  # a new model each time: no warm start from the previous pattern
        h.run()
        assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
        return float(h.getInfo().objective_function_value)

    cost = np.zeros(n + 1)
    cost[n] = -1.0
    t_star = -solve(cost, -inf, 1.0)
    if t_star <= MARGIN / 2:
        return False, False
    cost = np.zeros(n + 1)
    cost[list(r_cols)] = RNG_MOVES.normal(size=len(r_cols))
    moves = -solve(-cost, t_star / 2, t_star / 2) > MOVE_TOL or solve(cost, t_star / 2, t_star / 2) < -MOVE_TOL
    return True, moves


def brute_contacting_separating(system: GraspSystem) -> dict[str, bool]:
    nr, _ = _rows(system)
    n = system.M + system.D
    out = {}
    for signs in itertools.product("0-", repeat=system.L):
        eq = [nr[i] for i in range(system.L) if signs[i] == "0"]
        strict = [-nr[i] for i in range(system.L) if signs[i] == "-"]
        ok, moves = _max_margin(n, eq, strict, range(system.M, n))
        if ok:
            out["".join(signs)] = moves
    return out


def brute_tokens(dim: int) -> list[str]:
    if dim == 2:
        return ["F", "S+", "S-", "D"]
    return ["F", "D"] + [f"S({a},{b})" for a, b in itertools.product("+-0", repeat=2) if (a, b) != ("0", "0")]


def brute_sticking_sliding(system: GraspSystem) -> dict[str, bool]:
    """Every token vector (default two tangent planes in 3-D: the tangent axes)."""
    nr, tr = _rows(system)
    n = system.M + system.D
    out = {}
    for toks in itertools.product(brute_tokens(system.dim), repeat=system.L):
        eq: list[Array] = []
        strict: list[Array] = []
        for i, tok in enumerate(toks):
            if tok == "D":
                strict.append(-nr[i])
                continue
            eq.append(nr[i])
            signs = "0" * (system.d - 1) if tok == "F" else tok[1:].strip("()").replace(",", "")
            for k, s in enumerate(signs):
                if s == "0":
                    eq.append(tr[i, k])
                else:
                    strict.append(tr[i, k] if s == "+" else -tr[i, k])
        ok, moves = _max_margin(n, eq, strict, range(system.M, n))
        if ok:
            out[" ".join(toks)] = moves
    return out


def categories_of(ss: dict[str, bool]) -> dict[str, bool]:
    out: dict[str, bool] = {}
    for mode, moves in ss.items():
        cat = "".join(t[0] for t in mode.split(" "))
        out[cat] = out.get(cat, False) or moves
    return out


def brute_admissible(ss: dict[str, bool], combination: str) -> bool:
    allowed = {"F": "F", "S": "S", "N": "FS", "D": "FSD"}
    for mode, moves in ss.items():
        if moves and all(t[0] in allowed[c] for t, c in zip(mode.split(" "), combination, strict=True)):
            return True
    return False


def as_dicts(system: GraspSystem, **kw: object) -> tuple[dict[str, bool], dict[str, bool], dict[str, bool]]:
    e = enumerate_modes(system, **kw)  # type: ignore[arg-type]
    assert e.sticking_sliding_complete
    cs = {m.signs: m.object_moves for m in e.contacting_separating}
    cat = {m.categories: m.object_moves for m in e.categories}
    ss = {m.mode: m.object_moves for m in e.sticking_sliding}
    assert len(cs) == e.n_contacting_separating and len(ss) == e.n_sticking_sliding  # no duplicates
    return cs, cat, ss


def check_against_brute_force(system: GraspSystem) -> None:
    cs, cat, ss = as_dicts(system)
    assert cs == brute_contacting_separating(system)
    brute_ss = brute_sticking_sliding(system)
    assert ss == brute_ss
    assert cat == categories_of(brute_ss)
    e = enumerate_modes(system)
    for comb in itertools.product("FSND", repeat=system.L):
        c = "".join(comb)
        assert combination_admissible(e, c) == brute_admissible(brute_ss, c), c


# --------------------------------------------------------------------------------------------
# Known answers


def test_planar_box_two_corners_by_hand() -> None:
    """Box centre (0, 0.5) on a table at x = -1, +1, normal (0, 1), no fingers: ``v = dr =
    (vx, vy, w)``. The object point (x, 0) moves with (vx + 0.5 w, vy + w x); contact i keeps
    contact iff vy + w x_i = 0 and separates iff > 0.
    - contacting/separating: '00' (vy = w = 0, vx free), '0-' (pivot about the left corner,
      w > 0), '-0' (w < 0), '--' (lift): 4 = 2^2, all move the object.
    - sliding: the tangent is t = (-1, 0); t^T A_i v = vx + 0.5 w. In '00' both contacts share
      it: 'F F' (v = 0, no motion), 'S+ S+', 'S- S-'. In '0-' the pivot may roll or slide:
      'F D' (rotation about the corner), 'S+ D', 'S- D'; likewise 'D F', 'D S+', 'D S-'; 'D D'.
      Total 3 + 3 + 3 + 1 = 10, all but 'F F' move the object.
    - categories: FF, SS, FD, SD, DF, DS, DD (FS and SF need w = vy = 0, then both tangential
      velocities are equal): 7, all but FF move.
    - admissible combinations: every F/S/D word but FF, FS, SF.
    """
    system = table_scene_2d({"type": "box", "size": [2.2, 1.0]}, [0.0, 0.5], [-1.0, 1.0])
    cs, cat, ss = as_dicts(system)
    assert cs == {"00": True, "0-": True, "-0": True, "--": True}
    assert ss == {
        "F F": False,
        "S+ S+": True,
        "S- S-": True,
        "F D": True,
        "S+ D": True,
        "S- D": True,
        "D F": True,
        "D S+": True,
        "D S-": True,
        "D D": True,
    }
    assert cat == {"FF": False, "SS": True, "FD": True, "SD": True, "DF": True, "DS": True, "DD": True}
    e = enumerate_modes(system)
    admissible = {"".join(c) for c in itertools.product("FSD", repeat=2) if combination_admissible(e, "".join(c))}
    assert admissible == {"SS", "FD", "DF", "SD", "DS", "DD"}
    assert combination_admissible(e, "NN") and combination_admissible(e, "ND")
    check_against_brute_force(system)


def test_disk_on_table_by_hand() -> None:
    """Disk (radius 0.5, centre (0, 0.5)) on a table at (0, 0): the contact point moves with
    (vx + 0.5 w, vy). Modes: contacting ('F' rolling, 'S+', 'S-') or 'D' (lift): 4, all moving;
    2 contacting/separating modes; categories F, S, D; every letter admissible."""
    system = table_scene_2d({"type": "disk", "radius": 0.5}, [0.0, 0.5], [0.0])
    cs, cat, ss = as_dicts(system)
    assert cs == {"0": True, "-": True}
    assert ss == {"F": True, "S+": True, "S-": True, "D": True}
    assert cat == {"F": True, "S": True, "D": True}
    e = enumerate_modes(system)
    assert all(combination_admissible(e, c) for c in "FSND")
    check_against_brute_force(system)


def test_cube_on_table_by_hand_and_brute_force() -> None:
    """Cube on a table, corners (+-0.5, +-0.5, 0), centre (0, 0, 0.5), no fingers.

    Contacting/separating: the object's lift of the corners is an affine function of the corner
    that must be >= 0; its zero set meets the square in: everything (all contacting), nothing
    (lift), one corner (4), one edge (4). Three zero corners force the fourth; two diagonal ones
    put the others on opposite sides. 10 modes.

    Sticking/sliding (tangent axes t1 = y, t2 = -x, two hyperplanes per contact):
    - all contacting: planar motion (vx, vy, wz); the corner (x, y) slides with
      (vx - wz y, vy + wz x): hyperplanes vy +- 0.5 wz = 0 and vx +- 0.5 wz = 0, four planes in
      general position in R^3: 14 regions + 24 sectors + 12 rays + the origin = 51 faces;
    - an edge (x = -0.5, say): wx = 0, vz = -0.5 wy, wy < 0; both corners slide with
      (a -+ 0.5 wz, b), a, b, wz free: 3 generic planes: 8 + 12 + 6 + 1 = 27 faces, times 4 edges;
    - a corner: its tangential velocity is free: 1 + 8 = 9, times 4 corners; the lift: 1.
    Total 51 + 108 + 36 + 1 = 196; only the all-stick 'F F F F' (v = 0) leaves the object still.
    Categories: all contacting 1 (FFFF) + 1 (SSSS) + 4 (one corner sticks: rotation about it);
    edges 4 x 4 (FF, FS, SF, SS); corners 4 x 2; lift 1: 31.
    """
    system = cube_on_table()
    cs, cat, ss = as_dicts(system)
    assert len(cs) == 10 and all(cs.values())
    assert len(ss) == 196 and [m for m, mv in ss.items() if not mv] == ["F F F F"]
    assert len(cat) == 31
    assert cs == brute_contacting_separating(system)
    brute = brute_sticking_sliding(system)
    assert ss == brute
    assert cat == categories_of(brute)


def test_collinear_contacts_few_lps() -> None:
    """A planar box on 10 collinear table contacts: only the end contacts can be pivots, so there
    are 4 contacting/separating modes, 7 categories and 10 sticking/sliding modes (as for two
    contacts) among 2^10 sign vectors and 3^10 stick/slide/separate patterns; the search must
    solve O(L * #modes) LPs, far fewer than 3^L."""
    L = 10
    xs = list(np.linspace(-1.0, 1.0, L))
    e = enumerate_modes(table_scene_2d({"type": "box", "size": [2.2, 1.0]}, [0.0, 0.5], xs))
    assert e.n_contacting_separating == 4 and e.n_categories == 7 and e.n_sticking_sliding == 10
    assert e.lp_counts["contacting_separating"] <= L * e.n_contacting_separating
    assert e.lp_count <= 2 * L * (e.n_contacting_separating + e.n_categories + e.n_sticking_sliding)
    assert e.lp_count < 3**L / 100
    stick = "F" + "D" * (L - 1)
    assert combination_admissible(e, stick) and not combination_admissible(e, "F" * L)
    assert not combination_admissible(e, "DFD" + "D" * (L - 3))  # an inner pivot is impossible


def test_planar_example_against_brute_force() -> None:
    check_against_brute_force(build_system(load_scene(EXAMPLES / "planar_disk_envelope.json")))


def test_free_fingertips_factor_into_a_product() -> None:
    """Four 3-joint fingertips (free: any relative velocity) and a palm: 2^5 contacting/separating
    modes, 3^5 categories, 10^4 x 10 sticking/sliding modes, and only the palm is searched."""
    system = build_system(load_scene(EXAMPLES / "sphere_four_finger_palm.json"))
    e = enumerate_modes(system, max_modes=None)
    assert e.free_contacts == (0, 1, 2, 3)
    assert (e.n_contacting_separating, e.n_categories, e.n_sticking_sliding) == (32, 243, 10**5)
    assert e.lp_count < 50
    # the palm alone decides: it may stick only if the object rotates about the contact point
    assert all(combination_admissible(e, c + "F") for c in ("FFFF", "SSSS", "DDDD"))


# --------------------------------------------------------------------------------------------
# Property test: random small systems


@pytest.mark.parametrize("seed", range(12))
def test_random_planar_systems_equal_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    system = random_system(rng, 2, int(rng.integers(1, 6)))
    check_against_brute_force(system)
    assert as_dicts(system) == as_dicts(system, factor_free_contacts=False)


@pytest.mark.parametrize("seed", range(6))
def test_random_spatial_systems_equal_brute_force(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    system = random_system(rng, 3, int(rng.integers(1, 4)))
    check_against_brute_force(system)
    assert as_dicts(system) == as_dicts(system, factor_free_contacts=False)


def test_random_systems_exercise_free_contacts() -> None:
    """The random generator does produce factorable systems (so the comparisons above check
    the product path too)."""
    hits = 0
    for seed in range(12):
        rng = np.random.default_rng(seed)
        hits += bool(enumerate_modes(random_system(rng, 2, int(rng.integers(1, 6)))).free_contacts)
    assert hits >= 2


# --------------------------------------------------------------------------------------------
# API details


def test_more_tangent_planes_refine_sliding() -> None:
    """A free 3-D contact (disk-like sphere on a table) has 1 + 4m sliding-sign faces + stick."""
    system = make_system([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], [0.0, 0.0, 0.5])
    for m in (2, 3, 4):
        e = enumerate_modes(system, tangent_planes=m)
        slides = [s.mode for s in e.sticking_sliding if s.mode.startswith("S")]
        assert len(slides) == 4 * m and all(len(s.split(",")) == m for s in slides)
    with pytest.raises(ValueError):
        enumerate_modes(system, tangent_planes=1)


def test_max_modes_truncates_and_json() -> None:
    system = cube_on_table()
    e = enumerate_modes(system, max_modes=50)
    assert not e.sticking_sliding_complete and e.n_sticking_sliding == 50
    assert e.n_contacting_separating == 10 and e.n_categories == 31  # always complete
    full = enumerate_modes(system)
    data = json.loads(json.dumps(full.to_json()))
    assert data["contacting_separating"] == 10 and data["sticking_sliding"] == 196
    assert sum(len(m["sticking_sliding"]) for m in data["modes"]) == 196
    assert {m["signs"] for m in data["modes"]} == {m.signs for m in full.contacting_separating}
    assert data["lp_count"] == full.lp_count > 0


def test_refine_false_keeps_admissibility() -> None:
    """Pruning needs only the first two stages: same categories and answers, no stage-3 LPs."""
    system = build_system(load_scene(EXAMPLES / "planar_disk_envelope.json"))
    full = enumerate_modes(system)
    quick = enumerate_modes(system, refine=False)
    assert quick.categories == full.categories and quick.contacting_separating == full.contacting_separating
    assert quick.n_sticking_sliding == 0 and not quick.sticking_sliding_complete and not quick.refined
    assert quick.lp_counts["sticking_sliding"] == 0
    for comb in itertools.product("FSD", repeat=system.L):
        c = "".join(comb)
        assert combination_admissible(quick, c) == combination_admissible(full, c)


def test_no_contacts_and_bad_combinations() -> None:
    e = enumerate_modes(make_system(np.zeros((0, 2)), np.zeros((0, 2)), [0.0, 0.0]))
    assert [m.signs for m in e.contacting_separating] == [""]
    assert combination_admissible(e, "")  # a free object moves
    e = enumerate_modes(table_scene_2d({"type": "disk", "radius": 0.5}, [0.0, 0.5], [0.0]))
    with pytest.raises(CombinationError):
        combination_admissible(e, "FF")
    with pytest.raises(CombinationError):
        combination_admissible(e, "X")


# --------------------------------------------------------------------------------------------
# Published counts: a unit cube against 1 to 5 planes (Huang, Cheng & Mason, WAFR 2020)


@pytest.mark.parametrize(("k", "expected"), list(enumerate(PUBLISHED_CS_COUNTS, start=1)))
def test_cube_against_planes_has_the_published_mode_counts(k: int, expected: int) -> None:
    """The unit cube with its corners against the floor, then the walls x = -0.5, y = -0.5,
    x = +0.5, y = +0.5 (fixed boxes; vertex-face contacts, four a plane, a corner on two or three
    planes is a contact of each): 10, 46, 136, 10 and 2 contacting/separating modes. The scene goes
    through the loader, so the corner normals (the planes') must lie in the cube's normal cones."""
    scene = scene_from_dict(cube_in_planes(k))
    assert len(scene.contacts) == 4 * k
    system = build_system(scene)
    modes = contacting_separating_modes(system)
    assert len(modes) == expected == len({m.signs for m in modes})
    assert enumerate_modes(system, refine=False).contacting_separating == modes
    if k <= 3:  # 16, 256 and 4096 sign vectors (1.5 s): every one checked by its own max-margin LP
        assert {m.signs: m.object_moves for m in modes} == brute_contacting_separating(system)


def test_cube_in_five_planes_by_hand() -> None:
    """Floor and four walls: the walls stop every horizontal motion and every rotation (a
    rotation about a horizontal axis pushes a wall corner into its wall), so the cube either stays
    or lifts straight up, the floor separating and the walls' corners sliding up: 2 modes."""
    system = build_system(scene_from_dict(cube_in_planes(5)))
    modes = contacting_separating_modes(system)
    assert [(m.signs, m.object_moves) for m in modes] == [("0" * 20, False), ("-" * 4 + "0" * 16, True)]


def test_contact_grids_keep_the_corner_modes_at_32_contacts() -> None:
    """4 x 4 grids of contacts on the floor and one wall (32 contacts): a non-positive affine
    function on a square vanishes on a face of it, so a grid point is contacting exactly when the
    corners of its face (or edge) are, and the modes are the 46 of the corners."""
    grid = build_system(scene_from_dict(cube_in_planes(2, grid=4)))
    corners = build_system(scene_from_dict(cube_in_planes(2)))
    assert grid.L == 32
    at_corners = [i for i, p in enumerate(grid.points) if np.all(np.abs(np.abs(p) - 0.5) < 1e-12)]
    assert len(at_corners) == 8
    grid_modes = {"".join(m.signs[i] for i in at_corners) for m in contacting_separating_modes(grid)}
    assert len(contacting_separating_modes(grid)) == 46
    assert grid_modes == {m.signs for m in contacting_separating_modes(corners)}


@pytest.mark.parametrize(("k", "grid"), [(5, 2), (2, 4)])  # 20 and 32 contacts
def test_twenty_and_thirty_two_contacts_analyse_one_combination(k: int, grid: int) -> None:
    """Floor sticking, walls detaching: the floor carries the weight and holds the cube still
    (a~ = 0). All sliding: in five planes nothing can move (a~ = 0); against the floor and the wall
    x = -0.5 the cube slides along y only (a~ = 1), which no finger drives (no fingers): not
    feasible, "DAFC is empty"."""
    system = build_system(scene_from_dict(cube_in_planes(k, grid=grid)))
    n = grid * grid  # contacts on the floor, listed first
    report = analyze_combination(system, "F" * n + "D" * (system.L - n))
    assert report.stationary is not None and report.parts.ms.a_bar == 0 and not report.summary.feasible
    report = analyze_combination(system, "S" * system.L)
    assert report.stationary is not None and not report.summary.feasible
    assert report.parts.ms.a_bar == (0 if k == 5 else 1)
    if k == 2:
        np.testing.assert_allclose(np.abs(report.parts.ms.Lambda_r_t[:, 0]), [0, 1, 0, 0, 0, 0], atol=1e-9)
        assert report.summary.reason == "DAFC is empty"
