"""Speed of the contact-state planner. Prints figures and the machine.

    .venv/bin/python benchmarks/planning.py                 # planar example (target < 0.5 s)
    .venv/bin/python benchmarks/planning.py --sphere        # also the 3-D sphere (target < 5 s)
    .venv/bin/python benchmarks/planning.py --repeat 3
    .venv/bin/python benchmarks/planning.py --slide         # also a pose goal reached by sliding
    .venv/bin/python benchmarks/planning.py --lift          # also the two-arm 3 cm box lift (target < 60 s)
    .venv/bin/python benchmarks/planning.py --wrap          # also the nine-contact wrap (target: a plan < 60 s)
    .venv/bin/python benchmarks/planning.py --roll          # also a sphere rolled 5 cm on a table (3-D rolling)
    .venv/bin/python benchmarks/planning.py --link-roll     # also a sphere rolled on a link's side (effort weight 0)
    .venv/bin/python benchmarks/planning.py --all           # every scene above

For each scene: whether a plan to active closure was found, its steps, nodes expanded and
generated, lazy edges checked, and the time split between the closure analysis, OMPL (transfer
planning and certified collision checks), IK (CasADi), object-motion integration and the rest
(graph search and bookkeeping). Times are wall-clock and, beside them, the process's CPU time
(user + sys), which a busy shared machine changes less; the machine's load average is printed
before and after each scene. Each found plan is re-checked by ``planner.verify.verify_plan``
(outside the timing).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine import machine  # noqa: E402

from analysis.loader import load_scene  # noqa: E402
from planner import Goal, plan  # noqa: E402
from planner.options import PlannerOptions  # noqa: E402
from planner.verify import verify_plan  # noqa: E402


def load() -> str:
    """The 1-minute load average of the machine (others share its cores)."""
    return f"{os.getloadavg()[0]:.2f}"


def run(name: str, target: float, repeat: int, time_limit: float | None, goal: Goal | None = None,
        options: PlannerOptions | None = None) -> None:
    scene = load_scene(ROOT / "examples" / f"{name}.json")
    goal = goal or Goal(type="active")
    totals = []
    cpus = []
    last = None
    load_before = load()
    for _ in range(repeat):
        c0 = time.process_time()
        p = plan(scene, goal, time_limit=time_limit, options=options)
        cpus.append(time.process_time() - c0)
        totals.append(p.stats.seconds_total)
        last = p
    assert last is not None
    load_after = load()
    s = last.stats
    print(f"\n{name}, goal {goal.model_dump(exclude_none=True)}: found={last.found} steps={len(last.steps)} "
          f"({', '.join(st.transition.kind + ' ' + st.transition.combination for st in last.steps)})")
    if not last.found:
        print(f"  reason: {last.reason}")
    print(f"  time to plan: median {statistics.median(totals):.2f} s over {repeat} run(s) "
          f"(min {min(totals):.2f}, max {max(totals):.2f}) "
          f"(target < {target:g} s: {'met' if statistics.median(totals) < target else 'NOT met'}); "
          f"CPU (user + sys) median {statistics.median(cpus):.2f} s")
    print(f"  nodes expanded {s.nodes_expanded}, generated {s.nodes_generated}, lazy edges checked "
          f"{s.lazy_edges_checked}; load average {load_before} before, {load_after} after")
    print(f"  analysis {s.seconds_analysis:.2f} s | OMPL {s.seconds_ompl:.2f} s | IK {s.seconds_ik:.2f} s | "
          f"object motion {s.seconds_motion:.2f} s | search+rest {s.seconds_search:.2f} s")
    if last.found:
        print(f"  cost {last.cost:.6f}; verify_plan: {verify_plan(scene, last) or 'no problem'}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--sphere", action="store_true", help="also plan for sphere_four_finger_palm")
    ap.add_argument("--slide", action="store_true",
                    help="also the planar pose goal (0.1, 0.5, 0) reached by sliding the disk on the palm")
    ap.add_argument("--lift", action="store_true", help="also the two-arm lift of baxter_hug_box (3 cm)")
    ap.add_argument("--wrap", action="store_true", help="also sphere_four_finger_wrap to active closure (9 contacts)")
    ap.add_argument("--roll", action="store_true",
                    help="also sphere_table_roll: a finger rolls the sphere 5 cm along the table (no sliding)")
    ap.add_argument("--link-roll", action="store_true",
                    help="also sphere_link_roll: a link's side rolls the sphere 5 cm along the table (no sliding, "
                         "effort weight 0 as ctp plan --effort-weight 0)")
    ap.add_argument("--all", action="store_true",
                    help="every scene: --sphere --slide --lift --wrap --roll --link-roll")
    ap.add_argument("--time-limit", type=float, default=None)
    args = ap.parse_args()
    print("machine:", machine())
    run("planar_disk_envelope", 0.5, args.repeat, args.time_limit)
    if args.slide or args.all:
        run("planar_disk_envelope", 5.0, args.repeat, args.time_limit,
            Goal(type="pose", pose=[0.1, 0.5, 0.0], tolerance=0.02))
    if args.sphere or args.all:
        run("sphere_four_finger_palm", 5.0, args.repeat, args.time_limit or 120.0)
    if args.lift or args.all:  # two arms lift the box 3 cm off the table (position within 5 mm, rotation 0.3 rad)
        run("baxter_hug_box", 60.0, args.repeat, args.time_limit or 300.0,
            Goal(type="displacement", displacement=[0.0, 0.0, 0.03, 0.0, 0.0, 0.0], position_tolerance=0.005,
                 rotation_tolerance=0.3))
    if args.wrap or args.all:
        run("sphere_four_finger_wrap", 60.0, args.repeat, args.time_limit or 300.0)
    if args.roll or args.all:  # rolling in 3-D: the table contact rolls in every object motion
        run("sphere_table_roll", 10.0, args.repeat, args.time_limit or 120.0,
            Goal(type="displacement", displacement=[0.05, 0.0, 0.0, 0.0, 0.0, 0.0], position_tolerance=0.005,
                 rotation_tolerance="free"), PlannerOptions(sliding_motions=False))
    if args.link_roll or args.all:  # rolling on a moving link's side (planner/link_roll.py)
        run("sphere_link_roll", 10.0, args.repeat, args.time_limit or 120.0,
            Goal(type="displacement", displacement=[0.05, 0.0, 0.0, 0.0, 0.0, 0.0], position_tolerance=0.005,
                 rotation_tolerance="free"), PlannerOptions(sliding_motions=False, effort_weight=0.0))


if __name__ == "__main__":
    main()
