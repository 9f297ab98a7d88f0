"""The text report of a torque replay (sim/report.py): every contact, the coordinates' names and
the verdict on the combination."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from analysis.loader import load_scene
from sim.mjcf import DEFAULT_PARAMS
from sim.report import format_report
from sim.torque_replay import simulate_torques

PLANAR = Path(__file__).parents[2] / "examples" / "planar_disk_envelope.json"


def test_report_lists_every_contact() -> None:
    scene = load_scene(PLANAR)
    params = dataclasses.replace(DEFAULT_PARAMS, ramp_time=0.002)
    r = simulate_torques(scene, np.zeros(4), duration=0.01, combination="DDDDF", params=params)
    text = format_report(r)
    for c in scene.contacts:
        assert c.body in text
    assert "dtheta" in text and "all contacts agree" in text
