"""Enumeration of all contact-state combinations with pruning.

A combination is feasible when the stationary grasp (18) exists and DAFC (22) is non-empty.
Pruning, all exact:

* motion space: ``a~ = 0`` (the object cannot move) needs only an SVD;
* stationary grasp monotonicity: the force set of a contact shrinks F -> S/N -> D (cone ->
  normal only -> nothing), so (18) infeasible for a combination is infeasible for every
  combination that downgrades any of its contacts, and a solution whose forces fit a weaker
  pattern (zero force, or normal-only, by the absolute thresholds of :mod:`analysis.scales`)
  is a candidate certificate for every combination at least as strong, used only once it is
  re-checked against that combination's eq. (18) in newtons;
* optionally the kinematic contact modes (:mod:`analysis.modes`): a combination no object
  twist realises (F stick, S slide, D not penetrating) is skipped.
"""

from __future__ import annotations

import itertools
import multiprocessing as mp
import os
import re
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.combination import CombinationParts, CombinationSummary, summarize
from analysis.contacts import GraspSystem
from analysis.exceptions import CombinationError
from analysis.scales import REUSE_TOL
from analysis.stationary import DEGENERATE_TOL, certifies, min_total_normal, stationary_violation

_CLASS = {"F": 2, "S": 1, "N": 1, "D": 0}


_OPS: dict[str, Callable[[int, int], bool]] = {
    ">=": lambda a, b: a >= b, "<=": lambda a, b: a <= b, "==": lambda a, b: a == b,
    "!=": lambda a, b: a != b, ">": lambda a, b: a > b, "<": lambda a, b: a < b, "=": lambda a, b: a == b,
}
_WHERE = re.compile(r"^\s*([FSND])\s*(>=|<=|==|!=|=|>|<)\s*(\d+)\s*$")


def parse_where(text: str) -> Callable[[str], bool]:
    """A filter on letter counts, e.g. ``'D>=3'`` or ``'F<=2, S==0'`` (all must hold).

    Raise :class:`CombinationError` at ``where`` naming the part that is not ``<letter><op><count>``.
    """
    conds: list[tuple[str, Callable[[int, int], bool], int]] = []
    for part in re.split(r",|\band\b", text):
        if not part.strip():
            continue
        m = _WHERE.match(part.upper())
        if m is None:
            raise CombinationError(("where",), f"'{part.strip()}' is not a condition like 'D>=3' "
                                   "(a letter F, S, N or D, one of >= <= == != > <, a count)")
        conds.append((m.group(1), _OPS[m.group(2)], int(m.group(3))))
    if not conds:
        raise CombinationError(("where",), "is empty: give conditions like 'D>=3' or 'F<=2, S==0'")
    return lambda c: all(op(c.count(letter), k) for letter, op, k in conds)


@dataclass
class EnumerationStats:
    combinations: int = 0
    pruned_motion: int = 0
    pruned_stationary: int = 0
    pruned_modes: int = 0
    stationary_lps: int = 0
    dafc_lps: int = 0  # LPs of the DAFC oracles (membership, redundancy, relaxation, realisability)
    stopped_at_limit: bool = False  # the enumeration stopped after ``limit`` feasible combinations


class _StationaryCache:
    """Monotone memory of stationary-grasp feasibility over force classes (F=2, S/N=1, D=0).

    An infeasible combination makes every combination it dominates infeasible (their force sets
    are subsets). A feasible one leaves its certificate: the contact forces ``(L, d)`` in newtons
    and the weakest class each contact needs (zero force -> 0, normal only -> 1, else 2, with the
    absolute thresholds of :mod:`analysis.scales`). A cached certificate answers for another
    combination only after it is re-checked against that combination's eq. (18) in physical units
    (:func:`analysis.stationary.certifies`).
    """

    def __init__(self, L: int) -> None:
        self.infeasible = np.zeros((0, L), dtype=np.int8)  # (k, L)
        self.witnesses = np.zeros((0, L), dtype=np.int8)  # (k, L)
        self.forces: list[Array] = []  # per witness, (L, d) contact forces [N]
        self.violations = np.zeros(0)  # per infeasible entry, its least friction violation (inf: none)

    def candidates(self, cls: tuple[int, ...]) -> list[Array]:
        """Cached certificates whose classes fit the combination with classes ``cls``."""
        if not self.witnesses.shape[0]:
            return []
        c = np.asarray(cls, dtype=np.int8)
        return [self.forces[k] for k in np.flatnonzero(np.all(c >= self.witnesses, axis=1))[:4]]

    def infeasible_for(self, cls: tuple[int, ...]) -> tuple[bool, float | None]:
        """Is (18) infeasible for ``cls`` by a cached stronger combination, and the largest friction
        violation among those (a lower bound of its own: a weaker force set needs at least as much)."""
        if not self.infeasible.shape[0]:
            return False, None
        c = np.asarray(cls, dtype=np.int8)
        hit = np.all(c <= self.infeasible, axis=1)
        if not np.any(hit):
            return False, None
        return True, float(np.max(self.violations[hit]))

    def add_infeasible(self, cls: tuple[int, ...], violation: float | None) -> None:
        self.infeasible = np.vstack([self.infeasible, np.asarray(cls, dtype=np.int8)])
        self.violations = np.r_[self.violations, np.inf if violation is None else violation]

    def add_witness(self, parts: CombinationParts, f_c: Array) -> None:
        forces = _contact_forces(parts, f_c)
        self.witnesses = np.vstack([self.witnesses, np.asarray(_witness_classes(parts, forces), dtype=np.int8)])
        self.forces.append(forces)


def _contact_forces(parts: CombinationParts, f_c: Array) -> Array:
    """The force on the object at every contact, ``(L, d)`` world frame [N] (zero at D-points)."""
    sy, sel = parts.system, parts.sel
    out = np.zeros((sy.L, sy.d))
    for i, s in enumerate(sel.combination):
        f = f_c[sel.c_slices[i]]
        if s == "F":
            out[i] = f
        elif s in "SN":
            out[i] = float(f[0]) * sy.normals[i]
    return out


def _selected_forces(parts: CombinationParts, forces: Array) -> Array:
    """``f_c`` of the combination of ``parts`` from contact forces ``(L, d)``."""
    sy, sel = parts.system, parts.sel
    out = np.zeros(sel.L_c)
    for i, s in enumerate(sel.combination):
        sl = sel.c_slices[i]
        if s == "F":
            out[sl] = forces[i]
        elif s in "SN":
            out[sl] = forces[i] @ sy.normals[i]
    return out


def _witness_classes(parts: CombinationParts, forces: Array) -> tuple[int, ...]:
    """Weakest force class of each contact that the contact forces ``(L, d)`` still satisfy:
    0 when the force is at most ``ZERO_FORCE F0``, 1 when its tangential part is, else 2."""
    sy = parts.system
    zero = sy.scales.zero_force
    out = []
    for i in range(sy.L):
        f = forces[i]
        if float(np.linalg.norm(f)) <= zero:
            out.append(0)
        elif np.linalg.norm(f - (f @ sy.normals[i]) * sy.normals[i]) > zero:
            out.append(2)
        else:
            out.append(1)
    return tuple(out)


def _order(combos: Iterable[str]) -> list[str]:
    """Strongest combinations first, so infeasibility propagates downwards."""
    return sorted(combos, key=lambda c: -sum(_CLASS[s] for s in c))


#: Enumerations larger than this are split over worker processes (when ``workers`` > 1).
PARALLEL_THRESHOLD = 2000

_WORKER: dict[str, object] = {}


def _worker_init(system: GraspSystem, admissible: Callable[[str], bool] | None) -> None:
    _WORKER["system"] = system
    _WORKER["admissible"] = admissible


def _worker_run(chunk: list[str]) -> tuple[list[CombinationSummary], EnumerationStats]:
    system = _WORKER["system"]
    assert isinstance(system, GraspSystem)
    adm = _WORKER["admissible"]
    return _enumerate_serial(system, chunk, adm if callable(adm) else None, None)


def enumerate_combinations(
    system: GraspSystem,
    combinations: Iterable[str] | None = None,
    admissible: Callable[[str], bool] | None = None,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
    where: Callable[[str], bool] | None = None,
    limit: int | None = None,
) -> tuple[list[CombinationSummary], EnumerationStats]:
    """Summaries of every combination (scene order of letters), strongest-first evaluation.

    ``admissible`` (e.g. from the contact modes) may veto combinations no motion realises.
    Results are returned in the canonical product order (F/S/D or N/D per contact).
    ``workers``: processes for large enumerations (default: all cores above
    ``PARALLEL_THRESHOLD`` combinations, else 1); each worker keeps its own pruning memory.
    ``where`` (:func:`parse_where`) keeps only the combinations it accepts; ``limit`` stops after
    that many feasible combinations (one process, strongest first) and returns the rows decided so
    far, with ``stats.stopped_at_limit``.
    """
    letters = ["FSD" if m > 0 else "ND" for m in system.mu]
    canonical = ["".join(p) for p in itertools.product(*letters)] if combinations is None else list(combinations)
    if where is not None:
        canonical = [c for c in canonical if where(c)]
    if limit is not None:
        if limit < 1:
            raise CombinationError(("limit",), f"{limit} must be at least 1")
        workers = 1
    if workers is None:
        workers = (os.cpu_count() or 1) if len(canonical) > PARALLEL_THRESHOLD else 1
    if workers <= 1:
        return _enumerate_serial(system, canonical, admissible, progress, limit)
    ordered = _order(canonical)
    n_chunks = max(workers * 2, 1)
    chunks = [ordered[k::n_chunks] for k in range(n_chunks)]  # interleaved: similar strength mix
    stats = EnumerationStats(combinations=len(canonical))
    results: dict[str, CombinationSummary] = {}
    done = 0
    ctx = mp.get_context("fork")
    with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_worker_init,
                             initargs=(system, admissible)) as pool:
        for summaries, st in pool.map(_worker_run, chunks):
            for sm in summaries:
                results[sm.combination] = sm
            for f in ("pruned_motion", "pruned_stationary", "pruned_modes", "stationary_lps", "dafc_lps"):
                setattr(stats, f, getattr(stats, f) + getattr(st, f))
            done += len(summaries)
            if progress is not None:
                progress(done, len(canonical))
    return [results[c] for c in canonical], stats


def _enumerate_serial(
    system: GraspSystem,
    canonical: list[str],
    admissible: Callable[[str], bool] | None,
    progress: Callable[[int, int], None] | None,
    limit: int | None = None,
) -> tuple[list[CombinationSummary], EnumerationStats]:
    stats = EnumerationStats(combinations=len(canonical))
    feasible = 0
    cache = _StationaryCache(system.L)
    results: dict[str, CombinationSummary] = {}
    ordered = _order(canonical)
    for k, c in enumerate(ordered):
        if progress is not None:
            progress(k, len(ordered))
        parts = CombinationParts.build(system, c)
        ms, st = parts.ms, parts.st
        if ms.a_bar == 0:
            stats.pruned_motion += 1
            results[c] = CombinationSummary(c, False, "object cannot move (a~ = 0)", ms.a, 0, 0, st.p, True, None)
            continue
        if admissible is not None and not admissible(c):
            stats.pruned_modes += 1
            results[c] = CombinationSummary(c, False, "no object motion realises these contact states",
                                            ms.a, ms.a_bar, 0, st.p, True, None)
            continue
        cls = tuple(_CLASS[s] for s in c)
        pruned, bound = cache.infeasible_for(cls)
        known: bool | None = False if pruned else None
        violation: float | None = None
        if pruned and bound is not None and bound > DEGENERATE_TOL:
            violation = bound  # not degenerate: its own violation is at least that
        if known is None and any(certifies(system, st, parts.fs, _selected_forces(parts, f), REUSE_TOL)
                                 for f in cache.candidates(cls)):
            known = True
        if known is None:
            stats.stationary_lps += 1
            found = min_total_normal(system, st, parts.fs)
            if found is None:
                violation = stationary_violation(system, st, parts.fs)
                cache.add_infeasible(cls, violation)
            else:
                cache.add_witness(parts, found[1])
            known = found is not None
        else:
            stats.pruned_stationary += 1
        oracle = parts.oracle()
        summary = summarize(parts, stationary_known=known, violation=violation, oracle=oracle)
        stats.dafc_lps += oracle.lp_count
        results[c] = summary
        feasible += summary.feasible
        if limit is not None and feasible >= limit:
            stats.stopped_at_limit = k + 1 < len(ordered)
            break
    if progress is not None:
        progress(len(ordered), len(ordered))
    return [results[c] for c in canonical if c in results], stats
