"""Request bodies validated outside the event loop (the checks themselves: :mod:`api.body_rules`).

FastAPI validates a declared body model in the event loop before the route runs. The
scene-taking routes declare their body as ``Annotated[Model, SkipValidation]``: the OpenAPI
schema is the model's, FastAPI only parses the JSON, and the route checks the parsed body with its
:class:`~api.body_rules.BodyRule` (``check_raw``, the cheap counts that need no model: a 20,000-link
chain is refused in microseconds) and validates it with :func:`~api.body_rules.validate_body`, in a worker thread
(``await validated(...)`` from an ``async def`` route; a plain ``def`` route already runs in one).
The thread keeps the scene model's Python validators off the event loop. An invalid body raises
the same :class:`RequestValidationError` FastAPI would, so its 422 is unchanged (``detail`` names
the field).

A JSON body over ``inline_body_bytes`` (64 kB; the bundled scenes are under 10 kB) is screened
first in a light worker (:class:`ScreenedBodyRoute`, :func:`~api.body_rules.screen_body`): the worker decodes it
and runs the route's rule, counts and model, and answers with the refusal or "accepted". Decoding
a megabyte of JSON holds the interpreter about 35 ms, and pydantic's native validation holds it
too, so in the server a few such bodies at once stalled every other request (``/health`` 0.24-0.32 s
for four bodies of 8,900 contacts); screened, a refused body costs the server only its bytes. An
accepted body is then read by the route as a small one is (it passed the same checks, so its
size is the scene's own).
"""

from __future__ import annotations

import asyncio
import email.message
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

from fastapi import HTTPException, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from pydantic import BaseModel

from analysis.exceptions import SceneError
from api.body_rules import RULE_SETTINGS, RULES, decode_json, validate_body
from api.exceptions import ApiError
from api.lanes import use_lane
from api.settings import Settings

M = TypeVar("M", bound=BaseModel)


async def validated(model: type[M], data: Any) -> M:
    """:func:`validate_body` in a worker thread."""
    return await asyncio.to_thread(validate_body, model, data)


def raise_refusal(outcome: dict[str, Any]) -> None:
    """The exception the route would have raised for the outcome of
    :func:`~api.body_rules.screen_body` (none
    when accepted): the app's exception handlers give it the same response."""
    if "refused" in outcome:
        r = outcome["refused"]
        raise ApiError(r["status"], r["detail"], limit=r["limit"], errors=r["errors"])
    if "invalid" in outcome:
        raise RequestValidationError(outcome["invalid"])
    if "scene" in outcome:
        s = outcome["scene"]
        raise SceneError(tuple(s["loc"]), s["reason"], s["errors"])
    if "unreadable" in outcome:
        cause: Exception = RecursionError() if outcome["unreadable"] == "recursion" else ValueError()
        raise HTTPException(status_code=400, detail="There was an error parsing the body") from cause


def _is_json(content_type: str | None) -> bool:
    """Whether FastAPI reads a body of this content type as JSON (strict: a body without a
    content type is not)."""
    if not content_type:
        return False
    message = email.message.Message()
    message["content-type"] = content_type
    subtype = message.get_content_subtype()
    return message.get_content_maintype() == "application" and (subtype == "json" or subtype.endswith("+json"))


async def screen_large_body(request: Request, rule: str) -> None:
    """Screen ``request``'s JSON body in a light worker when it is over ``inline_body_bytes``
    (under ``request_time_limit``; ``X-Lane: light``), raising the route's refusal. Light: decoding
    and counting take tens of milliseconds a megabyte, and the heavy lane may be busy with a table
    for up to its time limit. A smaller body is decoded here (:func:`~api.body_rules.decode_json`:
    a key written twice is a 422 either way)."""
    settings: Settings = request.app.state.settings
    if request.method != "POST" or not _is_json(request.headers.get("content-type")):
        return
    body = await request.body()  # kept by the request: the route reads the same bytes
    if len(body) <= settings.inline_body_bytes:
        try:  # decoded here, refusing a key written twice; FastAPI then reads the request's decoded JSON
            request._json = decode_json(body)  # Starlette's cache of Request.json()
        except ApiError:
            raise
        except (ValueError, RecursionError):
            pass  # not JSON: FastAPI decodes it again and gives its own answer
        return
    use_lane(request, "light")
    limits = {name: getattr(settings, name) for name in RULE_SETTINGS}
    outcome = await request.app.state.light_pool.run("body", {"rule": rule, "body": body, "limits": limits},
                                                        timeout=settings.request_time_limit)
    raise_refusal(outcome)


class ScreenedBodyRoute(APIRoute):
    """A route whose large JSON body is screened in a worker before FastAPI decodes it
    (:func:`screen_large_body`): the routes named in :data:`RULES`; others are plain routes."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()
        if self.name not in RULES:
            return handler
        rule = self.name

        async def screened(request: Request) -> Response:
            await screen_large_body(request, rule)
            return await handler(request)

        return screened
