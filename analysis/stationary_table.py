"""Stationary grasps (paper eq. 18) of many combinations from few LPs, by monotonicity.

The force set of a contact shrinks F -> S/N -> D (cone -> normal force only -> nothing), so with
the classes F = 2, S/N = 1, D = 0:

* (18) infeasible for a combination is infeasible for every combination whose classes are at most
  its own (a weaker force set); the least friction violation (:func:`stationary_violation`) of the
  weaker one is at least as large;
* a solution of (18), the contact forces ``(L, d)`` in newtons, fits every combination whose
  classes are at least the weakest class each contact needs (zero force -> 0, normal only -> 1,
  else 2, by the absolute thresholds of :mod:`analysis.scales`). It is used for such a combination
  only after it is re-checked against that combination's own eq. (18) in physical units, as
  :func:`analysis.stationary.certifies` does (equilibrium, friction rows, grip bound, joint torque
  limits), vectorised over the combinations.

The combinations are decided strongest first; one LP (:func:`min_total_normal`) for each one that
no earlier answer decides.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection, letter_codes, selection
from analysis.friction import friction_set
from analysis.scales import REUSE_TOL, snap
from analysis.statics import statics
from analysis.stationary import DEGENERATE_TOL, min_total_normal, stationary_violation
from analysis.torque_limits import LIMIT_TOL

#: Force class of each letter: F = 2, S/N = 1, D = 0.
CLASS = {"F": 2, "S": 1, "N": 1, "D": 0}


def classes(combinations: list[str]) -> NDArray[np.int8]:
    """``(R, L)`` force classes of the combinations (2 minus :func:`letter_codes`)."""
    if not combinations:
        return np.zeros((0, 0), dtype=np.int8)
    return (2 - letter_codes(combinations, len(combinations[0]))).astype(np.int8)


def _masks(cls: NDArray[np.int8]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Bit masks ``(R,)`` of the contacts of class 2 (F) and of class at least 1 (F, S, N) of
    each row of ``cls`` ``(R, L)``: a row's classes are at most another's, contact by contact,
    exactly when both its masks are subsets of the other's."""
    bits = np.int64(1) << np.arange(cls.shape[1], dtype=np.int64)  # (L,)
    return (cls == 2) @ bits, (cls >= 1) @ bits


def _at_most(Fm: NDArray[np.int64], Sm: NDArray[np.int64], F_top: int | NDArray[np.int64],
             S_top: int | NDArray[np.int64]) -> NDArray[np.bool_]:
    """Are the classes of the masks ``Fm``, ``Sm`` (:func:`_masks`) at most those of ``F_top``,
    ``S_top``, contact by contact (elementwise, broadcast)?"""
    return ((Fm & ~F_top) | (Sm & ~S_top)) == 0


@dataclass(frozen=True)
class StationaryVerdicts:
    """Eq. (18) for each combination (in the order given)."""

    feasible: NDArray[np.bool_]  # (R,)
    violation: Array  # (R,) least friction violation of an infeasible one (nan: feasible, or none)
    own: NDArray[np.bool_]  # (R,) decided by its own minimum-grip LP (else by monotonicity)
    lps: int  # LPs solved (minimum grip and violation LPs)


def contact_forces(system: GraspSystem, sel: Selection, f_c: Array) -> Array:
    """The force on the object at every contact, ``(L, d)`` world frame [N] (zero at D-points)."""
    out = np.zeros((system.L, system.d))
    for i, s in enumerate(sel.combination):
        f = f_c[sel.c_slices[i]]
        if s == "F":
            out[i] = f
        elif s in "SN":
            out[i] = float(f[0]) * system.normals[i]
    return out


def witness_classes(system: GraspSystem, forces: Array) -> NDArray[np.int8]:
    """Weakest force class of each contact that the contact forces ``(L, d)`` still satisfy:
    0 when the force is at most ``ZERO_FORCE F0``, 1 when its tangential part is, else 2."""
    zero = system.scales.zero_force
    out = np.zeros(system.L, dtype=np.int8)
    for i in range(system.L):
        f = forces[i]
        if float(np.linalg.norm(f)) <= zero:
            out[i] = 0
        elif np.linalg.norm(f - (f @ system.normals[i]) * system.normals[i]) > zero:
            out[i] = 2
        else:
            out[i] = 1
    return out


@dataclass(frozen=True)
class _Witness:
    """A solution of (18) as per-contact options: for each contact and class (D, S/N, F) what the
    selected force of that class contributes (the f_c of a combination keeps the full force at an
    F-point, the normal component at an S/N-point, nothing at a D-point)."""

    classes: NDArray[np.int8]  # (L,)
    wrench: Array  # (L, 3, D) contribution to G_c f_c [N, N m]
    torque: Array  # (L, 3, M) contribution to J_c^T f_c [N m]
    friction: Array  # (L, 3) largest friction-row value max(C f_c) of the contact [units of F0]
    normal: Array  # (L, 3) contribution to the total normal force (the grip rows) [N]

    @classmethod
    def of(cls, system: GraspSystem, forces: Array) -> _Witness:
        L, D, M = system.L, system.D, system.M
        F0 = system.scales.force
        wrench, torque = np.zeros((L, 3, D)), np.zeros((L, 3, M))
        friction, normal = np.zeros((L, 3)), np.zeros((L, 3))
        facets = system.pyramid[0]  # (L, k, d)
        for i in range(L):
            f, n = forces[i], system.normals[i]
            f_n = float(f @ n)
            for k, vec in ((1, f_n * n), (2, f)):
                wrench[i, k] = system.G_blocks[i] @ vec
                torque[i, k] = system.J_blocks[i].T @ vec
            C = snap(facets[i] / np.linalg.norm(facets[i], axis=1, keepdims=True))  # friction_set's F rows
            friction[i, 1] = -f_n / F0
            friction[i, 2] = float(np.max(C @ f)) / F0
            normal[i, 1] = f_n
            normal[i, 2] = float(snap(n) @ f)
        return cls(witness_classes(system, forces), wrench, torque, friction, normal)

    def certifies(self, system: GraspSystem, cls: NDArray[np.int8]) -> NDArray[np.bool_]:
        """For combinations of classes ``cls`` ``(k, L)`` (each at least :attr:`classes`): do the
        selected forces solve their (18) within ``REUSE_TOL F0``, the grip bound and the joint
        torque limits (:func:`analysis.stationary.certifies`, vectorised)."""
        k = cls.shape[0]
        idx = cls.astype(np.intp)  # (k, L)
        cols = np.arange(system.L)[None, :]
        sc = system.scales
        w = self.wrench[cols, idx].sum(axis=1) + system.w_ex  # (k, D)
        eq = np.max(np.abs(w * sc.wrench_weights()), axis=1)  # (k,) units of F0
        fr = np.maximum(np.max(self.friction[cols, idx], axis=1, initial=0.0), 0.0)  # (k,)
        total = self.normal[cols, idx].sum(axis=1)  # (k,)
        ok = (eq <= REUSE_TOL) & (fr <= REUSE_TOL) & (total <= sc.grip_bound * (1 + REUSE_TOL))
        if system.tau_max is not None and k:
            tau = self.torque[cols, idx].sum(axis=1)  # (k, M)
            ok &= ~np.any(np.abs(tau) > system.tau_max * (1.0 + LIMIT_TOL), axis=1)
        return ok


def stationary_verdicts(system: GraspSystem, combinations: list[str],
                        progress: Callable[[int], None] | None = None) -> StationaryVerdicts:
    """Eq. (18) for every combination of the list, strongest first, with one LP per combination
    that no earlier answer decides (module docstring). An infeasible combination's ``violation``
    is its own :func:`stationary_violation` when it was decided by its own LP or when the bound of
    the stronger infeasible ones is at most ``DEGENERATE_TOL`` (so degenerate verdicts are
    marked), else that bound. ``progress(k)`` is called with the LPs solved so far."""
    R = len(combinations)
    cls = classes(combinations)  # (R, L)
    Fm, Sm = _masks(cls) if R else (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))  # (R,), (R,)
    status = np.zeros(R, dtype=np.int8)  # 0 undecided, 1 feasible, -1 infeasible
    violation = np.full(R, np.nan)
    own = np.zeros(R, dtype=bool)  # decided by its own LP
    infeasible_rows: list[int] = []
    lps = 0
    order = np.argsort(-cls.sum(axis=1, dtype=np.int64), kind="stable").tolist() if R else []
    for r in order:
        if status[r]:
            continue
        sel = selection(system, combinations[r])
        st, fs = statics(system, sel), friction_set(system, sel)
        found = min_total_normal(system, st, fs)
        lps += 1
        own[r] = True
        open_ = np.flatnonzero(status == 0)
        if found is None:
            status[r] = -1
            violation[r] = _violation(stationary_violation(system, st, fs))
            lps += 1
            infeasible_rows.append(r)
            weaker = open_[_at_most(Fm[open_], Sm[open_], int(Fm[r]), int(Sm[r]))]
            status[weaker] = -1
        else:
            status[r] = 1
            wit = _Witness.of(system, contact_forces(system, sel, found[1]))
            wF, wS = _masks(wit.classes[None, :])
            fits = open_[_at_most(wF, wS, Fm[open_], Sm[open_])]  # classes at least the witness's
            fits = fits[fits != r]
            status[fits[wit.certifies(system, cls[fits])]] = 1
        if progress is not None:
            progress(lps)
    # the bound of each pruned infeasible combination: the largest violation of the stronger
    # infeasible ones (its own is at least that); at most DEGENERATE_TOL: its own LP says
    pruned = np.flatnonzero((status == -1) & ~own)
    bound = np.full(pruned.size, -np.inf)
    for r in infeasible_rows:
        v = violation[r]
        dom = _at_most(Fm[pruned], Sm[pruned], int(Fm[r]), int(Sm[r]))
        bound[dom] = np.maximum(bound[dom], np.inf if np.isnan(v) else v)
    for k, row in enumerate(pruned.tolist()):
        if bound[k] > DEGENERATE_TOL:
            violation[row] = bound[k]
        else:
            sel = selection(system, combinations[row])
            violation[row] = _violation(stationary_violation(system, statics(system, sel), friction_set(system, sel)))
            lps += 1
    return StationaryVerdicts(status == 1, violation, own, lps)


def _violation(v: float | None) -> float:
    """A violation as a float (nan when no contact carries force: :func:`stationary_violation`)."""
    return np.nan if v is None else float(v)
