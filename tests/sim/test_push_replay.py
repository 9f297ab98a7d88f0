"""The Panda's forearm push (issue 11) replayed in MuJoCo: the planned 10 cm push of the box along
the table (tests/planner/test_push.py), one continuous simulation with the plan's torques (T, 32)
on the arm, the box sliding on the table with the scene's mu. With a posture torque on the arm's
self-motion (:func:`sim.torque_replay.self_motion_torque`) the box ends within 5 % of the planned
displacement, never dropped; under pure torque control every step replayed from its planned
state is within 5 %, but in one continuous run the arm's elbow swings out of its plane and the
forearm loses the box, which is why that torque exists."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Scene
from planner import Goal, plan
from planner.plan import Plan
from planner.state import state_from_scene
from sim.plan_replay import PlanSimulationOptions, simulate_plan
from sim.step_replay import replay_plan
from sim.torque_replay import self_motion_torque

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
#: the self-motion returns to the planned posture at 50/s, above the ~12/s at which it diverges
POSTURE_RATE = 50.0


@pytest.fixture(scope="module")
def box_scene() -> Scene:
    return load_scene(EXAMPLES / "panda_forearm_box.json")


@pytest.fixture(scope="module")
def push_plan(box_scene: Scene) -> Plan:
    target = state_from_scene(box_scene).pose_vector()
    target[0] -= 0.10
    p = plan(box_scene, Goal(type="pose", pose=[float(v) for v in target], position_tolerance=0.003,
                             rotation_tolerance=0.3))
    assert p.found, p.reason
    return p


def test_self_motion_torque_moves_no_contact_and_vanishes_on_the_plan(box_scene: Scene) -> None:
    hand = HandKinematics.from_scene(box_scene)
    st = state_from_scene(box_scene, hand)
    ref = hand.resolve_body("arm/panda_link4")
    assert ref is not None
    points = [(ref, st.contacts[0].point_body)]
    rng = np.random.default_rng(5)
    q = st.q + 0.05 * rng.standard_normal(hand.M)
    gains = np.full(hand.M, 3.0)
    tau = self_motion_torque(hand, points, q, st.q, gains)
    J = hand.point_jacobian(ref, hand.point_position(ref, st.contacts[0].point_body, q), q)  # (3, M)
    # no contact force can balance it (it is orthogonal to range(J^T)) ...
    f, *_ = np.linalg.lstsq(J.T, tau, rcond=None)
    assert float(np.linalg.norm(J.T @ f)) < 1e-9 * float(np.linalg.norm(tau))
    assert float(np.linalg.norm(tau)) > 1e-3
    # ... and it is a restoring torque on the self-motion: it does positive work towards q_ref
    assert float(tau @ (st.q - q)) > 0
    np.testing.assert_allclose(self_motion_torque(hand, points, st.q, st.q, gains), 0.0, atol=1e-12)


@pytest.mark.slow
def test_push_replays_within_5_percent(box_scene: Scene, push_plan: Plan) -> None:
    assert PlanSimulationOptions().posture_rate == POSTURE_RATE  # the default: what ctp simulate does
    sim = simulate_plan(box_scene, push_plan)
    assert not sim.dropped, sim.drop_reason
    assert len(sim.steps) == len(push_plan.steps)
    err = sim.error
    assert err.relative_position <= 0.05 and err.relative_rotation <= 0.05, sim.to_json()
    assert sim.ok
    assert float(np.linalg.norm(sim.simulated[:3])) > 0.095  # the box did go the 10 cm
    # the box slid on the table: it stayed at its height and did not turn on the way
    poses = sim.object_path.poses
    np.testing.assert_allclose(poses[:, 2], push_plan.start_pose[2], atol=2e-3)
    assert float(np.max(np.abs(poses[:, 1]))) < 2e-3
    assert float(np.max(np.linalg.norm(poses[:, 3:], axis=1))) < 0.02
    for s in sim.steps:  # each motion within 5 % of its planned length
        assert float(np.linalg.norm(s.simulated)) == pytest.approx(float(np.linalg.norm(s.planned)), rel=0.05)


@pytest.mark.slow
def test_every_push_step_replays_within_5_percent_from_its_planned_state(box_scene: Scene, push_plan: Plan) -> None:
    """Step by step (each motion restarted from its planned state, pure torque control: the torques
    of T alone), every one of the motions moves the box within 5 % of its plan, along -x."""
    rep = replay_plan(box_scene, push_plan)
    assert rep.ok and not rep.dropped
    assert len(rep.steps) == len(push_plan.steps)
    for s in rep.steps:
        assert s.ok and not s.dropped, s.note
        assert s.error.relative_position <= 0.05 and s.error.relative_rotation <= 0.05
        assert s.simulated[0] < 0 and abs(float(s.simulated[1])) < 1e-4


@pytest.mark.slow
def test_pure_torque_control_loses_the_box(box_scene: Scene, push_plan: Plan) -> None:
    """The finding the posture torque answers: with the analysis' torques alone (zero on the joints
    that turn the arm out of its plane), the arm's self-motion diverges during the push and the
    forearm leaves the box before the end."""
    sim = simulate_plan(box_scene, push_plan, options=PlanSimulationOptions(posture_rate=0.0))
    assert sim.dropped or not sim.ok
    assert max(s.joint_error for s in sim.steps) > 0.5  # rad: the elbow swung away from the plan
