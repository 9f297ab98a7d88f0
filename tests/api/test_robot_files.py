"""``GET /robot-files/example-robot-data/{path}``: the URDFs and meshes of the installed
example-robot-data for the dashboard's 3-D view. Real files come back with their bytes and a
media type; traversal, symbolic links out of the folder, absolute paths and files that are not
robot files are 404 JSON naming the reason and never a folder of the server."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from service_helpers import settings_for

from analysis.urdf import example_robot_data_dir
from api.main import create_app
from api.routes import robot_files

ERD = example_robot_data_dir()
ALLEGRO = "allegro_hand_description/urdf/allegro_right_hand.urdf"
MESH = "allegro_hand_description/meshes/link_0.0.STL"
URL = "/robot-files/example-robot-data/"


@pytest.fixture
def client(tmp_path: Path) -> TestClient:
    return TestClient(create_app(settings_for(tmp_path)))  # no lifespan: no workers needed


@pytest.fixture
def fake_root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A robots folder of our own with a mesh, a secret outside it and links pointing out."""
    root = tmp_path / "robots"
    (root / "bot" / "meshes").mkdir(parents=True)
    (root / "bot" / "meshes" / "a.stl").write_bytes(b"solid a\nendsolid a\n")
    (root / "bot" / "notes.txt").write_text("not a robot file")
    secret = tmp_path / "secret.stl"
    secret.write_text("outside the folder")
    os.symlink(secret, root / "bot" / "meshes" / "out.stl")
    os.symlink(tmp_path, root / "bot" / "up")
    os.symlink(root / "bot" / "meshes" / "a.stl", root / "bot" / "inside.stl")
    os.symlink(root / "loop.stl", root / "loop.stl")
    monkeypatch.setattr(robot_files, "_robots_dir", lambda: root.resolve())
    return root


@pytest.mark.skipif(ERD is None, reason="example-robot-data is not installed")
def test_serves_the_allegro_urdf_and_its_meshes(client: TestClient) -> None:
    assert ERD is not None
    r = client.get(URL + ALLEGRO)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("application/xml")
    assert r.content == (ERD / ALLEGRO).read_bytes()
    assert "<robot" in r.text and "link_3.0_tip" in r.text
    # every mesh the URDF names is served (the dashboard maps package:// to this route)
    meshes = sorted({line.split('filename="')[1].split('"')[0] for line in r.text.splitlines()
                     if "<mesh filename=" in line})
    assert meshes, "the Allegro URDF names its meshes"
    for uri in meshes:
        rel = uri.removeprefix("package://example-robot-data/robots/")
        got = client.get(URL + rel)
        assert got.status_code == 200, (uri, got.text)
        assert got.headers["content-type"] == "model/stl"
        assert got.content == (ERD / rel).read_bytes()


def test_real_file_through_a_fake_root(client: TestClient, fake_root: Path) -> None:
    r = client.get(URL + "bot/meshes/a.stl")
    assert r.status_code == 200 and r.content.startswith(b"solid a")
    # a link that stays inside the folder is fine
    assert client.get(URL + "bot/inside.stl").status_code == 200


@pytest.mark.parametrize(("path", "why"), [
    ("bot/meshes/out.stl", "inside the robots folder"),       # symlink to a file outside
    ("bot/up/secret.stl", "inside the robots folder"),        # symlinked folder outside
    ("bot/../../secret.stl", None),  # traversal (the HTTP client resolves it: outside the route)
    ("bot/%2e%2e/%2e%2e/secret.stl", "inside the robots folder"),  # encoded traversal
    ("/etc/hosts.stl", "inside the robots folder"),           # absolute
    ("bot//meshes/a.stl", "inside the robots folder"),        # empty component
    ("bot/notes.txt", "only robot description files"),        # not a robot file
    ("bot/meshes", "only robot description files"),           # a folder
    ("bot/meshes/missing.stl", "no such file"),
    ("loop.stl", "no such file"),                             # a symbolic-link loop
])
def test_refused_with_a_reason_and_no_server_path(client: TestClient, fake_root: Path, path: str,
                                                   why: str | None) -> None:
    r = client.get(URL + path)
    assert r.status_code == 404, (path, r.status_code, r.text)
    assert r.headers["content-type"].startswith("application/json")
    detail = r.json()["detail"]
    assert why is None or why in detail, detail
    assert str(fake_root) not in r.text and str(fake_root.parent) not in r.text
    assert "outside the folder" not in r.text


def test_not_installed_is_a_404(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(robot_files, "_robots_dir", lambda: None)
    r = client.get(URL + MESH)
    assert r.status_code == 404 and "not installed" in r.json()["detail"]


def test_too_long_and_nul(client: TestClient, fake_root: Path) -> None:
    assert client.get(URL + "a/" * 300 + "x.stl").status_code == 404
    r = client.get(URL + "bot/a%00.stl")
    assert r.status_code == 404 and "not a valid path" in r.json()["detail"]
