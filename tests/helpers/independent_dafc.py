"""DAFC (22) membership of one given motion, re-derived from the scene file with scipy: the
independent side of the DAFC checks (issue 9).

Contact Jacobians come from pinocchio for URDF fingers (:mod:`independent_urdf`) and from a
forward kinematics written here (scipy rotations) for axis/origin chains; grasp maps are
``G_i = [I; [r_i x]]``. For a motion ``[dq; dr]`` (joint velocities, object twist ``[v; w]`` at
``p_o``) the relative velocity of contact ``i`` is ``v_rel = J_i dq - G_i^T dr`` (finger minus
object point). The checks:

* F-points: ``v_rel = 0``; S/N-points: ``n^T v_rel = 0``, and an S-point slides
  (``|v_rel| > SLIP_MIN |[dq; dr]|``); D-points: ``n^T v_rel <= 0`` (no penetration);
* the object motions of the combination: ``S_r`` = the ``dr`` part of the null space of those
  equalities (scipy ``null_space``); the W_2 condition of (22) says the net wrench
  ``w = sum G_i f_i + w_ex`` lies in ``S_r``;
* one ``scipy.optimize.linprog`` maximises the work ``dr^T w`` over F-points in their inscribed
  ``k``-sided pyramids, S-points with the force ``lambda (n + mu (-v_obj_rel)/|.|)`` whose
  friction opposes the object's slip, N-points ``lambda n``, D-points nothing, the total normal
  force at most ``GRIP * |w_ex|``. ``dr`` is a member when the maximum exceeds ``WORK_MIN``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from independent_urdf import contact_torque_maps
from numpy.typing import NDArray
from scipy.linalg import null_space
from scipy.optimize import linprog
from scipy.spatial.transform import Rotation

Array = NDArray[np.float64]

GRIP = 1e3  # total normal force at most GRIP |w_ex| (the product's grip bound)
SLIP_MIN = 1e-7  # an S-point slides: |slip| above this fraction of the motion size
MOTION_TOL = 1e-9  # kinematic equalities, per unit motion
WORK_MIN = 1e-6  # member: work above WORK_MIN |w_ex| per unit object motion (moments per size)
METHOD = "highs"


def _skew(r: Array) -> Array:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def _chain_jacobian(finger: dict[str, Any], k: int, x: Array) -> Array:
    """``(3, n)`` world velocity of the world point ``x`` on body ``k`` of an axis/origin chain."""
    base = finger["base"]
    R = Rotation.from_quat(np.r_[base["quat_wxyz"][1:], base["quat_wxyz"][0]])
    p = np.asarray(base["position"], float)
    n = len(finger["joints"])
    J = np.zeros((3, n))
    for j, (joint, q) in enumerate(zip(finger["joints"], finger["q"], strict=True)):
        p = p + R.apply(np.asarray(joint["origin"], float))
        axis = np.asarray(joint["axis"], float) / np.linalg.norm(joint["axis"])
        R = R * Rotation.from_rotvec(q * axis)
        if j <= k:
            J[:, j] = np.cross(R.apply(axis), x - p)
    return J


def contact_jacobians(data: dict[str, Any]) -> list[Array]:
    """Per contact its ``(3, M)`` point Jacobian (zero for fixed bodies), joints in finger order."""
    if any("urdf" in f for f in data["fingers"]):
        maps, _ = contact_torque_maps(data)
        return [T.T for T in maps]
    sizes = [len(f["joints"]) for f in data["fingers"]]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    out = []
    for c in data["contacts"]:
        J = np.zeros((3, int(offsets[-1])))
        if "/" in c["body"]:
            name, k = c["body"].split("/", 1)
            i = next(m for m, f in enumerate(data["fingers"]) if f["name"] == name)
            J[:, offsets[i]:offsets[i + 1]] = _chain_jacobian(data["fingers"][i], int(k), np.asarray(c["point"], float))
        out.append(J)
    return out


def _frame(n: Array) -> tuple[Array, Array]:
    e = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, e)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


@dataclass(frozen=True)
class MemberCheck:
    """The independent verdict on one motion."""

    motion_errors: tuple[str, ...]  # kinematic conditions the motion violates
    work: float  # the largest work of admissible forces (N m per unit motion; -inf: infeasible)
    forces: Array | None  # (L, 3) contact forces of the maximiser
    work_min: float  # the member threshold for this motion

    @property
    def member(self) -> bool:
        return not self.motion_errors and self.work > self.work_min


def check_member(data: dict[str, Any], combination: str, dq: Array, dr: Array) -> MemberCheck:
    """Is the motion ``[dq; dr]`` of the 3-D scene ``data`` a DAFC (22) member for ``combination``?"""
    assert int(data["dim"]) == 3
    pts = np.array([c["point"] for c in data["contacts"]], float)
    nrm = np.array([c["normal"] for c in data["contacts"]], float)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    mu = np.array([c["mu"] for c in data["contacts"]], float)
    p_o = np.asarray(data["object"]["pose"]["position"], float)
    w_ex = np.asarray(data["external_wrench"], float)
    F0 = max(float(np.linalg.norm(w_ex)), 1e-12)
    ell = max(float(np.max(np.linalg.norm(pts - p_o, axis=1))), 1e-12)
    k_sides = int(data.get("friction_cone_sides", 16))
    Js = contact_jacobians(data)
    M = Js[0].shape[1]
    G = [np.vstack([np.eye(3), _skew(p - p_o)]) for p in pts]  # (6, 3) each
    dq, dr = np.asarray(dq, float), np.asarray(dr, float)
    size = float(np.linalg.norm(np.r_[dq, dr]))
    # kinematics: equality rows of the combination, on [dq; dr]
    eq_rows: list[Array] = []
    errors: list[str] = []
    for i, s in enumerate(combination):
        A_i = np.hstack([Js[i], -G[i].T])  # (3, M + 6): v_rel
        v_rel = A_i @ np.r_[dq, dr]
        if s == "F":
            eq_rows.extend(A_i)
            if np.linalg.norm(v_rel) > MOTION_TOL * size:
                errors.append(f"contact {i} (F) moves relative to the object: {np.linalg.norm(v_rel):.3g}")
        elif s in "SN":
            eq_rows.append(nrm[i] @ A_i)
            if abs(nrm[i] @ v_rel) > MOTION_TOL * size:
                errors.append(f"contact {i} ({s}) separates or penetrates: {nrm[i] @ v_rel:.3g}")
            if s == "S" and np.linalg.norm(v_rel) <= SLIP_MIN * size:
                errors.append(f"contact {i} (S) does not slide: {np.linalg.norm(v_rel):.3g}")
        elif nrm[i] @ v_rel > MOTION_TOL * size:
            errors.append(f"contact {i} (D) penetrates: {nrm[i] @ v_rel:.3g}")
    N = null_space(np.array(eq_rows)) if eq_rows else np.eye(M + 6)
    S_r = np.linalg.svd(N[M:], full_matrices=False)
    U, sv = S_r[0], S_r[1]
    basis = U[:, sv > 1e-9 * max(1.0, float(sv.max(initial=0.0)))]  # (6, a_bar) object motions
    perp = null_space(basis.T) if basis.shape[1] < 6 else np.zeros((6, 0))  # (6, 6 - a_bar)
    # forces: per variable the wrench it puts on the object (6,), and its normal force
    cols: list[Array] = []
    normal: list[float] = []
    owner: list[tuple[int, Array]] = []
    for i, s in enumerate(combination):
        n = nrm[i]
        if s == "F" and mu[i] > 0:
            t1, t2 = _frame(n)
            gens = [n + mu[i] * (np.cos(a) * t1 + np.sin(a) * t2) for a in 2 * np.pi * np.arange(k_sides) / k_sides]
        elif s == "S":
            slip = -(Js[i] @ dq - G[i].T @ dr)  # object point relative to the finger
            gens = [n - mu[i] * slip / np.linalg.norm(slip)] if np.linalg.norm(slip) > 0 else []
        elif s in "FN":
            gens = [n]
        else:
            gens = []
        for g in gens:
            cols.append(G[i] @ g)
            normal.append(1.0)
            owner.append((i, g))
    if not cols:
        w = w_ex
        ok = perp.shape[1] == 0 or bool(np.linalg.norm(perp.T @ w) <= 1e-9 * F0)
        return MemberCheck(tuple(errors), float(dr @ w) if ok else -np.inf, np.zeros((len(pts), 3)),
                           WORK_MIN * F0 * float(np.linalg.norm(np.r_[dr[:3], dr[3:] * ell])))
    W = np.array(cols).T  # (6, n)
    # W_2: the net wrench has no component off the object motions (rows in units of |w_ex|)
    A_eq = perp.T @ W / F0 if perp.shape[1] else None
    b_eq = -perp.T @ w_ex / F0 if perp.shape[1] else None
    res = linprog(-(dr @ W) / F0, A_ub=np.array(normal)[None, :], b_ub=[GRIP], A_eq=A_eq, b_eq=b_eq,
                  bounds=[(0, None)] * len(cols), method=METHOD)
    work_min = WORK_MIN * F0 * float(np.linalg.norm(np.r_[dr[:3], dr[3:] * ell]))
    if res.status != 0:
        return MemberCheck(tuple(errors), -np.inf, None, work_min)
    lam = res.x * F0
    forces = np.zeros((len(pts), 3))
    for v, (i, g) in zip(lam, owner, strict=True):
        forces[i] += v * g
    return MemberCheck(tuple(errors), float(dr @ (W @ lam + w_ex)), forces, work_min)


def planar_jacobians(data: dict[str, Any]) -> list[Array]:
    """Per contact of a 2-D scene its ``(2, M)`` point Jacobian, from the fingers' base, link
    lengths and ``q`` (forward kinematics written here): joint ``j`` at ``p_j`` moves a point
    ``x`` of a later link by ``z x (x - p_j)``; zero for fixed bodies."""
    sizes = [len(f["links"]) for f in data["fingers"]]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    out = []
    for c in data["contacts"]:
        J = np.zeros((2, int(offsets[-1])))
        if "/" in c["body"]:
            name, k = c["body"].split("/", 1)
            i = next(m for m, f in enumerate(data["fingers"]) if f["name"] == name)
            f = data["fingers"][i]
            p = np.asarray(f["base"]["position"], float)
            ang = float(f["base"].get("angle", 0.0))
            x = np.asarray(c["point"], float)
            for j, (link, q) in enumerate(zip(f["links"], f["q"], strict=True)):
                ang += q
                if j <= int(k):
                    r = x - p
                    J[:, offsets[i] + j] = [-r[1], r[0]]
                p = p + link["length"] * np.array([np.cos(ang), np.sin(ang)])
        out.append(J)
    return out


def check_member_planar(data: dict[str, Any], combination: str, dq: Array, dr: Array) -> MemberCheck:
    """:func:`check_member` for a 2-D scene (object twist ``[v_x, v_y, omega]`` at ``p_o``;
    friction cones exact: the two edges ``n +- mu t``)."""
    assert int(data["dim"]) == 2
    pts = np.array([c["point"] for c in data["contacts"]], float)
    nrm = np.array([c["normal"] for c in data["contacts"]], float)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    mu = np.array([c["mu"] for c in data["contacts"]], float)
    p_o = np.asarray(data["object"]["pose"]["position"], float)
    w_ex = np.asarray(data["external_wrench"], float)
    F0 = max(float(np.linalg.norm(w_ex)), 1e-12)
    ell = float(data["object"]["shape"].get("radius", np.max(np.linalg.norm(pts - p_o, axis=1))))
    Js = planar_jacobians(data)
    M = Js[0].shape[1]
    G = [np.array([[1.0, 0.0], [0.0, 1.0], [-(p - p_o)[1], (p - p_o)[0]]]) for p in pts]  # (3, 2)
    dq, dr = np.asarray(dq, float), np.asarray(dr, float)
    size = float(np.linalg.norm(np.r_[dq, dr]))
    eq_rows: list[Array] = []
    errors: list[str] = []
    cols: list[Array] = []
    normal: list[float] = []
    for i, s in enumerate(combination):
        A_i = np.hstack([Js[i], -G[i].T])  # (2, M + 3)
        v_rel = A_i @ np.r_[dq, dr]
        n = nrm[i]
        t = np.array([-n[1], n[0]])
        if s == "F":
            eq_rows.extend(A_i)
            if np.linalg.norm(v_rel) > MOTION_TOL * size:
                errors.append(f"contact {i} (F) moves relative to the object")
            gens = [n + mu[i] * t, n - mu[i] * t]
        elif s in "SN":
            eq_rows.append(n @ A_i)
            if abs(n @ v_rel) > MOTION_TOL * size:
                errors.append(f"contact {i} ({s}) separates or penetrates")
            slip = -v_rel
            if s == "S" and np.linalg.norm(slip) <= SLIP_MIN * size:
                errors.append(f"contact {i} (S) does not slide")
            gens = [n - mu[i] * slip / np.linalg.norm(slip)] if s == "S" and np.linalg.norm(slip) > 0 else [n]
        else:
            if n @ v_rel > MOTION_TOL * size:
                errors.append(f"contact {i} (D) penetrates")
            gens = []
        for g in gens:
            cols.append(G[i] @ g)
            normal.append(1.0)
    N = null_space(np.array(eq_rows)) if eq_rows else np.eye(M + 3)
    U, sv, _ = np.linalg.svd(N[M:], full_matrices=False)
    basis = U[:, sv > 1e-9 * max(1.0, float(sv.max(initial=0.0)))]
    perp = null_space(basis.T) if basis.shape[1] < 3 else np.zeros((3, 0))
    work_min = WORK_MIN * F0 * float(np.linalg.norm(np.r_[dr[:2], dr[2:] * ell]))
    if not cols:
        ok = perp.shape[1] == 0 or bool(np.linalg.norm(perp.T @ w_ex) <= 1e-9 * F0)
        return MemberCheck(tuple(errors), float(dr @ w_ex) if ok else -np.inf, None, work_min)
    W = np.array(cols).T  # (3, n)
    res = linprog(-(dr @ W) / F0, A_ub=np.array(normal)[None, :], b_ub=[GRIP],
                  A_eq=perp.T @ W / F0 if perp.shape[1] else None,
                  b_eq=-perp.T @ w_ex / F0 if perp.shape[1] else None,
                  bounds=[(0, None)] * len(cols), method=METHOD)
    if res.status != 0:
        return MemberCheck(tuple(errors), -np.inf, None, work_min)
    return MemberCheck(tuple(errors), float(dr @ (W @ (res.x * F0) + w_ex)), None, work_min)
