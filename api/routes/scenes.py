"""Scenes: the bundled examples, upload (JSON or YAML) with validation, and drawing geometry."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, File, Response, UploadFile
from pydantic import SkipValidation, ValidationError

from analysis.exceptions import SceneError
from analysis.loader import (
    check_geometry,
    parse_scene_data,
    read_scene_data,
    scene_from_dict,
    wants_detection,
    with_detected_contacts,
)
from analysis.scene import Scene
from api.bodies import validated
from api.deps import AnalysisPoolDep, LightPoolDep, SettingsDep, check_hand_size, check_raw_hand_size
from api.errors import ApiError
from api.lanes import geometry_lane, run_in_lane
from api.schemas import ContactsCreate, ContactsPublic, ErrorBody, ExampleScene, GeometryCreate, _check_files

router = APIRouter(prefix="/scenes", tags=["scenes"])


@router.get("/examples", response_model=list[ExampleScene])
def list_examples(settings: SettingsDep) -> list[dict[str, Any]]:
    """The example scenes shipped with the service (each with its full scene, ready to post)."""
    out = []
    for path in sorted(settings.examples_dir.glob("*.json")):
        try:
            data = read_scene_data(path)  # the scene files' one parser
        except SceneError:
            continue
        if not isinstance(data, dict) or "contacts" not in data:
            continue
        out.append({"name": data.get("name", path.stem), "file": path.name, "dim": data.get("dim", 0),
                    "contacts": len(data.get("contacts", [])), "description": data.get("description", ""),
                    "scene": data})
    return out


@router.post("/upload", response_model=dict[str, Any], responses={413: {"model": ErrorBody},
                                                                  422: {"model": ErrorBody}})
async def upload_scene(file: Annotated[UploadFile, File(description="a scene, .json or .yaml")],
                       settings: SettingsDep) -> dict[str, Any]:
    """Validate an uploaded scene file and return it as JSON (422 names the bad field).

    The file goes through the scene files' one parser (:func:`analysis.loader.parse_scene_data`:
    size, nesting depth, YAML aliases and JSON-only values checked before anything is built),
    then the model and the geometric checks, all off the event loop."""
    raw = await file.read(settings.max_body_bytes + 1)
    if len(raw) > settings.max_body_bytes:
        raise ApiError(413, f"file too large: the limit is {settings.max_body_bytes} bytes",
                       limit=settings.max_body_bytes)
    name = (file.filename or "scene.json").lower()
    suffix = ".yaml" if name.endswith((".yaml", ".yml")) else ".json"
    scene = await asyncio.to_thread(_validate_upload, raw, suffix, settings.max_body_bytes, settings)
    return scene.model_dump(mode="json")


def _validate_upload(raw: bytes, suffix: str, max_bytes: int, settings: Any) -> Scene:
    try:
        data = parse_scene_data(raw, suffix, max_bytes=max_bytes)
    except SceneError as e:
        where = ".".join(str(p) for p in e.loc)
        raise ApiError(422, f"{'scene.' + where if where else 'file'}: {e.reason}",
                       errors=[{"loc": ["scene", *e.loc] if e.loc else ["file"], "msg": e.reason,
                                "type": "scene_file"}]) from None
    try:
        _check_files(data)
    except ValueError as e:
        raise ApiError(422, f"scene.{e}") from None
    if wants_detection(data):  # contacts omitted, [] or "auto": found from the geometry
        data, _ = with_detected_contacts(data)
    try:
        scene = Scene.model_validate(data)
    except ValidationError:
        scene_from_dict(data)  # raises the SceneError naming the first bad field (422)
        raise
    check_hand_size(scene, settings)  # the joint count before any kinematics (413 naming the limit)
    check_geometry(scene)  # SceneError -> 422 naming the field
    return scene


@router.post("/geometry", responses={413: {"model": ErrorBody}, 422: {"model": ErrorBody}})
async def scene_geometry(raw: Annotated[GeometryCreate, SkipValidation], settings: SettingsDep,
                         light: LightPoolDep, pool: AnalysisPoolDep, response: Response) -> dict[str, Any]:
    """World coordinates to draw: each finger's links (segments and radii) for the scene's ``q``
    or for each of ``configurations``, fixed bodies, object, contacts (with friction-cone half angle).

    Computed in a worker under ``request_time_limit`` (422 with ``limit`` past it): a light one for
    a few configurations, else a heavy one (api/lanes.py, ``X-Lane``); scenes over ``max_joints``
    joints get 413."""
    check_raw_hand_size(raw, settings)  # 413 before the model spends time on a huge chain
    body = await validated(GeometryCreate, raw)  # off the event loop (api/bodies.py)
    scene: Scene = body.scene
    check_hand_size(scene, settings)
    M = scene.M
    for k, q in enumerate(body.configurations or []):
        if len(q) != M:
            raise ApiError(422, f"configurations.{k}: has {len(q)} values; the hand has {M} joints",
                           errors=[{"loc": ["configurations", k], "msg": f"needs {M} values",
                                    "type": "value_error"}])
    payload = {"scene": scene.model_dump(mode="json"), "configurations": body.configurations}
    lane = geometry_lane(len(body.configurations or [None]), [len(f.q) for f in scene.fingers])
    response.headers["X-Lane"] = lane
    return await run_in_lane(lane, light, pool, "geometry", payload, timeout=settings.request_time_limit)



@router.post("/contacts", response_model=ContactsPublic, responses={413: {"model": ErrorBody},
                                                                   422: {"model": ErrorBody}})
async def scene_contacts(raw: Annotated[ContactsCreate, SkipValidation], settings: SettingsDep,
                         light: LightPoolDep, pool: AnalysisPoolDep, response: Response) -> dict[str, Any]:
    """The contacts between the object and every finger link and fixed body at the scene's
    configuration, found from the geometry within ``tolerance`` (any ``contacts`` the scene has
    are replaced), the complete scene with them, and the near misses (closer than 10
    tolerances, not touching). With ``touch``, the named links are first placed on the object
    (``ctp contacts --touch``). An object that touches nothing is a 422 at ``scene.contacts``.

    Computed in a light worker under ``request_time_limit``; scenes over ``max_joints`` joints get 413."""
    check_raw_hand_size(raw, settings)  # 413 before the model spends time on a huge chain
    body = await validated(ContactsCreate, raw)  # off the event loop (api/bodies.py)
    payload = {"scene": body.scene, "tolerance": body.tolerance, "mu": body.mu, "touch": body.touch}
    response.headers["X-Lane"] = "light"
    return await run_in_lane("light", light, pool, "contacts", payload, timeout=settings.request_time_limit)
