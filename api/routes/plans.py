"""Plans: a job each. ``POST /plans`` -> 202 + id; poll ``GET /plans/{id}``; ``GET /plans/{id}/result``."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Response
from pydantic import SkipValidation

from analysis.scene import MAX_MAGNITUDE
from api.bodies import ScreenedBodyRoute
from api.body_rules import PLAN_BODY
from api.deps import RunnerDep, SettingsDep, StoreDep, check_scene
from api.errors import ApiError
from api.routes import _jobs
from api.schemas import ErrorBody, JobList, JobStatus, PlanCreate, PlanPublic
from planner.goals import check_combination

router = APIRouter(prefix="/plans", tags=["plans"], route_class=ScreenedBodyRoute)
KIND, WHAT = "plan", "plan"


@router.post("", status_code=202, response_model=PlanPublic,
             responses={413: {"model": ErrorBody}, 422: {"model": ErrorBody}})
def create_plan(raw: Annotated[PlanCreate, SkipValidation], settings: SettingsDep, store: StoreDep,
                runner: RunnerDep, response: Response) -> dict[str, Any]:
    """Queue a plan from the scene's grasp to ``goal``; 202 with the job (``url`` to poll)."""
    # 413 before the model spends time on a huge chain, then the model in the thread this route
    # runs in; a body over inline_body_bytes was screened in a worker (api/bodies.py)
    body = PLAN_BODY.validate(raw, settings)
    check_scene(body.scene, settings)
    if body.goal.combination is not None and len(body.goal.combination) != len(body.scene.contacts):
        raise ApiError(422, f"goal.combination: '{body.goal.combination}' has {len(body.goal.combination)} "
                            f"letters; the scene has {len(body.scene.contacts)} contacts",
                       errors=[{"loc": ["goal", "combination"], "msg": "one letter per contact",
                                "type": "value_error"}])
    check_combination(body.goal, body.scene)  # letters that fit each contact's friction (SceneError: 422)
    for name in ("pose", "displacement"):  # pose vectors of the scene's dimension, checked before queueing
        vec = getattr(body.goal, name)
        if vec is not None and len(vec) != body.scene.D:
            raise ApiError(422, f"goal.{name}: has {len(vec)} values; a {body.scene.dim}-D object needs "
                                f"{body.scene.D}",
                           errors=[{"loc": ["goal", name], "msg": f"needs {body.scene.D} values",
                                    "type": "value_error"}])
    if body.goal.point is not None and len(body.goal.point) != body.scene.dim:
        raise ApiError(422, f"goal.point: has {len(body.goal.point)} values; a {body.scene.dim}-D scene needs "
                            f"{body.scene.dim}",
                       errors=[{"loc": ["goal", "point"], "msg": f"needs {body.scene.dim} values",
                                "type": "value_error"}])
    _check_wrenches(body.goal.wrenches, body.scene.D, body.scene.dim)
    limit = _jobs.time_limit(body.time_limit, settings.job_time_limit)
    goal = body.goal.model_dump(mode="json")
    for key in ("body", "point"):  # a contact goal's fields: every other goal keeps its stored form (cache key)
        if goal[key] is None:
            del goal[key]
    request = {"scene": body.scene.model_dump(mode="json"), "goal": goal, "time_limit": limit}
    if body.replay:
        request["replay"] = True  # only when asked: other requests keep their stored form
    if body.options is not None:
        # the switches given; an effort_weight of null is the planner's default, stored as not given
        request["options"] = {k: v for k, v in body.options.model_dump(mode="json", exclude_unset=True).items()
                              if not (k == "effort_weight" and v is None)}
    job = _jobs.submit(store, runner, KIND, request)
    response.headers["Location"] = f"/plans/{job.id}"
    return _jobs.public(job, "/plans")


@router.get("", response_model=JobList)
def list_plans(store: StoreDep, status: JobStatus | None = None,
               limit: Annotated[int, Query(ge=1, le=1000)] = 100,
               offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0) -> dict[str, Any]:
    """Plans, newest first."""
    items = [_jobs.public(j, "/plans") for j in store.list_jobs(KIND, status, limit, offset)]
    return {"items": items, "count": len(items)}


@router.get("/{plan_id}", response_model=PlanPublic, responses=_jobs.ERRORS)
def get_plan(plan_id: str, store: StoreDep) -> dict[str, Any]:
    """Status (queued, running, succeeded, failed, cancelled), progress 0..1, timings, and why it failed."""
    return _jobs.public(_jobs.get(store, KIND, plan_id, WHAT), "/plans")


@router.get("/{plan_id}/result", responses={**_jobs.ERRORS, 409: {"model": ErrorBody,
                                                                   "description": "not finished or failed"}})
def get_plan_result(plan_id: str, store: StoreDep) -> dict[str, Any]:
    """The plan: ``steps`` (kind, combination, joint and object paths, torques), and at the top level
    ``found``, ``outcome`` and ``reason``. A job that ran to its end succeeded whether or not a plan
    was found: a plan that was not found has ``found: false``, ``outcome: "no_plan"``, no steps and
    a ``reason`` naming what blocked it; a start that already meets the goal has ``found: true``,
    ``outcome: "start_meets_goal"`` and no steps; otherwise ``outcome: "reached"``. A plan asked
    with ``replay: true`` also has ``replay``: ``status`` ``done`` (the MuJoCo replay's object
    path, per-step planned and simulated displacements, position error in m and rotation error in
    rad, ``dropped``), ``skipped`` (nothing to replay) or ``failed`` (its ``error``; the plan stands)."""
    return _jobs.result(store, KIND, plan_id, WHAT)


@router.delete("/{plan_id}", response_model=PlanPublic, responses=_jobs.CANCEL_ERRORS)
def cancel_plan(plan_id: str, store: StoreDep, runner: RunnerDep) -> dict[str, Any]:
    """Cancel: a queued plan at once, a running one as soon as its worker is stopped; a plan that
    already succeeded or failed: 409, nothing changed."""
    return _jobs.public(_jobs.cancel(store, runner, KIND, plan_id, WHAT), "/plans")


def _check_wrenches(wrenches: list[list[float]] | None, D: int, dim: int) -> None:
    """``goal.wrenches``: each a wrench of ``D`` components (force and moment) of bounded size,
    refused at submission (422 naming the entry) rather than failing the job later."""
    for k, w in enumerate(wrenches or []):
        loc: list[str | int] = ["goal", "wrenches", k]
        if len(w) != D:
            raise ApiError(422, f"goal.wrenches.{k}: has {len(w)} components; a {dim}-D object's wrench has {D} "
                                "(force and moment)",
                           errors=[{"loc": loc, "msg": f"needs {D} components", "type": "value_error"}])
        big = next((j for j, v in enumerate(w) if abs(v) > MAX_MAGNITUDE), None)
        if big is not None:
            raise ApiError(422, f"goal.wrenches.{k}.{big}: {w[big]:g} is larger than {MAX_MAGNITUDE:g} in "
                                "magnitude", errors=[{"loc": [*loc, big], "msg": f"at most {MAX_MAGNITUDE:g}",
                                                     "type": "too_large"}])
