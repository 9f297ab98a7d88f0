"""The culled minimum of :meth:`CollisionModel.finger_clearance` (capsule fingers) equals the
minimum of every term of :meth:`CollisionModel.clearance_terms` minus the allowance, bit for bit,
and it does skip blocks (issue 11: planner speed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import planner.collision as collision_mod
from analysis.kinematics import BodyRef, HandKinematics
from analysis.loader import load_scene
from planner.collision import CollisionModel

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "planar_disk_envelope"])
def test_culled_min_equals_every_term(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    scene = load_scene(ROOT / "examples" / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos = np.asarray(scene.object.pose.position, dtype=float)
    rot = np.eye(3)
    rng = np.random.default_rng(7)
    calls = {"blocks": 0}
    orig_box, orig_seg = collision_mod._shape_segments_distance, collision_mod.segment_segment_distances

    def box(*a: object) -> np.ndarray:
        calls["blocks"] += 1
        return orig_box(*a)  # type: ignore[arg-type]

    def seg(*a: object) -> np.ndarray:
        calls["blocks"] += 1
        return orig_seg(*a)  # type: ignore[arg-type]

    monkeypatch.setattr(collision_mod, "_shape_segments_distance", box)
    monkeypatch.setattr(collision_mod, "segment_segment_distances", seg)
    n_eval = 0
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        tip = BodyRef(f"{hand.fingers[f].name}/{hand.fingers[f].n_joints - 1}", f, hand.fingers[f].n_joints - 1)
        for k in range(150):
            q = hand.q0.copy()
            q[sl] += rng.normal(0.0, 0.6, sl.stop - sl.start)
            touching = [tip] if k % 3 == 0 else []
            allow = None
            if k % 2 == 0:  # an allowance as start_allowance gives one (<= 0), here random
                n_terms = model.clearance_terms(f, q, pos, rot).size
                allow = np.minimum(0.0, rng.normal(0.0, 0.01, n_terms))
            terms = model.clearance_terms(f, q, pos, rot, touching)
            want = float((terms - allow).min() if allow is not None else terms.min())
            before = calls["blocks"]
            got = model.finger_clearance(f, q, pos, rot, touching, allow)
            n_eval += calls["blocks"] - before
            assert got == want  # bit for bit
    # the object block is always evaluated (1 call each); most pair/fixed blocks are skipped
    total = 150 * len(hand.fingers)
    assert total <= n_eval < 2 * total
