"""``analysis.memo``: inside a scope the statics (eq. 8-10) and the motion space (eq. 7, 19) of a
combination are computed once per exact ``J_c``, ``G_c`` / ``A_c`` and shared read-only, bit for
bit what they are outside it; a released contact's state shares them with its parent's
combination that has the contact ``D`` (issue 11: planner speed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis import memo
from analysis.contacts import build_system, selection
from analysis.loader import load_scene
from analysis.motion import motion_space
from analysis.statics import statics

ROOT = Path(__file__).resolve().parents[2]


def _arrays(st, ms):  # type: ignore[no-untyped-def]
    return [st.JcT_pinv, st.Gamma, st.D, st.Xi, ms.Lambda, ms.Lambda_r_t, ms.Lambda_q_t, ms.Lambda_qr_t]


def test_scope_shares_statics_and_motion_space_bit_for_bit() -> None:
    scene = load_scene(ROOT / "examples" / "planar_disk_envelope.json")
    system = build_system(scene)
    released = scene.model_copy(update={"contacts": scene.contacts[2:]})  # the left finger let go
    child = build_system(released)
    fresh = {c: (statics(system, selection(system, c)), motion_space(system, selection(system, c)))
             for c in ("FFFFF", "DDFFF")}
    with memo.scope():
        a = [(statics(s, selection(s, c)), motion_space(s, selection(s, c)))
             for s, c in ((system, "FFFFF"), (system, "DDFFF"), (system, "DDFFF"), (child, "FFF"))]
        for (st, ms), c in zip(a[:3], ("FFFFF", "DDFFF", "DDFFF"), strict=True):
            for got, want in zip(_arrays(st, ms), _arrays(*fresh[c]), strict=True):
                np.testing.assert_array_equal(got, want)
                assert not got.flags.writeable
        same = zip(_arrays(*a[1]), _arrays(*a[2]), strict=True)
        assert all(x is y for x, y in same)  # one computation for the same combination
        # the parent's DDFFF and the child's FFF: the same J_c, G_c and A_c, so the same bases
        np.testing.assert_array_equal(a[1][0].J_c, a[3][0].J_c)
        assert all(x is y for x, y in zip(_arrays(*a[1]), _arrays(*a[3]), strict=True))
        assert not any(x is y for x, y in zip(_arrays(*a[0]), _arrays(*a[1]), strict=True))
    st, ms = statics(system, selection(system, "DDFFF")), motion_space(system, selection(system, "DDFFF"))
    assert st.Gamma.flags.writeable and st.Gamma is not a[1][0].Gamma  # outside a scope: computed afresh


def test_a_computation_that_raises_is_not_remembered() -> None:
    calls = {"n": 0}

    def fails() -> tuple[np.ndarray]:
        calls["n"] += 1
        raise ValueError("no")

    with memo.scope():
        for _ in range(2):
            with pytest.raises(ValueError):
                memo.remembered(("t",), fails, lambda r: r)
        assert calls["n"] == 2
        x = memo.remembered(("u",), lambda: (np.zeros(2),), lambda r: r)
        assert memo.remembered(("u",), lambda: (np.ones(2),), lambda r: r) is x
    assert not memo.active()


def test_a_scope_keeps_the_results_used_last(monkeypatch: pytest.MonkeyPatch) -> None:
    """Beyond ``MAX_ENTRIES`` the least recently used result is dropped (computed again if asked
    for), a result used again is kept."""
    monkeypatch.setattr(memo, "MAX_ENTRIES", 3)
    calls = {"n": 0}

    def value(k: int) -> tuple[np.ndarray]:
        calls["n"] += 1
        return (np.full(2, float(k)),)

    with memo.scope():
        first = [memo.remembered(("k", k), lambda k=k: value(k), lambda r: r) for k in range(3)]  # type: ignore[misc]
        assert memo.remembered(("k", 0), lambda: value(0), lambda r: r) is first[0]  # 0 used again
        memo.remembered(("k", 3), lambda: value(3), lambda r: r)  # drops 1, the least recently used
        assert calls["n"] == 4
        assert memo.remembered(("k", 0), lambda: value(0), lambda r: r) is first[0]
        assert memo.remembered(("k", 2), lambda: value(2), lambda r: r) is first[2]
        again = memo.remembered(("k", 1), lambda: value(1), lambda r: r)
        assert again is not first[1] and calls["n"] == 5
        np.testing.assert_array_equal(again[0], first[1][0])
