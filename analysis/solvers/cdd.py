"""pycddlib adapter: vertex/ray enumeration of polyhedra and cones (double description).

Inputs and outputs are numpy arrays; cdd's failures are re-raised as :class:`SolverError`.
Floating-point arithmetic is used (a numerical inconsistency is retried on rounded unit rows,
``RETRY_DECIMALS``); generators are normalised (rays to unit length) and redundant ones removed
with ``matrix_canonicalize``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import cdd
import numpy as np

from analysis._types import Array
from analysis.exceptions import SolverError
from analysis.solvers.highs import LPModel

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
    gen = _generators(H, lin)
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


#: Significant digits of the rounded retries after cdd's "numerical inconsistency" (the standalone
#: pycddlib has no exact GMP arithmetic): rows scaled to unit norm and rounded, a perturbation of
#: the data of at most 1e-12, then 1e-9, relative.
RETRY_DECIMALS = (12, 9)


def _generators(H: Array, lin: list[int]) -> cdd.Matrix:
    """cdd's generators of the H-representation ``[b, -A]`` rows ``H`` (``lin``: equality rows);
    on a floating-point inconsistency, retried on unit rows rounded to ``RETRY_DECIMALS``."""

    def attempts() -> Iterator[Array]:
        """``H``, then (only after a failure) its unit rows rounded to each of ``RETRY_DECIMALS``."""
        yield H
        norms = np.linalg.norm(H, axis=1, keepdims=True)
        unit = H / np.where(norms > 0.0, norms, 1.0)
        for d in RETRY_DECIMALS:
            yield np.round(unit, d)

    error: Exception | None = None
    for data in attempts():
        try:
            mat = cdd.matrix_from_array(data.tolist(), lin_set=lin, rep_type=cdd.RepType.INEQUALITY)
            return cdd.copy_generators(cdd.polyhedron_from_matrix(mat))
        except (RuntimeError, ValueError) as e:
            error = e
    raise SolverError("cdd", str(error)) from error


def cone_generators(B: Array) -> Generators:
    """Generators of the cone ``{x : B x <= 0}`` (a single vertex at the origin)."""
    B = np.asarray(B, dtype=float)
    return polyhedron_generators(B, np.zeros(B.shape[0]))


def _unique_rows(A: Array, decimals: int = 10) -> Array:
    """Rows of ``A`` without (numerical) duplicates, first occurrence kept."""
    if A.shape[0] < 2:
        return A
    _, idx = np.unique(np.round(A, decimals), axis=0, return_index=True)
    return A[np.sort(idx)]


#: Above this many generators, redundancy is removed with HiGHS LPs (one per generator) instead
#: of cdd's canonicalisation, which is several times slower on a few hundred rows.
LP_REDUCTION_ABOVE = 24


def _reduce_by_lp(g: Generators) -> Generators:
    """Drop every vertex in the hull of the others plus the recession cone, and every ray in
    the cone of the other rays plus the lines (sequentially, so the set stays generating).

    One warm-started HiGHS model per kind: generator ``i`` is tested by fixing its own weight to
    zero and asking for the others to reproduce it.
    """
    V, R, Ln = g.vertices, g.rays, g.lines
    n = V.shape[1] if V.size else R.shape[1]
    keep_r = np.ones(len(R), dtype=bool)
    if len(R) > 1:
        A = np.vstack([R, Ln, -Ln]).T  # (n, k)
        model = LPModel(A.shape[1], A_eq=A, b_eq=np.zeros(n), lb=0.0)
        zero = np.zeros(A.shape[1])
        for i in range(len(R)):
            model.set_col_bounds(i, 0.0, 0.0)
            model.set_eq_rhs(R[i])
            if model.solve(zero).found:
                keep_r[i] = False  # stays fixed at zero: removed for the following tests
            else:
                model.set_col_bounds(i, 0.0, np.inf)
    R = R[keep_r]
    keep_v = np.ones(len(V), dtype=bool)
    if len(V) > 1:
        A = np.vstack([np.hstack([V, np.ones((len(V), 1))]), np.hstack([np.vstack([R, Ln, -Ln]),
                                                                          np.zeros((len(R) + 2 * len(Ln), 1))])]).T
        model = LPModel(A.shape[1], A_eq=A, b_eq=np.zeros(n + 1), lb=0.0)
        zero = np.zeros(A.shape[1])
        for i in range(len(V)):
            model.set_col_bounds(i, 0.0, 0.0)
            model.set_eq_rhs(np.r_[V[i], 1.0])
            if model.solve(zero).found:
                keep_v[i] = False
            else:
                model.set_col_bounds(i, 0.0, np.inf)
    return Generators(V[keep_v].reshape(-1, n), R.reshape(-1, n), Ln)


def _pointed(R: Array) -> bool:
    """Is ``cone(R)`` pointed (rays ``R`` ``(k, n)``, unit rows)? ``max sum lam`` s.t.
    ``R^T lam = 0``, ``0 <= lam <= 1`` is zero exactly then (tolerance ``1e-9``)."""
    if len(R) < 2:
        return True
    res = LPModel(len(R), A_eq=R.T, b_eq=np.zeros(R.shape[1]), lb=0.0, ub=1.0).solve(np.ones(len(R)), maximize=True)
    return bool(res.found and res.objective is not None and res.objective <= 1e-9)


def reduce_generators(g: Generators) -> Generators:
    """Remove redundant vertices/rays (cdd canonical V-representation).

    Duplicates (common after a linear map with a null space) are dropped first, since cdd's
    redundancy removal costs one LP per row. A pointed set (no lines, and no nonnegative
    combination of the rays vanishes: :func:`_pointed`) is reduced by HiGHS LPs
    (:func:`_reduce_by_lp`; the irredundant vertices and rays of a pointed polyhedron are unique,
    so the answer is cdd's); cdd's canonical form also finds implicit lines (opposite rays), so it
    is kept for the others. pycddlib 3.0.0's ``matrix_canonicalize`` aborts the whole process
    (``munmap_chunk(): invalid pointer``, not an exception) on some nearly parallel rays, e.g. the
    torque set of SSDDSSSDFDDF in ``sphere_wrap_three_link`` (one vertex, 19 rays in 16-D).
    """
    n = g.vertices.shape[1] if g.vertices.size else (g.rays.shape[1] if g.rays.size else g.lines.shape[1])
    g = Generators(_unique_rows(g.vertices), _unique_rows(g.rays), _unique_rows(g.lines))
    if len(g.vertices) + len(g.rays) > LP_REDUCTION_ABOVE or (not len(g.lines) and _pointed(g.rays)):
        return _reduce_by_lp(g)  # already irredundant: cdd's check would cost one LP per row again
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


def generators_to_inequalities(g: Generators) -> tuple[Array, Array, bool]:
    """H-representation ``A x <= b`` of ``conv(vertices) + cone(rays) + span(lines)``:
    ``(A (m, n), b (m,), has_equalities)``; ``has_equalities`` when the set lies in a hyperplane."""
    n = g.vertices.shape[1] if g.vertices.size else g.rays.shape[1]
    rows = [[1.0, *v] for v in g.vertices] + [[0.0, *r] for r in g.rays]
    lin = list(range(len(rows), len(rows) + len(g.lines)))
    rows += [[0.0, *ln] for ln in g.lines]
    try:
        mat = cdd.matrix_from_array(rows, lin_set=lin, rep_type=cdd.RepType.GENERATOR)
        H = cdd.copy_inequalities(cdd.polyhedron_from_matrix(mat))  # rows [b, -A]: b - A x >= 0
    except (RuntimeError, ValueError) as e:
        raise SolverError("cdd", str(e)) from e
    arr = np.array(H.array, dtype=float).reshape(-1, n + 1)
    keep = np.any(arr[:, 1:] != 0.0, axis=1)
    return -arr[keep, 1:], arr[keep, 0], bool(H.lin_set)
