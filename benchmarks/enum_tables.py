"""Whole enumeration tables of example scenes, dumped for before/after comparisons, with CPU seconds.

    .venv/bin/python benchmarks/enum_tables.py --out /tmp/tables.json [--workers 1] [--no-symmetric-empty] [scene ...]
    .venv/bin/python benchmarks/enum_tables.py --compare /tmp/before.json /tmp/after.json

Each row: combination, verdict, DAFC dimension, exactness, reason (and a, a~, dim DPFC). The
comparison prints the rows whose verdict, DAFC dimension or exactness differ (and, apart, the rows
whose reason text differs). CPU seconds: this process and its finished children (robust to other
load on a shared machine); the wall time is printed too, with the machine.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine import machine  # noqa: E402

from analysis.contacts import build_system  # noqa: E402
from analysis.enumerate import enumerate_combinations  # noqa: E402
from analysis.loader import load_scene  # noqa: E402

SCENES = ["sphere_four_finger_wrap", "planar_disk_envelope", "sphere_four_finger_palm", "baxter_hug_box"]


def cpu_seconds() -> float:
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def dump(scenes: list[str], workers: int, symmetric_empty: bool = True) -> dict[str, object]:
    out: dict[str, object] = {"machine": machine()}
    for name in scenes:
        sy = build_system(load_scene(ROOT / "examples" / f"{name}.json"))
        c0, t0 = cpu_seconds(), time.perf_counter()
        rows, st = enumerate_combinations(sy, workers=workers, symmetric_empty=symmetric_empty)
        cpu, wall = cpu_seconds() - c0, time.perf_counter() - t0
        print(f"{name}: {len(rows)} combinations, {sum(r.feasible for r in rows)} feasible, "
              f"CPU {cpu:.1f} s, wall {wall:.1f} s (workers={workers}), {st.lps} LPs "
              f"({st.dafc_searched} own DAFC searches, {st.dafc_shared} shared, {st.dafc_mirrored} at a symmetric "
              f"row's member, {st.dafc_mirrored_empty} empty as a symmetric row)", flush=True)
        out[name] = {"cpu": cpu, "wall": wall, "lps": st.lps, "rows": [
            [r.combination, r.feasible, r.dim_dafc, r.exact, r.reason, r.a, r.a_bar, r.dim_dpfc] for r in rows]}
    return out


def compare(before: dict[str, dict[str, list[list[object]]]], after: dict[str, dict[str, list[list[object]]]]) -> int:
    total = 0
    for name in [k for k in before if k != "machine" and k in after]:
        b = {r[0]: r for r in before[name]["rows"]}
        a = {r[0]: r for r in after[name]["rows"]}
        if set(a) != set(b):
            print(f"{name}: the combinations differ")
            total += 1
            continue
        diff = [c for c in b if b[c][1:4] != a[c][1:4] or b[c][5:] != a[c][5:]]
        reason = [c for c in b if c not in diff and b[c][4] != a[c][4]]
        total += len(diff)
        print(f"{name}: {len(b)} rows, {len(diff)} differ in verdict/dim/exact, {len(reason)} in the reason text only")
        for c in diff[:20]:
            print("  ", b[c], "->", a[c])
        for c in reason[:5]:
            print("   reason:", b[c][4], "->", a[c][4])
    return total


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--out")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--compare", nargs=2)
    ap.add_argument("--no-symmetric-empty", dest="symmetric_empty", action="store_false",
                    help="every row its own DAFC search: no proven emptiness carried to symmetric rows "
                         "(enumerate_combinations(symmetric_empty=False))")
    args = ap.parse_args()
    if args.compare:
        before, after = (json.loads(Path(p).read_text()) for p in args.compare)
        sys.exit(1 if compare(before, after) else 0)
    print(machine())
    out = dump(args.scenes, args.workers, args.symmetric_empty)
    if args.out:
        Path(args.out).write_text(json.dumps(out))


if __name__ == "__main__":
    main()
