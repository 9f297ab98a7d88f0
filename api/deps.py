"""Dependencies of the routes (``Annotated`` aliases: settings, store, workers, runner) and the
checks every scene-taking route makes (:func:`check_scene`).

The dependencies only read ``app.state``: they are coroutines, so FastAPI calls them in the event
loop (a plain ``def`` dependency is sent to its thread pool: a thread round trip per dependency
and request, about a millisecond of the server's CPU for the four of ``POST /analyses``)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Depends, Request

from analysis.loader import check_geometry
from analysis.scene import Scene
from api.cache import ResultCache
from api.errors import ApiError
from api.jobs import JobRunner
from api.settings import Settings
from api.store import JobStore
from api.workers import ProcessPool


async def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


async def get_store(request: Request) -> JobStore:
    store: JobStore = request.app.state.store
    return store


async def get_analysis_pool(request: Request) -> ProcessPool:
    pool: ProcessPool = request.app.state.analysis_pool
    return pool


async def get_light_pool(request: Request) -> ProcessPool:
    pool: ProcessPool = request.app.state.light_pool
    return pool


async def get_cache(request: Request) -> ResultCache:
    cache: ResultCache = request.app.state.analysis_cache
    return cache


async def get_runner(request: Request) -> JobRunner | None:
    runner: JobRunner | None = request.app.state.runner
    return runner


async def get_executor_name(request: Request) -> str:
    name: str = request.app.state.executor_name
    return name


SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[JobStore, Depends(get_store)]
AnalysisPoolDep = Annotated[ProcessPool, Depends(get_analysis_pool)]
LightPoolDep = Annotated[ProcessPool, Depends(get_light_pool)]
CacheDep = Annotated[ResultCache, Depends(get_cache)]
RunnerDep = Annotated[JobRunner | None, Depends(get_runner)]
ExecutorNameDep = Annotated[str, Depends(get_executor_name)]


def check_scene(scene: Scene, settings: Settings, *, enumerate_all: bool = False) -> None:
    """A request's scene, after the body's model validated its structure: its geometry (contact
    points on their bodies and on the object, normals in the normal cones: 422 naming the field,
    as a scene file gets) and, when the request enumerates every combination (``enumerate_all``:
    ``POST /enumerations``, ``POST /analyses`` without a combination), its size (413 over
    ``max_contacts``). One combination and plans take any number of contacts."""
    check_hand_size(scene, settings)
    check_geometry(scene)  # SceneError -> 422 located in "scene"
    if enumerate_all:
        check_scene_size(scene, settings)


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
    """:func:`check_hand_size` on the parsed body, before the model validates it: validating a
    scene of 20,000 links takes pydantic a few hundred milliseconds in native code that holds
    the interpreter (no other request is served meanwhile), counting them takes microseconds."""
    _hand_size_error(raw_joint_count(body), settings)


def raw_contact_count(body: Any) -> int | None:
    """The contacts listed by the scene of a parsed, not yet validated request body, or None
    when it lists none (``"auto"``, missing, not a list)."""
    scene = body.get("scene") if isinstance(body, dict) else None
    contacts = scene.get("contacts") if isinstance(scene, dict) else None
    return len(contacts) if isinstance(contacts, list) else None


def check_raw_contacts(body: Any, settings: Settings, *, enumerate_all: bool) -> None:
    """:func:`check_scene_size` on the parsed body, before the model validates it: the model's
    checks of 9,000 contacts (a 1 MB body) take a quarter of a second of the interpreter, which
    the event loop shares; counting them takes microseconds. Only for requests that enumerate
    every combination (one combination is bounded by its letters, see :func:`check_raw_combination`)."""
    n = raw_contact_count(body)
    if enumerate_all and n is not None:
        _too_many_contacts(n, settings)


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


def check_hand_size(scene: Scene, settings: Settings) -> None:
    """Scenes over ``max_joints`` joints in all: 413 with the limit, before any kinematics (the
    cost of building and drawing a chain grows with its length)."""
    _hand_size_error(scene.M, settings)


def _hand_size_error(n: int, settings: Settings) -> None:
    if n > settings.max_joints:
        raise ApiError(413, f"scene.fingers: {n} joints in all; this server's limit is {settings.max_joints} "
                            "(max_joints)", limit=settings.max_joints,
                       errors=[{"loc": ["scene", "fingers"], "msg": f"more than {settings.max_joints} joints",
                                "type": "too_large"}])


def check_scene_size(scene: Scene, settings: Settings) -> None:
    """Scenes over ``max_contacts`` contacts: 413 with the limit."""
    _too_many_contacts(len(scene.contacts), settings)


def _too_many_contacts(n: int, settings: Settings) -> None:
    if n > settings.max_contacts:
        raise ApiError(413, f"scene.contacts: {n} contacts; this server's limit is {settings.max_contacts} "
                            f"(max_contacts)", limit=settings.max_contacts,
                       errors=[{"loc": ["scene", "contacts"], "msg": f"more than {settings.max_contacts} contacts",
                                "type": "too_large"}])
