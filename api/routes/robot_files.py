"""Robot files for the dashboard's 3-D view: the URDFs, meshes and textures of the installed
example-robot-data package, so the browser draws a scene's URDF fingers with their real visual
meshes (``urdf.file`` = ``"example-robot-data:<path>"`` is ``GET /robot-files/example-robot-data/<path>``).

Only files inside the package's ``robots`` folder are served, after resolving symbolic links, and
only robot-description suffixes (URDF, meshes, textures); anything else is a 404 JSON whose message
names the requested path only, never a folder of the server.
"""

from __future__ import annotations

import functools
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse

from api.errors import ApiError
from api.schemas import ErrorBody

router = APIRouter(prefix="/robot-files", tags=["robot files"])

#: suffix (lower case) -> media type of the files a robot description needs
MEDIA_TYPES = {
    ".urdf": "application/xml", ".xml": "application/xml",
    ".stl": "model/stl", ".dae": "model/vnd.collada+xml", ".obj": "model/obj", ".mtl": "text/plain",
    ".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".tga": "image/x-tga",
}
MAX_PATH = 512


@functools.cache
def _robots_dir() -> Path | None:
    """example-robot-data's ``robots`` folder, resolved (imported here, on first use, so the
    service process loads pinocchio only if a robot file is asked for)."""
    from analysis.urdf import example_robot_data_dir

    root = example_robot_data_dir()
    return root.resolve() if root is not None else None


def _not_found(path: str, why: str) -> ApiError:
    shown = path if len(path) <= 120 else path[:117] + "..."
    return ApiError(404, f"robot file 'example-robot-data:{shown}' not found: {why}")


@router.get("/example-robot-data/{path:path}", response_class=FileResponse,
            responses={200: {"description": "the file", "content": {t: {} for t in sorted(set(MEDIA_TYPES.values()))}},
                       404: {"model": ErrorBody, "description": "no such robot file (or not a robot file)"}})
def example_robot_data_file(path: str) -> FileResponse:
    """A URDF, mesh (STL, COLLADA, OBJ/MTL) or texture (PNG, JPEG, TGA) of example-robot-data's
    ``robots`` folder, e.g. ``allegro_hand_description/meshes/link_0.0.STL``."""
    if not path or len(path) > MAX_PATH or "\x00" in path or "\\" in path:
        raise _not_found(path[:MAX_PATH], "not a valid path")
    suffix = Path(path).suffix.lower()
    media = MEDIA_TYPES.get(suffix)
    if media is None:
        raise _not_found(path, f"only robot description files are served ({', '.join(sorted(MEDIA_TYPES))})")
    root = _robots_dir()
    if root is None:
        raise _not_found(path, "the example-robot-data package is not installed")
    if path.startswith("/") or any(part in ("", ".", "..") for part in path.split("/")):
        raise _not_found(path, "the path must stay inside the robots folder")
    try:
        target = (root / path).resolve(strict=True)
    except (OSError, RuntimeError):  # missing, or a symbolic-link loop
        raise _not_found(path, "no such file in the robots folder") from None
    if not target.is_relative_to(root):  # a symbolic link out of the folder
        raise _not_found(path, "the path must stay inside the robots folder")
    if not target.is_file() or target.suffix.lower() != suffix:  # the link's target is a robot file too
        raise _not_found(path, "no such file in the robots folder")
    return FileResponse(target, media_type=media, headers={"Cache-Control": "public, max-age=3600"})
