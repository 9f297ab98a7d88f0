"""``examples/allegro_right_box.json`` against the contact detector (issue 10).

Run from the repository root: ``.venv/bin/python examples/make_allegro_scene.py [--out FULL.json]``.

The scene (the Allegro right hand, palm up, holding a bar in a power grasp) keeps its committed
configuration and its six hand-written contacts, one per touching body at the foot of the
link's midpoint (the 400-line least-squares generator that first solved the grasp is in the git
history, commit 4662a71). What the script does now is a few lines on top of the detector
(:func:`analysis.loader.with_detected_contacts`, as ``ctp contacts``): it finds the contacts of
the same configuration from the geometry, checks that each hand-written contact lies in the
patch the detector finds on its body with the same normal and that the detector finds no other
body, and with ``--out`` writes the detected scene (patch corners instead of midpoints).
New scenes are written by ``ctp contacts --touch`` directly (``examples/allegro_cylinder.json``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import nnls

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.loader import scene_from_dict, with_detected_contacts  # noqa: E402

SCENE = ROOT / "examples" / "allegro_right_box.json"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="write the detected scene (JSON) here")
    args = ap.parse_args()
    data = json.loads(SCENE.read_text())
    given = data.pop("contacts")
    full, detection = with_detected_contacts(data)
    scene_from_dict(full)  # the detected scene passes the validation
    bad = sorted({c.body for c in detection.contacts} - {c["body"] for c in given})
    for c in given:
        mine = [k for k in detection.contacts if k.body == c["body"]]
        P = np.array([k.point for k in mine]).reshape(-1, 3)
        # distance of the hand-written point to the patch (convex hull of the detected corners)
        off = np.inf
        if mine:  # weights >= 0 summing to 1 (a heavily weighted extra row), by NNLS
            w, _ = nnls(np.vstack([P.T, 1e6 * np.ones(len(P))]), np.append(c["point"], 1e6))
            off = float(np.linalg.norm(P.T @ w - np.asarray(c["point"])))
        turn = max((float(np.linalg.norm(np.subtract(k.normal, c["normal"]))) for k in mine), default=np.inf)
        print(f"{c['body']:22s} {len(mine)} detected corner(s); hand-written point {off:.1e} from the patch, "
              f"normals differ by {turn:.1e}")
        if off > 1e-9 or turn > 1e-9:
            bad.append(c["body"])
    if args.out:
        args.out.write_text(json.dumps(full, indent=2) + "\n")
        print(f"wrote {args.out} ({len(detection.contacts)} contacts)")
    if bad:
        print(f"MISMATCH: {', '.join(bad)}")
        return 1
    print("the hand-written contacts agree with the detector")
    return 0


if __name__ == "__main__":
    sys.exit(main())
