"""Speed of the kinematic contact-mode enumeration (analysis/modes.py).

Run: ``.venv/bin/python benchmarks/modes.py [--max-modes N] [--repeat R] [--quick]``.

Prints the machine, then the cube against 1-5 planes of Huang, Cheng & Mason (WAFR 2020) with
their published contacting/separating counts and the wall time of ``ctp modes`` on the 20-contact
cube in five planes (a new process, start-up included), then for the example scenes and for
synthetic scenes of growing size:
the number of contacts ``L``, joints ``M``, contacting/separating modes (``cs``), stick/slide
categories (``cat``), sticking/sliding modes (``ss``; ``+`` when ``--max-modes`` stopped the
listing), LPs solved, seconds (best of ``--repeat``), LPs per mode, and the brute-force pattern
counts ``2^L`` / ``3^L`` an exhaustive enumeration would test. The scaling summary fits
``seconds ~ modes^a`` and ``LPs ~ modes^b`` over each synthetic family (output-sensitive: ``a, b``
near 1, independent of ``2^L``).
"""

from __future__ import annotations

from machine import machine  # first: it pins the BLAS kernel before numpy loads (analysis/blas.py)

# isort: split
import argparse
import importlib.metadata
import json
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "helpers"))  # cube_planes: the scenes of the published counts

from cube_planes import PUBLISHED_CS_COUNTS, cube_in_planes  # noqa: E402

from analysis.contacts import GraspSystem, build_system, system_from_arrays  # noqa: E402
from analysis.loader import load_scene, scene_from_dict  # noqa: E402
from analysis.modes import ModeEnumeration, enumerate_modes  # noqa: E402

Array = NDArray[np.float64]
EXAMPLES = ROOT / "examples"


def system_from(points: Array, normals: Array, p_o: Array, J_blocks: Array) -> GraspSystem:
    return system_from_arrays(points, normals, p_o, J_blocks)


def box_on_table_2d(L: int) -> GraspSystem:
    """A planar box on ``L`` collinear table contacts (no fingers): 4 contacting/separating
    modes whatever ``L``, among ``2^L`` sign vectors."""
    xs = np.linspace(-1.0, 1.0, L)
    pts = np.stack([xs, np.zeros(L)], axis=1)
    return system_from(pts, np.tile([0.0, 1.0], (L, 1)), np.array([0.0, 0.5]), np.zeros((L, 2, 0)))


def box_on_table_3d(k: int) -> GraspSystem:
    """A box on a ``k x k`` grid of table contacts (no fingers)."""
    g = np.linspace(-0.5, 0.5, k)
    pts = np.array([[x, y, 0.0] for x in g for y in g])
    L = len(pts)
    return system_from(pts, np.tile([0.0, 0.0, 1.0], (L, 1)), np.array([0.0, 0.0, 0.5]), np.zeros((L, 3, 0)))


def disk_one_joint_fingers(L: int) -> GraspSystem:
    """A disk touched by ``L`` one-joint planar fingers (inclined links, tip contacts) and a
    table: every contact can separate, so modes grow like ``2^L`` and more."""
    pts: list[Array] = []
    nrm: list[Array] = []
    J = np.zeros((L + 1, 2, L))
    for i in range(L):
        th = np.pi * (i + 0.5) / L
        p = np.array([np.cos(th), np.sin(th)])
        u = np.array([np.cos(th + 1.0), np.sin(th + 1.0)])  # link direction, 1 rad off the normal
        base = p + 0.8 * u
        r = p - base
        J[i, :, i] = [-r[1], r[0]]  # revolute joint about z at the base
        pts.append(p)
        nrm.append(-p)
    pts.append(np.array([0.0, -1.0]))
    nrm.append(np.array([0.0, 1.0]))
    return system_from(np.array(pts), np.array(nrm), np.zeros(2), J)


def sphere_fingertips(L: int) -> GraspSystem:
    """A sphere on a palm with ``L`` fingertips of 3-joint fingers: free contacts (factored)."""
    rng = np.random.default_rng(L)
    pts: list[Array] = [np.array([0.0, 0.0, -1.0])]
    nrm: list[Array] = [np.array([0.0, 0.0, 1.0])]
    J = np.zeros((L + 1, 3, 3 * L))
    for i in range(L):
        th = 2 * np.pi * i / L
        p = np.array([np.cos(th) * 0.8, np.sin(th) * 0.8, 0.6])
        p /= np.linalg.norm(p)
        pts.append(p)
        nrm.append(-p)
        J[i + 1, :, 3 * i : 3 * i + 3] = rng.normal(size=(3, 3))
    return system_from(np.array(pts), np.array(nrm), np.zeros(3), J)


def run(system: GraspSystem, max_modes: int | None, repeat: int) -> tuple[ModeEnumeration, float]:
    best = np.inf
    e = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        e = enumerate_modes(system, max_modes=max_modes)
        best = min(best, time.perf_counter() - t0)
    assert e is not None
    return e, float(best)


HEADER = (
    f"{'case':<34} {'L':>3} {'M':>3} {'cs':>6} {'cat':>7} {'ss':>9} {'LPs':>8} {'s':>8} "
    f"{'LP/mode':>8} {'2^L':>7} {'3^L':>9}"
)


def row(name: str, system: GraspSystem, e: ModeEnumeration, secs: float) -> str:
    modes = e.n_contacting_separating + e.n_categories + e.n_sticking_sliding
    ss = f"{e.n_sticking_sliding}{'' if e.sticking_sliding_complete else '+'}"
    return (
        f"{name:<34} {system.L:>3} {system.M:>3} {e.n_contacting_separating:>6} {e.n_categories:>7} {ss:>9} "
        f"{e.lp_count:>8} {secs:>8.3f} {e.lp_count / modes:>8.2f} {2**system.L:>7} {3**system.L:>9}"
    )


def ctp_modes_seconds(scene: dict[str, object]) -> float:
    """Wall seconds of ``ctp modes SCENE`` in a new process (the command a user runs)."""
    ctp = Path(sys.executable).with_name("ctp")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scene.json"
        path.write_text(json.dumps(scene))
        t0 = time.perf_counter()
        subprocess.run([str(ctp), "modes", str(path)], check=True, capture_output=True)
        return time.perf_counter() - t0


def fit(xs: Sequence[float], ys: Sequence[float]) -> float:
    """Slope of log y against log x (least squares); nan when x does not vary."""
    lx, ly = np.log(np.maximum(xs, 1e-12)), np.log(np.maximum(ys, 1e-12))
    return float(np.polyfit(lx, ly, 1)[0]) if np.ptp(lx) > 1e-9 else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-modes", type=int, default=200_000, help="cap on listed sticking/sliding modes")
    ap.add_argument("--repeat", type=int, default=1, help="best of this many runs")
    ap.add_argument("--quick", action="store_true", help="smaller synthetic families")
    args = ap.parse_args()

    print("machine:", machine())
    hv = importlib.metadata.version("highspy")
    print("python", platform.python_version(), "| numpy", np.__version__, "| highspy", hv)
    print(f"max_modes={args.max_modes} (listing cap for sticking/sliding modes; '+' = capped)\n")

    print("cube against k planes (floor, walls x-, y-, x+, y+; 4 corner contacts a plane); pub = published cs")
    print(HEADER, f"{'pub':>5}")
    for k, published in enumerate(PUBLISHED_CS_COUNTS, start=1):
        system = build_system(scene_from_dict(cube_in_planes(k)))
        e, secs = run(system, args.max_modes, args.repeat)
        print(row(f"  {k} planes", system, e, secs), f"{published:>5}",
              "ok" if e.n_contacting_separating == published else "MISMATCH")
    print(f"  ctp modes on the 20-contact cube in five planes: {ctp_modes_seconds(cube_in_planes(5)):.2f} s wall "
          "(one process, imports included; target < 10 s)\n")

    print("examples")
    print(HEADER)
    for name in ("planar_disk_envelope", "sphere_four_finger_palm", "sphere_four_finger_wrap"):
        system = build_system(load_scene(EXAMPLES / f"{name}.json"))
        e, secs = run(system, args.max_modes, args.repeat)
        print(row(name, system, e, secs), f" free={list(e.free_contacts)} lps={e.lp_counts}")

    families: dict[str, tuple[Callable[[int], GraspSystem], list[int]]] = {
        "box on table 2-D (L collinear)": (box_on_table_2d, [2, 4, 8, 16, 32] if not args.quick else [2, 4, 8]),
        "box on table 3-D (k x k grid)": (box_on_table_3d, [2, 3, 4, 5] if not args.quick else [2, 3]),
        "disk + L one-joint fingers 2-D": (disk_one_joint_fingers, [1, 2, 3, 4, 5, 6] if not args.quick else [1, 2, 3]),
        "sphere + L free fingertips 3-D": (sphere_fingertips, [1, 2, 3, 4] if not args.quick else [1, 2]),
    }
    summary = []
    for fam, (make, sizes) in families.items():
        print(f"\n{fam}")
        print(HEADER)
        modes: list[float] = []
        lps: list[float] = []
        secs_l: list[float] = []
        per_lm: list[float] = []
        for k in sizes:
            system = make(k)
            e, secs = run(system, args.max_modes, args.repeat)
            print(row(f"  size {k}", system, e, secs))
            n_modes = e.n_contacting_separating + e.n_categories + e.n_sticking_sliding
            modes.append(n_modes)
            lps.append(e.lp_count)
            secs_l.append(secs)
            per_lm.append(e.lp_count / (system.L * n_modes))
        summary.append((fam, fit(modes, secs_l), fit(modes, lps), max(per_lm), secs_l[-1] / modes[-1] * 1e6))
    print("\nscaling per family: log-log slopes seconds ~ modes^a and LPs ~ modes^b (nan: modes constant);")
    print("LPs / (L * modes) stays bounded when the search is output-sensitive (the bound is O(L * modes))")
    for fam, a, b, lplm, usm in summary:
        print(f"  {fam:<34} a={a:5.2f} b={b:5.2f}  max LPs/(L*modes)={lplm:.2f}  largest: {usm:.0f} us/mode")

if __name__ == "__main__":
    main()
