"""Scenes: the bundled examples, upload (JSON or YAML) with validation, and drawing geometry."""

from __future__ import annotations

import json
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, File, UploadFile

from analysis.kinematics import HandKinematics
from analysis.loader import check_geometry, parse_scene_text
from analysis.scene import Scene
from api.deps import SettingsDep
from api.errors import ApiError
from api.schemas import ErrorBody, ExampleScene, GeometryCreate, _check_files

router = APIRouter(prefix="/scenes", tags=["scenes"])


@router.get("/examples", response_model=list[ExampleScene])
def list_examples(settings: SettingsDep) -> list[dict[str, Any]]:
    """The example scenes shipped with the service (each with its full scene, ready to post)."""
    out = []
    for path in sorted(settings.examples_dir.glob("*.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
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
    """Validate an uploaded scene file and return it as JSON (422 names the bad field)."""
    raw = await file.read(settings.max_body_bytes + 1)
    if len(raw) > settings.max_body_bytes:
        raise ApiError(413, f"file too large: the limit is {settings.max_body_bytes} bytes",
                       limit=settings.max_body_bytes)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ApiError(422, "file: not UTF-8 text") from None
    name = (file.filename or "scene.json").lower()
    suffix = ".yaml" if name.endswith((".yaml", ".yml")) else ".json"
    import yaml

    try:
        data = yaml.safe_load(text) if suffix == ".yaml" else json.loads(text)
    except (json.JSONDecodeError, yaml.YAMLError) as e:
        raise ApiError(422, f"file: cannot parse {suffix[1:].upper()}: {e}") from None
    try:
        _check_files(data)
    except ValueError as e:
        raise ApiError(422, f"scene.{e}") from None
    scene = parse_scene_text(json.dumps(data), ".json")  # SceneError -> 422 naming the field
    return scene.model_dump(mode="json")


@router.post("/geometry", responses={422: {"model": ErrorBody}})
def scene_geometry(body: GeometryCreate) -> dict[str, Any]:
    """World coordinates to draw: each finger's links (segments and radii) for the scene's ``q``
    or for each of ``configurations``, fixed bodies, object, contacts (with friction-cone half angle)."""
    scene: Scene = body.scene
    check_geometry(scene)  # SceneError -> 422 naming the field
    hand = HandKinematics.from_scene(scene)
    confs = body.configurations if body.configurations is not None else [list(map(float, hand.q0))]
    for k, q in enumerate(confs):
        if len(q) != hand.M:
            raise ApiError(422, f"configurations.{k}: has {len(q)} values; the hand has {hand.M} joints",
                           errors=[{"loc": ["configurations", k], "msg": f"needs {hand.M} values",
                                    "type": "value_error"}])
    frames = []
    for q in confs:
        qa = np.asarray(q, dtype=float)
        fingers = []
        for i, f in enumerate(scene.fingers):
            links = []
            for name in hand.fingers[i].body_names():
                ref = hand.resolve_body(name)
                assert ref is not None
                a, b = hand.fingers[i].body_segment(ref.link, qa[hand.finger_slice(i)])
                links.append({"body": name, "a": _r(a[: scene.dim]), "b": _r(b[: scene.dim]),
                              "radius": hand.body_radius(ref)})
            fingers.append({"name": f.name, "links": links})
        frames.append({"q": _r(qa), "fingers": fingers})
    contacts = [{"index": i, "body": c.body, "point": c.point, "normal": c.normal, "mu": c.mu,
                 "half_angle": float(np.arctan(c.mu))} for i, c in enumerate(scene.contacts)]
    return {"dim": scene.dim, "joints": hand.M, "object": scene.object.model_dump(mode="json"),
            "fixed_bodies": [b.model_dump(mode="json") for b in scene.fixed_bodies],
            "contacts": contacts, "frames": frames}


def _r(a: Any) -> list[float]:
    return [round(float(x), 9) for x in np.asarray(a).ravel()]
