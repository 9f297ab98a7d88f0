"""pycddlib adapter: vertex/ray enumeration of polyhedra and cones (double description).

Inputs and outputs are numpy arrays; cdd's failures are re-raised as :class:`SolverError`.
Floating-point arithmetic is used; generators are normalised (rays to unit length) and
redundant ones removed with ``matrix_canonicalize``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cdd
import numpy as np

from analysis._types import Array
from analysis.exceptions import SolverError

#: Entries below this magnitude in cdd's output are set to zero.
CLEAN_TOL = 1e-11


@dataclass(frozen=True)
class Generators:
    """``P = conv(vertices) + cone(rays) + span(lines)``."""

    vertices: Array  # (nv, n)
    rays: Array  # (nr, n) unit
    lines: Array  # (nl, n) unit

    @property
    def dim(self) -> int:
        return int(self.vertices.shape[1] if self.vertices.size else self.rays.shape[1])

    @property
    def is_empty(self) -> bool:
        return self.vertices.shape[0] == 0

    def map(self, T: Array) -> Generators:
        """Image under the linear map ``x -> T x`` (``T`` of shape ``(m, n)``), not reduced."""
        m = T.shape[0]
        return Generators(
            (self.vertices @ T.T).reshape(-1, m),
            _unit_rows((self.rays @ T.T).reshape(-1, m)),
            _unit_rows((self.lines @ T.T).reshape(-1, m)),
        )

    def all_directions(self) -> Array:
        """Rays and both signs of lines: generators of the recession cone ``(k, n)``."""
        return np.vstack([self.rays, self.lines, -self.lines]).reshape(-1, self.rays.shape[1])


def _unit_rows(R: Array) -> Array:
    if R.size == 0:
        return R
    norms = np.linalg.norm(R, axis=1)
    keep = norms > 1e-12
    return R[keep] / norms[keep, None]


def _clean(A: Array) -> Array:
    A = np.asarray(A, dtype=float)
    A[np.abs(A) < CLEAN_TOL] = 0.0
    return A


def polyhedron_generators(
    A_ub: Array, b_ub: Array, A_eq: Array | None = None, b_eq: Array | None = None
) -> Generators:
    """V-representation of ``{x : A_ub x <= b_ub, A_eq x = b_eq}``."""
    A_ub = np.asarray(A_ub, dtype=float)
    n = A_ub.shape[1]
    rows = [np.hstack([np.asarray(b_ub, dtype=float).reshape(-1, 1), -A_ub])]
    lin: list[int] = []
    if A_eq is not None and len(A_eq):
        A_eq = np.asarray(A_eq, dtype=float)
        start = A_ub.shape[0]
        rows.append(np.hstack([np.asarray(b_eq, dtype=float).reshape(-1, 1), -A_eq]))
        lin = list(range(start, start + A_eq.shape[0]))
    H = np.vstack(rows)
    if H.shape[0] == 0:
        return Generators(np.zeros((1, n)), np.zeros((0, n)), np.eye(n))
    try:
        mat = cdd.matrix_from_array(H.tolist(), lin_set=lin, rep_type=cdd.RepType.INEQUALITY)
        poly = cdd.polyhedron_from_matrix(mat)
        gen = cdd.copy_generators(poly)
    except (RuntimeError, ValueError) as e:  # pragma: no cover - cdd internal failure
        raise SolverError("cdd", str(e)) from e
    G = np.array(gen.array, dtype=float).reshape(-1, n + 1)
    lines_idx = set(gen.lin_set)
    verts, rays, lines = [], [], []
    for k, row in enumerate(G):
        if k in lines_idx:
            lines.append(row[1:])
        elif row[0] > 0.5:
            verts.append(row[1:] / row[0])
        else:
            rays.append(row[1:])
    if not verts and not np.any(H[:, 0]):
        # a homogeneous system is a cone: cdd lists its rays and lines only, the origin is implicit
        verts.append(np.zeros(n))
    return Generators(
        _clean(np.array(verts).reshape(-1, n)),
        _clean(_unit_rows(np.array(rays).reshape(-1, n))),
        _clean(_unit_rows(np.array(lines).reshape(-1, n))),
    )


def cone_generators(B: Array) -> Generators:
    """Generators of the cone ``{x : B x <= 0}`` (a single vertex at the origin)."""
    B = np.asarray(B, dtype=float)
    return polyhedron_generators(B, np.zeros(B.shape[0]))


def reduce_generators(g: Generators) -> Generators:
    """Remove redundant vertices/rays (cdd canonical V-representation)."""
    n = g.vertices.shape[1] if g.vertices.size else (g.rays.shape[1] if g.rays.size else g.lines.shape[1])
    rows = (
        [[1.0, *v] for v in g.vertices] + [[0.0, *r] for r in g.rays] + [[0.0, *ln] for ln in g.lines]
    )
    if not rows:
        return g
    lin = set(range(len(g.vertices) + len(g.rays), len(rows)))
    try:
        mat = cdd.matrix_from_array(rows, lin_set=lin, rep_type=cdd.RepType.GENERATOR)
        cdd.matrix_canonicalize(mat)
    except (RuntimeError, ValueError) as e:  # pragma: no cover
        raise SolverError("cdd", str(e)) from e
    G = np.array(mat.array, dtype=float).reshape(-1, n + 1)
    lset = set(mat.lin_set)
    verts = [r[1:] / r[0] for k, r in enumerate(G) if k not in lset and r[0] > 0.5]
    rays = [r[1:] for k, r in enumerate(G) if k not in lset and r[0] <= 0.5]
    lines = [r[1:] for k, r in enumerate(G) if k in lset]
    return Generators(
        _clean(np.array(verts).reshape(-1, n)),
        _clean(_unit_rows(np.array(rays).reshape(-1, n))),
        _clean(_unit_rows(np.array(lines).reshape(-1, n))),
    )
