"""``OPTIONS`` and ``405`` answers that name every method of a path.

Starlette answers a method a path does not take with 405 and an ``Allow`` header that names the
methods of the first route of that path only (``/plans`` said ``POST`` although ``GET /plans``
works), and has no ``OPTIONS`` answer. This middleware answers ``OPTIONS`` on a known path with
204 and ``Allow`` listing the methods of every route of the path (``/plans``: ``GET, POST,
OPTIONS``; ``/plans/{id}``: ``GET, DELETE, OPTIONS``), and puts the same list in every 405.
"""

from __future__ import annotations

import contextlib
from typing import Any

from starlette.routing import Match, Mount

_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE")


def allowed_methods(app: Any, scope: Any) -> list[str]:
    """The methods some route of ``app`` takes at the request's path (empty: no such path),
    found by asking each route whether it would take the request with each method."""
    routes = getattr(getattr(app, "router", None), "routes", [])
    methods = []
    for m in _METHODS:
        probe = {**scope, "method": m}
        for route in routes:
            if isinstance(route, Mount):  # static files: not an API path
                continue
            with contextlib.suppress(Exception):
                if route.matches(probe)[0] == Match.FULL:
                    methods.append(m)
                    break
    return [*methods, "OPTIONS"] if methods else []


class AllowedMethods:
    """ASGI middleware: see the module docstring."""

    def __init__(self, app: Any):
        self.app = app

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if scope["method"] == "OPTIONS":
            allow = allowed_methods(scope.get("app"), scope)
            if allow:
                await send({"type": "http.response.start", "status": 204,
                            "headers": [(b"allow", ", ".join(allow).encode()), (b"content-length", b"0")]})
                await send({"type": "http.response.body", "body": b""})
                return

        async def send_with_allow(msg: Any) -> None:
            if msg["type"] == "http.response.start" and msg["status"] == 405:
                allow = allowed_methods(scope.get("app"), scope)
                if allow:
                    headers = [(k, v) for k, v in msg.get("headers", []) if k.lower() != b"allow"]
                    msg = {**msg, "headers": [*headers, (b"allow", ", ".join(allow).encode())]}
            await send(msg)

        await self.app(scope, receive, send_with_allow)
