"""``POST /analyses``: synchronous closure analysis in a worker process, with a time limit."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Request
from fastapi.responses import Response
from pydantic import SkipValidation

from api.bodies import validated
from api.cache import BODY_SHA256, answer, cache_key
from api.deps import AnalysisPoolDep, CacheDep, LightPoolDep, SettingsDep, check_raw_hand_size, check_scene
from api.errors import ApiError
from api.lanes import analysis_lane, run_in_lane
from api.schemas import AnalysisCreate, AnalysisPublic, ErrorBody

router = APIRouter(tags=["analyses"])

_ERRORS: dict[int | str, dict[str, Any]] = {
    413: {"model": ErrorBody, "description": "too many contacts or body too large (``limit``)"},
    422: {"model": ErrorBody, "description": "invalid input (``detail`` names the field), the analysis "
                                             "says no, or the request time limit was reached"},
    503: {"model": ErrorBody, "description": "no worker free within the time limit"},
}


@router.post("/analyses", response_model=AnalysisPublic, responses=_ERRORS)
async def create_analysis(raw: Annotated[AnalysisCreate, SkipValidation], request: Request, settings: SettingsDep,
                          pool: AnalysisPoolDep, light: LightPoolDep, cache: CacheDep) -> Any:
    """The full report of ``combination``, or (without it) the table of every combination.

    Runs in a worker process; past ``request_time_limit`` seconds the worker is stopped and the
    answer is 422 with ``limit`` (large enumerations belong in ``POST /enumerations``). One
    combination runs on the light workers, a table on the others (api/lanes.py: ``X-Lane``), so a
    light request does not wait behind tables. A request that repeats an earlier one (the same scene
    and parameters) is answered from the content-addressed cache (header ``X-Cache: hit``), one
    identical to a request still running waits for its answer (``X-Cache: shared``)."""
    check_raw_hand_size(raw, settings)  # 413 before the model spends time on a huge chain
    body = await validated(AnalysisCreate, raw)  # off the event loop (api/bodies.py)
    scene = body.scene
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
    key = cache_key("analysis", payload)
    lane = analysis_lane(body.combination, len(scene.contacts), scene.M)

    async def compute() -> bytes:
        # the geometric checks build the hand's kinematics: off the event loop
        await asyncio.to_thread(check_scene, scene, settings, enumerate_all=body.combination is None)
        result = await run_in_lane(lane, light, pool, "analysis", payload, timeout=settings.request_time_limit)
        return AnalysisPublic.model_validate(result).model_dump_json().encode()

    # a request that passed every check and succeeded before is answered from the cache; one that
    # repeats a request being computed now waits for that one
    content, how = await answer(cache, key, compute)
    body_sha256 = request.scope.get(BODY_SHA256)
    if body_sha256:  # the same bytes again: answered before routing (api.cache.RepeatedBodies)
        cache.remember_body(body_sha256, key)
    headers = {"X-Cache": how, **({"X-Lane": lane} if how == "miss" else {})}
    return Response(content, media_type="application/json", headers=headers)
