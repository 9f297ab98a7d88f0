"""Inverse kinematics of a fingertip at a new contact (the regrasp D -> F of eq. 33).

The tip (end of the last link's axis) is put at a point of the object surface with the last link
pointing into the object (``link direction . normal >= min_alignment``):

* scene serial chains: CasADi/IPOPT, ``min |q - seed|^2`` subject to those constraints (one
  parametric problem per chain, built once);
* any other :class:`~analysis.kinematics.FingerModel` (URDF fingers evaluated by pinocchio):
  :func:`numeric_ik`, damped least squares on the point Jacobians within the joint limits
  (:func:`joint_limits`).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np

from analysis._types import Array
from analysis.kinematics import HandKinematics, SerialChain


def _chain_tip_symbolic(chain: SerialChain, q: Any) -> tuple[Any, Any]:
    """World tip position and the direction of the last link, as CasADi expressions."""
    R: Any = ca.DM(chain.base_R)
    p: Any = ca.DM(chain.base_p)
    for j in range(chain.n_joints):
        p = p + R @ ca.DM(chain.origins[j])
        a = chain.axes[j]
        K = ca.DM([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        R = R @ (ca.DM.eye(3) + ca.sin(q[j]) * K + (1 - ca.cos(q[j])) * (K @ K))
    tip = p + R @ ca.DM(chain.tip)
    return tip, R @ ca.DM(chain.tip / max(float(np.linalg.norm(chain.tip)), 1e-12))


#: IPOPT problems by the chain's geometry and the dimension (:func:`_ik_key`), least recently used
#: first; bounded, so a long-running service that plans on many scenes does not keep them all
_IK_SOLVERS: OrderedDict[tuple[bytes, ...], Any] = OrderedDict()
_IK_SOLVERS_MAX = 64
#: IPOPT iterations of one IK solve (:func:`_ik_solver`)
IK_MAX_ITER = 60


def _ik_solver(chain: SerialChain, dim: int) -> Any:
    """The CasADi/IPOPT problem of :func:`fingertip_ik` for one chain (built once, parametric in the
    seed, the target and the normal)."""
    key = _ik_key(chain, dim)
    got = _IK_SOLVERS.get(key)
    if got is not None:
        _IK_SOLVERS.move_to_end(key)
        return got
    n = chain.n_joints
    q = ca.SX.sym("q", n)
    tip, axis = _chain_tip_symbolic(chain, q)
    q0 = ca.SX.sym("q0", n)
    target = ca.SX.sym("target", dim)
    normal = ca.SX.sym("normal", dim)
    g = ca.vertcat(tip[:dim] - target, ca.dot(axis[:dim], normal))
    nlp = {"x": q, "p": ca.vertcat(q0, target, normal), "f": ca.sumsqr(q - q0), "g": g}
    # every solve that succeeds takes <= 20 iterations on the bundled scenes (297 solves of the palm
    # scene's plan); 60 ends the unreachable targets' solves 3x sooner than 200 did (issue 11)
    opts: dict[str, Any] = {"ipopt.print_level": 0, "print_time": False, "ipopt.max_iter": IK_MAX_ITER,
                            "ipopt.tol": 1e-10, "ipopt.sb": "yes"}
    solver = ca.nlpsol("ik", "ipopt", nlp, opts)
    _IK_SOLVERS[key] = solver
    while len(_IK_SOLVERS) > _IK_SOLVERS_MAX:
        _IK_SOLVERS.popitem(last=False)
    return solver


def _ik_key(chain: SerialChain, dim: int) -> tuple[bytes, ...]:
    """What the IK problem of ``chain`` depends on: its base pose, joint axes and origins, tip and the
    dimension, exactly (the bytes of the float64 arrays). Each plan builds its chains anew, so a key
    by the object's identity rebuilt the problem for every plan (about 5 ms a finger) and kept every
    chain alive."""
    arrays = (chain.base_R, chain.base_p, chain.axes, chain.origins, chain.tip)
    return (str(dim).encode(), *(np.ascontiguousarray(a, dtype=float).tobytes() for a in arrays))


def alignment_bound(chain: SerialChain, target: Array) -> Array | None:
    """For a chain whose links after the first joint move in one plane (a yaw joint, then joints
    with parallel axes ``a`` perpendicular to it: a finger that turns about its base and bends),
    the unit normal ``(3,)`` of the plane the chain must lie in to put its tip at ``target``; the
    last link then points along a direction of that plane. ``None`` for any other chain, or when
    ``target`` lies on the yaw axis (every plane through the axis holds it).

    The plane: every joint after the first turns about ``a_1 = R_0 a`` (rotations about ``a`` keep
    it), which is perpendicular to the yaw axis ``z``; the second joint sits on the yaw axis
    (``origin_1`` along it) and the later origins and the tip are perpendicular to ``a``, so the
    links, the tip and the last link's direction lie in the plane through the second joint normal
    to ``a_1``. That plane holds ``target`` and the yaw axis: ``a_1 = +-(z x (target - p_1))``."""
    n = chain.n_joints
    if n < 2:
        return None
    ax = chain.axes / np.linalg.norm(chain.axes, axis=1)[:, None]  # (n, 3), joint frames
    a = ax[1]
    if not all(abs(abs(float(ax[k] @ a)) - 1.0) < 1e-12 for k in range(2, n)):
        return None  # the later joints are not parallel to the second
    if abs(float(ax[0] @ a)) > 1e-12 or np.linalg.norm(np.cross(chain.origins[1], ax[0])) > 1e-12:
        return None  # the second joint is not perpendicular to the yaw axis, or not on it
    if any(abs(float(v @ a)) > 1e-12 for v in (*chain.origins[2:], chain.tip)):
        return None  # a later link leaves the plane
    z = chain.base_R @ ax[0]  # (3,) world yaw axis
    p1 = chain.base_p + chain.base_R @ (chain.origins[0] + chain.origins[1])  # (3,) on the yaw axis
    c = np.cross(z, np.asarray(target, dtype=float)[:3] - p1)
    nc = float(np.linalg.norm(c))
    if nc < 1e-9:
        return None
    return np.asarray(c / nc)


#: a planar IK target (:func:`planar_reach_gap`) out of reach by more than this (scene units) is
#: not solved, and the alignment asked for is relaxed by :data:`PLANAR_ALIGNMENT_SLACK` for the
#: test: a solve IPOPT calls a success violates each constraint by at most its
#: ``acceptable_constr_viol_tol`` (1e-2, absolute; ``constr_viol_tol`` is 1e-4), so its tip lies
#: within sqrt(2) 1e-2 of the target and its alignment at most 1e-2 below the one asked for: no
#: solve that could succeed is skipped
PLANAR_REACH_MARGIN = 2e-2
PLANAR_ALIGNMENT_SLACK = 1e-2


def planar_reach_gap(chain: SerialChain, target: Array, normal: Array, min_alignment: float) -> float | None:
    """For a planar chain (joint axes along the world z, links in the xy-plane, no joint limits),
    how far (scene units) the tip's ``target`` ``(2,)`` lies out of reach for every direction ``u``
    of the last link with ``u . normal >= min_alignment``; 0 where some direction reaches it,
    ``inf`` where no direction is aligned. ``None`` for any other chain.

    The last joint ``w = target - L_n u`` must lie in the annulus the first ``n - 1`` links reach
    about the first joint ``p_0``: radii ``[max(0, 2 max L_k - sum L_k), sum L_k]`` (``[0, 0]`` for
    one link), the last link turning freely about it. Over the arc of aligned directions,
    ``|c - L_n u|`` (``c = target - p_0``) runs continuously between its values where ``c . u`` is
    largest and smallest on the arc (at ``u`` along ``+-c`` when the arc holds it, else at an end
    of the arc); the gap is the distance of that interval from the annulus."""
    Rb = chain.base_R
    if abs(abs(float(Rb[2, 2])) - 1.0) > 1e-12 or np.any(np.abs(chain.axes[:, :2]) > 1e-12):
        return None  # the base turns the plane, or a joint does not turn about z
    if np.any(np.abs(chain.origins[1:, 2]) > 1e-12) or abs(float(chain.tip[2])) > 1e-12:
        return None  # a link leaves the plane
    if np.any(np.abs(chain.axes[:, 2]) < 1e-12) or getattr(chain, "lower", None) is not None:
        return None
    lengths = [float(np.linalg.norm(o[:2])) for o in chain.origins[1:]]  # (n - 1,) joint to joint
    L_n = float(np.linalg.norm(chain.tip[:2]))
    r_hi = float(sum(lengths))
    r_lo = max(0.0, 2.0 * max(lengths, default=0.0) - r_hi)
    p0 = (chain.base_p + Rb @ chain.origins[0])[:2]
    c = np.asarray(target, dtype=float)[:2] - p0  # (2,)
    nrm = np.asarray(normal, dtype=float)[:2]
    n_len = float(np.linalg.norm(nrm))
    if n_len == 0.0:
        return 0.0 if min_alignment <= 0.0 else float("inf")
    cos_half = min_alignment / n_len
    if cos_half > 1.0:
        return float("inf")
    half = float(np.arccos(max(cos_half, -1.0)))  # the arc: angles within `half` of the normal's
    phi_n = float(np.arctan2(nrm[1], nrm[0]))
    c_len = float(np.linalg.norm(c))
    phi_c = float(np.arctan2(c[1], c[0]))

    def within(phi: float) -> bool:
        return abs((phi - phi_n + np.pi) % (2 * np.pi) - np.pi) <= half

    ends = [c_len * float(np.cos(phi_n + s * half - phi_c)) for s in (-1.0, 1.0)]  # c . u at the arc's ends
    dot_hi = c_len if within(phi_c) else max(ends)
    dot_lo = -c_len if within(phi_c + np.pi) else min(ends)
    g_lo = float(np.sqrt(max(c_len**2 + L_n**2 - 2.0 * L_n * dot_hi, 0.0)))
    g_hi = float(np.sqrt(max(c_len**2 + L_n**2 - 2.0 * L_n * dot_lo, 0.0)))
    return max(r_lo - g_hi, g_lo - r_hi, 0.0)


#: IK target alignment that no solution can reach by this much is not solved (IPOPT's constraint
#: tolerance is 1e-4 at most, so no solve that could succeed is skipped)
ALIGNMENT_MARGIN = 1e-3


def joint_limits(hand: HandKinematics, finger: int) -> tuple[Array, Array]:
    """Lower and upper joint limits ``(n,)`` of a finger (a URDF finger's ``lower``/``upper``;
    unbounded for scene serial chains)."""
    chain = hand.fingers[finger]
    n = chain.n_joints
    lo = getattr(chain, "lower", None)
    hi = getattr(chain, "upper", None)
    lo_a = np.full(n, -np.inf) if lo is None else np.asarray(lo, dtype=float)
    hi_a = np.full(n, np.inf) if hi is None else np.asarray(hi, dtype=float)
    return lo_a, hi_a


def numeric_ik(
    hand: HandKinematics,
    finger: int,
    target: Array,  # (d,)
    normal: Array,  # (d,) unit, into the object
    seed: Array,  # (n,)
    min_alignment: float = 0.5,
    iters: int = 200,
    damping: float = 1e-3,
) -> Array | None:
    """Inverse kinematics of any :class:`~analysis.kinematics.FingerModel` from its point
    Jacobians: damped least squares from ``seed`` on the tip position (the end of the last link's
    axis) at ``target``, with one more row raising the alignment ``u . normal`` of the last link
    (unit axis ``u``) while it is below ``min_alignment + 0.05``; every iterate is clipped to the
    joint limits (:func:`joint_limits`). Returns the joints ``(n,)`` or ``None`` if it does not
    converge (tip error above 1e-9 or alignment below ``min_alignment``)."""
    chain = hand.fingers[finger]
    d = hand.dim
    k = chain.n_joints - 1
    lo, hi = joint_limits(hand, finger)
    q = np.clip(np.asarray(seed, dtype=float), lo, hi)
    target = np.asarray(target, dtype=float)[:d]
    normal = np.asarray(normal, dtype=float)[:d]
    for _ in range(iters):
        a, b = chain.body_segment(k, q)
        a, b = a[:d], b[:d]
        L = float(np.linalg.norm(b - a))
        u = (b - a) / max(L, 1e-12)
        err = target - b
        align = float(u @ normal)
        if float(np.linalg.norm(err)) < 1e-9 and align >= min_alignment - 1e-9:
            return q
        Jb = chain.point_jacobian(k, np.r_[b, np.zeros(3 - d)] if d < 3 else b, q)[:d]
        rows, errs = [Jb], [err]
        if align < min_alignment + 0.05 and L > 1e-9:
            Ja = chain.point_jacobian(k, np.r_[a, np.zeros(3 - d)] if d < 3 else a, q)[:d]
            du = (np.eye(d) - np.outer(u, u)) @ (Jb - Ja) / L  # (d, n)
            rows.append((normal @ du)[None, :])
            errs.append(np.array([min_alignment + 0.1 - align]))
        J = np.vstack(rows)
        e = np.concatenate(errs)
        dq = J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(J.shape[0]), e)
        nrm = float(np.linalg.norm(dq))
        if nrm > 0.3:
            dq *= 0.3 / nrm
        q = np.clip(q + dq, lo, hi)
    a, b = chain.body_segment(k, q)
    u = (b[:d] - a[:d]) / max(float(np.linalg.norm(b[:d] - a[:d])), 1e-12)
    if float(np.linalg.norm(target - b[:d])) < 1e-9 and float(u @ normal) >= min_alignment - 1e-9:
        return q
    return None


def fingertip_ik(
    hand: HandKinematics,
    finger: int,
    target: Array,  # (d,) world point on the object surface
    normal: Array,  # (d,) unit, into the object
    seeds: Sequence[Array],
    min_alignment: float = 0.5,
) -> list[Array]:
    """Joint configurations ``(n,)`` of ``finger`` whose tip is at ``target`` with the last link
    pointing into the object (``link direction . normal >= min_alignment``), closest to each seed.

    Serial chains of the scene: CasADi/IPOPT, ``min |q - seed|^2`` subject to those constraints.
    Any other finger (URDF, evaluated by pinocchio): :func:`numeric_ik` (damped least squares on
    the point Jacobians, within the joint limits)."""
    chain = hand.fingers[finger]
    d = hand.dim
    out: list[Array] = []
    if not isinstance(chain, SerialChain):
        for s in seeds:
            x = numeric_ik(hand, finger, target, normal, np.asarray(s, dtype=float), min_alignment)
            if x is not None and all(np.linalg.norm(x - o) > 1e-6 for o in out):
                out.append(x)
        return out
    if d == 3 and (plane := alignment_bound(chain, target)) is not None:
        # the last link lies in the plane of normal `plane`: its best alignment with `normal` is
        # the length of the normal's projection on that plane; below min_alignment, no solution
        nu = np.asarray(normal, dtype=float)[:3] / float(np.linalg.norm(normal))
        if float(np.linalg.norm(nu - (nu @ plane) * plane)) < min_alignment - ALIGNMENT_MARGIN:
            return out
    if d == 2:
        gap = planar_reach_gap(chain, target, normal, min_alignment - PLANAR_ALIGNMENT_SLACK)
        if gap is not None and gap > PLANAR_REACH_MARGIN:
            return out  # no configuration puts the tip there with the last link aligned
    solver = _ik_solver(chain, d)
    lbg = np.r_[np.zeros(d), min_alignment]
    ubg = np.r_[np.zeros(d), np.inf]
    for s in seeds:
        s = np.asarray(s, dtype=float)
        sol = solver(x0=s, p=np.r_[s, target[:d], normal[:d]], lbg=lbg, ubg=ubg)
        if not solver.stats()["success"]:
            continue
        qs = np.asarray(sol["x"]).ravel()
        qs = s + ((qs - s + np.pi) % (2 * np.pi) - np.pi)  # nearest equivalent to the seed
        if all(np.linalg.norm(qs - o) > 1e-6 for o in out):
            out.append(qs)
    return out

