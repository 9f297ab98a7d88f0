"""Rolling in 3-D (issue 11 item 1): a sphere on a table (examples/sphere_table_roll.json) pushed
by a finger's tip rolls on the table. ContactManifold(rolling=True) replaces the table contact's
glued point by the rows ``dp + r n x w = 0``; along the ray ``s = t dr`` of a rolling twist
(``v = r omega x n``) the sphere rolls exactly: the gap stays zero, its material point at the
contact stays at rest, and the contact point moves by ``r`` times the turn on the table and on the
sphere. The plan rolls the sphere 5 cm and verify_plan re-checks the rolling from the poses."""

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
from planner.manifold import ContactManifold
from planner.object_motion import (
    ROLL_SLIP_TOL,
    motion_manifold,
    rolled_contacts,
    rolling_slip,
    rolls_on_links,
    rolls_on_planes,
)
from planner.options import PlannerOptions
from planner.plan import Plan, PlanStep
from planner.state import state_from_scene
from planner.verify import ROLL_TOL, verify_plan

SCENE = EXAMPLES / "sphere_table_roll.json"
R = 0.5  # the sphere's radius in SCENE
N = np.array([0.0, 0.0, 1.0])  # the table's outward normal, into the sphere
TABLE = 1  # the table contact's index in SCENE
GOAL = Goal(type="displacement", displacement=[0.05, 0.0, 0.0, 0.0, 0.0, 0.0], position_tolerance=0.005,
            rotation_tolerance="free")


@pytest.fixture(scope="module")
def scene() -> Scene:
    return load_scene(SCENE)


def _rolling_twist(omega: np.ndarray) -> np.ndarray:
    """The twist ``(v, omega)`` ``(6,)`` that rolls the sphere on the table: ``v = r omega x n``."""
    return np.concatenate([R * np.cross(omega, N), omega])


def test_table_contact_rolls_and_the_finger_tip_is_glued(scene: Scene) -> None:
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    assert rolls_on_planes(scene) and not rolls_on_links(scene)
    man = motion_manifold(scene, hand, st, [0, 1])
    assert [k[0] for k in man.plane_rolls] == [TABLE] and len(man.items) == 1  # the finger tip glued
    np.testing.assert_allclose(man.plane_rolls[0][2], N)
    assert not rolls_on_planes(load_scene(EXAMPLES / "planar_disk_rolling_v.json"))  # 2-D: rolls_on_links


def test_rolling_jacobian_matches_finite_differences(scene: Scene) -> None:
    """``F'`` of the manifold with the finger glued, the table rolling and the direction rows, against
    central differences of ``F`` at random points ``[q; s]`` (rotation vectors up to 0.5 rad)."""
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    rng = np.random.default_rng(11)
    dr = _rolling_twist(np.array([0.0, 1.0, 0.0]))
    man = motion_manifold(scene, hand, st, [0, 1], direction=dr)
    h = 1e-6
    for _ in range(5):
        x = np.concatenate([st.q + 0.2 * rng.standard_normal(hand.M), 0.05 * rng.standard_normal(3),
                            0.3 * rng.standard_normal(3)])
        J = man.jacobian(x)  # (rows, M + 6)
        fd = np.column_stack([(man.function(x + h * e) - man.function(x - h * e)) / (2 * h)
                              for e in np.eye(len(x))])
        np.testing.assert_allclose(J, fd, atol=1e-7)


def test_rolling_rows_have_the_glued_points_tangent_space(scene: Scene) -> None:
    """At ``s = 0`` the rolling rows span the glued table point's rows (eq. 7: equal velocities of
    the two material points), so the manifold's tangent space is still the motion space."""
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    x0 = np.concatenate([st.q, np.zeros(6)])
    rolling = motion_manifold(scene, hand, st, [TABLE]).jacobian(x0)  # (3, M + 6)
    glued = ContactManifold(hand, st, [TABLE]).jacobian(x0)  # (3, M + 6)
    assert np.linalg.matrix_rank(rolling) == np.linalg.matrix_rank(glued) == 3
    assert np.linalg.matrix_rank(np.vstack([rolling, glued]), tol=1e-12) == 3


@pytest.mark.parametrize("omega", [[0.0, 0.3, 0.0], [0.2, -0.25, 0.0], [0.1, 0.2, 0.4]])
def test_sphere_rolls_exactly_along_a_rolling_ray(scene: Scene, omega: list[float]) -> None:
    """Along ``s = t (v, omega)`` with ``v = r omega x n`` (a spin ``omega . n`` included): the rows
    are zero, the sphere's material point at the contact has velocity zero at every ``t``
    (central differences of its world position), its centre stays ``r`` over the table, and the
    contact point has moved by ``r |omega_t| t`` on the table and on the sphere (object frame:
    ``r`` times the arc it travelled on the unit sphere). The glued
    point's manifold is not zero on the same ray: its material point has risen ``r (1 - n . R n)``
    off the table (the glued rows would sink the sphere that much into the table)."""
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    man = motion_manifold(scene, hand, st, [TABLE])
    glued = ContactManifold(hand, st, [TABLE])
    w = np.asarray(omega)
    tw = _rolling_twist(w)
    wt = float(np.linalg.norm(w - (w @ N) * N))
    for t in (0.25, 0.5, 1.0):
        x = np.concatenate([st.q, t * tw])
        assert float(np.linalg.norm(man.function(x))) <= 1e-15
        pose = man.pose(t * tw)
        assert abs(float(pose.position[2]) - R) <= 1e-15
        y = pose.position - R * N  # the contact point, on the table
        z = pose.to_local(y)  # ... on the sphere
        h = 1e-6  # the material point at y, carried by the motion: velocity zero
        y_mat = [man.pose((t + e) * tw).to_world(z) for e in (h, -h)]
        assert float(np.linalg.norm(y_mat[0] - y_mat[1])) / (2 * h) <= 1e-8
        np.testing.assert_allclose(np.linalg.norm(y - (st.position - R * N)), R * wt * t, rtol=1e-12)
        # on the sphere: the arc the contact point travelled (a spin bends it off a great circle),
        # summed over 400 pieces
        zs = [man.pose(u * tw).to_local(man.pose(u * tw).position - R * N) for u in np.linspace(0.0, t, 401)]
        arc = sum(float(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)) for a, b in itertools.pairwise(zs))
        np.testing.assert_allclose(arc, wt * t, rtol=1e-5)
        np.testing.assert_allclose(zs[0], st.contacts[TABLE].point_object, atol=1e-15)
        _, y_r, z_r, n_r = man.plane_rolling_contact(0, x)
        np.testing.assert_allclose(y_r, y, atol=1e-15)
        np.testing.assert_allclose(z_r, z, atol=1e-15)
        np.testing.assert_allclose(pose.R_d @ n_r, N, atol=1e-15)
        # the glued point (material) has risen r (1 - n . R n) off the table point it was glued to:
        # holding it there would sink the sphere that much into the table
        sink = R * (1.0 - float(N @ pose.rotation @ N))
        assert sink > 1e-4
        np.testing.assert_allclose(glued.function(x)[2], -sink, rtol=1e-9)


def test_rolling_rows_slip_off_a_ray(scene: Scene) -> None:
    """Rolling is non-holonomic: a point of the manifold reached along a bent path of it (two rays,
    ``w`` turning its direction) is on the rows, but the bent path slips (the contact's material
    point moves), at second order; the straight ray to the same point rolls. The planner's
    :func:`rolling_slip` measures the same."""
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    man = motion_manifold(scene, hand, st, [TABLE])

    def slip(path: list[np.ndarray]) -> float:
        """Sum over the path's segments of the contact's material displacement ``dp - r omega x n``."""
        poses = [man.pose(s) for s in path]
        out = 0.0
        for a, b in itertools.pairwise(poses):
            om = matrix_to_rotvec(b.rotation @ a.rotation.T)
            out += float(np.linalg.norm(b.position - a.position - R * np.cross(om, N)))
        return out

    tx, ty = _rolling_twist(np.array([0.3, 0.0, 0.0])), _rolling_twist(np.array([0.0, 0.3, 0.0]))
    ts = np.linspace(0.0, 1.0, 201)
    bent = [t * tx for t in ts] + [tx + t * ty for t in ts[1:]]
    straight = [t * (tx + ty) for t in np.linspace(0.0, 1.0, 401)]
    for s in (bent[-1], straight[-1]):
        assert float(np.linalg.norm(man.function(np.concatenate([st.q, s])))) <= 1e-15
    assert slip(straight) <= 1e-12
    assert slip(bent) > 1e-3 * R  # second order, on the second leg
    # the planner's measure (plan_object_motion refuses a path above ROLL_SLIP_TOL) agrees
    np.testing.assert_allclose(rolling_slip(man, np.array(bent)), slip(bent), rtol=1e-12)
    assert rolling_slip(man, np.array(straight)) <= 1e-12 < ROLL_SLIP_TOL < slip(bent)


def _roll_plan(scene: Scene) -> Plan:
    p = plan(scene, GOAL, options=PlannerOptions(sliding_motions=False))
    assert p.found, p.reason
    return p


@pytest.fixture(scope="module")
def roll_plan(scene: Scene) -> Plan:
    return _roll_plan(scene)


@pytest.mark.slow
def test_roll_plan_is_found_verified_and_rolls(scene: Scene, roll_plan: Plan) -> None:
    """Every object motion is FF (the finger's tip glued, the table rolling); the plan ends within
    the goal's 5 mm of 5 cm along +x; the sphere turned about +y by ``dx / r`` (rolling), its centre
    stayed at ``r``; verify_plan (which re-checks the rolling) finds no problem; the states after
    the motions carry the rolled table contact, so the table's contact point moved by the
    displacement and the sphere's by ``r`` times the turn."""
    p = roll_plan
    motions = [s for s in p.steps if s.transition.kind == "object_motion"]
    assert len(motions) >= 3 and all(s.transition.combination.count("F") == 2 for s in motions)
    d = p.displacement
    assert abs(d[0] - 0.05) <= 0.005 and abs(d[1]) <= 1e-9 and abs(d[2]) <= 1e-9
    np.testing.assert_allclose(d[3:], [0.0, d[0] / R, 0.0], atol=1e-9)
    assert verify_plan(scene, p) == []
    first, last = p.steps[0].before, p.steps[-1].after
    i0 = first.bodies().index("table")
    i1 = last.bodies().index("table")
    np.testing.assert_allclose(last.world_point(i1) - first.world_point(i0), [d[0], 0.0, 0.0], atol=1e-9)
    z0, z1 = first.contacts[i0].point_object, last.contacts[i1].point_object
    angle = float(np.arctan2(np.linalg.norm(np.cross(z0, z1)), z0 @ z1))
    np.testing.assert_allclose(R * angle, d[0], rtol=1e-8)
    np.testing.assert_allclose(last.contacts[i1].normal_object, -z1 / R, atol=1e-9)
    for a, b in itertools.pairwise(p.steps):
        assert a.after.key() == b.before.key()  # the next motion starts from the rolled contact


@pytest.mark.slow
def test_every_waypoint_rolls(scene: Scene, roll_plan: Plan) -> None:
    """From the plan's poses: at every waypoint of every object motion the centre is ``r`` over the
    table and the rows ``dp + r n x w`` from the step's start are zero (so the path lies on the
    rolling ray); between waypoints the material contact point does not move."""
    hand = HandKinematics.from_scene(scene)
    for step in roll_plan.steps:
        t = step.transition
        if t.kind != "object_motion":
            continue
        start = Pose.from_vector(t.object_path[0], 3)
        for a, b in itertools.pairwise(t.object_path):
            pa, pb = Pose.from_vector(a, 3), Pose.from_vector(b, 3)
            assert abs(float(pb.position[2]) - R) <= 1e-9
            s = pb.displacement_from(start)
            assert float(np.linalg.norm(s[:3] + R * np.cross(N, s[3:]))) <= 1e-9
            om = matrix_to_rotvec(pb.rotation @ pa.rotation.T)
            assert float(np.linalg.norm(pb.position - pa.position - R * np.cross(om, N))) <= 1e-9
        s1 = Pose.from_vector(t.object_path[-1], 3).displacement_from(start)
        man = motion_manifold(scene, hand, step.before, [i for i, ch in enumerate(t.combination) if ch != "D"])
        got = rolled_contacts(hand, scene, step.before, [i for i, ch in enumerate(t.combination) if ch != "D"],
                              t.q_path[-1], s1)
        j = step.before.bodies().index("table")
        assert man.plane_rolls and man.plane_rolls[0][0] == j
        np.testing.assert_allclose(got[j].point_object, step.after.contacts[step.after.bodies().index("table")]
                                   .point_object, atol=1e-9)


def _with_step(p: Plan, k: int, step: PlanStep) -> Plan:
    return replace(p, steps=(*p.steps[:k], step, *p.steps[k + 1:]))


@pytest.mark.slow
def test_verify_rejects_slipping_and_a_contact_left_behind(scene: Scene, roll_plan: Plan) -> None:
    """An object path whose sphere turns 0.01 rad more than it rolls is refused (slip, the travel on
    the table not ``r`` times the turn), and so is a state after a motion with the table contact's
    point on the sphere left where it was (the sphere rolled on)."""
    k = next(i for i, s in enumerate(roll_plan.steps) if s.transition.kind == "object_motion")
    step = roll_plan.steps[k]
    t = step.transition
    path = t.object_path.copy()
    path[:, 4] += np.linspace(0.0, 0.01, len(path))
    problems = verify_plan(scene, _with_step(roll_plan, k, replace(step, transition=replace(t, object_path=path))))
    assert any("slips" in m for m in problems), problems
    assert any("travels" in m and "on the plane" in m for m in problems), problems
    assert 0.01 * R > 1e3 * ROLL_TOL
    j = step.after.bodies().index("table")
    contacts = list(step.after.contacts)
    old = step.before.contacts[step.before.bodies().index("table")]
    contacts[j] = replace(contacts[j], point_object=old.point_object, normal_object=old.normal_object)
    left = replace(step, after=step.after.with_contacts(tuple(contacts)))
    problems = verify_plan(scene, _with_step(roll_plan, k, left))
    assert any("not a valid scene" in m or "where it rolled" in m for m in problems), problems


@pytest.mark.slow
def test_roll_plan_round_trips_through_its_json(scene: Scene, roll_plan: Plan) -> None:
    data = roll_plan.to_json()
    back = Plan.from_json(data, scene)
    assert back.to_json() == data
    assert verify_plan(scene, back) == []
