"""A box pushed along the table (issue 11): the Panda's forearm sticks across the box's top edge
(F) while the box's four bottom corners slide on the table (S): the contact manifold's vertex
rows, the normal of a contact on an edge or a corner, and the planned 10 cm push (found, every
object segment along the analysed direction, verified, no penetration, the torques pushing the
box against the table's kinetic friction)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from analysis.contacts import build_system
from analysis.exceptions import SceneError
from analysis.geometry import shape_signed_distance
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.pose import Pose
from analysis.scene import Scene
from planner import Goal, plan
from planner.manifold import ContactManifold, project_manifold
from planner.object_motion import MIN_DIRECTION_COSINE, corner_normal, direction_cosines
from planner.plan import Plan
from planner.state import state_from_scene, state_scene
from planner.verify import verify_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
#: the push: 10 cm along -x (the direction the forearm presses the box's far top edge)
PUSH = np.array([-0.10, 0.0, 0.0])
POSITION_TOL = 0.003  # m
ROTATION_TOL = 0.3  # rad


@pytest.fixture(scope="module")
def box_scene() -> Scene:
    return load_scene(EXAMPLES / "panda_forearm_box.json")


def _table_corners(scene: Scene) -> list[int]:
    return [i for i, c in enumerate(scene.contacts) if c.body == "table"]


def test_vertex_rows_keep_the_corners_on_the_table_and_match_finite_differences(box_scene: Scene) -> None:
    hand = HandKinematics.from_scene(box_scene)
    st = state_from_scene(box_scene, hand)
    corners = _table_corners(box_scene)
    man = ContactManifold(hand, st, [0], corners, box_scene)
    assert man.rows == 3 + len(corners)
    x0 = np.concatenate([st.q, np.zeros(man.D)])
    assert float(np.linalg.norm(man.function(x0))) < 1e-9  # the scene's contacts touch
    rng = np.random.default_rng(11)
    for _ in range(3):  # analytic Jacobian = central differences, anywhere (rotated, lifted)
        x = x0 + 0.02 * rng.standard_normal(len(x0))
        Jn = np.column_stack([(man.function(x + e) - man.function(x - e)) / 2e-7 for e in 1e-7 * np.eye(len(x))])
        np.testing.assert_allclose(man.jacobian(x), Jn, atol=1e-6)
    # the corner rows are the corners' heights above the table: zero for any motion in the table's
    # plane (a slide and a turn about the vertical), the lift dz for a lift, and tilted corners
    # rise and sink in proportion to their lever arms
    M = hand.M
    rows = slice(3, 3 + len(corners))
    for s in ([0.03, -0.02, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.4], [-0.05, 0.01, 0.0, 0.0, 0.0, -0.2]):
        np.testing.assert_allclose(man.function(np.concatenate([st.q, s]))[rows], 0.0, atol=1e-9)
    np.testing.assert_allclose(man.function(np.concatenate([st.q, [0, 0, 0.01, 0, 0, 0]]))[rows], 0.01, atol=1e-9)
    tilt = 0.05  # about the object's y axis through p_o: corner height = -x_c sin + z_c cos - z_c
    heights = man.function(np.concatenate([st.q, [0, 0, 0, 0, tilt, 0]]))[rows]
    for k, i in enumerate(corners):
        xc, zc = st.contacts[i].point_object[0], st.contacts[i].point_object[2]
        assert heights[k] == pytest.approx(-xc * np.sin(tilt) + zc * np.cos(tilt) - zc, abs=1e-9)
    # a projection from an ambient point lifted off the table puts the corners back on it
    x, res = project_manifold(man, x0 + np.r_[np.zeros(M), 0.0, 0.0, 0.004, 0.0, 0.0, 0.0])
    assert res < 1e-10
    assert abs(man.pose(x[M:]).position[2] - st.position[2]) < 1e-9


def test_a_link_sliding_on_a_box_edge_is_refused_naming_the_contact(box_scene: Scene) -> None:
    """A link slides on a box's face (tests/planner/test_line_contacts.py), not on its edge: the
    forearm across the box's top edge is refused, naming the contact and the reason."""
    hand = HandKinematics.from_scene(box_scene)
    st = state_from_scene(box_scene, hand)
    with pytest.raises(SceneError, match=r"contacts\.0: a sliding contact of a link \(arm/panda_link4\).*edge"):
        ContactManifold(hand, st, [], [0], box_scene)


def test_corner_normal_is_the_smooth_bodys_normal(box_scene: Scene) -> None:
    hand = HandKinematics.from_scene(box_scene)
    st = state_from_scene(box_scene, hand)
    for i in _table_corners(box_scene):  # a box corner on the table: the table's normal (+z, into the box)
        ref = hand.resolve_body(st.contacts[i].body)
        assert ref is not None
        n = corner_normal(box_scene, hand, ref, st.q, st.pose, st.contacts[i].point_object)
        assert n is not None
        np.testing.assert_allclose(n, [0.0, 0.0, 1.0], atol=1e-9)
    # the forearm across the top edge: the capsule's normal at the point, the scene's own normal
    ref = hand.resolve_body("arm/panda_link4")
    assert ref is not None
    n = corner_normal(box_scene, hand, ref, st.q, st.pose, st.contacts[0].point_object)
    assert n is not None
    np.testing.assert_allclose(n, box_scene.contacts[0].normal, atol=1e-6)
    # a point inside a face of the box: the box's own normal holds
    assert corner_normal(box_scene, hand, ref, st.q, st.pose, np.array([0.0, 0.0, 0.13])) is None


def test_displacement_goal_is_the_pose_goal_of_the_displaced_start(box_scene: Scene) -> None:
    start = state_from_scene(box_scene).pose
    push = Goal(type="displacement", displacement=[*PUSH, 0.0, 0.0, 0.0], position_tolerance=POSITION_TOL,
                rotation_tolerance=ROTATION_TOL)
    goal = push.resolved(start)
    assert goal.type == "pose" and goal.displacement is None
    assert goal.position_tolerance == POSITION_TOL and goal.rotation_tolerance == ROTATION_TOL
    assert goal.pose is not None
    np.testing.assert_allclose(np.asarray(goal.pose), [0.25, 0.0, 0.13, 0.0, 0.0, 0.0], atol=1e-12)
    # a turn composes with the start's rotation (world rotation vector): exp(w) R_0
    turned = Goal(type="displacement", displacement=[0.0, 0.0, 0.03, 0.0, 0.0, 0.2]).resolved(start)
    R = Pose.from_vector(np.asarray(turned.pose), 3).rotation
    c, s_ = np.cos(0.2), np.sin(0.2)
    np.testing.assert_allclose(R @ start.rotation.T, [[c, -s_, 0], [s_, c, 0], [0, 0, 1]], atol=1e-12)
    assert turned.pose is not None and turned.pose[2] == pytest.approx(0.16)
    assert Goal(type="pose", pose=[0.0] * 6).resolved(start).pose == [0.0] * 6  # other goals: as they are
    with pytest.raises(ValidationError, match="needs the field 'displacement'"):
        Goal(type="displacement")
    with pytest.raises(ValidationError, match="displacement must have 3"):
        Goal(type="displacement", displacement=[0.1, 0.0])
    with pytest.raises(SceneError, match=r"goal\.displacement.*6 values"):
        plan(box_scene, Goal(type="displacement", displacement=[0.1, 0.0, 0.0]))


@pytest.fixture(scope="module")
def push_plan(box_scene: Scene) -> Plan:
    """The push as a displacement goal ("push by dx"); tests/sim/test_push_replay.py plans it as a pose."""
    return plan(box_scene, Goal(type="displacement", displacement=[*PUSH, 0.0, 0.0, 0.0],
                                position_tolerance=POSITION_TOL, rotation_tolerance=ROTATION_TOL))


@pytest.mark.slow
def test_the_box_is_pushed_10_cm_along_the_table(box_scene: Scene, push_plan: Plan) -> None:
    p = push_plan
    assert p.found, p.reason
    corners = _table_corners(box_scene)
    assert p.steps and all(s.transition.kind == "object_motion" for s in p.steps)
    for s in p.steps:
        t = s.transition
        assert t.combination == "FSSSS", t.combination  # the forearm sticks, the four corners slide
        assert tuple(t.figures.sliding_contacts) == tuple(corners)  # type: ignore[union-attr]
        # every object segment within cosine 0.99 of the analysed direction (the torque's motion)
        assert t.torque_set is not None
        dr = np.asarray(t.torque_set["direction"], float)
        S = np.array([Pose.from_vector(v, 3).displacement_from(s.before.pose) for v in t.object_path])
        assert direction_cosines(S, dr).min() >= MIN_DIRECTION_COSINE
        assert dr[0] < -0.99  # along -x, the push
    moved = np.asarray(p.final_pose) - np.asarray(p.start_pose)
    assert float(np.linalg.norm(moved[:3] - PUSH)) <= POSITION_TOL, moved
    assert abs(moved[2]) < 1e-6 and float(np.linalg.norm(moved[3:])) < 1e-3  # on the table, not turned


@pytest.mark.slow
def test_the_push_verifies_and_nothing_penetrates(box_scene: Scene, push_plan: Plan) -> None:
    hand = HandKinematics.from_scene(box_scene)
    assert verify_plan(box_scene, push_plan) == []
    # the plan file says the same (its states are rebuilt from the file: the normals of the box's
    # corners and edge come from the table and the forearm)
    again = Plan.from_json(push_plan.to_json(), box_scene, hand)
    assert verify_plan(box_scene, again) == []
    # independently of the planner's collision model: the forearm capsule (sampled densely along
    # its axis) never enters the box, and the box's bottom corners stay on the table top (z = 0)
    ref = hand.resolve_body("arm/panda_link4")
    assert ref is not None
    half = np.asarray(box_scene.object.shape.size) / 2  # type: ignore[union-attr]
    bottom = np.array([[sx * half[0], sy * half[1], -half[2]] for sx in (-1, 1) for sy in (-1, 1)])
    t = np.linspace(0.0, 1.0, 401)[:, None]
    for s in push_plan.steps:
        for q, v in zip(s.transition.q_path, s.transition.object_path, strict=True):
            pose = Pose.from_vector(v, 3)
            a, b = hand.body_segment(ref, q)
            gaps = [shape_signed_distance(box_scene.object.shape, pose.to_local(x), 3) for x in a + t * (b - a)]
            assert min(g for g in gaps if g is not None) - hand.body_radius(ref) > -1e-5
            z = np.array([pose.to_world(c)[2] for c in bottom])
            np.testing.assert_allclose(z, 0.0, atol=1e-6)


@pytest.mark.slow
def test_the_chosen_torques_push_the_box_against_the_table_friction(box_scene: Scene, push_plan: Plan) -> None:
    """The chosen torque (a member of T, 32) read back through the forearm's contact Jacobian: the
    force it puts on the box lies in the forearm's friction cone and its push along -x beats the
    table's kinetic friction on the normal load it leaves (weight plus the forearm's downward push),
    so the box slides; and it holds no torque on the joints that turn the arm out of its plane."""
    hand = HandKinematics.from_scene(box_scene)
    mass_g = 9.81  # the scene's external wrench: 1 kg under gravity
    mu_table, mu_arm = 0.4, 0.5
    for s in push_plan.steps:
        tr = s.transition
        assert tr.tau is not None
        tau = np.asarray(tr.tau, dtype=float)  # (M,) the chosen member of T (32)
        sc = state_scene(box_scene, s.before, hand)
        sy = build_system(sc, hand, s.before.q)
        J0 = sy.J_blocks[0]  # (3, M) the forearm contact's point Jacobian
        f, *_ = np.linalg.lstsq(J0.T, tau, rcond=None)  # force of the forearm on the box
        assert float(np.linalg.norm(J0.T @ f - tau)) < 1e-6 * float(np.linalg.norm(tau))
        n = sy.normals[0]  # into the box
        fn = float(f @ n)
        assert fn > 0 and float(np.linalg.norm(f - fn * n)) <= mu_arm * fn * (1 + 1e-6)
        load = mass_g - float(f[2])  # the table's normal load
        assert -float(f[0]) > mu_table * load, (f, load)
        np.testing.assert_allclose(tau[[0, 2, 4, 6]], 0.0, atol=1e-6)
