"""Dependencies of the routes (``Annotated`` aliases: settings, store, workers, runner) and the
checks every scene-taking route makes (:func:`check_scene`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from analysis.loader import check_geometry
from analysis.scene import Scene
from api.errors import ApiError
from api.jobs import JobRunner
from api.settings import Settings
from api.store import JobStore
from api.workers import ProcessPool


def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def get_store(request: Request) -> JobStore:
    store: JobStore = request.app.state.store
    return store


def get_analysis_pool(request: Request) -> ProcessPool:
    pool: ProcessPool = request.app.state.analysis_pool
    return pool


def get_runner(request: Request) -> JobRunner | None:
    runner: JobRunner | None = request.app.state.runner
    return runner


def get_executor_name(request: Request) -> str:
    name: str = request.app.state.executor_name
    return name


SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[JobStore, Depends(get_store)]
AnalysisPoolDep = Annotated[ProcessPool, Depends(get_analysis_pool)]
RunnerDep = Annotated[JobRunner | None, Depends(get_runner)]
ExecutorNameDep = Annotated[str, Depends(get_executor_name)]


def check_scene(scene: Scene, settings: Settings) -> None:
    """A request's scene, after the body's model validated its structure: its geometry (contact
    points on their bodies and on the object, normals into it: 422 naming the field, as a scene
    file gets) and its size (413 over ``max_contacts``)."""
    check_geometry(scene)  # SceneError -> 422 located in "scene"
    check_scene_size(scene, settings)


def check_scene_size(scene: Scene, settings: Settings) -> None:
    """Scenes over ``max_contacts`` contacts: 413 with the limit."""
    n = len(scene.contacts)
    if n > settings.max_contacts:
        raise ApiError(413, f"scene.contacts: {n} contacts; this server's limit is {settings.max_contacts} "
                            f"(max_contacts)", limit=settings.max_contacts,
                       errors=[{"loc": ["scene", "contacts"], "msg": f"more than {settings.max_contacts} contacts",
                                "type": "too_large"}])
