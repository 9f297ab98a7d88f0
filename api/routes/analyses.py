"""``POST /analyses``: synchronous closure analysis in a worker process, with a time limit."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from api.deps import AnalysisPoolDep, SettingsDep, check_scene
from api.errors import ApiError
from api.schemas import AnalysisCreate, AnalysisPublic, ErrorBody

router = APIRouter(tags=["analyses"])

_ERRORS: dict[int | str, dict[str, Any]] = {
    413: {"model": ErrorBody, "description": "too many contacts or body too large (``limit``)"},
    422: {"model": ErrorBody, "description": "invalid input (``detail`` names the field), the analysis "
                                             "says no, or the request time limit was reached"},
    503: {"model": ErrorBody, "description": "no worker free within the time limit"},
}


@router.post("/analyses", response_model=AnalysisPublic, responses=_ERRORS)
async def create_analysis(body: AnalysisCreate, settings: SettingsDep, pool: AnalysisPoolDep) -> dict[str, Any]:
    """The full report of ``combination``, or (without it) the table of every combination.

    Runs in a worker process; past ``request_time_limit`` seconds the worker is stopped and the
    answer is 422 with ``limit`` (large enumerations belong in ``POST /enumerations``)."""
    scene = body.scene
    check_scene(scene, settings)
    if body.combination is not None and len(body.combination) != len(scene.contacts):
        raise ApiError(422, f"combination: '{body.combination}' has {len(body.combination)} letters; the scene "
                            f"has {len(scene.contacts)} contacts",
                       errors=[{"loc": ["combination"], "msg": "one letter per contact", "type": "value_error"}])
    if body.direction is not None:
        if body.combination is None:
            raise ApiError(422, "direction: needs combination",
                           errors=[{"loc": ["direction"], "msg": "needs combination", "type": "value_error"}])
        if len(body.direction) != scene.D:
            raise ApiError(422, f"direction: has {len(body.direction)} components; the object has {scene.D} "
                                "coordinates",
                           errors=[{"loc": ["direction"], "msg": f"needs {scene.D} components",
                                    "type": "value_error"}])
    if body.nu is not None and body.combination is None:
        raise ApiError(422, "nu: needs combination",
                       errors=[{"loc": ["nu"], "msg": "needs combination", "type": "value_error"}])
    payload = {"scene": scene.model_dump(mode="json"), "combination": body.combination,
               "direction": body.direction, "nu": body.nu}
    return await pool.run("analysis", payload, timeout=settings.request_time_limit)
