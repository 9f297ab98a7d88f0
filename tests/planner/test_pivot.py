"""A box tipped onto its edge by a link (issue 11, a pivot): the Panda's forearm sticks across the
box's far top edge (F), the two table corners on the near bottom edge stick (F) and the two far
ones separate (D), and the box turns about the near edge. The goal is a displacement: the turn by
0.2 rad about that edge (about -y through the edge's midpoint), position part the edge-fixed
motion of ``p_o``. Two scenes: examples/panda_forearm_box.json (the push's box; its pivot is
marginal: the forearm can turn it only just before the near corners slide, so the torque set's
work is small) and examples/panda_forearm_tall_box.json (a taller, narrower box on a grippier
table, replayed in MuJoCo by tests/sim/test_pivot_replay.py). Checked: the D-set the goal lifts,
the analysed direction (a rotation about the edge), the plan (found, every object segment along
its analysed direction, verified, the edge's corners on the table, the box's rotation the
goal's)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.pose import Pose
from analysis.scene import Scene
from planner import Goal, plan
from planner.motion_edges import _goal_lifted_contacts
from planner.object_motion import MIN_DIRECTION_COSINE, direction_cosines
from planner.plan import Plan
from planner.state import state_from_scene
from planner.verify import verify_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TURN = 0.2  # rad, about -y (the box's top goes towards -x, where the forearm pushes it)
POSITION_TOL = 0.003  # m
ROTATION_TOL = 0.01  # rad
AXIS = np.array([0.0, -1.0, 0.0])


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' formula, independent of analysis.pose: R = I + sin K + (1 - cos) K^2."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def edge_point(scene: Scene) -> np.ndarray:
    """The midpoint of the pivot edge: the box's near bottom edge (smallest x, on the table)."""
    p = np.asarray(scene.object.pose.position, float)
    half = np.asarray(scene.object.shape.size, float) / 2  # type: ignore[union-attr]
    return np.array([p[0] - half[0], p[1], p[2] - half[2]])


def pivot_displacement(scene: Scene, angle: float = TURN) -> list[float]:
    """``[dx, dy, dz, rx, ry, rz]``: ``p_o`` turned by ``angle`` about the pivot edge, and the turn."""
    p = np.asarray(scene.object.pose.position, float)
    c = edge_point(scene)
    moved = c + _rot(AXIS, angle) @ (p - c) - p
    return [float(v) for v in (*moved, *(angle * AXIS))]


@pytest.fixture(scope="module", params=["panda_forearm_box.json", "panda_forearm_tall_box.json"])
def box_scene(request: pytest.FixtureRequest) -> Scene:
    return load_scene(EXAMPLES / request.param)


def _corners(scene: Scene) -> tuple[list[int], list[int]]:
    """(the table corners on the pivot edge, the others)."""
    table = [i for i, c in enumerate(scene.contacts) if c.body == "table"]
    on_edge = [i for i in table if abs(scene.contacts[i].point[0] - edge_point(scene)[0]) < 1e-9]
    return on_edge, [i for i in table if i not in on_edge]


def test_the_goal_lifts_the_corners_off_the_pivot_edge_only(box_scene: Scene) -> None:
    st = state_from_scene(box_scene)
    on_edge, off_edge = _corners(box_scene)
    assert len(on_edge) == 2 and len(off_edge) == 2
    table = tuple(on_edge + off_edge)
    fixed = tuple(sorted(table))
    assert _goal_lifted_contacts(st, fixed, np.asarray(pivot_displacement(box_scene))) == tuple(sorted(off_edge))
    # a turn the other way lifts the other edge
    assert _goal_lifted_contacts(st, fixed, -np.asarray(pivot_displacement(box_scene))) == tuple(sorted(on_edge))
    # no pivot: a push along the table lifts none, a lift lifts them all (both: no D-subset)
    assert _goal_lifted_contacts(st, fixed, np.array([-0.1, 0.0, 0.0, 0.0, 0.0, 0.0])) == ()
    assert _goal_lifted_contacts(st, fixed, np.array([0.0, 0.0, 0.05, 0.0, 0.0, 0.0])) == ()


@pytest.fixture(scope="module")
def pivot_plan(box_scene: Scene) -> Plan:
    return plan(box_scene, Goal(type="displacement", displacement=pivot_displacement(box_scene),
                                position_tolerance=POSITION_TOL, rotation_tolerance=ROTATION_TOL))


def test_the_box_is_tipped_about_its_edge(box_scene: Scene, pivot_plan: Plan) -> None:
    p = pivot_plan
    assert p.found, p.reason
    on_edge, off_edge = _corners(box_scene)
    assert p.steps and all(s.transition.kind == "object_motion" for s in p.steps)
    first = p.steps[0].transition
    expect = "".join("D" if i in off_edge else "F" for i in range(len(box_scene.contacts)))
    assert first.combination == expect == "FFFDD"  # the forearm and the edge stick, the far corners separate
    assert all(s.transition.combination == "FFF" for s in p.steps[1:])  # then on the edge alone
    start = Pose.from_vector(np.asarray(p.start_pose), 3)
    for s in p.steps:
        t = s.transition
        assert t.torque_set is not None
        dr = np.asarray(t.torque_set["direction"], float)
        # every object segment within cosine 0.99 of the analysed direction (the torque's motion)
        S = np.array([Pose.from_vector(v, 3).displacement_from(s.before.pose) for v in t.object_path])
        assert direction_cosines(S, dr).min() >= MIN_DIRECTION_COSINE
        # the analysed direction is a turn about the pivot edge: angular part along -y, and the
        # velocity of p_o is w x (p_o - c) for c on the edge (the edge's points do not move)
        w = dr[3:]
        assert float(w @ AXIS) / float(np.linalg.norm(w)) > 1 - 1e-9
        c = s.before.pose.to_world(start.to_local(edge_point(box_scene)))
        np.testing.assert_allclose(dr[:3], np.cross(w, s.before.position - c), atol=1e-9)
        # the pivot edge's corners stay where they were on the table
        for v in t.object_path:
            pose = Pose.from_vector(v, 3)
            for i in on_edge:
                x = pose.to_world(start.to_local(np.asarray(box_scene.contacts[i].point, float)))
                assert float(np.linalg.norm(x - box_scene.contacts[i].point)) < 1e-4
    # the far corners lifted by the first step (its separations), the box turned by the goal's angle
    assert min(first.figures.separations) > 0  # type: ignore[union-attr]
    final = Pose.from_vector(np.asarray(p.final_pose), 3)
    goal_R = _rot(AXIS, TURN) @ start.rotation
    angle = float(np.arccos(np.clip((np.trace(final.rotation @ goal_R.T) - 1) / 2, -1, 1)))
    assert angle <= ROTATION_TOL
    target = np.asarray(p.start_pose[:3]) + np.asarray(pivot_displacement(box_scene)[:3])
    assert float(np.linalg.norm(final.position - target)) <= POSITION_TOL
    depth = float(box_scene.object.shape.size[0])  # type: ignore[union-attr]
    for i in off_edge:  # the far corners are in the air, at depth sin(turn) (within the tolerance)
        x = final.to_world(start.to_local(np.asarray(box_scene.contacts[i].point, float)))
        assert abs(x[2] - depth * np.sin(TURN)) <= depth * ROTATION_TOL + POSITION_TOL


def test_the_pivot_verifies(box_scene: Scene, pivot_plan: Plan) -> None:
    assert pivot_plan.found, pivot_plan.reason
    assert verify_plan(box_scene, pivot_plan) == []
    hand = HandKinematics.from_scene(box_scene)
    again = Plan.from_json(pivot_plan.to_json(), box_scene, hand)
    assert verify_plan(box_scene, again) == []
