"""Results remembered within a scope, by their exact inputs (the planner opens one per plan).

The grasp states of one search pose the same linear algebra and the same LPs again: a state
reached by releasing contacts has, for its all-sticking combination, the matrices its parent has
for the combination with those contacts ``D`` (the same ``J_c``, ``G_c``, ``A_c`` bit for bit).
Inside :func:`scope` a deterministic computation asked for with inputs equal, bit for bit, to
those of an earlier one returns the earlier result (:func:`remembered`): the one-shot LPs
(:func:`analysis.solvers.highs.solve_lp`), the pseudo-inverses and null spaces of the statics
(eq. 8-10) and of the motion space (eq. 7, 19). Each is a function of those inputs only (LAPACK
and a fresh HiGHS instance are deterministic), so the result is the one the computation would
give; its arrays are made read-only, as every caller in the scope shares them. Outside a scope
nothing is kept, and a computation that raises is not remembered. A scope keeps the
:data:`MAX_ENTRIES` results used last (the repeats come from a state and its parent, close
together in a search; the nine-contact wrap's plan computes 2,522 distinct ones, about 19 kB each
with their keys).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")

#: Results a scope keeps (the least recently used is dropped beyond it).
MAX_ENTRIES = 1024

#: The results of the open scope by key, least recently used first (``None``: no scope open).
_SCOPE: ContextVar[dict[tuple[Any, ...], Any] | None] = ContextVar("analysis_memo", default=None)


@contextmanager
def scope() -> Iterator[None]:
    """Within the block, :func:`remembered` computes each distinct key once; a block inside
    another shares the outer one's results, and a new block starts empty."""
    if _SCOPE.get() is not None:
        yield
        return
    token = _SCOPE.set({})
    try:
        yield
    finally:
        _SCOPE.reset(token)


def exact_key(*arrays: Any) -> tuple[Any, ...]:
    """The exact value of each argument as float: its shape and bytes (``None`` kept as ``None``)."""
    out: list[Any] = []
    for a in arrays:
        if a is None:
            out.append(None)
        else:
            v = np.asarray(a, dtype=float)
            out.append((v.shape, v.tobytes()))
    return tuple(out)


def active() -> bool:
    """Whether a scope is open (the caller may skip building a key otherwise)."""
    return _SCOPE.get() is not None


def remembered(key: tuple[Any, ...], compute: Callable[[], T], arrays: Callable[[T], tuple[Any, ...]]) -> T:
    """``compute()``, or inside a scope the result remembered under ``key`` (which must hold every
    input of the computation exactly, and name it); ``arrays(result)`` lists the result's arrays,
    made read-only when it is kept."""
    memo = _SCOPE.get()
    if memo is None:
        return compute()
    if key in memo:
        got: T = memo.pop(key)
        memo[key] = got  # the most recently used last
        return got
    got = compute()
    for a in arrays(got):
        if isinstance(a, np.ndarray):
            a.setflags(write=False)
    memo[key] = got
    if len(memo) > MAX_ENTRIES:
        del memo[next(iter(memo))]
    return got
