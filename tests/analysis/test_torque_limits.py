"""Joint torque limits of a hand (analysis.torque_limits): scene limits win, else URDF efforts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene, scene_from_dict
from analysis.torque_limits import hand_torque_limits, urdf_effort_limits

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_planar_scene_without_limits_has_none() -> None:
    assert hand_torque_limits(load_scene(EXAMPLES / "planar_disk_envelope.json")) is None


def test_scene_limits_are_exact() -> None:
    data = load_scene(EXAMPLES / "planar_disk_envelope.json").model_dump(mode="json", exclude_none=True)
    data["joint_torque_limits"] = [0.1, 2.5, 1e-3, 7.0]
    lim = hand_torque_limits(scene_from_dict(data))
    assert lim is not None and lim.tolist() == [0.1, 2.5, 1e-3, 7.0]  # exact, no unit change


def test_panda_urdf_effort_limits() -> None:
    pytest.importorskip("pinocchio")
    from analysis.urdf import UrdfFinger, resolve_urdf_path

    path = resolve_urdf_path("example-robot-data:panda_description/urdf/panda.urdf")
    arm = UrdfFinger("arm", path, "panda_link0", "panda_link7", np.zeros(7))
    eff = urdf_effort_limits(arm)
    assert eff is not None
    # Franka's datasheet and the URDF: 87 N m on joints 1-4, 12 N m on joints 5-7
    np.testing.assert_allclose(eff, [87, 87, 87, 87, 12, 12, 12], rtol=0, atol=1e-12)
    hand = HandKinematics(3, [arm], [])
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")  # no joint_torque_limits: URDF efforts used
    lim = hand_torque_limits(scene, hand)
    assert lim is not None
    np.testing.assert_array_equal(lim, eff)
