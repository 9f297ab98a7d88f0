"""Full-report JSON of a fixed set of combinations, dumped and compared (issue 13: a faster report
must give the same answers).

    .venv/bin/python benchmarks/report_json.py dump OUT.jsonl      # 261 reports, CPU per report
    .venv/bin/python benchmarks/report_json.py compare A.jsonl B.jsonl [--tol 1e-9]

The set: every one of the 243 combinations of ``examples/planar_disk_envelope.json``, 12 of
``sphere_four_finger_palm`` and 6 of ``allegro_right_box`` (a seeded sample of their feasible
combinations, ``np.random.default_rng(13)``, written out below so that a change of the table does
not change the set). Each line holds the scene, the combination, the report's JSON
(``CombinationReport.to_json``) or the error the analysis raised, and the CPU seconds it took
(not compared). ``compare`` walks both JSON trees: same keys, same list lengths, same strings and
booleans, numbers within ``--tol`` (absolute, or relative to the larger magnitude when that is
above 1); it prints "reports N, differing K" and the first differences, and exits 1 when K > 0.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.combination import analyze_combination  # noqa: E402
from analysis.contacts import build_system  # noqa: E402
from analysis.exceptions import CTPError  # noqa: E402
from analysis.loader import load_scene  # noqa: E402

#: The seeded samples (feasible combinations drawn with ``np.random.default_rng(13)``).
PALM = ("FFSDF", "FFDFF", "FSSSF", "FDFDF", "DFDSS", "DFDDF", "DSFFS", "DSFSS", "DSFDF", "DSSFS", "DDFSF",
        "DDSFS")
ALLEGRO = ("FFSSFS", "SDFDFS", "SDSSDF", "SDDSSF", "DDFSDF", "DDFDSF")


def report_set() -> list[tuple[str, str]]:
    """(scene, combination) of every report compared."""
    planar = ["".join(c) for c in itertools.product("FSD", repeat=5)]
    return ([("planar_disk_envelope", c) for c in planar] + [("sphere_four_finger_palm", c) for c in PALM]
            + [("allegro_right_box", c) for c in ALLEGRO])


def dump(out: Path) -> None:
    systems: dict[str, Any] = {}
    cpu: dict[str, list[float]] = {}
    with out.open("w") as fh:
        for scene, combo in report_set():
            if scene not in systems:
                systems[scene] = build_system(load_scene(ROOT / "examples" / f"{scene}.json"))
                analyze_combination(systems[scene], combo)  # warm-up (imports, CasADi)
            c0 = time.process_time()
            try:
                rep: Any = analyze_combination(systems[scene], combo).to_json()
                err = None
            except CTPError as e:
                rep, err = None, f"{type(e).__name__}: {e}"
            dt = time.process_time() - c0
            cpu.setdefault(scene, []).append(dt)
            fh.write(json.dumps({"scene": scene, "combination": combo, "report": rep, "error": err, "cpu": dt})
                     + "\n")
    for scene, t in cpu.items():
        t = sorted(t)
        print(f"{scene}: {len(t)} reports, CPU mean {1e3 * sum(t) / len(t):.1f} ms, "
              f"p95 {1e3 * t[int(0.95 * (len(t) - 1))]:.1f} ms, max {1e3 * t[-1]:.1f} ms")


def _diff(a: Any, b: Any, path: str, tol: float, out: list[str]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        if a.keys() != b.keys():
            out.append(f"{path}: keys {sorted(a.keys() ^ b.keys())} in one only")
        for k in a.keys() & b.keys():
            _diff(a[k], b[k], f"{path}.{k}", tol, out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{path}: length {len(a)} vs {len(b)}")
            return
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _diff(x, y, f"{path}[{k}]", tol, out)
    elif isinstance(a, bool) or isinstance(b, bool) or isinstance(a, str) or a is None or b is None:
        if a != b:
            out.append(f"{path}: {a!r} vs {b!r}")
    elif isinstance(a, int | float) and isinstance(b, int | float):
        if math.isnan(a) and math.isnan(b):
            return
        if not abs(a - b) <= tol * max(1.0, abs(a), abs(b)):
            out.append(f"{path}: {a!r} vs {b!r}")
    elif a != b:
        out.append(f"{path}: {a!r} vs {b!r}")


def compare(a: Path, b: Path, tol: float, show: int = 20) -> int:
    ra = [json.loads(line) for line in a.read_text().splitlines()]
    rb = [json.loads(line) for line in b.read_text().splitlines()]
    ka = {(r["scene"], r["combination"]): r for r in ra}
    kb = {(r["scene"], r["combination"]): r for r in rb}
    differing = 0
    shown = 0
    for key in ka.keys() | kb.keys():
        if key not in ka or key not in kb:
            differing += 1
            print(f"{key}: in one file only")
            continue
        out: list[str] = []
        _diff({"report": ka[key]["report"], "error": ka[key]["error"]},
              {"report": kb[key]["report"], "error": kb[key]["error"]}, "", tol, out)
        if out:
            differing += 1
            if shown < show:
                shown += 1
                print(f"{key[0]} {key[1]}: {len(out)} differences, first: " + "; ".join(out[:3]))
    print(f"reports {len(ka.keys() | kb.keys())}, differing {differing} (numbers within {tol:g})")
    return differing


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out", type=Path)
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    c.add_argument("--tol", type=float, default=1e-9)
    args = ap.parse_args()
    if args.cmd == "dump":
        dump(args.out)
    else:
        raise SystemExit(1 if compare(args.a, args.b, args.tol) else 0)


if __name__ == "__main__":
    main()
