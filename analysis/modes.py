"""Kinematic contact-mode enumeration (in the spirit of Huang, Cheng & Mason 2020).

Definitions
-----------
Generalised velocity ``v = [dq; dr]`` (``M`` joints, then ``D`` object coordinates; ``n = M + D``).
For contact ``i``, ``A_i v = dp_CF - dp_CO`` (finger material point minus object material point,
``system.contact_A(i)``) and the unit normal ``n_i`` points into the object, so

- ``n_i^T A_i v > 0``  would be penetration (never allowed),
- ``n_i^T A_i v = 0``  keeps the contact (*contacting*, sign ``'0'``),
- ``n_i^T A_i v < 0``  separates (*separating*, sign ``'-'``).

A **contacting/separating mode** is a sign vector ``s in {0, -}^L`` realised by some ``v``: the
non-empty faces of the central hyperplane arrangement ``{n_i^T A_i v = 0}`` that lie in the
non-penetration cone ``{n_i^T A_i v <= 0 for all i}``.

A **sticking/sliding mode** refines a contacting/separating mode: each contacting contact sticks
(``A_i v = 0``) or slides (tangential relative velocity ``T_i A_i v != 0``, ``T_i`` =
``system.tangents[i]``); a sliding contact is further labelled by the signs of its tangential
velocity against a fixed set of *tangent hyperplanes* ``{u_k^T T_i A_i v = 0}``:

- 2-D: one tangent, ``u_0 = 1``; tokens ``'S+'`` / ``'S-'`` (sign of ``t_i^T A_i v``);
- 3-D: ``m = tangent_planes >= 2`` directions ``u_k = (cos(k pi/m), sin(k pi/m))`` in the tangent
  basis ``(t1, t2) = system.tangents[i]`` (``m = 2``: the two tangent axes, the polyhedral
  approximation of Huang et al.); token ``'S(s_0,...,s_{m-1})'`` with ``s_k in {+, -, 0}`` the
  sign of ``u_k^T T_i A_i v`` (never all ``0``: that is sticking).

A sticking/sliding mode is the relatively open polyhedral cone of the ``v`` that realise it.

String encoding (JSON and the result objects)
---------------------------------------------
- ``signs``: one character per contact in scene order, ``'0'`` contacting, ``'-'`` separating
  (e.g. ``'00-'``);
- ``categories``: one letter per contact, ``'F'`` stick, ``'S'`` slide, ``'D'`` separating
  (the letters of a combination string, e.g. ``'FSD'``);
- ``mode`` (sticking/sliding): one token per contact separated by single spaces:
  ``'F'`` stick, ``'D'`` separating, ``'S+'``/``'S-'`` (2-D) or ``'S(+,0)'`` (3-D) sliding
  (e.g. ``'F S+ D'``). The signs are those of the velocity of the finger point relative to the
  object point, ``A_i v``, along the tangent directions.

Every mode records ``object_moves``: whether some realisation has ``dr != 0``. A mode's cone is
relatively open in the subspace ``null(E)`` of its equality rows ``E``, so it contains a ``v``
with ``dr != 0`` iff ``null(E)`` is not contained in ``{dr = 0}`` (a rank test, no LP).

Algorithm (output-sensitive)
----------------------------
Three depth-first searches, each refining the leaves of the previous one; a child of a search
node is kept only if it is realisable, so every infeasible branch is cut at its first infeasible
prefix and the work is proportional to the number of modes (times the depth), never to ``2^L``
or ``3^L``:

1. contacting/separating: contacts in order, children ``'0'`` / ``'-'``; the unassigned contacts
   are constrained to ``n_j^T A_j v <= 0``, so a realisable prefix always extends to a mode.
2. stick/slide categories: over the contacting contacts, children stick (adds the tangent rows
   as equalities) / slide. "Slide" (``T_i A_i v != 0``) is not convex, but a non-empty convex
   set ``K`` avoids a finite union of proper subspaces iff it avoids each one (each meets
   ``aff(K)`` in a null set), and ``K`` avoids ``{T_i A_i v = 0}`` iff ``T_i A_i N != 0`` for a
   basis ``N`` of ``aff(K) = null(E)``: so the slide conditions are rank tests.
3. sliding signs: over the tangent hyperplanes of the sliding contacts, children ``+ / - / 0``.

Realisability of a node is one LP (HiGHS, one warm-started model for the whole enumeration):
``E v = 0``, ``sigma_j h_j v >= margin`` on the strict rows, ``h_j v <= 0`` on the unassigned
normal rows, ``|v|_inf <= 1``, with every hyperplane row ``h`` scaled to unit norm. Strictness
is handled by homogeneity (a strict cone is non-empty iff it has a point with margin ``margin``
inside the unit box, up to that tolerance). LPs are saved three ways: the LP solution (a
*witness*) of a node, possibly rescaled, already realises one of its children; a row that
vanishes on ``null(E)`` can only take sign ``0``; and in stage 3, once a ``+`` and a ``-`` child
have witnesses, the point of the segment between them where ``g v = 0`` realises the ``0``
child (the node's set is convex). Stage 1 solves at most ``L * #modes`` LPs, stage 2 at most
one per search node, stage 3 at most two per search node.

Contacts whose fingers can produce any relative velocity at them whatever the object does
(the stacked Jacobian of a group of contacts sharing joints has full row rank ``d * #contacts``,
e.g. a fingertip of a 3-joint finger in 3-D) are *free*: every per-contact label is realisable
independently of the rest and of the object motion, so the enumeration is the product of the
enumeration of the other contacts with all labels of the free ones (``factor_free_contacts``).
"""

from __future__ import annotations

import itertools
import math
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.contacts import GraspSystem
from analysis.exceptions import CombinationError
from analysis.linalg import null_space
from analysis.solvers.highs import INF, RowBoundLP

__all__ = [
    "CategoryMode",
    "ContactSeparatingMode",
    "ModeEnumeration",
    "ModeTolerances",
    "StickSlideMode",
    "combination_admissible",
    "contacting_separating_modes",
    "enumerate_modes",
    "mode_hyperplanes",
]


# --------------------------------------------------------------------------------------------
# Tolerances and result types


@dataclass(frozen=True)
class ModeTolerances:
    """Numerical tolerances of the enumeration (all rows are scaled to unit norm first).

    - ``margin``: a strict inequality ``sigma h v < 0`` counts as realised when some ``v`` with
      ``|v|_inf <= 1`` satisfies it with ``sigma h v <= -margin`` (and all others likewise);
      equivalently with margin 1 inside the box ``|v|_inf <= 1 / margin``.
    - ``feasibility``: HiGHS primal feasibility tolerance; also how close to 0 a witness value
      must be to count as satisfying an equality without a new LP.
    - ``rank``: singular values (and Frobenius norms of restricted rows) at or below it are zero
      in the null-space and avoidance tests (``object_moves``, "slide" realisability).
    - ``free_rank``: a contact group is *free* when ``sigma_min / sigma_max`` of its stacked
      Jacobian exceeds it (full row rank, well conditioned).
    """

    margin: float = 1e-6
    feasibility: float = 1e-10
    rank: float = 1e-9
    free_rank: float = 1e-6


@dataclass(frozen=True)
class ContactSeparatingMode:
    """A contacting/separating mode: ``signs[i]`` is ``'0'`` (contacting) or ``'-'`` (separating)."""

    signs: str
    object_moves: bool


@dataclass(frozen=True)
class CategoryMode:
    """A stick/slide/separate pattern: ``categories[i]`` in ``'F'`` (stick), ``'S'`` (slide),
    ``'D'`` (separating)."""

    categories: str
    object_moves: bool

    @property
    def signs(self) -> str:
        return "".join("-" if c == "D" else "0" for c in self.categories)


@dataclass(frozen=True)
class StickSlideMode:
    """A sticking/sliding mode: one token per contact (see the module docstring)."""

    tokens: tuple[str, ...]
    object_moves: bool

    @property
    def mode(self) -> str:
        """The tokens joined by single spaces, e.g. ``'F S+ D'``."""
        return " ".join(self.tokens)

    @property
    def signs(self) -> str:
        return "".join("-" if t == "D" else "0" for t in self.tokens)

    @property
    def categories(self) -> str:
        return "".join(t[0] for t in self.tokens)


class _AdmissibilityIndex:
    """Bit masks of the stick/slide/separate patterns that move the object.

    Pattern ``k`` covers a combination iff ``F subset stick_k``, ``S subset slide_k`` and
    ``N`` (and F, S) avoid ``sep_k``; queries are vectorised over the patterns and memoised.
    """

    def __init__(self, L: int, patterns: Iterable[str]):
        self.L = L
        stick, slide, sep = [], [], []
        for p in patterns:
            stick.append(sum(1 << i for i, c in enumerate(p) if c == "F"))
            slide.append(sum(1 << i for i, c in enumerate(p) if c == "S"))
            sep.append(sum(1 << i for i, c in enumerate(p) if c == "D"))
        self._wide = L > 62
        dtype: Any = object if self._wide else np.int64
        self.stick = np.array(stick, dtype=dtype)
        self.slide = np.array(slide, dtype=dtype)
        self.sep = np.array(sep, dtype=dtype)
        self._memo: dict[str, bool] = {}

    def query(self, combination: str) -> bool:
        hit = self._memo.get(combination)
        if hit is not None:
            return hit
        f = sum(1 << i for i, c in enumerate(combination) if c == "F")
        s = sum(1 << i for i, c in enumerate(combination) if c == "S")
        c = f | s | sum(1 << i for i, ch in enumerate(combination) if ch == "N")
        ok = ((self.stick & f) == f) & ((self.slide & s) == s) & ((self.sep & c) == 0)
        ans = bool(np.any(ok))
        self._memo[combination] = ans
        return ans


@dataclass(frozen=True)
class ModeEnumeration:
    """All kinematic contact modes of one configuration (see the module docstring).

    ``contacting_separating``: the contacting/separating modes; ``categories``: the
    stick/slide/separate patterns; ``sticking_sliding``: the sticking/sliding modes (complete
    unless ``max_modes`` was reached or ``refined`` is ``False``: ``sticking_sliding_complete``). ``lp_count`` LPs were
    solved (``lp_counts`` per stage); ``free_contacts`` were factored out (see module docstring).
    """

    dim: int
    L: int
    tangent_planes: int
    contacting_separating: tuple[ContactSeparatingMode, ...]
    categories: tuple[CategoryMode, ...]
    sticking_sliding: tuple[StickSlideMode, ...]
    sticking_sliding_complete: bool
    lp_counts: dict[str, int]
    free_contacts: tuple[int, ...]
    refined: bool = True  # False: stage 3 skipped (enumerate_modes(refine=False))
    tolerances: ModeTolerances = field(default_factory=ModeTolerances)
    _index: _AdmissibilityIndex | None = field(default=None, repr=False, compare=False)

    @property
    def lp_count(self) -> int:
        """Total number of LPs solved."""
        return int(sum(self.lp_counts.values()))

    @property
    def n_contacting_separating(self) -> int:
        return len(self.contacting_separating)

    @property
    def n_categories(self) -> int:
        return len(self.categories)

    @property
    def n_sticking_sliding(self) -> int:
        return len(self.sticking_sliding)

    @property
    def admissibility(self) -> _AdmissibilityIndex:
        if self._index is None:  # built by enumerate_modes; kept lazily for hand-made instances
            idx = _AdmissibilityIndex(self.L, (c.categories for c in self.categories if c.object_moves))
            object.__setattr__(self, "_index", idx)
        assert self._index is not None
        return self._index

    def to_json(self) -> dict[str, Any]:
        """``{"contacting_separating": N, "sticking_sliding": M, "modes": [...]}`` plus metadata.

        Each entry of ``modes`` is a contacting/separating mode: ``signs``, ``object_moves`` and
        ``sticking_sliding``, the list of its refinements ``{"mode": "F S+ D", "object_moves"}``.
        """
        groups: dict[str, list[dict[str, Any]]] = {m.signs: [] for m in self.contacting_separating}
        for r in self.sticking_sliding:
            groups.setdefault(r.signs, []).append({"mode": r.mode, "object_moves": r.object_moves})
        return {
            "contacting_separating": self.n_contacting_separating,
            "sticking_sliding": self.n_sticking_sliding,
            "sticking_sliding_complete": self.sticking_sliding_complete,
            "refined": self.refined,
            "categories": self.n_categories,
            "lp_count": self.lp_count,
            "lp_counts": dict(self.lp_counts),
            "dim": self.dim,
            "tangent_planes": self.tangent_planes,
            "free_contacts": list(self.free_contacts),
            "encoding": {
                "signs": "per contact: '0' contacting (n^T A v = 0), '-' separating (n^T A v < 0)",
                "categories": "per contact: F stick, S slide, D separating",
                "mode": (
                    "tokens separated by spaces: F stick, D separating, S+/S- (2-D) or "
                    "S(s_0,...,s_{m-1}) (3-D) sliding, s_k the sign of u_k^T T A v"
                ),
            },
            "modes": [
                {"signs": m.signs, "object_moves": m.object_moves, "sticking_sliding": groups[m.signs]}
                for m in self.contacting_separating
            ],
            "category_modes": [
                {"categories": c.categories, "object_moves": c.object_moves} for c in self.categories
            ],
        }


# --------------------------------------------------------------------------------------------
# Hyperplanes


def tangent_directions(dim: int, tangent_planes: int = 2) -> Array:
    """Directions ``u_k`` (``(m, d-1)``) in the tangent basis whose hyperplanes label sliding.

    2-D: ``[[1]]``. 3-D: ``u_k = (cos(k pi/m), sin(k pi/m))``, ``k = 0..m-1``, ``m >= 2``.
    """
    if dim == 2:
        return np.ones((1, 1))
    if tangent_planes < 2:
        raise ValueError("tangent_planes must be >= 2 in 3-D (sticking needs the full tangent plane)")
    ang = np.pi * np.arange(tangent_planes) / tangent_planes
    U = np.stack([np.cos(ang), np.sin(ang)], axis=1)  # (m, 2)
    U[np.abs(U) < 1e-15] = 0.0
    return U


def _unit_rows(X: Array) -> Array:
    norms = np.linalg.norm(X, axis=-1, keepdims=True)
    return np.divide(X, norms, out=np.zeros_like(X), where=norms > 0)


def mode_hyperplanes(system: GraspSystem, tangent_planes: int = 2) -> tuple[Array, Array]:
    """Unit-norm rows of the arrangement: normal rows ``(L, n)`` = ``n_i^T A_i`` and tangent rows
    ``(L, m, n)`` = ``u_k^T T_i A_i`` (``n = M + D``), each divided by its norm."""
    n = system.M + system.D
    U = tangent_directions(system.dim, tangent_planes)  # (m, d-1)
    normal = np.zeros((system.L, n))  # (L, M + D)
    tangent = np.zeros((system.L, U.shape[0], n))  # (L, m, M + D)
    for i in range(system.L):
        A_i = system.contact_A(i)  # (d, M + D)
        normal[i] = system.normals[i] @ A_i
        tangent[i] = U @ (system.tangents[i] @ A_i)
    return _unit_rows(normal), _unit_rows(tangent)


def _slide_tokens(dim: int, U: Array) -> list[str]:
    """All sliding tokens realisable by some tangential velocity (faces of the central line
    arrangement ``{u_k^T w = 0}`` in the tangent plane, except the origin)."""
    if dim == 2:
        return ["S+", "S-"]
    phis = np.arctan2(U[:, 1], U[:, 0])
    rays = np.sort(np.mod(np.concatenate([phis + np.pi / 2, phis + 3 * np.pi / 2]), 2 * np.pi))
    mids = (rays + np.roll(rays, -1) + np.where(np.arange(len(rays)) == len(rays) - 1, 2 * np.pi, 0)) / 2
    tokens: list[str] = []
    for a in np.concatenate([rays, mids]):
        w = np.array([np.cos(a), np.sin(a)])
        vals = U @ w
        tok = "S(" + ",".join("0" if abs(x) < 1e-9 else ("+" if x > 0 else "-") for x in vals) + ")"
        if tok not in tokens:
            tokens.append(tok)
    return tokens


def _nonzero_on(rows: Array, N: Array, tol: float) -> bool:
    """Whether the subspace ``range(N)`` is not inside ``null(rows)``."""
    return N.shape[1] > 0 and float(np.linalg.norm(rows @ N)) > tol


# --------------------------------------------------------------------------------------------
# The three searches on the reduced problem (free contacts removed)


class _LimitReachedError(Exception):
    """Raised inside the third search when ``max_modes`` is reached."""


@dataclass
class _Leaf:
    labels: tuple[str, ...]
    witness: Array
    N: Array  # (n, k) orthonormal basis of null(E) of the leaf
    object_moves: bool


class _Search:
    def __init__(
        self,
        normal: Array,  # (L, n)
        tangent: Array,  # (L, m, n)
        r_cols: NDArray[np.intp],  # (D,) columns of dr
        dim: int,
        tol: ModeTolerances,
    ):
        self.normal = normal
        self.tangent = tangent
        self.L, self.m, self.n = tangent.shape
        self.r_cols = r_cols
        self.dim = dim
        self.tol = tol
        # Row layout of the LP: normal rows 0..L-1, then tangent row (i, k) at L + i m + k.
        H = np.vstack([normal, tangent.reshape(self.L * self.m, self.n)])  # (L (1 + m), n)
        self.lp = RowBoundLP(H, tol.feasibility)
        self.lower = np.full(H.shape[0], -INF)
        self.upper = np.full(H.shape[0], INF)
        # Parallel rows (|h_a . h_b| >= 1 - 1e-14, angle <= 1.5e-7 < margin): once one has a sign
        # the other's is forced, e.g. the identical tangent rows of coplanar table contacts.
        gram = H @ H.T  # (K, K)
        self.parallel: list[list[tuple[int, float]]] = [
            [(int(b), float(np.sign(gram[a, b]))) for b in np.flatnonzero(np.abs(gram[a]) >= 1.0 - 1e-14) if b != a]
            for a in range(H.shape[0])
        ]

    # row bound helpers ------------------------------------------------------------------
    def _t(self, i: int, k: int) -> int:
        return self.L + i * self.m + k

    def _set(self, row: int, kind: str) -> None:
        lo, up = {
            "free": (-INF, INF),
            "closed": (-INF, 0.0),
            "0": (0.0, 0.0),
            "-": (-INF, -self.tol.margin),
            "+": (self.tol.margin, INF),
        }[kind]
        self.lower[row] = lo
        self.upper[row] = up

    def _forced(self, row: int) -> str | None:
        """The sign ``row`` must take because a parallel row already has one, else ``None``."""
        for other, sg in self.parallel[row]:
            lo, up = self.lower[other], self.upper[other]
            if lo == 0.0 and up == 0.0:
                return "0"
            if up < 0.0 or lo > 0.0:  # '-' (up = -margin) or '+' (lo = margin)
                return "+" if (lo > 0.0) == (sg > 0) else "-"
        return None

    def _witness(self, v: Array, value: float, kind: str) -> Array | None:
        """``v`` (the parent's witness, ``value = h v`` on the new row) or a multiple of it if it
        already realises the child ``kind``; ``None`` if an LP is needed. Every constraint but
        the box is homogeneous, so ``c v`` with ``c >= 1`` and ``|c v|_inf <= 1`` stays feasible."""
        eps = self.tol.feasibility
        if kind == "0":
            return v if abs(value) <= eps else None
        sv = value if kind == "+" else -value
        if sv >= self.tol.margin - eps:
            return v
        if sv > eps:
            c = self.tol.margin / sv
            if c * float(np.max(np.abs(v))) <= 1.0:
                return c * v
        return None

    def _moves(self, N: Array) -> bool:
        return _nonzero_on(np.eye(self.n)[self.r_cols], N, self.tol.rank)

    # stage 1 ----------------------------------------------------------------------------
    def contacting_separating(self) -> list[_Leaf]:
        self.lower[:] = -INF
        self.upper[:] = INF
        for i in range(self.L):
            self._set(i, "closed")
        out: list[_Leaf] = []
        signs: list[str] = []

        def rec(i: int, v: Array, N: Array) -> None:
            # N: basis of null(E) for the equalities so far (contains aff(K))
            if i == self.L:
                out.append(_Leaf(tuple(signs), v, N, self._moves(N)))
                return
            a = self.normal[i]
            val = float(a @ v)
            # a vanishes on null(E) (so on K): contact i cannot separate.
            forced = self._forced(i)
            if forced is not None:  # '+' (penetration) leaves no child
                kinds: tuple[str, ...] = (forced,) if forced != "+" else ()
            else:
                kinds = ("0", "-") if _nonzero_on(a[None, :], N, self.tol.rank) else ("0",)
            for kind in kinds:
                self._set(i, kind)
                w = self._witness(v, val, kind)
                if w is None:
                    w = self.lp.solve(self.lower, self.upper)
                if w is not None:
                    signs.append(kind)
                    rec(i + 1, w, N @ null_space((a @ N)[None, :], self.tol.rank) if kind == "0" else N)
                    signs.pop()
            self._set(i, "closed")

        rec(0, np.zeros(self.n), np.eye(self.n))  # v = 0 satisfies every closed row
        return out

    def _load_leaf_bounds(self, labels: Sequence[str]) -> None:
        self.lower[:] = -INF
        self.upper[:] = INF
        for i, lab in enumerate(labels):
            self._set(i, "-" if lab in ("-", "D") else "0")
            if lab == "F":
                for k in range(self.m):
                    self._set(self._t(i, k), "0")

    # stage 2 ----------------------------------------------------------------------------
    def categories(self, cs: _Leaf) -> list[_Leaf]:
        self._load_leaf_bounds(cs.labels)
        Z = [i for i, s in enumerate(cs.labels) if s == "0"]
        labels = ["D" if s == "-" else "?" for s in cs.labels]
        out: list[_Leaf] = []
        slides: list[int] = []

        def rec(j: int, v: Array, N: Array) -> None:
            if j == len(Z):
                out.append(_Leaf(tuple(labels), v, N, self._moves(N)))
                return
            i = Z[j]
            T_i = self.tangent[i]  # (m, n)
            # stick: T_i A_i v = 0 added to the equalities
            rows = [self._t(i, k) for k in range(self.m)]
            for r in rows:
                self._set(r, "0")
            if float(np.max(np.abs(T_i @ v))) <= self.tol.feasibility:
                w: Array | None = v
            else:
                w = self.lp.solve(self.lower, self.upper)
            if w is not None:
                N2 = N @ null_space(T_i @ N, self.tol.rank)
                if all(_nonzero_on(self.tangent[s], N2, self.tol.rank) for s in slides):
                    labels[i] = "F"
                    rec(j + 1, w, N2)
            for r in rows:
                self._set(r, "free")
            # slide: same polytope, must avoid {T_i A_i v = 0}
            if _nonzero_on(T_i, N, self.tol.rank):
                labels[i] = "S"
                slides.append(i)
                rec(j + 1, v, N)
                slides.pop()
            labels[i] = "?"

        rec(0, cs.witness, cs.N)
        return out

    # stage 3 ----------------------------------------------------------------------------
    def sticking_sliding(
        self, cat: _Leaf, budget: list[int], out: list[tuple[tuple[str, ...], bool]]
    ) -> None:
        """Append the sticking/sliding refinements of ``cat`` to ``out``; ``budget[0]`` leaves
        may still be added (negative: no limit), then :class:`_LimitReachedError`."""
        self._load_leaf_bounds(cat.labels)
        S = [i for i, c in enumerate(cat.labels) if c == "S"]
        seq = [(i, k) for i in S for k in range(self.m)]
        signs: dict[int, list[str]] = {i: [] for i in S}

        def token(i: int) -> str:
            tok = "S" + signs[i][0] if self.dim == 2 else "S(" + ",".join(signs[i]) + ")"
            return sys.intern(tok)  # one string object per distinct token (memory)

        def rec(p: int, v: Array, N: Array, pending: frozenset[int]) -> None:
            if p == len(seq):
                if budget[0] == 0:
                    raise _LimitReachedError
                budget[0] -= 1  # a negative budget never reaches 0: no limit
                labels = tuple(token(i) if c == "S" else c for i, c in enumerate(cat.labels))
                out.append((labels, self._moves(N)))  # no witness/basis: there may be millions
                return
            i, k = seq[p]
            row = self._t(i, k)
            g = self.tangent[i, k]
            val = float(g @ v)
            found: dict[str, Array] = {}
            # g vanishes on aff(K) = range(N): only the '0' child exists (and v realises it).
            forced = self._forced(row)
            if forced is not None:
                kinds: tuple[str, ...] = (forced,)
            else:
                kinds = ("+", "-", "0") if _nonzero_on(g[None, :], N, self.tol.rank) else ("0",)
            for kind in kinds:
                self._set(row, kind)
                w = self._witness(v, val, kind)
                if w is None and kind == "0" and "+" in found and "-" in found:
                    # K is convex: the segment between a '+' and a '-' point crosses g v = 0
                    # inside K, so the '0' child needs no LP.
                    vp, vm = found["+"], found["-"]
                    gp, gm = float(g @ vp), float(g @ vm)
                    w = (gp * vm - gm * vp) / (gp - gm)
                elif w is None:
                    w = self.lp.solve(self.lower, self.upper)
                if w is None:
                    continue
                found[kind] = w
                if kind == "0":
                    N2 = N @ null_space((g @ N)[None, :], self.tol.rank)
                    if not all(_nonzero_on(self.tangent[s], N2, self.tol.rank) for s in pending):
                        continue
                    pending2 = pending
                else:
                    N2, pending2 = N, pending - {i}
                signs[i].append(kind)
                rec(p + 1, w, N2, pending2)
                signs[i].pop()
            self._set(row, "free")

        rec(0, cat.witness, cat.N, frozenset(S))


# --------------------------------------------------------------------------------------------
# Free contacts


def _free_contacts(system: GraspSystem, tol: ModeTolerances) -> tuple[list[int], list[int]]:
    """Contacts of groups with full-row-rank Jacobians and the joints of those groups.

    Groups are the connected components of contacts linked by shared joints (nonzero columns
    of ``J_ij``). A group ``(C, Q)`` is free when ``J[C, Q]`` (``(d |C|, |Q|)``) has full row
    rank with ``sigma_min / sigma_max > free_rank``.
    """
    L, M = system.L, system.M
    if M == 0 or L == 0:
        return [], []
    free_c: list[int] = []
    free_q: list[int] = []
    for C, Q in system.joint_groups():
        if not Q or len(Q) < system.d * len(C):
            continue
        JCQ = np.vstack([system.J_blocks[i][:, Q] for i in C])  # (d |C|, |Q|)
        s = np.linalg.svd(JCQ, compute_uv=False)
        if s[-1] > tol.free_rank * s[0]:
            free_c.extend(C)
            free_q.extend(Q)
    return sorted(free_c), sorted(free_q)


def _expand(
    reduced: Sequence[tuple[tuple[str, ...], bool]],
    kept: Sequence[int],
    free: Sequence[int],
    choices: Sequence[str],
    L: int,
    limit: int | None = None,
) -> tuple[list[tuple[tuple[str, ...], bool]], bool]:
    """Product of reduced labels with every choice at each free contact (full-length labels)."""
    out: list[tuple[tuple[str, ...], bool]] = []
    combos = list(itertools.product(choices, repeat=len(free))) if free else [()]
    for labels, moves in reduced:
        for combo in combos:
            if limit is not None and len(out) >= limit:
                return out, False
            full = [""] * L
            for i, lab in zip(kept, labels, strict=True):
                full[i] = lab
            for i, lab in zip(free, combo, strict=True):
                full[i] = lab
            out.append((tuple(full), moves))
    return out, True


# --------------------------------------------------------------------------------------------
# Public API


def _token_rank(slide_tokens: Sequence[str]) -> dict[str, int]:
    """Sort order of the tokens: F, then sliding tokens by their signs (+ < 0 < -), then D."""
    order = sorted(slide_tokens, key=lambda t: t.translate(str.maketrans("+0-", "012")))
    return {"F": 0, **{t: k + 1 for k, t in enumerate(order)}, "D": len(order) + 1}


def _reduced_search(
    system: GraspSystem, tangent_planes: int, factor_free_contacts: bool, tol: ModeTolerances
) -> tuple[_Search, list[int], list[int]]:
    """The search over the contacts that are not free (``kept``), on the columns of the joints
    that move them and of ``dr``; ``free`` are the factored contacts (module docstring)."""
    L, M = system.L, system.M
    normal, tangent = mode_hyperplanes(system, tangent_planes)  # (L, n), (L, m, n)
    m = tangent.shape[1]
    free_c, free_q = _free_contacts(system, tol) if factor_free_contacts else ([], [])
    kept = [i for i in range(L) if i not in set(free_c)]
    cols = [j for j in range(M) if j not in set(free_q)] + list(range(M, M + system.D))
    r_cols = np.arange(len(cols) - system.D, len(cols))
    search = _Search(
        normal[np.ix_(kept, cols)],
        tangent[kept][:, :, cols].reshape(len(kept), m, len(cols)),
        r_cols,
        system.dim,
        tol,
    )
    return search, kept, free_c


def _cs_order(signs: str) -> str:
    """Sort key of sign strings: contacting ``'0'`` before separating ``'-'``, contact by contact."""
    return signs.translate(str.maketrans("0-", "01"))


def contacting_separating_modes(
    system: GraspSystem, *, factor_free_contacts: bool = True, tol: ModeTolerances | None = None
) -> tuple[ContactSeparatingMode, ...]:
    """The contacting/separating modes of ``system`` only (stage 1 of :func:`enumerate_modes`,
    the same list as its ``contacting_separating``): the sign vectors ``s in {0, -}^L`` realised
    by some ``v`` with ``n_i^T A_i v = 0`` where ``s_i = '0'``, ``< 0`` where ``'-'`` and never
    ``> 0`` (no penetration); the count Huang, Cheng and Mason (2020) report, e.g. 10 for a cube
    on a table with four corner contacts. At most ``L`` LPs a mode."""
    tol = tol or ModeTolerances()
    search, kept, free_c = _reduced_search(system, 2, factor_free_contacts, tol)
    leaves = [(lf.labels, lf.object_moves) for lf in search.contacting_separating()]
    cs, _ = _expand(leaves, kept, free_c, ["0", "-"], system.L)
    return tuple(
        ContactSeparatingMode("".join(s), mv) for s, mv in sorted(cs, key=lambda x: _cs_order("".join(x[0])))
    )


def enumerate_modes(
    system: GraspSystem,
    *,
    tangent_planes: int = 2,
    max_modes: int | None = 200_000,
    refine: bool = True,
    factor_free_contacts: bool = True,
    tol: ModeTolerances | None = None,
) -> ModeEnumeration:
    """Enumerate the contacting/separating, stick/slide and sticking/sliding modes of ``system``.

    ``tangent_planes`` (3-D only, ``>= 2``): number of tangent hyperplanes that label sliding.
    ``max_modes``: stop listing sticking/sliding modes after this many
    (``sticking_sliding_complete`` is then ``False``; the other two lists are always complete).
    ``refine=False`` skips the sticking/sliding signs (stage 3, the only stage whose output can
    be huge: ~10^5 modes and more for 3-D hands); :func:`combination_admissible` needs only the
    first two stages, so pruning should use ``refine=False``.
    ``factor_free_contacts``: treat contacts whose fingers can move them freely as a product
    (exact; ``False`` searches them too, for checking).
    Raises :class:`SolverError` when HiGHS fails (infeasibility is an answer, not a failure).
    """
    tol = tol or ModeTolerances()
    L, d = system.L, system.dim
    U = tangent_directions(d, tangent_planes)
    search, kept, free_c = _reduced_search(system, tangent_planes, factor_free_contacts, tol)
    m = search.m
    counts: dict[str, int] = {}

    cs_leaves = search.contacting_separating()
    counts["contacting_separating"] = search.lp.count
    cat_leaves = [c for cs in cs_leaves for c in search.categories(cs)]
    counts["categories"] = search.lp.count - counts["contacting_separating"]

    # The factored product multiplies each reduced sticking/sliding mode by ``per_reduced``.
    slide_tokens = _slide_tokens(d, U)
    free_choices = ["F", *slide_tokens, "D"]
    per_reduced = len(free_choices) ** len(free_c)
    budget = [-1 if max_modes is None else math.ceil(max_modes / per_reduced)]
    ss_leaves: list[tuple[tuple[str, ...], bool]] = []
    complete = True
    before = search.lp.count
    try:
        for cat in cat_leaves if refine else []:
            search.sticking_sliding(cat, budget, ss_leaves)
    except _LimitReachedError:
        complete = False
    complete = complete and refine
    counts["sticking_sliding"] = search.lp.count - before

    cs, _ = _expand([(lf.labels, lf.object_moves) for lf in cs_leaves], kept, free_c, ["0", "-"], L)
    cats, _ = _expand([(lf.labels, lf.object_moves) for lf in cat_leaves], kept, free_c, ["F", "S", "D"], L)
    ss, ok = _expand(ss_leaves, kept, free_c, free_choices, L, max_modes)
    rank = _token_rank(slide_tokens)
    complete = complete and ok

    cs_modes = tuple(
        ContactSeparatingMode("".join(s), mv) for s, mv in sorted(cs, key=lambda x: _cs_order("".join(x[0])))
    )
    cat_modes = tuple(
        CategoryMode("".join(c), mv)
        for c, mv in sorted(cats, key=lambda x: "".join(x[0]).translate(str.maketrans("FSD", "012")))
    )
    ss_modes = tuple(
        StickSlideMode(t, mv) for t, mv in sorted(ss, key=lambda x: bytes(map(rank.__getitem__, x[0])))
    )
    index = _AdmissibilityIndex(L, (c.categories for c in cat_modes if c.object_moves))
    return ModeEnumeration(
        dim=d,
        L=L,
        tangent_planes=m,
        contacting_separating=cs_modes,
        categories=cat_modes,
        sticking_sliding=ss_modes,
        sticking_sliding_complete=complete,
        lp_counts=counts,
        free_contacts=tuple(free_c),
        refined=refine,
        tolerances=tol,
        _index=index,
    )


def combination_admissible(enumeration: ModeEnumeration, combination: str) -> bool:
    """Necessary kinematic condition for a contact-state combination to move the object.

    ``True`` iff some realised mode with ``dr != 0`` has every F contact sticking, every S
    contact sliding, every N contact contacting (sticking or sliding) and D contacts anything
    non-penetrating (kept or separating). Letters: F, N, S, D, one per contact in scene order.
    Queries are answered from bit masks of the moving stick/slide/separate patterns (vectorised,
    memoised), so checking every combination of a scene is cheap.
    """
    c = combination.strip().upper()
    if len(c) != enumeration.L:
        raise CombinationError(
            ("combination",), f"has {len(c)} letters but the scene has {enumeration.L} contacts"
        )
    for i, s in enumerate(c):
        if s not in "FNSD":
            raise CombinationError(("combination", i), f"'{s}' is not a contact state (use F, N, S or D)")
    return enumeration.admissibility.query(c)
