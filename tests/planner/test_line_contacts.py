"""Line contacts of whole arms (issue 11): Baxter's elbows and forearms lying flat on the box's
sides (examples/baxter_hug_box_lines.json, each capsule's line contact written as its two end
points by ``ctp contacts``), and links sliding on a box's face (S at links,
:class:`planner.manifold.ContactManifold`).

* **The turn a point contact allows, a line contact resists.** With one point per link (the
  hand-made examples/baxter_hug_box.json) the arms can lift the box 3 cm while it tilts 0.078 rad
  about the faces' normal (the links turning on the faces about their contact points); with the
  line's two end points sticking, the object can move only along two directions, computed here
  independently (pinocchio's Jacobians, scipy's null space): a swing about the shoulders (the box
  goes up and forward alike and tilts) and a sideways one. That lift is not among them, and the
  planner finds no straight lift (position within 5 mm).
* **The lift the hug allows**: the swing, planned in 1 cm motions (line contacts: each motion
  ``motion_step`` long, re-analysed), verified (``verify_plan`` finds nothing, so every segment of
  the object path lies within 0.99 of its analysed direction and nothing penetrates), reaching
  the goal within its tolerance. Its MuJoCo replay: tests/sim/test_line_contact_replay.py.
* **A link sliding on a face**: the gap rows (the link's axis point the link's radius off the
  face's plane) and their Jacobian (finite differences), the contact after the motion on the face
  under the link's axis and within the face, the row of a forearm's contact at its elbow joint
  left out (the elbow's sticking contact holds the joint centre there), so the manifold is regular.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from independent_urdf import IndependentArm
from scipy.linalg import null_space, subspace_angles

from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Scene
from planner import Goal, plan
from planner.manifold import ContactManifold, project_manifold
from planner.options import PlannerOptions
from planner.state import StateAnalysis, state_from_scene
from planner.verify import verify_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
LINES = EXAMPLES / "baxter_hug_box_lines.json"
POINTS = EXAMPLES / "baxter_hug_box.json"
#: the point-contact plan's lift, its displacement (ctp plan examples/baxter_hug_box.json --goal pose --pose
#: '0.511962 0.0 0.963923 0 0 0' --position-tolerance 0.005 --rotation-tolerance 0.3): up 3.13 cm,
#: turned 0.078 rad about y, the faces' normal
POINT_LIFT = np.array([-0.00194, 0.0, 0.03133, 0.0, 0.07797, 0.0])
#: the swing the line contacts allow, 3 cm up (the goal of the lift the hug allows)
SWING = [0.0293, 0.0, 0.03, 0.0, -0.075, 0.0]
STRAIGHT = Goal(type="pose", pose=[0.511962, 0.0, 0.963923, 0, 0, 0], position_tolerance=0.005,
                rotation_tolerance=0.3)


@pytest.fixture(scope="module")
def lines() -> Scene:
    return load_scene(LINES)


def _independent_object_motions(path: Path) -> np.ndarray:
    """Orthonormal basis ``(6, a~)`` of the object motions ``(v, w)`` (velocity of ``p_o``, angular
    velocity) for which both arms have joint velocities keeping every arm contact's material
    points together (table contacts let go): the null space of ``[J_c, -G^T]`` from pinocchio."""
    data = json.loads(path.read_text())
    arms = [IndependentArm(f) for f in data["fingers"]]
    sizes = [len(a.chain) for a in arms]
    off = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    p_o = np.asarray(data["object"]["pose"]["position"], float)
    rows = []
    for c in data["contacts"]:
        if "/" not in c["body"]:
            continue
        fname, link = c["body"].split("/", 1)
        i = next(k for k, a in enumerate(arms) if a.name == fname)
        p = np.asarray(c["point"], float)
        J = np.zeros((3, off[-1] + 6))
        J[:, off[i]:off[i + 1]] = arms[i].point_jacobian(link, p)
        r = p - p_o
        J[:, off[-1]:off[-1] + 3] = -np.eye(3)
        J[:, off[-1] + 3:] = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])  # -(w x r)
        rows.append(J)
    N = null_space(np.vstack(rows), rcond=1e-10)  # (M + 6, k)
    return _orth(N[-6:])


def _proj(A: np.ndarray) -> np.ndarray:
    Q = _orth(A)
    return np.asarray(Q @ Q.T)


def _orth(A: np.ndarray) -> np.ndarray:
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    return np.asarray(U[:, s > 1e-8 * max(float(s[0]), 1e-300)])


def test_line_contacts_leave_the_object_a_swing_only(lines: Scene) -> None:
    hand = HandKinematics.from_scene(lines)
    state = state_from_scene(lines, hand)
    Lr = StateAnalysis.of(lines, state, hand).parts("FFFFFFFFDDDD").ms.Lambda_r_t  # (6, a~)
    ind = _independent_object_motions(LINES)
    assert Lr.shape[1] == 2 and ind.shape[1] == 2
    assert float(np.max(subspace_angles(Lr, ind))) < 1e-6
    # one of them is a swing about an axis parallel to the faces' normal, above and behind the box
    # (the shoulders): v = w x (p_o - c) with w along y
    k = int(np.argmax(np.abs(ind[4])))
    v, w = ind[:3, k], ind[3:, k]
    assert abs(w[1]) / np.linalg.norm(w) > 1 - 1e-9
    c = state.position - np.cross(v, w) / float(w @ w)  # the axis through c
    assert c[0] < state.position[0] - 0.3 and c[2] > state.position[2] + 0.3
    # the point contacts' lift (the planner's choice towards 3 cm up: the motion closest to it,
    # position weighted by 1/5 mm, rotation by 1/0.3 rad) goes straight up turning about y, the
    # faces' normal; it is not a motion of the line contacts
    pts = _independent_object_motions(POINTS)
    assert pts.shape[1] == 4
    wgt = np.r_[np.full(3, 1 / 0.005), np.full(3, 1 / 0.3)]
    rest = np.array([0.0, 0.0, 0.03, 0.0, 0.0, 0.0])
    u = pts @ np.linalg.lstsq(wgt[:, None] * pts, wgt * rest, rcond=None)[0]
    u /= np.linalg.norm(u)
    lift = POINT_LIFT / np.linalg.norm(POINT_LIFT)
    assert float(u @ lift) > 0.999  # what the point plan did (its chord)
    assert u[2] > 0.3 and u[4] > 0.9 and abs(u[0]) < 0.01
    assert float(np.linalg.norm(u - _proj(ind) @ u)) > 0.3


def test_the_straight_lift_has_no_plan_with_line_contacts(lines: Scene) -> None:
    p = plan(lines, STRAIGHT)
    assert not p.found and p.outcome == "no_plan"


def test_the_swing_is_planned_in_short_verified_motions(lines: Scene) -> None:
    goal = Goal(type="displacement", displacement=SWING, position_tolerance=0.003, rotation_tolerance=0.3)
    p = plan(lines, goal)
    assert p.found, p.reason
    assert verify_plan(lines, p) == []
    assert verify_plan(lines, type(p).from_json(p.to_json(), lines)) == []
    size = object_size(lines)
    step = PlannerOptions().motion_step * size
    assert len(p.steps) >= 5
    for k, s in enumerate(p.steps):
        t = s.transition
        assert t.kind == "object_motion" and set(t.combination[:8]) == {"F"}
        assert t.combination[8:] == ("DDDD" if k == 0 else "")
        assert float(np.linalg.norm(t.object_path[-1] - t.object_path[0])) <= 1.01 * step  # (along a curve)
    disp = p.final_pose - p.start_pose
    assert float(np.linalg.norm(disp[:3] - np.asarray(SWING[:3]))) <= 0.003
    assert disp[2] > 0.027  # up by at least 2.7 cm, as far forward
    assert abs(disp[0] - disp[2]) < 0.003


def _sliding_manifold(lines: Scene) -> tuple[ContactManifold, np.ndarray, HandKinematics]:
    hand = HandKinematics.from_scene(lines)
    state = state_from_scene(lines, hand)
    man = ContactManifold(hand, state, [0, 1, 4, 5], [2, 3, 6, 7], lines)  # elbows stick, forearms slide
    return man, np.concatenate([state.q, np.zeros(6)]), hand


def test_sliding_link_rows_and_their_jacobian(lines: Scene) -> None:
    man, x0, _ = _sliding_manifold(lines)
    assert float(np.max(np.abs(man.function(x0)))) < 1e-10
    # the forearms' contacts at the elbow joints have no row: the elbows' hold the joint centres
    assert man.contact_rows == 3 * 4 + 2
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(3):
        x = x0 + 0.05 * rng.standard_normal(x0.size)
        J = man.jacobian(x)
        Jn = np.column_stack([(man.function(x + h * e) - man.function(x - h * e)) / (2 * h) for e in np.eye(x.size)])
        np.testing.assert_allclose(J, Jn, atol=1e-7)
    # regular: the rank is the same at the start and at projected points around it
    r0 = np.linalg.matrix_rank(man.jacobian(x0), tol=1e-8)
    for _ in range(3):
        x, res = project_manifold(man, x0 + 0.01 * rng.standard_normal(x0.size))
        assert res < 1e-9
        assert np.linalg.matrix_rank(man.jacobian(x), tol=1e-8) == r0


def test_a_slid_contact_is_on_the_face_under_the_link(lines: Scene) -> None:
    man, x0, hand = _sliding_manifold(lines)
    rng = np.random.default_rng(5)
    half = np.asarray(lines.object.shape.size, float) / 2.0  # type: ignore[union-attr]
    for _ in range(5):
        x, res = project_manifold(man, x0 + 0.03 * rng.standard_normal(x0.size))
        assert res < 1e-9
        q = x[: hand.M]
        for k, i in enumerate([2, 3, 6, 7]):
            y, p_obj, n_obj = man.sliding_contact(k, x)
            np.testing.assert_allclose(n_obj, lines.contacts[i].normal, atol=1e-12)  # the face's, object frame
            assert abs(abs(p_obj[1]) - half[1]) < 1e-9  # on the side face's plane
            assert np.all(np.abs(p_obj) <= half + 1e-9)  # within the face
            if i in (2, 6):
                continue  # at the elbow joint: no row of its own (its axis point may leave the face
                #           at second order as the elbow rolls), still put on the face
            if abs(abs(p_obj[0]) - half[0]) < 1e-9:
                continue  # moved along the face to its edge (the forearm reaches past it)
            face = man.sliding_faces[k]
            assert face is not None
            a = hand.point_position(man.sliding[k], face[0], q)  # the link's axis point over it
            assert abs(float(np.linalg.norm(y - a)) - hand.body_radius(man.sliding[k])) < 1e-9
