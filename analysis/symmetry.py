"""Symmetries of a grasp's contact kinematics (eq. 1-2), to carry DAFC member motions across.

A symmetry is an orthogonal map ``R`` of the world frame ``(d, d)`` (a rotation or a reflection
about the object origin ``p_o``), a permutation ``pi`` of the contacts and a signed permutation
``P`` of the joints such that, for every contact ``i``,

    p_pi(i) - p_o = R (p_i - p_o),   n_pi(i) = R n_i,   mu_pi(i) = mu_i,   A_pi(i) T = R A_i,

with ``T = blockdiag(P, T_r)`` and ``T_r`` the map of object twists and wrenches (``R`` on the
linear part, ``det(R) R`` on the angular one in 3-D, ``det(R)`` in the plane: an angular velocity
is a pseudovector), and ``T_r w_ex = w_ex``. Then ``A_pi(i) (T v) = R (A_i v)``: the motion
``T v`` moves the contact ``pi(i)`` as ``v`` moves ``i``, turned by ``R``, so it keeps the same
contacts, slides the same ones (the slips turned by ``R``) and lets the same ones go. A DAFC member
motion of a combination ``c`` is therefore a candidate member of its image ``pi(c)`` (the letter
of contact ``i`` on contact ``pi(i)``).

The four fingers of ``examples/sphere_four_finger_wrap.json`` spaced by 90 degrees about the
vertical give such maps (the rotations by 90, 180 and 270 degrees, and the four reflections).

Only motions are carried over, never a verdict: the enumeration tries ``T v`` on ``pi(c)`` with
the force LPs of :func:`analysis.dafc_family.members_at`, which certify it for ``pi(c)`` in
physical units or decide nothing. So the maps need not be exact: they are accepted within
``TOL`` (the bundled scenes give their coordinates to 10 digits), and a friction pyramid whose
facets are not turned by ``R`` (its tangent basis comes from the world axes,
:func:`analysis.contacts.tangent_basis`) only means that the forces are found again for
``pi(c)``.
"""

from __future__ import annotations

import itertools
import operator
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.contacts import GraspSystem

#: Relative tolerance of the maps (points in units of the largest lever arm; normals, Jacobian
#: columns and the external wrench relative to their sizes).
TOL = 1e-6
#: Above this many contacts, no search for symmetries (the anchor pairs grow as ``L^2``).
MAX_CONTACTS = 32


@dataclass(frozen=True)
class Symmetry:
    """One map of the grasp onto itself (module docstring)."""

    perm: NDArray[np.intp]  # (L,) contact i goes to contact perm[i]
    R: Array  # (d, d) orthogonal map of the world frame
    T: Array  # (M + D, M + D) map of the motions [dq; dr]
    #: the largest relative mismatch of the mapped data (points, normals, rows of A, w_ex) and of
    #: the friction pyramids' generators (:attr:`GraspSystem.pyramid`, turned by ``R``, against
    #: those of the image contacts; inf where they do not match at all)
    residual: float = 0.0

    def combination(self, c: str) -> str:
        """The image of the combination ``c``: contact ``perm[i]`` takes the letter of ``i``."""
        pick: Callable[[str], Iterable[str]] | None = self.__dict__.get("_pick")
        if pick is None:  # the letters at ``inv`` in one C call (the enumeration maps millions)
            inv = self._inverse
            pick = operator.itemgetter(*inv) if inv else (lambda _: ())
            object.__setattr__(self, "_pick", pick)
        return "".join(pick(c))

    @property
    def _inverse(self) -> list[int]:
        """``inv`` with ``perm[inv[k]] = k`` (computed once)."""
        inv: list[int] | None = self.__dict__.get("_inv")
        if inv is None:
            inv = [0] * len(self.perm)
            for i, k in enumerate(self.perm.tolist()):
                inv[k] = i
            object.__setattr__(self, "_inv", inv)
        return inv

    def motion(self, v: Array) -> Array:
        """The image ``T v`` ``(M + D,)`` of a motion ``[dq; dr]``."""
        return self.T @ v


def twist_map(R: Array) -> Array:
    """``T_r`` ``(D, D)``: an object twist ``[v; omega]`` (or wrench ``[f; m]``) turned by ``R``."""
    det = float(np.sign(np.linalg.det(R)))
    if R.shape[0] == 2:
        return np.block([[R, np.zeros((2, 1))], [np.zeros((1, 2)), np.full((1, 1), det)]])
    return np.block([[R, np.zeros((3, 3))], [np.zeros((3, 3)), det * R]])


def _anchor(r: Array, n: Array) -> list[int] | None:
    """At most two contacts whose arms and normals span the space, or the plane (3-D: the rest
    by a cross product), or None."""
    d = r.shape[1]
    L = r.shape[0]
    for i in range(L):
        if np.linalg.matrix_rank(np.vstack([r[i], n[i]]), tol=1e-6) >= d:
            return [i]
    for i, j in itertools.combinations(range(L), 2):
        if np.linalg.matrix_rank(np.vstack([r[i], n[i], r[j], n[j]]), tol=1e-6) >= min(d, 3):
            return [i, j]
    if d == 3:
        for i, j in itertools.combinations(range(L), 2):
            if np.linalg.matrix_rank(np.vstack([r[i], n[i], r[j], n[j]]), tol=1e-6) == 2:
                return [i, j]
    return None


def _completion(cols: list[Array]) -> tuple[int, ...]:
    """Which of the anchors' vectors complete their span to the space: none (they span it), the
    largest one (2-D: its perpendicular) or the pair with the largest cross product (3-D)."""
    X = np.array(cols).T  # (d, k)
    d = X.shape[0]
    if np.linalg.matrix_rank(X, tol=1e-6) >= d:
        return ()
    if d == 2:
        return (int(np.argmax([np.linalg.norm(c) for c in cols])),)
    pairs = list(itertools.combinations(range(len(cols)), 2))
    return pairs[int(np.argmax([np.linalg.norm(np.cross(cols[a], cols[b])) for a, b in pairs]))]


def _frame(r: Array, n: Array, idx: tuple[int, ...], det: float, pick: tuple[int, ...]) -> Array:
    """The arms and normals of the contacts ``idx`` as columns, completed by the perpendicular
    (2-D) or cross product (3-D) of the vectors ``pick`` (:func:`_completion`) times ``det``
    (that column maps with ``det(R)``)."""
    cols = [v for i in idx for v in (r[i], n[i])]
    X = np.array(cols).T  # (d, k)
    if not pick:
        return X
    if len(pick) == 1:
        a = cols[pick[0]]
        return np.column_stack([X, det * np.array([-a[1], a[0]])])
    return np.column_stack([X, det * np.cross(cols[pick[0]], cols[pick[1]])])


def symmetries(system: GraspSystem) -> list[Symmetry]:
    """Every map of the grasp onto itself other than the identity (module docstring), found from
    the images of one or two anchor contacts and checked on every contact, or [] (also above
    ``MAX_CONTACTS`` contacts and without any joint or contact)."""
    sy = system
    L, d, M = sy.L, sy.d, sy.M
    if L == 0 or L > MAX_CONTACTS:
        return []
    r = sy.points - sy.p_o  # (L, d)
    n = sy.normals
    ell = max(1.0, float(np.max(np.linalg.norm(r, axis=1))))
    anchors = _anchor(r / ell, n)
    if anchors is None:
        return []
    fixed = ~np.any(sy.J_blocks != 0.0, axis=(1, 2))  # (L,) contacts on fixed bodies

    def like(i: int, j: int) -> bool:
        return bool(sy.mu[i] == sy.mu[j] and fixed[i] == fixed[j]
                    and abs(np.linalg.norm(r[i]) - np.linalg.norm(r[j])) <= TOL * ell
                    and abs(float(r[i] @ n[i]) - float(r[j] @ n[j])) <= TOL * ell)

    images = [[j for j in range(L) if like(i, j)] for i in anchors]
    pick = _completion([v for i in anchors for v in (r[i] / ell, n[i])])
    out: list[Symmetry] = []
    seen: set[bytes] = set()
    for img in itertools.product(*images):
        if len(set(img)) < len(img):
            continue
        for det in (1.0, -1.0):
            X = _frame(r / ell, n, tuple(anchors), 1.0, pick)
            Y = _frame(r / ell, n, tuple(img), det, pick)
            R = Y @ np.linalg.pinv(X)  # (d, d)
            if not np.allclose(R.T @ R, np.eye(d), atol=TOL) or abs(np.linalg.det(R) - det) > TOL:
                continue
            g = _complete(sy, R, r, ell)
            if g is None:
                continue
            key = g.perm.tobytes() + np.round(g.T, 6).tobytes()
            if key in seen or (np.array_equal(g.perm, np.arange(L)) and np.allclose(g.T, np.eye(M + sy.D))):
                continue
            seen.add(key)
            out.append(g)
    return out


def _complete(sy: GraspSystem, R: Array, r: Array, ell: float) -> Symmetry | None:
    """The contact and joint maps that go with ``R``, checked (``A_pi(i) T = R A_i`` for every
    contact, ``T_r w_ex = w_ex``), or None."""
    L, d, M = sy.L, sy.d, sy.M
    rr, nn = r @ R.T, sy.normals @ R.T  # (L, d) turned arms and normals
    perm = np.full(L, -1, dtype=np.intp)
    for i in range(L):
        dist = np.linalg.norm(r - rr[i], axis=1) / ell + np.linalg.norm(sy.normals - nn[i], axis=1)
        j = int(np.argmin(dist))
        if dist[j] > 2 * TOL or sy.mu[j] != sy.mu[i]:
            return None
        perm[i] = j
    if len(set(perm.tolist())) < L:
        return None
    Tr = twist_map(R)
    w = sy.w_ex
    if float(np.linalg.norm(Tr @ w - w)) > TOL * max(float(np.linalg.norm(w)), 1e-300):
        return None
    # the joints: column q of the turned Jacobians (rows of contact i moved to pi(i)) is column
    # sigma(q) of the scene's, times s_q = +-1
    turned = np.zeros((L, d, M))
    turned[perm] = np.einsum("ab,lbm->lam", R, sy.J_blocks)
    Jt = turned.reshape(L * d, M)  # (L d, M)
    J = sy.J  # (L d, M)
    scale = max(1.0, float(np.max(np.abs(J)))) if J.size else 1.0
    P = np.zeros((M, M))
    used = np.zeros(M, dtype=bool)
    for q in range(M):
        for s in (1.0, -1.0):
            err = np.max(np.abs(J - s * Jt[:, q : q + 1]), axis=0) if J.size else np.zeros(M)  # (M,)
            cand = np.flatnonzero((err <= TOL * scale) & ~used)
            if cand.size:
                P[int(cand[0]), q] = s
                used[int(cand[0])] = True
                break
        else:
            return None
    T = np.zeros((M + sy.D, M + sy.D))
    T[:M, :M] = P
    T[M:, M:] = Tr
    A = np.array([sy.contact_A(i) for i in range(L)])  # (L, d, M + D)
    lhs = A[perm] @ T  # (L, d, M + D)
    rhs = np.einsum("ab,lbn->lan", R, A)
    res_A = float(np.max(np.abs(lhs - rhs), initial=0.0)) / max(scale, ell)
    if res_A > TOL:
        return None
    res = max(res_A, float(np.max(np.abs(r @ R.T - r[perm]))) / ell,
              float(np.max(np.abs(sy.normals @ R.T - sy.normals[perm]))),
              float(np.linalg.norm(Tr @ w - w)) / max(float(np.linalg.norm(w)), 1e-300))
    gens = sy.pyramid[1]  # (L, k, d)
    for i in range(L):
        turned_g = gens[i] @ R.T  # (k, d)
        dist = np.linalg.norm(turned_g[:, None, :] - gens[int(perm[i])][None, :, :], axis=2)  # (k, k)
        size = max(float(np.max(np.linalg.norm(gens[i], axis=1), initial=0.0)), 1e-300)
        res = max(res, float(np.max(dist.min(axis=1), initial=0.0)) / size,
                  float(np.max(dist.min(axis=0), initial=0.0)) / size)
    return Symmetry(perm, R, T, res)
