"""The FastAPI application: ``api.main:app`` (``uvicorn api.main:app``), or ``create_app(settings)``.

Routes: ``POST /analyses`` (synchronous, in a worker process, time-limited), ``/plans`` and
``/enumerations`` (jobs: 202 + id, status, result, cancel, list), ``/scenes/examples``,
``/scenes/upload``, ``/scenes/geometry``, ``/health``, OpenAPI at ``/docs``, the dashboard at ``/``.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.openapi.utils import get_openapi
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from api import errors
from api.cache import RepeatedBodies, ResultCache
from api.http_methods import AllowedMethods
from api.jobs import JobRunner
from api.lanes import HEAVY_NICE, LaneHeader
from api.routes import analyses, enumerations, health, plans, robot_files, robots, scenes
from api.schemas import ErrorBody
from api.settings import Settings, get_settings
from api.store import JobStore
from api.workers import ProcessPool, RayExecutor

STATIC = Path(__file__).resolve().parent / "static"
# Swagger UI served from the vendored npm package (api/static/vendor/manifest.json), so /docs
# works with no internet; ReDoc is not vendored and so is switched off
SWAGGER_UI = "/static/vendor/swagger-ui/5.35.0"
log = logging.getLogger("ctp.api")


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        store = JobStore(settings.database_url, timeout=settings.store_timeout_seconds)
        # two lanes: tables of every combination on niced workers, light requests on their own
        # (api/lanes.py); jobs in the background at the same lower priority
        pool = ProcessPool(settings.analysis_workers, "analysis", nice=HEAVY_NICE)
        light = ProcessPool(settings.light_workers, "light")
        executor: ProcessPool | RayExecutor
        if settings.ray_address:
            executor = RayExecutor(settings.ray_address, settings.job_workers)
            app.state.executor_name = f"ray ({settings.ray_address})"
        else:
            executor = ProcessPool(settings.job_workers, "jobs", nice=HEAVY_NICE)
            app.state.executor_name = f"processes ({settings.job_workers})"
        await asyncio.gather(pool.start(), light.start())
        runner = None
        if settings.run_jobs:
            await executor.start()
            runner = JobRunner(store, executor, slots=settings.job_workers, lease=settings.job_lease_seconds,
                               poll=settings.job_poll_seconds, default_time_limit=settings.job_time_limit,
                               max_attempts=settings.job_max_attempts,
                               retry_max=settings.store_retry_max_seconds)
            runner.start()
        app.state.store, app.state.analysis_pool, app.state.runner = store, pool, runner
        app.state.light_pool = light
        app.state.analysis_cache = ResultCache(settings.analysis_cache_entries)
        try:
            yield
        finally:
            pool.closing = executor.closing = light.closing = True
            if runner is not None:
                await runner.stop()
            await executor.close()
            await pool.close()
            await light.close()
            store.close()

    app = FastAPI(
        title="Contact-state transition planner",
        version="0.1.0",
        summary="Closure analysis (DAFC, DPFC, joint torques) and contact-state transition plans over HTTP.",
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    errors.install(app)
    for r in (analyses.router, plans.router, enumerations.router, scenes.router, health.router):
        app.include_router(r)
    app.include_router(robot_files.router)  # URDFs and meshes for the 3-D view
    app.include_router(robots.router_for(settings))  # POST /robots: uploaded URDFs (exports CTP_DATA_DIR)
    app.add_middleware(errors.BodySizeLimit, limit=settings.max_body_bytes)
    app.add_middleware(AllowedMethods)
    app.add_middleware(LaneHeader)
    app.add_middleware(RepeatedBodies, path="/analyses", limit=settings.max_body_bytes)  # outermost
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]

    @app.get("/", include_in_schema=False)
    def dashboard() -> FileResponse:
        return FileResponse(STATIC / "index.html")

    @app.get("/docs", include_in_schema=False)
    def docs() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=app.openapi_url or "/openapi.json", title=f"{app.title} - API docs",
            swagger_js_url=f"{SWAGGER_UI}/swagger-ui-bundle.js", swagger_css_url=f"{SWAGGER_UI}/swagger-ui.css",
            swagger_favicon_url=f"{SWAGGER_UI}/favicon-32x32.png", oauth2_redirect_url="/docs/oauth2-redirect",
            swagger_ui_parameters={"validatorUrl": None})  # no request to validator.swagger.io

    @app.get("/docs/oauth2-redirect", include_in_schema=False)
    def docs_oauth2_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    return app


def _openapi(app: FastAPI) -> dict[str, Any]:
    """FastAPI's schema, with the error bodies this service really sends (api/errors.py): every
    422 is an ``ErrorBody`` (``detail`` a string naming the field, ``errors`` the list), and
    every operation with a body may answer 413 (``max_body_bytes``)."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(title=app.title, version=app.version, summary=app.summary, routes=app.routes)
    comps = schema.setdefault("components", {}).setdefault("schemas", {})
    body = ErrorBody.model_json_schema(ref_template="#/components/schemas/{model}")
    comps.update(body.pop("$defs", {}))
    comps["ErrorBody"] = body
    comps["HTTPValidationError"] = {"$ref": "#/components/schemas/ErrorBody"}
    ref = {"$ref": "#/components/schemas/ErrorBody"}
    err = {"description": "error", "content": {"application/json": {"schema": ref}}}
    for ops in schema.get("paths", {}).values():
        for op in ops.values():
            if "requestBody" in op:
                op["responses"].setdefault("413", {**err, "description": "request body too large (limit)"})
                op["responses"].setdefault("422", {**err, "description": "invalid request (detail names the field)"})
    app.openapi_schema = schema
    return schema


app = create_app()
