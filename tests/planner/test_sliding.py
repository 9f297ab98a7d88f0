"""Object motions with sliding contacts (S, eq. 5 and 11-12): the contact manifold with gap rows,
and a pose goal reached by sliding the disk along the palm."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.exceptions import SceneError
from analysis.kinematics import HandKinematics
from analysis.scene import Box, Scene
from planner import Goal, plan
from planner.manifold import ContactManifold
from planner.state import state_from_scene, state_scene
from planner.verify import verify_plan
from sim.plan_replay import simulate_plan
from sim.step_replay import replay_plan
from sim.torque_replay import simulate_torques


def test_sliding_rows_jacobian_matches_finite_differences(planar_scene: Scene) -> None:
    """Gap rows of a fixed body (palm) and of a finger link, next to F-point rows."""
    hand = HandKinematics.from_scene(planar_scene)
    st = state_from_scene(planar_scene, hand)
    bodies = st.bodies()
    palm, link = bodies.index("palm"), next(i for i, b in enumerate(bodies) if b != "palm")
    sticking = [i for i in range(st.L) if i not in (palm, link)]
    man = ContactManifold(hand, st, sticking, [palm, link], planar_scene)
    assert man.rows == 2 * len(sticking) + 2
    x0 = np.concatenate([st.q, np.zeros(man.D)])
    assert float(np.linalg.norm(man.function(x0))) < 1e-9  # the scene's contacts touch
    rng = np.random.default_rng(7)
    for _ in range(3):
        x = x0 + 0.02 * rng.standard_normal(len(x0))
        Jn = np.column_stack([(man.function(x + e) - man.function(x - e)) / 2e-7 for e in 1e-7 * np.eye(len(x))])
        np.testing.assert_allclose(man.jacobian(x), Jn, atol=1e-6)
    # the palm's gap row depends on the object's position only, along the palm normal (+y)
    row = man.jacobian(x0)[2 * len(sticking)]
    np.testing.assert_allclose(row[: hand.M], 0.0, atol=1e-12)
    np.testing.assert_allclose(row[hand.M:], [0.0, 1.0, 0.0], atol=1e-6)


def test_a_link_slides_on_a_disk_a_sphere_or_a_face(planar_scene: Scene) -> None:
    """On a box a link's contact slides only on a face (tests/planner/test_line_contacts.py): the
    disk's contact put on a box it does not lie on is refused, naming the contact."""
    hand = HandKinematics.from_scene(planar_scene)
    st = state_from_scene(planar_scene, hand)
    boxed = planar_scene.model_copy(update={"object": planar_scene.object.model_copy(
        update={"shape": Box(type="box", size=[1.0, 1.0])})})
    with pytest.raises(SceneError, match=r"contacts\.0: a sliding contact of a link .*face"):
        ContactManifold(hand, st, [], [0], boxed)


@pytest.fixture(scope="module")
def slide_plan(planar_scene: Scene):  # type: ignore[no-untyped-def]
    return plan(planar_scene, Goal(type="pose", pose=[0.1, 0.5, 0.0], tolerance=0.02))


def test_pose_goal_is_reached_by_sliding_on_the_palm(planar_scene: Scene, slide_plan) -> None:  # type: ignore[no-untyped-def]
    p = slide_plan
    assert p.found, p.reason
    slides = [s for s in p.steps if s.transition.kind == "object_motion" and "S" in s.transition.combination]
    assert slides, [s.transition.combination for s in p.steps]
    assert float(np.linalg.norm(np.asarray(p.final_pose) - [0.1, 0.5, 0.0])) <= 0.02
    assert verify_plan(planar_scene, p) == []
    for s in slides:
        t = s.transition
        i = t.combination.index("S")
        assert t.contacts_before[i] == "palm" and "palm" in t.contacts_after
        before = s.before.contacts[s.before.bodies().index("palm")]
        after = s.after.contacts[s.after.bodies().index("palm")]
        dx = float(t.object_path[-1][0] - t.object_path[0][0])
        assert dx > 0  # towards the goal
        # the contact point moves along the palm with the disk; it stays at the bottom of the disk
        assert after.point_body[0] - before.point_body[0] == pytest.approx(dx, abs=1e-6)
        assert after.point_body[1] == pytest.approx(0.0, abs=1e-9)
        np.testing.assert_allclose(s.after.world_point(s.after.bodies().index("palm")), after.point_body[:2],
                                   atol=1e-9)
        np.testing.assert_allclose(s.after.world_normal(s.after.bodies().index("palm")), [0.0, 1.0], atol=1e-6)


def test_sliding_steps_replay_in_mujoco(planar_scene: Scene, slide_plan) -> None:  # type: ignore[no-untyped-def]
    """Each sliding motion, replayed with its torque from T, moves the disk as planned (5 %), the
    palm contact slides and the fingertips stick."""
    r = replay_plan(planar_scene, slide_plan)
    assert not r.dropped
    assert all(s.ok for s in r.steps), [s.note for s in r.steps if not s.ok]
    assert r.relative_error <= 0.05
    step = next(s for s in slide_plan.steps if "S" in s.transition.combination)
    t = step.transition
    hand = HandKinematics.from_scene(planar_scene)
    assert t.tau is not None
    res = simulate_torques(state_scene(planar_scene, step.before, hand), t.tau, duration=2.0,
                           combination=t.combination,
                           stop_distance=float(np.linalg.norm(t.object_path[-1] - t.object_path[0])))
    assert [c.observed for c in res.contacts] == ["slide" if ch == "S" else "stick" for ch in t.combination]
    assert all(c.agrees for c in res.contacts)


def test_sliding_plan_replays_continuously(planar_scene: Scene, slide_plan) -> None:  # type: ignore[no-untyped-def]
    """The whole pose plan (regrasps, then six sliding motions) in one MuJoCo run ends within 5 %
    of the planned displacement and never drops the disk."""
    r = simulate_plan(planar_scene, slide_plan)
    assert not r.dropped, r.drop_reason
    assert r.relative_error <= 0.05
    slides = [s for s in r.steps if "S" in s.combination]
    assert slides and all(s.simulated[0] > 0.9 * s.planned[0] for s in slides)
