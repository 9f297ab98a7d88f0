"""Speed of the closure analysis. Prints figures and the machine.

    .venv/bin/python benchmarks/analysis.py            # all figures
    .venv/bin/python benchmarks/analysis.py --quick    # skip the 3^9 enumeration
    .venv/bin/python benchmarks/analysis.py --planar-reports [--repeat 3]   # CPU per planar report only
    .venv/bin/python benchmarks/analysis.py --planar-sets   # sampled DAFC directions: one by one vs test_many
    .venv/bin/python benchmarks/analysis.py --twelve   # also the full 3^12 feasible list (minutes)

Figures: enumeration of all 3^L combinations (feasibility + DAFC dimension) of the example
scenes, on one core and with worker processes, with CPU seconds (robust to other load on a shared
machine) and LPs solved; the full report of one combination; the scaling with the number of
contacts (the wrap scene restricted to its first L contacts); the 12-contact wrap (reports, and
its enumeration on a seeded sample with the projection to all 3^12 combinations); the contact
modes of the cube in five planes (20 contacts). Issue 9's targets are printed in brackets.

``--planar-reports``: the CPU of the full report (``analyze_combination(...).to_json()``, default
samples) of every one of the 243 planar combinations, mean and p95, and of the first 200 (the
light requests of ``benchmarks/service.py --scenario mixed``, which by Little's law wait about
20 clients x that mean / 2 workers). Best of ``--repeat`` runs per combination (one process).
"""

from __future__ import annotations

from machine import machine  # first: it pins the BLAS kernel before numpy loads (analysis/blas.py)

# isort: split
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

from analysis.combination import analyze_combination  # noqa: E402
from analysis.contacts import build_system  # noqa: E402
from analysis.enumerate import EnumerationStats, enumerate_combinations  # noqa: E402
from analysis.loader import load_scene, scene_from_dict  # noqa: E402


def cpu_seconds() -> float:
    """CPU time of this process and its finished children (robust to other load on the machine)."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


LAST_STATS: list[EnumerationStats] = []


def time_enum(name: str, workers: int, repeat: int = 1, symmetric_empty: bool = True
              ) -> tuple[float, int, int, float, int]:
    """Best wall time, feasible count, combinations, CPU seconds and LPs solved of that run (its
    statistics in ``LAST_STATS``); ``symmetric_empty``: :func:`enumerate_combinations`' option."""
    sy = build_system(load_scene(ROOT / "examples" / f"{name}.json"))
    times = []
    cpus = []
    feas = n = lps = 0
    for _ in range(repeat):
        c = cpu_seconds()
        t = time.perf_counter()
        res, st = enumerate_combinations(sy, workers=workers, symmetric_empty=symmetric_empty)
        times.append(time.perf_counter() - t)
        cpus.append(cpu_seconds() - c)
        feas, n, lps = sum(r.feasible for r in res), len(res), st.stationary_lps + st.dafc_lps
        LAST_STATS[:] = [st]
    k = int(np.argmin(times))
    return times[k], feas, n, cpus[k], lps


def how(st: EnumerationStats) -> str:
    """How the DAFC rows were decided."""
    return (f"{st.dafc_searched} own DAFC searches, {st.dafc_shared} rows by a stronger row's member "
            f"({st.dafc_batched} of the LPs at its motion, batched; {st.dafc_mirrored} rows at a symmetric row's "
            f"member{f', {st.dafc_mirrored_empty} empty as a symmetric row' if st.dafc_mirrored_empty else ''})")


def time_report(name: str, combination: str, repeat: int = 5) -> tuple[float, float]:
    """Median wall and CPU seconds of the full report of one combination."""
    sy = build_system(load_scene(ROOT / "examples" / f"{name}.json"))
    analyze_combination(sy, combination)  # warm-up (imports, CasADi)
    times, cpus = [], []
    for _ in range(repeat):
        c = time.process_time()
        t = time.perf_counter()
        analyze_combination(sy, combination)
        times.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    return statistics.median(times), statistics.median(cpus)


def twelve_contact_sample(n: int = 1500) -> tuple[int, float, float, int, int]:
    """The 12-contact wrap's enumeration on a seeded sample of ``n`` of its 3^12 combinations (one
    process): (n, wall s, CPU s, LPs, feasible). Per-combination cost times 531,441 is what the
    full feasible list would cost."""
    sy = build_system(load_scene(ROOT / "examples" / "sphere_wrap_three_link.json"))
    rng = np.random.default_rng(0)
    combos = sorted({"".join(rng.choice(list("FSD"), sy.L)) for _ in range(n)})
    c = time.process_time()
    t = time.perf_counter()
    res, st = enumerate_combinations(sy, combinations=combos, workers=1)
    return len(combos), time.perf_counter() - t, time.process_time() - c, st.stationary_lps + st.dafc_lps, sum(
        r.feasible for r in res)


def cube_modes() -> tuple[float, float, int, float]:
    """Contact modes of the cube in five planes (20 contacts): in-process wall and CPU seconds, LPs,
    and the wall seconds of ``ctp modes`` in a new process (imports included)."""
    sys.path.insert(0, str(ROOT / "tests" / "helpers"))
    from cube_planes import cube_in_planes
    from modes import ctp_modes_seconds

    from analysis.modes import enumerate_modes

    sy = build_system(scene_from_dict(cube_in_planes(5)))
    c = time.process_time()
    t = time.perf_counter()
    e = enumerate_modes(sy, refine=False)
    return time.perf_counter() - t, time.process_time() - c, e.lp_count, ctp_modes_seconds(cube_in_planes(5))


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


def planar_report_cpu(repeat: int = 1) -> dict[str, float]:
    """CPU seconds of the full report (JSON included) of every planar combination, in the order
    of the table (best of ``repeat`` passes over all of them). Each report starts without built
    IPOPT solvers, as a service worker's request for a combination it has not seen does."""
    import itertools

    from analysis.solvers.casadi_nlp import _solvers

    sy = build_system(load_scene(ROOT / "examples" / "planar_disk_envelope.json"))
    combos = ["".join(c) for c in itertools.product("FSD", repeat=sy.L)]
    analyze_combination(sy, combos[0]).to_json()  # warm-up (imports, CasADi)
    best = {c: np.inf for c in combos}
    for _ in range(repeat):
        for c in combos:
            _solvers().clear()
            t = time.process_time()
            analyze_combination(sy, c).to_json()
            best[c] = min(best[c], time.process_time() - t)
    return best


def _mean_p95(values: list[float]) -> tuple[float, float]:
    v = sorted(values)
    return sum(v) / len(v), v[int(0.95 * (len(v) - 1))]


def print_planar_reports(repeat: int) -> None:
    cpu = planar_report_cpu(repeat)
    every = list(cpu.values())
    first = every[:200]
    m, p = _mean_p95(every)
    m2, p2 = _mean_p95(first)
    print(f"planar_disk_envelope full report CPU (best of {repeat}), all {len(every)} combinations: mean "
          f"{1e3 * m:.1f} ms, p95 {1e3 * p:.1f} ms, max {1e3 * max(every):.1f} ms; the first 200 (the service's "
          f"mixed light requests): mean {1e3 * m2:.1f} ms, p95 {1e3 * p2:.1f} ms  [about 20 ms for a light p95 "
          "under 400 ms]")


def planar_sampled_sets() -> tuple[float, float, int]:
    """CPU seconds of the sampled DAFC directions of the first 200 planar combinations (those the
    report samples, before the refinement), tested one at a time (``DAFCOracle.test``) and all at
    once (``DAFCOracle.test_many``), each on a fresh oracle that has run ``dafc_nonempty`` first
    as in a report; the two orders alternate per combination. Returns both totals and the number
    of directions whose answers differ (membership, reason or work beyond 1e-9: should be 0)."""
    import itertools

    from analysis.combination import CombinationParts
    from analysis.dafc import dafc_nonempty, default_samples, sample_directions

    sy = build_system(load_scene(ROOT / "examples" / "planar_disk_envelope.json"))
    combos = ["".join(c) for c in itertools.product("FSD", repeat=sy.L)][:200]
    one = many = 0.0
    differ = 0
    for k, c in enumerate(combos):
        parts = CombinationParts.build(sy, c)
        if parts.ms.a_bar == 0:
            continue
        U = sample_directions(parts.ms, default_samples(parts.ms.a_bar))
        answers = {}
        for batched in ((False, True) if k % 2 else (True, False)):
            oracle = parts.oracle()
            dafc_nonempty(oracle)
            t = time.process_time()
            answers[batched] = (oracle.test_many(U) if batched else
                                [oracle.test(parts.ms.Lambda_r_t @ u, witness=False) for u in U])
            dt = time.process_time() - t
            many, one = (many + dt, one) if batched else (many, one + dt)
        for a, b in zip(answers[False], answers[True], strict=True):
            if (a.member, a.reason) != (b.member, b.reason) or not np.allclose(a.work, b.work, rtol=1e-9, atol=1e-9,
                                                                               equal_nan=True):
                differ += 1
    return one, many, differ


def twelve_contact_reports() -> list[float]:
    """Wall time of the full report of 15 combinations of the 12-contact wrap (SSDDSSSDFDDF, the
    fifth random one, once aborted the process in cdd's matrix_canonicalize)."""
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
    ap.add_argument("--planar-reports", action="store_true", help="only the CPU per planar full report")
    ap.add_argument("--repeat", type=int, default=1, help="--planar-reports: passes (best per combination)")
    ap.add_argument("--planar-sets", action="store_true",
                    help="only the sampled DAFC directions of the planar reports, one at a time and test_many")
    ap.add_argument("--twelve", action="store_true", help="also the full feasible list of the 12-contact wrap")
    args = ap.parse_args()
    print(f"machine: {machine()}")
    print(f"load average before: {os.getloadavg()[0]:.2f} (other work on the machine inflates wall times; "
          "CPU seconds are robust to it)")
    if args.planar_reports:
        print_planar_reports(args.repeat)
        print(f"load average after: {os.getloadavg()[0]:.2f}")
        return
    if args.planar_sets:
        one, many, differ = planar_sampled_sets()
        print(f"planar_disk_envelope sampled DAFC directions of the first 200 combinations (CPU, fresh oracles, "
              f"orders alternating): one at a time {one:.3f} s, test_many {many:.3f} s; {differ} answers differ")
        print(f"load average after: {os.getloadavg()[0]:.2f}")
        return
    t, f, n, c, lps = time_enum("planar_disk_envelope", workers=1, repeat=3)
    print(f"planar_disk_envelope: all {n} combinations, one core: {t:.2f} s wall, {c:.2f} s CPU, {lps} LPs "
          f"({f} feasible)")
    t, f, n, c, lps = time_enum("sphere_four_finger_palm", workers=1, repeat=3)
    print(f"sphere_four_finger_palm: all {n} combinations, one core: {t:.2f} s wall, {c:.2f} s CPU, {lps} LPs "
          f"({f} feasible)  [target < 2 s]")
    t, c = time_report("sphere_four_finger_palm", "FSFSF")
    print(f"sphere_four_finger_palm FSFSF full report: {t:.3f} s wall, {c:.3f} s CPU  [target < 0.2 s]")
    med, p90, mx, n = report_distribution("sphere_four_finger_palm")
    print(f"sphere_four_finger_palm full report over its {n} feasible combinations: median {med:.3f} s, "
          f"p90 {p90:.3f} s, max {mx:.3f} s")
    t, c = time_report("planar_disk_envelope", "FDFDD")
    print(f"planar_disk_envelope FDFDD full report: {t:.3f} s wall, {c:.3f} s CPU")
    print_planar_reports(1)
    print("scaling with the number of contacts (wrap scene, first L-1 finger contacts + palm, one core):")
    for L, n, t, f in scaling(7 if args.quick else 8):
        print(f"  L = {L}: {n:5d} combinations  {t:7.2f} s  {1e3 * t / n:6.2f} ms/combination  ({f} feasible)")
    t, f, n, c, lps = time_enum("baxter_hug_box", workers=1)
    print(f"baxter_hug_box (two URDF arms hugging a box on a table): all {n} combinations, one core: "
          f"{t:.2f} s wall, {c:.2f} s CPU, {lps} LPs ({f} feasible)")
    med, p90, mx, n = report_distribution("baxter_hug_box", at_most=40)
    print(f"baxter_hug_box full report over {n} of its feasible combinations (seeded sample): median {med:.3f} s, "
          f"p90 {p90:.3f} s, max {mx:.3f} s")
    twelve = twelve_contact_reports()
    print(f"sphere_wrap_three_link (12 contacts) full report, {len(twelve)} combinations (all F, 4 patterns, "
          f"10 seeded random): median {statistics.median(twelve):.3f} s, max {max(twelve):.3f} s wall  "
          "[target < 1 s]")
    w, c, lps, cli = cube_modes()
    print(f"cube in five planes (20 contacts) contact modes: {w:.3f} s wall, {c:.3f} s CPU, {lps} LPs in process; "
          f"ctp modes (new process, imports included): {cli:.2f} s wall  [target < 10 s]")
    n, w, c, lps, f = twelve_contact_sample(300 if args.quick else 1500)
    print(f"sphere_wrap_three_link enumeration of {n} seeded combinations, one core: {w:.1f} s wall, {c:.1f} s CPU, "
          f"{lps} LPs ({f} feasible); x 531,441 / {n}: {c * 531441 / n:.0f} s CPU for the full list (an upper bound: "
          "a sparse sample shares few DAFC members; --twelve runs the full list)  [target < 60 s]")
    if not args.quick:
        cores = os.cpu_count() or 1
        t, f, n, c, lps = time_enum("sphere_four_finger_wrap", workers=cores)
        print(f"sphere_four_finger_wrap: all {n} combinations, {cores} processes: {t:.1f} s wall, "
              f"{c:.1f} s CPU in total, {lps} LPs ({f} feasible; {how(LAST_STATS[0])})  [target < 5 s]")
        t, f, n, c, lps = time_enum("sphere_four_finger_wrap", workers=cores, symmetric_empty=False)
        print(f"sphere_four_finger_wrap, every proven-empty row's image searched too (symmetric_empty=False): "
              f"{cores} processes: {t:.1f} s wall, {c:.1f} s CPU in total, {lps} LPs ({f} feasible; "
              f"{how(LAST_STATS[0])})")
    if args.twelve:
        cores = os.cpu_count() or 1
        for option in (True, False):
            t, f, n, c, lps = time_enum("sphere_wrap_three_link", workers=cores, symmetric_empty=option)
            print(f"sphere_wrap_three_link (12 contacts){'' if option else ', symmetric_empty=False'}: the feasible "
                  f"list of all {n} combinations, {cores} processes: {t:.1f} s wall, {c:.1f} s CPU in total, {lps} "
                  f"LPs ({f} feasible; {how(LAST_STATS[0])}){'  [target < 60 s]' if option else ''}")
    print(f"load average after: {os.getloadavg()[0]:.2f} ({Path('/proc/loadavg').read_text().strip()})")


if __name__ == "__main__":
    main()
