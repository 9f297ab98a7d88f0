"""Speed of the closure analysis. Prints figures and the machine.

    .venv/bin/python benchmarks/analysis.py            # all figures
    .venv/bin/python benchmarks/analysis.py --quick    # skip the 3^9 enumeration

Figures: enumeration of all 3^L combinations (feasibility + DAFC dimension) of the example
scenes, on one core and with worker processes; the full report of one combination; and the
scaling with the number of contacts (the wrap scene restricted to its first L contacts).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine import machine  # noqa: E402

from analysis.combination import analyze_combination  # noqa: E402
from analysis.contacts import build_system  # noqa: E402
from analysis.enumerate import enumerate_combinations  # noqa: E402
from analysis.loader import load_scene, scene_from_dict  # noqa: E402


def cpu_seconds() -> float:
    """CPU time of this process and its finished children (robust to other load on the machine)."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def time_enum(name: str, workers: int, repeat: int = 1) -> tuple[float, int, int, float]:
    """Best wall time, feasible count, combinations, CPU seconds of that run."""
    sy = build_system(load_scene(ROOT / "examples" / f"{name}.json"))
    times = []
    cpus = []
    feas = n = 0
    for _ in range(repeat):
        c = cpu_seconds()
        t = time.perf_counter()
        res, _ = enumerate_combinations(sy, workers=workers)
        times.append(time.perf_counter() - t)
        cpus.append(cpu_seconds() - c)
        feas, n = sum(r.feasible for r in res), len(res)
    k = int(np.argmin(times))
    return times[k], feas, n, cpus[k]


def time_report(name: str, combination: str, repeat: int = 5) -> float:
    sy = build_system(load_scene(ROOT / "examples" / f"{name}.json"))
    analyze_combination(sy, combination)  # warm-up (imports, CasADi)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        analyze_combination(sy, combination)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def report_distribution(name: str, at_most: int | None = None) -> tuple[float, float, float, int]:
    """Median, 90th percentile and max time of the full report over every feasible combination
    (or a seeded sample of ``at_most`` of them)."""
    sy = build_system(load_scene(ROOT / "examples" / f"{name}.json"))
    res, _ = enumerate_combinations(sy, workers=1)
    feasible = [r for r in res if r.feasible]
    if at_most is not None and len(feasible) > at_most:
        pick = np.random.default_rng(0).choice(len(feasible), at_most, replace=False)
        feasible = [feasible[int(k)] for k in sorted(pick)]
    times = []
    for r in feasible:
        if r.feasible:
            t = time.perf_counter()
            analyze_combination(sy, r.combination)
            times.append(time.perf_counter() - t)
    times.sort()
    return statistics.median(times), times[int(0.9 * (len(times) - 1))], times[-1], len(times)


def twelve_contact_reports() -> list[float]:
    """Wall time of the full report of 15 combinations of the 12-contact wrap."""
    sy = build_system(load_scene(ROOT / "examples" / "sphere_wrap_three_link.json"))
    analyze_combination(sy, "F" * 12)  # warm-up
    rng = np.random.default_rng(0)
    combos = ["F" * 12, "FFSFFSFFSFFD", "SSDSSDSSDSSD", "FFDFFDFFDFFD", "FDDFDDFDDFDD"]
    combos += ["".join(rng.choice(list("FSD"), 12)) for _ in range(10)]
    times = []
    for c in combos:
        t = time.perf_counter()
        analyze_combination(sy, c)
        times.append(time.perf_counter() - t)
    return times


def scaling(max_L: int) -> list[tuple[int, int, float, int]]:
    import json

    data = json.loads((ROOT / "examples" / "sphere_four_finger_wrap.json").read_text())
    # keep the palm (last contact) and the first L-1 finger contacts
    rows = []
    for L in range(3, max_L + 1):
        d = dict(data)
        d["contacts"] = data["contacts"][: L - 1] + data["contacts"][-1:]
        sy = build_system(scene_from_dict(d))
        t = time.perf_counter()
        res, _ = enumerate_combinations(sy, workers=1)
        rows.append((L, len(res), time.perf_counter() - t, sum(r.feasible for r in res)))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="skip the 19,683-combination enumeration")
    args = ap.parse_args()
    print(f"machine: {machine()}")
    print(f"load average before: {os.getloadavg()[0]:.2f} (other work on the machine inflates wall times; "
          "CPU seconds are robust to it)")
    t, f, n, c = time_enum("planar_disk_envelope", workers=1, repeat=3)
    print(f"planar_disk_envelope: all {n} combinations, one core: {t:.2f} s wall, {c:.2f} s CPU ({f} feasible)")
    t, f, n, c = time_enum("sphere_four_finger_palm", workers=1, repeat=3)
    print(f"sphere_four_finger_palm: all {n} combinations, one core: {t:.2f} s wall, {c:.2f} s CPU "
          f"({f} feasible)  [target < 2 s]")
    t = time_report("sphere_four_finger_palm", "FSFSF")
    print(f"sphere_four_finger_palm FSFSF full report: {t:.3f} s  [target < 0.2 s]")
    med, p90, mx, n = report_distribution("sphere_four_finger_palm")
    print(f"sphere_four_finger_palm full report over its {n} feasible combinations: median {med:.3f} s, "
          f"p90 {p90:.3f} s, max {mx:.3f} s")
    t = time_report("planar_disk_envelope", "FDFDD")
    print(f"planar_disk_envelope FDFDD full report: {t:.3f} s")
    print("scaling with the number of contacts (wrap scene, first L-1 finger contacts + palm, one core):")
    for L, n, t, f in scaling(7 if args.quick else 8):
        print(f"  L = {L}: {n:5d} combinations  {t:7.2f} s  {1e3 * t / n:6.2f} ms/combination  ({f} feasible)")
    t, f, n, c = time_enum("baxter_hug_box", workers=1)
    print(f"baxter_hug_box (two URDF arms hugging a box on a table): all {n} combinations, one core: "
          f"{t:.2f} s wall, {c:.2f} s CPU ({f} feasible)")
    med, p90, mx, n = report_distribution("baxter_hug_box", at_most=40)
    print(f"baxter_hug_box full report over {n} of its feasible combinations (seeded sample): median {med:.3f} s, "
          f"p90 {p90:.3f} s, max {mx:.3f} s")
    twelve = twelve_contact_reports()
    print(f"sphere_wrap_three_link (12 contacts) full report, {len(twelve)} combinations (all F, 4 patterns, "
          f"10 seeded random): median {statistics.median(twelve):.3f} s, max {max(twelve):.3f} s  [target < 1 s]")
    if not args.quick:
        cores = os.cpu_count() or 1
        t, f, n, c = time_enum("sphere_four_finger_wrap", workers=cores)
        print(f"sphere_four_finger_wrap: all {n} combinations, {cores} processes: {t:.1f} s wall, "
              f"{c:.1f} s CPU in total ({f} feasible)  [target < 5 s]")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
