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


def run_plan(payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    """A plan from the scene's grasp to the goal (``planner.plan``)."""
    from planner import Goal, plan  # on a worker's first plan only (see the module docstring)

    t0 = time.perf_counter()
    scene = scene_from_dict(payload["scene"])
    goal = Goal.model_validate(payload["goal"])
    result = plan(scene, goal, progress=progress, time_limit=payload.get("time_limit"))
    out: dict[str, Any] = result.to_json()
    out.setdefault("elapsed_seconds", time.perf_counter() - t0)
    return out


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


def _rounded(a: Any) -> list[float]:
    return [round(float(x), 9) for x in np.asarray(a).ravel()]


TASKS: dict[str, Callable[[dict[str, Any], Progress | None], dict[str, Any]]] = {
    "analysis": run_analysis,
    "enumeration": run_enumeration,
    "plan": run_plan,
    "geometry": run_geometry,
    "contacts": run_contacts,
}


def run_task(kind: str, payload: dict[str, Any], progress: Progress | None = None) -> dict[str, Any]:
    return TASKS[kind](payload, progress)

