"""The culled minimum of :meth:`CollisionModel.finger_clearance` (capsule fingers, evaluated with
numpy) equals the minimum of every term of :meth:`CollisionModel.clearance_terms` minus the
allowance, bit for bit, and it does skip blocks (issue 11: planner speed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import planner.collision as collision_mod
from analysis.kinematics import BodyRef, HandKinematics
from analysis.loader import load_scene
from planner.collision import CollisionModel

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def _numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests check the numpy evaluation (culled blocks, bit for bit); a planar capsule scene
    would otherwise go through the float one (:meth:`CollisionModel._planar_min`), which
    tests/planner/test_collision_planar.py compares with the terms to round-off."""
    monkeypatch.setattr(CollisionModel, "_planar", lambda self, finger: None)


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


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "planar_disk_envelope", "baxter_hug_box"])
def test_many_configurations_at_once_equal_one_at_a_time(name: str) -> None:
    """``finger_clearances`` (N configurations in one pass) is ``finger_clearance`` of each, bit for
    bit, with and without an allowance; on Baxter (fingers checked against each other, URDF
    chains) it goes one configuration at a time."""
    scene = load_scene(ROOT / "examples" / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos = np.asarray(scene.object.pose.position, dtype=float)
    rot = np.eye(3)
    rng = np.random.default_rng(11)
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        X = hand.q0[sl] + rng.normal(0.0, 0.6, (40 if name != "baxter_hug_box" else 6, sl.stop - sl.start))
        allow = np.minimum(0.0, rng.normal(0.0, 0.01, model.clearance_terms(f, hand.q0, pos, rot).size))
        for al in (None, allow):
            got = model.finger_clearances(f, hand.q0, X, pos, rot, al)
            q = hand.q0.copy()
            want = []
            for x in X:
                q[sl] = x
                want.append(model.finger_clearance(f, q, pos, rot, (), al))
            np.testing.assert_array_equal(got, np.array(want))
            if name != "baxter_hug_box":  # (its arms press on the box about q0: all in contact)
                assert np.any(got < 0.0) and np.any(got >= 0.0)  # both verdicts occur


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "sphere_four_finger_wrap"])
def test_many_configurations_cull_link_pairs_by_their_bound(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``finger_clearances`` computes a link pair's distance only where its lower bound (midpoint
    distance minus the half lengths) is below the minimum so far: curled fingers (joints 1.5 rad
    about q0) bring some own pairs close, most stay far; the answers equal ``finger_clearance``
    one configuration at a time, bit for bit, and both kinds of pair occur."""
    scene = load_scene(ROOT / "examples" / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos = np.asarray(scene.object.pose.position, dtype=float)
    rot = np.eye(3)
    rng = np.random.default_rng(3)
    rows = {"computed": 0, "all": 0}
    orig = collision_mod.segment_segment_distances

    def seg(*a: np.ndarray) -> np.ndarray:
        rows["computed"] += len(a[0])
        return orig(*a)

    monkeypatch.setattr(collision_mod, "segment_segment_distances", seg)
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        X = hand.q0[sl] + rng.normal(0.0, 1.5, (60, sl.stop - sl.start))
        got = model.finger_clearances(f, hand.q0, X, pos, rot)
        rows["all"] += 60 * len(model._finger_data(f).pairs)
        mark = rows["computed"]  # the batch's rows (not the one-at-a-time calls below)
        q = hand.q0.copy()
        want = []
        for x in X:
            q[sl] = x
            want.append(model.finger_clearance(f, q, pos, rot))
        rows["computed"] = mark  # not the one-at-a-time calls
        np.testing.assert_array_equal(got, np.array(want))
    assert 0 < rows["computed"] < 0.5 * rows["all"]


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "planar_disk_envelope", "sphere_wrap_three_link",
                                  "panda_forearm_box", "baxter_hug_box"])
def test_clearances_along_a_path_equal_one_state_at_a_time(name: str) -> None:
    """``clearances_along`` (every joint and the object moving, as along an object motion: the hand
    at random configurations about q0, the object shifted and turned) is ``finger_clearance`` of
    each state, bit for bit, with the touching links and an allowance; the three-link wrap checks
    its fingers against each other (pairs with the other fingers' links at each state), Baxter's
    URDF chains go one state at a time. Both verdicts occur (the Panda's forearm lies on the box
    and Baxter's arms press on it: overlaps everywhere)."""
    scene = load_scene(ROOT / "examples" / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    d = scene.dim
    rng = np.random.default_rng(17)
    N = 30 if name != "baxter_hug_box" else 4
    size = float(np.max(np.abs(np.asarray(scene.object.pose.position, dtype=float)))) + 1.0
    Q = hand.q0 + rng.normal(0.0, 0.4, (N, hand.M))
    P = np.asarray(scene.object.pose.position, dtype=float)[:d] + rng.normal(0.0, 0.02 * size, (N, d))
    Rs = np.array([Rotation.from_rotvec(rng.normal(0.0, 0.2, 3) * ([0, 0, 1] if d == 2 else 1)).as_matrix()
                   for _ in range(N)])
    verdicts = set()
    for f in range(len(hand.fingers)):
        n_terms = model.clearance_terms(f, hand.q0, P[0], Rs[0]).size
        allow = np.minimum(0.0, rng.normal(0.0, 0.01, n_terms))
        tip = BodyRef(f"{hand.fingers[f].name}/{hand.fingers[f].n_joints - 1}", f, hand.fingers[f].n_joints - 1)
        for touching, al in (((), None), ((tip,), allow)):
            got = model.clearances_along(f, Q, P, Rs, al, touching)
            want = [model.finger_clearance(f, Q[k], P[k], Rs[k], touching, al) for k in range(N)]
            np.testing.assert_array_equal(got, np.array(want))
            verdicts |= set((got >= 0.0).tolist())
    if name not in ("baxter_hug_box", "panda_forearm_box"):
        assert verdicts == {True, False}


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "planar_disk_envelope", "sphere_four_finger_wrap",
                                  "baxter_hug_box"])
def test_sign_only_checks_equal_the_clearance_sign(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``clear_many``, ``clear_along`` and ``is_clear`` (validity checks: blocks culled against a
    floor, not against the minimum so far) answer ``finger_clearance(...) >= floor`` exactly, with
    and without an allowance and touching links, at configurations about the start where both
    verdicts occur (floors 0, -1e-9 as object motions use, -0.01, 0.02; along a path the object
    moves too); on the capsule scenes they evaluate fewer pair and fixed-body blocks than the
    exact minimum."""
    scene = load_scene(ROOT / "examples" / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos = np.asarray(scene.object.pose.position, dtype=float)
    rot = Rotation.from_rotvec([0.0, 0.0, 0.05]).as_matrix() if scene.dim == 3 else np.eye(3)
    rng = np.random.default_rng(5)
    rows = {"n": 0}
    orig_box, orig_seg = collision_mod._shape_segments_distance, collision_mod.segment_segment_distances

    def box(*a: object, **k: object) -> np.ndarray:
        rows["n"] += len(a[1])  # type: ignore[arg-type]
        return orig_box(*a, **k)  # type: ignore[arg-type]

    def seg(*a: np.ndarray) -> np.ndarray:
        rows["n"] += len(a[0])
        return orig_seg(*a)

    monkeypatch.setattr(collision_mod, "_shape_segments_distance", box)
    monkeypatch.setattr(collision_mod, "segment_segment_distances", seg)
    verdicts = set()
    exact_rows = sign_rows = 0
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        chain = hand.fingers[f]
        tip = BodyRef(f"{chain.name}/{chain.n_joints - 1}", f, chain.n_joints - 1)
        X = hand.q0[sl] + rng.normal(0.0, 1.2, (60 if name != "baxter_hug_box" else 4, sl.stop - sl.start))
        allow = np.minimum(0.0, rng.normal(0.0, 0.01, model.clearance_terms(f, hand.q0, pos, rot).size))
        for al, touching in ((None, ()), (allow, ()), (allow, (tip,))):
            rows["n"] = 0
            want = model.finger_clearances(f, hand.q0, X, pos, rot, al, touching) >= 0.0
            exact_rows += rows["n"]
            rows["n"] = 0
            got = model.clear_many(f, hand.q0, X, pos, rot, al, touching)
            sign_rows += rows["n"]
            np.testing.assert_array_equal(got, want)
            q = hand.q0.copy()
            for x, w in zip(X, want, strict=True):
                q[sl] = x
                assert model.is_clear(f, q, pos, rot, touching, al) == bool(w)
                assert bool(w) == (model.finger_clearance(f, q, pos, rot, touching, al) >= 0.0)
            verdicts |= set(want.tolist())
            # another floor (object motions accept -1e-9), and along a path where the object moves too
            values = model.finger_clearances(f, hand.q0, X, pos, rot, al, touching)
            for floor in (-1e-9, -0.01, 0.02):
                np.testing.assert_array_equal(model.clear_many(f, hand.q0, X, pos, rot, al, touching, floor),
                                              values >= floor)
            Q = np.tile(hand.q0, (len(X), 1))
            Q[:, sl] = X
            positions = pos[None, :] + rng.normal(0.0, 0.05, (len(X), len(pos)))
            rotations = np.repeat(rot[None], len(X), axis=0)
            along = model.clearances_along(f, Q, positions, rotations, al, touching)
            for floor in (0.0, -1e-9, -0.01):
                np.testing.assert_array_equal(model.clear_along(f, Q, positions, rotations, al, touching, floor),
                                              along >= floor)
                for k in range(0, len(X), 7):
                    got_k = model.is_clear(f, Q[k], positions[k], rotations[k], touching, al, floor)
                    assert got_k == (along[k] >= floor)
    if name != "baxter_hug_box":  # (its arms press on the box about q0: all in contact)
        assert verdicts == {True, False}
        assert sign_rows < exact_rows


@pytest.mark.parametrize("name", ["sphere_four_finger_palm", "planar_disk_envelope", "sphere_four_finger_wrap"])
def test_clearances_below_floors_and_the_certificate(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``clearances_below`` is ``finger_clearances`` bit for bit where that is below the floor, and at
    least the floor elsewhere; ``path_clearance_certified``, which asks for its middle clearances
    only below the floor that decides the two halves, answers as with every value exact (the same
    verdict, smallest clearance and number of checks) on random paths of each finger."""
    scene = load_scene(ROOT / "examples" / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos = np.asarray(scene.object.pose.position, dtype=float)
    rot = np.eye(3)
    rng = np.random.default_rng(9)
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        X = hand.q0[sl] + rng.normal(0.0, 1.0, (50, sl.stop - sl.start))
        exact = model.finger_clearances(f, hand.q0, X, pos, rot)
        floors = rng.uniform(-0.1, 0.4, 50)
        got = model.clearances_below(f, hand.q0, X, floors, pos, rot)
        below = exact < floors
        assert below.any() and (~below).any()
        np.testing.assert_array_equal(got[below], exact[below])
        assert np.all(got[~below] >= floors[~below]) and np.all(got >= exact)
    results = []
    for f in range(len(hand.fingers)):
        sl = hand.finger_slice(f)
        chain = hand.fingers[f]
        tip = BodyRef(f"{chain.name}/{chain.n_joints - 1}", f, chain.n_joints - 1)
        for _ in range(6):
            path = hand.q0[sl] + np.cumsum(rng.normal(0.0, 0.15, (4, sl.stop - sl.start)), axis=0)
            path[0] = hand.q0[sl]
            results.append(collision_mod.path_clearance_certified(model, f, hand.q0, path, pos, rot, [tip], 2))
    with monkeypatch.context() as m:  # every middle clearance exact
        m.setattr(CollisionModel, "clearances_below",
                  lambda self, finger, q, X, floors, *a: self.finger_clearances(finger, q, X, *a))
        rng = np.random.default_rng(9)
        for f in range(len(hand.fingers)):  # the same random stream as above
            sl = hand.finger_slice(f)
            rng.normal(0.0, 1.0, (50, sl.stop - sl.start))
            rng.uniform(-0.1, 0.4, 50)
        k = 0
        for f in range(len(hand.fingers)):
            sl = hand.finger_slice(f)
            chain = hand.fingers[f]
            tip = BodyRef(f"{chain.name}/{chain.n_joints - 1}", f, chain.n_joints - 1)
            for _ in range(6):
                path = hand.q0[sl] + np.cumsum(rng.normal(0.0, 0.15, (4, sl.stop - sl.start)), axis=0)
                path[0] = hand.q0[sl]
                assert collision_mod.path_clearance_certified(model, f, hand.q0, path, pos, rot, [tip], 2) == results[k]
                k += 1
    assert {ok for ok, _, _ in results} == {True, False}
