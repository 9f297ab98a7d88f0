"""The contact forces a given joint torque produces (analysis/torque_forces.py, eq. 29 read
backwards with W_2 of 22), re-derived with scipy from the scene file: contact Jacobians of the
independent forward kinematics (tests/helpers/independent_dafc.py), grasp maps ``[I; [r x]]``,
the object motions the F-points allow from scipy's ``null_space``, and one ``linprog`` for the
largest friction margin (the friction pyramid's rows are the analysis' own: they define the set).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from independent_dafc import _skew, contact_jacobians
from scipy.linalg import null_space
from scipy.optimize import linprog

from analysis.combination import CombinationParts
from analysis.contacts import build_system
from analysis.loader import load_scene
from analysis.stationary import stationary_grasp
from analysis.torque_forces import TorqueForces, torque_forces

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
WRAP = EXAMPLES / "sphere_four_finger_wrap.json"
COMBINATION = "FFFFFFFFD"  # the nine-contact wrap with the palm let go
TOL = 1e-7


@pytest.fixture(scope="module")
def wrap() -> tuple[dict, CombinationParts]:  # type: ignore[type-arg]
    data = json.loads(WRAP.read_text())
    p = CombinationParts.build(build_system(load_scene(WRAP)), COMBINATION)
    return data, p


def _independent(data: dict, C: np.ndarray, tau: np.ndarray) -> tuple[float, np.ndarray]:  # type: ignore[type-arg]
    """The largest friction margin of forces ``(L_c,)`` (F-points' 3-vectors, world) with
    ``sum J_i^T f_i = tau`` (its part in their range) and the net wrench in the object motions
    the F-points allow, by scipy; and those forces."""
    pts = np.array([c["point"] for c in data["contacts"]], float)
    p_o = np.asarray(data["object"]["pose"]["position"], float)
    w_ex = np.asarray(data["external_wrench"], float)
    Js = contact_jacobians(data)
    M = Js[0].shape[1]
    F = [i for i, ch in enumerate(COMBINATION) if ch == "F"]
    G = [np.vstack([np.eye(3), _skew(pts[i] - p_o)]) for i in F]  # (6, 3) each
    JT = np.hstack([Js[i].T for i in F])  # (M, 3 k)
    Gc = np.hstack(G)  # (6, 3 k)
    # object motions of the F-points: the dr part of null([J_i, -G_i^T])
    A = np.vstack([np.hstack([Js[i], -g.T]) for i, g in zip(F, G, strict=True)])
    N = null_space(A)
    U, sv, _ = np.linalg.svd(N[M:], full_matrices=False)
    motions = U[:, sv > 1e-9]  # (6, a~)
    blocked = null_space(motions.T)  # (6, 6 - a~): W_2 says w has no component there
    R = np.linalg.svd(JT, full_matrices=False)
    rng = R[0][:, R[1] > 1e-9 * R[1][0]]  # (M, r) range of J^T
    n = JT.shape[1]
    A_eq = np.vstack([np.hstack([rng.T @ JT, np.zeros((rng.shape[1], 1))]),
                      np.hstack([blocked.T @ Gc, np.zeros((blocked.shape[1], 1))])])
    b_eq = np.concatenate([rng.T @ tau, -blocked.T @ w_ex])
    res = linprog(np.r_[np.zeros(n), -1.0], A_ub=np.hstack([C, np.ones((C.shape[0], 1))]), b_ub=np.zeros(C.shape[0]),
                  A_eq=A_eq, b_eq=b_eq, bounds=[(None, None)] * n + [(None, 1e3)], method="highs")
    assert res.status == 0, res.message
    return float(res.x[-1]), res.x[:n]


def _check_equations(data: dict, f: np.ndarray, tau: np.ndarray, r: TorqueForces) -> None:  # type: ignore[type-arg]
    """``sum J_i^T f_i + unbalanced = tau`` and the net wrench's part off the object motions is 0,
    with the independent Jacobians and grasp maps."""
    pts = np.array([c["point"] for c in data["contacts"]], float)
    p_o = np.asarray(data["object"]["pose"]["position"], float)
    Js = contact_jacobians(data)
    F = [i for i, ch in enumerate(COMBINATION) if ch == "F"]
    fs = f.reshape(len(F), 3)
    np.testing.assert_allclose(sum(Js[i].T @ fi for i, fi in zip(F, fs, strict=True)) + r.unbalanced, tau, atol=TOL)
    w = np.asarray(data["external_wrench"], float) + sum(
        np.r_[fi, np.cross(pts[i] - p_o, fi)] for i, fi in zip(F, fs, strict=True))
    M = Js[0].shape[1]
    A = np.vstack([np.hstack([Js[i], -np.vstack([np.eye(3), _skew(pts[i] - p_o)]).T]) for i in F])
    N = null_space(A)
    U, sv, _ = np.linalg.svd(N[M:], full_matrices=False)
    motions = U[:, sv > 1e-9]
    assert float(np.linalg.norm(w - motions @ (motions.T @ w))) <= TOL * (1 + float(np.linalg.norm(w)))


def test_the_stationary_torque_produces_its_own_forces(wrap) -> None:  # type: ignore[no-untyped-def]
    """The stationary grasp (18) of the wrap with the palm let go: its torque produces forces in
    the friction set, the largest margin equals scipy's, and it is at least that of the
    stationary grasp's own forces (which are one solution)."""
    data, p = wrap
    g = stationary_grasp(p.system, p.sel, p.st, p.fs, "interior")
    r = torque_forces(p.system, p.sel, p.st, p.fs, g.tau)
    assert r.realised and r.in_friction_set and r.f_c is not None
    assert float(np.max(np.abs(r.unbalanced))) <= TOL * (1 + float(np.max(np.abs(g.tau))))  # tau_st = J_c^T f_c
    _check_equations(data, r.f_c, g.tau, r)
    margin, _ = _independent(data, p.fs.C, g.tau)
    assert r.margin == pytest.approx(margin, abs=1e-6)
    assert r.margin >= -float(np.max(p.fs.C @ g.f_c)) - 1e-9
    assert r.margin == pytest.approx(-float(np.max(p.fs.C @ r.f_c)), abs=1e-9)


def test_a_tangential_push_at_a_tip_leaves_the_friction_set(wrap) -> None:  # type: ignore[no-untyped-def]
    """Adding to the stationary torque the joint torques of a large tangential force at one
    fingertip (seeded direction in its tangent plane): the forces that torque produces lie
    outside the friction set (margin < 0), by as much as scipy finds, and still satisfy the
    equations."""
    data, p = wrap
    g = stationary_grasp(p.system, p.sel, p.st, p.fs, "interior")
    rng = np.random.default_rng(11)
    Js = contact_jacobians(data)
    k = 1  # f1/2, a middle link on the sphere
    n = np.asarray(data["contacts"][k]["normal"], float)
    t = rng.standard_normal(3)
    t -= (t @ n) * n
    t *= 20.0 / np.linalg.norm(t)
    tau = g.tau + Js[k].T @ t
    r = torque_forces(p.system, p.sel, p.st, p.fs, tau)
    assert r.realised and r.f_c is not None and not r.in_friction_set
    _check_equations(data, r.f_c, tau, r)
    margin, _ = _independent(data, p.fs.C, tau)
    assert margin < 0 and r.margin == pytest.approx(margin, abs=1e-6)


def test_a_torque_no_contact_can_balance_is_reported_apart(wrap) -> None:  # type: ignore[no-untyped-def]
    """A torque on the self-motion of a finger (joint motions that move none of its contact
    points: here finger 4's last joint, behind its two contacts on links 1 and 2) is not produced
    by any contact force: it is ``unbalanced``, the rest is."""
    data, p = wrap
    g = stationary_grasp(p.system, p.sel, p.st, p.fs, "interior")
    extra = np.zeros(p.system.M)
    extra[15] = 0.3  # f4's joint 3 moves no contact of f4/1, f4/2
    r = torque_forces(p.system, p.sel, p.st, p.fs, g.tau + extra)
    np.testing.assert_allclose(r.unbalanced, extra, atol=TOL)
    assert r.realised and r.f_c is not None
    _check_equations(data, r.f_c, g.tau + extra, r)
