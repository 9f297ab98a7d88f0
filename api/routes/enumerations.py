"""Enumerations as jobs: every combination of a scene, for scenes too large for the synchronous
``POST /analyses`` (e.g. nine contacts: 19,683 combinations). Same life cycle as plans."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Response
from pydantic import SkipValidation

from api.bodies import ScreenedBodyRoute
from api.body_rules import ENUMERATION_BODY
from api.deps import RunnerDep, SettingsDep, StoreDep, check_scene
from api.routes import _jobs
from api.schemas import AnalysisPublic, EnumerationCreate, EnumerationPublic, ErrorBody, JobList, JobStatus

router = APIRouter(prefix="/enumerations", tags=["enumerations"], route_class=ScreenedBodyRoute)
KIND, WHAT = "enumeration", "enumeration"


@router.post("", status_code=202, response_model=EnumerationPublic,
             responses={413: {"model": ErrorBody}, 422: {"model": ErrorBody}})
def create_enumeration(raw: Annotated[EnumerationCreate, SkipValidation], settings: SettingsDep, store: StoreDep,
                       runner: RunnerDep, response: Response) -> dict[str, Any]:
    """Queue the enumeration of every combination; 202 with the job."""
    # 413 before the model spends time on a huge chain or thousands of contacts, then the model in
    # the thread this route runs in; a body over inline_body_bytes was screened in a worker (api/bodies.py)
    body = ENUMERATION_BODY.validate(raw, settings)
    check_scene(body.scene, settings, enumerate_all=True)
    limit = _jobs.time_limit(body.time_limit, settings.job_time_limit)
    job = _jobs.submit(store, runner, KIND, {"scene": body.scene.model_dump(mode="json"), "time_limit": limit})
    response.headers["Location"] = f"/enumerations/{job.id}"
    return _jobs.public(job, "/enumerations")


@router.get("", response_model=JobList)
def list_enumerations(store: StoreDep, status: JobStatus | None = None,
                      limit: Annotated[int, Query(ge=1, le=1000)] = 100,
                      offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0) -> dict[str, Any]:
    items = [_jobs.public(j, "/enumerations") for j in store.list_jobs(KIND, status, limit, offset)]
    return {"items": items, "count": len(items)}


@router.get("/{job_id}", response_model=EnumerationPublic, responses=_jobs.ERRORS)
def get_enumeration(job_id: str, store: StoreDep) -> dict[str, Any]:
    return _jobs.public(_jobs.get(store, KIND, job_id, WHAT), "/enumerations")


@router.get("/{job_id}/result", response_model=AnalysisPublic,
            responses={**_jobs.ERRORS, 409: {"model": ErrorBody, "description": "not finished or failed"}})
def get_enumeration_result(job_id: str, store: StoreDep) -> dict[str, Any]:
    return _jobs.result(store, KIND, job_id, WHAT)


@router.delete("/{job_id}", response_model=EnumerationPublic, responses=_jobs.CANCEL_ERRORS)
def cancel_enumeration(job_id: str, store: StoreDep, runner: RunnerDep) -> dict[str, Any]:
    return _jobs.public(_jobs.cancel(store, runner, KIND, job_id, WHAT), "/enumerations")
