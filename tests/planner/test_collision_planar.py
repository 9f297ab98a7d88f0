"""Planar capsule fingers' clearances in float arithmetic (:meth:`CollisionModel._planar_min`, issue
11: planner speed) equal the numpy terms of :meth:`CollisionModel.clearance_terms` to round-off,
with every kind of term: the disk object (touching links too), the fixed segment and disk (the
base link trimmed), own non-adjacent link pairs and the links of another finger, allowances; the
sign-only checks and the floors keep their contracts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import planner.collision as collision_mod
from analysis.kinematics import BodyRef, HandKinematics
from analysis.loader import load_scene, scene_from_dict
from analysis.scene import Scene
from planner.collision import CollisionModel

ROOT = Path(__file__).resolve().parents[2]
TOL = 1e-12  # scene units; the scene is about 2 units across


def _three_link_scene() -> Scene:
    """planar_disk_envelope with three-link fingers (own non-adjacent pairs), a fixed disk about
    the origin besides the palm segment, and no contacts (the model only)."""
    data = json.loads((ROOT / "examples" / "planar_disk_envelope.json").read_text())
    for f, q in zip(data["fingers"], ([1.3, -0.9, -0.8], [1.8, 0.9, 0.8]), strict=True):
        f["links"] = [{"length": 0.6, "radius": 0.02}, {"length": 0.6, "radius": 0.0}, {"length": 0.5, "radius": 0.03}]
        f["q"] = q
    data["fixed_bodies"].append({"name": "boss", "shape": {"type": "disk", "radius": 0.15}})
    data["contacts"] = [{"body": "palm", "point": [0.0, 0.0], "normal": [0.0, 1.0], "mu": 0.5}]
    return scene_from_dict(data, geometry=False)


def _models() -> list[tuple[str, Scene, HandKinematics, CollisionModel]]:
    out = []
    scene = load_scene(ROOT / "examples" / "planar_disk_envelope.json")
    hand = HandKinematics.from_scene(scene)
    out.append(("envelope", scene, hand, CollisionModel.of(scene, hand)))
    scene = _three_link_scene()
    hand = HandKinematics.from_scene(scene)
    base = CollisionModel.of(scene, hand)
    both = frozenset({(0, 1)})  # the two fingers checked against each other
    out.append(("three-link", scene, hand, CollisionModel(scene, hand, base.min_radius, base.sample_step, both,
                                                          frozenset())))
    return out


@pytest.mark.parametrize("case", range(2))
def test_float_clearance_equals_every_term(case: int) -> None:
    name, scene, hand, model = _models()[case]
    assert all(model._planar(f) is not None for f in range(len(hand.fingers)))
    if name == "three-link":
        assert len(model._planar(0).pairs) == 1 + 9  # type: ignore[union-attr]  # (0, 2) and 3 x 3 with the other finger
    rng = np.random.default_rng(21)
    pos0 = np.asarray(scene.object.pose.position, dtype=float)
    worst, sides = 0.0, set()
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        n = hand.fingers[f].n_joints
        tip = BodyRef(f"{hand.fingers[f].name}/{n - 1}", f, n - 1)
        for k in range(120):
            q = hand.q0 + rng.normal(0.0, 0.7, hand.M)
            pos = pos0 + rng.normal(0.0, 0.1, 2)
            th = rng.normal(0.0, 0.5)
            rot = np.array([[np.cos(th), -np.sin(th), 0.0], [np.sin(th), np.cos(th), 0.0], [0.0, 0.0, 1.0]])
            touching = [tip] if k % 3 == 0 else []
            terms = model.clearance_terms(f, q, pos, rot, touching)
            allow = np.minimum(0.0, rng.normal(0.0, 0.02, terms.size)) if k % 2 else None
            want = float((terms - allow).min() if allow is not None else terms.min())
            got = model.finger_clearance(f, q, pos, rot, touching, allow)
            worst = max(worst, abs(got - want))
            sides.add(want >= 0.0)
            with pytest.MonkeyPatch.context() as m:  # the numpy path: the same minimum, bit for bit
                m.setattr(CollisionModel, "_planar", lambda self, finger: None)
                assert model.finger_clearance(f, q, pos, rot, touching, allow) == want
            for floor in (0.0, -1e-9, 0.02):
                if abs(want - floor) > TOL:
                    assert model.is_clear(f, q, pos, rot, touching, allow, floor) == (want >= floor)
            X = hand.q0[sl] + rng.normal(0.0, 0.7, (5, sl.stop - sl.start))
            exact = model.finger_clearances(f, q, X, pos, rot, allow, touching)
            qq = q.copy()
            for x, e in zip(X, exact, strict=True):
                qq[sl] = x
                t = model.clearance_terms(f, qq, pos, rot, touching)
                assert abs(e - float((t - allow).min() if allow is not None else t.min())) <= TOL
    assert worst <= TOL
    assert sides == {True, False}


@pytest.mark.parametrize("case", range(2))
def test_float_rows_keep_the_floor_contracts(case: int) -> None:
    """``clear_many`` answers ``clearance >= floor`` and ``clearances_below`` is exact below its
    floors and at least them elsewhere, evaluated in float arithmetic (few rows) and vectorised
    (many rows) alike."""
    _, scene, hand, model = _models()[case]
    rng = np.random.default_rng(4)
    pos = np.asarray(scene.object.pose.position, dtype=float)
    rot = np.eye(3)
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        for N in (3, collision_mod.PLANAR_ROWS + 6):
            X = hand.q0[sl] + rng.normal(0.0, 1.0, (N, sl.stop - sl.start))
            q = hand.q0.copy()
            exact = []
            for x in X:
                q[sl] = x
                t = model.clearance_terms(f, q, pos, rot)
                exact.append(float(t.min()))
            ex = np.array(exact)
            for floor in (0.0, -0.01, 0.03):
                got = model.clear_many(f, hand.q0, X, pos, rot, None, (), floor)
                far = np.abs(ex - floor) > TOL
                np.testing.assert_array_equal(got[far], (ex >= floor)[far])
            floors = rng.uniform(-0.1, 0.3, N)
            below = model.clearances_below(f, hand.q0, X, floors, pos, rot)
            low = ex < floors - TOL
            np.testing.assert_allclose(below[low], ex[low], rtol=0.0, atol=TOL)
            assert np.all(below[~low] >= np.minimum(floors[~low], ex[~low]) - TOL)


def test_float_path_only_for_planar_capsule_disk_scenes() -> None:
    """3-D hands and the URDF / mesh scenes keep the numpy (or coal) evaluation."""
    for name in ("sphere_four_finger_palm", "baxter_hug_box"):
        scene = load_scene(ROOT / "examples" / f"{name}.json")
        hand = HandKinematics.from_scene(scene)
        model = CollisionModel.of(scene, hand)
        assert all(model._planar(f) is None for f in range(len(hand.fingers)))
