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

M = TypeVar("M", bound=BaseModel)


def validate_body(model: type[M], data: Any) -> M:
    """``model`` from a parsed JSON body; RequestValidationError (located in ``body``) if invalid."""
    if isinstance(data, model):
        return data
    try:
        return model.model_validate(data)
    except ValidationError as e:
        errors = [{**err, "loc": ("body", *err["loc"])} for err in e.errors(include_url=False)]
        raise RequestValidationError(errors) from None


async def validated(model: type[M], data: Any) -> M:
    """:func:`validate_body` in a worker thread."""
    return await asyncio.to_thread(validate_body, model, data)
