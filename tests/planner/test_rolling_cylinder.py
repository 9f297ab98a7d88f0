"""Rolling of a cylinder lying on a table (issue 11 item 1; examples/cylinder_table_roll.json): its
two table contacts (the ends of its line contact) roll. ContactManifold(rolling=True) gives each
the rows ``dp + r n x w = 0`` and the cylinder the rows ``P w = 0`` (it turns about its own axis
``a_0`` only). Rolling about a fixed axis is holonomic, so every point of the manifold is the
cylinder rolled without slipping: the contact line at rest, moved by ``r theta`` on the table and
on the cylinder."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest
from closure_helpers import EXAMPLES

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.pose import Pose
from analysis.rotations import matrix_to_rotvec
from analysis.scene import Scene
from planner import Goal, plan
from planner.manifold import ContactManifold, project_manifold
from planner.object_motion import motion_manifold, rolled_contacts, rolling_slip, rolls_on_planes
from planner.options import PlannerOptions
from planner.plan import Plan
from planner.state import state_from_scene
from planner.verify import ROLL_TOL, verify_plan

SCENE = EXAMPLES / "cylinder_table_roll.json"
R, H = 0.5, 0.8  # the cylinder's radius and length in SCENE
N = np.array([0.0, 0.0, 1.0])  # the table's outward normal
ENDS = [1, 2]  # the table contacts: the ends (0, -H/2, 0), (0, H/2, 0) of the line contact


@pytest.fixture(scope="module")
def scene() -> Scene:
    return load_scene(SCENE)


def test_table_contacts_roll_and_the_tip_is_glued(scene: Scene) -> None:
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    assert rolls_on_planes(scene)
    man = motion_manifold(scene, hand, st, [0, *ENDS])
    assert [k[0] for k in man.plane_rolls] == ENDS and len(man.items) == 1
    assert man.axis is not None
    np.testing.assert_allclose(man.axis, [0.0, 1.0, 0.0], atol=1e-15)
    assert [man.plane_offset(k) for k in range(2)] == pytest.approx([-H / 2, H / 2])  # object z: world y
    assert man.axis_rows.shape == (2, 3) and np.abs(man.axis_rows @ man.axis).max() <= 1e-15


def test_cylinder_rows_jacobian_matches_finite_differences(scene: Scene) -> None:
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    rng = np.random.default_rng(7)
    man = motion_manifold(scene, hand, st, [0, *ENDS], direction=np.array([R, 0, 0, 0, 1.0, 0]))
    h = 1e-6
    for _ in range(5):
        x = np.concatenate([st.q + 0.2 * rng.standard_normal(hand.M), 0.05 * rng.standard_normal(3),
                            0.3 * rng.standard_normal(3)])
        fd = np.column_stack([(man.function(x + h * e) - man.function(x - h * e)) / (2 * h)
                              for e in np.eye(len(x))])
        np.testing.assert_allclose(man.jacobian(x), fd, atol=1e-7)


def test_cylinder_rows_have_the_glued_ends_tangent_space(scene: Scene) -> None:
    """At ``s = 0`` the rolling rows (rank 5) span the two glued ends' rows (rank 5 of 6)."""
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    x0 = np.concatenate([st.q, np.zeros(6)])
    rolling = motion_manifold(scene, hand, st, ENDS).jacobian(x0)
    glued = ContactManifold(hand, st, ENDS).jacobian(x0)
    assert np.linalg.matrix_rank(rolling) == np.linalg.matrix_rank(glued) == 5
    assert np.linalg.matrix_rank(np.vstack([rolling, glued]), tol=1e-12) == 5


def test_every_manifold_point_is_an_exact_roll(scene: Scene) -> None:
    """Random ambient points projected onto the table contacts' manifold: the cylinder has turned
    about its own axis by ``theta`` and its centre moved by ``r theta a x n`` (holonomic: no
    path dependence), its axis still parallel to the table at height ``r``, both ends' material
    points at rest (central differences along the roll), the contact moved by ``r |theta|`` on
    the table and on the cylinder, and rolled_contacts puts each end there."""
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    man = motion_manifold(scene, hand, st, ENDS)
    a = st.rotation[:, 2]
    rng = np.random.default_rng(3)
    for _ in range(5):
        x, res = project_manifold(man, np.concatenate([st.q, 0.2 * rng.standard_normal(6)]))
        assert res <= 1e-11
        s = x[hand.M:]
        pose = man.pose(s)
        w = matrix_to_rotvec(pose.rotation @ st.rotation.T)
        theta = float(w @ a)
        assert float(np.linalg.norm(w - theta * a)) <= 1e-12
        np.testing.assert_allclose(pose.position - st.position, R * theta * np.cross(a, N), atol=1e-12)
        np.testing.assert_allclose(pose.rotation[:, 2], a, atol=1e-12)
        contacts = rolled_contacts(hand, scene, st, ENDS, x[: hand.M], s)
        for k, i in enumerate(ENDS):
            z = H / 2 * (1 if k else -1)
            y = pose.position + z * a - R * N  # the contact point on the table
            assert abs(float(y[2])) <= 1e-12
            np.testing.assert_allclose(y - st.world_point(i), R * theta * np.cross(a, N), atol=1e-12)
            y_obj = pose.to_local(y)
            arc = R * float(np.arccos(np.clip(y_obj[:2] @ np.asarray(st.contacts[i].point_object)[:2] / R**2, -1, 1)))
            assert arc == pytest.approx(R * abs(theta), abs=1e-9)
            h = 1e-6  # the material point at y carried along the roll: at rest
            ds = np.concatenate([R * np.cross(a, N), a])
            moved = [man.pose(s + e * ds).to_world(y_obj) for e in (h, -h)]
            assert float(np.linalg.norm(moved[0] - moved[1])) / (2 * h) <= 1e-8
            np.testing.assert_allclose(contacts[i].point_object, y_obj, atol=1e-12)
            np.testing.assert_allclose(contacts[i].normal_object, pose.rotation.T @ N, atol=1e-12)
            np.testing.assert_allclose(contacts[i].point_body, y, atol=1e-12)  # the table is the world frame
        S = np.linspace(0.0, 1.0, 7)[:, None] * s[None, :]
        assert rolling_slip(man, S) <= 1e-12


def test_a_yaw_slips_the_ends(scene: Scene) -> None:
    """A turn about the table normal (not a motion of the manifold) slips the two ends by ``H/2``
    times the turn each: rolling_slip measures it."""
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    man = motion_manifold(scene, hand, st, ENDS)
    S = np.array([np.zeros(6), [0, 0, 0, 0, 0, 0.01]])
    assert rolling_slip(man, S) == pytest.approx(H / 2 * 0.01, rel=1e-6)
    assert float(np.linalg.norm(man.function(np.concatenate([st.q, S[1]])))) > 1e-3


GOAL = Goal(type="displacement", displacement=[0.05, 0.0, 0.0, 0.0, 0.0, 0.0], position_tolerance=0.005,
            rotation_tolerance="free")


@pytest.fixture(scope="module")
def roll_plan(scene: Scene) -> Plan:
    p = plan(scene, GOAL, options=PlannerOptions(sliding_motions=False))
    assert p.found, p.reason
    return p


@pytest.mark.slow
def test_cylinder_roll_plan_is_found_verified_and_rolls(scene: Scene, roll_plan: Plan) -> None:
    """Every object motion is FFF (the tip glued, both table contacts rolling); the plan ends within
    5 mm of 5 cm along +x, the cylinder turned about its axis (+y) by ``dx / r``; verify_plan
    passes; each end's contact point moved by ``dx`` on the table and by ``r`` times the turn on
    the cylinder, keeping its place along the axis."""
    p = roll_plan
    motions = [s for s in p.steps if s.transition.kind == "object_motion"]
    assert len(motions) >= 3 and all(s.transition.combination == "FFF" for s in motions)
    first, last = p.steps[0].before, p.steps[-1].after
    dp = last.position - first.position
    w = matrix_to_rotvec(last.rotation @ first.rotation.T)
    assert abs(dp[0] - 0.05) <= 0.005 and abs(dp[1]) <= 1e-9 and abs(dp[2]) <= 1e-9
    np.testing.assert_allclose(w, [0.0, dp[0] / R, 0.0], atol=1e-9)
    assert verify_plan(scene, p) == []
    for i in ENDS:
        np.testing.assert_allclose(last.world_point(i) - first.world_point(i), [dp[0], 0.0, 0.0], atol=1e-9)
        z0, z1 = np.asarray(first.contacts[i].point_object), np.asarray(last.contacts[i].point_object)
        assert z1[2] == pytest.approx(z0[2], abs=1e-12)
        angle = float(np.arctan2(z0[0] * z1[1] - z0[1] * z1[0], z0[:2] @ z1[:2]))
        assert R * abs(angle) == pytest.approx(dp[0], rel=1e-8)
    for a, b in itertools.pairwise(p.steps):
        assert a.after.key() == b.before.key()


@pytest.mark.slow
def test_verify_rejects_a_yawing_cylinder(scene: Scene, roll_plan: Plan) -> None:
    """An object path that also turns the cylinder 0.01 rad about the table normal (its ends slide
    sideways on the table) is refused: the ends slip."""
    k = next(i for i, s in enumerate(roll_plan.steps) if s.transition.kind == "object_motion")
    step = roll_plan.steps[k]
    t = step.transition
    path = np.array([Pose.from_vector(v, 3).displaced(np.array([0, 0, 0, 0, 0, e])).vector()
                     for v, e in zip(t.object_path, np.linspace(0.0, 0.01, len(t.object_path)), strict=True)])
    bad = replace(roll_plan, steps=(*roll_plan.steps[:k], replace(step, transition=replace(t, object_path=path)),
                                    *roll_plan.steps[k + 1:]))
    problems = verify_plan(scene, bad)
    assert sum("slips" in m for m in problems) == 2, problems  # both ends
    assert H / 2 * 0.01 > 1e3 * ROLL_TOL
