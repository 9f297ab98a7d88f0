"""MuJoCo replay of the planar plan: the object ends within 5 % of the planned displacement and is
never dropped; every regrasp step holds the object still. Step by step (``replay_plan``) and as one
continuous simulation (``simulate_plan``, ``ctp simulate PLAN.json``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.pose import Pose
from analysis.scene import Scene
from ctp.cli import app
from planner.plan import Plan
from sim.final_grasp import final_holding_torque
from sim.plan_replay import simulate_plan
from sim.step_replay import replay_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_planar_plan_replays_in_mujoco(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    r = replay_plan(planar_scene, planar_plan)
    assert not r.dropped
    assert all(s.ok for s in r.steps), [s.note for s in r.steps if not s.ok]
    assert float(np.linalg.norm(r.planned)) > 0.0
    assert r.relative_error <= 0.05
    lift = [s for s in r.steps if s.kind == "object_motion"]
    assert lift and all(s.simulated[1] > 0 for s in lift)  # the object really rises off the palm


# --------------------------------------------------------------------------------------------
# Continuous replay of the whole plan (sim.plan_replay): one simulation, never reset


@pytest.fixture(scope="module")
def planar_continuous(planar_scene: Scene, planar_plan):  # type: ignore[no-untyped-def]
    return simulate_plan(planar_scene, planar_plan)


def test_planar_plan_continuous_replay_meets_the_plan(planar_scene: Scene, planar_plan, planar_continuous) -> None:  # type: ignore[no-untyped-def]
    r = planar_continuous
    s = object_size(planar_scene)
    assert not r.dropped, r.drop_reason
    assert [st.kind for st in r.steps] == [st.transition.kind for st in planar_plan.steps]
    np.testing.assert_allclose(r.planned, planar_plan.displacement, atol=1e-9)
    assert float(np.linalg.norm(r.planned)) > 0.0
    assert r.relative_error <= 0.05, (r.simulated, r.planned)
    # the final pose is within 5 % of the planned displacement of the planned final pose
    err = float(np.linalg.norm(r.simulated_final_pose - planar_plan.final_pose))
    assert err <= 0.05 * float(np.linalg.norm(planar_plan.displacement))
    # the object stays still while fingers let go and make contact (well under 1 % of its size)
    assert r.max_regrasp_deviation <= 2e-3 * s
    # the fingers moved kinematically along their paths, unobstructed (rad, per 0.2 ms step)
    assert 0.0 <= r.tracking_error <= 1e-4
    driven = [st for st in r.steps if st.kind != "object_motion"]
    assert [st.driven_finger for st in driven] == ["left", "left", "right", "right"]
    # the object motion lifts the disk off the palm by the planned amount
    lift = r.steps[-1]
    assert lift.kind == "object_motion" and lift.simulated[1] > 0.95 * lift.planned[1] > 0.0
    assert r.ok


def test_continuous_replay_records_the_object_path(planar_scene: Scene, planar_plan, planar_continuous) -> None:  # type: ignore[no-untyped-def]
    """The sampled object path: from the start pose to the simulated final pose, a sample every
    ``path_interval`` of simulated time, each step's samples making up its ``simulated``
    displacement and staying within the deviation the monitor measured at every MuJoCo step."""
    from sim.plan_paths import path_deviation
    from sim.plan_replay import DEFAULT_OPTIONS

    r = planar_continuous
    path = r.object_path
    T = len(path.times)
    assert path.poses.shape == (T, 3) and path.steps.shape == (T,)
    assert path.interval == DEFAULT_OPTIONS.path_interval == 0.005
    np.testing.assert_allclose(path.poses[0], planar_plan.start_pose, atol=1e-6)
    np.testing.assert_array_equal(path.poses[-1], r.simulated_final_pose)
    assert path.times[0] == 0.0 and path.times[-1] == pytest.approx(r.duration, abs=1e-12)
    gaps = np.diff(path.times)
    assert np.all(gaps >= 0.0) and float(np.max(gaps)) <= path.interval + 2.5e-4  # one 0.2 ms MuJoCo step late at most
    assert r.duration / path.interval <= T  # sampled all along, not only at the step ends
    assert list(np.unique(path.steps)) == [-1, *[st.index for st in r.steps]]
    assert np.all(np.diff(path.steps) >= 0)  # in step order
    s = object_size(planar_scene)
    for st, pst in zip(r.steps, planar_plan.steps, strict=True):
        seg = path.of_step(st.index)  # (k + 1, 3): the pose before the step, then its samples
        assert len(seg) >= 2
        np.testing.assert_allclose(seg[-1] - seg[0], st.simulated, atol=1e-12)
        planned_path = pst.transition.object_path
        devs = [path_deviation(Pose.from_vector(p, 2), planned_path, s) for p in seg[1:]]
        assert max(devs) <= st.max_deviation + 1e-12
    # the object motion's samples move along the lift: the height rises overall, the path is no jump
    lift = path.of_step(r.steps[-1].index)
    assert lift[-1, 1] - lift[0, 1] > 0.9 * r.steps[-1].planned[1] > 0.0
    assert float(np.max(np.abs(np.diff(lift[:, 1])))) < 0.2 * float(r.steps[-1].planned[1])
    data = r.to_json()["object_path"]
    assert len(data["times"]) == T and data["steps"] == [int(k) for k in path.steps]
    np.testing.assert_allclose(np.array(data["poses"]), path.poses, atol=0.0)


def test_path_interval_must_be_positive() -> None:
    from sim.plan_replay import PlanSimulationOptions

    with pytest.raises(ValueError, match="path_interval"):
        PlanSimulationOptions(path_interval=0.0)


def test_ctp_simulate_replays_a_plan_file(tmp_path, planar_continuous) -> None:  # type: ignore[no-untyped-def]
    plan_file, rep_file = tmp_path / "plan.json", tmp_path / "replay.json"
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "active",
                                 "--out", str(plan_file)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(app, ["simulate", str(plan_file), "--json", str(rep_file)])
    assert r.exit_code == 0, r.output
    assert "final pose simulated" in r.output and "dropped: no" in r.output
    # the replay states its model of the hand: holds with the servo, object motions without
    assert "control: holds: the planned holding torque (18) and a joint servo" in r.output
    assert "object motions: the plan's torque (32)" in r.output and "no servo" in r.output
    rep = json.loads(rep_file.read_text())
    assert rep["control"].startswith("holds:") and 0.0 < rep["hold_servo_share"] < 0.05
    assert not rep["dropped"] and rep["ok"] and rep["relative_error"] <= 0.05
    assert len(rep["steps"]) == len(planar_continuous.steps)
    # the file (rounded to 1e-10) replays like the in-memory plan
    np.testing.assert_allclose(rep["simulated_final_pose"], planar_continuous.simulated_final_pose, atol=1e-6)
    # --scene instead of the file's own scene entry
    data = json.loads(plan_file.read_text())
    del data["scene"]
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(data))
    r = CliRunner().invoke(app, ["simulate", str(bare), "--scene", str(EXAMPLES / "planar_disk_envelope.json")])
    assert r.exit_code == 0, r.output


def _plan_dict(tmp_path: Path) -> dict:  # type: ignore[type-arg]
    out = tmp_path / "plan.json"
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "active",
                                 "--out", str(out)])
    assert r.exit_code == 0, r.output
    data: dict = json.loads(out.read_text())  # type: ignore[type-arg]
    return data


@pytest.mark.parametrize(
    ("case", "field"),
    [
        ("not_a_plan", "object"),  # a JSON object without "steps" is read as a scene: it has no object
        ("not_found", "found"),
        ("no_scene", "scene"),
        ("bad_scene", "scene.object"),
        ("steps_not_list", "steps"),
        ("short_joint_path", "steps.1.joint_path"),
        ("bad_kind", "steps.0.kind"),
        ("bad_torque", "steps.4.torques.chosen"),
        ("bad_final_torque", "final_holding_torque"),
    ],
)
def test_ctp_simulate_bad_plan_files_exit_2(tmp_path, case: str, field: str) -> None:  # type: ignore[no-untyped-def]
    data = _plan_dict(tmp_path)
    if case == "not_a_plan":
        data = {"dim": 2}
    elif case == "not_found":
        data.update(found=False, steps=[], reason="time limit")
    elif case == "no_scene":
        del data["scene"]
    elif case == "bad_scene":
        data["scene"]["object"] = 3
    elif case == "steps_not_list":
        data["steps"] = 3
    elif case == "short_joint_path":
        data["steps"][1]["joint_path"] = [row[:3] for row in data["steps"][1]["joint_path"]]
    elif case == "bad_kind":
        data["steps"][0]["kind"] = "teleport"
    elif case == "bad_torque":
        data["steps"][4]["torques"]["chosen"] = [1.0, 2.0]
    elif case == "bad_final_torque":
        data["final_holding_torque"] = [0.0, float("nan")]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    r = CliRunner().invoke(app, ["simulate", str(bad)])
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output
    assert field in r.output, r.output


def test_ctp_simulate_missing_plan_file_exits_2(tmp_path) -> None:  # type: ignore[no-untyped-def]
    r = CliRunner().invoke(app, ["simulate", str(tmp_path / "nowhere.json")])
    assert r.exit_code == 2 and "cannot read" in r.output


def test_final_holding_torque_rebuilt_from_the_file_equals_the_planners(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    """For plan files without ``final_holding_torque`` the final grasp is rebuilt from the file
    (points, bodies, object-surface normals): its tau_st (18) is the planner's."""
    hand = HandKinematics.from_scene(planar_scene)
    steps = Plan.from_json(planar_plan.to_json(), planar_scene, hand).steps
    rebuilt = final_holding_torque(planar_scene, hand, steps[-1])
    assert planar_plan.final_tau is not None and rebuilt is not None
    np.testing.assert_allclose(rebuilt, planar_plan.final_tau, atol=1e-8)


# --------------------------------------------------------------------------------------------
# The outcome: position and rotation errors apart, with units; off tolerance exits 3


def test_pose_error_keeps_metres_and_radians_apart() -> None:
    from sim.plan_replay import PoseError

    start = Pose.from_vector([0.0, 0.5, 0.0], 2)
    planned = Pose.from_vector([0.0, 0.52, 0.0], 2)  # a 2 cm lift, no rotation
    sim = Pose.from_vector([0.001, 0.52, 0.002], 2)  # 1 mm aside, turned by 2 mrad
    e = PoseError.of(start, planned, sim, size=0.5)
    assert e.position == pytest.approx(0.001) and e.rotation == pytest.approx(0.002)
    assert e.planned_translation == pytest.approx(0.02) and e.planned_rotation == pytest.approx(0.0)
    assert e.relative_position == pytest.approx(0.05)  # of the 2 cm planned
    assert e.relative_rotation == pytest.approx(0.002 / (0.02 / 0.5))  # of the turn that moves the surface 2 cm
    turn = PoseError.of(start, Pose.from_vector([0.0, 0.5, 0.3], 2), Pose.from_vector([0.0, 0.5, 0.33], 2), 0.5)
    assert turn.rotation == pytest.approx(0.03) and turn.relative_rotation == pytest.approx(0.1)
    assert turn.position == 0.0 and turn.relative_position == 0.0
    text = e.describe(0.05)
    assert "position error 0.001 m" in text and "rotation error 0.002 rad" in text


def test_planar_continuous_replay_reports_both_errors(planar_scene: Scene, planar_continuous) -> None:  # type: ignore[no-untyped-def]
    r = planar_continuous
    data = r.to_json()
    pos = float(np.linalg.norm(r.simulated_final_pose[:2] - r.planned_final_pose[:2]))
    rot = abs(float(r.simulated_final_pose[2] - r.planned_final_pose[2]))
    assert data["position_error"] == pytest.approx(pos, abs=1e-12)
    assert data["rotation_error"] == pytest.approx(rot, abs=1e-9)
    assert data["relative_position_error"] <= 0.05 and data["relative_rotation_error"] <= 0.05
    assert data["relative_error"] == max(data["relative_position_error"], data["relative_rotation_error"])
    assert "final_pose_error" not in data  # the older figure that added metres to radians


def test_ctp_simulate_off_tolerance_exits_3(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A replay that ends 20 % short of the plan's lift: 'NOT within tolerance', exit code 3, the
    position error in metres and the rotation error in radians."""
    data = _plan_dict(tmp_path)
    lift = data["final_pose"][1] - data["start_pose"][1]
    assert lift > 0.0
    data["final_pose"][1] += 0.2 * lift  # the file claims a 20 % higher lift than its steps make
    bad = tmp_path / "claims_more.json"
    bad.write_text(json.dumps(data))
    out = tmp_path / "replay.json"
    r = CliRunner().invoke(app, ["simulate", str(bad), "--json", str(out)])
    assert r.exit_code == 3, r.output
    assert "NOT within tolerance" in r.output and "dropped: no" in r.output
    assert " m (" in r.output and " rad (" in r.output, r.output
    rep = json.loads(out.read_text())
    assert not rep["ok"] and not rep["dropped"]
    assert rep["relative_position_error"] > 0.1 and rep["relative_rotation_error"] <= 0.05
    assert rep["position_error"] == pytest.approx(0.2 * lift, rel=0.3)


def test_step_and_total_displacements_are_the_turn_not_the_pose_vectors_difference() -> None:
    """The replay's planned and simulated displacements (per step and in total, printed by ``ctp
    simulate``) are ``Pose.displacement_from``'s: a cylinder that starts turned -90 degrees about x
    and rolls 0.1 rad about +y has the displacement ``(dp, 0, 0.1, 0)``; 2-D angles are not wrapped."""
    from sim.plan_replay import _displacement

    start = Pose.from_vector([0.0, 0.0, 0.5, -np.pi / 2, 0.0, 0.0], 3)
    s = np.array([0.05, 0.0, 0.0, 0.0, 0.1, 0.0])
    np.testing.assert_allclose(_displacement(start.vector(), start.displaced(s).vector()), s, atol=1e-12)
    np.testing.assert_allclose(_displacement(np.array([0.0, 0.0, 3.0]), np.array([0.1, 0.0, -3.0])),
                               [0.1, 0.0, -6.0], atol=1e-15)
