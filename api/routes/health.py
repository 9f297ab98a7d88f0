from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version
from typing import Any

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from api.deps import AnalysisPoolDep, ExecutorNameDep, SettingsDep, StoreDep
from api.errors import store_unavailable_response
from api.schemas import ErrorBody, Health
from api.store import StoreUnavailable

router = APIRouter(tags=["health"])


def _version() -> str:
    try:
        return version("contact-transition-planner")
    except PackageNotFoundError:  # pragma: no cover
        return "unknown"


@router.get("/health", response_model=Health,
            responses={503: {"model": ErrorBody, "description": "the job store is unavailable (Retry-After)"}})
def health(settings: SettingsDep, store: StoreDep, pool: AnalysisPoolDep, executor: ExecutorNameDep) -> Any:
    """Liveness and what this server runs on; ``jobs`` counts jobs by status. 503 with
    ``"store": "unavailable"`` while the job store cannot be read or written (a lock shows)."""
    try:
        store.ping()
        counts = store.counts()
    except StoreUnavailable as e:
        resp: JSONResponse = store_unavailable_response(
            e, settings.store_retry_after_seconds, status="unavailable", database=store.backend,
            executor=executor, analysis_workers=pool.alive(), job_workers=settings.job_workers)
        return resp
    return Health(status="ok", version=_version(), database=store.backend, executor=executor,
                  analysis_workers=pool.alive(), job_workers=settings.job_workers, store="ok", jobs=counts)
