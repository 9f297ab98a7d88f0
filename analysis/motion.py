"""Motion space, finger redundancy and allowable motions (paper eq. 7, 19-21)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis import memo
from analysis._types import Array
from analysis.contacts import GraspSystem, Selection, constrained_matrices, letter_codes
from analysis.linalg import null_space, orth, pinv

#: Rows of ``B = A_d Phi_full`` with a norm at most this are zero (:attr:`MotionSpace.B`): the
#: allowability tolerance of a unit motion (``ALLOW_TOL`` of :mod:`analysis.dafc`).
NULL_ROW_TOL = 1e-7


@dataclass(frozen=True)
class MotionSpace:
    """Bases of the motions that keep the F/S/N contacts (eq. 7 and 19).

    ``[dq; dr] = Phi_full dzeta_c`` with ``dzeta_c = [dzeta~ (a_bar); dzeta~_r (a - a_bar)]``:
    the first ``a_bar`` coordinates move the object along the orthonormal columns of
    ``Lambda_r_t`` (with the least-norm finger motion ``Lambda_q_t``), the others are the finger
    redundancy ``Lambda_qr_t`` that leaves the object still.
    """

    M: int
    Lambda: Array  # (M + D, a)     eq. 7, orthonormal basis of null(A_c)
    Lambda_r_t: Array  # (D, a_bar)  Lambda~_r, orthonormal basis of range(Lambda_r)
    Lambda_q_t: Array  # (M, a_bar)  Lambda~_q, J_c Lambda~_q = G_c^T Lambda~_r
    Lambda_qr_t: Array  # (M, a - a_bar)  Lambda~_qr, orthonormal basis of null(J_c)
    A_c: Array  # (L_c, M + D)
    A_s: Array  # (d #S, M + D)
    A_d: Array  # (#D, M + D)

    def __post_init__(self) -> None:
        a_bar, r = self.Lambda_r_t.shape[1], self.Lambda_qr_t.shape[1]
        assert self.Lambda_q_t.shape == (self.M, a_bar)
        assert self.Lambda.shape[1] == a_bar + r, "dim null(A_c) must equal a_bar + dim null(J_c)"

    @property
    def a(self) -> int:
        return int(self.Lambda.shape[1])

    @property
    def a_bar(self) -> int:
        return int(self.Lambda_r_t.shape[1])

    @property
    def n_redundant(self) -> int:
        return int(self.Lambda_qr_t.shape[1])

    @property
    def D(self) -> int:
        return int(self.Lambda_r_t.shape[0])

    @property
    def Phi_full(self) -> Array:
        """``[[Lambda~_q, Lambda~_qr], [Lambda~_r, O]]``: ``(M + D, a)``, ``[dq; dr] = Phi_full dzeta_c``."""
        top = np.hstack([self.Lambda_q_t, self.Lambda_qr_t])  # (M, a)
        bottom = np.hstack([self.Lambda_r_t, np.zeros((self.D, self.n_redundant))])  # (D, a)
        return np.vstack([top, bottom])

    @property
    def Phi(self) -> Array:
        """``Phi = [Lambda~_r, O]``: ``(D, a)``, ``dr = Phi dzeta_c``."""
        return self.Phi_full[self.M :]

    @property
    def B(self) -> Array:
        """``A_d Phi_full``: ``(#D, a)``; the allowable set is ``{dzeta_c : B dzeta_c <= 0}`` (eq. 20).

        A row whose norm is at most :data:`NULL_ROW_TOL` is set to zero: that D-point's normal
        velocity is below the allowability tolerance for every unit motion (it can neither
        separate nor penetrate; its constraint row lies, up to rounding, in the row space of
        ``A_c``), so its sign is rounding noise. Kept, it cuts the allowable cone exactly (cdd)
        while the membership test accepts it within the tolerance, and a 1e-9 change of the
        contact data can then empty the cone (issue 9: FDFFFFDDD of the Baxter touch example).
        """
        B = self.A_d @ self.Phi_full  # (#D, a)
        if B.size:
            B[np.linalg.norm(B, axis=1) <= NULL_ROW_TOL] = 0.0
        return B

    @property
    def P_s(self) -> Array:
        """``P_s = -A_s Phi_full``: ``(d #S, a)``; sliding ``dp_Cs = P_s dzeta_c`` (eq. 21)."""
        return -self.A_s @ self.Phi_full

    def zeta_c(self, u: Array, zeta_r: Array | None = None) -> Array:
        """Stack object coordinates ``u`` (a_bar,) and redundancy (a - a_bar,) into ``dzeta_c``."""
        zr = np.zeros(self.n_redundant) if zeta_r is None else np.asarray(zeta_r, dtype=float)
        return np.concatenate([np.asarray(u, dtype=float), zr])

    def coordinates(self, dr: Array) -> Array:
        """Coordinates ``u = Lambda~_r^T dr`` of an object motion in the motion space."""
        return self.Lambda_r_t.T @ np.asarray(dr, dtype=float)


def motion_space(system: GraspSystem, sel: Selection) -> MotionSpace:
    """Eq. (7) ``Lambda = null(A_c)`` and its split (19) into object motion and redundancy.

    ``Lambda~_r = orth(Lambda_r)``; ``Lambda~_q = J_c^+ G_c^T Lambda~_r`` (least-norm finger
    motion that keeps the F/S/N constraints while the object moves, so ``A_c Phi_full = 0``);
    ``Lambda~_qr = null(J_c)``.
    """
    A_c, A_s, A_d = constrained_matrices(system, sel)
    M = system.M

    def bases() -> tuple[Array, Array, Array, Array]:
        Lam = null_space(A_c)  # (M + D, a)
        Lam_r_t = orth(Lam[M:])  # (D, a_bar)
        J_c = A_c[:, :M]  # (L_c, M)
        G_c_T = -A_c[:, M:]  # (L_c, D)
        Lam_q_t = pinv(J_c) @ G_c_T @ Lam_r_t if M else np.zeros((0, Lam_r_t.shape[1]))
        Lam_qr_t = null_space(J_c) if M else np.zeros((0, 0))
        return Lam, Lam_r_t, Lam_q_t, Lam_qr_t

    # a function of A_c and M only: remembered within a planner's search (analysis.memo)
    Lam, Lam_r_t, Lam_q_t, Lam_qr_t = memo.remembered(("motion_space", memo.exact_key(A_c), M), bases, lambda r: r)
    return MotionSpace(M, Lam, Lam_r_t, Lam_q_t, Lam_qr_t, A_c, A_s, A_d)


def _ranks(blocks: Array, letters: Array, chunk: int = 4096) -> Array:
    """Ranks of the stacked row blocks of many combinations, with the tolerance of
    :func:`analysis.linalg.rank` (``RANK_RTOL * max(1, s_max)`` of each matrix).

    ``blocks`` ``(L, 2, d, n)``: per contact its rows as an F-point (``d`` rows) and as an S/N-point
    (its normal row, then ``d - 1`` zero rows); ``letters`` ``(R, L)``: 0 for F, 1 for S/N, 2 for D.
    Each combination's matrix is padded with zero rows to ``(L d, n)`` (zero rows change no singular
    value but add zeros), so the SVDs run as one batched LAPACK call per chunk."""
    from analysis.linalg import RANK_RTOL  # the same tolerance as null_space/orth/rank

    L, _, d, n = blocks.shape
    R = letters.shape[0]
    out = np.zeros(R, dtype=int)
    padded = np.concatenate([blocks, np.zeros((L, 1, d, n))], axis=1)  # (L, 3, d, n): D = no rows
    rows = np.arange(L)
    for s in range(0, R, chunk):
        idx = letters[s : s + chunk]  # (k, L)
        mats = padded[rows[None, :], idx].reshape(idx.shape[0], L * d, n)  # (k, L d, n)
        if n == 0 or L * d == 0:
            continue
        sv = np.linalg.svd(mats, compute_uv=False)  # (k, min(L d, n))
        tol = RANK_RTOL * np.maximum(1.0, sv[:, 0])
        out[s : s + chunk] = np.sum(sv > tol[:, None], axis=1)
    return out


def motion_dims(system: GraspSystem, combinations: list[str]) -> tuple[Array, Array]:
    """``(a, a_bar)`` of eq. (7) and (19) for many combinations at once, without building their
    motion spaces: ``a = M + D - rank(A_c)`` and ``a_bar = a - dim null(J_c)`` (the split of
    :func:`motion_space`, whose :class:`MotionSpace` checks ``a = a_bar + dim null(J_c)``), the
    ranks with the tolerance of :mod:`analysis.linalg`. Returns two ``(R,)`` integer arrays."""
    L, d, M = system.L, system.d, system.M
    n = M + system.D
    blocks_A = np.zeros((L, 2, d, n))  # (L, 2, d, M + D)
    blocks_J = np.zeros((L, 2, d, M))
    for i in range(L):
        A_i = system.contact_A(i)  # (d, M + D)
        blocks_A[i, 0] = A_i
        blocks_A[i, 1, 0] = system.normals[i] @ A_i
        blocks_J[i, 0] = system.J_blocks[i]
        blocks_J[i, 1, 0] = system.normals[i] @ system.J_blocks[i]
    letters = letter_codes(combinations, L)  # (R, L)
    a = n - _ranks(blocks_A, letters)
    null_J = M - _group_ranks(system, blocks_J, letters) if M else np.zeros(len(combinations), dtype=int)
    return a, a - null_J


#: :func:`_group_ranks` leaves to the whole matrix's SVD the rows with a singular value within this
#: relative distance of the rank threshold (there the two computations may round apart).
GROUP_RANK_MARGIN = 1e-6


def _group_ranks(system: GraspSystem, blocks: Array, letters: Array) -> Array:
    """:func:`_ranks` of the stacked ``J_c`` rows ``blocks`` ``(L, 2, d, M)``, from the finger groups
    (:meth:`GraspSystem.joint_groups`): the groups' joints are disjoint and each contact's row block
    is zero off its group's joints, so ``J_c`` is block diagonal up to the order of rows and columns
    and its singular values are the union of those of the groups' blocks. Each group's block
    depends only on the letters of its contacts, so its singular values are computed once per
    pattern present (at most 3^k); the rank counts those above the threshold of :func:`_ranks`
    (``RANK_RTOL * max(1, s_max)``, ``s_max`` the largest over the groups). The few rows with a
    singular value within ``GROUP_RANK_MARGIN`` of that threshold are counted by :func:`_ranks` on
    the whole matrix, so the answer is that of :func:`_ranks`."""
    from analysis.linalg import RANK_RTOL

    L, _, d, _ = blocks.shape
    R = letters.shape[0]
    if R == 0:
        return np.zeros(0, dtype=int)
    padded = np.concatenate([blocks, np.zeros((L, 1, d, blocks.shape[3]))], axis=1)  # (L, 3, d, M)
    svs: list[Array] = []  # per group (R, m_g) singular values of its block, per row
    for C, Q in system.joint_groups():
        if not Q:
            continue  # a fixed-body contact: no rows in J_c
        k = len(C)
        key = letters[:, C].astype(np.int64) @ (3 ** np.arange(k, dtype=np.int64))  # (R,) the group's letters
        uniq, inv = np.unique(key, return_inverse=True)
        patterns = (uniq[:, None] // 3 ** np.arange(k, dtype=np.int64)) % 3  # (P, k) those present
        mats = padded[np.array(C)[None, :], patterns][..., Q].reshape(len(uniq), k * d, len(Q))
        sv = np.linalg.svd(mats, compute_uv=False)  # (P, m_g)
        svs.append(sv[inv.reshape(-1)])
    if not svs:
        return np.zeros(R, dtype=int)
    allsv = np.concatenate(svs, axis=1)  # (R, sum m_g)
    tol = RANK_RTOL * np.maximum(1.0, allsv.max(axis=1))  # (R,)
    out = np.sum(allsv > tol[:, None], axis=1)
    near = np.flatnonzero(np.any(np.abs(allsv - tol[:, None]) <= GROUP_RANK_MARGIN * tol[:, None], axis=1))
    if near.size:
        out[near] = _ranks(blocks, letters[near])
    return out
