"""Scenes: the bundled examples, upload (JSON or YAML) with validation, and drawing geometry."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, File, Request, UploadFile
from pydantic import SkipValidation

from analysis.exceptions import SceneError
from analysis.loader import FILE_ERROR, read_scene_data
from analysis.scene import Scene
from api.bodies import ScreenedBodyRoute, validated
from api.body_rules import CONTACTS_BODY, GEOMETRY_BODY, hand_size_error
from api.deps import AnalysisPoolDep, LightPoolDep, SettingsDep, check_hand_size
from api.errors import ApiError
from api.lanes import geometry_lane, run_in_lane, upload_lane, use_lane
from api.schemas import ContactsCreate, ContactsPublic, ErrorBody, ExampleScene, GeometryCreate
from api.workers import TaskError, TaskTimeout

router = APIRouter(prefix="/scenes", tags=["scenes"], route_class=ScreenedBodyRoute)


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
                       settings: SettingsDep, light: LightPoolDep, pool: AnalysisPoolDep,
                       request: Request) -> dict[str, Any]:
    """Validate an uploaded scene file and return it as JSON (422 names the bad field).

    The file goes through the scene files' one parser (:func:`analysis.loader.parse_scene_data`:
    size, nesting depth, YAML aliases and JSON-only values checked before anything is built),
    then the model and the geometric checks, all in a worker under ``request_time_limit``
    (:func:`api.tasks.run_upload`): a light one for a file up to ``LIGHT_MAX_UPLOAD_BYTES``, else
    a heavy one (``X-Lane``). Scenes over ``max_joints`` joints get 413."""
    raw = await file.read(settings.max_body_bytes + 1)
    if len(raw) > settings.max_body_bytes:
        raise ApiError(413, f"file too large: the limit is {settings.max_body_bytes} bytes",
                       limit=settings.max_body_bytes)
    name = (file.filename or "scene.json").lower()
    suffix = ".yaml" if name.endswith((".yaml", ".yml")) else ".json"
    payload = {"raw": raw, "suffix": suffix, "max_bytes": settings.max_body_bytes, "max_joints": settings.max_joints}
    lane = use_lane(request, upload_lane(len(raw)))
    try:
        out = await run_in_lane(lane, light, pool, "upload", payload, timeout=settings.request_time_limit)
    except TaskError as e:
        first = (e.errors or [{}])[0]
        if e.type == "scene" and first.get("type") == FILE_ERROR:  # the file itself: at ``file`` or the value
            loc = list(first.get("loc") or [])
            raise ApiError(422, f"{'scene.' + '.'.join(map(str, loc)) if loc else 'file'}: {first['msg']}",
                           errors=[{"loc": ["scene", *loc] if loc else ["file"], "msg": first["msg"],
                                    "type": FILE_ERROR}]) from None
        raise
    except TaskTimeout as e:
        detail = (f"time limit: reading and checking the file took more than {e.limit:g} s "
                  "(request_time_limit); send a smaller file, or JSON, which reads faster than YAML")
        raise ApiError(422, detail, limit=e.limit,
                       errors=[{"loc": ["file"], "msg": detail, "type": "time_limit"}]) from None
    if out["scene"] is None:
        hand_size_error(out["joints"], settings)  # 413 naming the limit, before any kinematics
    scene: dict[str, Any] = out["scene"]
    return scene


@router.post("/geometry", responses={413: {"model": ErrorBody}, 422: {"model": ErrorBody}})
async def scene_geometry(raw: Annotated[GeometryCreate, SkipValidation], settings: SettingsDep,
                         light: LightPoolDep, pool: AnalysisPoolDep, request: Request) -> dict[str, Any]:
    """World coordinates to draw: each finger's links (segments and radii) for the scene's ``q``
    or for each of ``configurations``, fixed bodies, object, contacts (with friction-cone half angle).

    Computed in a worker under ``request_time_limit`` (422 with ``limit`` past it): a light one for
    a few configurations, else a heavy one (api/lanes.py, ``X-Lane``); scenes over ``max_joints``
    joints get 413."""
    GEOMETRY_BODY.check_raw(raw, settings)  # 413 before the model spends time on a huge chain
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
    lane = use_lane(request, geometry_lane(len(body.configurations or [None]), [len(f.q) for f in scene.fingers]))
    return await run_in_lane(lane, light, pool, "geometry", payload, timeout=settings.request_time_limit)



@router.post("/contacts", response_model=ContactsPublic, responses={413: {"model": ErrorBody},
                                                                   422: {"model": ErrorBody}})
async def scene_contacts(raw: Annotated[ContactsCreate, SkipValidation], settings: SettingsDep,
                         light: LightPoolDep, pool: AnalysisPoolDep, request: Request) -> dict[str, Any]:
    """The contacts between the object and every finger link and fixed body at the scene's
    configuration, found from the geometry within ``tolerance`` (any ``contacts`` the scene has
    are replaced), the complete scene with them, and the near misses (closer than 10
    tolerances, not touching). With ``touch``, the named links are first placed on the object
    (``ctp contacts --touch``). An object that touches nothing is a 422 at ``scene.contacts``.

    Computed in a light worker under ``request_time_limit``; scenes over ``max_joints`` joints get 413."""
    CONTACTS_BODY.check_raw(raw, settings)  # 413 before the model spends time on a huge chain
    body = await validated(ContactsCreate, raw)  # off the event loop (api/bodies.py)
    payload = {"scene": body.scene, "tolerance": body.tolerance, "mu": body.mu, "touch": body.touch}
    use_lane(request, "light")
    return await run_in_lane("light", light, pool, "contacts", payload, timeout=settings.request_time_limit)
