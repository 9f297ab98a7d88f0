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

Each IPOPT solver is built once per problem and kept (:data:`SOLVERS_KEPT` of them per thread,
least recently used dropped): the data of a combination (``Lambda~``, ``B``, ``C``, ``G``, ...) are
constants of the CasADi expressions, exactly as in a solver built for one call, and only the
direction ``u`` of (31) and its complement ``N_u`` enter as the parameter vector ``p`` (their
zero entries stay structural zeros, so the derivatives IPOPT sees have the same sparsity as a
solver built with them as constants). A report that solves (31) for several directions of one
combination, or twice for one direction (restarted from the DAFC certificate), builds IPOPT once;
its answers are the ones a fresh solver gives.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from analysis._types import Array
from analysis.exceptions import SolverError

_INFEASIBLE = {"Infeasible_Problem_Detected", "Restoration_Failed", "Local_Infeasibility"}
_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}

#: Built IPOPT solvers kept per thread (least recently used dropped).
SOLVERS_KEPT = 32
#: The unit slip is ``s / sqrt(|s|^2 + SLIP_SMOOTH)`` (smooth at ``s = 0``): with ``|s| >= slip_min``
#: its length is at least ``1 / sqrt(1 + SLIP_SMOOTH / slip_min^2)`` (``1 - 5e-5`` for ``1e-4``).
SLIP_SMOOTH = 1e-12
#: IPOPT's tolerance on the constraints' violation (unscaled) at ``Solve_Succeeded``.
CONSTR_VIOL_TOL = 1e-9


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
        w = w - p.mu_s[k] * f[col] * (ca.DM(p.G_s_blocks[k]) @ (s / ca.sqrt(nrm2 + SLIP_SMOOTH)))
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
        "ipopt.constr_viol_tol": CONSTR_VIOL_TOL,
        "error_on_fail": False,
    }


@dataclass(frozen=True)
class _Built:
    """One built problem: the IPOPT function and its constraint bounds ``lbg <= g <= ubg``."""

    solver: Any  # ca.Function
    lbg: Array  # (n_g,)
    ubg: Array  # (n_g,)


_local = threading.local()  # each thread its own solvers: a CasADi function is not shared across threads


def _solvers() -> OrderedDict[tuple[Any, ...], _Built]:
    """This thread's built solvers, least recently used first."""
    built: OrderedDict[tuple[Any, ...], _Built] | None = getattr(_local, "built", None)
    if built is None:
        built = _local.built = OrderedDict()
    return built


def _key(p: RedundancyNLP, kind: str, max_iter: int, with_direction: bool) -> tuple[Any, ...]:
    """What a built solver depends on: the options, every array of ``p`` but the direction (by its
    bytes) and, for (31), the zero pattern of ``u`` and ``N_u`` (their values are parameters)."""
    h = hashlib.sha256()
    for a in (p.Lambda_q_t, p.Lambda_qr_t, p.Lambda_r_t, p.B, p.P_s, p.C, p.G_c, p.G_s_blocks, p.mu_s, p.Xi, p.w_ex):
        arr = np.ascontiguousarray(a, dtype=float)
        h.update(repr(arr.shape).encode())
        h.update(arr.tobytes())
    key: tuple[Any, ...] = (kind, max_iter, p.with_forces, p.w_min, p.slip_min, p.s_cols, h.hexdigest())
    if with_direction:
        key += (p.u.shape, tuple(np.flatnonzero(p.u)), p.N_u.shape, tuple(np.flatnonzero(p.N_u)))
    return key


def _cached(key: tuple[Any, ...], build: Callable[[], _Built]) -> _Built:
    built = _solvers()
    got = built.get(key)
    if got is None:
        try:
            got = build()
        except RuntimeError as e:
            raise SolverError("IPOPT", str(e)) from e
        built[key] = got
        while len(built) > SOLVERS_KEPT:
            built.popitem(last=False)
    else:
        built.move_to_end(key)
    return got


def _masked(name: str, a: Array) -> tuple[ca.SX, ca.SX]:
    """A symbolic copy of ``a`` (vector or matrix) whose zero entries are structural zeros, and the
    parameter vector of its non-zero entries (in ``np.flatnonzero`` order)."""
    a2 = np.atleast_2d(a.reshape(a.shape[0], -1))
    nz = np.flatnonzero(a2)
    sym = ca.SX.sym(name, len(nz))
    m = ca.SX(a2.shape[0], a2.shape[1])
    for k, flat in enumerate(nz):
        i, j = divmod(int(flat), a2.shape[1])
        m[i, j] = sym[k]
    return m, sym


def _build_redundancy(p: RedundancyNLP, max_iter: int) -> _Built:
    """Problem (31) with ``u`` and ``N_u`` as parameters (see the module docstring)."""
    r = p.Lambda_qr_t.shape[1]
    L_c = p.C.shape[1]
    a_bar = p.u.shape[0]
    d = p.G_s_blocks.shape[2] if p.G_s_blocks.size else 0
    nz = r
    nf = L_c if p.with_forces else 0
    u, u_par = _masked("u", p.u)  # (a_bar, 1)
    N_u, n_par = _masked("N_u", p.N_u)  # (a_bar, a_bar - 1)
    x = ca.SX.sym("x", nz + nf)
    z = x[:nz]
    zc = ca.vertcat(u, z)
    dq = ca.DM(p.Lambda_q_t) @ u + ca.DM(p.Lambda_qr_t) @ z
    obj = ca.sumsqr(dq)
    cons = _Constraints()
    if p.with_forces:
        f = x[nz:]
        obj = obj + 1e-6 * ca.sumsqr(f)
        wr = ca.DM(p.Lambda_r_t.T) @ _force_constraints(p, cons, zc, f, d)
        if a_bar > 1:
            cons.add(N_u.T @ wr, 0.0, 0.0)
        cons.add(u.T @ wr, p.w_min, np.inf)
    elif p.B.shape[0]:
        cons.add(ca.DM(p.B) @ zc, -np.inf, 0.0)
    nlp = {"x": x, "p": ca.vertcat(u_par, n_par), "f": obj, "g": ca.vertcat(*cons.g) if cons.g else ca.SX(0, 1)}
    solver = ca.nlpsol("phi_min", "ipopt", nlp, _ipopt_options(max_iter))
    return _Built(solver, np.array(cons.lbg), np.array(cons.ubg))


def solve_redundancy(
    p: RedundancyNLP, zeta0: Array | None = None, f0: Array | None = None, max_iter: int = 300
) -> RedundancyResult:
    """Solve (31) with IPOPT from ``zeta0`` (default: zero redundancy) and forces ``f0``."""
    nz = p.Lambda_qr_t.shape[1]
    nf = p.C.shape[1] if p.with_forces else 0
    built = _cached(_key(p, "phi_min", max_iter, True), lambda: _build_redundancy(p, max_iter))
    solver = built.solver
    x0 = np.zeros(nz + nf)
    if zeta0 is not None:
        x0[:nz] = zeta0
    if p.with_forces:
        x0[nz:] = f0 if f0 is not None and np.all(np.isfinite(f0)) else 1.0
    u2, n2 = np.atleast_2d(p.u.reshape(p.u.shape[0], -1)), np.atleast_2d(p.N_u.reshape(p.N_u.shape[0], -1))
    par = np.concatenate([u2.ravel()[np.flatnonzero(u2)], n2.ravel()[np.flatnonzero(n2)]])
    try:
        sol = solver(x0=x0, p=par, lbg=built.lbg, ubg=built.ubg)
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


def _build_realisable(p: RedundancyNLP, max_iter: int) -> _Built:
    """The problem of :func:`solve_realisable_direction` (no parameters: the direction is free)."""
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
    solver = ca.nlpsol("realisable", "ipopt", {"x": x, "f": obj, "g": ca.vertcat(*cons.g)}, _ipopt_options(max_iter))
    return _Built(solver, np.array(cons.lbg), np.array(cons.ubg))


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
    built = _cached(_key(p, "realisable", max_iter, False), lambda: _build_realisable(p, max_iter))
    solver = built.solver
    wr0 = p.Lambda_r_t.T @ (p.G_c @ f0 + p.w_ex)
    x0 = np.concatenate([u0, zeta0, f0, [max(float(u0 @ wr0), p.w_min)]])
    try:
        sol = solver(x0=x0, lbg=built.lbg, ubg=built.ubg)
    except RuntimeError as e:
        raise SolverError("IPOPT", str(e)) from e
    status = str(solver.stats().get("return_status", "unknown"))
    xs = np.asarray(sol["x"], dtype=float).ravel()
    un = xs[:a_bar] / max(1e-12, float(np.linalg.norm(xs[:a_bar])))
    return RealisableResult(status in _OK, status, un, xs[a_bar : a_bar + r], xs[a_bar + r : a_bar + r + L_c])
