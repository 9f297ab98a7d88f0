"""Every error the service returns, mapped in one place.

* 422: malformed JSON, scene, goal or combination (pydantic, ``SceneError``); ``detail`` names
  the field (``scene.contacts.2.normal: ...``), ``errors`` lists them all. Also: the analysis
  says no (e.g. the requested direction has no torque set) or a solver hit its limit; and a
  synchronous analysis over ``request_time_limit`` (``detail`` says so and points to
  ``POST /enumerations``; ``limit`` = the limit). A time limit is a property of the request
  (too much work for a synchronous call), not a server fault, hence 422 and not 504.
* 413: too many contacts (``limit`` = ``max_contacts``) or request body too large
  (``limit`` = ``max_body_bytes``).
* 404: unknown job. 409: result of an unfinished or failed job (``detail``: status, reason), or
  ``DELETE`` of a job that already succeeded or failed (nothing changes).
* 413 also: a scene over ``max_joints`` joints (``limit``). 405: ``Allow`` names every method of
  the path, as ``OPTIONS`` does (api/http_methods.py).
* 503: a worker crashed; or the job store is unavailable (unreachable, locked by another
  process, damaged, disk full): every route that needs it answers JSON 503 with ``Retry-After``
  and ``"store": "unavailable"`` (``/health`` too), never a 500 and never the driver's text.

A job never turns an error into an HTTP status: it fails, and ``GET /plans/{id}`` says why
(``error``: "solver time limit: ...", "time limit: ...", "analysis: no stationary grasp ...").
"""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import SQLAlchemyError
from starlette.exceptions import HTTPException

from analysis.exceptions import CTPError, SceneError
from api.exceptions import ApiError as ApiError  # raised by the routes as api.errors.ApiError
from api.store import StoreUnavailable, failure_kind
from api.workers import TaskError, TaskTimeout

log = logging.getLogger("ctp.api")


def not_found(what: str, ident: str) -> ApiError:
    return ApiError(404, f"{what} '{ident}' not found")


def _clean(loc: Any) -> list[str | int]:
    from analysis.scene import _clean_loc

    parts = [p if isinstance(p, int) else str(p) for p in loc]
    if parts and parts[0] == "body":
        parts = parts[1:]
    if parts and parts[0] == "scene":
        return ["scene", *list(_clean_loc(tuple(parts[1:])))]
    return parts


def _fmt(loc: list[str | int]) -> str:
    return ".".join(str(p) for p in loc) if loc else "body"


def _items(errors: Any) -> list[dict[str, Any]]:
    out = []
    for e in errors:
        loc = _clean(e.get("loc", ()))
        msg = str(e.get("msg", "")).removeprefix("Value error, ")  # pydantic's prefix of a validator's own words
        out.append({"loc": loc, "msg": msg, "type": str(e.get("type", "value_error"))})
    return out


def _body(detail: str, errors: list[dict[str, Any]] | None = None, limit: float | None = None) -> dict[str, Any]:
    body: dict[str, Any] = {"detail": detail, "errors": errors or []}
    if limit is not None:
        body["limit"] = limit
    return body


def validation_response(errors: list[dict[str, Any]]) -> JSONResponse:
    loc: list[str | int] = list(errors[0]["loc"]) if errors else []
    msg = str(errors[0]["msg"]) if errors else "invalid request"
    return JSONResponse(_body(f"{_fmt(loc)}: {msg}", errors), status_code=422)


_REQUEST_FIELDS = ("combination", "direction", "nu", "goal", "time_limit", "scene", "touch", "samples")


def _in_request(loc: list[Any]) -> list[Any]:
    """A location inside the request body: scene errors are located in ``scene``."""
    return loc if loc and loc[0] in _REQUEST_FIELDS else ["scene", *loc]


def task_error_response(e: TaskError) -> JSONResponse:
    if e.type == "scene":
        loc = _in_request(list(e.loc or []))
        errs = [{"loc": _in_request(list(x["loc"])), "msg": x["msg"], "type": x["type"]} for x in (e.errors or [])]
        msg = e.message.split(": ", 1)[1] if ": " in e.message else e.message
        return validation_response(errs or [{"loc": loc, "msg": msg, "type": "scene"}])
    if e.type in ("analysis", "solver_time_limit"):
        return JSONResponse(_body(e.message, [{"loc": [], "msg": e.message, "type": e.type}]), status_code=422)
    if e.type == "worker_died":
        return JSONResponse(_body(f"the analysis worker stopped unexpectedly: {e.message}"), status_code=503)
    log.error("internal task error: %s", e.message)
    return JSONResponse(_body(f"internal error: {e.message}"), status_code=500)


def store_unavailable_response(exc: StoreUnavailable, retry_after: int, **extra: Any) -> JSONResponse:
    """The one answer to a store that cannot be used now: 503, ``Retry-After``, JSON naming only
    the kind of failure (the SQL, the driver's message and the URL stay in the server log)."""
    detail = f"{exc}; retry in {retry_after} s"
    body = {**_body(detail, [{"loc": [], "msg": detail, "type": "store_unavailable"}]), "store": "unavailable",
            **extra}
    return JSONResponse(body, status_code=503, headers={"Retry-After": str(retry_after)})


def _retry_after(request: Request) -> int:
    return int(getattr(request.app.state.settings, "store_retry_after_seconds", 5))


def install(app: FastAPI) -> None:
    @app.exception_handler(StoreUnavailable)
    async def _store(request: Request, exc: StoreUnavailable) -> JSONResponse:
        return store_unavailable_response(exc, _retry_after(request))

    @app.exception_handler(SQLAlchemyError)
    async def _store_raw(request: Request, exc: SQLAlchemyError) -> JSONResponse:
        # a database error that bypassed the store's translation: the same answer, nothing leaked
        log.warning("untranslated store error: %s", type(exc).__name__)
        return store_unavailable_response(StoreUnavailable(failure_kind(exc)), _retry_after(request))

    @app.exception_handler(RequestValidationError)
    async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        return validation_response(_items(exc.errors()))

    @app.exception_handler(SceneError)
    async def _scene(_: Request, exc: SceneError) -> JSONResponse:
        errs = [{**x, "loc": _in_request(list(x["loc"]))} for x in _items(exc.errors)]
        return validation_response(errs)

    @app.exception_handler(CTPError)
    async def _ctp(_: Request, exc: CTPError) -> JSONResponse:
        return JSONResponse(_body(str(exc)), status_code=422)

    @app.exception_handler(ApiError)
    async def _api(_: Request, exc: ApiError) -> JSONResponse:
        return JSONResponse(_body(exc.detail, exc.errors, exc.limit), status_code=exc.status)

    @app.exception_handler(HTTPException)
    async def _http(_: Request, exc: HTTPException) -> JSONResponse:
        limit = exc.limit if isinstance(exc, _TooLarge) else None
        if exc.status_code == 400:  # the body could not be read as JSON or multipart: say so as a 422
            detail = f"body: {exc.detail} (send UTF-8 JSON, or multipart/form-data for uploads)"
            if isinstance(exc.__cause__, RecursionError):
                detail = "body: the JSON is nested too deeply to parse"
            return JSONResponse(_body(detail, [{"loc": ["body"], "msg": str(exc.detail), "type": "body_unreadable"}]),
                                status_code=422)
        return JSONResponse(_body(str(exc.detail), limit=limit), status_code=exc.status_code,
                            headers=getattr(exc, "headers", None))

    @app.exception_handler(TaskTimeout)
    async def _timeout(_: Request, exc: TaskTimeout) -> JSONResponse:
        detail = (f"time limit: the analysis was {exc} (request_time_limit); submit large enumerations "
                  "as a job with POST /enumerations")
        return JSONResponse(_body(detail, [{"loc": [], "msg": detail, "type": "time_limit"}], exc.limit),
                            status_code=422)

    @app.exception_handler(TaskError)
    async def _task(_: Request, exc: TaskError) -> JSONResponse:
        return task_error_response(exc)


#: Requests whose body has a limit of its own: (method, path) -> the setting that holds it.
OWN_BODY_LIMITS = {("POST", "/robots"): "max_robot_archive_bytes"}


class BodySizeLimit:
    """ASGI middleware: a request body over ``limit`` bytes gets 413 (by its Content-Length, or
    while it streams in when it is chunked). The requests of :data:`OWN_BODY_LIMITS` (robot
    archives) have the limit of their setting instead."""

    def __init__(self, app: Any, limit: int):
        self.app = app
        self.limit = limit

    def _limit_of(self, scope: Any) -> tuple[int, str]:
        setting = OWN_BODY_LIMITS.get((scope.get("method", ""), scope.get("path", "")))
        settings = getattr(getattr(scope.get("app"), "state", None), "settings", None)
        if setting is not None and settings is not None:
            return int(getattr(settings, setting)), setting
        return self.limit, "max_body_bytes"

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit, setting = self._limit_of(scope)
        for name, value in scope.get("headers", []):
            if name == b"content-length":
                try:
                    size = int(value)
                except ValueError:
                    size = -1
                if size > limit or size < 0:
                    await self._reject(send, limit, setting)
                    return
        seen = 0
        started = False

        async def limited_receive() -> Any:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > limit:
                    raise _TooLarge(limit, setting)
            return msg

        async def tracking_send(msg: Any) -> None:
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except _TooLarge:
            if not started:
                await self._reject(send, limit, setting)

    async def _reject(self, send: Any, limit: int, setting: str) -> None:
        import json

        body = json.dumps(_body(f"request body too large: the limit is {limit} bytes ({setting})",
                                limit=limit)).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
        await send({"type": "http.response.body", "body": body})


class _TooLarge(HTTPException):
    def __init__(self, limit: int, setting: str = "max_body_bytes"):
        super().__init__(413, f"request body too large: the limit is {limit} bytes ({setting})")
        self.limit = limit
