"""A sphere rolling on a moving link's side (issue 11 item 1; planner/link_roll.py).

examples/sphere_link_roll.json: a sphere on a table held from behind by the middle of a capsule
link's side. Rolled 10 cm along +x (the table contact rolling too), a glued link point pivots the
sphere about it relative to the link and presses it ``r (1 - cos phi)`` into the link (8.5 mm);
the integrated rolling path keeps the gap at round-off and slips at integration accuracy (second
order in the step), the contact point moving by ``r phi`` on the link and on the sphere. Checked
from the states alone: link poses by an independent forward kinematics of the scene's joints
(scipy rotations), distances with coal, slip and travels in the link's frame."""

from __future__ import annotations

import coal
import numpy as np
import pytest
from closure_helpers import EXAMPLES
from roll_helpers import independent_link_axis
from scipy.spatial.transform import Rotation

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Scene
from planner import Goal, plan
from planner.link_roll import LINK_ROLL_SLIP_TOL, LinkRollingMotion, link_roll_check, link_rolls
from planner.manifold import pose_displacement, project_manifold
from planner.object_motion import link_rolling_motion, motion_manifold, rolled_contacts, rolling_slip
from planner.options import PlannerOptions
from planner.plan import Plan
from planner.state import GraspState, state_from_scene
from planner.verify import verify_plan

SCENE = EXAMPLES / "sphere_link_roll.json"
R, RHO = 0.5, 0.05  # the sphere's radius and the link's in SCENE
LINK, TABLE = 0, 1  # contact indices in SCENE
#: rolling on the table along +x: omega = (0, 1/r, 0) per unit of centre motion (v = r omega x n)
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


def _coal_gap(scene: Scene, q: np.ndarray, centre: np.ndarray) -> float:
    """Signed distance of the sphere at ``centre`` from the capsule link 2 (coal)."""
    a, b, _ = independent_link_axis(scene, q, 2)
    e = b - a
    L = float(np.linalg.norm(e))
    z = e / L
    x = np.cross(z, [0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.cross(z, [1.0, 0.0, 0.0])
    x = x / np.linalg.norm(x)
    Rc = np.column_stack([x, np.cross(z, x), z])
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    d = coal.distance(coal.Capsule(RHO, L), coal.Transform3s(Rc, 0.5 * (a + b)),
                      coal.Sphere(R), coal.Transform3s(np.eye(3), centre), req, res)
    return float(d)


def _rolling(scene: Scene, hand: HandKinematics, st: GraspState, sticking: list[int],
             direction: np.ndarray | None = None) -> LinkRollingMotion:
    lm = link_rolling_motion(scene, hand, st, sticking, direction=direction)
    assert lm is not None
    return lm


def _glued_path(scene: Scene, hand: HandKinematics, st: GraspState, steps: int = 100) -> np.ndarray:
    """Today's manifold (the link point glued, the table rolling) along DR, progress held per step."""
    man = motion_manifold(scene, hand, st, [LINK, TABLE], direction=DR)
    x = np.concatenate([st.q, np.zeros(6)])
    X = [x]
    for k in range(steps):
        t = (k + 1) * DISTANCE / steps
        x, res = project_manifold(man, x + DISTANCE / steps * np.concatenate([np.zeros(hand.M), DR]),
                                  progress=(DR, t))
        assert res < 1e-10
        X.append(x)
    return np.array(X)


def test_the_link_contact_rolls_and_the_table_rolls(scene: Scene, setup: tuple[HandKinematics, GraspState]) -> None:
    hand, st = setup
    lm = _rolling(scene, hand, st, [LINK, TABLE], DR)
    assert lm.rolls == (LINK,) and [k[0] for k in lm.base.plane_rolls] == [TABLE] and not lm.base.items
    assert link_rolls(hand, load_scene(EXAMPLES / "sphere_table_roll.json"), state_from_scene(
        load_scene(EXAMPLES / "sphere_table_roll.json")), [0, 1]) == ()  # a sharp tip: glued


def test_no_slip_rows_are_the_material_points_velocities(scene: Scene,
                                                         setup: tuple[HandKinematics, GraspState]) -> None:
    """``no_slip(x) x'`` is the velocity of the sphere's material point at the contact minus the
    link's there, by central differences of the two points' positions, at random ``x``, ``x'``."""
    hand, st = setup
    lm = _rolling(scene, hand, st, [LINK, TABLE])
    ref = lm.refs[0]
    rng = np.random.default_rng(3)
    eps = 1e-6
    for _ in range(5):
        x = np.concatenate([st.q + 0.05 * rng.standard_normal(3), 0.02 * rng.standard_normal(3),
                            0.3 * rng.standard_normal(3)])
        xd = rng.standard_normal(9)
        q, s = x[:3], x[3:]
        pose = lm.pose(s)
        a, b, _ = independent_link_axis(scene, q, 2)
        t = float(np.clip((pose.position - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1))
        u = pose.position - (a + t * (b - a))
        c = pose.position - R * u / np.linalg.norm(u)  # the contact point on the sphere
        on_obj, on_link = pose.to_local(c), hand.to_local(ref, c, q)

        def rel(sign: float, on_obj: np.ndarray = on_obj, on_link: np.ndarray = on_link,
                q: np.ndarray = q, s: np.ndarray = s, xd: np.ndarray = xd) -> np.ndarray:
            return (lm.pose(s + sign * eps * xd[3:]).to_world(on_obj)
                    - hand.point_position(ref, on_link, q + sign * eps * xd[:3]))

        np.testing.assert_allclose(lm.no_slip(x) @ xd, (rel(1.0) - rel(-1.0)) / (2 * eps), atol=1e-7)


def test_a_glued_link_point_presses_the_sphere_into_the_link(scene: Scene,
                                                             setup: tuple[HandKinematics, GraspState]) -> None:
    """The "before": the glued point pivots the sphere about it relative to the link; after 10 cm
    the coal distance is ``-r (1 - cos phi)``, ``phi`` the sphere's turn against the link."""
    hand, st = setup
    X = _glued_path(scene, hand, st)
    q, pose = X[-1, :3], st.pose.displaced(X[-1, 3:])
    gap = _coal_gap(scene, q, pose.position)
    _, _, R0 = independent_link_axis(scene, st.q, 2)
    _, _, R1 = independent_link_axis(scene, q, 2)
    phi = float(np.linalg.norm(Rotation.from_matrix((R1.T @ pose.rotation) @ (R0.T @ st.pose.rotation).T)
                               .as_rotvec()))
    assert gap == pytest.approx(-R * (1 - np.cos(phi)), abs=1e-6)
    assert gap < -8e-3  # 8.5 mm into the link


def test_the_rolling_path_keeps_the_gap_and_does_not_slip(scene: Scene,
                                                          setup: tuple[HandKinematics, GraspState]) -> None:
    """The integrated path: coal gap at every state below 1e-9, the table contact rolling (slip of
    rolling_slip below 1e-12), the link contact's slip (link_roll_check) below 1e-6, of second
    order in the step (halving it quarters the slip), and the contact point moving by ``r`` times
    the sphere's turn against the link on both surfaces (equal travels), where the link's
    independent forward kinematics says it lies."""
    hand, st = setup
    lm = _rolling(scene, hand, st, [LINK, TABLE], DR)
    path = lm.integrate(DR, DISTANCE, steps=200)
    assert path.max_residual < 1e-10
    for x in path.X[::10]:
        assert abs(_coal_gap(scene, x[:3], st.pose.displaced(x[3:]).position)) < 1e-9
    assert rolling_slip(lm.base, path.X[:, 3:]) < 1e-12
    np.testing.assert_allclose(path.X[-1, 3:], DISTANCE * DR, atol=1e-12)  # on the analysed ray
    chk = link_roll_check(hand, lm.refs[0], R, path.X, st.pose)
    assert chk.slip == path.slip < LINK_ROLL_SLIP_TOL
    assert chk.travel_link == pytest.approx(chk.travel_object, rel=1e-5)
    assert chk.travel_link == pytest.approx(R * chk.turn, rel=1e-5)  # in-plane: no spin about u
    assert chk.turn > 0.15  # the contact really moves: 8 cm on each surface
    coarse = lm.integrate(DR, DISTANCE, steps=100)
    assert 3.5 < coarse.slip / path.slip < 4.5
    # the rolled contact: on the link's surface (independent FK) and on the sphere
    out = rolled_contacts(hand, scene, st, [LINK, TABLE], path.X[-1, :3], path.X[-1, 3:])
    q, pose = path.X[-1, :3], st.pose.displaced(path.X[-1, 3:])
    a, b, Rl = independent_link_axis(scene, q, 2)
    c_world = a + Rl @ out[LINK].point_body
    t = float((c_world - a) @ (b - a) / ((b - a) @ (b - a)))
    assert 0 < t < 1 and np.linalg.norm(c_world - (a + t * (b - a))) == pytest.approx(RHO, abs=1e-9)
    np.testing.assert_allclose(pose.to_world(out[LINK].point_object), c_world, atol=1e-9)
    assert np.linalg.norm(out[LINK].point_object) == pytest.approx(R, abs=1e-12)
    np.testing.assert_allclose(pose.R_d @ out[LINK].normal_object, (pose.position - c_world) / R, atol=1e-9)
    assert np.linalg.norm(c_world - st.world_point(LINK)) > 0.05  # it moved on the link
    assert abs(pose.to_world(out[TABLE].point_object)[2]) < 1e-12  # the table contact rolled too


def test_on_a_still_link_it_is_the_plane_formula(scene: Scene, setup: tuple[HandKinematics, GraspState]) -> None:
    """Known answer: the link contact alone, the sphere rolled along the link's axis ``e`` (the
    capsule's side is flat along it): the twist ``v = r omega x u``, ``omega = u x e / r``, needs no
    hand motion, so the path is the plane case's ray, ``dp + r u x w = 0``, and the contact moves
    ``|dp|`` along the link and ``r |w|`` on the sphere (a great circle's arc)."""
    hand, st = setup
    a, b, _ = independent_link_axis(scene, st.q, 2)
    e = (b - a) / np.linalg.norm(b - a)
    u = (st.pose.position - st.world_point(LINK)) / R
    twist = np.concatenate([e, np.cross(u, e) / R])
    dr = twist / np.linalg.norm(twist)
    lm = _rolling(scene, hand, st, [LINK], dr)
    dist = 0.08 * float(np.linalg.norm(twist))  # 8 cm along the axis
    path = lm.integrate(dr, dist, steps=40)
    np.testing.assert_allclose(path.X[:, :3], np.tile(st.q, (len(path.X), 1)), atol=1e-12)
    s = path.X[-1, 3:]
    np.testing.assert_allclose(s, dist * dr, atol=1e-12)
    np.testing.assert_allclose(s[:3] + R * np.cross(u, s[3:]), 0.0, atol=1e-12)
    chk = link_roll_check(hand, lm.refs[0], R, path.X, st.pose)
    assert chk.slip < 1e-12 and chk.max_gap < 1e-9
    assert chk.travel_link == pytest.approx(0.08, rel=1e-9)
    # on the sphere a great circle's arc r |w|, summed as its 40 chords
    assert chk.travel_object == pytest.approx(40 * 2 * R * np.sin(np.linalg.norm(s[3:]) / 80), rel=1e-9)


GOAL = Goal(type="displacement", displacement=[0.05, 0.0, 0.0, 0.0, 0.0, 0.0], position_tolerance=0.005,
            rotation_tolerance="free")
#: effort_weight 0: with the default 0.1 the search prefers regrasping with the finger's tip (its
#: torques are smaller) to rolling on the link's side
OPTIONS = PlannerOptions(sliding_motions=False, effort_weight=0.0)


@pytest.fixture(scope="module")
def roll_plan(scene: Scene) -> Plan:
    p = plan(scene, GOAL, options=OPTIONS)
    assert p.found, p.reason
    return p


def test_the_plan_rolls_on_the_link_and_verifies(scene: Scene, roll_plan: Plan) -> None:
    """Every step an FF object motion rolling on the link (the integrated path, ``ompl_planner_states
    = 0``: rolling on a moving link is non-holonomic, no manifold of OMPL holds it), passing
    verify_plan (gap, slip, both travels, the rolled contact); recomputed here: coal gap below 1e-9
    at every waypoint, slip below 1e-6 per step, and the contact moved along the link by the summed
    travel."""
    assert verify_plan(scene, roll_plan) == []
    hand = HandKinematics.from_scene(scene)
    ref = hand.resolve_body("f/2")
    assert ref is not None
    travel = 0.0
    for step in roll_plan.steps:
        t = step.transition
        assert t.kind == "object_motion" and t.combination == "FF" and t.figures.ompl_planner_states == 0
        X = np.array([np.concatenate([q, pose_displacement(step.before, v)])
                      for q, v in zip(t.q_path, t.object_path, strict=True)])
        for x in X:
            assert abs(_coal_gap(scene, x[:3], step.before.pose.displaced(x[3:]).position)) < 1e-9
        chk = link_roll_check(hand, ref, R, X, step.before.pose)
        assert chk.slip < 1e-6
        travel += chk.travel_link
    first, last = roll_plan.steps[0].before, roll_plan.steps[-1].after
    moved = float(np.linalg.norm(last.contacts[last.bodies().index("f/2")].point_body
                                 - first.contacts[first.bodies().index("f/2")].point_body))
    assert moved > 0.015 and moved == pytest.approx(travel, rel=1e-3)  # along the link's straight side
    assert np.linalg.norm(last.position - first.position) > 0.045


@pytest.mark.slow
def test_a_glued_link_plan_fails_verification(scene: Scene, monkeypatch: pytest.MonkeyPatch) -> None:
    """The planner with the link contact glued (link_rolls patched to none while it plans):
    verify_plan, which follows the rolling, finds its object motions pressing the sphere into
    the link (gap) and off the rolling contact."""
    import planner.object_motion as om

    monkeypatch.setattr(om, "link_rolls", lambda *a, **k: ())
    p = plan(scene, GOAL, options=OPTIONS)
    monkeypatch.undo()
    assert p.found
    motions = [s for s in p.steps if s.transition.kind == "object_motion"
               and "f/2" in s.before.bodies() and s.transition.combination == "FF"]
    assert motions
    problems = verify_plan(scene, p)
    assert any("leaves the link's surface" in m or "leaves the contact manifold" in m for m in problems), problems
