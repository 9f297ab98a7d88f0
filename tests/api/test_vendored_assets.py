"""Vendored front-end assets (api/static/vendor): Swagger UI served by the app itself so ``/docs``
works offline, three.js and urdf-loader as ES modules behind index.html's import map. Every file
the manifest lists exists and has its recorded sha256, and every module import resolves to a
vendored file."""

from __future__ import annotations

import hashlib
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from service_helpers import settings_for

from api.main import STATIC, create_app

VENDOR = STATIC / "vendor"
MANIFEST = json.loads((VENDOR / "manifest.json").read_text())
EXTERNAL = re.compile(r"""(?:https?:)?//[a-z0-9.-]+\.[a-z]{2,}""", re.I)
IMPORT = re.compile(r"""(?:^|[;\s])(?:import|export)\s[^'"]*?from\s*['"]([^'"]+)['"]"""
                    r"""|^import\s*['"]([^'"]+)['"]""", re.M)


class _Refs(HTMLParser):
    """The URLs a page loads: script src, link href, img src."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[str] = []
        self.importmap: list[str] = []
        self._in_map = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        for key in ("src", "href"):
            if a.get(key) and tag in ("script", "link", "img"):
                self.urls.append(str(a[key]))
        self._in_map = tag == "script" and a.get("type") == "importmap"

    def handle_endtag(self, tag: str) -> None:
        self._in_map = False

    def handle_data(self, data: str) -> None:
        if self._in_map:
            self.importmap.append(data)


@pytest.fixture
def plain_client(tmp_path: Path) -> TestClient:
    # no lifespan: static pages and the docs need no workers
    return TestClient(create_app(settings_for(tmp_path)))


def _refs(html: str) -> _Refs:
    p = _Refs()
    p.feed(html)
    return p


def test_docs_served_from_local_files_only(plain_client: TestClient) -> None:
    r = plain_client.get("/docs")
    assert r.status_code == 200 and "text/html" in r.headers["content-type"]
    assert not EXTERNAL.search(r.text), EXTERNAL.findall(r.text)
    urls = _refs(r.text).urls
    types = {".js": "javascript", ".css": "text/css", ".png": "image/png"}
    assert {Path(u).suffix for u in urls} == set(types), urls
    for u in urls:
        assert u.startswith("/static/vendor/swagger-ui/"), u
        got = plain_client.get(u)
        assert got.status_code == 200, u
        assert types[Path(u).suffix] in got.headers["content-type"], (u, got.headers["content-type"])
    assert "SwaggerUIBundle" in plain_client.get(next(u for u in urls if u.endswith(".js"))).text
    assert "'/openapi.json'" in r.text and plain_client.get("/openapi.json").status_code == 200
    assert '"validatorUrl": null' in r.text  # no badge fetched from validator.swagger.io
    redirect = plain_client.get("/docs/oauth2-redirect")
    assert redirect.status_code == 200 and not EXTERNAL.search(redirect.text)
    assert plain_client.get("/redoc").status_code == 404  # not vendored, so switched off


def test_dashboard_page_has_no_external_url(plain_client: TestClient) -> None:
    r = plain_client.get("/")
    assert r.status_code == 200
    assert not EXTERNAL.search(r.text), EXTERNAL.findall(r.text)
    for u in _refs(r.text).urls:
        assert u.startswith("/"), u
        assert plain_client.get(u).status_code == 200, u


def test_manifest_files_exist_and_match_their_checksums() -> None:
    listed: set[Path] = set()
    for pkg in MANIFEST["packages"]:
        assert re.fullmatch(r"\d+\.\d+\.\d+", pkg["version"]), pkg  # an exact version, no range
        assert pkg["folder"] == f"{pkg['folder'].split('/')[0]}/{pkg['version']}"
        assert pkg["tarball"] == f"https://registry.npmjs.org/{pkg['name']}/-/{pkg['name']}-{pkg['version']}.tgz"
        assert pkg["integrity"].startswith("sha512-") and pkg["license"]
        for rel, digest in pkg["files"].items():
            path = VENDOR / rel
            assert path.is_file(), rel
            assert rel.startswith(pkg["folder"] + "/"), rel
            assert hashlib.sha256(path.read_bytes()).hexdigest() == digest, f"{rel}: checksum differs"
            listed.add(path.resolve())
    on_disk = {p.resolve() for p in VENDOR.rglob("*") if p.is_file() and p.parent != VENDOR}  # the records aside
    assert on_disk == listed, f"files not in the manifest: {sorted(map(str, on_disk - listed))}"
    assert {p["name"] for p in MANIFEST["packages"]} == {"swagger-ui-dist", "three", "urdf-loader"}


def _import_map() -> dict[str, str]:
    blocks = _refs((STATIC / "index.html").read_text()).importmap
    assert len(blocks) == 1, "index.html has one import map"
    imports: dict[str, str] = json.loads(blocks[0])["imports"]
    return imports


def _resolve(spec: str, base: Path, imports: dict[str, str]) -> Path:
    """Where the browser finds module ``spec`` imported from file ``base`` (import-map rules:
    an exact key, else the longest prefix key ending in "/")."""
    if spec.startswith(("./", "../")):
        return (base.parent / spec).resolve()
    if spec in imports:
        url = imports[spec]
    else:
        prefixes = [k for k in imports if k.endswith("/") and spec.startswith(k)]
        assert prefixes, f"{base.name}: bare import {spec!r} is not in the import map"
        key = max(prefixes, key=len)
        url = imports[key] + spec[len(key):]
    assert url.startswith("/static/"), url
    return (STATIC / url.removeprefix("/static/")).resolve()


def test_import_map_points_at_vendored_files_and_every_import_resolves() -> None:
    imports = _import_map()
    for key, url in imports.items():
        target = STATIC / url.removeprefix("/static/")
        assert url.startswith("/static/vendor/"), url
        assert target.is_dir() if key.endswith("/") else target.is_file(), (key, url)
    # walk the module graph from the entry points the dashboard uses
    todo = [_resolve(s, STATIC / "index.html", imports)
            for s in ("three", "three/addons/controls/OrbitControls.js", "urdf-loader")]
    seen: set[Path] = set()
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        assert f.is_file(), f"missing module {f}"
        assert VENDOR.resolve() in f.parents, f
        seen.add(f)
        for m in IMPORT.finditer(f.read_text()):
            todo.append(_resolve(m.group(1) or m.group(2), f, imports))
    names = {p.name for p in seen}
    assert {"three.module.js", "three.core.js", "OrbitControls.js", "URDFLoader.js", "URDFClasses.js",
            "STLLoader.js", "ColladaLoader.js"} <= names, names
