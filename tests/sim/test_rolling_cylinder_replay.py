"""The cylinder roll (tests/planner/test_rolling_cylinder.py: a finger rolls the cylinder of
examples/cylinder_table_roll.json, lying on its side, 5 cm along the table) replayed continuously in
MuJoCo with the plan's torques: the cylinder ends within 5 % of the planned displacement, position
and rotation each, having turned about its own axis only (no yaw, no tilt), its centre moved by
``r`` times MuJoCo's turn within 5 % (rolling without slipping), and MuJoCo's contact with the
table moved by that much on the table, where the plan put the contact line (within 5 %)."""

from __future__ import annotations

import numpy as np
import pytest
from roll_helpers import roll_and_replay

from analysis.rotations import matrix_to_rotvec

R = 0.5  # the cylinder's radius
TABLE = "world"  # MuJoCo's body of the fixed bodies' geoms (the table is the only one)


@pytest.mark.slow
def test_cylinder_roll_replays_with_the_rolling_kinematics() -> None:
    _, p, sim, p0, p1 = roll_and_replay("cylinder_table_roll")
    turn = matrix_to_rotvec(p1.rotation @ p0.rotation.T)  # (3,) MuJoCo's turn
    theta = float(turn[1])  # about the cylinder's axis, world +y
    assert theta > 0.05 and float(np.linalg.norm(turn[[0, 2]])) <= 0.01 * theta
    dp = p1.position - p0.position
    assert abs(float(dp[0]) - R * theta) <= 0.05 * R * theta, (dp, R * theta)
    assert sim.start_contacts is not None and sim.final_contacts is not None
    assert TABLE in sim.start_contacts and TABLE in sim.final_contacts, "the cylinder left the table"
    on_table = float(np.linalg.norm((sim.final_contacts[TABLE] - sim.start_contacts[TABLE])[:2]))
    assert abs(on_table - R * theta) <= 0.05 * R * theta, (on_table, R * theta)
    first, last = p.steps[0].before, p.steps[-1].after
    planned = float(np.linalg.norm(last.world_point(1) - first.world_point(1)))  # an end of the contact line
    assert abs(on_table - planned) <= 0.05 * planned, (on_table, planned)
