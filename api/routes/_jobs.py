"""What the job resources (plans, enumerations) share: submit, status, result, cancel, list."""

from __future__ import annotations

import time
from typing import Any

from api.errors import ApiError, not_found
from api.jobs import JobRunner
from api.schemas import JobPublic
from api.store import Job, JobStore

ERRORS: dict[int | str, dict[str, Any]] = {
    404: {"description": "no such job"},
}
CANCEL_ERRORS: dict[int | str, dict[str, Any]] = {
    **ERRORS,
    409: {"description": "the job has already succeeded or failed: nothing to cancel, nothing changed"},
}


def public(job: Job, prefix: str) -> dict[str, Any]:
    queued = None
    if job.started_at is not None:
        queued = job.started_at - job.created_at
    elif job.status == "queued":
        queued = time.time() - job.created_at
    url = f"{prefix}/{job.id}"
    return {"id": job.id, "kind": job.kind, "status": job.status, "progress": job.progress,
            "message": job.message, "error": job.error, "created_at": job.created_at,
            "started_at": job.started_at, "finished_at": job.finished_at, "elapsed_seconds": job.elapsed,
            "queued_seconds": queued, "attempts": job.attempts,
            "result_url": f"{url}/result" if job.status == "succeeded" else None, "url": url}


def submit(store: JobStore, runner: JobRunner | None, kind: str, request: dict[str, Any]) -> Job:
    job = store.submit(kind, request)  # committed before the 202 goes out
    if runner is not None:
        runner.wake()
    return job


def get(store: JobStore, kind: str, job_id: str, what: str) -> Job:
    job = store.get(job_id)
    if job is None or job.kind != kind:
        raise not_found(what, job_id)
    return job


def result(store: JobStore, kind: str, job_id: str, what: str) -> dict[str, Any]:
    job = get(store, kind, job_id, what)
    if job.status != "succeeded":
        why = f" ({job.error})" if job.error else ""
        raise ApiError(409, f"{what} '{job_id}' has no result: it is {job.status}{why}")
    data = store.result(job_id)
    assert data is not None
    return data


def cancel(store: JobStore, runner: JobRunner | None, kind: str, job_id: str, what: str) -> Job:
    job = get(store, kind, job_id, what)
    if job.status == "cancelled":
        return job  # cancelling again changes nothing and says so with the job
    if job.status in ("succeeded", "failed"):  # nothing to cancel: 409, the job unchanged
        raise ApiError(409, f"{what} '{job_id}' has already {job.status}: a finished {what} cannot be cancelled",
                       errors=[{"loc": [], "msg": f"already {job.status}", "type": "conflict"}])
    out = store.cancel(job_id)
    if runner is not None:
        runner.wake()
    assert out is not None
    return out


def time_limit(requested: float | None, maximum: float) -> float:
    if requested is not None and requested > maximum:
        raise ApiError(422, f"time_limit: {requested:g} s is over this server's limit of {maximum:g} s "
                            "(job_time_limit)", limit=maximum,
                       errors=[{"loc": ["time_limit"], "msg": f"at most {maximum:g}", "type": "too_large"}])
    return requested if requested is not None else maximum


__all__ = ["CANCEL_ERRORS", "ERRORS", "JobPublic", "cancel", "get", "public", "result", "submit", "time_limit"]
