"""Placing the robot on the object (analysis.placement, ``ctp contacts --touch``, issue 10): on the
Franka Panda and on Baxter's two arms the named links end on the object, nothing penetrates,
the joint limits hold; distances checked with an independent formula (the box's signed distance
along each link axis, minimised exactly as it is convex along a segment); bad input."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from analysis.detect import UnplacedScene
from analysis.exceptions import SceneError
from analysis.geometry import box_signed_distance
from analysis.kinematics import HandKinematics, segment_distance
from analysis.loader import GEOMETRY_TOL, load_scene, with_detected_contacts
from analysis.placement import TOUCH_TOL, place_touching, placed_scene_data
from analysis.scene import Box, Scene
from ctp.cli import app

ROOT = Path(__file__).resolve().parents[2]
PANDA_SOURCE = ROOT / "examples" / "unplaced" / "panda_forearm_box.json"
BAXTER = ROOT / "examples" / "baxter_hug_box.json"
BAXTER_LINKS = ["left_lower_elbow", "left_upper_forearm", "right_lower_elbow", "right_upper_forearm"]


def _raw(path: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads(path.read_text())
    data.pop("contacts", None)
    return data


def _box_capsule_distance(box_lo: np.ndarray, box_hi: np.ndarray, a: np.ndarray, b: np.ndarray,
                          radius: float) -> float:
    """Signed distance of the capsule ``[a, b]`` (radius) to the axis-aligned box ``[lo, hi]``:
    the box's signed distance is convex along the axis, so a golden-section search finds its
    minimum (to 1e-12 in the parameter)."""
    c, h = (box_lo + box_hi) / 2, (box_hi - box_lo) / 2

    def f(t: float) -> float:
        return float(box_signed_distance(a + t * (b - a), c, h))

    lo, hi, g = 0.0, 1.0, (np.sqrt(5.0) - 1.0) / 2.0
    while hi - lo > 1e-12:
        x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
        if f(x1) <= f(x2):
            hi = x2
        else:
            lo = x1
    return min(f(0.0), f(1.0), f((lo + hi) / 2)) - radius


def _box_bounds(scene: Scene, shape: Box, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    half = np.asarray(shape.size, dtype=float) / 2
    return centre - half, centre + half


def _check_placed(data: dict[str, Any], touch: list[str], q_scene: np.ndarray) -> None:
    """Named links at distance 0 (TOUCH_TOL) of the object, no link into the object or the table
    deeper than TOUCH_TOL, every joint inside its URDF limits, all by the independent formula."""
    scene = UnplacedScene.model_validate(data)
    assert scene.object.pose.quat_wxyz == [1.0, 0.0, 0.0, 0.0]
    hand = HandKinematics.from_scene(scene)
    assert isinstance(scene.object.shape, Box)
    boxes = {"object": _box_bounds(scene, scene.object.shape, np.asarray(scene.object.pose.position))}
    for fb in scene.fixed_bodies:
        assert isinstance(fb.shape, Box) and fb.shape.position is not None
        boxes[fb.name] = _box_bounds(scene, fb.shape, np.asarray(fb.shape.position))
    names = set(touch)
    touched = set()
    for f in hand.fingers:
        lower, upper = f.lower, f.upper  # type: ignore[attr-defined]
        assert np.all(f.q0 >= lower) and np.all(f.q0 <= upper), f.name
        for label in f.body_names():
            ref = hand.resolve_body(label)
            assert ref is not None
            a, b = hand.body_segment(ref, hand.q0)
            for target, (lo, hi) in boxes.items():
                d = _box_capsule_distance(lo, hi, a, b, hand.body_radius(ref))
                assert d >= -TOUCH_TOL, (label, target, d)
                if target == "object" and (label in names or label.split("/", 1)[1] in names):
                    assert abs(d) <= TOUCH_TOL, (label, d)
                    touched.add(label)
    assert len(touched) == len(touch)
    assert not np.allclose(hand.q0, q_scene)  # the configuration did move


def test_panda_forearm_placed_on_the_box() -> None:
    data = _raw(PANDA_SOURCE)
    q_scene = np.asarray(data["fingers"][0]["q"], dtype=float)
    placed, placement = placed_scene_data(data, ["panda_link4"])
    _check_placed(placed, ["panda_link4"], q_scene)
    assert placement.touch[0][0] == "arm/panda_link4"
    assert placement.displacement == pytest.approx(float(np.linalg.norm(placement.q - q_scene)), abs=1e-12)
    assert placement.displacement < 0.1  # measured: 0.018 rad


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_baxter_four_links_placed_on_the_box_sides(seed: int) -> None:
    # the hug configuration perturbed by about 3 degrees a joint: elbows and forearms back on the box
    data = _raw(BAXTER)
    rng = np.random.default_rng(seed)
    for f in data["fingers"]:
        f["q"] = (np.asarray(f["q"]) + rng.normal(0.0, 0.05, len(f["q"]))).tolist()
    q_scene = np.concatenate([f["q"] for f in data["fingers"]])
    placed, _ = placed_scene_data(data, BAXTER_LINKS)
    _check_placed(placed, BAXTER_LINKS, q_scene)
    _, detection = with_detected_contacts(placed)
    bodies = {c.body for c in detection.contacts}
    assert {f"{s}/{s}_{k}" for s in ("left", "right") for k in ("lower_elbow", "upper_forearm")} <= bodies
    assert all(abs(c.gap) <= GEOMETRY_TOL for c in detection.contacts)


def test_a_scene_already_touching_stays_put() -> None:
    scene = load_scene(BAXTER)
    data = scene.model_dump(exclude={"contacts"})
    _, placement = placed_scene_data(data, BAXTER_LINKS)
    assert placement.displacement < 1e-6


def test_panda_example_is_what_ctp_contacts_touch_writes(tmp_path: Path) -> None:
    out = tmp_path / "panda.json"
    r = CliRunner().invoke(app, ["contacts", str(PANDA_SOURCE), "--touch", "panda_link4", "--out", str(out)])
    assert r.exit_code == 0, r.output
    written = json.loads(out.read_text())
    bundled = json.loads((ROOT / "examples" / "panda_forearm_box.json").read_text())
    assert "ctp contacts examples/unplaced/panda_forearm_box.json --touch panda_link4" in bundled["description"]
    np.testing.assert_allclose(written["fingers"][0]["q"], bundled["fingers"][0]["q"], atol=1e-9)
    assert [c["body"] for c in written["contacts"]] == [c["body"] for c in bundled["contacts"]]
    for c, k in zip(written["contacts"], bundled["contacts"], strict=True):
        np.testing.assert_allclose(c["point"], k["point"], atol=1e-8)
        np.testing.assert_allclose(c["normal"], k["normal"], atol=1e-8)
    assert [c["body"] for c in bundled["contacts"]] == ["arm/panda_link4"] + ["table"] * 4


def test_unknown_link_lists_the_valid_ones() -> None:
    data = _raw(PANDA_SOURCE)
    with pytest.raises(SceneError) as e:
        placed_scene_data(data, ["panda_link9"])
    assert e.value.loc == ("touch",)
    assert "'panda_link9' is not a finger link" in str(e.value) and "arm/panda_link4" in str(e.value)
    with pytest.raises(SceneError, match="fixed body"):
        placed_scene_data(data, ["table"])
    two = _raw(BAXTER)
    two["fingers"][1] = copy.deepcopy(two["fingers"][0]) | {"name": "other"}
    with pytest.raises(SceneError, match="ambiguous"):
        placed_scene_data(two, ["left_lower_elbow"])


def test_cli_touch_bad_input_exits_2(tmp_path: Path) -> None:
    r = CliRunner().invoke(app, ["contacts", str(PANDA_SOURCE), "--touch", "elbow"])
    assert r.exit_code == 2
    assert "touch" in r.output and "arm/panda_link4" in r.output and "Traceback" not in r.output
    # a link that cannot reach the object: the box moved out of the arm's reach
    data = _raw(PANDA_SOURCE)
    data["object"]["pose"]["position"] = [3.0, 0.0, 0.13]
    data["fixed_bodies"][0]["shape"]["size"] = [8.0, 8.0, 0.04]
    far = tmp_path / "far.json"
    far.write_text(json.dumps(data))
    r = CliRunner().invoke(app, ["contacts", str(far), "--touch", "panda_link4"])
    assert r.exit_code == 2
    assert "no configuration within the joint limits" in r.output and "panda_link4" in r.output
    # without --touch: the object on the wide table touches it only; a box in the air touches nothing
    data["object"]["pose"]["position"] = [3.0, 0.0, 0.5]
    far.write_text(json.dumps(data))
    r = CliRunner().invoke(app, ["contacts", str(far)])
    assert r.exit_code == 2 and "touches nothing" in r.output and "nearest body is 'table'" in r.output
    # the scene as given: the forearm is 5.6 mm into the box (--touch moves it out)
    r = CliRunner().invoke(app, ["contacts", str(PANDA_SOURCE)])
    assert r.exit_code == 2 and "'arm/panda_link4' penetrates the object" in r.output


def test_place_touching_refuses_a_scene_outside_its_joint_limits() -> None:
    data = _raw(PANDA_SOURCE)
    data["fingers"][0]["q"][3] = 0.5  # joint 4's upper limit is -0.0698
    with pytest.raises(SceneError, match="outside its joint limits"):
        place_touching(UnplacedScene.model_validate(data), ["panda_link4"])


def test_planar_fingertips_placed_on_the_disk() -> None:
    # the planar example with its contacts removed and every joint turned by 0.05 rad: the distal
    # links placed back on the disk; distances by the segment-to-centre formula
    data = _raw(ROOT / "examples" / "planar_disk_envelope.json")
    for f in data["fingers"]:
        f["q"] = [v + 0.05 for v in f["q"]]
    names = ["left/1", "right/1"]
    placed, placement = placed_scene_data(data, names)
    scene = UnplacedScene.model_validate(placed)
    hand = HandKinematics.from_scene(scene)
    centre = np.asarray(scene.object.pose.position, dtype=float)
    radius = scene.object.shape.radius  # type: ignore[union-attr]
    for label in hand.body_names():
        ref = hand.resolve_body(label)
        if ref is None or ref.finger is None:
            continue
        a, b = hand.body_segment(ref, hand.q0)
        d = segment_distance(centre, np.asarray(a), np.asarray(b)) - radius - hand.body_radius(ref)
        assert d >= -TOUCH_TOL, label
        if label in names:
            assert abs(d) <= TOUCH_TOL, (label, d)
    assert {n for n, _ in placement.touch} == set(names)
    _, detection = with_detected_contacts(placed)
    assert set(names) <= {c.body for c in detection.contacts}


def test_baxter_touch_example_is_what_ctp_contacts_touch_writes(tmp_path: Path) -> None:
    """The two-arm example written by the command in its description, from a scene without
    contacts whose arms start off the box: the same q and contacts come out, elbows and
    forearms on the box's sides and the table's four corners."""
    bundled = json.loads((ROOT / "examples" / "baxter_hug_box_touch.json").read_text())
    command = bundled["description"].split("Written by: ")[1].split()
    assert command[:2] == ["ctp", "contacts"]
    out = tmp_path / "baxter.json"
    args = [a if a != "examples/baxter_hug_box_touch.json" else str(out) for a in command[1:]]
    args = [str(ROOT / a) if a.startswith("examples/") else a for a in args]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    written = json.loads(out.read_text())
    for f, g in zip(written["fingers"], bundled["fingers"], strict=True):
        np.testing.assert_allclose(f["q"], g["q"], atol=1e-9)
    assert [c["body"] for c in written["contacts"]] == [c["body"] for c in bundled["contacts"]]
    for c, k in zip(written["contacts"], bundled["contacts"], strict=True):
        np.testing.assert_allclose(c["point"], k["point"], atol=1e-8)
        np.testing.assert_allclose(c["normal"], k["normal"], atol=1e-8)
    bodies = {c["body"] for c in bundled["contacts"]}
    assert {f"{s}/{s}_{k}" for s in ("left", "right") for k in ("lower_elbow", "upper_forearm")} <= bodies
    assert sum(c["body"] == "table" for c in bundled["contacts"]) == 4
    unplaced = json.loads((ROOT / "examples" / "unplaced" / "baxter_hug_box.json").read_text())
    assert "contacts" not in unplaced
    assert not np.allclose(unplaced["fingers"][0]["q"], bundled["fingers"][0]["q"])  # the arms were moved
