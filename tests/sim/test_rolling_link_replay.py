"""The sphere of examples/sphere_link_roll.json rolled 5 cm along the table while it rolls on the
side of the finger's capsule link (planner/link_roll.py; tests/planner/test_rolling_link_3d.py),
replayed continuously in MuJoCo with the plan's torques: the sphere ends within 5 % of the planned
displacement (position and rotation each), and MuJoCo's contact point between sphere and link
moves, on the link (link frame) and on the sphere (object frame), by ``r`` times the sphere's turn
against the link within 5 % (rolling without slipping), as far as the plan moved it on the link
(within 5 %); a glued link point would not have moved on either."""

from __future__ import annotations

import numpy as np
import pytest
from roll_helpers import roll_and_replay

from analysis.kinematics import HandKinematics
from analysis.rotations import matrix_to_rotvec
from planner.options import PlannerOptions

R = 0.5  # the sphere's radius
LINK = "f/2"  # the rolling link (MuJoCo's body of it has the same name)


@pytest.mark.slow
def test_sphere_rolls_on_the_link_in_mujoco() -> None:
    # effort_weight 0: without it the search prefers regrasping with the finger's tip (its torques
    # are smaller) to rolling on the link's side
    scene, p, sim, p0, p1 = roll_and_replay("sphere_link_roll",
                                            PlannerOptions(sliding_motions=False, effort_weight=0.0))
    assert all(s.transition.kind == "object_motion" for s in p.steps)  # no regrasp: it rolls on the link
    hand = HandKinematics.from_scene(scene)
    ref = hand.resolve_body(LINK)
    assert ref is not None and sim.start_q is not None and sim.final_q is not None
    assert sim.start_contacts is not None and sim.final_contacts is not None
    assert LINK in sim.start_contacts and LINK in sim.final_contacts, "the sphere left the link"
    x0, x1 = sim.start_contacts[LINK], sim.final_contacts[LINK]  # (3,) world
    (RL0, _), (RL1, _) = hand.body_pose(ref, sim.start_q), hand.body_pose(ref, sim.final_q)
    phi = float(np.linalg.norm(matrix_to_rotvec((RL1.T @ p1.rotation) @ (RL0.T @ p0.rotation).T)))
    assert phi > 0.03  # the sphere turned against the link (0.041 rad: 2 cm on each surface)
    on_link = float(np.linalg.norm(hand.to_local(ref, x1, sim.final_q) - hand.to_local(ref, x0, sim.start_q)))
    z0, z1 = p0.to_local(x0), p1.to_local(x1)  # the contact point on the sphere, object frame
    on_sphere = R * float(np.arctan2(np.linalg.norm(np.cross(z0, z1)), z0 @ z1))
    print(f"MuJoCo: turn against the link {phi:.6f} rad, contact travel on the link {on_link:.6f}, on the sphere "
          f"{on_sphere:.6f}, r phi {R * phi:.6f}")
    for travel in (on_link, on_sphere):
        assert abs(travel - R * phi) <= 0.05 * R * phi, (travel, R * phi)  # rolling kinematics
    first, last = p.steps[0].before, p.steps[-1].after
    i0, i1 = first.bodies().index(LINK), last.bodies().index(LINK)
    planned = float(np.linalg.norm(last.contacts[i1].point_body - first.contacts[i0].point_body))
    print(f"plan: contact travel on the link {planned:.6f}; replay error position {sim.error.relative_position:.4f}, "
          f"rotation {sim.error.relative_rotation:.4f}")
    assert abs(on_link - planned) <= 0.05 * planned, (on_link, planned)  # where the plan rolled it
