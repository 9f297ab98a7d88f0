"""The replay's model of the hand (sim/mjcf.py, sim/plan_replay.py): the fingers' damping lowered
for fast joints, ``phi`` read off a plan's object motions, the hold servo and the stated control.

Known answers: ``b_q = 0.04 b_r s^2 / max(1, (s phi)^2)``, so the power the fingers' damping takes
at the joint speed ``phi`` per unit object speed is at most 4 % of the object's (equal at
``s phi >= 1``, less below), the masses unchanged; a path's ``phi`` is its joint path length over
its object path length; a planar plan (two-joint fingers, ``s phi < 1``) is replayed with the
damping as before.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.geometry import object_size
from analysis.loader import load_scene
from sim.mjcf import DEFAULT_PARAMS, build_model, damping, finger_dof_addresses, joint_speed_factor
from sim.plan_paths import joint_speed_ratio
from sim.plan_replay import PlanSimulationOptions

EXAMPLES = Path(__file__).parents[2] / "examples"
SPHERE = EXAMPLES / "sphere_four_finger_palm.json"


@pytest.mark.parametrize("phi", [None, 0.5, 2.0, 3.0, 6.3, 40.0])
def test_finger_damping_takes_at_most_4_percent_of_the_power(phi: float | None) -> None:
    scene = load_scene(SPHERE)
    s = object_size(scene)
    tau = np.linspace(-1.0, 2.0, 16)
    base, d = damping(scene, tau), damping(scene, tau, DEFAULT_PARAMS, phi)
    assert d.object_damping == base.object_damping and d.force_scale == base.force_scale
    expected = base.finger_damping / max(1.0, (s * (phi or 0.0)) ** 2)
    assert d.finger_damping == pytest.approx(expected, rel=1e-12)
    assert d.finger_damping == pytest.approx(base.finger_damping / joint_speed_factor(s, phi), rel=1e-12)
    if phi is not None:  # power ratio b_q phi^2 / b_r at unit object speed
        assert d.finger_damping * phi**2 / d.object_damping <= DEFAULT_PARAMS.finger_damping_rel * (1 + 1e-12)
    # the fingers' masses stay those of the nominal damping; the MuJoCo model carries the damping
    assert d.link_mass == base.link_mass and d.finger_armature == base.finger_armature
    model = build_model(scene, DEFAULT_PARAMS, tau, phi)
    np.testing.assert_allclose(model.dof_damping[finger_dof_addresses(model, scene)], d.finger_damping, rtol=1e-12)


def test_joint_speed_ratio_is_joint_over_object_path_length() -> None:
    rng = np.random.default_rng(3)
    dr = rng.standard_normal(6)
    dq = rng.standard_normal(16)
    u = np.linspace(0.0, 0.02, 11)[:, None]
    q_path, obj = 0.3 + u * dq, 1.0 + u * dr
    assert joint_speed_ratio(q_path, obj) == pytest.approx(np.linalg.norm(dq) / np.linalg.norm(dr), rel=1e-12)
    assert joint_speed_ratio(q_path, np.repeat(obj[:1], 11, axis=0)) is None


def test_planar_plan_keeps_its_damping(planar_scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    """The planar lift turns the joints slower than ``1/s`` per unit object motion, so the
    replay's damping is the one it always had, and the replay says nothing of it."""
    motions = [s.transition for s in planar_plan.steps if s.transition.kind == "object_motion"]
    assert motions
    for t in motions:
        phi = joint_speed_ratio(t.q_path, t.object_path)
        assert phi is not None and object_size(planar_scene) * phi < 1.0
        assert joint_speed_factor(object_size(planar_scene), phi) == 1.0


def test_hold_rate_must_be_a_rate() -> None:
    with pytest.raises(ValueError, match="hold_rate"):
        PlanSimulationOptions(hold_rate=-1.0)
    with pytest.raises(ValueError, match="hold_rate"):
        PlanSimulationOptions(hold_rate=float("inf"))


def test_simulate_torques_checks_its_hold_rate() -> None:
    from analysis.exceptions import SceneError
    from sim.torque_replay import simulate_torques

    scene = load_scene(SPHERE)
    with pytest.raises(SceneError, match="hold_rate"):
        simulate_torques(scene, np.zeros(16), duration=0.01, hold_rate=-1.0)
