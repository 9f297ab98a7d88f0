"""Enumeration of all contact-state combinations with pruning.

A combination is feasible when the stationary grasp (18) exists and DAFC (22) is non-empty.
Pruning, all exact:

* motion space: ``a~ = 0`` (the object cannot move) needs only an SVD;
* stationary grasp monotonicity: the force set of a contact shrinks F -> S/N -> D (cone ->
  normal only -> nothing), so (18) infeasible for a combination is infeasible for every
  combination that downgrades any of its contacts, and a solution whose forces fit a weaker
  pattern (zero force, or normal-only) certifies every combination at least as strong;
* optionally the kinematic contact modes (:mod:`analysis.modes`): a combination no object
  twist realises (F stick, S slide, D not penetrating) is skipped.
"""

from __future__ import annotations

import itertools
import multiprocessing as mp
import os
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.combination import CombinationParts, CombinationSummary, summarize
from analysis.contacts import GraspSystem
from analysis.stationary import min_total_normal

_CLASS = {"F": 2, "S": 1, "N": 1, "D": 0}


@dataclass
class EnumerationStats:
    combinations: int = 0
    pruned_motion: int = 0
    pruned_stationary: int = 0
    pruned_modes: int = 0
    stationary_lps: int = 0
    dafc_lps: int = 0


class _StationaryCache:
    """Monotone memory of stationary-grasp feasibility over force classes (F=2, S/N=1, D=0)."""

    def __init__(self, L: int) -> None:
        self.infeasible = np.zeros((0, L), dtype=np.int8)  # (k, L)
        self.witnesses = np.zeros((0, L), dtype=np.int8)  # (k, L)

    def known(self, cls: tuple[int, ...]) -> bool | None:
        c = np.asarray(cls, dtype=np.int8)
        if self.witnesses.shape[0] and bool(np.any(np.all(c >= self.witnesses, axis=1))):
            return True
        if self.infeasible.shape[0] and bool(np.any(np.all(c <= self.infeasible, axis=1))):
            return False
        return None

    def add(self, cls: tuple[int, ...], witness: tuple[int, ...] | None) -> None:
        if witness is None:
            self.infeasible = np.vstack([self.infeasible, np.asarray(cls, dtype=np.int8)])
        else:
            self.witnesses = np.vstack([self.witnesses, np.asarray(witness, dtype=np.int8)])


def _witness_classes(parts: CombinationParts, f_c: Array) -> tuple[int, ...]:
    """Weakest force class of each contact that the solution ``f_c`` still satisfies."""
    sy, sel = parts.system, parts.sel
    out = []
    scale = max(1e-12, float(np.max(np.abs(f_c), initial=0.0)))
    for i, s in enumerate(sel.combination):
        sl = sel.c_slices[i]
        f = f_c[sl]
        if s == "D" or float(np.max(np.abs(f), initial=0.0)) <= 1e-9 * scale:
            out.append(0)
        elif s == "F" and np.linalg.norm(f - (f @ sy.normals[i]) * sy.normals[i]) > 1e-9 * scale:
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
) -> tuple[list[CombinationSummary], EnumerationStats]:
    """Summaries of every combination (scene order of letters), strongest-first evaluation.

    ``admissible`` (e.g. from the contact modes) may veto combinations no motion realises.
    Results are returned in the canonical product order (F/S/D or N/D per contact).
    ``workers``: processes for large enumerations (default: all cores above
    ``PARALLEL_THRESHOLD`` combinations, else 1); each worker keeps its own pruning memory.
    """
    letters = ["FSD" if m > 0 else "ND" for m in system.mu]
    canonical = ["".join(p) for p in itertools.product(*letters)] if combinations is None else list(combinations)
    if workers is None:
        workers = (os.cpu_count() or 1) if len(canonical) > PARALLEL_THRESHOLD else 1
    if workers <= 1:
        return _enumerate_serial(system, canonical, admissible, progress)
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
) -> tuple[list[CombinationSummary], EnumerationStats]:
    stats = EnumerationStats(combinations=len(canonical))
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
        known = cache.known(cls)
        if known is None:
            stats.stationary_lps += 1
            found = min_total_normal(system, st, parts.fs)
            cache.add(cls, None if found is None else _witness_classes(parts, found[1]))
            known = found is not None
        else:
            stats.pruned_stationary += 1
        summary = summarize(parts, stationary_known=known)
        results[c] = summary
    if progress is not None:
        progress(len(ordered), len(ordered))
    return [results[c] for c in canonical], stats
