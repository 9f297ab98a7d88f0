"""The cylinder of examples/cylinder_link_roll.json rolled 5 cm along the table while it rolls on the
side of the finger's capsule link lying along it (planner/link_roll.py;
tests/planner/test_rolling_link_cylinder.py), replayed continuously in MuJoCo with the plan's
torques (the link touching it through spheres at its line contact's ends, sim/mjcf.py): the
cylinder ends within 5 % of the planned displacement (position and rotation each), turned about
its own axis only by its displacement over ``r`` (rolling on the table), and MuJoCo's contact
point between cylinder and link moves across the axes by the same length on the link (link frame)
and on the cylinder (object frame), as far as the plan moved it (rolling on the link), to half of
MuJoCo's contact layer."""

from __future__ import annotations

import numpy as np
import pytest
from roll_helpers import roll_and_replay

from analysis.kinematics import HandKinematics
from analysis.rotations import matrix_to_rotvec
from planner.options import PlannerOptions

R = 0.5  # the cylinder's radius
LINK = "f/2"  # the rolling link (MuJoCo's body of it has the same name)
EPS = 0.005  # MuJoCo's contact layer: the link's capsule is 0.055 there (sim/mjcf.py, 0.05 in the scene)


@pytest.mark.slow
def test_cylinder_rolls_on_the_link_in_mujoco() -> None:
    scene, p, sim, p0, p1 = roll_and_replay("cylinder_link_roll",
                                            PlannerOptions(sliding_motions=False, effort_weight=0.0))
    assert all(s.transition.kind == "object_motion" for s in p.steps)  # no regrasp: it rolls on the link
    hand = HandKinematics.from_scene(scene)
    ref = hand.resolve_body(LINK)
    assert ref is not None and sim.final_q is not None
    assert sim.final_contacts is not None and LINK in sim.final_contacts, "the cylinder left the link"
    turn = matrix_to_rotvec(p1.rotation @ p0.rotation.T)  # (3,) world: about y, the cylinder's axis
    dx = float(p1.position[0] - p0.position[0])
    assert abs(turn[0]) + abs(turn[2]) < 0.02 * abs(turn[1])
    assert turn[1] == pytest.approx(dx / R, rel=0.05)  # no slip on the table
    # MuJoCo's contact at the end (near one end of the line) against the scene's contact at that end:
    # its travel on the link and on the cylinder (MuJoCo touches at distance 0 at the start, where
    # it reports no contact yet)
    x1 = sim.final_contacts[LINK]  # (3,) world
    first, last = p.steps[0].before, p.steps[-1].after
    ends = [i for i, b in enumerate(first.bodies()) if b == LINK]
    i = min(ends, key=lambda j: abs(float(first.world_point(j)[1] - x1[1])))
    x0 = first.world_point(i)
    # across the axes only: MuJoCo touches through spheres moved inwards along the line (sim/mjcf.py)
    d_link = hand.to_local(ref, x1, sim.final_q) - hand.to_local(ref, x0, first.q)  # (3,) link frame, axis y
    d_cyl = p1.to_local(x1) - first.pose.to_local(x0)  # (3,) object frame, axis z
    on_link, on_cylinder = float(np.hypot(d_link[0], d_link[2])), float(np.linalg.norm(d_cyl[:2]))
    planned = float(np.linalg.norm(last.contacts[i].point_body - first.contacts[i].point_body))
    print(f"MuJoCo: turn {turn[1]:.6f} rad for dx / r {dx / R:.6f}; contact travel on the link {on_link:.6f}, "
          f"on the cylinder {on_cylinder:.6f}; plan: {planned:.6f}; replay error position "
          f"{sim.error.relative_position:.4f}, rotation {sim.error.relative_rotation:.4f}")
    # MuJoCo's contact point lies within its contact layer (the capsule grown and the cylinder shrunk
    # by EPS): the travels to half of it (measured 8.87 mm on the link, 9.72 on the cylinder, 6.99
    # planned); a contact that did not roll on the link would not have moved on it
    assert on_link > 0.005 and on_cylinder > 0.005
    assert on_link == pytest.approx(on_cylinder, abs=EPS / 2)  # rolling on the link
    assert on_link == pytest.approx(planned, abs=EPS / 2)  # where the plan rolled it
