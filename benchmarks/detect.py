"""Speed of contact detection and placement (analysis/detect.py, analysis/placement.py; issue 10).

Run: ``.venv/bin/python benchmarks/detect.py [--repeat R]``.

Prints the machine, then, each as the best of ``--repeat`` runs in wall time and in CPU time
(user + sys of this process):

* detection on Baxter's two arms hugging the box (``examples/baxter_hug_box.json``, contacts
  removed) with the URDF's collision geometry (``"link_geometry": "urdf"``: cylinders, boxes,
  meshes as convex hulls) and with the link capsules: ``detect_contacts`` builds the hand each
  call from the cached URDF, collision and hull models (warm, as in every command after its
  first scene); the second line adds the validation of the scene's JSON;
* ``--touch`` with Baxter's four elbow and forearm links from the hug configuration moved about
  3 degrees a joint (seeded), capsules and URDF geometry;
* ``--touch`` on the Panda forearm example and the Allegro cylinder example (four fingertips).

The targets of the issue: detection on the two-arm robot with URDF collision geometry under
0.2 s; ``--touch`` with four links under 5 s.
"""

from __future__ import annotations

from machine import machine  # first: it pins the BLAS kernel before numpy loads (analysis/blas.py)

# isort: split
import argparse
import copy
import functools
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.detect import Detection, UnplacedScene, detect_contacts  # noqa: E402
from analysis.placement import Placement, placed_scene_data  # noqa: E402

BAXTER_LINKS = ["left_lower_elbow", "left_upper_forearm", "right_lower_elbow", "right_upper_forearm"]
ALLEGRO_TIPS = ["index/link_3.0_tip", "middle/link_7.0_tip", "ring/link_11.0_tip", "thumb/link_15.0_tip"]


def _cpu() -> float:
    return time.process_time()  # user + sys CPU of this process


def best(fn: Callable[[], Any], repeat: int) -> tuple[float, float, Any]:
    """Best wall and CPU seconds over ``repeat`` calls, and the last result."""
    wall, cpu, out = np.inf, np.inf, None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), _cpu()
        out = fn()
        wall, cpu = min(wall, time.perf_counter() - w0), min(cpu, _cpu() - c0)
    return wall, cpu, out


def _baxter(geometry: str, perturb: int | None = None) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((ROOT / "examples" / "baxter_hug_box.json").read_text())
    data.pop("contacts")
    for f in data["fingers"]:
        f["link_geometry"] = geometry
    if perturb is not None:
        rng = np.random.default_rng(perturb)
        for f in data["fingers"]:
            f["q"] = (np.asarray(f["q"]) + rng.normal(0.0, 0.05, len(f["q"]))).tolist()
    return data


def _detect_from_data(data: dict[str, Any]) -> Detection:
    return detect_contacts(UnplacedScene.model_validate(data))


def _place(data: dict[str, Any], touch: list[str]) -> tuple[dict[str, Any], Placement]:
    return placed_scene_data(copy.deepcopy(data), touch)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(machine())
    for geometry in ("urdf", "capsule"):
        scene = UnplacedScene.model_validate(_baxter(geometry))
        detect_contacts(scene)  # warm the URDF, collision and hull caches
        w, c, det = best(functools.partial(detect_contacts, scene), args.repeat)
        print(f"detect, Baxter two arms, {geometry} geometry: {len(det.contacts)} contacts, "
              f"{len(det.near_misses)} near misses: wall {w:.4f} s, CPU {c:.4f} s")
        w, c, det = best(functools.partial(_detect_from_data, _baxter(geometry)), args.repeat)
        print(f"  the same from the scene's JSON (validated first): wall {w:.4f} s, CPU {c:.4f} s")
    for geometry in ("capsule", "urdf"):
        for seed in (1, 2, 3):
            data = _baxter(geometry, perturb=seed)
            w, c, (_, pl) = best(functools.partial(_place, data, BAXTER_LINKS), args.repeat)
            print(f"--touch 4 links, Baxter, {geometry} geometry, seed {seed}: |dq| {pl.displacement:.3f} rad, "
                  f"{pl.iterations} SQP iterations: wall {w:.3f} s, CPU {c:.3f} s")
    for name, touch in (("panda_forearm_box", ["panda_link4"]), ("allegro_cylinder", ALLEGRO_TIPS)):
        data = json.loads((ROOT / "examples" / "unplaced" / f"{name}.json").read_text())
        w, c, (_, pl) = best(functools.partial(_place, data, touch), args.repeat)
        print(f"--touch {len(touch)} link(s), {name}: |dq| {pl.displacement:.3f} rad, {pl.iterations} SQP "
              f"iterations: wall {w:.3f} s, CPU {c:.3f} s")


if __name__ == "__main__":
    main()
