"""A content-addressed cache of analysis results: the same scene and the same request parameters
are answered without a worker.

The key is the SHA-256 of the canonical JSON (sorted keys, no spaces) of the task kind and its
payload (the validated scene as ``Scene.model_dump(mode="json")`` plus the request's parameters),
so two requests that differ only in key order or number spelling (``1`` vs ``1.0``) share an
entry. Only successful results are kept, as the JSON bytes sent, least recently used first out.
The analysis is deterministic for a given scene and parameters, so a cached answer is the
answer. Identical requests that arrive while the first is still computed wait for it instead of
computing it again (:func:`answer`: ``shared``); when that one fails, they get its error.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import threading
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from typing import Any, Literal


def cache_key(kind: str, payload: dict[str, Any]) -> str:
    """SHA-256 (hex) of the canonical JSON of ``{"kind": kind, **payload}``."""
    text = json.dumps({"kind": kind, **payload}, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


#: Most bytes the cache holds in all (a table of 19,683 combinations is a few megabytes).
MAX_CACHE_BYTES = 64_000_000


class ResultCache:
    """At most ``max_entries`` results (JSON bytes) by key and ``max_bytes`` in all, least
    recently used out first."""

    def __init__(self, max_entries: int, max_bytes: int = MAX_CACHE_BYTES):
        self.max_entries = max_entries
        self.max_bytes = max_bytes
        self.size = 0
        self._data: OrderedDict[str, bytes] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0
        #: results being computed, by key (the event loop's only: no lock)
        self.inflight: dict[str, asyncio.Future[bytes]] = {}
        #: SHA-256 of a request body, byte for byte, -> the key of its answer (:class:`RepeatedBodies`)
        self._bodies: OrderedDict[str, str] = OrderedDict()

    def get(self, key: str) -> bytes | None:
        with self._lock:
            value = self._data.get(key)
            if value is None:
                self.misses += 1
                return None
            self._data.move_to_end(key)
            self.hits += 1
            return value

    def put(self, key: str, value: bytes) -> None:
        if self.max_entries <= 0 or len(value) > self.max_bytes:
            return
        with self._lock:
            old = self._data.pop(key, None)
            self.size -= len(old) if old is not None else 0
            self._data[key] = value
            self.size += len(value)
            while len(self._data) > self.max_entries or self.size > self.max_bytes:
                _, dropped = self._data.popitem(last=False)
                self.size -= len(dropped)

    def __len__(self) -> int:
        return len(self._data)

    def remember_body(self, body_sha256: str, key: str) -> None:
        """A request body whose answer is cached under ``key`` (at most ``4 * max_entries``)."""
        if self.max_entries <= 0:
            return
        with self._lock:
            self._bodies[body_sha256] = key
            self._bodies.move_to_end(body_sha256)
            while len(self._bodies) > 4 * self.max_entries:
                self._bodies.popitem(last=False)

    def get_body(self, body_sha256: str) -> bytes | None:
        """The cached answer of a request body seen before, byte for byte, or None."""
        with self._lock:
            key = self._bodies.get(body_sha256)
        return None if key is None else self.get(key)


How = Literal["hit", "shared", "miss"]


async def answer(cache: ResultCache, key: str, compute: Callable[[], Awaitable[bytes]]) -> tuple[bytes, How]:
    """The result for ``key``: from the cache (``hit``), from an identical request being computed
    now (``shared``: its result, or its error raised again), else ``compute()`` (``miss``, and the
    result is cached)."""
    hit = cache.get(key)
    if hit is not None:
        return hit, "hit"
    leader = cache.inflight.get(key)
    if leader is not None:
        try:
            return await asyncio.shield(leader), "shared"
        except asyncio.CancelledError:
            if not leader.cancelled():
                raise  # this request was cancelled, not the one it waited for
            # that request was cancelled (its client went away): compute it here
    fut: asyncio.Future[bytes] = asyncio.get_running_loop().create_future()
    cache.inflight[key] = fut
    try:
        content = await compute()
    except asyncio.CancelledError:
        fut.cancel()
        raise
    except BaseException as e:
        fut.set_exception(e)
        fut.exception()  # retrieved: no "never retrieved" warning when nobody waited
        raise
    else:
        cache.put(key, content)
        fut.set_result(content)
        return content, "miss"
    finally:
        if cache.inflight.get(key) is fut:
            del cache.inflight[key]


#: Where :class:`RepeatedBodies` leaves the SHA-256 of the body for the route (``request.scope``).
BODY_SHA256 = "ctp.body_sha256"


class RepeatedBodies:
    """ASGI middleware: a ``POST`` to ``path`` whose body is byte for byte one answered before
    (its SHA-256 was remembered with :meth:`ResultCache.remember_body`) gets the cached answer
    without routing, parsing or validation (``X-Cache: hit``). Any other request goes on with the
    body's SHA-256 in ``scope["ctp.body_sha256"]``. Bodies without a ``Content-Length`` or over
    ``limit`` are not read here (the body size limit answers them)."""

    def __init__(self, app: Any, path: str, limit: int):
        self.app = app
        self.path = path
        self.limit = limit

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] != self.path:
            await self.app(scope, receive, send)
            return
        length = next((v for k, v in scope.get("headers", []) if k == b"content-length"), None)
        if length is None or not length.isdigit() or int(length) > self.limit:
            await self.app(scope, receive, send)
            return
        chunks: list[bytes] = []
        messages: list[Any] = []
        while True:
            msg = await receive()
            messages.append(msg)
            if msg["type"] != "http.request":
                break  # the client went away: let the app see it
            chunks.append(msg.get("body", b""))
            if not msg.get("more_body", False):
                break
        digest = hashlib.sha256(b"".join(chunks)).hexdigest()
        cache: ResultCache | None = getattr(getattr(scope.get("app"), "state", None), "analysis_cache", None)
        hit = cache.get_body(digest) if cache is not None else None
        if hit is not None:
            await send({"type": "http.response.start", "status": 200,
                        "headers": [(b"content-type", b"application/json"), (b"x-cache", b"hit"),
                                    (b"content-length", str(len(hit)).encode())]})
            await send({"type": "http.response.body", "body": hit})
            return
        replay = iter(messages)

        async def replayed() -> Any:
            msg = next(replay, None)
            return msg if msg is not None else await receive()

        await self.app({**scope, BODY_SHA256: digest}, replayed, send)
