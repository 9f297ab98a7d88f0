"""CasADi + IPOPT adapter for the torque problem's redundancy choice (paper eq. 31).

Decision variables ``x = [dzeta~_r (r); f_c (L_c)]`` for a fixed unit object direction
``u = dzeta~_d``:

    min  phi^2 = |Lambda~_q u + Lambda~_qr dzeta~_r|^2 + eps |f_c|^2
    s.t. A_d Phi_full [u; dzeta~_r] <= 0                          (allowable, eq. 20)
         C f_c <= 0                                               (F, eq. 16)
         |slip_i|^2 >= delta^2 for every S-point                  (an S-point must slide)
         Xi^T w = 0,  N_u^T Lambda~_r^T w = 0,  u^T Lambda~_r^T w >= w_min   (W_2/W_3 rows of 30)
    with w = G_c f_c - sum_i mu_i n_i G_i slip_i/|slip_i| + w_ex  (eq. 12).

IPOPT's failures become :class:`SolverError`; a locally infeasible problem is reported as
``found = False`` with IPOPT's status.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from analysis._types import Array
from analysis.exceptions import SolverError

_INFEASIBLE = {"Infeasible_Problem_Detected", "Restoration_Failed", "Local_Infeasibility"}
_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}


@dataclass(frozen=True)
class RedundancyNLP:
    """Data of problem (31); arrays in the paper's symbols."""

    u: Array  # (a_bar,) unit object direction coordinates dzeta~_d
    N_u: Array  # (a_bar, a_bar - 1) orthonormal complement of u
    Lambda_q_t: Array  # (M, a_bar)
    Lambda_qr_t: Array  # (M, r)
    Lambda_r_t: Array  # (D, a_bar)
    B: Array  # (#D, a) = A_d Phi_full
    P_s: Array  # (d #S, a) slip of the S-points
    C: Array  # (m, L_c) friction rows
    G_c: Array  # (D, L_c)
    G_s_blocks: Array  # (#S, D, d) grasp blocks of the S-points
    s_cols: tuple[int, ...]  # column of each S-point's normal force in f_c
    mu_s: Array  # (#S,)
    Xi: Array  # (D, p)
    w_ex: Array  # (D,)
    with_forces: bool  # False: the forces do not depend on the redundancy (pure QP in dzeta~_r)
    w_min: float = 1e-6
    slip_min: float = 1e-4


@dataclass(frozen=True)
class RedundancyResult:
    found: bool
    status: str
    zeta_r: Array  # (r,)
    f_c: Array | None  # (L_c,)
    phi: float


class _Constraints:
    """``lbg <= g(x) <= ubg`` collected row block by row block."""

    def __init__(self) -> None:
        self.g: list[ca.SX] = []
        self.lbg: list[float] = []
        self.ubg: list[float] = []

    def add(self, expr: ca.SX, lb: float, ub: float) -> None:
        n = int(expr.shape[0])
        self.g.append(expr)
        self.lbg += [lb] * n
        self.ubg += [ub] * n


def _force_constraints(p: RedundancyNLP, cons: _Constraints, zc: ca.SX, f: ca.SX, d: int) -> ca.SX:
    """Allowability, friction set, sliding S-points and the passive balance (rows of (30)) for the
    motion ``zc`` and forces ``f``; returns the net wrench ``w`` (eq. 12 friction included)."""
    if p.B.shape[0]:
        cons.add(ca.DM(p.B) @ zc, -np.inf, 0.0)
    cons.add(ca.DM(p.C) @ f, -np.inf, 0.0)
    w = ca.DM(p.G_c) @ f + ca.DM(p.w_ex)
    slip_all = ca.DM(p.P_s) @ zc
    for k, col in enumerate(p.s_cols):
        s = slip_all[k * d : (k + 1) * d]
        nrm2 = ca.sumsqr(s)
        cons.add(nrm2, p.slip_min**2, np.inf)
        w = w - p.mu_s[k] * f[col] * (ca.DM(p.G_s_blocks[k]) @ (s / ca.sqrt(nrm2 + 1e-12)))
    if p.Xi.shape[1]:
        cons.add(ca.DM(p.Xi.T) @ w, 0.0, 0.0)
    return w


def _ipopt_options(max_iter: int) -> dict[str, Any]:
    return {
        "ipopt.print_level": 0,
        "print_time": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": max_iter,
        "ipopt.tol": 1e-10,
        "ipopt.constr_viol_tol": 1e-9,
        "error_on_fail": False,
    }


def solve_redundancy(
    p: RedundancyNLP, zeta0: Array | None = None, f0: Array | None = None, max_iter: int = 300
) -> RedundancyResult:
    """Solve (31) with IPOPT from ``zeta0`` (default: zero redundancy) and forces ``f0``."""
    r = p.Lambda_qr_t.shape[1]
    L_c = p.C.shape[1]
    a_bar = p.u.shape[0]
    d = p.G_s_blocks.shape[2] if p.G_s_blocks.size else 0
    nz = r
    nf = L_c if p.with_forces else 0
    x = ca.SX.sym("x", nz + nf)
    z = x[:nz]
    zc = ca.vertcat(ca.DM(p.u), z)
    dq = ca.DM(p.Lambda_q_t) @ ca.DM(p.u) + ca.DM(p.Lambda_qr_t) @ z
    obj = ca.sumsqr(dq)
    cons = _Constraints()
    if p.with_forces:
        f = x[nz:]
        obj = obj + 1e-6 * ca.sumsqr(f)
        wr = ca.DM(p.Lambda_r_t.T) @ _force_constraints(p, cons, zc, f, d)
        if a_bar > 1:
            cons.add(ca.DM(p.N_u.T) @ wr, 0.0, 0.0)
        cons.add(ca.DM(p.u).T @ wr, p.w_min, np.inf)
    elif p.B.shape[0]:
        cons.add(ca.DM(p.B) @ zc, -np.inf, 0.0)
    nlp = {"x": x, "f": obj, "g": ca.vertcat(*cons.g) if cons.g else ca.SX(0, 1)}
    opts = _ipopt_options(max_iter)
    try:
        solver = ca.nlpsol("phi_min", "ipopt", nlp, opts)
        x0 = np.zeros(nz + nf)
        if zeta0 is not None:
            x0[:nz] = zeta0
        if p.with_forces:
            x0[nz:] = f0 if f0 is not None and np.all(np.isfinite(f0)) else 1.0
        sol = solver(x0=x0, lbg=np.array(cons.lbg), ubg=np.array(cons.ubg))
    except RuntimeError as e:
        raise SolverError("IPOPT", str(e)) from e
    status = str(solver.stats().get("return_status", "unknown"))
    xs = np.asarray(sol["x"], dtype=float).ravel()
    zeta = xs[:nz]
    f_c = xs[nz:] if p.with_forces else None
    phi = float(np.linalg.norm(p.Lambda_q_t @ p.u + p.Lambda_qr_t @ zeta))
    if status in _OK:
        return RedundancyResult(True, status, zeta, f_c, phi)
    if status in _INFEASIBLE or "Infeasib" in status:
        return RedundancyResult(False, status, zeta, f_c, phi)
    if status in ("Maximum_Iterations_Exceeded", "Maximum_CpuTime_Exceeded"):
        return RedundancyResult(False, status, zeta, f_c, phi)
    raise SolverError("IPOPT", f"problem (31) ended with status '{status}'")


@dataclass(frozen=True)
class RealisableResult:
    found: bool
    status: str
    u: Array  # (a_bar,) unit direction whose net wrench is parallel to it
    zeta_r: Array  # (r,)
    f_c: Array  # (L_c,)


def solve_realisable_direction(
    p: RedundancyNLP, u0: Array, zeta0: Array, f0: Array, max_iter: int = 300
) -> RealisableResult:
    """Find a DAFC direction in which T (32) is not empty: the set S of (30) with the direction
    itself free, i.e. ``u`` (unit), ``dzeta~_r``, ``f_c`` and ``lambda >= w_min`` with

        Lambda~_r^T w = lambda u,  Xi^T w = 0,  f_c in F,  A_d Phi_full [u; dzeta~_r] <= 0,
        |slip_i| >= delta,   w = G_c f_c - sum_i mu_i n_i G_i slip_i/|slip_i| + w_ex,

    minimising ``phi^2`` as (31), started from a DAFC certificate ``(u0, zeta0, f0)``. The data
    of ``p`` other than ``u`` and ``N_u`` are used. IPOPT is a local solver: ``found = False``
    does not prove that no such direction exists.
    """
    r = p.Lambda_qr_t.shape[1]
    L_c = p.C.shape[1]
    a_bar = p.Lambda_r_t.shape[1]
    d = p.G_s_blocks.shape[2] if p.G_s_blocks.size else 0
    x = ca.SX.sym("x", a_bar + r + L_c + 1)
    u, z, f, lam = x[:a_bar], x[a_bar : a_bar + r], x[a_bar + r : a_bar + r + L_c], x[-1]
    zc = ca.vertcat(u, z)
    dq = ca.DM(p.Lambda_q_t) @ u + ca.DM(p.Lambda_qr_t) @ z
    obj = ca.sumsqr(dq) + 1e-6 * ca.sumsqr(f)
    cons = _Constraints()
    cons.add(ca.sumsqr(u), 1.0, 1.0)
    w = _force_constraints(p, cons, zc, f, d)
    cons.add(ca.DM(p.Lambda_r_t.T) @ w - lam * u, 0.0, 0.0)
    cons.add(lam, p.w_min, np.inf)
    opts = _ipopt_options(max_iter)
    try:
        solver = ca.nlpsol("realisable", "ipopt", {"x": x, "f": obj, "g": ca.vertcat(*cons.g)}, opts)
        wr0 = p.Lambda_r_t.T @ (p.G_c @ f0 + p.w_ex)
        x0 = np.concatenate([u0, zeta0, f0, [max(float(u0 @ wr0), p.w_min)]])
        sol = solver(x0=x0, lbg=np.array(cons.lbg), ubg=np.array(cons.ubg))
    except RuntimeError as e:
        raise SolverError("IPOPT", str(e)) from e
    status = str(solver.stats().get("return_status", "unknown"))
    xs = np.asarray(sol["x"], dtype=float).ravel()
    un = xs[:a_bar] / max(1e-12, float(np.linalg.norm(xs[:a_bar])))
    return RealisableResult(status in _OK, status, un, xs[a_bar : a_bar + r], xs[a_bar + r : a_bar + r + L_c])
