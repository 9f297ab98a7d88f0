"""Shared helpers of the closure-analysis tests (paper section III-IV).

* the example scenes, loaded once, and seeded samples of their combinations;
* two hand-built scenes with answers derived by hand (``disk_scene``, ``box_scene``);
* re-computations of the physics that do not use the code under test: the slip and the
  kinetic friction of S-points straight from ``A`` (eq. 2, 11), the full contact force of
  every contact, and an LP solved with scipy for certificates.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linprog

from analysis.combination import CombinationParts
from analysis.contacts import GraspSystem, Selection, all_combinations, build_system
from analysis.loader import load_scene, scene_from_dict
from analysis.scene import Scene

Array = NDArray[np.float64]

EXAMPLES = Path(__file__).parents[2] / "examples"
PLANAR = EXAMPLES / "planar_disk_envelope.json"
PALM = EXAMPLES / "sphere_four_finger_palm.json"
EXAMPLE_NAMES = ("planar_disk_envelope", "sphere_four_finger_palm", "sphere_four_finger_wrap", "allegro_right_box")


@functools.cache
def example_system(name: str) -> GraspSystem:
    return build_system(load_scene(EXAMPLES / f"{name}.json"))


def sample_combinations(system: GraspSystem, n: int, seed: int) -> list[str]:
    """A seeded sample of ``n`` combinations (all of them when there are fewer)."""
    combos = all_combinations(system)
    if len(combos) <= n:
        return combos
    rng = np.random.default_rng(seed)
    return [combos[k] for k in sorted(rng.choice(len(combos), size=n, replace=False))]


@functools.lru_cache(maxsize=4096)
def parts_of(name: str, combination: str) -> CombinationParts:
    return CombinationParts.build(example_system(name), combination)


# --------------------------------------------------------------------------------------------
# Hand-built scenes


DISK_R = 0.5


def disk_scene(links: int) -> Scene:
    """A disk of radius 0.5 at the origin held between two frictionless fingertips at
    ``(-0.5, 0)`` (normal ``+x``) and ``(0.5, 0)`` (normal ``-x``); no external wrench.

    ``links = 1``: each finger is one vertical link of length 1 whose tip moves along x only.
    ``links = 2``: each finger is an L-shaped 2-link chain (0.6 + 0.6) whose tip can move in
    any direction, so the fingers have redundancy.
    """
    R = DISK_R
    fingers: list[dict[str, object]] = []
    for name, side in (("left", -1.0), ("right", 1.0)):
        if links == 1:
            fingers.append({"name": name, "base": {"position": [side * R, -1.0], "angle": np.pi / 2},
                            "links": [{"length": 1.0}], "q": [0.0]})
        else:  # base (+-1.1, -0.6), first link horizontal towards the disk, second link up
            fingers.append({"name": name, "base": {"position": [side * 1.1, -0.6],
                                                   "angle": 0.0 if side < 0 else np.pi},
                            "links": [{"length": 0.6}, {"length": 0.6}],
                            "q": [0.0, np.pi / 2 if side < 0 else -np.pi / 2]})
    return scene_from_dict({
        "name": f"frictionless-disk-{links}-link",
        "dim": 2,
        "object": {"pose": {"position": [0.0, 0.0], "angle": 0.0}, "shape": {"type": "disk", "radius": R}},
        "external_wrench": [0.0, 0.0, 0.0],
        "fingers": fingers,
        "contacts": [
            {"body": f"left/{links - 1}", "point": [-R, 0.0], "normal": [1.0, 0.0], "mu": 0.0},
            {"body": f"right/{links - 1}", "point": [R, 0.0], "normal": [-1.0, 0.0], "mu": 0.0},
        ],
    })


#: Block on a table: half width, half height, and the x of the two support contacts.
BOX_A, BOX_B, BOX_C = 0.5, 0.5, 0.4


def box_scene(h: float, mu: float, p_o: tuple[float, float] = (0.0, BOX_B)) -> Scene:
    """A 1 x 1 block resting on a fixed table (y = 0) at two bottom contacts ``(-0.4, 0)`` and
    ``(0.4, 0)`` (friction ``mu``), pushed horizontally at ``(-0.5, h)`` by the tip of a
    frictionless 2-link finger. Unit weight at the block's centre ``(0, 0.5)``. Contacts in
    the order: left support, right support, pusher (combination strings like ``SSN``).

    ``p_o`` is the object frame origin (where the wrench is expressed); the block and the weight
    stay where they are whatever ``p_o`` is.
    """
    alpha = float(np.arccos(1.0 / 1.2))  # links 0.6 + 0.6, base 1.0 left of the tip
    com = np.array([0.0, BOX_B])
    rel = com - np.asarray(p_o, dtype=float)
    moment = float(rel[0] * -1.0)  # (com - p_o) x (0, -1)
    return scene_from_dict({
        "name": f"block-h{h}-mu{mu}",
        "dim": 2,
        "object": {"pose": {"position": list(p_o), "angle": 0.0},
                   "shape": {"type": "box", "size": [2 * BOX_A, 2 * BOX_B], "position": rel.tolist()}},
        "external_wrench": [0.0, -1.0, moment],
        "fixed_bodies": [{"name": "table", "shape": {"type": "segment", "points": [[-2.0, 0.0], [2.0, 0.0]]}}],
        "fingers": [{"name": "pusher", "base": {"position": [-BOX_A - 1.0, h], "angle": 0.0},
                     "links": [{"length": 0.6}, {"length": 0.6}], "q": [alpha, -2 * alpha]}],
        "contacts": [
            {"body": "table", "point": [-BOX_C, 0.0], "normal": [0.0, 1.0], "mu": mu},
            {"body": "table", "point": [BOX_C, 0.0], "normal": [0.0, 1.0], "mu": mu},
            {"body": "pusher/1", "point": [-BOX_A, h], "normal": [1.0, 0.0], "mu": 0.0},
        ],
    })


# --------------------------------------------------------------------------------------------
# Independent re-computations


def slip(system: GraspSystem, i: int, motion: Array) -> Array:
    """Slip of the object relative to the finger at contact ``i``: ``dp_C = -A_i [dq; dr]`` (eq. 2)."""
    return -(system.contact_A(i) @ motion)


def effective_grasp_matrix(system: GraspSystem, sel: Selection, G_c: Array, motion: Array) -> Array:
    """``G_c`` plus, in the normal column of every S-point, the wrench of its kinetic friction
    ``-mu s/|s|`` per unit normal force (eq. 11-12) for the motion ``[dq; dr]``."""
    G = np.array(G_c, dtype=float, copy=True)
    for i in sel.s_index:
        s = slip(system, i, motion)
        G[:, sel.c_slices[i].start] += system.G_blocks[i] @ (-system.mu[i] * s / np.linalg.norm(s))
    return G


def full_forces(system: GraspSystem, sel: Selection, f_c: Array, motion: Array | None) -> Array:
    """The force ``(L, d)`` each contact puts on the object: F the vector, N/S ``n_f n`` plus,
    at S-points, kinetic friction ``-mu n_f s/|s|`` for the motion; D nothing."""
    out = np.zeros((system.L, system.d))
    for i, s in enumerate(sel.combination):
        sl = sel.c_slices[i]
        if s == "F":
            out[i] = f_c[sl]
        elif s in "NS":
            n_f = float(f_c[sl][0])
            out[i] = n_f * system.normals[i]
            if s == "S" and motion is not None:
                v = slip(system, i, motion)
                out[i] += -system.mu[i] * n_f * v / np.linalg.norm(v)
    return out


def scipy_lp(
    c: Array,
    A_ub: Array | None = None,
    b_ub: Array | None = None,
    A_eq: Array | None = None,
    b_eq: Array | None = None,
    box: float | None = None,
    maximize: bool = False,
) -> tuple[int, float | None, Array | None]:
    """``linprog`` with free variables (optionally bounded by ``|x_k| <= box``): (status,
    objective in the caller's sense, x). Status 0 optimal, 2 infeasible, 3 unbounded."""
    n = len(c)
    bounds = [(-box, box) if box is not None else (None, None)] * n
    sign = -1.0 if maximize else 1.0
    res = linprog(
        sign * np.asarray(c, dtype=float),
        A_ub=None if A_ub is None or len(A_ub) == 0 else A_ub,
        b_ub=None if A_ub is None or len(A_ub) == 0 else b_ub,
        A_eq=None if A_eq is None or len(A_eq) == 0 else A_eq,
        b_eq=None if A_eq is None or len(A_eq) == 0 else b_eq,
        bounds=bounds,
        method="highs",
    )
    if res.status != 0:
        return int(res.status), None, None
    return 0, sign * float(res.fun), np.asarray(res.x, dtype=float)
