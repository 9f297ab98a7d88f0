"""Request bodies validated outside the event loop.

FastAPI validates a declared body model in the event loop before the route runs. The
scene-taking routes declare their body as ``Annotated[Model, SkipValidation]``: the OpenAPI
schema is the model's, FastAPI only parses the JSON, and the route checks the parsed body with its
:class:`BodyRule` (:meth:`BodyRule.check_raw`, the cheap counts that need no model: a 20,000-link
chain is refused in microseconds) and validates it with :func:`validate_body`, in a worker thread
(``await validated(...)`` from an ``async def`` route; a plain ``def`` route already runs in one).
The thread keeps the scene model's Python validators off the event loop. An invalid body raises
the same :class:`RequestValidationError` FastAPI would, so its 422 is unchanged (``detail`` names
the field).

A JSON body over ``inline_body_bytes`` (64 kB; the bundled scenes are under 10 kB) is screened
first in a light worker (:class:`ScreenedBodyRoute`, :func:`screen_body`): the worker decodes it
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
import json
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import Any, Generic, Literal, TypeVar

from fastapi import HTTPException, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from pydantic import BaseModel, ValidationError

from analysis.exceptions import SceneError
from analysis.loader import wants_detection, with_detected_contacts
from analysis.scene import Scene
from api.deps import check_raw_combination, check_raw_contacts, check_raw_hand_size
from api.errors import ApiError
from api.lanes import use_lane
from api.schemas import AnalysisCreate, ContactsCreate, EnumerationCreate, GeometryCreate, PlanCreate, _check_files
from api.settings import Settings

M = TypeVar("M", bound=BaseModel)


def validate_body(model: type[M], data: Any) -> M:
    """``model`` from a parsed JSON body; RequestValidationError (located in ``body``) if invalid.

    A ``scene`` (a :class:`~analysis.scene.Scene` field) whose contacts are omitted, ``[]`` or
    ``"auto"`` gets the contacts found from its geometry first (:func:`with_detected_contacts`;
    its SceneError is a 422 naming ``scene.<field>``), once its files passed the HTTP check."""
    if isinstance(data, model):
        return data
    field = model.model_fields.get("scene")
    scene = data.get("scene") if isinstance(data, dict) else None
    if field is not None and field.annotation is Scene and wants_detection(scene):
        try:
            _check_files(scene)
        except ValueError:
            pass  # the model's validation below names the file
        else:
            data = {**data, "scene": with_detected_contacts(scene)[0]}
    try:
        return model.model_validate(data)
    except ValidationError as e:
        errors = [{**err, "loc": ("body", *err["loc"])} for err in e.errors(include_url=False)]
        raise RequestValidationError(errors) from None


async def validated(model: type[M], data: Any) -> M:
    """:func:`validate_body` in a worker thread."""
    return await asyncio.to_thread(validate_body, model, data)


#: When a route counts the contacts its body lists before the model (413 over ``max_contacts``).
CountContacts = Literal["never", "always", "without_combination"]


@dataclass(frozen=True)
class BodyRule(Generic[M]):
    """What a scene-taking route checks on its parsed JSON body, in this order: the joints (413
    over ``max_joints``), the contacts when the request enumerates every combination (413 over
    ``max_contacts``), the combination's letters against the contacts listed (422), then the model.
    The route and the screening worker (:func:`screen_body`) run the same rule."""

    model: type[M]
    count_contacts: CountContacts = "never"
    letters: bool = False  # ``combination`` has one letter per listed contact

    def check_raw(self, raw: Any, settings: Settings) -> None:
        """The counts that need no model (microseconds; ApiError 413/422)."""
        check_raw_hand_size(raw, settings)
        if self.count_contacts != "never":
            enumerate_all = self.count_contacts == "always" or not (isinstance(raw, dict) and raw.get("combination"))
            check_raw_contacts(raw, settings, enumerate_all=enumerate_all)
        if self.letters:
            check_raw_combination(raw)

    def validate(self, raw: Any, settings: Settings) -> M:
        """:meth:`check_raw`, then :func:`validate_body`."""
        self.check_raw(raw, settings)
        return validate_body(self.model, raw)


ANALYSIS_BODY = BodyRule(AnalysisCreate, count_contacts="without_combination", letters=True)
ENUMERATION_BODY = BodyRule(EnumerationCreate, count_contacts="always")
PLAN_BODY = BodyRule(PlanCreate)
GEOMETRY_BODY = BodyRule(GeometryCreate)
CONTACTS_BODY = BodyRule(ContactsCreate)

#: The rule of each route (by its endpoint's name) whose large bodies are screened in a worker.
RULES: dict[str, BodyRule[Any]] = {
    "create_analysis": ANALYSIS_BODY,
    "create_enumeration": ENUMERATION_BODY,
    "create_plan": PLAN_BODY,
    "scene_geometry": GEOMETRY_BODY,
    "scene_contacts": CONTACTS_BODY,
}

#: The settings a rule reads, sent to the screening worker.
RULE_SETTINGS = ("max_joints", "max_contacts")


def screen_body(rule: str, body: bytes, limits: dict[str, Any]) -> dict[str, Any]:
    """The worker's half of :class:`ScreenedBodyRoute`: ``body`` decoded as FastAPI decodes JSON
    and run through ``RULES[rule]`` with ``limits`` (:data:`RULE_SETTINGS`). Returns the outcome as
    plain data, which :func:`raise_refusal` turns into the route's own answer: ``{"accepted":
    True}``, or ``"invalid"`` (validation or JSON decode errors, located in ``body``),
    ``"unreadable"`` (``"recursion"``: nested too deeply; ``"other"``: not UTF-8 and the like),
    ``"refused"`` (an :class:`ApiError`'s fields), ``"scene"`` (a SceneError's)."""
    try:
        data = json.loads(body)
    except json.JSONDecodeError as e:
        return {"invalid": [{"type": "json_invalid", "loc": ["body", e.pos], "msg": "JSON decode error"}]}
    except RecursionError:
        return {"unreadable": "recursion"}
    except ValueError:  # UnicodeDecodeError: bytes that are not UTF-8 (or -16, -32)
        return {"unreadable": "other"}
    settings = Settings.model_construct(**limits)
    try:
        RULES[rule].validate(data, settings)
    except ApiError as e:
        return {"refused": {"status": e.status, "detail": e.detail, "limit": e.limit, "errors": e.errors}}
    except RequestValidationError as e:
        return {"invalid": [{"type": str(x.get("type", "value_error")), "loc": list(x.get("loc", ())),
                             "msg": str(x.get("msg", ""))} for x in e.errors()]}
    except SceneError as e:
        return {"scene": {"loc": list(e.loc), "reason": e.reason, "errors": e.errors}}
    return {"accepted": True}


def raise_refusal(outcome: dict[str, Any]) -> None:
    """The exception the route would have raised for the outcome of :func:`screen_body` (none
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
    for up to its time limit."""
    settings: Settings = request.app.state.settings
    if request.method != "POST" or not _is_json(request.headers.get("content-type")):
        return
    body = await request.body()  # kept by the request: the route reads the same bytes
    if len(body) <= settings.inline_body_bytes:
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
