"""Mesh files for the tests: an ASCII STL of a box (the mesh-object and URDF-geometry tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_box_stl(path: Path, half: np.ndarray) -> None:
    """Write an ASCII STL of the box ``|x_k| <= half_k`` ``(3,)``: each face two triangles, with
    its outward normal."""
    lines = ["solid box"]
    for k in range(3):
        i, j = [m for m in range(3) if m != k]
        for s in (-1.0, 1.0):
            ring = []
            for u, v in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                x = np.zeros(3)
                x[k], x[i], x[j] = s * half[k], u * half[i], v * half[j]
                ring.append(x)
            n = np.zeros(3)
            n[k] = s
            for tri in ((ring[0], ring[1], ring[2]), (ring[0], ring[2], ring[3])):
                lines.append(f"facet normal {n[0]} {n[1]} {n[2]}\nouter loop")
                lines += [f"vertex {x[0]} {x[1]} {x[2]}" for x in tri]
                lines.append("endloop\nendfacet")
    lines.append("endsolid box")
    path.write_text("\n".join(lines) + "\n")
