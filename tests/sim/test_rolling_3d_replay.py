"""The 3-D rolling plan (tests/planner/test_rolling_3d.py: a finger rolls the sphere of
examples/sphere_table_roll.json 5 cm along the table) replayed continuously in MuJoCo with the
plan's torques (T, 32): the sphere ends within 5 % of the planned displacement, position and
rotation each, and MuJoCo's contact point between sphere and table moves, on the table and on the
sphere, by ``r`` times the sphere's turn within 5 % (rolling without slipping), where the plan put
it (also within 5 %); a glued table point would not have moved at all."""

from __future__ import annotations

import numpy as np
import pytest
from roll_helpers import roll_and_replay

from analysis.rotations import matrix_to_rotvec

R = 0.5  # the sphere's radius
TABLE = "world"  # MuJoCo's body of the fixed bodies' geoms (the table is the only one)


@pytest.mark.slow
def test_sphere_roll_replays_with_the_rolling_kinematics() -> None:
    _, p, sim, p0, p1 = roll_and_replay("sphere_table_roll")
    assert sim.start_contacts is not None and sim.final_contacts is not None
    assert TABLE in sim.start_contacts and TABLE in sim.final_contacts, "the sphere left the table"
    turn = matrix_to_rotvec(p1.rotation @ p0.rotation.T)  # (3,) MuJoCo's turn of the sphere
    assert abs(float(turn[2])) <= 0.01 * float(np.linalg.norm(turn))  # no spin about the table's normal
    theta = float(np.linalg.norm(turn))
    assert theta > 0.05
    x0, x1 = sim.start_contacts[TABLE], sim.final_contacts[TABLE]  # (3,) world
    on_table = float(np.linalg.norm((x1 - x0)[:2]))
    z0, z1 = p0.to_local(x0), p1.to_local(x1)  # the contact point on the sphere, object frame
    on_sphere = R * float(np.arctan2(np.linalg.norm(np.cross(z0, z1)), z0 @ z1))
    for travel in (on_table, on_sphere):
        assert abs(travel - R * theta) <= 0.05 * R * theta, (travel, R * theta)  # rolling kinematics
    first, last = p.steps[0].before, p.steps[-1].after
    planned = float(np.linalg.norm(last.world_point(last.bodies().index("table"))
                                   - first.world_point(first.bodies().index("table"))))
    assert abs(on_table - planned) <= 0.05 * planned, (on_table, planned)  # where the plan rolled it
