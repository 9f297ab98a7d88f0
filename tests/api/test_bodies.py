"""Bodies over ``inline_body_bytes`` are screened in a worker (api/bodies.py): every answer equals
the one of the same body read in the server, and the server's event loop never waits for it."""

from __future__ import annotations

import asyncio
import copy
import json
import time
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient
from service_helpers import example, settings_for

from api.body_rules import screen_body
from api.main import create_app
from api.workers import ProcessPool

PLANAR = example("planar_disk_envelope")  # five contacts


def _chain(n: int) -> dict[str, Any]:
    scene = copy.deepcopy(PLANAR)
    scene["fingers"][0]["links"] = [{"length": 0.01} for _ in range(n)]
    scene["fingers"][0]["q"] = [0.0] * n
    return scene


def _far_away_auto() -> dict[str, Any]:
    """Contacts left to the detector, the object far from every body: a SceneError at contacts."""
    scene = copy.deepcopy(PLANAR)
    scene["contacts"] = "auto"
    scene["object"]["pose"]["position"] = [50.0, 50.0]
    return scene


def _seven_contacts() -> dict[str, Any]:
    scene = copy.deepcopy(PLANAR)
    scene["contacts"] = scene["contacts"] + scene["contacts"][:2]
    return scene


J = {"content-type": "application/json"}

#: (route, body bytes, headers): valid and invalid bodies of every screened route and every kind of
#: refusal (the counts, the model, a SceneError, JSON that does not decode), plus a body FastAPI
#: does not read as JSON.
CASES: list[tuple[str, bytes, dict[str, str]]] = [
    ("/analyses", json.dumps({"scene": PLANAR, "combination": "FDFDD"}).encode(), J),
    ("/analyses", json.dumps({"scene": _seven_contacts()}).encode(), J),  # 413 max_contacts
    ("/analyses", json.dumps({"scene": PLANAR, "combination": "FDF"}).encode(), J),  # letters
    ("/analyses", json.dumps({"scene": PLANAR, "combination": "FDFDD", "nu": 5.5}).encode(), J),  # model
    ("/analyses", json.dumps({"scene": _chain(400), "combination": "FDFDD"}).encode(), J),  # 413 max_joints
    ("/enumerations", json.dumps({"scene": _seven_contacts()}).encode(), J),
    ("/enumerations", json.dumps({"scene": {**PLANAR, "dim": 4}}).encode(), J),
    ("/plans", json.dumps({"scene": PLANAR, "goal": {"kind": "active"}}).encode(), J),
    ("/plans", json.dumps({"scene": _far_away_auto(), "goal": {"type": "active"}}).encode(), J),  # SceneError
    ("/scenes/geometry", json.dumps({"scene": PLANAR, "configurations": [[0.0]]}).encode(), J),
    ("/scenes/geometry", json.dumps({"scene": PLANAR, "extra": [0] * 10}).encode(), J),
    ("/scenes/contacts", json.dumps({"scene": {**PLANAR, "contacts": "auto"}, "tolerance": -1}).encode(), J),
    ("/analyses", b'{"scene": {"dim": 2,', J),  # JSON decode error
    ("/analyses", json.dumps({"scene": PLANAR, "combination": "FDFDD"})[:-1].encode() + b', "combination": "FFFFF"}',
     J),  # a key written twice
    ("/plans", json.dumps({"scene": PLANAR, "goal": {"type": "active"}}).replace(
        '"contacts": [', '"contacts": [], "contacts": [', 1).encode(), J),
    ("/plans", b"[" * 100_000 + b"]" * 100_000, J),  # nested too deeply
    ("/analyses", b'{"scene": "\xff\xfe"}', J),  # not UTF-8
    ("/analyses", b'{"scene": 1}', {"content-type": "text/plain"}),  # not read as JSON
    ("/analyses", json.dumps({"scene": PLANAR, "combination": "FDFDD"}).encode(),
     {"content-type": "application/vnd.ctp+json"}),
]


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[TestClient, TestClient]]:
    """The same service twice: bodies read in the server (the default 64 kB), and every JSON body
    screened in a worker first (``inline_body_bytes=0``)."""
    inline = create_app(settings_for(tmp_path_factory.mktemp("inline"), run_jobs=False))
    screened = create_app(settings_for(tmp_path_factory.mktemp("screened"), run_jobs=False, inline_body_bytes=0))
    with TestClient(inline) as a, TestClient(screened) as b:
        yield a, b


def _answer(r: Any) -> tuple[int, Any]:
    body = r.json()
    if isinstance(body, dict):  # a job's id, times and links and an analysis' time differ
        body = {k: v for k, v in body.items()
                if k not in ("id", "url", "created_at", "updated_at", "links", "elapsed_seconds")}
    return r.status_code, body


@pytest.mark.parametrize("k", range(len(CASES)))
def test_a_screened_body_gets_the_answer_of_a_body_read_in_the_server(pair: tuple[TestClient, TestClient],
                                                                      k: int) -> None:
    route, content, headers = CASES[k]
    inline, screened = pair
    a = inline.post(route, content=content, headers=headers)
    b = screened.post(route, content=content, headers=headers)
    assert _answer(a) == _answer(b), (a.text[:300], b.text[:300])
    assert a.status_code < 500, a.text[:300]
    if b.status_code >= 400:  # a refusal of a JSON body says it was screened in a light worker
        assert (b.headers.get("x-lane") == "light") == (headers is J), b.headers
        if len(content) <= 64_000 and route != "/scenes/contacts":  # refused in the server
            assert "x-lane" not in a.headers, a.headers


def test_the_cases_cover_every_outcome_of_the_screen() -> None:
    limits = {"max_joints": 128, "max_contacts": 6}
    rules = {"/analyses": "create_analysis", "/enumerations": "create_enumeration", "/plans": "create_plan",
             "/scenes/geometry": "scene_geometry", "/scenes/contacts": "scene_contacts"}
    kinds = set()
    for route, content, headers in CASES:
        if headers is J:
            kinds |= set(screen_body(rules[route], content, limits))
    assert kinds == {"accepted", "invalid", "unreadable", "refused", "scene"}, kinds


@pytest.mark.parametrize("inline", [True, False])
def test_a_key_written_twice_is_422_naming_it(pair: tuple[TestClient, TestClient], inline: bool) -> None:
    """JSON keeps the last of two equal keys silently: the scene's first ``contacts`` (or the first
    ``combination``) would be lost without a word. Refused read in the server and screened alike."""
    client = pair[0] if inline else pair[1]
    body = json.dumps({"scene": PLANAR, "goal": {"type": "active"}})
    body = body.replace('"contacts": [', '"contacts": [], "contacts": [', 1)
    r = client.post("/plans", content=body.encode(), headers=J)
    assert r.status_code == 422, r.text
    assert r.json()["detail"] == "body: the key 'contacts' is written twice in one object; write each key once"
    assert r.json()["errors"][0]["type"] == "duplicate_key"
    r = client.post("/plans", content=body.replace('"contacts": [], ', "", 1).encode(), headers=J)
    assert r.status_code == 202, r.text


def test_a_large_message_to_a_worker_still_importing_does_not_block_the_event_loop() -> None:
    """A fresh worker reads nothing until it has imported the analysis (seconds); a pipe holds
    64 kB, so a 1 MB task message written from the event loop held it that long."""

    async def main() -> tuple[float, dict[str, Any]]:
        pool = ProcessPool(1, "test")
        await pool.start(wait=False)
        worst, stop = 0.0, asyncio.Event()

        async def tick() -> None:
            nonlocal worst
            while not stop.is_set():
                t0 = time.perf_counter()
                await asyncio.sleep(0.01)
                worst = max(worst, time.perf_counter() - t0 - 0.01)

        ticker = asyncio.ensure_future(tick())
        try:
            body = json.dumps({"scene": PLANAR, "pad": "x" * 1_000_000}).encode()
            out = await pool.run("body", {"rule": "create_analysis", "body": body,
                                          "limits": {"max_joints": 128, "max_contacts": 6}}, timeout=120)
        finally:
            stop.set()
            await ticker
            await pool.close()
        return worst, out

    worst, out = asyncio.run(main())
    assert out == {"invalid": [{"type": "extra_forbidden", "loc": ["body", "pad"], "msg": "Extra inputs are not "
                                                                                      "permitted"}]}, out
    assert worst < 0.3, worst
