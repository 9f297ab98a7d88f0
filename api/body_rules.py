"""The checks of a scene-taking route's JSON body, one :class:`BodyRule` per route: the counts
that need no model (joints, contacts, the combination's letters: microseconds, so a 20,000-link
chain or 9,000 contacts are refused before pydantic spends a fraction of a second on them), then
the model (:func:`validate_body`). The route runs its rule in the server (:mod:`api.bodies`); for
a body over ``inline_body_bytes`` a worker runs the same rule first (:func:`screen_body`), so this
module imports nothing of the server (no store, no workers)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Generic, Literal, TypeVar

from fastapi.exceptions import RequestValidationError
from pydantic import BaseModel, ValidationError

from analysis.exceptions import SceneError
from analysis.loader import wants_detection, with_detected_contacts
from analysis.scene import Scene
from api.exceptions import ApiError
from api.schemas import AnalysisCreate, ContactsCreate, EnumerationCreate, GeometryCreate, PlanCreate, _check_files
from api.settings import Settings

M = TypeVar("M", bound=BaseModel)


def raw_joint_count(body: Any) -> int:
    """The joints of the scene of a parsed, not yet validated request body (``body["scene"]``),
    counted from its lists alone: each finger's ``links``, ``joints`` or ``q``, at least one."""
    scene = body.get("scene") if isinstance(body, dict) else None
    fingers = scene.get("fingers") if isinstance(scene, dict) else None
    if not isinstance(fingers, list):
        return 0
    n = 0
    for f in fingers:
        lists = [f.get(k) for k in ("links", "joints", "q")] if isinstance(f, dict) else []
        n += max([1, *(len(v) for v in lists if isinstance(v, list))])
    return n


def check_raw_hand_size(body: Any, settings: Settings) -> None:
    """:func:`api.deps.check_hand_size` on the parsed body, before the model validates it: validating a
    scene of 20,000 links takes pydantic a few hundred milliseconds in native code that holds
    the interpreter (no other request is served meanwhile), counting them takes microseconds."""
    hand_size_error(raw_joint_count(body), settings)


def raw_contact_count(body: Any) -> int | None:
    """The contacts listed by the scene of a parsed, not yet validated request body, or None
    when it lists none (``"auto"``, missing, not a list)."""
    scene = body.get("scene") if isinstance(body, dict) else None
    contacts = scene.get("contacts") if isinstance(scene, dict) else None
    return len(contacts) if isinstance(contacts, list) else None


def check_raw_contacts(body: Any, settings: Settings, *, enumerate_all: bool) -> None:
    """:func:`api.deps.check_scene_size` on the parsed body, before the model validates it: the model's
    checks of 9,000 contacts (a 1 MB body) take a quarter of a second of the interpreter, which
    the event loop shares; counting them takes microseconds. Only for requests that enumerate
    every combination (one combination is bounded by its letters, see :func:`check_raw_combination`)."""
    n = raw_contact_count(body)
    if enumerate_all and n is not None:
        too_many_contacts(n, settings)


def check_raw_combination(body: Any) -> None:
    """``combination`` of a parsed body has one letter per contact the scene lists (422 naming
    it, before the model validates a scene that cannot match)."""
    n = raw_contact_count(body)
    combination = body.get("combination") if isinstance(body, dict) else None
    if n is not None and isinstance(combination, str) and len(combination) != n:
        raise combination_length_error(combination, n)


def combination_length_error(combination: str, contacts: int) -> ApiError:
    shown = combination if len(combination) <= 40 else combination[:37] + "..."
    return ApiError(422, f"combination: '{shown}' has {len(combination)} letters; the scene has {contacts} contacts",
                    errors=[{"loc": ["combination"], "msg": "one letter per contact", "type": "value_error"}])


def hand_size_error(n: int, settings: Settings) -> None:
    if n > settings.max_joints:
        raise ApiError(413, f"scene.fingers: {n} joints in all; this server's limit is {settings.max_joints} "
                            "(max_joints)", limit=settings.max_joints,
                       errors=[{"loc": ["scene", "fingers"], "msg": f"more than {settings.max_joints} joints",
                                "type": "too_large"}])


def too_many_contacts(n: int, settings: Settings) -> None:
    if n > settings.max_contacts:
        raise ApiError(413, f"scene.contacts: {n} contacts; this server's limit is {settings.max_contacts} "
                            f"(max_contacts)", limit=settings.max_contacts,
                       errors=[{"loc": ["scene", "contacts"], "msg": f"more than {settings.max_contacts} contacts",
                                "type": "too_large"}])


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


def duplicate_key_error(key: str) -> ApiError:
    shown = key if len(key) <= 40 else key[:37] + "..."
    return ApiError(422, f"body: the key {shown!r} is written twice in one object; write each key once",
                    errors=[{"loc": ["body"], "msg": f"duplicate key {shown!r}", "type": "duplicate_key"}])


def _unique_object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise duplicate_key_error(key)
        out[key] = value
    return out


def decode_json(body: bytes) -> Any:
    """``body`` decoded as Starlette decodes JSON (:func:`json.loads` of the bytes), except that a key
    written twice in one object is refused (ApiError 422): the standard library keeps the last one
    silently, so a scene's first ``contacts`` would be lost without a word (scene files are refused
    the same way, :mod:`analysis.loader`)."""
    return json.loads(body, object_pairs_hook=_unique_object)


def screen_body(rule: str, body: bytes, limits: dict[str, Any]) -> dict[str, Any]:
    """The worker's half of :class:`ScreenedBodyRoute`: ``body`` decoded as FastAPI decodes JSON
    and run through ``RULES[rule]`` with ``limits`` (:data:`RULE_SETTINGS`). Returns the outcome as
    plain data, which :func:`api.bodies.raise_refusal` turns into the route's own answer: ``{"accepted":
    True}``, or ``"invalid"`` (validation or JSON decode errors, located in ``body``),
    ``"unreadable"`` (``"recursion"``: nested too deeply; ``"other"``: not UTF-8 and the like),
    ``"refused"`` (an :class:`ApiError`'s fields), ``"scene"`` (a SceneError's)."""
    try:
        data = decode_json(body)
    except ApiError as e:  # a key written twice
        return {"refused": {"status": e.status, "detail": e.detail, "limit": e.limit, "errors": e.errors}}
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
