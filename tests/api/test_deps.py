"""The routes' dependencies run in the event loop: a plain ``def`` dependency is sent to FastAPI's
thread pool, a thread round trip per dependency and request (issue 13: the server's CPU per light
request)."""

from __future__ import annotations

import inspect

from fastapi.params import Depends

import api.deps as deps


def test_state_dependencies_are_coroutines() -> None:
    aliases = [deps.SettingsDep, deps.StoreDep, deps.AnalysisPoolDep, deps.LightPoolDep, deps.CacheDep,
               deps.RunnerDep, deps.ExecutorNameDep]
    for alias in aliases:
        marker = next(m for m in alias.__metadata__ if isinstance(m, Depends))
        assert marker.dependency is not None
        assert inspect.iscoroutinefunction(marker.dependency), marker.dependency.__name__
