"""``POST /analyses``: synchronous closure analysis in a worker process, with a time limit."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Request
from fastapi.responses import Response
from pydantic import SkipValidation

from api.bodies import ScreenedBodyRoute, validated
from api.body_rules import ANALYSIS_BODY, combination_length_error
from api.cache import BODY_SHA256, answer, cache_key
from api.deps import (
    AnalysisPoolDep,
    CacheDep,
    LightPoolDep,
    SettingsDep,
    check_hand_size,
    check_scene_size,
)
from api.errors import ApiError
from api.lanes import analysis_lane, run_in_lane, use_lane
from api.schemas import AnalysisCreate, AnalysisPublic, ErrorBody

router = APIRouter(tags=["analyses"], route_class=ScreenedBodyRoute)

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
    # the counts that need no model first: 413/422 before it spends time on a huge chain or
    # thousands of contacts (its checks share the interpreter with the event loop); the model off
    # the event loop; a body over inline_body_bytes was screened in a worker (api/bodies.py)
    ANALYSIS_BODY.check_raw(raw, settings)
    body = await validated(AnalysisCreate, raw)
    scene = body.scene
    if body.combination is not None and len(body.combination) != len(scene.contacts):
        raise combination_length_error(body.combination, len(scene.contacts))
    if body.direction is not None:
        if body.combination is None:
            raise ApiError(422, "direction: needs combination",
                           errors=[{"loc": ["direction"], "msg": "needs combination", "type": "value_error"}])
        if len(body.direction) != scene.D:
            raise ApiError(422, f"direction: has {len(body.direction)} components; the object has {scene.D} "
                                "coordinates",
                           errors=[{"loc": ["direction"], "msg": f"needs {scene.D} components",
                                    "type": "value_error"}])
    for name in ("nu", "samples"):
        if getattr(body, name) is not None and body.combination is None:
            raise ApiError(422, f"{name}: needs combination",
                           errors=[{"loc": [name], "msg": "needs combination", "type": "value_error"}])
    payload = {"scene": scene.model_dump(mode="json"), "combination": body.combination,
               "direction": body.direction, "nu": body.nu, "samples": body.samples}
    key = cache_key("analysis", payload)
    lane = analysis_lane(body.combination, len(scene.contacts), scene.M)

    check_hand_size(scene, settings)
    if body.combination is None:
        check_scene_size(scene, settings)  # 413 over max_contacts for a table

    async def compute() -> bytes:
        # the geometric checks (contact points on their bodies, normals in their cones) build the
        # hand's kinematics: the worker makes them (analysis.loader.scene_from_dict) before the
        # analysis, so the server spends no CPU on them; a SceneError is a 422 located in "scene"
        use_lane(request, lane)
        result = await run_in_lane(lane, light, pool, "analysis", payload, timeout=settings.request_time_limit)
        return AnalysisPublic.model_validate(result).model_dump_json().encode()

    # a request that passed every check and succeeded before is answered from the cache; one that
    # repeats a request being computed now waits for that one
    content, how = await answer(cache, key, compute)
    body_sha256 = request.scope.get(BODY_SHA256)
    if body_sha256:  # the same bytes again: answered before routing (api.cache.RepeatedBodies)
        cache.remember_body(body_sha256, key)
    return Response(content, media_type="application/json", headers={"X-Cache": how})
