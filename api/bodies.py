"""Request bodies validated outside the event loop.

FastAPI validates a declared body model in the event loop before the route runs. The
scene-taking routes declare their body as ``Annotated[Model, SkipValidation]``: the OpenAPI
schema is the model's, FastAPI only parses the JSON, and the route validates the parsed body with
:func:`validate_body`, in a worker thread (``await validated(...)`` from an ``async def`` route; a
plain ``def`` route already runs in one), after the cheap size checks that need no model
(:func:`api.deps.check_raw_hand_size`: a 20,000-link chain is refused in microseconds). The
thread keeps the scene model's Python validators off the event loop; pydantic's own validation is
native code that holds the interpreter while it runs, which ``max_body_bytes`` bounds (about 0.3 s
for 1 MB). An invalid body raises the same :class:`RequestValidationError` FastAPI would, so its
422 is unchanged (``detail`` names the field).
"""

from __future__ import annotations

import asyncio
from typing import Any, TypeVar

from fastapi.exceptions import RequestValidationError
from pydantic import BaseModel, ValidationError

from analysis.loader import wants_detection, with_detected_contacts
from analysis.scene import Scene
from api.schemas import _check_files

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
