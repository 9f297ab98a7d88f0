"""DAFC (22) members shared along a family of combinations.

A member of DAFC for one combination is a motion ``[dq; dr]`` (F-points stick, S-points slide,
D-points do not penetrate) and contact forces (friction set, passive equalities ``Xi^T w = 0``,
grip bound) whose net wrench ``w = G_eff f_c + w_ex`` does positive work along ``dr``. Let a
contact that carries no force in it (an F-, S- or N-point with force at most ``ZERO_FORCE F0``) go:
the combination with that contact D

* keeps the motion: the contact was kept (``n^T A_j v = 0``), so it does not penetrate, and the
  other contacts keep their states and slips;
* keeps the forces: the contact carried none, so ``f_c`` and ``w`` are those of the source;
* keeps ``W_2``: its motion space ``null(A_c)`` has fewer rows, so its object motions
  ``range(Lambda~_r)`` contain the source's, and the net wrench, which lies in the source's, lies
  in them (``Xi^T w = 0`` with ``Xi`` orthogonal to them).

So the member of one combination is a member of every combination that turns any subset of its
force-free contacts to D (:meth:`MemberCertificate.family`). It is used for such a combination
only after :meth:`MemberCertificate.check` re-checks it in physical units for that combination:
the motion (stick, slide, no penetration, with absolute tolerances), the friction rows, the
grip bound, the passive part of ``w`` off the object motions and, constructively, that the object
part of ``w`` is an object motion of the combination (a motion of its null space, residual at
rounding level), and the work above the threshold.

The dimension of DAFC for the combination is that of its allowable cone ``A_r`` (eq. 20), as the
per-combination search reports it for a member in the interior of ``A_r`` (for non-degenerate
data the member has a neighbourhood of members in ``A_r``); :meth:`FamilyKinematics.separating`
proves ``A_r`` full-dimensional (then of dimension ``a_bar``) with a motion that separates every
D-point strictly.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.combination import CombinationParts
from analysis.contacts import GraspSystem, letter_codes, selection
from analysis.dafc import ALLOW_TOL, SLIP_TOL, DirectionTest
from analysis.friction import kinetic_friction
from analysis.linalg import RANK_RTOL, null_space
from analysis.motion import NULL_ROW_TOL
from analysis.scales import FORCE_TOL, GRIP_BOUND, LP_FEAS_TOL, snap
from analysis.solvers.highs import solve_sparse_lp

#: Kinematic equalities of a reused motion (F sticks, S/N keeps contact), relative to its size:
#: far above rounding (~1e-15), far below any motion.
MOTION_TOL = 1e-9
#: A D-point separates strictly (:meth:`FamilyKinematics.separating`) when ``n^T A_j v`` is below
#: minus this fraction of the motion's size.
STRICT_TOL = 1e-9
#: A D-point's normal velocity row on an orthonormal basis of the motion space below this is
#: clearly zero (rounding); between it and ``1e3 NULL_ROW_TOL`` it is too close to the threshold of
#: :attr:`analysis.motion.MotionSpace.B` to be decided here.
ZERO_ROW = 1e-12
#: Rows per batch of :meth:`FamilyKinematics.separates` (batched SVDs).
CHUNK = 4096



def _norm(v: Array) -> float:
    """``float(np.linalg.norm(v))`` of a real vector, computed as it does (``sqrt(x . x)`` of the
    raveled ``x``, a copy when ``v`` is strided), without its overhead: the same bits."""
    x = v.ravel(order="K")
    return math.sqrt(float(x.dot(x)))

@dataclass(frozen=True)
class MemberCertificate:
    """A DAFC member of the combination ``source`` in scene coordinates, for re-use."""

    source: str
    direction: Array  # (D,) unit object direction dr
    motion: Array  # (M + D,) [dq; dr] of that unit object motion
    f_c: Array  # (L,) per contact: its normal force [N] (S/N), 0 (D), nan (F: see forces)
    forces: Array  # (L, d) per F-point its force [N]; zero rows elsewhere
    slips: Array  # (L, d) per S-point its unit slip (object relative to the finger); zero elsewhere
    Lambda_r_t: Array  # (D, a_bar) orthonormal basis of the object motions of the source
    Lambda: Array  # (M + D, a) basis of the source's motion space null(A_c) (eq. 7)

    @classmethod
    def of(cls, parts: CombinationParts, t: DirectionTest) -> MemberCertificate | None:
        """The certificate of the member ``t`` of ``parts``' combination (None without forces)."""
        if not t.member or t.forces is None or t.zeta_c is None:
            return None
        sy, sel, ms = parts.system, parts.sel, parts.ms
        L, d = sy.L, sy.d
        f_c = np.zeros(L)
        forces = np.zeros((L, d))
        slips = np.zeros((L, d))
        if sel.s_index:
            kf = kinetic_friction(sy, sel, (ms.P_s @ t.zeta_c).reshape(len(sel.s_index), d))
            for k, i in enumerate(sel.s_index):
                slips[i] = kf.slips[k]
        for i, s in enumerate(sel.combination):
            f = t.forces[sel.c_slices[i]]
            if s == "F":
                forces[i] = f
                f_c[i] = np.nan
            elif s in "SN":
                f_c[i] = float(f[0])
        return cls(sel.combination, t.direction, ms.Phi_full @ t.zeta_c, f_c, forces, slips,
                   ms.Lambda_r_t, ms.Lambda)

    def free(self, system: GraspSystem) -> list[int]:
        """The source's F/S/N contacts that carry no force (at most ``ZERO_FORCE F0``)."""
        zero = system.scales.zero_force
        out = []
        for i, s in enumerate(self.source):
            load = _norm(self.forces[i]) if s == "F" else abs(float(self.f_c[i]))
            if s != "D" and load <= zero:
                out.append(i)
        return out

    def family(self, system: GraspSystem) -> Iterator[str]:
        """The combinations that turn a non-empty subset of :meth:`free` contacts to D."""
        free = self.free(system)
        base = list(self.source)
        for mask in itertools.product((False, True), repeat=len(free)):
            if not any(mask):
                continue
            c = base.copy()
            for i, go in zip(free, mask, strict=True):
                if go:
                    c[i] = "D"
            yield "".join(c)

    def below(self) -> Iterator[str]:
        """Every combination that turns a non-empty subset of the source's F/S/N contacts to D
        (the motion keeps those contacts, so it is a motion of each; its forces may not fit)."""
        kept = [i for i, s in enumerate(self.source) if s != "D"]
        base = list(self.source)
        for mask in itertools.product((False, True), repeat=len(kept)):
            if not any(mask):
                continue
            c = base.copy()
            for i, go in zip(kept, mask, strict=True):
                if go:
                    c[i] = "D"
            yield "".join(c)

    def check(self, kin: FamilyKinematics, combinations: list[str]) -> NDArray[np.bool_]:
        """Which of ``combinations`` (members of :meth:`family`) this is a DAFC member of,
        re-checked in physical units (module docstring), vectorised over them."""
        sy, sc = kin.system, kin.system.scales
        L, M = sy.L, sy.M
        v = self.motion
        size = _norm(v)
        F0 = sc.force
        zero = sc.zero_force
        rel_all = kin.A @ v  # (L, d) finger point minus object point velocity, per contact
        kept_ok = np.ones(L, dtype=bool)  # the contact's own checks as in the source
        free_ok = np.zeros(L, dtype=bool)  # may go (D): kept, no force, does not penetrate
        W = np.zeros((L, sy.D))  # (L, D) wrench of each contact's force [N, N m]
        grip = np.zeros(L)
        eq_rows: list[Array] = []
        eq_owner: list[int] = []
        for i, s0 in enumerate(self.source):
            A_i = kin.A[i]  # (d, M + D)
            rel = rel_all[i]
            n, G = sy.normals[i], sy.G_blocks[i]
            along = float(n @ rel)
            if s0 == "F":
                kept_ok[i] = (_norm(rel) <= MOTION_TOL * size
                              and float(np.max(kin.facets[i] @ self.forces[i])) <= FORCE_TOL * F0)
                W[i] = G @ self.forces[i]
                grip[i] = float(snap(n) @ self.forces[i])
                free_ok[i] = _norm(self.forces[i]) <= zero
                eq_rows.extend(A_i)
                eq_owner.extend([i] * len(A_i))
            elif s0 in "SN":
                n_f = float(self.f_c[i])
                kept_ok[i] = abs(along) <= MOTION_TOL * size and n_f >= -FORCE_TOL * F0
                if s0 == "S":
                    kept_ok[i] &= _norm(rel) > SLIP_TOL * size
                W[i] = n_f * (G @ (n - (sy.mu[i] * self.slips[i] if s0 == "S" else 0.0)))
                grip[i] = n_f
                free_ok[i] = abs(n_f) <= zero
                eq_rows.append(kin.normal_rows[i])
                eq_owner.append(i)
            else:
                kept_ok[i] = along <= ALLOW_TOL
            free_ok[i] &= along <= ALLOW_TOL
        go = np.array([[s != s0 for s, s0 in zip(c, self.source, strict=True)] for c in combinations],
                      dtype=bool).reshape(len(combinations), L)  # (R, L) contacts turned to D
        ok = np.all(kept_ok | go, axis=1) & np.all(free_ok | ~go, axis=1)
        keep = ~go
        w = sy.w_ex + keep.astype(float) @ W  # (R, D)
        ok &= (keep.astype(float) @ grip) <= sc.grip_bound * (1.0 + FORCE_TOL)
        Lr = self.Lambda_r_t
        k = w @ Lr  # (R, a_bar)
        ok &= np.linalg.norm(w - k @ Lr.T, axis=1) / F0 <= FORCE_TOL * (1.0 + sc.length)  # no passive part (W_2)
        if eq_rows:
            # the object part of w is an object motion of each combination: the motion of the
            # source's motion space with that object part keeps the contacts the combination keeps
            Lam = self.Lambda
            vw = (k @ Lr.T) @ (Lam @ np.linalg.pinv(Lam[M:], rcond=RANK_RTOL)).T  # (R, M + D)
            res = np.abs(vw @ np.array(eq_rows).T)  # (R, #rows)
            res[go[:, np.array(eq_owner)]] = 0.0
            ok &= np.max(res, axis=1) <= MOTION_TOL * np.maximum(np.linalg.norm(vw, axis=1), 1e-300)
        dr = v[M:]
        ok &= w @ dr > sc.work_tol(dr)
        return ok

class FamilyKinematics:
    """Per-scene data of the family checks: each contact's rows of ``A`` ``(L, d, M + D)``, its
    normal row ``n^T A_i`` and its friction rows (unit, as in :func:`analysis.friction.friction_set`),
    and the finger redundancy ``null(J_c)`` group by group (:meth:`separating`).

    Contacts that share joints form a group (the connected components of "moved by a common
    joint"); groups have disjoint joints, so ``null(J_c)`` is the direct sum of the null spaces of
    the groups' own Jacobians, each fixed by the letters of the group's contacts. Per group,
    letters and set of D-points to move, the least-norm redundancy motion that moves those D-points
    away at unit normal speed is computed once and kept."""

    def __init__(self, system: GraspSystem) -> None:
        self.system = system
        L, M = system.L, system.M
        self.A = np.array([system.contact_A(i) for i in range(L)]).reshape(L, system.d, M + system.D)
        self.normal_rows = np.einsum("ld,ldn->ln", system.normals, self.A)  # (L, M + D)
        facets = system.pyramid[0]
        self.facets = [snap(facets[i] / np.linalg.norm(facets[i], axis=1, keepdims=True)) for i in range(L)]
        self.grip_normals = np.array([snap(system.normals[i]) for i in range(L)]).reshape(L, system.d)
        self.groups = system.joint_groups()
        self.M = M
        self._cache: dict[tuple[int, str, tuple[int, ...]], Array | None] = {}
        self._slip_cache: dict[tuple[int, str], bool] = {}
        self._gen_cols: list[Array] | None = None

    def generator_columns(self) -> list[Array]:
        """Per contact ``j``: ``(k'_j, L, d)``, the contact forces of the weights of its friction
        pyramid's generators (generator ``e`` in row ``j``, zero elsewhere), the F-point unknowns
        of :func:`members_at`; built once."""
        if self._gen_cols is None:
            sy = self.system
            cols = []
            for j, gens in enumerate(sy.pyramid[1]):
                block = np.zeros((len(gens), sy.L, sy.d))
                block[:, j] = gens
                cols.append(block)
            self._gen_cols = cols
        return self._gen_cols

    def slip_depends(self, combination: str) -> bool:
        """:func:`slip_depends_on_redundancy` group by group: ``null(J_c)`` is the direct sum of
        the groups' null spaces (their joints are disjoint), so ``J_s null(J_c)`` is non-zero
        exactly where the S-points of some group move on the null space of that group's own rows;
        each group's answer is kept per letters of its contacts."""
        sy = self.system
        for g, (C, Q) in enumerate(self.groups):
            letters = "".join(combination[i] for i in C)
            if "S" not in letters or not Q:
                continue
            key = (g, letters)
            hit = self._slip_cache.get(key)
            if hit is None:
                Z = _group_null_space(sy, C, Q, letters)  # (|Q|, r)
                J_s = np.vstack([sy.J_blocks[i][:, Q] for i, s in zip(C, letters, strict=True) if s == "S"])
                hit = bool(Z.shape[1] and np.abs(J_s @ Z).max() > 1e-9)
                self._slip_cache[key] = hit
            if hit:
                return True
        return False

    def separates(self, combinations: list[str], motions: Array) -> NDArray[np.bool_]:
        """``separating(c, v) is not None`` for each combination and motion ``(R, M + D)`` (each
        of that combination's motion space): the redundancy push of the groups (:meth:`separating`'s
        first step) decided for all rows at once, the rows it does not decide by
        :meth:`separating` one by one."""
        sy = self.system
        R, L = len(combinations), sy.L
        if R == 0:
            return np.zeros(0, dtype=bool)
        letters = letter_codes(combinations, L)  # (R, L)
        is_d = letters == 2  # (R, L)
        size = np.linalg.norm(motions, axis=1)  # (R,)
        vals = motions @ self.normal_rows.T  # (R, L) normal velocities
        stuck = is_d & (vals >= -STRICT_TOL * size[:, None])  # (R, L)
        done = ~stuck.any(axis=1)  # every D-point separates strictly already
        delta = np.zeros_like(motions)  # (R, M + D)
        by_groups = np.ones(R, dtype=bool)
        for g, (C, Q) in enumerate(self.groups):
            k = len(C)
            mine = stuck[:, C]  # (R, k)
            has = mine.any(axis=1)
            if not has.any():
                continue
            if not Q:
                by_groups &= ~has  # a fixed-body D-point that does not separate: one by one
                continue
            key = (letters[:, C] @ (3 ** np.arange(k))) * (1 << k) + mine @ (1 << np.arange(k))  # (R,)
            for val in np.unique(key[has]):
                rows_g = np.flatnonzero(has & (key == val))
                r0 = int(rows_g[0])
                dg = self._group_delta(g, "".join("FSD"[int(x)] for x in letters[r0, C]),
                                       tuple(i for i, m in zip(C, mine[r0], strict=True) if m))
                if dg is None:
                    by_groups[rows_g] = False
                else:
                    delta[rows_g, : sy.M] += dg
        out = done.copy()
        live = ~done & by_groups
        nd = np.linalg.norm(delta, axis=1)  # (R,)
        live &= nd > 0.0
        for t in (1e-3, 1e-2, 1e-1, 1.0):
            idx = np.flatnonzero(live & ~out)
            if not idx.size:
                break
            v2 = motions[idx] + (t * size[idx] / nd[idx])[:, None] * delta[idx]  # (r, M + D)
            val2 = v2 @ self.normal_rows.T  # (r, L)
            ok = np.all((val2 < -STRICT_TOL * np.linalg.norm(v2, axis=1)[:, None]) | ~is_d[idx], axis=1)
            out[idx[ok]] = True
        rest = np.flatnonzero(~out)
        for k in range(0, rest.size, CHUNK):
            idx = rest[k:k + CHUNK]
            out[idx] = self._separates_whole(letters[idx], motions[idx], stuck[idx], size[idx])
        return out

    def _separates_whole(self, letters: Array, motions: Array, stuck: Array, size: Array) -> NDArray[np.bool_]:
        """:meth:`separating`'s second step for rows ``(R, L)`` of letter codes (F 0, S/N 1, D 2),
        their motions ``(R, M + D)``, the D-points they do not separate strictly ``(R, L)`` and the
        motions' sizes: the least-norm motion of the whole motion space ``null(A_c)`` that moves
        every stuck D-point away at unit normal speed (where its row on that space is clearly not
        zero; undecided, False, near the threshold of a zero row), added by :func:`_strict`'s steps;
        batched SVDs of the zero-padded ``A_c`` and pseudo-inverses of the padded push rows."""
        sy = self.system
        d, n = sy.d, sy.M + sy.D
        Vt, rank = _padded_null_spaces(self.A, self.normal_rows, letters, d, n)  # (R, n, n), (R,)
        null_cols = np.arange(n)[None, :] >= rank[:, None]  # (R, n) rows of Vt spanning null(A_c)
        a = n - rank  # (R,)
        Rall = np.einsum("ln,rjn->rlj", self.normal_rows, Vt) * null_cols[:, None, :]  # (R, L, n)
        size_R = np.linalg.norm(Rall, axis=2)  # (R, L)
        ok = ~np.any(stuck & (size_R > ZERO_ROW) & (size_R < 1e3 * NULL_ROW_TOL), axis=1)
        live = stuck & (size_R >= 1e3 * NULL_ROW_TOL)  # (R, L)
        k = live.sum(axis=1)  # (R,)
        Rp = Rall * live[:, :, None]  # (R, L, n) the push rows, zero elsewhere
        U, sv, Wt = np.linalg.svd(Rp, full_matrices=False)  # (R, L, m), (R, m) descending, (R, m, n)
        kth = np.take_along_axis(sv, np.maximum(k - 1, 0)[:, None], axis=1)[:, 0]  # (R,) k-th largest
        # _unit_push: full row rank, well conditioned (the k-th singular value of the k live rows)
        pushable = (k <= a) & (kth > 1e-6 * np.maximum(1.0, sv[:, 0]))
        ok &= (k == 0) | pushable
        inv = np.where(sv > 1e-9 * sv[:, :1], 1.0 / np.where(sv > 0.0, sv, 1.0), 0.0)  # (R, m) pseudo-inverse
        y = np.einsum("rmn,rm->rn", Wt, inv * np.einsum("rlm,rl->rm", U, -live.astype(float)))  # (R, n) least norm
        y[k == 0] = 0.0
        delta = np.einsum("rjn,rj->rn", Vt, y)  # (R, n): Vt^T y, a motion of null(A_c)
        is_d = letters == 2
        keep = is_d & (~stuck | live)  # (R, L) the D-points that remain rows of the cone
        nd = np.linalg.norm(delta, axis=1)
        vals = motions @ self.normal_rows.T  # (R, L)
        found = (nd == 0.0) & np.all((vals < -STRICT_TOL * size[:, None]) | ~keep, axis=1)
        for t in (1e-3, 1e-2, 1e-1, 1.0):
            idx = np.flatnonzero(ok & (nd > 0.0) & ~found)
            if not idx.size:
                break
            v2 = motions[idx] + (t * size[idx] / nd[idx])[:, None] * delta[idx]
            val2 = v2 @ self.normal_rows.T
            found[idx[np.all((val2 < -STRICT_TOL * np.linalg.norm(v2, axis=1)[:, None]) | ~keep[idx], axis=1)]] = True
        return ok & found

    def _group_delta(self, g: int, letters: str, stuck: tuple[int, ...]) -> Array | None:
        """``(M,)`` joint motion of group ``g`` in ``null(J)`` of its contacts with ``letters``
        moving each contact of ``stuck`` away at unit normal speed (least norm), or None."""
        key = (g, letters, stuck)
        if key in self._cache:
            return self._cache[key]
        sy = self.system
        C, Q = self.groups[g]
        out: Array | None = None
        if Q:
            Z = _group_null_space(sy, C, Q, letters)  # (|Q|, r)
            R = np.array([sy.normals[i] @ sy.J_blocks[i][:, Q] for i in stuck]) @ Z  # (k, r)
            y = _unit_push(R)
            if y is not None:
                out = np.zeros(self.M)
                out[Q] = Z @ y
        self._cache[key] = out
        return out

    def separating(self, combination: str, motion: Array) -> Array | None:
        """A motion of ``combination``'s motion space that separates every D-point strictly, or
        None: ``motion`` (one of that space) plus the redundancy motions of the groups that move
        the D-points it does not separate strictly, else plus the least-norm motion of the whole
        motion space ``null(A_c)`` that does; checked. It lies in the interior of the allowable
        cone (eq. 20), which is then full-dimensional, of dimension ``a_bar``."""
        sy = self.system
        d_pts = [i for i, s in enumerate(combination) if s == "D"]
        if not d_pts:
            return motion
        rows = self.normal_rows[d_pts]  # (#D, M + D)
        size = _norm(motion)
        stuck = {i for i, val in zip(d_pts, rows @ motion, strict=True) if val >= -STRICT_TOL * size}
        if not stuck:
            return motion
        delta = np.zeros(sy.M + sy.D)
        by_groups = True
        for g, (C, Q) in enumerate(self.groups):
            mine = tuple(i for i in C if i in stuck)
            if not mine:
                continue
            dg = self._group_delta(g, "".join(combination[i] for i in C), mine) if Q else None
            if dg is None:
                by_groups = False  # a fixed-body D-point, or a group that cannot move its own
                break
            delta[: sy.M] += dg
        if by_groups:
            found = _strict(rows, motion, delta)
            if found is not None:
                return found
        # the whole motion space: dr may move too (a fixed body's D-point is left by the object);
        # a D-point whose normal velocity vanishes on all of it is no row of the cone
        # (MotionSpace.B), decided only where that is clear-cut
        # A_c = H_c A (eq. 4): an F-point's rows of A, an S/N-point's normal row
        c_rows = [self.A[i] if s == "F" else self.normal_rows[i][None, :]
                  for i, s in enumerate(combination) if s in "FSN"]
        # any orthonormal basis: the least-norm push Lam y below and the row sizes do not depend on it
        Lam = null_space(np.vstack(c_rows), canonical=False) if c_rows else np.eye(sy.M + sy.D)  # (M + D, a)
        order = sorted(stuck)
        R = self.normal_rows[order] @ Lam  # (k, a)
        size_R = np.linalg.norm(R, axis=1)  # (k,)
        if np.any((size_R > ZERO_ROW) & (size_R < 1e3 * NULL_ROW_TOL)):
            return None  # near the threshold of a zero row: the cone's own computation decides
        live = size_R >= 1e3 * NULL_ROW_TOL
        y = _unit_push(R[live]) if live.any() else np.zeros(Lam.shape[1])
        if y is None:
            return None
        keep = [k for k, i in enumerate(d_pts) if i not in stuck or live[order.index(i)]]
        return _strict(rows[keep], motion, Lam @ y)


def _unit_push(R: Array) -> Array | None:
    """The least-norm ``y`` with ``R y = -1`` when ``R`` ``(k, r)`` has full row rank (well
    conditioned), else None."""
    if R.shape[1] == 0 or R.shape[0] > R.shape[1]:
        return None
    sv = np.linalg.svd(R, compute_uv=False)
    if float(sv[-1]) <= 1e-6 * max(1.0, float(sv[0])):
        return None
    return np.linalg.lstsq(R, -np.ones(R.shape[0]), rcond=RANK_RTOL)[0]


def _strict(rows: Array, motion: Array, delta: Array) -> Array | None:
    """``motion + t delta`` (a few step sizes) whose every row value is strictly negative."""
    size, nd = _norm(motion), _norm(delta)
    if nd == 0.0:
        return motion if bool(np.all(rows @ motion < -STRICT_TOL * size)) else None
    for t in (1e-3, 1e-2, 1e-1, 1.0):
        v2 = motion + t * size * delta / nd
        if bool(np.all(rows @ v2 < -STRICT_TOL * _norm(v2))):
            return v2
    return None


def slip_depends_on_redundancy(system: GraspSystem, combination: str) -> bool:
    """:attr:`analysis.dafc.DAFCOracle.slip_depends_on_redundancy` from the finger redundancy
    alone: ``P_s[:, a_bar:] = -J_s Lambda~_qr`` with ``Lambda~_qr = null(J_c)`` (the same basis)."""
    sy = system
    sel = selection(sy, combination)
    if not sel.s_index or sy.M == 0:
        return False
    Z = null_space(sel.H_c @ sy.J) if sel.L_c else np.eye(sy.M)  # (M, r)
    if Z.shape[1] == 0:
        return False
    J_s = sel.H_s @ sy.J  # (d #S, M)
    return bool(np.abs(J_s @ Z).max() > 1e-9)


#: Weight of the object-motion rows in the least squares of :func:`probe_motions`.
WEIGHT = 1e3
#: Penalty, per unit of the force scale, on the slack of the passive equalities in
#: :func:`members_at` (each problem stays feasible; a point with slack decides nothing).
ELASTIC = 1e4
#: Slack of a passive equality that counts as none (units of the force scale).
SLACK_TOL = 1e-12


def members_at(kin: FamilyKinematics, pairs: list[tuple[str, Array]]) -> list[MemberCertificate | None]:
    """For each ``(combination, motion)``: the certificate when the motion ``[dq; dr]`` (unit
    ``dr``) is a DAFC (22) member of the combination, by forces found here and re-checked in
    physical units, else None. All the
    force LPs of (22) at their fixed motions (the slips, hence the friction columns, fixed) are
    solved as one block-diagonal LP: the blocks are independent, so each block's part of an optimal
    point is optimal for its own problem. The passive equalities ``Xi^T w = 0`` (``Xi`` from the
    combination's own motion space, batched SVDs) are elastic with the penalty ``ELASTIC``, so
    every block is feasible; a block whose point needs slack, or does no work above the threshold,
    decides nothing (False: the combination's own search decides). A True comes with forces that
    pass :meth:`DAFCOracle.certify`'s checks: motion (F stick, S slide, D no penetration), friction
    rows, grip bound, passive part of the net wrench and work, in physical units."""
    sy = kin.system
    sc = sy.scales
    L, d, M, D = sy.L, sy.d, sy.M, sy.D
    n = M + D
    B = len(pairs)
    if B == 0:
        return []
    F0 = sc.force
    letters = letter_codes([c for c, _ in pairs], sy.L)  # (B, L)
    Vt, rank = _padded_null_spaces(kin.A, kin.normal_rows, letters, d, n)  # (B, n, n), (B,)
    null_rows = np.arange(n)[None, :] >= rank[:, None]  # (B, n) rows of Vt spanning null(A_c)
    obj = Vt[:, :, M:] * null_rows[:, :, None]  # (B, n, D) rows: the object parts of null(A_c)
    _, s2, V2 = _svd_vt(obj)  # V2 (B, D, D)
    a_bar = np.sum(s2 > RANK_RTOL * np.maximum(1.0, s2[:, :1]), axis=1)  # (B,)
    # one block per pair: [lambda (F: weights of the friction pyramid's generators, S/N: the normal
    # force), units of F0; e+; e-], rows: grip, passive equalities
    cols_c: list[Array] = []
    trip_r: list[Array] = []
    trip_c: list[Array] = []
    trip_v: list[Array] = []
    row_lo: list[Array] = []
    row_up: list[Array] = []
    layout: list[tuple[int, int, int, Array, Array, Array]] = []
    n_col = n_row = 0
    ok = np.ones(B, dtype=bool)
    gen_cols = kin.generator_columns()  # per contact (k'_j, L, d): its generators as unknowns' forces
    normal_of: list[dict[int, int]] = []  # per pair: the unknown of each S/N-point
    for b, (comb, v) in enumerate(pairs):
        rel = kin.A @ v  # (L, d) finger point minus object point velocity
        size = _norm(v)
        Fc: list[Array] = []  # contact forces (k_j, L, d) of the unknowns, contact by contact
        n_unknowns = 0
        own: dict[int, int] = {}
        for j, s in enumerate(comb):
            n_j = sy.normals[j]
            along = float(n_j @ rel[j])
            if s == "F":
                ok[b] &= _norm(rel[j]) <= MOTION_TOL * size
                Fc.append(gen_cols[j])
                n_unknowns += gen_cols[j].shape[0]
            elif s in "SN":
                ok[b] &= abs(along) <= MOTION_TOL * size
                t = np.zeros(d)
                if s == "S":
                    slip = -rel[j]  # the object point relative to the finger
                    ok[b] &= _norm(slip) > SLIP_TOL * size
                    t = -sy.mu[j] * slip / max(1e-300, _norm(slip))
                col = np.zeros((1, L, d))
                col[0, j] = n_j + t
                Fc.append(col)
                own[j] = n_unknowns
                n_unknowns += 1
            else:
                ok[b] &= along <= ALLOW_TOL
        normal_of.append(own)
        Xi = V2[b, a_bar[b]:, :]  # (p, D) complement of the object motions
        Fm = np.concatenate(Fc) if Fc else np.zeros((0, L, d))  # (k, L, d)
        W = np.einsum("ldc,klc->dk", sy.G_blocks.transpose(0, 1, 2), Fm) if len(Fc) else np.zeros((D, 0))
        k, p = W.shape[1], Xi.shape[0]
        dr = v[M:]
        cols_c.append(np.r_[dr @ W, np.full(2 * p, -ELASTIC)])  # work per unit (units of F0), penalty
        grip = np.einsum("lc,klc->k", kin.grip_normals, Fm) if k else np.zeros(0)  # grip rows' normals
        nz = np.flatnonzero(grip)
        trip_r.append(np.full(nz.size, n_row))
        trip_c.append(n_col + nz)
        trip_v.append(grip[nz])
        row_lo.append(np.array([-np.inf]))
        row_up.append(np.array([GRIP_BOUND]))
        n_row += 1
        E = snap(Xi @ W)  # (p, k) passive rows, noise-level entries zero (as the oracle's)
        rhs = snap(-(Xi @ sy.w_ex) / F0)
        rr, cc = np.nonzero(E)
        trip_r.extend([n_row + rr, n_row + np.arange(p), n_row + np.arange(p)])
        trip_c.extend([n_col + cc, n_col + k + np.arange(p), n_col + k + p + np.arange(p)])
        trip_v.extend([E[rr, cc], np.ones(p), -np.ones(p)])
        row_lo.append(rhs)
        row_up.append(rhs)
        n_row += p
        layout.append((n_col, k, p, Fm, Xi, dr))
        n_col += k + 2 * p
    rows_i = np.concatenate(trip_r).astype(np.int64)
    cols_i = np.concatenate(trip_c).astype(np.int64)
    vals = np.concatenate(trip_v)
    order = np.lexsort((rows_i, cols_i))
    rows_i, cols_i, vals = rows_i[order], cols_i[order], vals[order]
    start = np.concatenate([[0], np.cumsum(np.bincount(cols_i, minlength=n_col))]).astype(np.int32)
    status, x = solve_sparse_lp(np.concatenate(cols_c), start, rows_i.astype(np.int32), vals,
                                np.concatenate(row_lo), np.concatenate(row_up), np.zeros(n_col),
                                np.full(n_col, np.inf), maximize=True, feasibility=LP_FEAS_TOL)
    if status != "optimal" or x is None:
        return [None] * B  # (every block is feasible and bounded: undecided, no verdict)
    out: list[MemberCertificate | None] = []
    for b, (comb, v) in enumerate(pairs):
        out.append(None)
        if not ok[b]:
            continue
        c0, k, p, Fm, Xi, dr = layout[b]
        lam, e = x[c0:c0 + k], x[c0 + k:c0 + k + 2 * p]
        if float(np.max(np.abs(e), initial=0.0)) > SLACK_TOL:
            ok[b] = False
            continue
        forces = np.einsum("k,klc->lc", lam, Fm) * F0  # (L, d) contact forces [N]
        w = np.einsum("ldc,lc->d", sy.G_blocks, forces) + sy.w_ex  # (D,)
        fric, grip = 0.0, 0.0
        for j, s in enumerate(comb):
            if s == "F":
                fric = max(fric, float(np.max(kin.facets[j] @ forces[j])))
                grip += float(kin.grip_normals[j] @ forces[j])
            elif s in "SN":
                n_f = float(sy.normals[j] @ forces[j]) if s == "N" else float(lam[normal_of[b][j]]) * F0
                fric = max(fric, -n_f)
                grip += n_f
        if not (fric <= FORCE_TOL * F0 and grip <= sc.grip_bound * (1.0 + FORCE_TOL)
                and float(np.max(np.abs(Xi @ w), initial=0.0)) / F0 <= FORCE_TOL * (1.0 + sc.length)
                and float(dr @ w) > sc.work_tol(dr)):
            continue
        f_c = np.zeros(L)
        f_F = np.zeros((L, d))
        slips = np.zeros((L, d))
        rel = kin.A @ v
        for j, s in enumerate(comb):
            if s == "F":
                f_c[j] = np.nan
                f_F[j] = forces[j]
            elif s in "SN":
                f_c[j] = float(lam[normal_of[b][j]]) * F0
                if s == "S":
                    slips[j] = -rel[j] / _norm(rel[j])
        out[b] = MemberCertificate(comb, dr.copy(), v, f_c, f_F, slips, V2[b, :a_bar[b], :].T.copy(),
                                   Vt[b, rank[b]:, :].T.copy())
    return out


def probe_motions(kin: FamilyKinematics, combinations: list[str]) -> list[list[Array]]:
    """A few candidate DAFC motions of each combination, computed in batches without an LP, for
    :func:`members_at` to try before the combination's own search: for the object directions
    ``-+ w_ex`` (lifted, dropped) and ``+-`` each of (up to) three axes of its object motions,
    projected on them, the motion of its motion space ``null(A_c)`` with that object motion that
    moves every D-point away at unit normal speed and (first) slides every S-point against its
    object point's tangential velocity, so that kinetic friction drags the object along (least
    squares), kept when it penetrates no D-point and slides every S-point. Any motion will do:
    :func:`members_at` certifies or decides nothing."""
    sy = kin.system
    d, M, D = sy.d, sy.M, sy.D
    n = M + D
    if not combinations:
        return []
    letters = letter_codes(combinations, sy.L)  # (B, L)
    Vt, rank = _padded_null_spaces(kin.A, kin.normal_rows, letters, d, n)  # (B, n, n), (B,)
    w = sy.w_ex / max(_norm(sy.w_ex), 1e-300)
    out: list[list[Array]] = []
    for b, c in enumerate(combinations):
        Lam = Vt[b, rank[b]:, :].T  # (n, a)
        found: list[Array] = []
        if Lam.shape[1] == 0:
            out.append(found)
            continue
        d_idx = [i for i, s in enumerate(c) if s == "D"]
        s_idx = [i for i, s in enumerate(c) if s == "S"]
        Rd = kin.normal_rows[d_idx] @ Lam if d_idx else np.zeros((0, Lam.shape[1]))  # (#D, a)
        obj = Lam[M:]  # (D, a)
        U, sv, _ = np.linalg.svd(obj, full_matrices=False)
        basis = U[:, sv > RANK_RTOL * max(1.0, float(sv[0]) if sv.size else 0.0)]  # (D, a_bar)
        targets = [-w, w] + [sign * basis[:, k] for k in range(min(basis.shape[1], 3)) for sign in (1.0, -1.0)]
        live = np.linalg.norm(Rd, axis=1) > 1e3 * NULL_ROW_TOL if Rd.size else np.zeros(0, dtype=bool)
        for t in targets:
            dr = basis @ (basis.T @ t)
            nd = _norm(dr)
            if nd < 1e-9:
                continue
            dr = dr / nd
            # the S-points' slips against their object points' tangential velocity, so that kinetic
            # friction drags the object along (as the oracle's friction-aligned redundancy)
            S_rows = [-kin.A[i] @ Lam for i in s_idx]  # slip = -A_i v
            S_goal = []
            for i in s_idx:
                vo = sy.G_blocks[i].T @ dr
                vt = vo - (vo @ sy.normals[i]) * sy.normals[i]
                S_goal.append(-vt / max(_norm(vt), 1e-9))
            variants = [True, False] if s_idx else [False]
            for aligned in variants:
                A = [WEIGHT * obj, Rd[live]]
                rhs = [WEIGHT * dr, -np.ones(int(live.sum()))]
                if aligned:
                    A += S_rows
                    rhs += S_goal
                y = np.linalg.lstsq(np.vstack(A), np.concatenate(rhs), rcond=RANK_RTOL)[0]
                v = Lam @ y
                v = v - Lam @ np.linalg.lstsq(obj, v[M:] - dr, rcond=RANK_RTOL)[0]  # object part exactly dr
                if _norm(v[M:] - dr) > 1e-9:
                    continue
                rel = kin.A @ v  # (L, d)
                size = _norm(v)
                if any(float(kin.normal_rows[i] @ v) > ALLOW_TOL for i in d_idx):
                    continue
                if any(_norm(rel[i]) <= SLIP_TOL * size for i in s_idx):
                    continue
                found.append(v)
        out.append(found)
    return out


def _group_null_space(sy: GraspSystem, C: list[int], Q: list[int], letters: str) -> Array:
    """``(|Q|, r)``: the joint motions of a finger group's joints ``Q`` that keep its contacts ``C``
    in the states ``letters`` with the object still (F: the contact's whole velocity zero, S and N:
    its normal velocity zero; D: free), a basis of the null space of those rows."""
    rows: list[Array] = []
    for i, s in zip(C, letters, strict=True):
        J = sy.J_blocks[i][:, Q]  # (d, |Q|)
        if s == "F":
            rows.extend(J)
        elif s in "SN":
            rows.append(sy.normals[i] @ J)
    return null_space(np.array(rows)) if rows else np.eye(len(Q))


def _padded_null_spaces(A: Array, normal_rows: Array, letters: NDArray[np.intp], d: int,
                        n: int) -> tuple[Array, Array]:
    """For each row of ``letters`` (``(R, L)``: 0 F, 1 S or N, 2 D), the SVD basis ``Vt`` ``(R, n, n)``
    of its constraint matrix ``A_c`` (each contact's ``d`` rows of ``A`` for F, its normal row for S
    and N, nothing for D; zero-padded to ``(L d, n)`` so that all rows are one batched SVD) and its
    rank ``(R,)``: the rows of ``Vt`` from ``rank`` on span null(``A_c``)."""
    R, L = letters.shape
    blocks = np.zeros((L, 3, d, n))
    blocks[:, 0] = A
    blocks[:, 1, 0] = normal_rows
    mats = blocks[np.arange(L)[None, :], letters].reshape(R, L * d, n)  # (R, L d, n) zero-padded A_c
    _, s1, Vt = _svd_vt(mats)  # Vt (R, n, n)
    rank = np.sum(s1 > RANK_RTOL * np.maximum(1.0, s1[:, :1]), axis=1)  # (R,)
    return Vt, rank


def _svd_vt(mats: Array) -> tuple[Array, Array, Array]:
    """``np.linalg.svd(mats, full_matrices=True)`` of a stack ``(R, m, n)`` where only the singular
    values ``(R, min(m, n))`` and the whole ``Vt`` ``(R, n, n)`` are used: with ``m >= n`` the thin
    SVD has the same ``Vt`` (LAPACK's ``gesdd`` computes ``V`` from the same bidiagonalisation of
    the triangular factor; equal to the last bit on the scenes' matrices) without the ``(m, m)``
    ``U``, about 30 % less time for the 12-contact wrap's ``(36, 18)`` ``A_c``. Returns ``(U, s,
    Vt)``, ``U`` thin when ``m >= n``."""
    return np.linalg.svd(mats, full_matrices=mats.shape[-2] < mats.shape[-1])
