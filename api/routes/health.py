from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter

from api.deps import AnalysisPoolDep, ExecutorNameDep, SettingsDep, StoreDep
from api.schemas import Health

router = APIRouter(tags=["health"])


def _version() -> str:
    try:
        return version("contact-transition-planner")
    except PackageNotFoundError:  # pragma: no cover
        return "unknown"


@router.get("/health", response_model=Health)
def health(settings: SettingsDep, store: StoreDep, pool: AnalysisPoolDep, executor: ExecutorNameDep) -> Health:
    """Liveness and what this server runs on; ``jobs`` counts jobs by status."""
    url = store.engine.url
    return Health(status="ok", version=_version(), database=url.get_backend_name(), executor=executor,
                  analysis_workers=pool.alive(), job_workers=settings.job_workers, jobs=store.counts())
