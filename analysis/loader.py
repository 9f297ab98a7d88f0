"""Loading a scene (JSON or YAML) and its geometric validation.

:mod:`analysis.scene` checks a scene's structure (types, lengths, counts, names). What needs the
hand's kinematics (:mod:`analysis.kinematics`) and the shapes' signed distances
(:mod:`analysis.geometry`) is checked here, after the model, contact by contact in scene order;
the first failing check of a contact is reported and the next contact is checked:

* the normal ``n`` has unit length (within ``UNIT_TOL``);
* the body names a fixed body or a body ``"<finger>/<k>"`` (``"<finger>/<link>"`` for URDF);
* the point ``p_C`` lies on the surface of its body (a link's axis inflated by its radius, or a
  fixed body's shape) and on the object's surface, within ``GEOMETRY_TOL``;
* the normal points into the object (``p_C + 1e-3 n`` is inside it).

A finger that cannot be built (a URDF that does not load) is reported instead of every contact
check. Errors are :class:`SceneError` whose ``loc`` names the field (``contacts.2.point``) and
whose ``errors`` list every failure with pydantic's keys (``type``, ``loc``, ``msg``, ``input``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import ValidationError
from pydantic_core import InitErrorDetails

from analysis.exceptions import SceneError
from analysis.geometry import body_surface_distance, object_signed_distance
from analysis.kinematics import HandKinematics
from analysis.scene import UNIT_TOL, Scene, clean_loc, scene_error_details

#: Absolute tolerance (scene length units) for "a point lies on a surface".
GEOMETRY_TOL = 1e-4

__all__ = [
    "GEOMETRY_TOL",
    "check_geometry",
    "geometry_errors",
    "load_scene",
    "parse_scene_text",
    "scene_from_dict",
]


def _contact_errors(scene: Scene) -> list[InitErrorDetails]:
    errors: list[InitErrorDetails] = []

    def err(loc: tuple[str | int, ...], msg: str, value: Any) -> None:
        errors.append(scene_error_details(loc, msg, value))

    try:
        hand = HandKinematics.from_scene(scene)
    except SceneError as e:
        err(tuple(e.loc), e.reason, None)
        return errors
    for i, c in enumerate(scene.contacts):
        n = np.asarray(c.normal, dtype=float)
        p = np.asarray(c.point, dtype=float)
        norm = float(np.linalg.norm(n))
        if abs(norm - 1.0) > UNIT_TOL:
            err(("contacts", i, "normal"), f"must be a unit vector (norm {norm:.6g})", c.normal)
            continue
        ref = hand.resolve_body(c.body)
        if ref is None:
            err(("contacts", i, "body"), f"unknown body '{c.body}' (known: {', '.join(hand.body_names())})",
                c.body)
            continue
        dist = body_surface_distance(scene, hand, ref, p)
        if dist is not None and abs(dist) > GEOMETRY_TOL:
            err(("contacts", i, "point"), f"is {abs(dist):.4g} away from the surface of body '{c.body}'",
                c.point)
            continue
        sd = object_signed_distance(scene, p)
        if sd is not None and abs(sd) > GEOMETRY_TOL:
            err(("contacts", i, "point"), f"is {abs(sd):.4g} away from the object's surface", c.point)
            continue
        inside = object_signed_distance(scene, p + 1e-3 * n)
        if inside is not None and inside >= 0.0:
            err(("contacts", i, "normal"), "must point into the object (it points outward)", c.normal)
    return errors


def _as_errors(e: ValidationError) -> list[dict[str, Any]]:
    """pydantic's error dicts with the union tags dropped from every ``loc``."""
    return [{**err, "loc": clean_loc(tuple(err["loc"]))} for err in e.errors()]


def _first_error(errors: list[dict[str, Any]]) -> SceneError:
    first = errors[0]
    return SceneError(tuple(first["loc"]), first["msg"], errors=errors)


def geometry_errors(scene: Scene) -> list[dict[str, Any]]:
    """Every geometric error of a structurally valid scene (see the module docstring), as
    pydantic-style dicts (``type`` ``"scene"``, ``loc`` relative to the scene, ``msg``,
    ``input``); empty when the scene is valid."""
    details = _contact_errors(scene)
    if not details:
        return []
    return _as_errors(ValidationError.from_exception_data("Scene", details))


def check_geometry(scene: Scene) -> None:
    """Raise :class:`SceneError` naming the first geometric error (``errors`` lists them all)."""
    errors = geometry_errors(scene)
    if errors:
        raise _first_error(errors) from None


def scene_from_dict(data: Any) -> Scene:
    """Validate a parsed scene (the model, then :func:`check_geometry`); raise
    :class:`SceneError` naming the first bad field."""
    if isinstance(data, Scene):
        return data  # pydantic does not validate a model instance again; neither does this
    try:
        scene = Scene.model_validate(data)
    except ValidationError as e:
        raise _first_error(_as_errors(e)) from None
    check_geometry(scene)
    return scene


def parse_scene_text(text: str, suffix: str = ".json") -> Scene:
    try:
        data = yaml.safe_load(text) if suffix in (".yaml", ".yml") else json.loads(text)
    except (json.JSONDecodeError, yaml.YAMLError) as e:
        raise SceneError((), f"cannot parse {suffix.lstrip('.').upper()}: {e}") from None
    return scene_from_dict(data)


def load_scene(path: str | Path) -> Scene:
    """Load a scene from a ``.json``, ``.yaml`` or ``.yml`` file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise SceneError((), f"cannot read {path}: {e.strerror}") from None
    return parse_scene_text(text, path.suffix.lower())
