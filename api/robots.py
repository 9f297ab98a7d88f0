"""Uploaded robots: a URDF with its meshes in a zip or tar archive (gzip, bzip2, xz or none),
kept by the SHA-256 of the archive in ``<data_dir>/robots/<sha256>/`` and referenced from scenes
as ``urdf.file = "robot:<sha256>/<path inside the archive>"`` (analysis/urdf.py
``resolve_urdf_path``).

Every member is checked before anything is written: only regular files and folders (symbolic
links, hard links, devices and FIFOs are refused), names relative and inside the archive's
folder (no absolute path, no drive letter, no ``..``, no backslash, no NUL), no name twice, at
most ``max_files`` files and ``max_unpacked`` bytes in all (counted again while unpacking, so a
member that lies about its size is stopped too). The archive must hold at least one URDF (an XML
file with a ``<robot>`` root, read without a DTD). It is unpacked into a fresh folder beside the
store and renamed into place in one step, so a robot folder is complete or absent. Every refusal
is :class:`RobotArchiveError` (a 4xx with the reason); no message shows a folder of the server.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import lzma
import os
import shutil
import stat
import tarfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import IO, Any

#: Longest member name (characters) and deepest folder nesting accepted.
MAX_NAME = 400
MAX_DEPTH = 24
#: Largest URDF file read for the listing (bytes).
MAX_URDF_BYTES = 16_000_000
_CHUNK = 1 << 20


class RobotArchiveError(Exception):
    """An archive refused: ``status`` (413 over a size limit, 422 otherwise), ``reason``."""

    def __init__(self, status: int, reason: str, limit: int | None = None):
        super().__init__(reason)
        self.status = status
        self.reason = reason
        self.limit = limit


@dataclass(frozen=True)
class Limits:
    unpacked_bytes: int
    files: int


@dataclass(frozen=True)
class _Member:
    name: str  # normalised, relative, POSIX
    is_dir: bool
    size: int
    handle: Any  # the zipfile.ZipInfo or tarfile.TarInfo


def robots_dir(data_dir: Path) -> Path:
    return data_dir / "robots"


def is_digest(text: str) -> bool:
    return len(text) == 64 and all(c in "0123456789abcdef" for c in text)


def _shown(name: str) -> str:
    name = name.replace("\x00", "\\0")
    return name if len(name) <= 120 else name[:117] + "..."


def member_name(raw: str) -> str:
    """The archive member's name, normalised (``a/b/c``), or RobotArchiveError naming it."""
    bad = f"archive member '{_shown(raw)}'"
    if "\x00" in raw or "\\" in raw:
        raise RobotArchiveError(422, f"{bad}: a name with a NUL or a backslash is not accepted")
    if raw.startswith("/") or (len(raw) > 1 and raw[1] == ":"):
        raise RobotArchiveError(422, f"{bad}: an absolute path is not accepted (the members must stay in "
                                     "the archive's folder)")
    parts = [p for p in raw.split("/") if p not in ("", ".")]
    if ".." in parts:
        raise RobotArchiveError(422, f"{bad}: '..' is not accepted (the members must stay in the archive's "
                                     "folder)")
    if not parts:
        raise RobotArchiveError(422, f"{bad}: an empty name")
    if len(raw) > MAX_NAME or len(parts) > MAX_DEPTH:
        raise RobotArchiveError(422, f"{bad}: longer than {MAX_NAME} characters or deeper than {MAX_DEPTH} "
                                     "folders")
    return "/".join(parts)


def _zip_members(z: zipfile.ZipFile) -> Iterator[_Member]:
    for info in z.infolist():
        name = member_name(info.filename)
        mode = info.external_attr >> 16
        if info.flag_bits & 0x1:
            raise RobotArchiveError(422, f"archive member '{_shown(info.filename)}': encrypted members are "
                                         "not accepted")
        if stat.S_ISLNK(mode):
            raise RobotArchiveError(422, f"archive member '{_shown(info.filename)}': symbolic links are not "
                                         "accepted")
        if stat.S_IFMT(mode) not in (0, stat.S_IFREG, stat.S_IFDIR):  # 0: no Unix type stored (a file)
            raise RobotArchiveError(422, f"archive member '{_shown(info.filename)}': only files and folders "
                                         "are accepted")
        yield _Member(name, info.is_dir(), info.file_size, info)


def _tar_members(t: tarfile.TarFile) -> Iterator[_Member]:
    for info in t:
        if info.issym():
            kind = "symbolic links are"
        elif info.islnk():
            kind = "hard links are"
        elif info.isfile() or info.isdir():
            kind = ""
        else:
            kind = "devices, FIFOs and other special files are"
        name = member_name(info.name)
        if kind:
            raise RobotArchiveError(422, f"archive member '{_shown(info.name)}': {kind} not accepted")
        yield _Member(name, info.isdir(), info.size, info)


def _checked(members: Iterator[_Member], limits: Limits) -> list[_Member]:
    out: list[_Member] = []
    seen: set[str] = set()
    files = 0
    total = 0
    for m in members:
        if m.name in seen:
            raise RobotArchiveError(422, f"archive member '{_shown(m.name)}': appears twice")
        seen.add(m.name)
        if not m.is_dir:
            files += 1
            total += max(0, m.size)
            if files > limits.files:
                raise RobotArchiveError(413, f"file: the archive holds more than {limits.files} files "
                                             "(max_robot_files)", limits.files)
            if total > limits.unpacked_bytes:
                raise RobotArchiveError(413, f"file: the archive unpacks to more than {limits.unpacked_bytes} "
                                             "bytes (max_robot_unpacked_bytes)", limits.unpacked_bytes)
        out.append(m)
    folders = {str(p) for m in out for p in PurePosixPath(m.name).parents if str(p) != "."}
    for m in out:
        if not m.is_dir and m.name in folders:
            raise RobotArchiveError(422, f"archive member '{_shown(m.name)}': both a file and a folder")
    if files == 0:
        raise RobotArchiveError(422, "file: the archive holds no files")
    return out


def _copy(src: IO[bytes], dst: Path, budget: list[int], limits: Limits) -> None:
    """Copy one member, counting its real bytes against what is left of the unpacked limit."""
    fd = os.open(dst, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
    with os.fdopen(fd, "wb") as out:
        while chunk := src.read(_CHUNK):
            budget[0] -= len(chunk)
            if budget[0] < 0:
                raise RobotArchiveError(413, f"file: the archive unpacks to more than {limits.unpacked_bytes} "
                                             "bytes (max_robot_unpacked_bytes)", limits.unpacked_bytes)
            out.write(chunk)



def _write_members(members: list[_Member], open_member: Callable[[_Member], Any], target: Path, budget: list[int],
                   limits: Limits, names: list[str]) -> None:
    """Write the checked ``members`` under ``target`` (folders made, files copied within the
    unpacked-size ``budget``), appending the files' names to ``names``."""
    for m in members:
        dst = target / m.name
        if m.is_dir:
            dst.mkdir(parents=True, exist_ok=True)
            continue
        dst.parent.mkdir(parents=True, exist_ok=True)
        with open_member(m) as src:
            _copy(src, dst, budget, limits)
        names.append(m.name)

def _unpack(archive: Path, target: Path, limits: Limits) -> list[str]:
    """Check every member of ``archive`` then write them under ``target`` (a new, empty folder);
    the files' names."""
    with archive.open("rb") as fh:
        head = fh.read(4)
    budget = [limits.unpacked_bytes]
    names: list[str] = []
    try:
        if head.startswith(b"PK\x03\x04") or head.startswith(b"PK\x05\x06"):
            with zipfile.ZipFile(archive) as z:
                _write_members(_checked(_zip_members(z), limits), lambda m: z.open(m.handle), target, budget, limits,
                               names)
        elif tarfile.is_tarfile(archive):
            with tarfile.open(archive, "r:*") as t:
                def open_tar(m: _Member) -> Any:
                    member = t.extractfile(m.handle)
                    if member is None:
                        raise RobotArchiveError(422, f"archive member '{_shown(m.name)}': cannot be read")
                    return member

                _write_members(_checked(_tar_members(t), limits), open_tar, target, budget, limits, names)
        else:
            raise RobotArchiveError(422, "file: not a zip or tar archive (.zip, .tar, .tar.gz, .tgz, .tar.bz2, "
                                         ".tar.xz)")
    except (zipfile.BadZipFile, tarfile.TarError, EOFError, zlib.error, lzma.LZMAError, gzip.BadGzipFile) as e:
        raise RobotArchiveError(422, f"file: the archive is damaged ({type(e).__name__})") from None
    except NotImplementedError:  # a zip compression method this Python cannot read
        raise RobotArchiveError(422, "file: the archive uses a compression method that is not supported") from None
    return names


# -- URDF listing ---------------------------------------------------------------------------------


def _urdf_info(folder: Path, name: str, files: set[str]) -> dict[str, Any] | None:
    """What a file named ``*.urdf`` holds (robot name, links, joints, meshes and which of them
    are not in the archive), or None when it is not a URDF (no ``<robot>`` root)."""
    path = folder / name
    if path.stat().st_size > MAX_URDF_BYTES:
        raise RobotArchiveError(413, f"archive member '{_shown(name)}': a URDF over {MAX_URDF_BYTES} bytes")
    text = path.read_bytes()
    if b"<!DOCTYPE" in text or b"<!ENTITY" in text:
        raise RobotArchiveError(422, f"archive member '{_shown(name)}': a URDF with a DTD or entities is not "
                                     "accepted")
    try:
        root = ET.parse(io.BytesIO(text)).getroot()
    except ET.ParseError as e:
        raise RobotArchiveError(422, f"archive member '{_shown(name)}': not well-formed XML ({e})") from None
    if root.tag != "robot":
        return None
    meshes: list[str] = []
    missing: list[str] = []
    packages: dict[str, str] = {}
    here = PurePosixPath(name).parent
    for mesh in root.iter("mesh"):
        uri = mesh.get("filename") or ""
        if not uri or uri in meshes:
            continue
        meshes.append(uri)
        found = _mesh_member(uri, here, files, packages)
        if found is None:
            missing.append(uri)
    def link_of(joint: Any, tag: str) -> str:
        e = joint.find(tag)
        return str(e.get("link", "")) if e is not None else ""

    def limit_of(joint: Any, side: str) -> float | None:
        e = joint.find("limit")
        try:
            return float(e.get(side)) if e is not None and e.get(side) is not None else None
        except ValueError:
            return None

    joints = [{"name": j.get("name", ""), "type": j.get("type", ""), "parent": link_of(j, "parent"),
               "child": link_of(j, "child"), "lower": limit_of(j, "lower"), "upper": limit_of(j, "upper")}
              for j in root.iter("joint")]
    return {"path": name, "robot": root.get("name", ""), "links": [lk.get("name", "") for lk in root.iter("link")],
            "joints": joints, "meshes": len(meshes), "missing_meshes": missing, "packages": packages}


def _mesh_member(uri: str, here: PurePosixPath, files: set[str], packages: dict[str, str]) -> str | None:
    """The archive file a mesh URI of a URDF in folder ``here`` names, or None: ``package://P/rest``
    is ``<folder>/rest`` for the folder of the archive named ``P`` (recorded in ``packages``),
    ``file://`` and absolute paths are never in the archive, other names are relative to the URDF."""
    if uri.startswith("package://"):
        pkg, _, rest = uri[len("package://"):].partition("/")
        if pkg in packages:
            cand = f"{packages[pkg]}/{rest}" if packages[pkg] else rest
            return cand if cand in files else None
        for f in sorted(files):
            if f == rest or f.endswith("/" + rest):
                base = f[: len(f) - len(rest)].rstrip("/")
                if PurePosixPath(base).name == pkg or not base:
                    packages[pkg] = base
                    return f
        for f in sorted(files):  # package folders named otherwise (e.g. the package is the archive root)
            if f.endswith("/" + rest) or f == rest:
                packages[pkg] = f[: len(f) - len(rest)].rstrip("/")
                return f
        return None
    if uri.startswith("file://") or uri.startswith("/"):
        return None
    parts: list[str] = []
    for p in (*here.parts, *uri.split("/")):
        if p == "..":
            if not parts:
                return None
            parts.pop()
        elif p not in ("", "."):
            parts.append(p)
    cand = "/".join(parts)
    return cand if cand in files else None


def _listing(folder: Path, digest: str, names: list[str]) -> dict[str, Any]:
    files = set(names)
    urdfs = []
    for n in sorted(names):
        if n.lower().endswith(".urdf"):
            info = _urdf_info(folder, n, files)
            if info is not None:
                urdfs.append({**info, "file": f"robot:{digest}/{n}"})
    if not urdfs:
        raise RobotArchiveError(422, "file: the archive holds no URDF file (a .urdf file with a <robot> root)")
    total = sum((folder / n).stat().st_size for n in names)
    return {"hash": digest, "prefix": f"robot:{digest}/", "files": len(names), "bytes": total,
            "urdf_files": urdfs}


# -- the store ------------------------------------------------------------------------------------


def sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def manifest_path(data_dir: Path, digest: str) -> Path:
    return robots_dir(data_dir) / f"{digest}.json"


def stored(data_dir: Path, digest: str) -> dict[str, Any] | None:
    """The listing of a robot uploaded before, or None."""
    if not is_digest(digest):
        return None
    try:
        data: dict[str, Any] = json.loads(manifest_path(data_dir, digest).read_text())
    except (OSError, ValueError):
        return None
    return data if (robots_dir(data_dir) / digest).is_dir() else None


def store_archive(archive: Path, data_dir: Path, limits: Limits) -> tuple[dict[str, Any], bool]:
    """Unpack and keep an uploaded archive (a file already on disk, under the size limit);
    ``(listing, created)``: ``created`` is False when the same archive was uploaded before."""
    digest = sha256_of(archive)
    known = stored(data_dir, digest)
    if known is not None:
        return known, False
    base = robots_dir(data_dir)
    base.mkdir(parents=True, exist_ok=True)
    work = base / f".incoming-{uuid.uuid4().hex}"
    work.mkdir()
    try:
        names = _unpack(archive, work, limits)
        listing = _listing(work, digest, names)
        final = base / digest
        try:
            os.rename(work, final)
        except OSError:  # the same archive, unpacked at the same time by another request
            if not final.is_dir():
                raise
        tmp = base / f".{digest}.json.{uuid.uuid4().hex}"
        tmp.write_text(json.dumps(listing, indent=1))
        os.replace(tmp, manifest_path(data_dir, digest))
        return listing, True
    finally:
        if work.exists():
            shutil.rmtree(work, ignore_errors=True)


def stored_file(data_dir: Path, digest: str, path: str) -> Path | None:
    """The file ``path`` of the robot ``digest``, or None when there is none or it would leave
    the robot's folder (symbolic links resolved)."""
    if not is_digest(digest) or not path or "\x00" in path or "\\" in path or len(path) > MAX_NAME:
        return None
    if path.startswith("/") or any(p in ("", ".", "..") for p in path.split("/")):
        return None
    root = robots_dir(data_dir) / digest
    try:
        target = (root / path).resolve(strict=True)
        inside = target.is_relative_to(root.resolve(strict=True))
    except (OSError, RuntimeError):
        return None
    return target if inside and target.is_file() else None
