"""Joint torque limits of a hand (analysis.torque_limits): scene limits win, else URDF efforts."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.optimize import linprog

from analysis.combination import analyze_combination
from analysis.contacts import GraspSystem, Selection, build_system, selection
from analysis.enumerate import enumerate_combinations
from analysis.exceptions import NoStationaryGrasp
from analysis.friction import FrictionSet, friction_set
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene, scene_from_dict
from analysis.statics import Statics, statics
from analysis.stationary import stationary_grasps
from analysis.torque_limits import hand_torque_limits, urdf_effort_limits

Array = NDArray[np.float64]

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_planar_scene_without_limits_has_none() -> None:
    assert hand_torque_limits(load_scene(EXAMPLES / "planar_disk_envelope.json")) is None


def test_scene_limits_are_exact() -> None:
    data = load_scene(EXAMPLES / "planar_disk_envelope.json").model_dump(mode="json", exclude_none=True)
    data["joint_torque_limits"] = [0.1, 2.5, 1e-3, 7.0]
    lim = hand_torque_limits(scene_from_dict(data))
    assert lim is not None and lim.tolist() == [0.1, 2.5, 1e-3, 7.0]  # exact, no unit change


def test_panda_urdf_effort_limits() -> None:
    pytest.importorskip("pinocchio")
    from analysis.urdf import UrdfFinger, resolve_urdf_path

    path = resolve_urdf_path("example-robot-data:panda_description/urdf/panda.urdf")
    arm = UrdfFinger("arm", path, "panda_link0", "panda_link7", np.zeros(7))
    eff = urdf_effort_limits(arm)
    assert eff is not None
    # Franka's datasheet and the URDF: 87 N m on joints 1-4, 12 N m on joints 5-7
    np.testing.assert_allclose(eff, [87, 87, 87, 87, 12, 12, 12], rtol=0, atol=1e-12)
    hand = HandKinematics(3, [arm], [])
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")  # no joint_torque_limits: URDF efforts used
    lim = hand_torque_limits(scene, hand)
    assert lim is not None
    np.testing.assert_array_equal(lim, eff)


# --------------------------------------------------------------------------------------------
# The limits bound the stationary grasp (18) and the torque set (32)

PLANAR = EXAMPLES / "planar_disk_envelope.json"


def _planar(limits: list[float] | None) -> GraspSystem:
    data = load_scene(PLANAR).model_dump(mode="json", exclude_none=True)
    if limits is not None:
        data["joint_torque_limits"] = limits
    return build_system(scene_from_dict(data))


def _parts(system: GraspSystem, combination: str) -> tuple[Selection, Statics, FrictionSet]:
    sel = selection(system, combination)
    return sel, statics(system, sel), friction_set(system, sel)


def _independent_stationary(system: GraspSystem, combination: str, tau_max: Array) -> bool:
    """Eq. (18) with ``|J_c^T f_c| <= tau_max`` posed directly with scipy's HiGHS: F-points in
    the exact 2-D cone (two edge rays), S-points along the normal, D-points unloaded."""
    cols, taus = [], []
    for i, s in enumerate(combination):
        n, t = system.normals[i], system.tangents[i][0]
        gens = [n + system.mu[i] * t, n - system.mu[i] * t] if s == "F" else [n] if s in "SN" else []
        for g in gens:
            cols.append(system.G_blocks[i] @ g)
            taus.append(system.J_blocks[i].T @ g)
    A_eq, T = np.array(cols).T, np.array(taus).T  # (3, k), (M, k)
    res = linprog(np.ones(len(cols)), A_ub=np.vstack([T, -T]), b_ub=np.r_[tau_max, tau_max], A_eq=A_eq,
                  b_eq=-system.w_ex, bounds=[(0, None)] * len(cols), method="highs")
    return bool(res.status == 0)


def test_no_limits_in_the_scene_poses_the_old_lps() -> None:
    system = _planar(None)
    assert system.tau_max is None
    assert system.joint_labels == ("left/j0", "left/j1", "right/j0", "right/j1")


def test_a_limit_below_the_grasps_need_makes_18_infeasible_and_names_the_joints() -> None:
    """FSFDD needs |tau_st| = 0.963 N m at both base joints (its minimum grip). Limits of 0.5 N m
    there make (18) infeasible; the error names both joints and the torque they need, and limits
    just above / below that torque make it feasible / infeasible, as an independent LP says."""
    combination = "FSFDD"
    free = _planar(None)
    assert np.max(np.abs(stationary_grasps(free, *_parts(free, combination))[1].tau)) > 0.9
    limited = _planar([0.5, 10.0, 0.5, 10.0])
    with pytest.raises(NoStationaryGrasp, match="within the joint torque limits") as err:
        stationary_grasps(limited, *_parts(limited, combination))
    text = str(err.value)
    assert "left/j0" in text and "right/j0" in text and "left/j1" not in text
    needed = [float(x) for x in re.findall(r" (?:at least )?([0-9.]+) N m \(limit", text)]
    assert len(needed) == 2 and needed[0] == pytest.approx(needed[1], rel=1e-6)
    for factor, feasible in ((1 + 1e-4, True), (1 - 1e-4, False)):
        lim = [needed[0] * factor, 10.0, needed[0] * factor, 10.0]
        system = _planar(lim)
        assert _independent_stationary(system, combination, np.array(lim)) is feasible
        if feasible:
            interior, min_grip = stationary_grasps(system, *_parts(system, combination))
            for g in (interior, min_grip):
                assert np.all(np.abs(g.tau) <= np.array(lim) * (1 + 1e-6)), g.tau
                assert g.equilibrium_residual(_parts(system, combination)[1], system.w_ex) < 1e-9
        else:
            with pytest.raises(NoStationaryGrasp):
                stationary_grasps(system, *_parts(system, combination))


def test_limits_change_the_table_verdict() -> None:
    """The table agrees: FSFDD feasible without limits, not with 0.5 N m at the base joints."""
    free = {s.combination: s for s in enumerate_combinations(_planar(None), ["FSFDD", "FSFSS"])[0]}
    tight = {s.combination: s for s in enumerate_combinations(_planar([0.5, 10.0, 0.5, 10.0]), ["FSFDD", "FSFSS"])[0]}
    assert free["FSFDD"].feasible and not tight["FSFDD"].feasible
    assert tight["FSFDD"].reason == "no stationary grasp (18)"


def test_limits_bound_the_recommended_torque_and_every_vertex_of_T() -> None:
    """FSFSS recommends |tau| up to 4.6 N m without limits; with 2.5 N m on every joint the
    recommended member and every vertex of T lie within the limits, and the member still does
    positive work and satisfies (32)."""
    combination, lim = "FSFSS", np.full(4, 2.5)
    free = analyze_combination(_planar(None), combination)
    assert free.torque is not None and np.max(np.abs(free.torque.tau)) > 2.5
    rep = analyze_combination(_planar(lim.tolist()), combination)
    ts = rep.torque
    assert ts is not None, rep.torque_error
    assert np.all(np.abs(ts.tau) <= lim * (1 + 1e-6))
    res = ts.residuals(ts.f_c)
    assert res["inequality"] <= 1e-7 and res["equality"] <= 1e-7 and res["work"] > 0
    assert ts.vertices is not None and len(ts.vertices)
    assert np.all(np.abs(ts.vertices) <= lim * (1 + 1e-6))
    assert rep.stationary is not None and np.all(np.abs(rep.stationary.tau) <= lim * (1 + 1e-6))


def test_a_motion_beyond_the_limits_is_refused_naming_the_joint_and_the_torque() -> None:
    """FSFSS's motion needs some torque at the base joints; below it, T is empty and the error
    names the joints; the named torque is what the motion needs (limits 1 % above it: T exists)."""
    combination = "FSFSS"
    tight = [0.3, 10.0, 0.3, 10.0]
    rep = analyze_combination(_planar(tight), combination)
    assert rep.torque is None and rep.torque_error is not None
    assert "within the joint torque limits" in rep.torque_error, rep.torque_error
    needed = {m[0]: float(m[1]) for m in re.findall(r"(\S+) (?:at least )?([0-9.]+) N m \(limit", rep.torque_error)}
    assert needed and set(needed) <= {"left/j0", "right/j0"}
    relaxed = [needed.get("left/j0", 0.3) * 1.01, 10.0, needed.get("right/j0", 0.3) * 1.01, 10.0]
    relaxed = [max(a, b) for a, b in zip(relaxed, tight, strict=True)]
    ok = analyze_combination(_planar(relaxed), combination, direction=rep.dafc.directions[0]
                             if rep.dafc is not None and len(rep.dafc.directions) else None)
    assert ok.torque is not None, ok.torque_error
