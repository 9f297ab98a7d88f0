"""The bookkeeping of :mod:`analysis.stationary_table`: force classes read as bytes, and the bit
masks that decide "at most these classes, contact by contact" for many rows at once."""

from __future__ import annotations

import numpy as np

from analysis.stationary_table import CLASS, _at_most, _masks, classes


def test_classes_known_answer() -> None:
    got = classes(["FSND", "DDFF"])
    assert got.dtype == np.int8
    np.testing.assert_array_equal(got, [[2, 1, 1, 0], [0, 0, 2, 2]])


def test_classes_are_the_letters_classes() -> None:
    assert classes([]).shape == (0, 0)
    rows = ["FS", "FS"]
    np.testing.assert_array_equal(classes(rows), [[CLASS[s] for s in c] for c in rows])


def test_masks_decide_elementwise_order() -> None:
    """``_at_most`` on the masks equals ``np.all(a <= b)`` for seeded random class rows, also
    with the top given per row (the witness test: rows at least a witness's classes)."""
    rng = np.random.default_rng(7)
    for L in (1, 5, 12, 20):
        cls = rng.integers(0, 3, size=(400, L)).astype(np.int8)  # (R, L)
        Fm, Sm = _masks(cls)
        for r in rng.integers(0, 400, size=20):
            want = np.all(cls <= cls[r], axis=1)
            np.testing.assert_array_equal(_at_most(Fm, Sm, int(Fm[r]), int(Sm[r])), want)
            # at least row r: r's masks against every row's as the top
            np.testing.assert_array_equal(_at_most(Fm[r:r + 1], Sm[r:r + 1], Fm, Sm), np.all(cls >= cls[r], axis=1))
