"""Orthonormal bases of null spaces and ranges (SVD with an explicit tolerance).

Each basis vector's sign is fixed (:func:`_canonical`): the SVD's choice of sign differs between
LAPACK/BLAS builds (the sign of a one-dimensional motion space flipped between two machines, and
with it every direction the reports print).
"""

from __future__ import annotations

import numpy as np

from analysis._types import Array

#: Singular values below ``RANK_RTOL * max(1, s_max)`` count as zero.
RANK_RTOL = 1e-7


def _tol(s: Array) -> float:
    return RANK_RTOL * max(1.0, float(s[0]) if s.size else 0.0)


#: the sign of a basis vector is set by its first component within this of its largest in size
PIVOT_TIE = 1e-9


def _canonical(B: Array) -> Array:
    """``B`` ``(n, k)`` with each column's sign fixed: positive on its pivot axis (the first
    component within :data:`PIVOT_TIE` of its largest in size). The SVD's vectors are unique up
    to sign where their singular values are distinct (ranges; a one-dimensional null space), so
    there the basis is canonical; a null space of dimension above one is not (its vectors may
    rotate inside it between LAPACK builds)."""
    out = B.copy()
    for j in range(out.shape[1]):
        a = np.abs(out[:, j])
        i = int(np.flatnonzero(a >= a.max() - PIVOT_TIE)[0])
        if out[i, j] < 0:
            out[:, j] = -out[:, j]
    return out


def null_space(A: Array, tol: float | None = None, canonical: bool = True) -> Array:
    """Orthonormal basis ``(n, n - rank)`` of ``{x : A x = 0}`` for ``A`` of shape ``(m, n)``.

    Singular values ``<= tol`` count as zero; by default ``tol = RANK_RTOL * max(1, s_max)``,
    the tolerance of :func:`rank`. ``canonical=False``: LAPACK's basis with its signs as they come,
    for callers whose result does not depend on the basis (projections, least-norm motions).
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[1]
    if A.shape[0] == 0 or n == 0:
        return np.eye(n)
    _, s, Vt = np.linalg.svd(A, full_matrices=True)
    rank = int(np.sum(s > (_tol(s) if tol is None else tol)))
    return _canonical(Vt[rank:].T) if canonical else Vt[rank:].T


def orth(A: Array) -> Array:
    """Orthonormal basis ``(m, rank)`` of the range of ``A`` of shape ``(m, n)``."""
    A = np.asarray(A, dtype=float)
    if A.size == 0:
        return np.zeros((A.shape[0], 0))
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    rank = int(np.sum(s > _tol(s)))
    return _canonical(U[:, :rank])


def rank(A: Array) -> int:
    A = np.asarray(A, dtype=float)
    if A.size == 0:
        return 0
    s = np.linalg.svd(A, compute_uv=False)
    return int(np.sum(s > _tol(s)))


def pinv(A: Array) -> Array:
    """Moore-Penrose pseudo-inverse with the same rank tolerance as :func:`rank`."""
    A = np.asarray(A, dtype=float)
    if A.size == 0:
        return np.zeros((A.shape[1], A.shape[0]))
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    keep = s > _tol(s)
    return (Vt[keep].T / s[keep]) @ U[:, keep].T
