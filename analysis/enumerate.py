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

import heapq
import itertools
import multiprocessing as mp
import os
import re
from collections.abc import Callable, Iterable
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.combination import CombinationParts, CombinationSummary, no_grasp_reason, summarize_with_member
from analysis.contacts import GraspSystem
from analysis.dafc import allowable_cone
from analysis.dafc_family import FamilyKinematics, MemberCertificate, members_at, slip_depends_on_redundancy
from analysis.exceptions import CombinationError
from analysis.motion import motion_dims
from analysis.stationary_table import CLASS, stationary_verdicts

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
    dafc_searched: int = 0  # combinations whose DAFC was decided by their own search
    dafc_shared: int = 0  # combinations decided by a re-checked member (motion) of a stronger one
    dafc_batched: int = 0  # of the DAFC LPs, force LPs at a stronger one's member motion (one HiGHS call a batch)
    dafc_ahead_unused: int = 0  # own searches run ahead in a worker, then decided by a member first

    @property
    def lps(self) -> int:
        return self.stationary_lps + self.dafc_lps


def _order(combos: Iterable[str]) -> list[str]:
    """Strongest combinations first (stable), so infeasibility and members propagate downwards."""
    return sorted(combos, key=lambda c: -sum(CLASS[s] for s in c))


#: Enumerations larger than this are split over worker processes (when ``workers`` > 1).
PARALLEL_THRESHOLD = 2000
#: Own DAFC searches run ahead of the committed order per worker (speculation window).
AHEAD = 8
#: Member motions of stronger combinations tried per combination, and force LPs per HiGHS call.
MOTIONS_PER_ROW = 2
BATCH = 256

_WORKER: dict[str, object] = {}


def _worker_init(system: GraspSystem) -> None:
    _WORKER["system"] = system


def _own_search(system: GraspSystem, combination: str) -> tuple[CombinationSummary, MemberCertificate | None, int]:
    """The DAFC search of one combination whose stationary grasp exists: its summary, the
    certificate of its member (for the family) and the LPs it solved."""
    parts = CombinationParts.build(system, combination)
    oracle = parts.oracle()
    summary, member = summarize_with_member(parts, stationary_known=True, oracle=oracle, realisable=False)
    cert = MemberCertificate.of(parts, member) if member is not None else None
    return summary, cert, oracle.lp_count


def _worker_search(combination: str) -> tuple[CombinationSummary, MemberCertificate | None, int]:
    system = _WORKER["system"]
    assert isinstance(system, GraspSystem)
    return _own_search(system, combination)


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
    Results are returned in the canonical product order (F/S/D or N/D per contact), or in the
    order of ``combinations``.

    The combinations are decided in stages, each over all of them at once: the motion-space
    dimensions (batched SVDs, :func:`analysis.motion.motion_dims`); the stationary grasps, by
    monotonicity from few LPs (:mod:`analysis.stationary_table`); then DAFC, strongest first,
    each combination by its own search (:func:`analysis.dafc.dafc_nonempty`) unless the
    re-checked member of a stronger combination decides it (:mod:`analysis.dafc_family`).
    ``workers`` processes (default: all cores above ``PARALLEL_THRESHOLD`` combinations, else 1)
    run the own searches ahead of the strongest-first order; the results are committed in that
    order, so the table does not depend on the number of workers.
    ``where`` (:func:`parse_where`) keeps only the combinations it accepts; ``limit`` stops after
    that many feasible combinations (strongest first) and returns the rows decided so far, with
    ``stats.stopped_at_limit``. ``progress(done, total)`` is called as combinations are decided.
    """
    letters = ["FSD" if m > 0 else "ND" for m in system.mu]
    canonical = ["".join(p) for p in itertools.product(*letters)] if combinations is None else list(combinations)
    if where is not None:
        canonical = [c for c in canonical if where(c)]
    if limit is not None and limit < 1:
        raise CombinationError(("limit",), f"{limit} must be at least 1")
    if workers is None:
        workers = (os.cpu_count() or 1) if len(canonical) > PARALLEL_THRESHOLD else 1
    ordered = _order(dict.fromkeys(canonical))
    results, stats = _Enumeration(system, ordered, admissible, progress).run(workers, limit)
    stats.combinations = len(canonical)
    return [results[c] for c in canonical if c in results], stats


class _Enumeration:
    """The staged enumeration of :func:`enumerate_combinations` over ``ordered`` (strongest first)."""

    def __init__(self, system: GraspSystem, ordered: list[str], admissible: Callable[[str], bool] | None,
                 progress: Callable[[int, int], None] | None) -> None:
        self.system, self.ordered, self.admissible, self.progress = system, ordered, admissible, progress
        self.results: dict[str, CombinationSummary] = {}
        self.stats = EnumerationStats()
        self.kin = FamilyKinematics(system)

    def _tick(self) -> None:
        if self.progress is not None:
            self.progress(len(self.results), len(self.ordered))

    def run(self, workers: int, limit: int | None) -> tuple[dict[str, CombinationSummary], EnumerationStats]:
        sy, st, res = self.system, self.stats, self.results
        D = sy.D
        a, a_bar = motion_dims(sy, self.ordered) if self.ordered else (np.zeros(0, int), np.zeros(0, int))
        self.dims = {c: (int(a[k]), int(a_bar[k])) for k, c in enumerate(self.ordered)}
        moving: list[str] = []
        for c in self.ordered:
            ak, abk = self.dims[c]
            if abk == 0:
                st.pruned_motion += 1
                res[c] = CombinationSummary(c, False, "object cannot move (a~ = 0)", ak, 0, 0, D, True, None)
            elif self.admissible is not None and not self.admissible(c):
                st.pruned_modes += 1
                res[c] = CombinationSummary(c, False, "no object motion realises these contact states",
                                            ak, abk, 0, D - abk, True, None)
            else:
                moving.append(c)
        self._tick()
        verdicts = stationary_verdicts(sy, moving)
        st.stationary_lps += verdicts.lps
        self.dafc_rows: list[str] = []
        for k, c in enumerate(moving):
            ak, abk = self.dims[c]
            if verdicts.feasible[k]:
                self.dafc_rows.append(c)
                continue
            v = float(verdicts.violation[k])
            res[c] = CombinationSummary(c, False, no_grasp_reason(None if np.isnan(v) else v), ak, abk, 0,
                                        D - abk, True, None)
        st.pruned_stationary = int(np.sum(~verdicts.own))  # (18) decided without an LP of its own
        self._tick()
        self._dafc(workers)
        if limit is not None:
            self._cut(limit)
        return res, st

    # -- DAFC: own searches and families ------------------------------------------------------------

    def _commit(self, c: str, summary: CombinationSummary, cert: MemberCertificate | None, lps: int) -> None:
        self.results[c] = summary
        self.stats.dafc_lps += lps
        self.stats.dafc_searched += 1
        if cert is not None:
            self._share(cert)

    def _share(self, cert: MemberCertificate) -> None:
        """Decide the undecided combinations of the certificate's family that it passes for, and
        queue its motion for the force LPs of the others below its combination (:meth:`_resolve`)."""
        sy = self.system
        family = [c for c in cert.family(sy) if c in self.pending and c not in self.results]
        if family:
            for c, good in zip(family, cert.check(self.kin, family), strict=True):
                if good:
                    self._feasible(c, cert.motion)
        for c in cert.below():
            if c in self.pending and c not in self.results:
                motions = self.queue.setdefault(c, [])
                if not motions:
                    heapq.heappush(self.heap, (self.pos[c], c))
                if len(motions) < MOTIONS_PER_ROW:
                    motions.append(cert.motion)

    def _feasible(self, c: str, motion: Array) -> bool:
        """Record ``c`` as feasible with the member motion ``motion`` (already certified for it),
        with the dimension of its allowable cone; False when that cone has no direction."""
        sy = self.system
        ak, abk = self.dims[c]
        dim = self._cone_dim(c, motion)
        if dim is None:
            return False
        exact = "S" not in c or (abk == 1 and not slip_depends_on_redundancy(sy, c))
        self.results[c] = CombinationSummary(c, True, "feasible", ak, abk, dim, sy.D - abk, exact,
                                             motion[sy.M:].copy(), motion)
        self.stats.dafc_shared += 1
        self.queue.pop(c, None)
        return True

    def _resolve(self, c: str) -> None:
        """Try the queued motions of stronger combinations' members on ``c`` and the next queued
        combinations (strongest first), all force LPs in one (:func:`members_at`)."""
        while c in self.queue and c not in self.results:
            batch: list[str] = []
            while self.heap and len(batch) < BATCH:
                _, row = heapq.heappop(self.heap)
                if row in self.queue and row not in self.results:
                    batch.append(row)
            if not batch:
                return
            pairs = [(row, self.queue[row][0]) for row in batch]
            good = members_at(self.kin, pairs)
            self.stats.dafc_lps += len(pairs)
            self.stats.dafc_batched += len(pairs)
            for (row, motion), ok in zip(pairs, good, strict=True):
                if ok and self._feasible(row, motion):
                    continue
                rest = self.queue.get(row, [])[1:]
                if rest:
                    self.queue[row] = rest
                    heapq.heappush(self.heap, (self.pos[row], row))
                else:
                    self.queue.pop(row, None)

    def _cone_dim(self, c: str, motion: Array) -> int | None:
        """The dimension of the allowable cone (the table's DAFC dimension for a member): ``a_bar``
        when a motion that separates every D-point strictly proves the cone full-dimensional
        (:meth:`FamilyKinematics.separating`), else from its generators
        (cdd), as :func:`analysis.dafc.dafc_nonempty` computes it; None when it has none."""
        if self.kin.separating(c, motion) is not None:
            return self.dims[c][1]
        parts = CombinationParts.build(self.system, c)
        dirs = allowable_cone(parts.ms).all_directions()
        if dirs.shape[0] == 0:
            return None
        return int(np.linalg.matrix_rank(dirs, tol=1e-9))

    def _dafc(self, workers: int) -> None:
        self.pending = set(self.dafc_rows)
        self.pos = {c: k for k, c in enumerate(self.dafc_rows)}
        self.queue: dict[str, list[Array]] = {}  # queued member motions of stronger combinations
        self.heap: list[tuple[int, str]] = []  # their combinations, strongest first
        if workers <= 1 or len(self.dafc_rows) < 2:
            for c in self.dafc_rows:
                self._resolve(c)
                if c not in self.results:
                    self._commit(c, *_own_search(self.system, c))
                    self._tick()
            return
        # own searches run ahead in worker processes; results are committed strictly in order
        ctx = mp.get_context("fork")
        with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_worker_init,
                                 initargs=(self.system,)) as pool:
            futures: dict[str, Future[tuple[CombinationSummary, MemberCertificate | None, int]]] = {}
            ahead = 0
            for k, c in enumerate(self.dafc_rows):
                self._resolve(c)
                if c in self.results:
                    fut = futures.pop(c, None)
                    if fut is not None and not fut.cancel():
                        self.stats.dafc_ahead_unused += 1  # it ran: decided by a member meanwhile
                    continue
                # keep the window full: the next combinations after c that nothing decides yet
                for nxt in self.dafc_rows[max(k, ahead):]:
                    ahead += 1
                    if len(futures) >= AHEAD * workers:
                        ahead -= 1
                        break
                    if nxt not in self.results and nxt not in futures and nxt not in self.queue:
                        futures[nxt] = pool.submit(_worker_search, nxt)
                fut = futures.pop(c, None)
                out = fut.result() if fut is not None else _own_search(self.system, c)
                self._commit(c, *out)
                self._tick()
                for done in [n for n in futures if n in self.results]:
                    if not futures.pop(done).cancel():
                        self.stats.dafc_ahead_unused += 1

    def _cut(self, limit: int) -> None:
        """Keep the rows up to the ``limit``-th feasible one (strongest-first order)."""
        feasible = 0
        for k, c in enumerate(self.ordered):
            feasible += self.results[c].feasible
            if feasible >= limit:
                self.stats.stopped_at_limit = k + 1 < len(self.ordered)
                for rest in self.ordered[k + 1:]:
                    self.results.pop(rest, None)
                return
