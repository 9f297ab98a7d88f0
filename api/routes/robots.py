"""Your own robot over HTTP: ``POST /robots`` takes a zip or tar archive of a URDF with its meshes
and keeps it by the SHA-256 of the archive (api/robots.py); scenes then name its URDF as
``urdf.file = "robot:<sha256>/<path inside the archive>"``. ``GET /robots/{sha256}`` lists it
again, ``GET /robots/{sha256}/files/{path}`` serves its files to the browser (URDF, meshes,
textures).

The service's data folder (``data_dir``) is exported as ``CTP_DATA_DIR`` when the app is made
(:func:`router_for`), so the app's process and the workers it spawns resolve ``robot:`` paths in
the same folder (one data folder per process).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import uuid
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, File, UploadFile
from fastapi.responses import FileResponse, JSONResponse

from api.deps import SettingsDep
from api.errors import ApiError
from api.robots import Limits, RobotArchiveError, robots_dir, store_archive, stored, stored_file
from api.routes.robot_files import MEDIA_TYPES
from api.schemas import ErrorBody
from api.settings import Settings

router = APIRouter(prefix="/robots", tags=["robots"])

#: Served with every stored file: the browser treats it as data (no script runs in an uploaded
#: XML file opened directly, no type sniffing); ``fetch`` from the dashboard is unaffected.
FILE_HEADERS = {"Content-Security-Policy": "default-src 'none'; sandbox", "X-Content-Type-Options": "nosniff",
                "Cache-Control": "public, max-age=31536000, immutable"}


def router_for(settings: Settings) -> APIRouter:
    """The router, after exporting ``settings.data_dir`` as ``CTP_DATA_DIR`` (absolute) for
    ``analysis.urdf.resolve_urdf_path`` in this process and in the workers spawned after it."""
    os.environ["CTP_DATA_DIR"] = str(settings.data_dir.expanduser().resolve())
    return router


def _save_upload(src: Any, dst: Path, limit: int) -> None:
    """Copy the spooled upload to ``dst``, at most ``limit`` bytes (413 past it)."""
    seen = 0
    with dst.open("xb") as out:
        while chunk := src.read(1 << 20):
            seen += len(chunk)
            if seen > limit:
                raise RobotArchiveError(413, f"file: the archive is larger than {limit} bytes "
                                             "(max_robot_archive_bytes)", limit)
            out.write(chunk)


def _store(src: Any, settings: Settings) -> tuple[dict[str, Any], bool]:
    base = robots_dir(settings.data_dir)
    base.mkdir(parents=True, exist_ok=True)
    upload = base / f".upload-{uuid.uuid4().hex}"
    try:
        _save_upload(src, upload, settings.max_robot_archive_bytes)
        return store_archive(upload, settings.data_dir,
                             Limits(settings.max_robot_unpacked_bytes, settings.max_robot_files))
    finally:
        with contextlib.suppress(OSError):
            upload.unlink()


_UPLOAD_ERRORS: dict[int | str, dict[str, Any]] = {
    200: {"description": "the same archive was uploaded before: its listing"},
    413: {"model": ErrorBody, "description": "archive, unpacked size or file count over its limit (``limit``)"},
    422: {"model": ErrorBody, "description": "not an archive, damaged, no URDF, or a member refused (traversal "
                                             "name, absolute path, symbolic or hard link, special file)"},
    503: {"model": ErrorBody, "description": "the data folder cannot be written now (e.g. disk full)"},
}


@router.post("", status_code=201, response_model=dict[str, Any], responses=_UPLOAD_ERRORS)
async def upload_robot(file: Annotated[UploadFile, File(description="a .zip, .tar, .tar.gz/.tgz, .tar.bz2 or "
                                                                     ".tar.xz of a URDF with its meshes")],
                       settings: SettingsDep) -> Any:
    """Keep a robot: its ``hash`` (SHA-256 of the archive), the ``prefix`` scenes use
    (``robot:<hash>/``) and ``urdf_files``: each URDF's ``path`` in the archive, its ``file`` for
    a scene's ``urdf.file``, robot name, links, joints, mesh count, ``missing_meshes`` (URIs not in
    the archive) and ``packages`` (``package://`` names -> folder in the archive). 201 when new,
    200 when the same archive was uploaded before."""
    try:
        listing, created = await asyncio.to_thread(_store, file.file, settings)
    except RobotArchiveError as e:
        raise ApiError(e.status, e.reason, limit=e.limit,
                       errors=[{"loc": ["file"], "msg": e.reason, "type": "robot_archive"}]) from None
    except OSError as e:  # the data folder: full, read-only, gone (never its path in the answer)
        reason = os.strerror(e.errno) if e.errno else type(e).__name__
        raise ApiError(503, f"the robot could not be stored now ({reason}); try again later") from None
    finally:
        await file.close()
    return JSONResponse({**listing, "created": created}, status_code=201 if created else 200)


@router.get("/{digest}", response_model=dict[str, Any],
            responses={404: {"model": ErrorBody, "description": "no robot uploaded with this hash"}})
def get_robot(digest: str, settings: SettingsDep) -> Any:
    """The listing of an uploaded robot (as ``POST /robots`` answered it)."""
    listing = stored(settings.data_dir, digest)
    if listing is None:
        raise ApiError(404, f"robot '{digest[:80]}' not found (no robot uploaded with this hash)")
    return listing


@router.get("/{digest}/files/{path:path}", response_class=FileResponse,
            responses={200: {"description": "the file", "content": {t: {} for t in sorted(set(MEDIA_TYPES.values()))}},
                       404: {"model": ErrorBody, "description": "no such file in the robot, or not a robot file"}})
def get_robot_file(digest: str, path: str, settings: SettingsDep) -> FileResponse:
    """A URDF, mesh (STL, COLLADA, OBJ/MTL) or texture of an uploaded robot, by its path in the
    archive, e.g. ``panda_description/meshes/visual/link0.dae``."""
    shown = path if len(path) <= 120 else path[:117] + "..."
    media = MEDIA_TYPES.get(Path(path).suffix.lower())
    if media is None:
        raise ApiError(404, f"robot file '{shown}' not found: only robot description files are served "
                            f"({', '.join(sorted(MEDIA_TYPES))})")
    target = stored_file(settings.data_dir, digest, path)
    if target is None:
        raise ApiError(404, f"robot file '{shown}' not found in robot '{digest[:80]}'")
    return FileResponse(target, media_type=media, headers=FILE_HEADERS)

