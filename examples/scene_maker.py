"""What the ``examples/make_*.py`` scripts share: writing a generated scene (or, with ``--check``,
comparing it with the committed file), the pushing finger of the rolling examples and their round object on
a table."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.loader import load_scene  # noqa: E402


def write_or_check(out: Path, build_scene: Callable[[], dict[str, Any]], description: str) -> None:
    """The script's command line: write ``build_scene()`` to ``out`` as indented JSON and load it
    back (the scene's own checks: contact points on their bodies, normals inward), or with
    ``--check`` say whether the committed file is up to date (exit 1 if not)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--check", action="store_true", help="compare with the committed scene")
    args = parser.parse_args()
    text = json.dumps(build_scene(), indent=2) + "\n"
    if args.check:
        same = out.read_text() == text
        print(f"{out.relative_to(ROOT)} is {'up to date' if same else 'OUT OF DATE'}")
        sys.exit(0 if same else 1)
    out.write_text(text)
    load_scene(out)
    print(f"wrote {out.relative_to(ROOT)}")


def pushing_finger(centre: np.ndarray, radius: float, elevation: float, base: np.ndarray,
                   last_link: float) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    """A three-joint finger (a yaw joint about z, two pitch joints about +y) standing at ``base``
    behind a round object of ``radius`` centred at ``centre`` (in its plane ``y = centre_y``),
    whose last link of length ``last_link`` points along the inward normal at the contact
    ``elevation`` above the equator and touches with its tip: ``(finger, tip, outward normal)``."""
    out = np.array([-np.cos(elevation), 0.0, np.sin(elevation)])  # outward normal at the contact
    tip = centre + radius * out
    joint2 = tip + last_link * out  # the last link points along the inward normal -out
    v1 = joint2 - base
    L1 = float(np.linalg.norm(v1))
    th1 = float(np.arctan2(v1[0], v1[2]))  # the first link's lean from the vertical towards +x
    th2 = float(np.arctan2(-out[0], -out[2]))  # the last link's
    finger = {
        "name": "f",
        "base": {"position": [float(v) for v in base], "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
        "joints": [
            {"axis": [0.0, 0.0, 1.0], "origin": [0.0, 0.0, 0.0]},
            {"axis": [0.0, 1.0, 0.0], "origin": [0.0, 0.0, 0.0]},
            {"axis": [0.0, 1.0, 0.0], "origin": [0.0, 0.0, round(L1, 12)]},
        ],
        "tip": [0.0, 0.0, last_link],
        "q": [0.0, round(th1, 12), round(th2 - th1, 12)],
    }
    return finger, tip, out


def on_table(name: str, description: str, shape: dict[str, Any], finger: dict[str, Any],
             finger_points: list[np.ndarray], out: np.ndarray, mu: float, table_points: list[list[float]],
             quat_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)) -> dict[str, Any]:
    """The rolling examples' scene: a round object (``shape``, a sphere or a cylinder lying on its
    side, turned by ``quat_wxyz``) resting on a table (a fixed box whose top face is ``z = 0``) with
    its centre at ``(0, 0, radius)``, a unit weight, the finger's last link ``f/2`` touching at
    ``finger_points`` (normal ``-out``, into the object) and the table at ``table_points``, all of
    friction ``mu``."""
    return {
        "name": name,
        "description": description,
        "dim": 3,
        "object": {"pose": {"position": [0.0, 0.0, float(shape["radius"])], "quat_wxyz": list(quat_wxyz)},
                   "shape": shape},
        "external_wrench": [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
        "fixed_bodies": [{"name": "table", "shape": {"type": "box", "size": [4.0, 3.0, 0.1],
                                                     "position": [0.0, 0.0, -0.05]}}],
        "fingers": [finger],
        "contacts": [
            *({"body": "f/2", "point": [float(v) for v in np.round(c, 12)],
               "normal": [float(v) for v in np.round(-out, 12)], "mu": mu} for c in finger_points),
            *({"body": "table", "point": t, "normal": [0.0, 0.0, 1.0], "mu": mu} for t in table_points),
        ],
    }
