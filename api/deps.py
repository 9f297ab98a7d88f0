"""Dependencies of the routes (``Annotated`` aliases: settings, store, workers, runner) and the
checks every scene-taking route makes (:func:`check_scene`).

The dependencies only read ``app.state``: they are coroutines, so FastAPI calls them in the event
loop (a plain ``def`` dependency is sent to its thread pool: a thread round trip per dependency
and request, about a millisecond of the server's CPU for the four of ``POST /analyses``)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from analysis.loader import check_geometry
from analysis.scene import Scene
from api.body_rules import hand_size_error, too_many_contacts
from api.cache import ResultCache
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


def check_hand_size(scene: Scene, settings: Settings) -> None:
    """Scenes over ``max_joints`` joints in all: 413 with the limit, before any kinematics (the
    cost of building and drawing a chain grows with its length)."""
    hand_size_error(scene.M, settings)


def check_scene_size(scene: Scene, settings: Settings) -> None:
    """Scenes over ``max_contacts`` contacts: 413 with the limit."""
    too_many_contacts(len(scene.contacts), settings)
