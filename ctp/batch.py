"""``ctp batch SCENES_DIR --goal active --out results/``: every scene of a folder, one result file
each, resumable, with a progress bar and a summary table; on a local process pool or on Ray.

Each scene's result is ``OUT/<scene file stem>.json`` (written atomically): ``status`` is
``succeeded`` (a plan was found, or the enumeration finished), ``no plan`` (the planner answered
that no plan exists, with its ``reason``) or ``failed`` (the scene is invalid or a solver failed:
``error``). A scene whose result file already exists is skipped (``--retry-failed`` re-runs the
failed ones), so an interrupted batch resumes where it stopped. ``OUT/summary.json`` lists them all.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer
from pydantic import ValidationError
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from analysis.exceptions import CTPError
from analysis.loader import load_scene
from api.tasks import run_enumeration
from planner import Goal, plan

SCENE_SUFFIXES = (".json", ".yaml", ".yml")
DONE = ("succeeded", "no plan", "failed")


def parse_goal(text: str) -> dict[str, Any]:
    """``active``, ``passive``, ``combination:FSDD`` or ``pose:x,y,theta[,...]``."""
    kind, _, arg = text.partition(":")
    data: dict[str, Any] = {"type": kind}
    if kind == "combination":
        data["combination"] = arg
    elif kind == "pose":
        data["pose"] = [float(v) for v in arg.split(",") if v.strip()]
    return Goal.model_validate(data).model_dump(mode="json", exclude_none=True)


def run_one(path: str, goal: dict[str, Any] | None, time_limit: float | None) -> dict[str, Any]:
    """Plan (``goal``) or enumerate one scene file; never raises (the error is the record)."""
    t0 = time.perf_counter()
    record: dict[str, Any] = {"scene_file": Path(path).name, "kind": "plan" if goal else "enumeration"}
    try:
        scene = load_scene(path)
        record["scene"] = scene.name
        if goal is not None:
            result = plan(scene, Goal.model_validate(goal), time_limit=time_limit).to_json()
            record["status"] = "succeeded" if result.get("found") else "no plan"
            record["steps"] = len(result.get("steps", []))
            record["reason"] = result.get("reason")
        else:
            result = run_enumeration({"scene": scene.model_dump(mode="json")})
            record["status"] = "succeeded"
            record["feasible"] = result["feasible"]
            record["combinations"] = len(result["combinations"])
        record["result"] = result
    except CTPError as e:
        record.update(status="failed", error=str(e))
    except Exception as e:  # a batch of thousands must go on past one bad scene
        record.update(status="failed", error=f"{type(e).__name__}: {e}")
    record["seconds"] = time.perf_counter() - t0
    return record


def scene_files(scenes_dir: Path) -> list[Path]:
    return sorted(p for p in scenes_dir.iterdir() if p.is_file() and p.suffix.lower() in SCENE_SUFFIXES)


def _done_record(out: Path, retry_failed: bool) -> dict[str, Any] | None:
    if not out.exists():
        return None
    try:
        record: dict[str, Any] = json.loads(out.read_text())
    except (OSError, json.JSONDecodeError):
        return None  # a torn or foreign file: run the scene again
    if record.get("status") not in DONE or (retry_failed and record["status"] == "failed"):
        return None
    return record


def _write(out: Path, record: dict[str, Any]) -> None:
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(record, indent=1))
    os.replace(tmp, out)


def _local(todo: list[Path], goal: dict[str, Any] | None, time_limit: float | None,
           workers: int) -> Iterator[tuple[Path, dict[str, Any]]]:
    import multiprocessing as mp

    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        futures: dict[Future[dict[str, Any]], Path] = {pool.submit(run_one, str(p), goal, time_limit): p
                                                       for p in todo}
        pending = set(futures)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                yield futures[f], f.result()


def _ray(todo: list[Path], goal: dict[str, Any] | None, time_limit: float | None,
         address: str) -> Iterator[tuple[Path, dict[str, Any]]]:
    import ray  # only with --ray: it takes about 4 s to import

    if not ray.is_initialized():
        ray.init(address=None if address == "local" else address, ignore_reinit_error=True, log_to_driver=False)
    task = ray.remote(max_retries=1)(run_one)
    refs = {task.remote(str(p), goal, time_limit): p for p in todo}
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        for ref in done:
            yield refs[ref], ray.get(ref)


def run_batch(scenes_dir: Path, out_dir: Path, goal: dict[str, Any] | None, *, ray_address: str | None = None,
              workers: int = 1, time_limit: float | None = None, retry_failed: bool = False,
              on_record: Callable[[Path, dict[str, Any], bool], None] | None = None) -> list[dict[str, Any]]:
    """Run every scene not done yet; return one summary row per scene (scene order)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files = scene_files(scenes_dir)
    records: dict[Path, dict[str, Any]] = {}
    todo = []
    for p in files:
        rec = _done_record(out_dir / f"{p.stem}.json", retry_failed)
        if rec is None:
            todo.append(p)
        else:
            records[p] = rec
            if on_record:
                on_record(p, rec, True)
    stream = _ray(todo, goal, time_limit, ray_address) if ray_address else _local(todo, goal, time_limit, workers)
    for p, rec in stream:
        _write(out_dir / f"{p.stem}.json", rec)
        records[p] = rec
        if on_record:
            on_record(p, rec, False)
    rows = [_row(p, records[p]) for p in files]
    _write(out_dir / "summary.json", {"goal": goal, "scenes": rows})
    return rows


def output_problem(scenes_dir: Path, out_dir: Path, files: list[Path]) -> str | None:
    """Why ``out_dir`` cannot hold the results of ``files`` (one message naming the option), or
    None: it must be a folder (made if missing) other than ``SCENES_DIR`` (the results would be
    read as scenes by the next run), and no two scene files may share a result file (``a.json``
    and ``a.yaml``, or a scene file named ``summary``)."""
    if out_dir.exists() and not out_dir.is_dir():
        return f"out: '{out_dir}' exists and is not a folder"
    if out_dir.resolve() == scenes_dir.resolve():
        return f"out: '{out_dir}' is SCENES_DIR; the result files would be read as scenes by the next run"
    by_stem: dict[str, Path] = {}
    for f in files:
        if f.stem == "summary":
            return f"SCENES_DIR: '{f.name}' would share its result file with OUT/summary.json; rename it"
        if f.stem in by_stem:
            return (f"SCENES_DIR: '{by_stem[f.stem].name}' and '{f.name}' would share the result file "
                    f"OUT/{f.stem}.json; rename one")
        by_stem[f.stem] = f
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        return f"out: cannot create the folder '{out_dir}' ({e.strerror or type(e).__name__})"
    if not os.access(out_dir, os.W_OK | os.X_OK):
        return f"out: the folder '{out_dir}' is not writable"
    return None


def _row(p: Path, rec: dict[str, Any]) -> dict[str, Any]:
    return {"file": p.name, "scene": rec.get("scene", p.stem), "status": rec["status"],
            "steps": rec.get("steps"), "feasible": rec.get("feasible"), "seconds": rec.get("seconds"),
            "note": rec.get("error") or rec.get("reason") or ""}


def batch(
    scenes_dir: Annotated[Path, typer.Argument(help="folder of scene files (.json, .yaml)")],
    out: Annotated[Path, typer.Option(help="folder for one result file per scene")] = Path("results"),
    goal: Annotated[str | None, typer.Option(help="plan to this goal: active, passive, combination:FSDD, "
                                                  "pose:x,y,theta")] = None,
    enumerate_: Annotated[bool, typer.Option("--enumerate", help="enumerate every combination instead of "
                                                                  "planning")] = False,
    ray: Annotated[str | None, typer.Option(help="run on Ray: an address, 'auto', or 'local'")] = None,
    workers: Annotated[int, typer.Option(help="local worker processes (without --ray)")] = max(1, (os.cpu_count()
                                                                                                   or 1)),
    time_limit: Annotated[float | None, typer.Option(help="seconds per plan")] = None,
    retry_failed: Annotated[bool, typer.Option(help="run failed scenes again")] = False,
) -> None:
    """Plan (--goal) or enumerate (--enumerate) every scene of a folder; resumable."""
    err = Console(stderr=True)
    console = Console()

    def fail(msg: str) -> NoReturn:
        err.print(f"[bold red]error:[/] {msg}", highlight=False, soft_wrap=True)
        raise typer.Exit(2)

    if not scenes_dir.is_dir():
        fail(f"SCENES_DIR: '{scenes_dir}' is not a folder")
    if (goal is None) == (not enumerate_):
        fail("goal: give either --goal GOAL (plan) or --enumerate")
    if workers < 1:
        fail(f"workers: {workers} must be at least 1")
    if time_limit is not None and time_limit <= 0:
        fail(f"time-limit: {time_limit} must be positive")
    goal_data = None
    if goal is not None:
        try:
            goal_data = parse_goal(goal)
        except (ValidationError, ValueError) as e:
            fail(f"goal: '{goal}' is not a goal ({str(e).splitlines()[0]})")
    try:
        files = scene_files(scenes_dir)
    except OSError as e:
        fail(f"SCENES_DIR: cannot list '{scenes_dir}' ({e.strerror or type(e).__name__})")
    if not files:
        fail(f"SCENES_DIR: no scene files (.json, .yaml) in '{scenes_dir}'")
    problem = output_problem(scenes_dir, out, files)
    if problem:
        fail(problem)
    with Progress(TextColumn("scenes"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TextColumn("{task.description}"), console=err) as bar:
        task = bar.add_task("", total=len(files))

        def on_record(p: Path, rec: dict[str, Any], skipped: bool) -> None:
            bar.update(task, advance=1, description=f"{p.name}: {'done before' if skipped else rec['status']}")

        try:
            rows = run_batch(scenes_dir, out, goal_data, ray_address=ray, workers=workers, time_limit=time_limit,
                             retry_failed=retry_failed, on_record=on_record)
        except OSError as e:  # the results cannot be written (disk full, folder removed): say so
            where = f"'{e.filename}'" if e.filename else f"'{out}'"
            fail(f"out: cannot write {where} ({e.strerror or type(e).__name__}); the results written "
                 "so far are kept and a new run resumes from them")
    table = Table(title=f"{len(rows)} scenes -> {out}")
    for col in ("scene", "status", "steps" if goal_data else "feasible", "time [s]", "note"):
        table.add_column(col)
    for r in rows:
        n = r["steps"] if goal_data else r["feasible"]
        table.add_row(r["scene"], r["status"], "-" if n is None else str(n),
                      "-" if r["seconds"] is None else f"{r['seconds']:.2f}", str(r["note"])[:80])
    console.print(table)
    if any(r["status"] == "failed" for r in rows):
        raise typer.Exit(1)


batch_app = typer.Typer(add_completion=False)
batch_app.command()(batch)


def main(args: list[str]) -> None:
    """Entry of ``ctp batch`` (registered lazily in :mod:`ctp.cli`)."""
    command = typer.main.get_command(batch_app)
    try:
        command.main(args=list(args), prog_name="ctp batch", standalone_mode=True)
    except SystemExit as e:
        if e.code:
            raise typer.Exit(e.code if isinstance(e.code, int) else 1) from None
