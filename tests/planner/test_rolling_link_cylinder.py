"""A cylinder rolling on a moving link's side, the axes parallel (issue 11 item 1; planner/link_roll.py).

examples/cylinder_link_roll.json: a cylinder lying on a table (axis along y) pushed from behind by
the side of a capsule link parallel to its axis, the line contact given by its two ends. Rolled
10 cm along +x (the table's two contacts rolling too), glued link points pivot the cylinder about
the line through them relative to the link and press it ``rho + r - sqrt(rho^2 + r^2 + 2 rho r
cos phi)`` into the link at both ends (1.76 mm); the integrated rolling path keeps both gaps at
round-off, the axes parallel, and slips at integration accuracy (second order in the step), the
contact line moving by the same length on the link and on the cylinder. Checked from the states
alone: the link's axis by an independent forward kinematics of the scene's joints (scipy
rotations), the gaps as distances of the cylinder's axis points from that axis (coal's GJK does
not separate a capsule lying along a cylinder), slip and travels in the link's frame."""

from __future__ import annotations

import numpy as np
import pytest
from closure_helpers import EXAMPLES
from roll_helpers import independent_link_axis
from scipy.spatial.transform import Rotation

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.pose import Pose
from analysis.scene import Scene
from planner import Goal, plan
from planner.link_roll import LINK_ROLL_SLIP_TOL, LinkRollingMotion, link_roll_check, link_rolls
from planner.manifold import pose_displacement, project_manifold
from planner.object_motion import link_rolling_motion, motion_manifold, rolled_contacts, rolling_slip
from planner.options import PlannerOptions
from planner.state import GraspState, state_from_scene
from planner.verify import verify_plan

SCENE = EXAMPLES / "cylinder_link_roll.json"
R, H, RHO = 0.5, 0.8, 0.05  # the cylinder's radius and length, the link's radius in SCENE
LINK = 2  # the finger's last link, the one the cylinder rolls on
ENDS, TABLE = (0, 1), (2, 3)  # contact indices in SCENE: the link's line contact, the table's
ALL = [*ENDS, *TABLE]
#: rolling on the table along +x: omega = (0, 1/r, 0) per unit of centre motion
TWIST = np.array([1.0, 0.0, 0.0, 0.0, 1.0 / R, 0.0])
DR = TWIST / np.linalg.norm(TWIST)
DISTANCE = 0.1 * float(np.linalg.norm(TWIST))  # the centre moves 10 cm


@pytest.fixture(scope="module")
def scene() -> Scene:
    return load_scene(SCENE)


@pytest.fixture(scope="module")
def setup(scene: Scene) -> tuple[HandKinematics, GraspState]:
    hand = HandKinematics.from_scene(scene)
    return hand, state_from_scene(scene, hand)


def _gaps(scene: Scene, q: np.ndarray, pose: Pose) -> tuple[list[float], float]:
    """The gap at each end ``z = -+H/2`` of the cylinder (its axis point's distance from the link's
    axis minus ``R + RHO``) and the sine of the angle between the two axes."""
    a, b, _ = independent_link_axis(scene, q, LINK)
    e = (b - a) / np.linalg.norm(b - a)
    axis = pose.rotation[:, 2]
    gaps = []
    for z in (-H / 2, H / 2):
        P = pose.position + z * axis
        d = P - a - ((P - a) @ e) * e
        gaps.append(float(np.linalg.norm(d)) - R - RHO)
    return gaps, float(np.linalg.norm(np.cross(axis, e)))


def _rolling(scene: Scene, hand: HandKinematics, st: GraspState, sticking: list[int],
             direction: np.ndarray | None = None) -> LinkRollingMotion:
    lm = link_rolling_motion(scene, hand, st, sticking, direction=direction)
    assert lm is not None
    return lm


def test_the_line_contact_rolls_when_the_axes_are_parallel(scene: Scene,
                                                           setup: tuple[HandKinematics, GraspState]) -> None:
    """Both ends of the link's line contact roll, the table's two on their manifold; one end alone,
    or the cylinder turned 0.01 rad about z (the axes no longer parallel), keep their glued points."""
    hand, st = setup
    lm = _rolling(scene, hand, st, ALL, DR)
    assert lm.rolls == ENDS and [k[0] for k in lm.base.plane_rolls] == list(TABLE) and not lm.base.items
    np.testing.assert_allclose(lm.offsets, [-H / 2, H / 2], atol=1e-12)
    assert link_rolls(hand, scene, st, [0, *TABLE]) == ()
    turned = Pose(st.pose.position, Rotation.from_rotvec([0.0, 0.0, 0.01]).as_matrix() @ st.pose.rotation, 3)
    assert link_rolls(hand, scene, st.with_pose(turned, st.q), ALL) == ()


def test_no_slip_rows_are_the_material_points_velocities(scene: Scene,
                                                         setup: tuple[HandKinematics, GraspState]) -> None:
    """At each end, ``no_slip(x) x'`` is the velocity of the cylinder's material point at the
    contact ``P_k - r u_k`` minus the link's there, by central differences of the
    two points' positions, at random ``x``, ``x'``."""
    hand, st = setup
    lm = _rolling(scene, hand, st, list(ENDS))
    ref = lm.refs[0]
    rng = np.random.default_rng(5)
    eps = 1e-6
    for _ in range(5):
        x = np.concatenate([st.q + 0.05 * rng.standard_normal(3), 0.02 * rng.standard_normal(3),
                            0.3 * rng.standard_normal(3)])
        xd = rng.standard_normal(9)
        q, s = x[:3], x[3:]
        pose = lm.pose(s)
        a, b, _ = independent_link_axis(scene, q, LINK)
        e = (b - a) / np.linalg.norm(b - a)
        rows = lm.no_slip(x) @ xd
        for k, z in enumerate((-H / 2, H / 2)):
            P = pose.position + z * pose.rotation[:, 2]
            t = float((P - a) @ e)
            u = P - (a + t * e)
            c = P - R * u / np.linalg.norm(u)  # the contact point on the cylinder
            on_obj, on_link = pose.to_local(c), hand.to_local(ref, c, q)

            def rel(sign: float, on_obj: np.ndarray = on_obj, on_link: np.ndarray = on_link,
                    q: np.ndarray = q, s: np.ndarray = s, xd: np.ndarray = xd) -> np.ndarray:
                return (lm.pose(s + sign * eps * xd[3:]).to_world(on_obj)
                        - hand.point_position(ref, on_link, q + sign * eps * xd[:3]))

            np.testing.assert_allclose(rows[3 * k: 3 * k + 3], (rel(1.0) - rel(-1.0)) / (2 * eps), atol=1e-7)


def _glued_path(scene: Scene, hand: HandKinematics, st: GraspState, steps: int = 100) -> np.ndarray:
    """The manifold before this change (the link's two points glued, the table rolling) along DR,
    progress held per step."""
    man = motion_manifold(scene, hand, st, ALL, direction=DR)
    x = np.concatenate([st.q, np.zeros(6)])
    X = [x]
    for k in range(steps):
        t = (k + 1) * DISTANCE / steps
        x, res = project_manifold(man, x + DISTANCE / steps * np.concatenate([np.zeros(hand.M), DR]),
                                  progress=(DR, t))
        assert res < 1e-10
        X.append(x)
    return np.array(X)


def test_glued_link_points_press_the_cylinder_into_the_link(scene: Scene,
                                                            setup: tuple[HandKinematics, GraspState]) -> None:
    """The "before": the two glued points pivot the cylinder about the line through them relative to
    the link, about the link's axis direction, across which the link's side is round (radius
    ``rho``), not flat as for the sphere: after 10 cm both axis points are ``|rho u + r R(phi) u|``
    from the link's axis, ``sqrt(rho^2 + r^2 + 2 rho r cos phi)`` (``phi`` the cylinder's turn
    against the link), both ends 1.76 mm into the link, the axes still parallel."""
    hand, st = setup
    X = _glued_path(scene, hand, st)
    q, pose = X[-1, :3], st.pose.displaced(X[-1, 3:])
    gaps, tilt = _gaps(scene, q, pose)
    _, _, R0 = independent_link_axis(scene, st.q, LINK)
    _, _, R1 = independent_link_axis(scene, q, LINK)
    phi = float(np.linalg.norm(Rotation.from_matrix((R1.T @ pose.rotation) @ (R0.T @ st.pose.rotation).T)
                               .as_rotvec()))
    np.testing.assert_allclose(gaps, np.sqrt(RHO**2 + R**2 + 2 * RHO * R * np.cos(phi)) - RHO - R, atol=1e-9)
    assert max(gaps) < -1.7e-3 and tilt < 1e-9  # 1.76 mm into the link at both ends


def test_the_rolling_path_keeps_both_gaps_and_does_not_slip(scene: Scene,
                                                            setup: tuple[HandKinematics, GraspState]) -> None:
    """The integrated path: both gaps below 1e-9 and the axes parallel at every state, the table
    contacts rolling (rolling_slip below 1e-12), each end's slip (link_roll_check) below 1e-6, of
    second order in the step, the contact moving by the same length on the link and on the
    cylinder; the rolled contacts on the link's surface (independent FK) and the cylinder's rim at
    their axial coordinates."""
    hand, st = setup
    lm = _rolling(scene, hand, st, ALL, DR)
    path = lm.integrate(DR, DISTANCE, steps=200)
    assert path.max_residual < 1e-10
    for x in path.X[::10]:
        gaps, tilt = _gaps(scene, x[:3], st.pose.displaced(x[3:]))
        assert max(abs(g) for g in gaps) < 1e-9 and tilt < 1e-9
    assert rolling_slip(lm.base, path.X[:, 3:]) < 1e-12
    np.testing.assert_allclose(path.X[-1, 3:], DISTANCE * DR, atol=1e-12)  # on the analysed ray
    checks = lm.checks(path.X)
    for z, chk in zip((-H / 2, H / 2), checks, strict=True):
        assert chk == link_roll_check(hand, lm.refs[0], R, path.X, st.pose, z, True)
        assert chk.slip < LINK_ROLL_SLIP_TOL and chk.max_gap < 1e-9 and chk.axis_angle < 1e-9
        assert chk.travel_link == pytest.approx(chk.travel_object, rel=1e-5)
        assert chk.travel_link > 0.012  # the contact line really moves round both
    assert path.slip == max(c.slip for c in checks)
    coarse = lm.integrate(DR, DISTANCE, steps=100)
    assert 3.5 < coarse.slip / path.slip < 4.5
    out = rolled_contacts(hand, scene, st, ALL, path.X[-1, :3], path.X[-1, 3:])
    q, pose = path.X[-1, :3], st.pose.displaced(path.X[-1, 3:])
    a, b, Rl = independent_link_axis(scene, q, LINK)
    e = (b - a) / np.linalg.norm(b - a)
    for i, z in zip(ENDS, (-H / 2, H / 2), strict=True):
        c_world = a + Rl @ out[i].point_body
        t = float((c_world - a) @ e)
        assert np.linalg.norm(c_world - (a + t * e)) == pytest.approx(RHO, abs=1e-9)
        np.testing.assert_allclose(pose.to_world(out[i].point_object), c_world, atol=1e-9)
        assert out[i].point_object[2] == pytest.approx(z, abs=1e-12)
        assert np.linalg.norm(out[i].point_object[:2]) == pytest.approx(R, abs=1e-12)
        P = pose.position + z * pose.rotation[:, 2]
        np.testing.assert_allclose(pose.R_d @ out[i].normal_object, (P - c_world) / R, atol=1e-9)
        assert np.linalg.norm(c_world - st.world_point(i)) > 0.05  # it moved
    for i in TABLE:
        assert abs(pose.to_world(out[i].point_object)[2]) < 1e-12  # the table contacts rolled too


GOAL = Goal(type="displacement", displacement=[0.05, 0.0, 0.0, 0.0, 0.0, 0.0], position_tolerance=0.005,
            rotation_tolerance="free")
OPTIONS = PlannerOptions(sliding_motions=False, effort_weight=0.0)


@pytest.mark.slow
def test_the_plan_rolls_on_the_link_and_verifies(scene: Scene) -> None:
    """Every step an FFFF object motion rolling on the link and the table (the integrated path),
    passing verify_plan (gaps, slip, travels, axis angle, the rolled contacts); recomputed here:
    both gaps below 1e-9 and the axes parallel at every waypoint, slip below 1e-6 per step, the
    cylinder turned by its displacement over ``R`` about y."""
    p = plan(scene, GOAL, options=OPTIONS)
    assert p.found, p.reason
    assert verify_plan(scene, p) == []
    hand = HandKinematics.from_scene(scene)
    ref = hand.resolve_body("f/2")
    assert ref is not None
    for step in p.steps:
        t = step.transition
        assert t.kind == "object_motion" and t.combination == "FFFF" and t.figures.ompl_planner_states == 0
        X = np.array([np.concatenate([q, pose_displacement(step.before, v)])
                      for q, v in zip(t.q_path, t.object_path, strict=True)])
        for x in X:
            gaps, tilt = _gaps(scene, x[:3], step.before.pose.displaced(x[3:]))
            assert max(abs(g) for g in gaps) < 1e-9 and tilt < 1e-9
        for i in ENDS:
            z = float(step.before.contacts[i].point_object[2])
            assert link_roll_check(hand, ref, R, X, step.before.pose, z, True).slip < 1e-6
    first, last = p.steps[0].before, p.steps[-1].after
    moved = last.position - first.position
    assert moved[0] > 0.045 and abs(moved[1]) < 1e-9
    turn = Rotation.from_matrix(last.pose.rotation @ first.pose.rotation.T).as_rotvec()
    np.testing.assert_allclose(turn, [0.0, moved[0] / R, 0.0], atol=1e-8)
