"""The work itself, run inside worker processes (or Ray tasks): pure functions of JSON-ready
payloads, returning JSON-ready results. They re-validate the scene (cheap) so a worker never
trusts a pickled object, and raise the project's exceptions, which the caller maps.

Worker processes (spawned, so they import afresh) load this module before saying they are ready,
and with it the analysis: a fresh worker is warm before its first request. The planner (with OMPL,
about 1.5 s to import) loads on a worker's first plan, so the analysis pool restarts quickly.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

from analysis.combination import analyze_combination
from analysis.contacts import build_system
from analysis.dafc import SEMANTICS
from analysis.enumerate import enumerate_combinations
from analysis.loader import scene_from_dict
from analysis.scene import check_enumerable

Progress = Callable[[float, str], None]

#: Job kinds and the task each runs.
KINDS = ("analysis", "enumeration", "plan")


#: Scenes whose grasp system a worker keeps (the light requests of one user are mostly other
#: combinations of the same scene: its validation and kinematics are done once).
SYSTEMS_KEPT = 4
_systems: OrderedDict[str, tuple[Any, Any]] = OrderedDict()


def _system(payload: dict[str, Any]) -> tuple[Any, Any]:
    """The scene and its grasp system, from this worker's last :data:`SYSTEMS_KEPT` scenes when
    it saw this one (by the SHA-256 of its canonical JSON; the analysis does not change a
    system). A scene that fails validation is never kept."""
    key = hashlib.sha256(json.dumps(payload["scene"], sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    kept = _systems.get(key)
    if kept is not None:
        _systems.move_to_end(key)
        return kept
    scene = scene_from_dict(payload["scene"])
    kept = scene, build_system(scene)
    _systems[key] = kept
    while len(_systems) > SYSTEMS_KEPT:
        _systems.popitem(last=False)
    return kept


def run_analysis(payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    """``POST /analyses``: the full report of one combination, or the table of all of them."""
    if payload.get("combination"):
        t0 = time.perf_counter()
        scene, system = _system(payload)
        direction = payload.get("direction")
        rep = analyze_combination(system, payload["combination"],
                                  direction=None if direction is None else np.asarray(direction, dtype=float),
                                  nu=payload.get("nu"), samples=payload.get("samples"))
        return {"scene": scene.name, "dim": scene.dim, "kind": "combination", "report": rep.to_json(),
                "elapsed_seconds": time.perf_counter() - t0}
    return run_enumeration(payload, progress)


def run_enumeration(payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    """Every combination's summary (feasible, DAFC dimension, an example direction)."""
    t0 = time.perf_counter()
    scene, system = _system(payload)
    check_enumerable(scene)  # 3**L combinations: the contact cap of full enumeration

    def on_step(k: int, n: int) -> None:
        if progress is not None and n:
            progress(k / n, f"{k} of {n} combinations")

    summaries, stats = enumerate_combinations(system, progress=on_step, workers=1)
    rows = [s.to_json() for s in summaries]
    return {"scene": scene.name, "dim": scene.dim, "kind": "enumeration", "semantics": SEMANTICS,
            "combinations": rows, "feasible": sum(1 for r in rows if r["feasible"]),
            "stats": {"combinations": stats.combinations, "pruned_motion": stats.pruned_motion,
                      "pruned_stationary": stats.pruned_stationary, "stationary_lps": stats.stationary_lps},
            "elapsed_seconds": time.perf_counter() - t0}


#: with ``replay``: the share of the job's time limit the search may use (the replay has the rest)
REPLAY_PLAN_SHARE = 0.75
#: with ``replay``: seconds of the time limit kept free after the replay (result written, worker reply)
REPLAY_MARGIN = 1.0
#: units of the replay's figures in a plan result (``replay.units``)
REPLAY_UNITS = {"position_error": "m", "rotation_error": "rad", "planned_translation": "m",
                "planned_rotation": "rad", "position_scale": "m", "rotation_scale": "rad",
                "relative_position_error": "1", "relative_rotation_error": "1", "duration": "s (simulated)",
                "object_path.times": "s (simulated)",
                "poses": "pose vectors: 2-D (x [m], y [m], theta [rad]); 3-D (p [m], rotation vector [rad])",
                "max_regrasp_deviation": "m (|dp| + object size * |dtheta|)", "tracking_error": "rad"}


def run_plan(payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    """A plan from the scene's grasp to the goal (``planner.plan``, with the planner switches of
    ``options``); with ``replay``, then its continuous MuJoCo replay (:func:`_replay`, the result's
    ``replay``)."""
    from planner import Goal, plan  # on a worker's first plan only (see the module docstring)
    from planner.options import PlannerOptions

    t0 = time.perf_counter()
    scene = scene_from_dict(payload["scene"])
    goal = Goal.model_validate(payload["goal"])
    limit = payload.get("time_limit")
    replay = bool(payload.get("replay"))
    search_limit = limit * REPLAY_PLAN_SHARE if (replay and limit is not None) else limit
    on_search = progress
    if replay and progress is not None:
        def on_search(frac: float, message: str) -> None:
            progress(REPLAY_PLAN_SHARE * frac, message)
    options = PlannerOptions(**payload["options"]) if payload.get("options") else None  # api.schemas.PlannerSwitches
    result = plan(scene, goal, progress=on_search, time_limit=search_limit, options=options)
    out: dict[str, Any] = result.to_json()
    out.setdefault("elapsed_seconds", time.perf_counter() - t0)
    if replay:
        left = None if limit is None else limit - (time.perf_counter() - t0) - REPLAY_MARGIN
        if progress is not None:
            progress(REPLAY_PLAN_SHARE, "replaying the plan in MuJoCo")
        out["replay"] = _replay(scene, out, left)
    return out


def _replay(scene: Any, plan_json: dict[str, Any], time_limit: float | None) -> dict[str, Any]:
    """The plan's continuous MuJoCo replay (:func:`sim.plan_replay.simulate_plan` of the plan's JSON
    form, as ``ctp simulate`` runs a plan file) within ``time_limit`` seconds, as JSON:
    ``status`` ``"done"`` with every figure of ``PlanSimulation.to_json`` (``ok``, ``dropped``,
    ``drop_reason``, position and rotation errors, per-step ``planned`` and ``simulated``, the
    sampled ``object_path``), ``summary`` (the errors in words with units) and ``units``;
    ``"skipped"`` when there is nothing to replay (no plan, or no steps); ``"failed"`` with the
    replay's ``error`` (out of time, a plan that does not fit its scene): the plan itself stands."""
    base: dict[str, Any] = {"units": REPLAY_UNITS}
    if not plan_json.get("found"):
        return {**base, "status": "skipped", "error": None, "reason": "no plan was found: nothing to replay"}
    if not plan_json.get("steps"):
        return {**base, "status": "skipped", "error": None,
                "reason": "the start already meets the goal: the plan has no steps to replay"}
    if time_limit is not None and time_limit <= 0:
        return {**base, "status": "failed", "error": "time limit: planning used the job's time limit, none was "
                                                     "left for the replay (time_limit)"}
    from analysis.exceptions import CTPError
    from sim.plan_replay import simulate_plan  # MuJoCo: on a worker's first replay only

    t0 = time.perf_counter()
    try:
        sim = simulate_plan(scene, plan_json, time_limit=time_limit)
    except CTPError as e:
        return {**base, "status": "failed", "error": f"{type(e).__name__}: {e}",
                "elapsed_seconds": time.perf_counter() - t0}
    except Exception as e:  # reported in the result, never silently: the plan is still returned
        return {**base, "status": "failed", "error": f"internal error in the replay ({type(e).__name__}: {e})",
                "elapsed_seconds": time.perf_counter() - t0}
    return {**base, "status": "done", "error": None, **sim.to_json(),
            "summary": ("dropped: " + sim.drop_reason) if sim.dropped else sim.error.describe(sim.tolerance),
            "elapsed_seconds": time.perf_counter() - t0}


def run_geometry(payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    """``POST /scenes/geometry``: world coordinates to draw (each finger's links for the scene's
    ``q`` or for each of ``configurations``, fixed bodies, object, contacts with their friction
    cone's half angle). In a worker, so its cost (the chain length times the configurations) is
    under the request's time limit."""
    from analysis.kinematics import HandKinematics

    scene = scene_from_dict(payload["scene"])
    hand = HandKinematics.from_scene(scene)
    confs = payload.get("configurations")
    if confs is None:
        confs = [list(map(float, hand.q0))]
    frames = []
    for k, q in enumerate(confs):
        if progress is not None and k % 50 == 0:
            progress(k / len(confs), f"{k} of {len(confs)} configurations")
        qa = np.asarray(q, dtype=float)
        fingers = []
        for i, f in enumerate(scene.fingers):
            links = []
            for name in hand.fingers[i].body_names():
                ref = hand.resolve_body(name)
                assert ref is not None
                a, b = hand.fingers[i].body_segment(ref.link, qa[hand.finger_slice(i)])
                links.append({"body": name, "a": _rounded(a[: scene.dim]), "b": _rounded(b[: scene.dim]),
                              "radius": hand.body_radius(ref)})
            fingers.append({"name": f.name, "links": links})
        frames.append({"q": _rounded(qa), "fingers": fingers})
    contacts = [{"index": i, "body": c.body, "point": c.point, "normal": c.normal, "mu": c.mu,
                 "half_angle": float(np.arctan(c.mu))} for i, c in enumerate(scene.contacts)]
    return {"dim": scene.dim, "joints": hand.M, "object": scene.object.model_dump(mode="json"),
            "fixed_bodies": [b.model_dump(mode="json") for b in scene.fixed_bodies],
            "contacts": contacts, "frames": frames}


def run_contacts(payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    """``POST /scenes/contacts``: the contacts found from the scene's geometry
    (:mod:`analysis.detect`, within ``tolerance``, friction ``mu`` where a body names none), the
    complete scene with them (validated as every scene is) and the near misses."""
    from analysis.loader import with_detected_contacts

    data = {k: v for k, v in payload["scene"].items() if k != "contacts"}
    if payload.get("touch"):
        from analysis.placement import placed_scene_data  # deferred: the placement's solver

        data, _ = placed_scene_data(data, list(payload["touch"]), tolerance=payload["tolerance"])
    full, det = with_detected_contacts(data, tolerance=payload["tolerance"], mu=payload["mu"])
    scene = scene_from_dict(full)
    return {"scene": scene.model_dump(mode="json"),
            "contacts": [{**c.to_json(), "gap": c.gap} for c in det.contacts],
            "near_misses": [{"body": m.body, "distance": m.distance, "object_point": list(m.object_point),
                             "body_point": list(m.body_point)} for m in det.near_misses],
            "tolerance": det.tolerance}


def run_upload(payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    """``POST /scenes/upload``: the uploaded bytes through the scene files' one parser
    (:func:`analysis.loader.parse_scene_data`), the HTTP file rule, contact detection where the
    scene leaves it, the model and the geometric checks; in a worker, so a slow or hostile file
    costs a worker's time under the request's time limit, never the server's. Returns the
    scene's JSON and its joint count; a scene over ``max_joints`` joints returns ``scene`` None
    before any kinematics (the route answers 413)."""
    from pydantic import ValidationError

    from analysis.exceptions import SceneError
    from analysis.loader import check_geometry, parse_scene_data, wants_detection, with_detected_contacts
    from analysis.scene import Scene
    from api.schemas import _check_files

    data = parse_scene_data(payload["raw"], payload["suffix"], max_bytes=payload["max_bytes"])  # FILE_ERROR items
    try:
        _check_files(data)
    except ValueError as e:  # "<field>: <reason>", a URDF or mesh outside the allowed places
        where, _, reason = str(e).partition(": ")
        loc = tuple(int(p) if p.isdigit() else p for p in where.split("."))
        raise SceneError(loc, reason) from None
    if wants_detection(data):  # contacts omitted, [] or "auto": found from the geometry
        data, _ = with_detected_contacts(data)
    try:
        scene = Scene.model_validate(data)
    except ValidationError:
        scene_from_dict(data)  # raises the SceneError naming the first bad field
        raise
    joints = scene.M
    if joints > payload["max_joints"]:
        return {"scene": None, "joints": joints}
    check_geometry(scene)
    return {"scene": scene.model_dump(mode="json"), "joints": joints}


def run_body(payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    """A scene-taking route's large JSON body, decoded and run through the route's rule in a
    worker (:func:`api.body_rules.screen_body`): the refusal or ``{"accepted": True}``."""
    from api.body_rules import screen_body

    return screen_body(payload["rule"], payload["body"], payload["limits"])


def _rounded(a: Any) -> list[float]:
    return [round(float(x), 9) for x in np.asarray(a).ravel()]


TASKS: dict[str, Callable[[dict[str, Any], Progress | None], dict[str, Any]]] = {
    "analysis": run_analysis,
    "enumeration": run_enumeration,
    "plan": run_plan,
    "geometry": run_geometry,
    "contacts": run_contacts,
    "upload": run_upload,
    "body": run_body,
}


def run_task(kind: str, payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    return TASKS[kind](payload, progress)

