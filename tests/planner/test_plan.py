"""Plans on the planar enveloping grasp: found, every step passes the analysis, JSON, no-path."""

from __future__ import annotations

import contextlib
import importlib
import json
from dataclasses import replace

import numpy as np
import pytest
from test_transfer import _dense_check

from analysis.exceptions import SceneError
from analysis.kinematics import BodyRef, HandKinematics
from analysis.loader import scene_from_dict
from analysis.scene import Scene
from planner import Goal, plan
from planner.collision import CollisionModel
from planner.goals import closure_is_active
from planner.state import StateAnalysis, all_f
from planner.verify import verify_plan


def test_planar_plan_reaches_active_closure(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    p = planar_plan
    assert p.found, p.reason
    kinds = [s.transition.kind for s in p.steps]
    # Fig. 5: fingers let go while the palm holds, fingertips regrasp, the object is lifted off the palm
    assert kinds.count("release") >= 2 and kinds.count("contact") >= 2 and kinds[-1] == "object_motion"
    assert "palm" not in p.final_contacts and len(p.final_contacts) >= 2
    first = StateAnalysis.of(planar_scene, p.steps[0].before, HandKinematics.from_scene(planar_scene))
    assert first.summary("FFFFF").a_bar == 0  # starts in passive closure
    hand = HandKinematics.from_scene(planar_scene)
    last = StateAnalysis.of(planar_scene, p.steps[-1].after, hand)
    assert last.parts(all_f(p.steps[-1].after)).ms.a_bar == 3
    assert closure_is_active(last, all_f(p.steps[-1].after), samples=200)
    # consecutive steps chain: each starts where the previous ended
    for a, b in zip(p.steps, p.steps[1:], strict=False):
        assert a.after.key() == b.before.key()
        np.testing.assert_allclose(a.transition.q_path[-1], b.transition.q_path[0], atol=1e-9)


def test_every_step_passes_the_analysis(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    assert verify_plan(planar_scene, planar_plan) == []


def test_plan_json(planar_plan, tmp_path) -> None:  # type: ignore[no-untyped-def]
    data = json.loads(json.dumps(planar_plan.to_json()))
    assert data["found"] is True and isinstance(data["steps"], list) and data["steps"]
    for s in data["steps"]:
        assert {"kind", "combination", "joint_path", "object_path", "torques"} <= set(s)
        assert s["kind"] in ("release", "contact", "object_motion")
        assert len(s["joint_path"]) == len(s["object_path"]) >= 2
    motion = next(s for s in data["steps"] if s["kind"] == "object_motion")
    assert motion["torques"]["chosen"] is not None and motion["torques"]["set"]["work"] > 0
    assert data["stats"]["nodes_expanded"] >= 1


def test_the_analysis_memo_leaves_the_plan_unchanged(planar_scene: Scene, planar_plan,  # type: ignore[no-untyped-def]
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """``plan`` solves each distinct LP of its states, and computes each distinct statics and motion
    space, once (``analysis.memo``): planned with everything afresh, the planar plan's JSON is the
    same but for the timings, and the memo did save LP models (the states pose the same LPs again)."""
    import analysis.solvers.highs as highs

    plan_mod = importlib.import_module("planner.plan")  # (the package's `plan` is the function)

    built = {"n": 0}
    orig_init = highs.LPModel.__init__

    def counting_init(self: highs.LPModel, *a: object, **k: object) -> None:
        built["n"] += 1
        orig_init(self, *a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(highs.LPModel, "__init__", counting_init)
    memo = plan(planar_scene, Goal(type="active"))
    with_memo, built["n"] = built["n"], 0
    monkeypatch.setattr(plan_mod, "analysis_memo", contextlib.nullcontext)
    fresh = plan(planar_scene, Goal(type="active"))
    assert with_memo < built["n"]

    def strip(p: object) -> object:
        data = p.to_json()  # type: ignore[attr-defined]
        data.pop("stats")
        for s in data["steps"]:
            s.get("figures", {}).pop("ompl_seconds", None)
        return data

    assert strip(memo) == strip(fresh) == strip(planar_plan)


def test_no_path_is_a_result_naming_the_block(planar_scene: Scene) -> None:
    p = plan(planar_scene, Goal(type="combination", combination="DDDDD"), max_expansions=2)
    assert not p.found and p.steps == () and "node limit" in p.reason


def test_start_without_stationary_grasp(planar_scene: Scene) -> None:
    data = planar_scene.model_dump(mode="json", exclude_none=True)
    data["contacts"] = [c for c in data["contacts"] if c["body"] == "palm"]
    data["external_wrench"] = [1.0, 0.0, 0.0]
    p = plan(scene_from_dict(data), Goal(type="active"))
    assert not p.found and "no stationary grasp (18)" in p.reason


def test_malformed_input_raises(planar_scene: Scene) -> None:
    with pytest.raises(SceneError, match=r"goal\.pose"):
        plan(planar_scene, Goal(type="pose", pose=[0, 0, 0, 0, 0, 0]))
    with pytest.raises(TypeError):
        plan(planar_scene, {"type": "active"})  # type: ignore[arg-type]
    with pytest.raises(SceneError, match="time_limit"):
        plan(planar_scene, Goal(type="active"), time_limit=-1.0)


def test_progress_is_reported(planar_scene: Scene) -> None:
    seen: list[tuple[float, str]] = []
    p = plan(planar_scene, Goal(type="combination", combination="DDDDD"), max_expansions=3,
             progress=lambda f, m: seen.append((f, m)))
    assert not p.found
    fr = [f for f, _ in seen]
    assert fr[-1] == 1.0 and all(0.0 <= f <= 1.0 for f in fr) and len(seen) >= 2


def test_finger_paths_of_the_plan_are_collision_free_every_millimetre(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    hand = HandKinematics.from_scene(planar_scene)
    model = CollisionModel.of(planar_scene, hand)
    checked = 0
    for step in planar_plan.steps:
        t = step.transition
        if t.kind != "contact":
            continue
        f = next(i for i, ch in enumerate(hand.fingers) if ch.name == t.figures.finger)
        chain = hand.fingers[f]
        tip = BodyRef(f"{chain.name}/{chain.n_joints - 1}", f, chain.n_joints - 1)
        path = t.q_path[:, hand.finger_slice(f)]
        assert _dense_check(model, f, step.before.q, path, step.before, len(path) - 2, tip) >= 0.0
        checked += 1
    assert checked >= 2


def test_passive_goal_holds_at_the_enveloping_grasp(planar_scene: Scene) -> None:
    p = plan(planar_scene, Goal(type="passive"))
    assert p.found and p.steps == ()  # the enveloping grasp is already in passive closure


def test_pose_goal_moves_the_object_there(planar_scene: Scene) -> None:
    p = plan(planar_scene, Goal(type="pose", pose=[0.0, 0.55, 0.0], tolerance=0.01))
    assert p.found, p.reason
    np.testing.assert_allclose(p.final_pose, [0.0, 0.55, 0.0], atol=0.01)
    assert [s.transition.kind for s in p.steps].count("object_motion") >= 1
    assert verify_plan(planar_scene, p) == []


# --------------------------------------------------------------------------------------------
# Plan.from_json: the one reader of the plan file, the inverse of Plan.to_json
# (imports inside the tests: this block is appended to the file, below its import section)


def _json(data: dict) -> dict:  # type: ignore[type-arg]
    out: dict = json.loads(json.dumps(data))  # type: ignore[type-arg]
    return out


def test_plan_from_json_inverts_to_json(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    from planner.plan import Plan

    data = _json(planar_plan.to_json())
    back = Plan.from_json(data, planar_scene)
    assert _json(back.to_json()) == data
    assert back.found and len(back.steps) == len(planar_plan.steps)
    np.testing.assert_allclose(back.displacement, planar_plan.displacement, atol=1e-9)
    np.testing.assert_allclose(back.final_tau, planar_plan.final_tau, atol=1e-9)
    # the rebuilt grasp states chain and are the planner's (contacts, object-frame points, normals)
    for a, b in zip(back.steps, back.steps[1:], strict=False):
        assert a.after.key() == b.before.key()
    for mine, theirs in zip(back.steps, planar_plan.steps, strict=True):
        assert mine.transition.kind == theirs.transition.kind
        assert mine.before.key() == theirs.before.key() and mine.after.key() == theirs.after.key()
        np.testing.assert_allclose(mine.after.q, theirs.after.q, atol=1e-9)
        for i in range(mine.after.L):
            np.testing.assert_allclose(mine.after.world_point(i), theirs.after.world_point(i), atol=1e-9)
            np.testing.assert_allclose(mine.after.world_normal(i), theirs.after.world_normal(i), atol=1e-6)
    # and again: reading is idempotent
    assert _json(Plan.from_json(back.to_json(), planar_scene).to_json()) == data


def test_plan_from_json_reads_a_plan_that_was_not_found(planar_scene: Scene) -> None:
    from planner.plan import Plan

    p = plan(planar_scene, Goal(type="combination", combination="DDDDD"), max_expansions=2)
    data = _json(p.to_json())
    back = Plan.from_json(data, planar_scene)
    assert not back.found and back.steps == () and back.reason == p.reason
    assert _json(back.to_json()) == data


@pytest.mark.parametrize(
    ("case", "loc"),
    [
        ("no_steps", ("steps",)),
        ("empty_steps", ("steps",)),
        ("no_start_pose", ("start_pose",)),
        ("short_final_pose", ("final_pose",)),
        ("step_not_object", ("steps", 2)),
        ("bad_kind", ("steps", 0, "kind")),
        ("unknown_body", ("steps", 0, "contacts_after", 0)),
        ("bad_combination", ("steps", 0, "combination")),
        ("short_joint_path", ("steps", 1, "joint_path")),
        ("nan_object_path", ("steps", 0, "object_path")),
        ("no_torques", ("steps", 0, "torques")),
        ("release_without_stationary", ("steps", 0, "torques", "stationary")),
        ("bad_chosen", ("steps", 4, "torques", "chosen")),
        ("bad_points", ("steps", 0, "contact_points_after")),
        ("bad_figures", ("steps", 0, "figures")),
        ("bad_final_torque", ("final_holding_torque",)),
        ("bad_goal", ("goal",)),
        ("no_stats", ("stats",)),
    ],
)
def test_plan_from_json_names_the_bad_field(planar_scene: Scene, planar_plan, case: str, loc: tuple) -> None:  # type: ignore[no-untyped-def,type-arg]
    from planner.plan import Plan

    data = _json(planar_plan.to_json())
    steps = data["steps"]
    assert steps[0]["kind"] == "release" and steps[4]["kind"] == "object_motion"
    if case == "no_steps":
        del data["steps"]
    elif case == "empty_steps":
        data["steps"] = []
    elif case == "no_start_pose":
        del data["start_pose"]
    elif case == "short_final_pose":
        data["final_pose"] = [0.0, 1.0]
    elif case == "step_not_object":
        steps[2] = 3
    elif case == "bad_kind":
        steps[0]["kind"] = "teleport"
    elif case == "unknown_body":
        steps[0]["contacts_after"][0] = "thumb/7"
    elif case == "bad_combination":
        steps[0]["combination"] += "F"
    elif case == "short_joint_path":
        steps[1]["joint_path"] = [row[:3] for row in steps[1]["joint_path"]]
    elif case == "nan_object_path":
        steps[0]["object_path"][0][0] = float("nan")
    elif case == "no_torques":
        del steps[0]["torques"]
    elif case == "release_without_stationary":
        steps[0]["torques"]["stationary"] = None
    elif case == "bad_chosen":
        steps[4]["torques"]["chosen"] = [1.0, 2.0]
    elif case == "bad_points":
        steps[0]["contact_points_after"] = steps[0]["contact_points_after"][:-1]
    elif case == "bad_figures":
        del steps[0]["figures"]["finger"]
    elif case == "bad_final_torque":
        data["final_holding_torque"] = [0.0, float("nan")]
    elif case == "bad_goal":
        data["goal"] = {"type": "teleport"}
    elif case == "no_stats":
        del data["stats"]
    with pytest.raises(SceneError) as e:
        Plan.from_json(data, planar_scene)
    assert e.value.loc == loc, e.value


def test_verify_finds_a_step_that_does_not_start_where_the_last_ended(planar_scene: Scene, planar_plan) -> None:  # type: ignore[no-untyped-def]
    """The planar plan's steps chain (each starts at the joints and the object pose the one before
    it ended at); moving the start of step 2 by 0.01 rad makes verify_plan name the jump."""
    assert verify_plan(planar_scene, planar_plan) == []
    s2 = planar_plan.steps[2]
    q_path = s2.transition.q_path.copy()
    q_path[0, 0] += 0.01
    moved = replace(s2, transition=replace(s2.transition, q_path=q_path))
    bad = replace(planar_plan, steps=(*planar_plan.steps[:2], moved, *planar_plan.steps[3:]))
    problems = verify_plan(planar_scene, bad)
    assert "step 2: starts 0.01 away from where step 1 ended (joints)" in problems


def test_a_validated_grasp_is_entered_only_at_its_own_configuration(planar_scene: Scene) -> None:
    """GraphNodes.arrives: a node (contacts and object pose) registered by a checked edge takes
    further edges only when they end at its hand configuration; otherwise the plan would jump
    between two steps (the palm plan did by 0.014 rad before)."""
    from planner.nodes import Q_MATCH, GraphNodes
    from planner.state import state_from_scene

    hand = HandKinematics.from_scene(planar_scene)
    nodes = GraphNodes(planar_scene, hand, Goal(type="active"))
    st = state_from_scene(planar_scene, hand)
    q = st.q.copy()
    q[0] += 0.05  # the same contacts and pose, another configuration
    other = st.with_contacts(st.contacts, q)
    assert other.key() == st.key()
    assert nodes.arrives(other)  # nothing registered yet
    nodes.add(other, validated=False)
    assert nodes.arrives(st)  # registered, not validated: may still be replaced
    nodes.add(st)
    assert nodes.arrives(st.with_contacts(st.contacts, st.q + 0.5 * Q_MATCH))
    assert not nodes.arrives(other)
    assert nodes.rejections["the same grasp is already reached with another hand configuration"] == 1


def test_displacement_of_an_object_that_starts_turned_is_its_turn(planar_plan) -> None:  # type: ignore[no-untyped-def]
    """``Plan.displacement`` is the ``s`` with ``start.displaced(s) == final`` (the displacement
    goal's meaning): a cylinder that starts turned -90 degrees about x and rolls 0.1 rad about +y
    (world) has the displacement ``(dp, 0, 0.1, 0)``, not the difference of its pose vectors."""
    from analysis.pose import Pose

    start = Pose.from_vector([0.0, 0.0, 0.5, -np.pi / 2, 0.0, 0.0], 3)
    s = np.array([0.05, 0.0, 0.0, 0.0, 0.1, 0.0])
    final = start.displaced(s)
    p = replace(planar_plan, start_pose=start.vector(), final_pose=final.vector())
    np.testing.assert_allclose(p.displacement, s, atol=1e-12)
    assert float(np.linalg.norm(final.vector() - start.vector() - s)) > 0.01  # the pose vectors' difference is not it
    np.testing.assert_allclose(planar_plan.displacement, planar_plan.final_pose - planar_plan.start_pose, atol=1e-15)
