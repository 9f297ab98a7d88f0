"""Enumeration of every contact-state combination; its pruning must not change any answer."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from closure_helpers import example_system, sample_combinations

from analysis.combination import CombinationParts, CombinationSummary, summarize
from analysis.contacts import all_combinations
from analysis.enumerate import enumerate_combinations


def _same(a: CombinationSummary, b: CombinationSummary) -> None:
    assert (a.combination, a.feasible, a.reason, a.a, a.a_bar, a.dim_dafc, a.dim_dpfc, a.exact) == (
        b.combination, b.feasible, b.reason, b.a, b.a_bar, b.dim_dafc, b.dim_dpfc, b.exact)
    if a.example_direction is None or b.example_direction is None:
        assert a.example_direction is None and b.example_direction is None
    else:
        np.testing.assert_allclose(a.example_direction, b.example_direction, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", ["planar_disk_envelope", "sphere_four_finger_palm"])
def test_pruning_is_exact(name: str) -> None:
    """Every one of the 243 combinations: the pruned enumeration equals summarize() with the
    stationary grasp (18) computed directly for that combination."""
    system = example_system(name)
    pruned, stats = enumerate_combinations(system, workers=1)
    canonical = ["".join(p) for p in itertools.product(*["FSD" if m > 0 else "ND" for m in system.mu])]
    assert [s.combination for s in pruned] == canonical == all_combinations(system)
    assert len(pruned) == 3**system.L == stats.combinations
    assert stats.pruned_stationary > 0  # the pruning was exercised
    assert stats.dafc_lps > 0 and stats.stationary_lps > 0  # both kinds of LP are counted
    for s in pruned:
        _same(s, summarize(CombinationParts.build(system, s.combination)))


def test_planar_results() -> None:
    """All-F on the planar envelope grasp is passive closure: the object cannot move
    (a~ = 0), so not feasible; all-D cannot hold the disk against gravity."""
    system = example_system("planar_disk_envelope")
    result = {s.combination: s for s in enumerate_combinations(system, workers=1)[0]}
    assert not result["FFFFF"].feasible and result["FFFFF"].a_bar == 0
    assert result["FFFFF"].reason == "object cannot move (a~ = 0)"
    assert result["DDDDD"].reason == "no stationary grasp (18)"
    feasible = [c for c, s in result.items() if s.feasible]
    assert feasible
    for c in feasible:
        s = result[c]
        assert s.a_bar >= 1 and 1 <= s.dim_dafc <= s.a_bar and s.example_direction is not None
        assert np.linalg.norm(s.example_direction) == pytest.approx(1.0, abs=1e-9)
    # mirror symmetry of the scene (x -> -x swaps left and right fingers): the feasible set is
    # closed under swapping contacts 0 <-> 2 and 1 <-> 3
    mirrored = {c[2] + c[3] + c[0] + c[1] + c[4] for c in feasible}
    assert mirrored == set(feasible)


def test_subset_and_order_of_requested_combinations() -> None:
    """A requested list comes back in the requested order, whatever the evaluation order."""
    system = example_system("planar_disk_envelope")
    combos = sample_combinations(system, 20, seed=4)[::-1]
    out, stats = enumerate_combinations(system, combinations=combos, workers=1)
    assert [s.combination for s in out] == combos and stats.combinations == 20


def test_enumeration_raises_no_solver_error_on_the_allegro_scene() -> None:
    """Every combination of the Allegro scene (near-singular contact geometry) is decided; two
    of them (SFFDSF, SFSSFF) once ended in a HiGHS 'Solve error' under warm-started primal
    simplex."""
    system = example_system("allegro_right_box")
    out, _ = enumerate_combinations(system, workers=1)
    assert len(out) == 3**system.L
    assert any(s.feasible for s in out)
