"""Full closure analysis of one contact-state combination (paper section IV) as one object.

``analyze_combination`` chains the steps: selection (3) -> motion space (7, 19) -> statics
(8-10) -> friction set (16) -> stationary grasp (18) -> DAFC (22) -> DPFC (28) -> torque set
(29-32) for a direction -> regrasp cone (33). Results are JSON-ready via ``to_json``.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection, selection
from analysis.dafc import (
    REFINEMENT,
    SEMANTICS,
    DAFCOracle,
    DAFCSet,
    DirectionTest,
    allowable_cone,
    dafc_nonempty,
    dafc_set,
    default_samples,
)
from analysis.dpfc import DPFC, dpfc
from analysis.exceptions import CTPError, NoStationaryGrasp
from analysis.friction import FrictionSet, friction_set, kinetic_friction
from analysis.motion import MotionSpace, motion_space
from analysis.quality import epsilon, wrench_ball
from analysis.regrasp import RegraspCone, regrasp_cone
from analysis.statics import Statics, statics
from analysis.stationary import (
    DEGENERATE_TOL,
    StationaryGrasp,
    min_total_normal,
    stationary_grasps,
    stationary_violation,
)
from analysis.torques import FrictionUncertainty, TorqueSet, friction_uncertainty, realisable_direction, torque_set

#: The full report's note where (18) has no solution: DAFC is not sampled.
NO_GRASP_DAFC = ("DAFC (22) not sampled: Theorem 1 defines it for an object held by a stationary grasp (18), "
                 "and there is none")


@dataclass(frozen=True)
class CombinationParts:
    """The matrices of one combination (shared by the summary and the full report)."""

    system: GraspSystem
    sel: Selection
    ms: MotionSpace
    st: Statics
    fs: FrictionSet

    @classmethod
    def build(cls, system: GraspSystem, combination: str) -> CombinationParts:
        sel = selection(system, combination)
        return cls(system, sel, motion_space(system, sel), statics(system, sel), friction_set(system, sel))

    def oracle(self) -> DAFCOracle:
        return DAFCOracle(self.system, self.sel, self.ms, self.st, self.fs)


@dataclass(frozen=True)
class CombinationSummary:
    """One row of the enumeration table."""

    combination: str
    feasible: bool
    reason: str
    a: int  # dim of the motion space (7)
    a_bar: int  # dim of the object-motion space (19)
    dim_dafc: int
    dim_dpfc: int  # p = rank(G_c Gamma): dimension of the span of DPFC directions
    exact: bool
    example_direction: Array | None  # (D,) a member of DAFC
    #: (M + D,) [dq; dr] of a motion realising the example direction that is a member (its forces
    #: do positive work): the certificate behind the verdict, for re-checks (not in to_json)
    example_motion: Array | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "combination": self.combination,
            "feasible": self.feasible,
            "reason": self.reason,
            "a": self.a,
            "a_bar": self.a_bar,
            "dim_dafc": self.dim_dafc,
            "dim_dpfc": self.dim_dpfc,
            "exact": self.exact,
            "example_direction": None if self.example_direction is None else _list(self.example_direction),
        }


def no_grasp_reason(violation: float | None) -> str:
    """The table's reason for an infeasible (18), degenerate when the friction rows would need to
    give by less than ``DEGENERATE_TOL F0`` (``violation`` from :func:`stationary_violation`)."""
    if violation is not None and violation <= DEGENERATE_TOL:
        return f"no stationary grasp (18); degenerate: it holds if friction and balance may give by {violation:.0e} F0"
    return "no stationary grasp (18)"


def summarize(parts: CombinationParts, stationary_known: bool | None = None,
              violation: float | None = None, oracle: DAFCOracle | None = None) -> CombinationSummary:
    """Feasibility (stationary grasp exists and DAFC is non-empty), DAFC dimension, an example.

    ``violation``: the least friction violation of (18) when it is infeasible, if known (else one
    LP, :func:`analysis.stationary.stationary_violation`), which marks degenerate verdicts.
    ``oracle``: the DAFC oracle of ``parts`` to use (a fresh one by default); the caller may read
    its ``lp_count`` afterwards."""
    return summarize_with_member(parts, stationary_known, violation, oracle)[0]


def summarize_with_member(parts: CombinationParts, stationary_known: bool | None = None,
                          violation: float | None = None, oracle: DAFCOracle | None = None,
                          realisable: bool = True) -> tuple[CombinationSummary, DirectionTest | None]:
    """:func:`summarize` and the DAFC member behind a feasible verdict (its motion and forces,
    for re-use by the enumeration: :mod:`analysis.dafc_family`). ``realisable=False``: the example
    direction is the first member found, not the first whose torque set is non-empty (the
    verdict, the dimension and the exactness do not depend on it; :func:`dafc_nonempty`)."""
    sy, sel, ms, st, fs = parts.system, parts.sel, parts.ms, parts.st, parts.fs
    c = sel.combination
    p = st.p
    if ms.a_bar == 0:
        return CombinationSummary(c, False, "object cannot move (a~ = 0)", ms.a, 0, 0, p, True, None), None
    if stationary_known is None:
        stationary_known = min_total_normal(sy, st, fs) is not None
    if not stationary_known:
        if violation is None:
            violation = stationary_violation(sy, st, fs)
        return CombinationSummary(c, False, no_grasp_reason(violation), ms.a, ms.a_bar, 0, p, True, None), None
    oracle = parts.oracle() if oracle is None else oracle
    best, dim, exact = dafc_nonempty(oracle, realisable=realisable)
    if best is None:
        reason = "DAFC is empty"
        if oracle.undecided:
            reason += f"; degenerate: {oracle.undecided} force LPs were numerically undecided"
            exact = False
        if oracle.sector_open:
            reason += f"; not proven: the slip-sector search left {oracle.sector_open} boxes open"
            exact = False
        return CombinationSummary(c, False, reason, ms.a, ms.a_bar, 0, p, exact, None), None
    motion = ms.Phi_full @ best.zeta_c if best.zeta_c is not None else None
    return CombinationSummary(c, True, "feasible", ms.a, ms.a_bar, dim, p, exact, best.direction, motion), best


@dataclass(frozen=True)
class CombinationReport:
    """Everything section IV says about one combination."""

    summary: CombinationSummary
    parts: CombinationParts
    stationary: StationaryGrasp | None
    stationary_min_grip: StationaryGrasp | None
    dafc: DAFCSet | None
    dpfc: DPFC | None
    torque: TorqueSet | None
    torque_error: str | None
    direction_test: DirectionTest | None
    uncertainty: FrictionUncertainty | None
    regrasp: RegraspCone | None
    notes: tuple[str, ...] = ()  # degeneracies and tolerances worth a user's attention

    def to_json(self) -> dict[str, Any]:
        ms, st = self.parts.ms, self.parts.st
        out: dict[str, Any] = self.summary.to_json()
        out["notes"] = list(self.notes)
        out["scales"] = {"force": self.parts.system.scales.force, "length": self.parts.system.scales.length}
        tau_max = self.parts.system.tau_max  # joint torque limits [N m]; null: unlimited
        out["joint_torque_limits"] = None if tau_max is None else [
            float(x) if np.isfinite(x) else None for x in tau_max]
        out["semantics"] = SEMANTICS
        out["motion_space"] = {
            "a": ms.a,
            "a_bar": ms.a_bar,
            "redundancy": ms.n_redundant,
            "Lambda_r_tilde": _list(ms.Lambda_r_t),
        }
        out["statics"] = {"p": st.p, "Xi": _list(st.Xi), "D": _list(st.D)}
        if self.stationary is not None:
            out["stationary"] = _grasp_json(self.stationary)
        if self.stationary_min_grip is not None:
            out["stationary_min_grip"] = _grasp_json(self.stationary_min_grip)
        if self.dafc is not None:
            out["dafc"] = {
                "exact": self.dafc.exact,
                "dim": self.dafc.dim,
                "directions": _list(self.dafc.directions),
                "member": [bool(m) for m in self.dafc.member],
                "work": [None if not np.isfinite(w) else float(w) for w in self.dafc.work],
                "refinement": REFINEMENT,  # how the boundaries between sampled directions were located
                "allowable_cone": {
                    "rays": _list(self.dafc.allowable.rays),
                    "lines": _list(self.dafc.allowable.lines),
                },
                "exact_description": None if self.dafc.description is None else {
                    "definition": "DAFC = {dr in cone(rays) + span(lines) : work_generators @ dr > 0 for some row}",
                    "work_generators": _list(self.dafc.description.work_generators),
                },
            }
        if self.dpfc is not None:
            dp = self.dpfc
            out["dpfc"] = {"dim": dp.dim, "enumerated": dp.enumerated, "vertices": _list(dp.vertices),
                           "rays": _list(dp.generators.rays), "lines": _list(dp.generators.lines)}
            if not dp.enumerated:
                assert dp.A_xi is not None and dp.b_xi is not None and dp.W_xi is not None
                out["dpfc"]["description"] = {
                    "definition": "DPFC = {W_xi @ xi : A_xi @ xi <= b_xi}; 'vertices' are its extreme wrenches "
                    "along +- each axis of its span (not every vertex)",
                    "A_xi": _list(dp.A_xi), "b_xi": _list(dp.b_xi), "W_xi": _list(dp.W_xi),
                    "unbounded_axes": dp.unbounded_axes}
        if self.dpfc is not None:  # grasp quality (analysis/quality.py), radii [N] in the (f, m / l) metric
            ball, eps = wrench_ball(self.dpfc, self.parts.system.scales), epsilon(st, self.parts.fs,
                                                                                 self.parts.system.scales)
            r_p = None if ball.radius is None or not np.isfinite(ball.radius) else ball.radius  # inf: not JSON
            out["quality"] = {"wrench_ball": r_p, "wrench_ball_reason": ball.reason,
                              "epsilon": eps.radius, "epsilon_kind": "Ferrari-Canny L1 (sum), primitive wrenches "
                              "of this combination's friction set", "metric_length": self.parts.system.scales.length}
        if self.direction_test is not None:
            t = self.direction_test
            out["direction_test"] = {"direction": _list(t.direction), "member": t.member, "reason": t.reason,
                                     "work": None if not np.isfinite(t.work) else float(t.work)}
        if self.torque is not None:
            ts = self.torque
            out["torque_set"] = {
                "direction": _list(ts.direction),
                "dq": _list(ts.dq),
                "phi": ts.phi,
                "nlp_status": ts.nlp_status,
                "vertices": None if ts.generators is None else _list(ts.generators.vertices),
                "rays": None if ts.generators is None else _list(ts.generators.rays),
                "lines": None if ts.generators is None else _list(ts.generators.lines),
                "enumerated": ts.generators is not None,
                "force_polyhedron": {"dim": ts.dim_P, "A_ub": _list(ts.A_ub), "b_ub": _list(ts.b_ub),
                                     "A_eq": _list(ts.A_eq), "b_eq": _list(ts.b_eq), "tau_map": _list(ts.T_map)},
                "recommended": _list(ts.tau),
                "contact_forces": _list(ts.f_c),
                "work": ts.work,
                "residuals": ts.residuals(ts.f_c),
            }
        if self.torque_error is not None:
            out["torque_set_error"] = self.torque_error
        if self.uncertainty is not None:
            u = self.uncertainty
            out["friction_uncertainty"] = {"nu": u.nu, "lambda": _list(u.lambdas), "feasible": u.feasible,
                                           "tau": None if u.tau is None else _list(u.tau), "reason": u.reason}
        if self.regrasp is not None:
            out["regrasp"] = {"J_d": _list(self.regrasp.J_d), "rays": _list(self.regrasp.rays),
                              "lines": _list(self.regrasp.lines), "exact": self.regrasp.exact,
                              "equilibrium": [bool(b) for b in self.regrasp.feasible]}
        return out


def _grasp_json(g: StationaryGrasp) -> dict[str, Any]:
    return {"kind": g.kind, "tau": _list(g.tau), "contact_forces": _list(g.f_c), "margin": g.margin,
            "total_normal": g.total_normal}


def _list(a: Array) -> Any:
    return np.round(np.asarray(a, dtype=float), 12).tolist()


def _realisable_candidates(
    parts: CombinationParts, oracle: DAFCOracle, target: Array, dset: DAFCSet | None, limit: int = 5
) -> Iterator[Array]:
    """Directions to try for the default torque set when the example direction has none, as they
    are asked for (at most ``limit``).

    A DAFC direction only guarantees positive work; T also needs the net wrench in the motion
    space parallel to the motion (W_3 of eq. 30). The net wrench of the oracle's certificate
    forces is such a direction for the same forces (exactly so without S-points), so it is tried
    first; then a direction from the NLP that makes the net wrench parallel to the motion
    (:func:`analysis.torques.realisable_direction`); then sampled DAFC members, bounded work first.

    The oracle's test of ``target`` runs when this generator is created (before the torque set of
    ``target``, whose own test it leaves warm, as when the list was built at once); the NLP and
    the sampled members only when the directions before them had no torque set (the NLP touches
    neither the oracle nor the torque sets tried before it, so the directions tried are the same).
    """
    t = oracle.test(target)

    def gen() -> Iterator[Array]:
        n = 0
        with_forces = t.member and t.forces is not None and t.zeta_c is not None
        if with_forces:
            assert t.forces is not None and t.zeta_c is not None
            W = parts.st.G_c
            if parts.sel.s_index:
                W = W + kinetic_friction(parts.system, parts.sel, oracle.slips_of(t.zeta_c)).G_w
            w = W @ t.forces + parts.system.w_ex
            k = parts.ms.Lambda_r_t @ (parts.ms.Lambda_r_t.T @ w)
            if np.linalg.norm(k) > 1e-9 and n < limit:
                n += 1
                yield k / np.linalg.norm(k)
        if with_forces and parts.sel.s_index and n < limit:
            try:
                v = realisable_direction(parts.system, parts.sel, parts.ms, parts.st, parts.fs, t)
            except CTPError:
                v = None
            if v is not None:
                n += 1
                yield v
        if dset is not None:
            # bounded work first (largest first): an unbounded supremum often means the net wrench
            # can grow without being parallel to the motion, which T (W_3) excludes
            finite = [j for j in np.argsort(-np.nan_to_num(dset.work, posinf=-1.0)) if dset.member[j]
                      and np.isfinite(dset.work[j])]
            unbounded = [j for j in range(len(dset.member)) if dset.member[j] and not np.isfinite(dset.work[j])]
            stride = max(1, len(unbounded) // max(1, limit - n - len(finite)))
            for j in finite + unbounded[::stride]:
                if n >= limit:
                    return
                n += 1
                yield dset.directions[j]

    return gen()


def analyze_combination(
    system: GraspSystem,
    combination: str,
    direction: Array | None = None,
    nu: float | None = None,
    samples: int | None = None,
) -> CombinationReport:
    """Full report of one combination; ``direction`` picks the motion for the torque set
    (default: the example DAFC direction); ``nu`` adds the friction-uncertainty combination."""
    parts = CombinationParts.build(system, combination)
    sy, sel, ms, st, fs = parts.system, parts.sel, parts.ms, parts.st, parts.fs
    try:
        pair = stationary_grasps(sy, sel, st, fs)
        grasp: StationaryGrasp | None = pair[0]
        grasp_min: StationaryGrasp | None = pair[1]
    except NoStationaryGrasp as e:
        grasp = grasp_min = None
        failure = str(e)
    else:
        failure = ""
    # only the torque limits stand in the way: the error names the joints and torques needed
    stationary_note = failure.split(": ", 1)[-1] if "within the joint torque limits" in failure else None
    oracle = parts.oracle()  # one oracle (its LP models built once) for the summary, the set and the torques
    summary = summarize(parts, stationary_known=grasp is not None, oracle=oracle)
    if samples is None:  # the circle/sphere densely, higher-dimensional motion spaces coarsely
        samples = default_samples(ms.a_bar)
    # DAFC (22) is where joint torques added to a stationary grasp tau_st (18) do work on the object:
    # Theorem 1 presupposes that grasp. Without one the LP of (22) still has "members" (the weight
    # alone does work along the directions the object would fall in), which are no DAFC: not sampled
    dset = dafc_set(oracle, samples=samples) if ms.a_bar and grasp is not None else None
    notes: list[str] = [stationary_note] if stationary_note else []
    if ms.a_bar and grasp is None:
        notes.append(NO_GRASP_DAFC)
    if dset is not None and dset.description_error:
        notes.append(dset.description_error)
    if grasp is None and ms.a_bar and "degenerate" in summary.reason:
        notes.append("degenerate: the contacts would hold the object if the friction rows and the balance could "
                     f"give by that fraction of the force scale ({sy.scales.force:.4g} N); a perturbation of the "
                     "contact data of that size may change this verdict")
    dtest: DirectionTest | None = oracle.test(np.asarray(direction, dtype=float)) if direction is not None else None
    if grasp is not None and not summary.feasible and summary.reason.startswith("DAFC is empty"):
        # any tested member decides: DAFC is not empty (the sampled set or the user's direction)
        found = [t for t in (dset.tests if dset is not None else ()) if t.member]
        if dtest is not None and dtest.member:
            found.append(dtest)
        if found:  # DAFC then has the dimension of A_r (dafc_nonempty)
            cone = allowable_cone(ms).all_directions()
            zc = found[0].zeta_c
            summary = CombinationSummary(summary.combination, True, "feasible", ms.a, ms.a_bar,
                                         int(np.linalg.matrix_rank(cone, tol=1e-9)), st.p, False,
                                         found[0].direction, None if zc is None else ms.Phi_full @ zc)
            notes.append("DAFC found non-empty by a direction the table's search did not test")
    dp = dpfc(st, fs, grasp) if grasp is not None else None
    rg = regrasp_cone(sy, sel, ms, st, fs) if grasp is not None else None
    torque: TorqueSet | None = None
    err: str | None = None
    unc: FrictionUncertainty | None = None
    target = None
    if direction is not None:
        target = np.asarray(direction, dtype=float)
    elif summary.example_direction is not None:
        target = summary.example_direction
    if grasp is not None and target is not None:
        others = _realisable_candidates(parts, oracle, target, dset) if direction is None else iter(())
        tried = 0
        for cand in itertools.chain([target], others):
            tried += 1
            try:
                torque = torque_set(sy, sel, ms, st, fs, grasp, cand, oracle=oracle)
                err = None
                break
            except CTPError as e:
                err = err or f"direction {np.round(cand, 4).tolist()}: {e}"
        if torque is None and tried > 1:
            err = f"{err} (and {tried - 1} other DAFC directions tried)"
    elif target is not None:
        err = "no stationary grasp (18): the torque set is not defined"
    if torque is not None and nu is not None:
        unc = friction_uncertainty(sy, sel, st, fs, torque, nu)
    return CombinationReport(summary, parts, grasp, grasp_min, dset, dp, torque, err, dtest, unc, rg, tuple(notes))
