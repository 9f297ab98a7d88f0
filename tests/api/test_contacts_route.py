"""POST /scenes/contacts and ``"contacts": "auto"`` in the service (issue 10), on real workers."""

from __future__ import annotations

import copy
import json

import numpy as np
from fastapi.testclient import TestClient
from service_helpers import example

PLANAR = example("planar_disk_envelope")


def _without_contacts() -> dict:
    scene = copy.deepcopy(PLANAR)
    del scene["contacts"]
    return scene


def test_contacts_route_finds_the_bundled_contacts(client: TestClient) -> None:
    r = client.post("/scenes/contacts", json={"scene": _without_contacts(), "mu": 0.4})
    assert r.status_code == 200, r.text
    body = r.json()
    assert [c["body"] for c in body["contacts"]] == [c["body"] for c in PLANAR["contacts"]]
    for got, want in zip(body["scene"]["contacts"], PLANAR["contacts"], strict=True):
        np.testing.assert_allclose(got["point"], want["point"], atol=1e-9)
        np.testing.assert_allclose(got["normal"], want["normal"], atol=1e-9)
        assert got["mu"] == 0.4
    assert all(c["gap"] < 1e-9 for c in body["contacts"]) and body["near_misses"] == []
    assert body["tolerance"] == 1e-3


def test_auto_contacts_are_analysed(client: TestClient) -> None:
    scene = {**_without_contacts(), "contacts": "auto"}
    r = client.post("/analyses", json={"scene": scene, "combination": "FDFDD"})
    assert r.status_code == 200, r.text
    s = client.post("/analyses", json={"scene": PLANAR, "combination": "FDFDD"})
    auto, given = r.json()["report"], s.json()["report"]
    assert auto["feasible"] is given["feasible"] is True
    assert (auto["dim_dafc"], auto["dim_dpfc"]) == (given["dim_dafc"], given["dim_dpfc"]) == (1, 2)
    assert auto["reason"] == given["reason"]


def test_bad_contacts_requests_are_422_naming_the_field(client: TestClient) -> None:
    far = _without_contacts()
    far["object"]["pose"]["position"] = [0.0, 3.0]
    r = client.post("/scenes/contacts", json={"scene": far})
    assert r.status_code == 422
    assert r.json()["detail"].startswith("scene.contacts:") and "touches nothing" in r.json()["detail"]
    r = client.post("/scenes/contacts", json={"scene": _without_contacts(), "tolerance": -1.0})
    assert r.status_code == 422 and "tolerance" in r.json()["detail"]
    r = client.post("/scenes/contacts", json={"scene": _without_contacts(), "colour": "red"})
    assert r.status_code == 422 and "colour" in r.json()["detail"]
    bad = {**_without_contacts(), "shine": 1}
    r = client.post("/scenes/contacts", json={"scene": bad})
    assert r.status_code == 422 and r.json()["detail"].startswith("scene.shine")


def test_upload_of_a_scene_without_contacts_returns_them(client: TestClient) -> None:
    files = {"file": ("scene.json", json.dumps(_without_contacts()).encode(), "application/json")}
    r = client.post("/scenes/upload", files=files)
    assert r.status_code == 200, r.text
    assert [c["body"] for c in r.json()["contacts"]] == [c["body"] for c in PLANAR["contacts"]]


def test_contacts_route_places_the_touching_links_first(client: TestClient) -> None:
    """``touch`` as in ``ctp contacts --touch``: the unplaced Panda's forearm is moved onto the
    box, then the contacts are found; an unknown link is a 422 naming ``touch``."""
    unplaced = example("unplaced/panda_forearm_box")
    r = client.post("/scenes/contacts", json={"scene": unplaced, "touch": ["panda_link4"]})
    assert r.status_code == 200, r.text
    body = r.json()
    assert "arm/panda_link4" in [c["body"] for c in body["contacts"]]
    assert all(c["gap"] < 1e-3 for c in body["contacts"])
    q0, q1 = unplaced["fingers"][0]["q"], body["scene"]["fingers"][0]["q"]
    assert not np.allclose(q0, q1)  # the arm was moved
    bad = client.post("/scenes/contacts", json={"scene": unplaced, "touch": ["no_such_link"]})
    assert bad.status_code == 422 and "no_such_link" in bad.text, bad.text
    assert bad.json()["errors"][0]["loc"] == ["touch"], bad.text
