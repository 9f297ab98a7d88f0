"""A unit cube with its faces against planes: the floor and walls of a corner as fixed boxes.

The mode-enumeration benchmark of Huang, Cheng and Mason ("Efficient Contact Mode Enumeration
in 3D", WAFR 2020): a unit cube centred at the origin with its corners against the first ``k``
planes of ``PLANES`` (the floor ``z = -0.5``, then the walls ``x = -0.5``, ``y = -0.5``,
``x = +0.5``, ``y = +0.5``), four corner contacts a plane, has ``PUBLISHED_CS_COUNTS[k - 1]``
contacting/separating modes. Each plane is a fixed box 0.1 thick on the far side of its face; a
corner touching two or three planes is a contact of each (a vertex-face contact, with the normal
of the plane it touches).

``grid = n`` puts an ``n x n`` grid of contacts on each touching face instead of its corners
(``n = 2``). A non-positive affine function on a square vanishes on a face of the square (none,
a vertex, an edge, all of it), so interior grid points never change which corners may separate:
the contacting/separating modes are those of the corners, whatever ``n``.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

#: plane name -> (axis, side): the plane is ``x_axis = side * 0.5``, touching that face of the cube.
PLANES: dict[str, tuple[int, int]] = {
    "floor": (2, -1),
    "wall_x-": (0, -1),
    "wall_y-": (1, -1),
    "wall_x+": (0, 1),
    "wall_y+": (1, 1),
}
#: Contacting/separating modes of the cube against the first 1, 2, 3, 4, 5 planes (the paper).
PUBLISHED_CS_COUNTS = (10, 46, 136, 10, 2)


def cube_in_planes(k: int, grid: int = 2, mu: float = 0.5) -> dict[str, Any]:
    """The scene (a dict of the scene format) of the unit cube against the first ``k`` planes of
    ``PLANES``, ``grid x grid`` contacts on each touching face (``4 k`` contacts for ``grid = 2``),
    contacts plane by plane; gravity ``-z`` on the cube."""
    fixed: list[dict[str, Any]] = []
    contacts: list[dict[str, Any]] = []
    ticks = np.linspace(-0.5, 0.5, grid).tolist()
    for name in list(PLANES)[:k]:
        axis, side = PLANES[name]
        size = [4.0, 4.0, 4.0]
        size[axis] = 0.1
        position = [0.0, 0.0, 0.0]
        position[axis] = side * 0.55
        fixed.append({"name": name, "shape": {"type": "box", "size": size, "position": position}})
        normal = [0.0, 0.0, 0.0]
        normal[axis] = -float(side)  # into the cube
        others = [a for a in range(3) if a != axis]
        for u, v in itertools.product(ticks, repeat=2):
            point = [0.0, 0.0, 0.0]
            point[axis] = side * 0.5
            point[others[0]], point[others[1]] = u, v
            contacts.append({"body": name, "point": point, "normal": normal, "mu": mu})
    return {
        "name": f"cube-{k}-planes" + ("" if grid == 2 else f"-grid{grid}"),
        "description": f"a unit cube against {k} planes ({', '.join(list(PLANES)[:k])}), {len(contacts)} contacts",
        "dim": 3,
        "object": {"pose": {"position": [0.0, 0.0, 0.0], "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
                   "shape": {"type": "box", "size": [1.0, 1.0, 1.0]}},
        "external_wrench": [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
        "fixed_bodies": fixed,
        "fingers": [],
        "contacts": contacts,
    }
