"""``ctp``: the command-line tool.

Bad input (a malformed scene, a wrong combination string, an unparsable direction) prints one
line naming the field and exits with code 2.

The analysis is imported at the top; the planner (OMPL, about 1.5 s), MuJoCo (1 s) and the batch
runner (Ray, about 4 s) and matplotlib are imported inside the commands that use them, so
``ctp analyze`` and ``ctp --help`` do not wait for them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any, NoReturn

import numpy as np
import typer
from pydantic import ValidationError
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from analysis.combination import analyze_combination
from analysis.contacts import build_system
from analysis.dafc import SEMANTICS
from analysis.detect import DEFAULT_MU, DEFAULT_TOLERANCE, NEAR_FACTOR
from analysis.enumerate import enumerate_combinations, parse_where
from analysis.exceptions import CTPError, SceneError
from analysis.geometry import object_size
from analysis.loader import load_scene, read_scene_data, scene_from_dict, with_detected_contacts
from analysis.modes import combination_admissible, enumerate_modes
from analysis.placement import placed_scene_data
from analysis.quality import combination_quality
from analysis.scene import check_enumerable, scene_json_schema

app = typer.Typer(add_completion=False, no_args_is_help=True, help="Contact-state closure analysis and planning.")
console = Console()
err_console = Console(stderr=True)


#: exit codes of ``ctp plan`` and ``ctp simulate`` beyond 0 (success) and 2 (bad input)
EXIT_NO_PLAN = 1  # ctp plan: no plan found
EXIT_DROPPED = 1  # ctp simulate: the object was dropped (or the analysis failed)
EXIT_OFF_PLAN = 3  # the replay ended outside its tolerance (ctp plan --replay: or dropped the object)
#: plan replays: the self-motion posture rate (1/s) of sim.plan_replay.PlanSimulationOptions
POSTURE_RATE = 50.0
POSTURE_HELP = ("plan replays: 1/s at which the hand's self-motion (joint motions that move no contact) "
                "is held to the planned posture during object motions; 0: pure torque control")
#: plan replays: the hold servo's rate (1/s) of sim.plan_replay.PlanSimulationOptions
HOLD_RATE = 500.0
HOLD_HELP = ("plan replays: 1/s of the joint servo that holds the touching fingers' contact-moving joint "
             "motions while the grasp holds still (never during object motions); 0: torque control in holds too")


def _fail(message: str, code: int = 2) -> NoReturn:
    err_console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)  # one line
    raise typer.Exit(code)


def _load(scene_path: Path) -> Any:
    """The scene, or exit 2 naming the field; corrections the loader made (``Scene.notes``, e.g. a
    normal normalised) are printed as notes on stderr."""
    try:
        sc = load_scene(scene_path)
    except SceneError as e:
        _fail(f"{scene_path}: {e}")
    for note in (*sc.notes, *_unlisted_notes(sc)):
        err_console.print(f"[bold yellow]note:[/] {scene_path}: {note}", highlight=False, soft_wrap=True)
    return sc


def _unlisted_notes(sc: Any) -> list[str]:
    """Bodies lying on the object along a line or a patch of which the scene lists fewer points
    (:func:`analysis.detect.unlisted_points`); none where the detector cannot take the scene."""
    from analysis.detect import unlisted_points

    try:
        return [u.describe() for u in unlisted_points(sc)]
    except CTPError:
        return []


def _check_out(path: Path | None, option: str) -> None:
    """Before any work: the folder an output file goes to must exist (exit 2 naming the option)."""
    if path is None:
        return
    parent = path.parent
    if not parent.is_dir():
        _fail(f"{option}: cannot write {path}: the folder '{parent}' does not exist")
    if path.is_dir():
        _fail(f"{option}: cannot write {path}: it is a folder")


def _write(path: Path, text: str, option: str) -> None:
    try:
        path.write_text(text)
    except OSError as e:
        _fail(f"{option}: cannot write {path}: {e.strerror or e}")
    console.print(f"wrote {path}")


def _parse_vector(text: str, field: str) -> np.ndarray:
    try:
        values = [float(v) for v in text.replace("[", "").replace("]", "").replace(",", " ").split()]
    except ValueError:
        _fail(f"{field}: '{text}' is not a list of numbers")
    if not values or not np.all(np.isfinite(values)):
        _fail(f"{field}: '{text}' must contain finite numbers")
    return np.array(values)


def _radius(r: float | None) -> str:
    """A quality radius [N] for the table: ``inf`` for an unbounded set, ``-`` when not computed."""
    return "-" if r is None else "inf" if not np.isfinite(r) else f"{r:.3g}"


def _fmt(v: np.ndarray | None, digits: int = 3) -> str:
    if v is None:
        return "-"
    return "[" + " ".join(f"{x: .{digits}f}" for x in np.asarray(v)) + "]"


@app.command()
def analyze(
    scene: Annotated[Path, typer.Argument(help="scene file (.json, .yaml)")],
    combination: Annotated[str | None, typer.Option(help="full report of one combination, e.g. FSDD")] = None,
    direction: Annotated[str | None, typer.Option(help="object motion for the torque set, e.g. '1,0.15,-1'")] = None,
    nu: Annotated[float | None, typer.Option(help="friction uncertainty: mu -> nu mu (0 <= nu <= 1)")] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="write everything to this JSON file")] = None,
    plot: Annotated[Path | None, typer.Option(help="draw the scene and DAFC directions (PNG)")] = None,
    feasible_only: Annotated[bool, typer.Option(help="list only feasible combinations")] = False,
    samples: Annotated[int | None, typer.Option(help="directions sampled for the DAFC set (--combination)")] = None,
    prune_modes: Annotated[bool | None, typer.Option(help="prune with kinematic contact modes (default: up to "
                                                     f"{MODES_PRUNE_MAX} contacts)")] = None,
    where: Annotated[str | None, typer.Option(help="only combinations with these letter counts, e.g. 'D>=3' "
                                              "or 'F<=2, S==0'")] = None,
    limit: Annotated[int | None, typer.Option(help="stop after this many feasible combinations "
                                              "(strongest first)")] = None,
    quality: Annotated[bool, typer.Option(help="grasp quality of each feasible combination: the DPFC wrench "
                                          "ball and the Ferrari-Canny epsilon [N, moments per object size]")] = False,
) -> None:
    """Closure analysis: every combination (table), or the full report of one."""

    _check_out(json_out, "--json")
    _check_out(plot, "--plot")
    sc = _load(scene)
    system = build_system(sc)
    if nu is not None and not 0.0 <= nu <= 1.0:
        _fail(f"nu: {nu} must lie in [0, 1]")
    dvec = None
    if direction is not None:
        dvec = _parse_vector(direction, "direction")
        if len(dvec) != sc.D:
            _fail(f"direction: has {len(dvec)} components; the object has {sc.D} coordinates")
    if combination is None and (direction is not None or nu is not None):
        _fail("direction/nu: need --combination")
    if combination is not None and (where is not None or limit is not None):
        _fail("where/limit: filter the table of every combination; drop them with --combination")
    if limit is not None and limit < 1:
        _fail(f"limit: {limit} must be at least 1")
    where_filter = None
    if where is not None:
        try:
            where_filter = parse_where(where)
        except CTPError as e:
            _fail(str(e))
    if combination is None:
        try:
            check_enumerable(sc)  # one combination and the modes take any number of contacts
        except SceneError as e:
            _fail(f"{scene}: {e}")
    try:
        if combination is not None:
            if samples is not None and samples < 4:
                _fail(f"samples: {samples} must be at least 4")
            report = analyze_combination(system, combination, direction=dvec, nu=nu, samples=samples)
            _print_report(report, sc)
            if json_out:
                data = {"scene": sc.name, **report.to_json()}
                _write(json_out, json.dumps(data, indent=2), "--json")
            if plot:
                from ctp.plot import plot_report

                plot_report(plot, sc, report)
                console.print(f"wrote {plot}")
            return
        summaries, stopped = _enumerate(system, prune_modes, where_filter, limit)
    except SceneError as e:
        _fail(str(e))
    except CTPError as e:
        _fail(str(e), code=1)
    rows = [s for s in summaries if s.feasible] if feasible_only or len(summaries) > 729 else summaries
    decided = "combinations decided (strongest first)" if stopped else "combinations"
    grades = {s.combination: combination_quality(system, s.combination) for s in summaries
              if s.feasible} if quality else {}
    table = Table(title=f"{sc.name}: {sum(s.feasible for s in summaries)} of {len(summaries)} {decided} feasible")
    cols = ["combination", "feasible", "dim DAFC", "dim DPFC", "example direction", "note"]
    if quality:
        cols[4:4] = ["ball [N]", "eps [N]"]
    for col in cols:
        table.add_column(col)
    for s in rows:
        cells = [s.combination, "yes" if s.feasible else "no", str(s.dim_dafc), str(s.dim_dpfc),
                 _fmt(s.example_direction, 2), ("" if s.exact else "sampled; ") + ("" if s.feasible else s.reason)]
        if quality:
            g = grades.get(s.combination)
            cells[4:4] = ["-", "-"] if g is None else [_radius(g.wrench_ball.radius), _radius(g.epsilon.radius)]
        table.add_row(*cells)
    console.print(table)
    if len(rows) < len(summaries):
        console.print(f"(showing feasible combinations only; {len(summaries)} in --json)")
    if stopped:
        console.print(f"(stopped after {limit} feasible combinations, strongest first: --limit)")
    if json_out:
        listed = [s.to_json() for s in summaries]
        for row in listed:
            g = grades.get(row["combination"])
            if g is not None:
                row["quality"] = g.to_json()
        data = {"scene": sc.name, "semantics": SEMANTICS, "combinations": listed}
        _write(json_out, json.dumps(data, indent=2), "--json")
    if plot:
        from ctp.plot import plot_report

        first = next((s for s in summaries if s.feasible), None)
        rep = analyze_combination(system, first.combination) if first else None
        plot_report(plot, sc, rep)
        console.print(f"wrote {plot}")


#: ``ctp analyze`` prunes the table with the contact modes by default up to this many contacts:
#: beyond, listing the stick/slide/separate patterns costs more than the combinations they would
#: spare (12 contacts: 386,336 patterns, over two minutes), whose motion space, stationary grasp
#: and DAFC the enumeration decides anyway.
MODES_PRUNE_MAX = 9


def _enumerate(system: Any, prune_modes: bool | None, where: Any = None, limit: int | None = None
               ) -> tuple[list[Any], bool]:
    admissible = None
    if prune_modes is None:
        prune_modes = system.L <= MODES_PRUNE_MAX
    if prune_modes:
        modes = enumerate_modes(system, refine=False)
        admissible = lambda c: combination_admissible(modes, c)  # noqa: E731
    with Progress(TextColumn("combinations"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=err_console, transient=True, disable=not sys.stderr.isatty()) as bar:
        task = bar.add_task("enumerate", total=None)

        def progress(k: int, n: int) -> None:
            bar.update(task, completed=k, total=n)

        summaries, stats = enumerate_combinations(system, admissible=admissible, progress=progress, where=where,
                                                  limit=limit)
    return summaries, stats.stopped_at_limit


def _print_report(report: Any, sc: Any) -> None:
    s = report.summary
    console.print(f"[bold]{sc.name}[/] combination [bold]{s.combination}[/]: "
                  f"{'feasible' if s.feasible else 'not feasible'} ({s.reason})")
    for note in report.notes:
        console.print(f"  [yellow]note:[/] {note}", highlight=False, soft_wrap=True)
    ms = report.parts.ms
    console.print(f"  motion space a = {ms.a}, object part a~ = {ms.a_bar}, redundancy {ms.n_redundant}; "
                  f"p = rank(G_c Gamma) = {report.parts.st.p}")
    tau_max = report.parts.system.tau_max
    if tau_max is not None:
        console.print(f"  joint torque limits [N m]: {_fmt(tau_max, 1)} (bound tau_st and the torque set)")
    if report.stationary is not None:
        g = report.stationary
        console.print(f"  stationary grasp (18, most interior): tau_st = {_fmt(g.tau)}  margin {g.margin:.3g}")
        console.print(f"  minimum grip: tau_st = {_fmt(report.stationary_min_grip.tau)}  "
                      f"total normal {report.stationary_min_grip.total_normal:.3g}")
    if report.dafc is not None:
        d = report.dafc
        console.print(f"  DAFC (22): dim {d.dim}, {int(d.member.sum())} of {len(d.member)} sampled directions, "
                      f"{'exact' if d.exact else 'sampled'}; example {_fmt(s.example_direction)}")
    if report.dpfc is not None:
        dp = report.dpfc
        if dp.enumerated:
            console.print(f"  DPFC (28): dim {dp.dim}, {len(dp.vertices)} vertices, {len(dp.rays)} rays")
        else:
            console.print(f"  DPFC (28): dim {dp.dim}, by {len(dp.b_xi)} inequalities in {dp.W_xi.shape[1]} "
                          f"internal-force coordinates (too many to enumerate its vertices); "
                          f"{len(dp.vertices)} extreme wrenches along its axes, {dp.unbounded_axes} unbounded")
    if report.direction_test is not None:
        t = report.direction_test
        console.print(f"  direction {_fmt(t.direction)}: {'in DAFC' if t.member else 'not in DAFC'} ({t.reason})")
    if report.torque is not None:
        ts = report.torque
        if ts.vertices is None or ts.rays is None:
            console.print(f"  torque set T (32) for {_fmt(ts.direction)}: force polyhedron of dimension {ts.dim_P}, "
                          "too large to enumerate (H-representation in --json); "
                          f"phi = |dq| = {ts.phi:.3g} ({ts.nlp_status})")
        else:
            console.print(f"  torque set T (32) for {_fmt(ts.direction)}: {len(ts.vertices)} vertices, "
                          f"{len(ts.rays)} rays; phi = |dq| = {ts.phi:.3g} ({ts.nlp_status})")
            for v in ts.vertices:
                console.print(f"    vertex {_fmt(v)}")
            for r in ts.rays:
                console.print(f"    ray    {_fmt(r)}")
        console.print(f"  recommended tau = {_fmt(ts.tau)} (work {ts.work:.3g})")
    if report.torque_error:
        console.print(f"  torque set: {report.torque_error}")
    if report.uncertainty is not None:
        u = report.uncertainty
        console.print(f"  friction uncertainty nu = {u.nu}: {u.reason}; lambda = {_fmt(u.lambdas)}")
    if report.regrasp is not None:
        rg = report.regrasp
        console.print(f"  regrasp cone (33): {len(rg.rays)} rays, {len(rg.lines)} lines "
                      f"({'exact' if rg.exact else 'S-points checked per generator'})")


@app.command()
def modes(
    scene: Annotated[Path, typer.Argument(help="scene file (.json, .yaml)")],
    json_out: Annotated[Path | None, typer.Option("--json", help="write the modes to this JSON file")] = None,
    tangent_planes: Annotated[int, typer.Option(help="3-D: tangent hyperplanes that label sliding")] = 2,
    max_modes: Annotated[int, typer.Option(help="stop listing sticking/sliding modes after this many")] = 200_000,
) -> None:
    """Kinematic contact modes (contacting/separating and sticking/sliding) that some motion realises."""

    _check_out(json_out, "--json")
    sc = _load(scene)
    if tangent_planes < 2:
        _fail(f"tangent-planes: {tangent_planes} must be at least 2")
    try:
        e = enumerate_modes(build_system(sc), tangent_planes=tangent_planes, max_modes=max_modes)
    except CTPError as err:
        _fail(str(err), code=1)
    data = e.to_json()
    console.print(f"{sc.name}: {data['contacting_separating']} contacting/separating modes, "
                  f"{data['sticking_sliding']} sticking/sliding modes"
                  + ("" if e.sticking_sliding_complete else " (listing stopped at --max-modes)")
                  + f"; {e.lp_count} LPs")
    if json_out:
        _write(json_out, json.dumps(data, indent=2), "--json")


def _read_plan_file(path: Path) -> dict[str, Any] | None:
    """The parsed plan when ``path`` is a plan file (a JSON object with top-level ``"steps"``),
    else None (a scene file)."""
    if path.suffix.lower() != ".json":
        return None
    try:
        data = read_scene_data(path)  # the scene files' parser: size, depth and encoding checked
    except SceneError as e:
        _fail(f"{path}: {e}")
    return data if isinstance(data, dict) and "steps" in data else None


def _plan_scene(plan_path: Path, data: dict[str, Any], scene_path: Path | None) -> Any:
    """The scene a plan file was made for: ``--scene``, else the file's ``"scene"`` entry."""

    if scene_path is not None:
        return _load(scene_path)
    if "scene" not in data:
        _fail(f"{plan_path}: scene: the plan file has no 'scene' entry (plans from 'ctp plan --out' have one); "
              "give --scene PATH")
    try:
        return scene_from_dict(data["scene"])
    except SceneError as e:
        _fail(f"{plan_path}: scene.{e}")


def _replay_options(posture_rate: float, hold_rate: float = HOLD_RATE) -> Any:
    """:class:`sim.plan_replay.PlanSimulationOptions` with ``--posture-rate`` and ``--hold-rate``
    (checked: exit 2)."""
    from sim.plan_replay import PlanSimulationOptions

    try:
        return PlanSimulationOptions(posture_rate=posture_rate, hold_rate=hold_rate)
    except ValueError as e:
        _fail(str(e).replace("posture_rate", "posture-rate", 1).replace("hold_rate", "hold-rate", 1))


def _simulate_plan_file(plan_path: Path, data: dict[str, Any], scene_path: Path | None,
                        json_out: Path | None, posture_rate: float, hold_rate: float = HOLD_RATE) -> None:
    """``ctp simulate PLAN.json``: the continuous replay of :func:`sim.plan_replay.simulate_plan`.
    Exit code 0 when the replay meets the plan, 1 if the object was dropped, 2 for bad input, 3 if
    it ended outside the tolerance (position or rotation)."""
    from sim.plan_replay import simulate_plan

    options = _replay_options(posture_rate, hold_rate)
    sc = _plan_scene(plan_path, data, scene_path)
    try:
        rep = simulate_plan(sc, data, options=options)
    except SceneError as e:
        _fail(f"{plan_path}: {e}")
    except CTPError as e:
        _fail(str(e), code=1)
    _print_plan_simulation(rep)
    if json_out:
        _write(json_out, json.dumps(rep.to_json(), indent=1), "--json")
    if rep.dropped:
        raise typer.Exit(EXIT_DROPPED)
    if not rep.ok:
        raise typer.Exit(EXIT_OFF_PLAN)


def _print_plan_simulation(rep: Any) -> None:
    for s in rep.steps:
        who = f" ({s.driven_finger})" if s.driven_finger else ""
        console.print(f"step {s.index} {s.kind}{who} {s.combination}: object moved {_fmt(s.simulated, 5)} "
                      f"(planned {_fmt(s.planned, 5)}); off path {s.max_deviation:.2e}; "
                      f"tracking {s.tracking_error:.1e} rad; {s.duration:.3f} s; {s.note}"
                      + (f"; hold servo {s.hold_servo:.2g} N m" if s.hold_servo > 0 else ""),
                      highlight=False, soft_wrap=True)
    console.print(f"final pose simulated {_fmt(rep.simulated_final_pose, 5)} vs planned "
                  f"{_fmt(rep.planned_final_pose, 5)}", highlight=False, soft_wrap=True)
    console.print(f"displacement simulated {_fmt(rep.simulated, 5)} vs planned {_fmt(rep.planned, 5)}; "
                  f"largest regrasp drift {rep.max_regrasp_deviation:.2e} (object size {rep.object_size:.3g}); "
                  f"{rep.duration:.2f} s simulated", highlight=False, soft_wrap=True)
    console.print(f"final pose: {rep.error.describe(rep.tolerance)}", highlight=False, soft_wrap=True)
    console.print(f"control: {rep.control}; largest hold servo torque {rep.hold_servo:.3g} N m "
                  f"({rep.hold_servo_share:.1%} of the largest holding torque)", highlight=False, soft_wrap=True)
    console.print("dropped: " + (f"YES ({rep.drop_reason})" if rep.dropped else "no") + "; "
                  + ("within tolerance" if rep.ok else "NOT within tolerance"), highlight=False, soft_wrap=True)


@app.command()
def simulate(
    scene: Annotated[Path, typer.Argument(help="scene file (.json, .yaml), or a plan file from 'ctp plan --out'")],
    combination: Annotated[str | None, typer.Option(help="expected contact states, e.g. DDDFF")] = None,
    torque: Annotated[str | None, typer.Option(help="joint torques, e.g. '0,0,3.48,2.20'; default: the "
                                                     "recommended member of T for --combination")] = None,
    direction: Annotated[str | None, typer.Option(help="object motion for the torque set")] = None,
    duration: Annotated[float, typer.Option(help="simulated seconds")] = 1.0,
    stop_fraction: Annotated[float, typer.Option(help="stop once the object moved this fraction of its size "
                                                      "(the analysis is first order)")] = 0.02,
    json_out: Annotated[Path | None, typer.Option("--json", help="write the result to this JSON file")] = None,
    scene_file: Annotated[Path | None, typer.Option("--scene", help="plan files: the scene it was planned "
                                                                     "from (default: the file's 'scene')")] = None,
    posture_rate: Annotated[float, typer.Option(help=POSTURE_HELP)] = POSTURE_RATE,
    hold_rate: Annotated[float, typer.Option(help=HOLD_HELP)] = HOLD_RATE,
) -> None:
    """Replay joint torques in MuJoCo (quasi-static) and report the object's motion and contacts;
    or, given a plan file, replay the whole plan in one simulation and compare the final pose with
    the plan's: position error in scene units (m) and rotation error in radians, each relative to
    the planned displacement, tolerance 5 % each.

    Exit codes: 0 done (a plan file: the replay met the plan); 1 the object was dropped (or the
    analysis found no torque to replay); 2 bad input; 3 a plan file's replay ended outside the
    tolerance."""
    from sim.report import format_report
    from sim.torque_replay import simulate_torques

    _check_out(json_out, "--json")
    plan_data = _read_plan_file(scene)
    if plan_data is not None:
        if combination is not None or torque is not None or direction is not None:
            _fail("combination/torque/direction: do not apply to a plan file")
        _simulate_plan_file(scene, plan_data, scene_file, json_out, posture_rate, hold_rate)
        return
    if scene_file is not None:
        _fail(f"scene: --scene is for plan files; {scene} is not a plan (no 'steps')")
    sc = _load(scene)
    if duration <= 0:
        _fail(f"duration: {duration} must be positive")
    predicted = None
    phi: float | None = None  # the joint speed per unit object speed of the analysed motion (eq. 31)
    try:
        if torque is not None:
            tau = _parse_vector(torque, "torque")
        elif combination is not None:
            dvec = _parse_vector(direction, "direction") if direction is not None else None
            if dvec is not None and len(dvec) != sc.D:
                _fail(f"direction: has {len(dvec)} components; the object has {sc.D} coordinates")
            rep = analyze_combination(build_system(sc), combination, direction=dvec)
            if rep.torque is None:
                _fail(f"combination {combination}: no torque set to replay ({rep.torque_error or rep.summary.reason})",
                      code=1)
            tau, predicted, phi = rep.torque.tau, rep.torque.direction, rep.torque.phi
            console.print(f"replaying the recommended member of T for {combination}: tau = {_fmt(tau)}; "
                          f"predicted direction {_fmt(predicted)}")
        else:
            _fail("torque: give --torque or --combination")

        result = simulate_torques(sc, tau, duration=duration, combination=combination,
                                  stop_distance=stop_fraction * object_size(sc) if stop_fraction > 0 else None,
                                  phi=phi)
    except SceneError as e:
        _fail(str(e))
    except CTPError as e:
        _fail(str(e), code=1)
    typer.echo(format_report(result))
    if predicted is not None:
        console.print(f"cosine(observed, predicted) = {result.cosine(predicted):.3f}")
    if json_out:
        data = {
            "scene": sc.name, "combination": combination, "tau": tau.tolist(), "dr": result.dr.tolist(),
            "direction": result.direction.tolist(), "dropped": result.dropped,
            "predicted_direction": None if predicted is None else predicted.tolist(),
            "contacts": [{"index": c.index, "body": c.body, "expected": c.expected, "observed": c.observed,
                          "agrees": c.agrees, "mean_normal_force": c.mean_normal_force, "slip": c.slip}
                         for c in result.contacts],
        }
        _write(json_out, json.dumps(data, indent=2), "--json")


@app.command()
def contacts(
    scene: Annotated[Path, typer.Argument(help="scene file (.json, .yaml); contacts it has are replaced")],
    out: Annotated[Path | None, typer.Option(help="write the complete scene (JSON) with the contacts found")] = None,
    tolerance: Annotated[float, typer.Option(help="distance within which two surfaces touch (scene units)")] = (
        DEFAULT_TOLERANCE),
    mu: Annotated[float, typer.Option(help="friction of the contacts on bodies that name none ('mu')")] = DEFAULT_MU,
    touch: Annotated[list[str] | None, typer.Option(
        help="move q first (within joint limits, nearest the scene's q) until this link touches the object "
             "without penetrating anything ('<finger>/<link>' or a link name; repeat for several links)")] = None,
) -> None:
    """Find the contacts between the object and every finger link and fixed body at the scene's
    configuration (an edge or face on a surface: the corners of the patch), list them and the
    near misses (closer than 10 tolerances, not touching), and write the complete scene. With
    --touch, the configuration is first moved so that the named links touch the object."""

    _check_out(out, "--out")
    if not (np.isfinite(tolerance) and tolerance > 0):
        _fail(f"tolerance: {tolerance} must be a positive number")
    if not (np.isfinite(mu) and mu >= 0):
        _fail(f"mu: {mu} must be a non-negative number")
    try:
        data = read_scene_data(scene)
        if not isinstance(data, dict):
            raise SceneError((), "a scene must be a mapping of fields")
        data = {k: v for k, v in data.items() if k != "contacts"}
        if touch:
            data, placed = placed_scene_data(data, list(touch), tolerance=tolerance)
            console.print(f"placed: {', '.join(f'{n} at {d:.2g}' for n, d in placed.touch)}; |q - q_scene| = "
                          f"{placed.displacement:.4g} rad; deepest pair {placed.min_distance:.2g}", highlight=False)
        full, det = with_detected_contacts(data, tolerance=tolerance, mu=mu)
        sc = scene_from_dict(full)  # the complete scene passes the validation of every scene
    except SceneError as e:
        _fail(f"{scene}: {e}")
    table = Table(title=f"{sc.name}: {len(det.contacts)} contacts within {tolerance:g}")
    for col in ("#", "body", "point", "normal (into the object)", "mu", "gap"):
        table.add_column(col)
    for i, c in enumerate(det.contacts):
        table.add_row(str(i), c.body, _fmt(np.array(c.point), 6), _fmt(np.array(c.normal), 6), f"{c.mu:g}",
                      f"{c.gap:.3g}")
    console.print(table)
    if det.near_misses:
        for m in det.near_misses:
            console.print(f"near miss: {m.body} at {m.distance:.4g} (object point {_fmt(np.array(m.object_point), 6)})",
                          highlight=False, soft_wrap=True)
    else:
        console.print(f"no near misses (nothing closer than {NEAR_FACTOR * tolerance:g} without touching)")
    if out:
        _write(out, json.dumps(full, indent=2) + "\n", "--out")


@app.command()
def plan(
    scene: Annotated[Path, typer.Argument(help="scene file (.json, .yaml)")],
    goal: Annotated[str, typer.Option(help="active | passive | fingertips | combination | pose | displacement | "
                                           "contact")
                    ] = "active",
    combination: Annotated[str | None, typer.Option(help="goal combination, e.g. FSDD (--goal combination)")] = None,
    pose: Annotated[str | None, typer.Option(help="goal pose: 2-D 'x y theta', 3-D 'x y z rx ry rz'")] = None,
    displacement: Annotated[str | None, typer.Option(
        help="goal displacement from the start pose (push by dx, lift by dz): 2-D 'dx dy dtheta', "
             "3-D 'dx dy dz rx ry rz'")] = None,
    body: Annotated[str | None, typer.Option(help="contact goal: the finger link that is to touch at --point")] = None,
    point: Annotated[str | None, typer.Option(help="contact goal: where it is to touch (world): 3-D 'x y z'")] = None,
    position_tolerance: Annotated[float | None, typer.Option(
        help="pose or contact goal: position tolerance in scene units (metres); default 1 % of the object "
             "size")] = None,
    rotation_tolerance: Annotated[str | None, typer.Option(
        help="pose goal: rotation tolerance in radians, or 'free'; default 0.05")] = None,
    tolerance: Annotated[float | None, typer.Option(
        help="pose goal: older single tolerance, the default of both of the above")] = None,
    free_axes: Annotated[str | None, typer.Option(
        help="pose or displacement goal: world axes along which the position is free, e.g. 'x y' (lift by "
             "dz wherever the lift swings the object sideways)")] = None,
    time_limit: Annotated[float | None, typer.Option(help="seconds for the search")] = None,
    link_replacement: Annotated[bool, typer.Option(
        help="also lay a link an arm let go of flat on a face of a box object again, the other arms "
             "pinned (whole-arm regrasps)")] = False,
    sliding: Annotated[bool | None, typer.Option(
        "--sliding/--no-sliding",
        help="object motions in which the contacts on fixed bodies slide (S) while the fingers stick; "
             "default: for pose and displacement goals (--no-sliding: a sphere on a table only rolls)")] = None,
    contact_slides: Annotated[bool, typer.Option(
        help="also slide a link's contact along a face of a box object while the other contacts hold it "
             "still (eq. 33 with an S-point; whole-arm regrasps)")] = False,
    link_sliding: Annotated[bool, typer.Option(
        help="object motions towards a goal pose in which the contacts of an arm's distal link slide "
             "along the object's faces (S at links)")] = False,
    separate_finger_contacts: Annotated[bool, typer.Option(
        help="object motions may also separate single finger contacts, not only those on fixed bodies "
             "(more edges, slower)")] = False,
    effort_weight: Annotated[float | None, typer.Option(
        help="weight of a transition's effort (joint torque, N m) in its cost, >= 0; default 0.1 "
             "(0: the cheapest plan by motions and contacts only, e.g. rolling on a link's side)")] = None,
    out: Annotated[Path | None, typer.Option(help="write the plan as JSON")] = None,
    replay: Annotated[bool, typer.Option(help="replay the whole plan in MuJoCo (one continuous simulation)")] = False,
    posture_rate: Annotated[float, typer.Option(help="--replay: " + POSTURE_HELP)] = POSTURE_RATE,
    hold_rate: Annotated[float, typer.Option(help="--replay: " + HOLD_HELP)] = HOLD_RATE,
) -> None:
    """Plan contact-state transitions from the scene's grasp to a goal: active or passive closure,
    fingertip contacts only, a combination (one letter per scene contact: D released, the others
    still touching in that state), an object pose, or a displacement of the object from its start
    (``--goal displacement --displacement '-0.1 0 0 0 0 0'``: push by 10 cm along -x), or a contact
    of a link at a new place (``--goal contact --body left/left_lower_elbow --point 'x y z'``; with
    ``--contact-slides`` an arm may slide it there along a face).

    Exit codes: 0 a plan was found (or the start already meets the goal; with --replay: and the
    replay met it); 1 no plan was found (the reason is printed); 2 bad input; 3 (--replay) the
    replay dropped the object or ended outside its tolerance."""

    import dataclasses

    from planner import Goal
    from planner import plan as make_plan
    from planner.options import PlannerOptions

    _check_out(out, "--out")
    if effort_weight is not None and not (np.isfinite(effort_weight) and effort_weight >= 0):
        _fail(f"--effort-weight: {effort_weight} must be a finite number >= 0")
    sc = _load(scene)
    rot: float | str | None = rotation_tolerance
    if rotation_tolerance is not None and rotation_tolerance.strip().lower() != "free":
        try:
            rot = float(rotation_tolerance)
        except ValueError:
            _fail(f"rotation-tolerance: '{rotation_tolerance}' is not a number of radians nor 'free'")
    elif rotation_tolerance is not None:
        rot = "free"
    try:
        g = Goal(type=goal, combination=combination,
                 pose=None if pose is None else [float(x) for x in _parse_vector(pose, "pose")],
                 displacement=None if displacement is None else [
                     float(x) for x in _parse_vector(displacement, "displacement")],
                 tolerance=tolerance, position_tolerance=position_tolerance, rotation_tolerance=rot, body=body,
                 point=None if point is None else [float(x) for x in _parse_vector(point, "point")],
                 free_axes=None if free_axes is None else free_axes.replace(",", " ").split())
    except ValidationError as e:
        err = e.errors()[0]
        where = ".".join(str(x) for x in err["loc"] if not str(x).startswith(("function-", "literal[")))
        _fail(f"goal{'.' + where if where else ''}: {str(err['msg']).removeprefix('Value error, ')}")
    with Progress(TextColumn("[bold]planning"), BarColumn(), TextColumn("{task.description}"),
                  TimeElapsedColumn(), console=err_console, transient=True) as bar:
        task = bar.add_task("", total=1.0)

        def step(fraction: float, message: str) -> None:
            bar.update(task, completed=fraction, description=message[:60])

        try:
            options = PlannerOptions(link_replacement=link_replacement, sliding_motions=sliding,
                                     contact_slides=contact_slides, link_sliding=link_sliding,
                                     separate_finger_contacts=separate_finger_contacts)
            if effort_weight is not None:  # else the planner's default
                options = dataclasses.replace(options, effort_weight=effort_weight)
            result = make_plan(sc, g, progress=step, time_limit=time_limit, options=options)
        except SceneError as e:
            _fail(str(e))
        except CTPError as e:
            _fail(str(e), code=1)
    if not result.found:
        console.print(f"[bold red]no plan:[/] {result.reason}", highlight=False, soft_wrap=True)
    elif not result.steps:
        console.print(f"[bold]goal met at the start:[/] {result.reason}", highlight=False, soft_wrap=True)
    else:
        table = Table(title=f"plan: {len(result.steps)} steps, cost {result.cost:.3f}")
        for col in ("step", "kind", "combination", "contacts after", "cost"):
            table.add_column(col)
        for st in result.steps:
            t = st.transition
            table.add_row(str(st.index), t.kind, t.combination, ", ".join(t.contacts_after), f"{t.cost:.3f}")
        console.print(table)
        console.print(f"object displacement {_fmt(result.displacement)}; "
                      f"{result.stats.nodes_expanded} nodes expanded in {result.stats.seconds_total:.2f} s")
    data = result.to_json()
    data["scene"] = sc.model_dump(mode="json", exclude_none=True)  # 'ctp simulate PLAN.json' reloads it
    rep = None
    if replay and result.found and not result.steps:
        console.print("replay: nothing to replay (no steps)")
    elif replay and result.found:
        from sim.plan_replay import simulate_plan

        try:
            rep = simulate_plan(sc, result, options=_replay_options(posture_rate, hold_rate))
        except CTPError as e:
            _fail(f"replay: {e}", code=1)
        _print_plan_simulation(rep)
        data["replay"] = rep.to_json()
    if out is not None:
        _write(out, json.dumps(data, indent=1), "--out")
    if not result.found:
        raise typer.Exit(EXIT_NO_PLAN)
    if rep is not None and not rep.ok:
        raise typer.Exit(EXIT_OFF_PLAN)


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True, "help_option_names": []})
def batch(ctx: typer.Context) -> None:
    """Plan (--goal) or enumerate (--enumerate) every scene of a folder; resumable; processes or Ray."""
    from ctp.batch import main as batch_main

    batch_main(ctx.args)


@app.command()
def schema(out: Annotated[Path | None, typer.Option(help="write to a file instead of stdout")] = None) -> None:
    """Print the JSON Schema of the scene format."""

    _check_out(out, "--out")
    text = json.dumps(scene_json_schema(), indent=2)
    if out:
        _write(out, text, "--out")
    else:
        sys.stdout.write(text + "\n")


def main() -> None:  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
