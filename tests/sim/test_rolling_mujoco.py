"""Rolling in MuJoCo: a disk turned by a moment on the side of a link (examples/
planar_disk_rolling_link.json) rolls without slipping, its contact point moving along the link
by ``r`` times the disk's rotation relative to the link, and the planner's rolling manifold
(ContactManifold(rolling=True)) predicts where the contact ends up; the glued-point rows of an F
contact do not (they keep the contact where it was)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from closure_helpers import EXAMPLES

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from planner.manifold import ContactManifold
from planner.state import state_from_scene
from sim.mjcf import (
    OBJECT_BODY,
    OBJECT_GEOM,
    build_model,
    finger_qpos_addresses,
    joint_name,
    link_body_name,
    object_pose,
    reset_to_scene,
)

R = 0.3  # the scene disk's radius (MuJoCo's sphere is r - eps, its capsule rho + eps: same sum)


def _contact(model: mujoco.MjModel, data: mujoco.MjData, g1: int, g2: int) -> np.ndarray:
    """World position ``(2,)`` of the MuJoCo contact between geoms ``g1`` and ``g2``."""
    for j in range(data.ncon):
        c = data.contact[j]
        if {int(c.geom1), int(c.geom2)} == {g1, g2}:
            return np.array(c.pos[:2])
    raise AssertionError("the disk lost its contact with the link")


def _solve_object(man: ContactManifold, q: np.ndarray, dtheta: float) -> np.ndarray:
    """Object displacement ``s`` ``(3,)`` on the manifold with the hand at ``q``, the disk turned by
    ``dtheta`` (Newton on the contact rows and ``s_theta = dtheta``)."""
    s = np.array([0.0, 0.0, dtheta])
    for _ in range(50):
        x = np.concatenate([q, s])
        F = np.r_[man.function(x)[: man.contact_rows], s[2] - dtheta]
        if float(np.linalg.norm(F)) < 1e-12:
            return s
        J = np.vstack([man.jacobian(x)[: man.contact_rows, man.M:], [0.0, 0.0, 1.0]])
        s = s - np.linalg.solve(J, F)
    raise AssertionError("no point of the manifold for the simulated rotation")


def roll_in_mujoco(moment: float, arm_rate: float) -> dict[str, float]:
    """MuJoCo run of the scene (see the test) and the planner's predictions: the disk's turn
    relative to the link ``rel``, the contact's travel along the link ``travel``, the rolling
    manifold's predicted travel ``pred``, the glued point's ``glued`` and the distance
    ``centre_error`` of the predicted disk centre from MuJoCo's."""
    scene = load_scene(EXAMPLES / "planar_disk_rolling_link.json")
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    ref = hand.resolve_body("arm/0")
    assert ref is not None
    model = build_model(scene)
    data = mujoco.MjData(model)
    reset_to_scene(model, data)
    qa = finger_qpos_addresses(model, scene)
    q0 = data.qpos[qa].copy()
    model.jnt_stiffness[model.joint(joint_name("arm", 0)).id] = 1e4
    ob, og, lg = model.body(OBJECT_BODY).id, model.geom(OBJECT_GEOM).id, model.geom(link_body_name("arm", 0)).id
    dt = model.opt.timestep
    p_start = _contact(model, data, og, lg)
    th0 = float(data.qpos[model.jnt_qposadr[model.joint("object:theta").id]])
    for k in range(round(1.0 / dt)):
        t = k * dt
        rise = min(1.0, t / 0.01)
        data.xfrc_applied[ob] = rise * np.array([0.0, -1.0, 0.0, 0.0, 0.0, moment])
        model.qpos_spring[qa] = q0 + arm_rate * t
        mujoco.mj_step(model, data)
    mujoco.mj_forward(model, data)
    q1 = data.qpos[qa].copy()
    th1 = float(data.qpos[model.jnt_qposadr[model.joint("object:theta").id]])
    p_end = _contact(model, data, og, lg)

    rel = (th1 - th0) - float(q1[0] - q0[0])  # the disk's turn relative to the link
    travel = hand.to_local(ref, p_end, q1)[0] - hand.to_local(ref, p_start, q0)[0]  # along the link
    # the planner's prediction from MuJoCo's final joint angle and disk rotation
    roll = ContactManifold(hand, st, [0], scene=scene, rolling=True)
    s = _solve_object(roll, q1, th1 - th0)
    _, y, _, _ = roll.rolling_contact(0, np.concatenate([q1, s]))
    pred = hand.to_local(ref, y, q1)[0] - hand.to_local(ref, p_start, q0)[0]
    centre = object_pose(model, data, 2).position
    glued = ContactManifold(hand, st, [0])
    sg = _solve_object(glued, q1, th1 - th0)
    yg = glued.pose(sg).to_world(st.contacts[0].point_object)
    return {"rel": rel, "travel": float(travel), "pred": float(pred),
            "glued": float(hand.to_local(ref, yg, q1)[0] - hand.to_local(ref, p_start, q0)[0]),
            "centre_error": float(np.linalg.norm(roll.pose(s).position - centre))}


@pytest.mark.parametrize(("moment", "arm_rate"), [(-0.2, 0.0), (0.15, 0.0), (-0.2, 0.06)])
def test_disk_rolls_on_link_in_mujoco(moment: float, arm_rate: float) -> None:
    """The arm's joint is a stiff spring (1e4 N m/rad) towards ``q0 + arm_rate t``; the disk is
    pressed on the link by 1 N and turned by ``moment`` for 1 s. From MuJoCo: the contact's travel
    along the link (link frame) equals ``-r (dtheta - dphi)`` within 5 % (the disk on the link's
    left side; ``dphi`` the link's turn); the rolling manifold, given MuJoCo's final joint angle and
    disk rotation, puts the contact within 5 % of the travel of MuJoCo's (along the link), while
    the glued point misses by the whole travel."""
    f = roll_in_mujoco(moment, arm_rate)
    rel, travel = f["rel"], f["travel"]
    assert abs(rel) > 0.05  # it did turn
    assert abs(travel - (-R * rel)) <= 0.05 * abs(R * rel), f
    assert abs(f["pred"] - travel) <= 0.05 * abs(travel), f
    assert f["centre_error"] <= 0.05 * abs(travel) + 0.01 * R, f  # MuJoCo's sphere is r - eps
    assert abs(f["glued"] - travel) > 0.9 * abs(travel), f  # glued: the contact does not move
