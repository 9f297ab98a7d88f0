"""``POST /robots`` (issue 12 item 5): a URDF with its meshes uploaded as a zip or tar, kept by the
SHA-256 of the archive, its files served back, and scenes that name ``robot:<hash>/<path>``
analysed and drawn and their contacts found; archives that would leave their folder, are too
large or hold no URDF refused with a 4xx naming the reason and no server folder."""

from __future__ import annotations

import copy
import hashlib
import io
import tarfile
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from service_helpers import ROOT, example, settings_for

from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from analysis.urdf import example_robot_data_dir
from api.main import create_app

ERD = example_robot_data_dir()
pytestmark = pytest.mark.skipif(ERD is None, reason="example-robot-data is not installed")
ERD_PACKAGE = "package://example-robot-data/robots/"


def robot_files(name: str, *, skip: tuple[str, ...] = ()) -> dict[str, bytes]:
    """``<name>/...`` of example-robot-data as archive members, its URDFs' mesh URIs rewritten
    from the installed package (``package://example-robot-data/robots/<name>/...``) to the
    archive's own package (``package://<name>/...``); folders in ``skip`` left out."""
    assert ERD is not None
    out: dict[str, bytes] = {}
    for p in sorted((ERD / name).rglob("*")):
        rel = p.relative_to(ERD).as_posix()
        if not p.is_file() or any(rel.startswith(f"{name}/{s}") for s in skip):
            continue
        data = p.read_bytes()
        if p.suffix == ".urdf":
            data = data.replace(ERD_PACKAGE.encode(), b"package://")
        out[rel] = data
    return out


def make_zip(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return buf.getvalue()


def make_tar(files: dict[str, bytes], mode: str = "w:gz", extra: list[tarfile.TarInfo] | None = None) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode=mode) as t:  # type: ignore[call-overload]
        for name, data in files.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            t.addfile(info, io.BytesIO(data))
        for info in extra or []:
            t.addfile(info)
    return buf.getvalue()


def post(client: TestClient, name: str, content: bytes) -> Any:
    return client.post("/robots", files={"file": (name, content, "application/octet-stream")})


MINI_URDF = b"""<?xml version="1.0"?>
<robot name="mini"><link name="base"/><link name="l1"><visual><geometry><mesh filename="../meshes/l1.stl"/>
</geometry></visual></link><joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>
"""


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("data")


@pytest.fixture(scope="module")
def robots(tmp_path_factory: pytest.TempPathFactory, data_dir: Path) -> Iterator[TestClient]:
    app = create_app(settings_for(tmp_path_factory.mktemp("robots"), data_dir=data_dir, max_contacts=9,
                                  max_robot_archive_bytes=3_000_000, max_robot_unpacked_bytes=4_000_000,
                                  max_robot_files=60))
    with TestClient(app) as c:
        yield c


def assert_clean(r: Any, data_dir: Path) -> None:
    """No folder of the server in the answer."""
    for p in (str(data_dir), str(data_dir.parent), str(ROOT), "site-packages", ".incoming", ".upload"):
        assert p not in r.text, (p, r.text)


# -- a real robot: the Panda, end to end ----------------------------------------------------------


def panda_scene(file: str, ball: list[float]) -> dict[str, Any]:
    return {"name": "panda-ball", "dim": 3,
            "object": {"pose": {"position": ball, "quat_wxyz": [1, 0, 0, 0]}, "shape": {"type": "sphere",
                                                                                     "radius": 0.05}},
            "external_wrench": [0, 0, -1, 0, 0, 0], "fixed_bodies": [],
            "fingers": [{"name": "arm", "base": {"position": [0, 0, 0], "quat_wxyz": [1, 0, 0, 0]},
                         "urdf": {"file": file, "root_link": "panda_link0", "tip_link": "panda_link7"},
                         "q": [0.0, -0.4, 0.0, -2.2, 0.0, 1.8, 0.8], "link_radius": 0.06}],
            "contacts": []}


def test_the_panda_uploaded_as_a_tar_gz_is_drawn_and_its_contacts_found(robots: TestClient,
                                                                        data_dir: Path) -> None:
    files = robot_files("panda_description", skip=("meshes/visual",))  # the collision meshes only
    archive = make_tar(files)
    r = post(robots, "panda.tar.gz", archive)
    assert r.status_code == 201, r.text
    body = r.json()
    digest = hashlib.sha256(archive).hexdigest()
    assert body["hash"] == digest and body["prefix"] == f"robot:{digest}/" and body["created"] is True
    assert body["files"] == len(files) and body["bytes"] == sum(len(v) for v in files.values())
    by_path = {u["path"]: u for u in body["urdf_files"]}
    assert set(by_path) == {"panda_description/urdf/panda.urdf", "panda_description/urdf/panda_collision.urdf"}
    panda = by_path["panda_description/urdf/panda.urdf"]
    assert panda["file"] == f"robot:{digest}/panda_description/urdf/panda.urdf" and panda["robot"] == "panda"
    assert "panda_link7" in panda["links"] and sum(j["type"] == "revolute" for j in panda["joints"]) == 7
    assert panda["packages"] == {"panda_description": "panda_description"}
    # the visual meshes were left out of the archive: named as missing, the collision ones found
    assert panda["missing_meshes"] and all("/meshes/visual/" in m for m in panda["missing_meshes"])
    assert (data_dir / "robots" / digest / "panda_description" / "urdf" / "panda.urdf").is_file()
    assert_clean(r, data_dir)

    again = post(robots, "same.tgz", archive)  # the same bytes: the same robot, nothing unpacked again
    assert again.status_code == 200 and again.json()["created"] is False and again.json()["hash"] == digest
    assert robots.get(f"/robots/{digest}").json()["urdf_files"] == body["urdf_files"]

    served = robots.get(f"/robots/{digest}/files/panda_description/meshes/collision/link3.stl")
    assert served.status_code == 200 and served.content == files["panda_description/meshes/collision/link3.stl"]
    assert served.headers["content-type"] == "model/stl" and "sandbox" in served.headers["content-security-policy"]

    # a ball put on the arm's link 4 (its capsule from the uploaded URDF, resolved in this
    # process too: the app exported its data folder), found by the detector, then analysed
    far = {**panda_scene(panda["file"], [2.0, 2.0, 2.0]),
           "contacts": [{"body": "arm/panda_link4", "point": [0, 0, 0], "normal": [0, 0, 1], "mu": 0.5}]}
    hand = HandKinematics.from_scene(Scene.model_validate(far))
    ref = hand.resolve_body("arm/panda_link4")
    assert ref is not None
    a, b = hand.fingers[0].body_segment(ref.link, hand.q0)
    radius = hand.body_radius(ref)
    mid = 0.5 * (a + b)
    axis = (b - a) / np.linalg.norm(b - a)
    side = np.cross(axis, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    assert side[2] > 0.9  # the link lies about horizontal: the ball sits on top of it
    ball = mid + side * (radius + 0.05)  # tangent to the link's capsule
    scene = panda_scene(panda["file"], [float(x) for x in ball])
    r = robots.post("/scenes/contacts", json={"scene": scene, "mu": 0.5})
    assert r.status_code == 200, r.text
    found = r.json()["contacts"]
    assert [c["body"] for c in found] == ["arm/panda_link4"], found
    np.testing.assert_allclose(found[0]["point"], mid + side * radius, atol=2e-3)
    np.testing.assert_allclose(found[0]["normal"], side, atol=2e-3)  # from the link into the ball
    # and the found scene analysed: one contact holds no ball against gravity, an analysis answer
    r = robots.post("/analyses", json={"scene": r.json()["scene"], "combination": "F"})
    assert r.status_code in (200, 422), r.text
    assert r.status_code == 200 or r.json()["errors"][0]["type"] == "analysis", r.text


def test_an_uploaded_allegro_hand_analyses_as_the_installed_one(robots: TestClient) -> None:
    """The Allegro example with its URDF uploaded as a zip: the same report as from the package."""
    files = robot_files("allegro_hand_description")
    r = post(robots, "allegro.zip", make_zip(files))
    assert r.status_code == 201, r.text
    urdf = next(u for u in r.json()["urdf_files"] if u["path"].endswith("allegro_right_hand.urdf"))
    assert urdf["missing_meshes"] == []
    scene = example("allegro_right_box")
    uploaded = copy.deepcopy(scene)
    for f in uploaded["fingers"]:
        if "urdf" in f:
            f["urdf"]["file"] = urdf["file"]
    combination = "F" * len(scene["contacts"])
    mine = robots.post("/analyses", json={"scene": uploaded, "combination": combination})
    theirs = robots.post("/analyses", json={"scene": scene, "combination": combination})
    assert mine.status_code == theirs.status_code == 200, (mine.text[:300], theirs.text[:300])
    a, b = mine.json()["report"], theirs.json()["report"]
    assert a["feasible"] == b["feasible"] and a["a"] == b["a"] and a["dim_dpfc"] == b["dim_dpfc"]
    np.testing.assert_allclose(a["stationary"]["tau"], b["stationary"]["tau"], atol=1e-9)


# -- refusals ------------------------------------------------------------------------------------


def _link(name: str, kind: bytes, target: str) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.type = kind
    info.linkname = target
    return info


def _zip_symlink() -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("r/urdf/r.urdf", MINI_URDF)
        info = zipfile.ZipInfo("r/meshes/l1.stl")
        info.external_attr = (0o120777 << 16)  # a symbolic link, as zip -y stores one
        z.writestr(info, "/etc/passwd")
    return buf.getvalue()


def _zip_named(name: str) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("r/urdf/r.urdf", MINI_URDF)
        z.writestr(zipfile.ZipInfo(name), b"x")
    return buf.getvalue()


def _tar_named(name: str) -> bytes:
    return make_tar({"r/urdf/r.urdf": MINI_URDF, name: b"x"})


MINI = {"r/urdf/r.urdf": MINI_URDF, "r/meshes/l1.stl": b"solid x\nendsolid x\n"}


@pytest.mark.parametrize(("name", "content", "status", "reason"), [
    ("up.tar.gz", _tar_named("../../evil.urdf"), 422, "'..' is not accepted"),
    ("up.zip", _zip_named("r/../../evil.stl"), 422, "'..' is not accepted"),
    ("abs.tar", _tar_named("/etc/cron.d/evil"), 422, "an absolute path is not accepted"),
    ("abs.zip", _zip_named("/tmp/evil.stl"), 422, "an absolute path is not accepted"),
    ("drive.zip", _zip_named("C:/evil.stl"), 422, "an absolute path is not accepted"),
    ("back.zip", _zip_named("r\\..\\evil.stl"), 422, "backslash"),
    ("sym.tgz", make_tar(MINI, extra=[_link("r/meshes/passwd.stl", tarfile.SYMTYPE, "/etc/passwd")]), 422,
     "symbolic links are not accepted"),
    ("sym.zip", _zip_symlink(), 422, "symbolic links are not accepted"),
    ("hard.tgz", make_tar(MINI, extra=[_link("r/meshes/h.stl", tarfile.LNKTYPE, "/etc/passwd")]), 422,
     "hard links are not accepted"),
    ("dev.tar", make_tar(MINI, "w", extra=[_link("r/dev0", tarfile.CHRTYPE, "")]), 422,
     "special files are not accepted"),
    ("dup.tar", make_tar(MINI, "w", extra=[tarfile.TarInfo("r/urdf/r.urdf")]), 422, "appears twice"),
    ("clash.zip", make_zip({**MINI, "r/meshes": b"a file where a folder is"}), 422, "both a file and a folder"),
    ("none.zip", make_zip({"r/readme.txt": b"no robot here", "r/mesh.stl": b"solid"}), 422, "no URDF file"),
    ("xacro.zip", make_zip({"r/r.urdf": b"<xacro:robot xmlns:xacro='x'/>"}), 422, "no URDF file"),
    ("dtd.zip", make_zip({"r/r.urdf": b"<!DOCTYPE r [<!ENTITY a 'aaaa'>]><robot name='&a;'/>"}), 422,
     "DTD or entities"),
    ("broken.zip", make_zip({"r/r.urdf": b"<robot name='x'><link"}), 422, "not well-formed XML"),
    ("scene.json", b'{"dim": 2}', 422, "not a zip or tar archive"),
    ("png.zip", b"\x89PNG\r\n\x1a\n" + b"\0" * 64, 422, "not a zip or tar archive"),
    ("cut.zip", make_zip(MINI)[:40], 422, "damaged"),
    ("many.zip", make_zip({**MINI, **{f"r/m/{i}.stl": b"s" for i in range(70)}}), 413, "more than 60 files"),
    ("huge.tar.xz", make_tar({**MINI, "r/meshes/big.stl": b"\0" * 5_000_000}, "w:xz"), 413,
     "unpacks to more than 4000000 bytes"),
    ("bomb.zip", make_zip({**MINI, "r/meshes/big.stl": b"\0" * 5_000_000}), 413,
     "unpacks to more than 4000000 bytes"),
])
def test_bad_archives_are_refused_naming_the_reason(robots: TestClient, data_dir: Path, name: str, content: bytes,
                                                    status: int, reason: str) -> None:
    before = sorted(p.name for p in (data_dir / "robots").iterdir()) if (data_dir / "robots").exists() else []
    r = post(robots, name, content)
    assert r.status_code == status, r.text
    body = r.json()
    assert reason in body["detail"] and body["errors"][0]["loc"] == ["file"], body
    assert_clean(r, data_dir)
    after = sorted(p.name for p in (data_dir / "robots").iterdir())
    assert after == before  # nothing kept, no half-unpacked folder left behind
    assert not Path("/etc/cron.d/evil").exists() and not (data_dir.parent / "evil.urdf").exists()


def test_a_member_that_lies_about_its_size_is_stopped_while_unpacking(robots: TestClient, data_dir: Path) -> None:
    """A zip whose headers say 10 bytes for a 5 MB member (so the declared sizes pass the
    unpacked limit): no more than the declared bytes are read, the check sum fails, 422 and
    nothing kept."""
    raw = make_zip({**MINI, "r/meshes/big.stl": b"\0" * 5_000_000})
    # patch the declared uncompressed size (central directory and local header) to 10 bytes
    z = zipfile.ZipFile(io.BytesIO(raw))
    info = z.getinfo("r/meshes/big.stl")
    patched = bytearray(raw)
    size = (5_000_000).to_bytes(4, "little")
    for at in [i for i in range(len(patched) - 3) if patched[i:i + 4] == size]:
        patched[at:at + 4] = (10).to_bytes(4, "little")
    assert zipfile.ZipFile(io.BytesIO(bytes(patched))).getinfo("r/meshes/big.stl").file_size == 10, info
    r = post(robots, "liar.zip", bytes(patched))
    assert r.status_code == 422 and "the archive is damaged" in r.json()["detail"], r.text
    assert not any(p.name.startswith(".incoming") for p in (data_dir / "robots").iterdir())


def test_an_archive_over_the_upload_limit_is_413(robots: TestClient) -> None:
    r = post(robots, "big.zip", b"PK\x03\x04" + b"\0" * 3_100_000)
    assert r.status_code == 413 and "max_robot_archive_bytes" in r.json()["detail"], r.text[:300]
    assert r.json()["limit"] == 3_000_000
    # the other routes keep their own, smaller limit
    r = robots.post("/analyses", content=b"{" + b" " * 300_000 + b"}", headers={"content-type": "application/json"})
    assert r.status_code == 413 and "max_body_bytes" in r.json()["detail"]


def test_no_request_without_a_file(robots: TestClient) -> None:
    r = robots.post("/robots", data={"other": "x"})
    assert r.status_code == 422 and r.json()["detail"].startswith("file:"), r.text


@pytest.mark.parametrize("path", ["../robots.json", "r/../../x.urdf", "/etc/passwd", "r/urdf/missing.urdf",
                                  "r/urdf/r.py", "r%2F..%2F..%2Fx.urdf"])
def test_files_outside_a_robot_or_not_robot_files_are_404(robots: TestClient, data_dir: Path, path: str) -> None:
    r = post(robots, "mini.zip", make_zip(MINI))
    assert r.status_code in (200, 201), r.text
    digest = r.json()["hash"]
    assert robots.get(f"/robots/{digest}/files/r/urdf/r.urdf").content == MINI_URDF
    got = robots.get(f"/robots/{digest}/files/{path}")
    assert got.status_code == 404, got.text
    assert_clean(got, data_dir)
    assert robots.get(f"/robots/{'0' * 64}/files/r/urdf/r.urdf").status_code == 404
    assert robots.get("/robots/not-a-hash").status_code == 404


def test_a_symlink_planted_in_the_store_is_not_followed(robots: TestClient, data_dir: Path, tmp_path: Path) -> None:
    """A link put into a robot's folder by someone else: neither served nor resolved for a scene."""
    r = post(robots, "mini.zip", make_zip(MINI))
    digest = r.json()["hash"]
    secret = tmp_path / "secret.urdf"
    secret.write_text("<robot name='secret'/>")
    link = data_dir / "robots" / digest / "r" / "urdf" / "planted.urdf"
    link.symlink_to(secret)
    try:
        assert robots.get(f"/robots/{digest}/files/r/urdf/planted.urdf").status_code == 404
        scene = panda_scene(f"robot:{digest}/r/urdf/planted.urdf", [1, 1, 1])
        r = robots.post("/scenes/geometry", json={"scene": scene})
        assert r.status_code == 422 and "fingers.0.urdf.file" in r.json()["detail"], r.text
        assert "not found" in r.json()["detail"]
        assert_clean(r, data_dir)
    finally:
        link.unlink()


@pytest.mark.parametrize(("file", "words"), [
    ("robot:abc/r.urdf", "64 hex digits"),
    (f"robot:{'0' * 64}/r/urdf/r.urdf", "no robot uploaded"),
    (f"robot:{'0' * 64}/../../../etc/passwd", "fingers.0.urdf.file"),
    ("/etc/passwd", "example-robot-data:<path>' or 'robot:<sha256>/<path>"),
])
def test_scenes_naming_no_uploaded_robot_are_422(robots: TestClient, data_dir: Path, file: str, words: str) -> None:
    r = robots.post("/scenes/geometry", json={"scene": panda_scene(file, [1, 1, 1])})
    assert r.status_code == 422 and "fingers.0.urdf.file" in r.json()["detail"] and words in r.text, r.text
    assert_clean(r, data_dir)


def test_robot_paths_resolve_in_the_default_data_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without ``CTP_DATA_DIR`` a ``robot:`` path resolves in ``ctp-data`` of the working
    directory, the service's default ``data_dir``: the CLI finds what a local server stored."""
    from analysis.urdf import resolve_urdf_path
    from api.settings import Settings

    digest = "ab" * 32
    urdf = tmp_path / Settings.model_fields["data_dir"].default / "robots" / digest / "r" / "r.urdf"
    urdf.parent.mkdir(parents=True)
    urdf.write_bytes(MINI_URDF)
    monkeypatch.delenv("CTP_DATA_DIR", raising=False)
    monkeypatch.chdir(tmp_path)
    assert resolve_urdf_path(f"robot:{digest}/r/r.urdf").resolve() == urdf.resolve()


# -- mesh objects and URDF collision geometry from an upload ----------------------------------------


@pytest.mark.parametrize("file", ["/etc/passwd", "x.stl", "example-robot-data:../../../etc/passwd",
                                  f"robot:{'0' * 64}/../../x.stl"])
def test_a_mesh_object_over_http_stays_inside_the_robot_folders(robots: TestClient, data_dir: Path,
                                                               file: str) -> None:
    """A mesh object's file is read by the server: over HTTP only from example-robot-data or an
    uploaded robot, containment checked; the answer names the field and no server folder."""
    scene = panda_scene("example-robot-data:panda_description/urdf/panda.urdf", [2.0, 2.0, 2.0])
    scene["object"]["shape"] = {"type": "mesh", "file": file}
    r = robots.post("/scenes/geometry", json={"scene": scene})
    assert r.status_code == 422, r.text
    assert "object.shape.file" in r.text or "object', 'shape', 'file" in r.text, r.text
    assert_clean(r, data_dir)


def test_an_uploaded_robots_collision_meshes_and_mesh_files_resolve(robots: TestClient, data_dir: Path) -> None:
    """``link_geometry: "urdf"`` finds the uploaded URDF's ``package://`` collision meshes inside
    its own folder, and a mesh object may be one of the upload's STL files."""
    # renamed, so that the installed example-robot-data cannot supply the meshes
    files = {k.replace("panda_description/", "my_arm/", 1): v.replace(b"package://panda_description/",
                                                                     b"package://my_arm/")
             for k, v in robot_files("panda_description", skip=("meshes/visual",)).items()}
    r = post(robots, "my_arm.tar.gz", make_tar(files))
    assert r.status_code in (200, 201), r.text
    digest = r.json()["hash"]
    scene = panda_scene(f"robot:{digest}/my_arm/urdf/panda.urdf", [2.0, 2.0, 2.0])
    scene["fingers"][0]["link_geometry"] = "urdf"
    scene["object"]["shape"] = {"type": "mesh", "file": f"robot:{digest}/my_arm/meshes/collision/link3.stl"}
    r = robots.post("/scenes/contacts", json={"scene": scene, "mu": 0.5})
    # the object 3 m away touches nothing: a clear 422 from the detector, not a missing file
    assert r.status_code == 422, r.text
    assert "touches nothing" in r.text or "no contact" in r.text.lower(), r.text
    assert_clean(r, data_dir)
