"""Whole-arm regrasps (issue 11 item 2, :mod:`planner.link_release`): a finger that touches the
object with several bodies lets go of one body's contacts and keeps the others (eq. 33, F -> D for
some links of one finger).

* Baxter hugging the box (examples/baxter_hug_box.json): ``--goal combination`` FDFFFF lifts the
  left forearm off the box and keeps the left elbow on it; checked independently of the planner's
  own checks: the kept contacts do not move along the path, the released body point ends at least
  half a ``min_radius`` off the box's surface (its signed distance through
  :func:`analysis.geometry.object_signed_distance`), the new grasp is a valid scene and the plan
  verifies (:func:`planner.verify.verify_plan`).
* The Allegro hand with its URDF collision geometry (examples/allegro_cylinder_urdf.json): the
  thumb touches with its tip sphere and its pad box; releasing one of them gives active closure.
* :func:`planner.link_release.minimal_motion` keeps every contact point's motion and drops the
  joint motion that moves none of them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from analysis.geometry import object_signed_distance
from analysis.kinematics import HandKinematics
from analysis.loader import check_geometry, load_scene
from analysis.scene import Scene
from analysis.torque_limits import hand_torque_limits
from planner import Goal, plan
from planner.link_release import link_release_edges, minimal_motion
from planner.nodes import GraphNodes
from planner.plan import Plan
from planner.state import state_from_scene, state_scene
from planner.verify import verify_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
KEPT_TOL = 1e-9  # m: a kept contact point's drift along the release path


@pytest.fixture(scope="module")
def baxter() -> Scene:
    return load_scene(EXAMPLES / "baxter_hug_box.json")


@pytest.fixture(scope="module")
def forearm_off(baxter: Scene) -> Plan:
    return plan(baxter, Goal(type="combination", combination="FDFFFF"))


def test_baxter_lifts_its_left_forearm_and_keeps_its_elbow(baxter: Scene, forearm_off: Plan) -> None:
    p = forearm_off
    assert p.found, p.reason
    assert [s.transition.kind for s in p.steps] == ["release"]
    step = p.steps[0]
    t = step.transition
    assert t.combination == "FDFFFF"
    assert "left/left_upper_forearm" in t.contacts_before
    assert "left/left_upper_forearm" not in t.contacts_after
    assert "left/left_lower_elbow" in t.contacts_after  # the same arm keeps its elbow on the box
    # the object stays still over the release
    np.testing.assert_allclose(t.object_path, np.tile(p.start_pose, (len(t.object_path), 1)), rtol=0, atol=0)
    hand = HandKinematics.from_scene(baxter)
    model_min_radius = GraphNodes(baxter, hand, p.goal).model.min_radius
    after_scene = state_scene(baxter, step.after, hand)
    for i, c in enumerate(step.before.contacts):
        ref = hand.resolve_body(c.body)
        assert ref is not None
        if ref.finger is None:
            continue
        x = np.array([hand.point_position(ref, c.point_body, q) for q in t.q_path])  # (n, 3)
        if c.body in t.contacts_after:  # kept: the point does not move
            assert float(np.max(np.linalg.norm(x - x[0], axis=1))) <= KEPT_TOL
            np.testing.assert_allclose(x[0], step.before.world_point(i), rtol=0, atol=1e-9)
        else:  # released: off the box's surface at the end, separating at every waypoint
            sd = [object_signed_distance(after_scene, xi) for xi in x]
            assert all(d is not None for d in sd)
            sd_ = np.array(sd, dtype=float)
            assert abs(sd_[0]) <= 1e-9
            assert np.all(np.diff(sd_) > 0)
            assert sd_[-1] >= 0.5 * model_min_radius
    # the right arm does not move (to round-off: the path's projections touch every joint, 5e-15 rad
    # on one machine's BLAS, exactly 0 on another's)
    right = hand.finger_slice(next(i for i, f in enumerate(hand.fingers) if f.name == "right"))
    np.testing.assert_allclose(t.q_path[:, right], np.tile(t.q_path[0, right], (len(t.q_path), 1)), rtol=0, atol=1e-12)
    check_geometry(after_scene)  # the new grasp is a valid scene
    assert verify_plan(baxter, p) == []


def test_every_link_release_edge_of_the_hug_keeps_its_contacts(baxter: Scene) -> None:
    """The edges of the start state: one per (arm, body) that can come off; each keeps the rest."""
    hand = HandKinematics.from_scene(baxter)
    st = state_from_scene(baxter, hand)
    nodes = GraphNodes(baxter, hand, Goal(type="active"))
    edges = link_release_edges(nodes, st)
    assert edges, dict(nodes.rejections)
    for t, new in edges:
        assert t.kind == "release"
        released = [b for b in t.contacts_before if b not in t.contacts_after]
        assert len(released) == 1 and released[0].split("/")[0] in ("left", "right")
        arm = released[0].split("/")[0]
        assert any(b.startswith(arm + "/") for b in t.contacts_after)  # the arm keeps a contact
        assert new.bodies() == t.contacts_after
        check_geometry(state_scene(baxter, new, hand))


def test_allegro_urdf_thumb_releases_one_of_its_two_contacts_to_active_closure() -> None:
    scene = load_scene(EXAMPLES / "allegro_cylinder_urdf.json")
    thumb = [c.body for c in scene.contacts if c.body.startswith("thumb/")]
    assert sorted(thumb) == ["thumb/link_15.0", "thumb/link_15.0_tip"]
    p = plan(scene, Goal(type="active"))
    assert p.found, p.reason
    assert [s.transition.kind for s in p.steps] == ["release"]
    t = p.steps[0].transition
    released = [b for b in t.contacts_before if b not in t.contacts_after]
    assert len(released) == 1 and released[0] in thumb  # one of the thumb's two, the other kept
    assert sum(b.startswith("thumb/") for b in t.contacts_after) == 1
    assert verify_plan(scene, p) == []
    # verify_plan checks every step's torques against the URDF's effort limits: a holding torque
    # 1.5 times over one joint's limit is reported, naming the joint and both figures
    hand = HandKinematics.from_scene(scene)
    limits = hand_torque_limits(scene, hand)
    assert limits is not None and t.tau_stationary is not None
    j = int(np.argmax(np.isfinite(limits)))
    tau = t.tau_stationary.copy()
    tau[j] = 1.5 * limits[j]
    bad = dataclasses.replace(p, steps=(dataclasses.replace(p.steps[0], transition=dataclasses.replace(
        t, tau_stationary=tau)),))
    problems = verify_plan(scene, bad)
    assert len(problems) == 1, problems
    label = hand.joint_labels()[j]
    said = f"holding torque (18) of joint {label} is {1.5 * limits[j]:.4g} N m, over its limit {limits[j]:.4g}"
    assert said in problems[0], problems


def test_minimal_motion_keeps_the_contact_motion_with_least_norm(baxter: Scene) -> None:
    rng = np.random.default_rng(11)
    hand = HandKinematics.from_scene(baxter)
    st = state_from_scene(baxter, hand)
    nodes = GraphNodes(baxter, hand, Goal(type="active"))
    f = next(i for i, fi in enumerate(hand.fingers) if fi.name == "left")
    sl = hand.finger_slice(f)
    rows = []
    for i, c in enumerate(st.contacts):
        ref = hand.resolve_body(c.body)
        if ref is not None and ref.finger == f:
            rows.append(hand.point_jacobian(ref, st.world_point(i), st.q)[:, sl])
    J = np.vstack(rows)  # (3 k, m)
    for _ in range(5):
        dq = rng.standard_normal(hand.M)
        u = minimal_motion(nodes, st, f, dq)  # (m,)
        np.testing.assert_allclose(J @ u, J @ dq[sl], rtol=0, atol=1e-10)
        assert float(np.linalg.norm(u)) <= float(np.linalg.norm(dq[sl])) + 1e-12
        # least norm: u is orthogonal to the null space of J (the wrist's self-motion)
        _, s, Vt = np.linalg.svd(J)
        null = Vt[int(np.sum(s > 1e-10 * s[0])):]
        np.testing.assert_allclose(null @ u, 0.0, rtol=0, atol=1e-10)
        assert null.shape[0] >= 1  # Baxter's arm beyond its forearm moves no contact


def test_towards_fingertip_goals_a_finger_keeps_its_tip_when_it_lets_go_of_a_body() -> None:
    """``keep_tips`` (the searches towards active closure and fingertip grasps, planner.graph.
    TIP_GOALS): the wrap's fingers touch with two inner links each, so none of their link releases
    is offered (they let go with the whole finger), while without it some are; the Allegro thumb
    may release its pad and keep its tip, not the other way round."""
    wrap = load_scene(EXAMPLES / "sphere_four_finger_wrap.json")
    hand = HandKinematics.from_scene(wrap)
    st = state_from_scene(wrap, hand)
    nodes = GraphNodes(wrap, hand, Goal(type="active"))
    assert link_release_edges(nodes, st, keep_tips=True) == []
    assert link_release_edges(nodes, st)  # the inner links can come off one by one
    allegro = load_scene(EXAMPLES / "allegro_cylinder_urdf.json")
    hand = HandKinematics.from_scene(allegro)
    st = state_from_scene(allegro, hand)
    nodes = GraphNodes(allegro, hand, Goal(type="active"))
    edges = link_release_edges(nodes, st, keep_tips=True)
    assert [[b for b in t.contacts_before if b not in t.contacts_after] for t, _ in edges] == [["thumb/link_15.0"]]
    assert "thumb/link_15.0_tip" in edges[0][1].bodies()
