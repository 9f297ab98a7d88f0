"""Basis signs (:mod:`analysis.linalg`): the SVD's sign of a basis vector differs between LAPACK
builds; each vector is returned positive on its pivot axis (its largest component), so a
one-dimensional null space, and a range with distinct singular values, come out the same for the
same subspace (a row order, a sign or a rotation of the matrix)."""

from __future__ import annotations

import numpy as np

from analysis.linalg import _canonical, null_space, orth

TOL = 1e-10


def _random_orthogonal(rng: np.random.Generator, n: int) -> np.ndarray:
    Q, R = np.linalg.qr(rng.standard_normal((n, n)))
    return Q * np.sign(np.diag(R))


def _pivots_positive(B: np.ndarray) -> bool:
    return all(B[int(np.argmax(np.abs(B[:, j]))), j] > 0 for j in range(B.shape[1]))


def test_signs_are_fixed_and_the_span_kept() -> None:
    rng = np.random.default_rng(7)
    B = np.linalg.qr(rng.standard_normal((6, 3)))[0]  # (6, 3)
    C = _canonical(B * np.array([1.0, -1.0, -1.0]))
    assert _pivots_positive(C)
    np.testing.assert_allclose(C @ C.T, B @ B.T, rtol=0, atol=TOL)
    np.testing.assert_allclose(np.abs(C), np.abs(B), rtol=0, atol=0)  # only signs change
    np.testing.assert_allclose(_canonical(-C), C, rtol=0, atol=0)


def test_a_one_dimensional_null_space_has_a_fixed_sign() -> None:
    rng = np.random.default_rng(3)
    A = rng.standard_normal((2, 3))  # (2, 3): null space of dimension 1
    N = null_space(A)
    assert N.shape == (3, 1) and _pivots_positive(N)
    np.testing.assert_allclose(A @ N, 0.0, rtol=0, atol=TOL)
    for M in (-A, A[::-1], _random_orthogonal(rng, 2) @ A):  # the same null space
        np.testing.assert_allclose(null_space(M), N, rtol=0, atol=TOL)


def test_a_range_with_distinct_singular_values_is_canonical() -> None:
    rng = np.random.default_rng(5)
    A = rng.standard_normal((6, 3)) @ rng.standard_normal((3, 7))  # (6, 7) of rank 3
    N, U = null_space(A), orth(A)
    assert N.shape == (7, 4) and U.shape == (6, 3)
    assert _pivots_positive(N) and _pivots_positive(U)
    np.testing.assert_allclose(A @ N, 0.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(U @ (U.T @ A), A, rtol=0, atol=1e-9)
    # A R has the same left singular vectors (R orthogonal): the same basis, signs included
    np.testing.assert_allclose(orth(A @ _random_orthogonal(rng, 7)), U, rtol=0, atol=1e-9)
    np.testing.assert_allclose(orth(-A), U, rtol=0, atol=1e-9)


def test_a_non_canonical_null_space_spans_the_same_space() -> None:
    """``null_space(canonical=False)`` (issue 9, speed): an orthonormal basis of the same null space
    as the canonical one, on seeded rank-deficient matrices: ``A N = 0``, ``N^T N = I`` and the
    same projector ``N N^T``."""
    rng = np.random.default_rng(3)
    for m, n, r in [(5, 9, 3), (12, 22, 10), (4, 4, 2), (6, 3, 3)]:
        A = rng.standard_normal((m, r)) @ rng.standard_normal((r, n))  # (m, n) of rank r
        N = null_space(A, canonical=False)
        C = null_space(A)
        assert N.shape == C.shape == (n, n - r)
        np.testing.assert_allclose(A @ N, 0.0, atol=1e-10)
        np.testing.assert_allclose(N.T @ N, np.eye(n - r), atol=1e-12)
        np.testing.assert_allclose(N @ N.T, C @ C.T, atol=1e-12)
