"""``ctp plan``."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from analysis.loader import load_scene, scene_from_dict
from ctp.cli import app

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_ctp_plan_writes_json(tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "plan.json"
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "active",
                                 "--out", str(out)])
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    assert data["found"] and data["steps"][-1]["kind"] == "object_motion"
    # the scene it was planned from, so that 'ctp simulate plan.json' can replay it
    assert scene_from_dict(data["scene"]) == load_scene(EXAMPLES / "planar_disk_envelope.json")


def test_ctp_plan_replay_writes_the_continuous_replay(tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "plan.json"
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "active",
                                 "--out", str(out), "--replay"])
    assert r.exit_code == 0, r.output
    rep = json.loads(out.read_text())["replay"]
    assert rep["ok"] and not rep["dropped"] and rep["relative_error"] <= 0.05
    assert len(rep["simulated"]) == len(rep["planned"]) == 3 and len(rep["steps"]) == 5


def test_ctp_plan_bad_goal_exits_2() -> None:
    r = CliRunner().invoke(app, ["plan", str(EXAMPLES / "planar_disk_envelope.json"), "--goal", "combination"])
    assert r.exit_code == 2


BOX = EXAMPLES / "baxter_hug_box.json"


def test_ctp_plan_combination_not_reached_is_no_plan_exit_1() -> None:
    # DDFFFF: the left arm's contacts released while the box still stands on the table. The start
    # (FFFFFF) does not meet it and no plan reaches it (FFFFDD, the lift, is reached: test_goals.py).
    r = CliRunner().invoke(app, ["plan", str(BOX), "--goal", "combination", "--combination", "DDFFFF",
                                 "--time-limit", "2"])
    assert r.exit_code == 1, r.output
    assert "no plan:" in r.output and "goal reached" not in r.output


def test_ctp_plan_goal_met_at_the_start_says_so(tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "plan.json"
    r = CliRunner().invoke(app, ["plan", str(BOX), "--goal", "combination", "--combination", "FFFFFF",
                                 "--out", str(out), "--replay"])
    assert r.exit_code == 0, r.output
    assert "goal met at the start" in r.output and "already meets the goal" in r.output
    assert "nothing to replay" in r.output
    data = json.loads(out.read_text())
    assert data["found"] is True and data["outcome"] == "start_meets_goal" and data["steps"] == []


def test_ctp_plan_pose_tolerances(tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "plan.json"
    # a 3 cm lift of the box is not met at the start with the default tolerances ...
    x, y, z = load_scene(BOX).object.pose.position
    lift = f"{x} {y} {z + 0.03} 0 0 0"
    r = CliRunner().invoke(app, ["plan", str(BOX), "--goal", "pose", "--pose", lift, "--time-limit", "1",
                                 "--out", str(out)])
    assert "already meets the goal" not in r.output
    assert r.exit_code == 1, r.output
    goal = json.loads(out.read_text())["goal"]
    assert goal == {"type": "pose", "pose": [x, y, z + 0.03, 0.0, 0.0, 0.0]}
    # ... and is, with a position tolerance of 3.5 cm (metres) and the rotation free
    r = CliRunner().invoke(app, ["plan", str(BOX), "--goal", "pose", "--pose", lift, "--position-tolerance",
                                 "0.035", "--rotation-tolerance", "free", "--out", str(out)])
    assert r.exit_code == 0 and "already meets the goal" in r.output, r.output
    goal = json.loads(out.read_text())["goal"]
    assert goal["position_tolerance"] == 0.035 and goal["rotation_tolerance"] == "free"


def test_ctp_plan_bad_tolerances_exit_2() -> None:
    base = ["plan", str(BOX), "--goal", "pose", "--pose", "0.5 0 1 0 0 0"]
    r = CliRunner().invoke(app, [*base, "--rotation-tolerance", "loose"])
    assert r.exit_code == 2 and "rotation-tolerance" in r.output, r.output
    r = CliRunner().invoke(app, [*base, "--position-tolerance", "-0.01"])
    assert r.exit_code == 2 and "goal.position_tolerance" in r.output, r.output
    r = CliRunner().invoke(app, ["plan", str(BOX), "--goal", "combination", "--combination", "FFFFD"])
    assert r.exit_code == 2 and "goal.combination" in r.output and "6 contacts" in r.output, r.output
    r = CliRunner().invoke(app, [*base, "--free-axes", "x q"])
    assert r.exit_code == 2 and "goal.free_axes" in r.output and "Traceback" not in r.output, r.output
    r = CliRunner().invoke(app, ["plan", str(BOX), "--free-axes", "x"])  # the default goal is active
    assert r.exit_code == 2 and "free_axes is for goal types 'pose' and 'displacement'" in r.output, r.output


def test_ctp_plan_and_simulate_document_their_exit_codes() -> None:
    for cmd in ("plan", "simulate"):
        r = CliRunner().invoke(app, [cmd, "--help"])
        assert r.exit_code == 0 and "Exit codes" in r.output and "3" in r.output, r.output


def test_ctp_plan_displacement_goal_is_the_pose_it_leads_to(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``--goal displacement``: lift by dz is the pose goal of the start pose raised by dz."""
    out = tmp_path / "plan.json"
    x, y, z = load_scene(BOX).object.pose.position
    r = CliRunner().invoke(app, ["plan", str(BOX), "--goal", "displacement", "--displacement", "0 0 0.03 0 0 0",
                                 "--time-limit", "1", "--out", str(out)])
    assert r.exit_code in (0, 1), r.output
    goal = json.loads(out.read_text())["goal"]
    assert goal["type"] == "pose" and goal["pose"][3:] == [0.0, 0.0, 0.0], goal
    assert abs(goal["pose"][0] - x) < 1e-12 and abs(goal["pose"][1] - y) < 1e-12
    assert abs(goal["pose"][2] - (z + 0.03)) < 1e-12


def test_ctp_plan_bad_displacements_exit_2() -> None:
    base = ["plan", str(BOX), "--goal", "displacement"]
    for extra, said in (([], "needs the field 'displacement'"), (["--displacement", "0 0 0.03"], "6 values"),
                        (["--displacement", "0 x"], "not a list of numbers")):
        r = CliRunner().invoke(app, [*base, *extra])
        assert r.exit_code == 2 and said in r.output and "Traceback" not in r.output, (extra, r.output)


def test_posture_rate_default_is_the_replays_and_bad_rates_exit_2(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from ctp.cli import POSTURE_RATE
    from sim.plan_replay import PlanSimulationOptions

    assert PlanSimulationOptions().posture_rate == POSTURE_RATE
    plan_file = tmp_path / "plan.json"
    plan_file.write_text(json.dumps({"steps": [], "scene": json.loads(
        (EXAMPLES / "planar_disk_envelope.json").read_text())}))
    for bad in ("-1", "nan", "inf"):
        r = CliRunner().invoke(app, ["simulate", str(plan_file), "--posture-rate", bad])
        assert r.exit_code == 2 and "posture-rate" in r.output and "Traceback" not in r.output, (bad, r.output)


def test_hold_rate_default_is_the_replays_and_bad_rates_exit_2(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from ctp.cli import HOLD_RATE
    from sim.plan_replay import PlanSimulationOptions

    assert PlanSimulationOptions().hold_rate == HOLD_RATE
    plan_file = tmp_path / "plan.json"
    plan_file.write_text(json.dumps({"steps": [], "scene": json.loads(
        (EXAMPLES / "planar_disk_envelope.json").read_text())}))
    for bad in ("-1", "nan", "inf"):
        r = CliRunner().invoke(app, ["simulate", str(plan_file), "--hold-rate", bad])
        assert r.exit_code == 2 and "hold-rate" in r.output and "Traceback" not in r.output, (bad, r.output)


def _spy_planner_options(monkeypatch):  # type: ignore[no-untyped-def]
    """Replace ``planner.plan`` by a one-expansion run that records the ``PlannerOptions`` each
    call receives (the list returned)."""
    import planner
    from planner.options import PlannerOptions

    seen: list[PlannerOptions | None] = []
    real = planner.plan

    def spy(*args, options=None, **kwargs):  # type: ignore[no-untyped-def]
        seen.append(options)
        return real(*args, options=options, max_expansions=1, **kwargs)

    monkeypatch.setattr(planner, "plan", spy)
    return seen


@pytest.mark.parametrize("name", ["link_replacement", "contact_slides", "link_sliding", "separate_finger_contacts"])
def test_ctp_plan_switch_flags_reach_the_planner(monkeypatch, name: str) -> None:  # type: ignore[no-untyped-def]
    """``--link-replacement``, ``--contact-slides``, ``--link-sliding`` and
    ``--separate-finger-contacts`` each turn on their ``PlannerOptions`` switch (off without it)."""
    seen = _spy_planner_options(monkeypatch)
    scene = str(Path(__file__).resolve().parents[2] / "examples" / "planar_disk_envelope.json")
    for flag, want in (([], False), (["--" + name.replace("_", "-")], True)):
        r = CliRunner().invoke(app, ["plan", scene, "--goal", "active", *flag])
        assert r.exit_code in (0, 1), r.output
        assert seen[-1] is not None and getattr(seen[-1], name) is want


def test_ctp_plan_effort_weight_reaches_the_planner(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """``--effort-weight W`` sets ``PlannerOptions.effort_weight`` (without it: the default 0.1)
    and nothing else of the options."""
    from planner.options import PlannerOptions

    seen = _spy_planner_options(monkeypatch)
    scene = str(Path(__file__).resolve().parents[2] / "examples" / "planar_disk_envelope.json")
    for flag, want in (([], PlannerOptions().effort_weight), (["--effort-weight", "0"], 0.0),
                       (["--effort-weight", "2.5"], 2.5)):
        r = CliRunner().invoke(app, ["plan", scene, "--goal", "active", *flag])
        assert r.exit_code in (0, 1), r.output
        assert seen[-1] is not None and seen[-1].effort_weight == want
        assert dataclasses.replace(seen[-1], effort_weight=PlannerOptions().effort_weight) == PlannerOptions()


@pytest.mark.slow
def test_ctp_plan_no_sliding_rolls_the_sphere(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``--no-sliding`` reaches the planner (PlannerOptions.sliding_motions = False): the sphere of
    examples/sphere_table_roll.json is rolled 5 cm with no object motion sliding on the table
    (the default, for a displacement goal, first slides it once: a cheaper plan)."""
    args = ["plan", str(EXAMPLES / "sphere_table_roll.json"), "--goal", "displacement", "--displacement",
            "0.05 0 0 0 0 0", "--position-tolerance", "0.005", "--rotation-tolerance", "free"]
    kinds = {}
    for flag in ("--no-sliding", "--sliding"):
        out = tmp_path / f"{flag}.json"
        r = CliRunner().invoke(app, [*args, flag, "--out", str(out)])
        assert r.exit_code == 0, r.output
        steps = json.loads(out.read_text())["steps"]
        kinds[flag] = [s["combination"] for s in steps if s["kind"] == "object_motion"]
    assert kinds["--no-sliding"] and all(c == "FF" for c in kinds["--no-sliding"])
    assert any("S" in c for c in kinds["--sliding"])


@pytest.mark.slow
def test_ctp_plan_contact_goal_by_a_slide_and_its_replay(tmp_path: Path) -> None:
    """``ctp plan --goal contact --body --point --contact-slides`` on Baxter's hug finds the forearm's
    release and the elbow's slide (exit 0), ``ctp simulate`` of the file replays it within 5 %
    (exit 0); without ``--contact-slides`` the point is not reached within the same expansions
    (exit 1)."""
    scene = str(EXAMPLES / "baxter_hug_box.json")
    goal = ["--goal", "contact", "--body", "left/left_lower_elbow", "--point", "0.5236 0.2 1.1104",
            "--position-tolerance", "0.001"]
    out = tmp_path / "slide.json"
    r = CliRunner().invoke(app, ["plan", scene, *goal, "--contact-slides", "--out", str(out)])
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    assert [s["kind"] for s in data["steps"]] == ["release", "slide"]
    assert data["steps"][1]["figures"]["body"] == "left/left_lower_elbow"
    r = CliRunner().invoke(app, ["simulate", str(out), "--scene", scene])
    assert r.exit_code == 0 and "slid in" in r.output and "within tolerance" in r.output, r.output
    r = CliRunner().invoke(app, ["plan", scene, *goal, "--time-limit", "120"])
    assert r.exit_code == 1 and "no plan" in r.output, r.output


def test_ctp_plan_help_states_the_planners_default_effort_weight() -> None:
    """The help of ``--effort-weight`` names ``PlannerOptions``' own default (the CLI imports the
    planner lazily, so the number is written in the help text; this keeps the two equal)."""
    from planner.options import PlannerOptions

    r = CliRunner().invoke(app, ["plan", "--help"], env={"COLUMNS": "400", "NO_COLOR": "1"})
    assert r.exit_code == 0
    assert f"default {PlannerOptions().effort_weight:g}" in " ".join(r.output.split())
