"""Joint torques that move the object along a DAFC direction (paper eq. 29-32) and the
friction-uncertainty combination (end of section IV-C).

1. Problem (31): among the motions ``dzeta_c = [dzeta~_d; dzeta~_r]`` realising the unit
   direction ``dzeta~_d``, pick the redundancy minimising ``phi = |dq|`` (CasADi/IPOPT,
   :mod:`analysis.solvers.casadi_nlp`), subject to the set S of (30). In the plane an S-point's
   unit slip is one of two tangents, so (31) is feasible exactly when one of ``2^#S`` LPs is
   (:func:`planar_slip_patterns`); when none is, IPOPT is not run. In 3-D a branch and bound
   over slip sectors (:func:`analysis.torque_sectors.slip_sector_screen`) proves it infeasible
   for many directions with a few LPs; then IPOPT is not run either.
2. Set (32) for that motion: with the slips fixed every condition of (30) is linear in the
   contact forces, so ``T = {tau(f_c) : f_c in P}`` with

       P = {f_c in F : Xi^T w = 0,  N_u^T Lambda~_r^T w = 0,  u^T Lambda~_r^T w >= 0},
       w = G_c f_c + w_s(f_c) + w_ex,   tau(f_c) = J_c^T f_c + J_s^T t_s(f_c),

   the total joint torque ``tau_st + tau_ad`` that balances the contact forces (kinetic friction
   included), with no extra torque in the redundancy (``tau~ = 0`` in (29),
   ``Lambda~_qr^T tau_ad = 0`` in (30)). Members with work ``> 0`` move the object; the face
   ``work = 0`` (which contains ``tau_st``) is the closure of that set. T is reported as the
   vertices and rays of the image of P (cdd), plus one recommended member.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.dafc import DAFCOracle, DirectionTest
from analysis.exceptions import EmptyTorqueSet, NotInDAFC, SolverError
from analysis.friction import FrictionSet, KineticFriction
from analysis.linalg import null_space, rank
from analysis.motion import MotionSpace
from analysis.solvers.casadi_nlp import RedundancyNLP, solve_realisable_direction, solve_redundancy
from analysis.solvers.cdd import Generators, polyhedron_generators, reduce_generators
from analysis.solvers.highs import solve_lp
from analysis.statics import Statics
from analysis.stationary import StationaryGrasp
from analysis.torque_conditions import TorqueConditions, torque_conditions
from analysis.torque_sectors import slip_sector_screen

#: Vertex enumeration of the force polyhedron behind T is attempted up to this dimension; above
#: it (e.g. several 3-D F-points with 16-sided pyramids: up to k^#F vertices) T is reported by
#: its H-representation in contact-force space and the linear map to joint torques.
MAX_ENUMERATION_DIM = 7
#: Above ``SMALL_DIM`` only with at most ``MAX_ENUMERATION_ROWS`` inequality rows (12 contacts,
#: FDDFDDFDDFDD: 7 dimensions and 4 sixteen-sided pyramids took cdd 2 s), as for DPFC.
SMALL_DIM = 4
MAX_ENUMERATION_ROWS = 64
#: ... and reported by vertices and rays only when the force polyhedron has at most this many
#: (removing the redundant ones among thousands costs one LP each: half a minute at 12 contacts).
MAX_GENERATORS = 400


@dataclass(frozen=True)
class TorqueSet:
    """T of eq. (32) for one direction and its chosen motion."""

    direction: Array  # (D,) unit object direction dr_d
    u: Array  # (a_bar,) its coordinates dzeta~_d
    zeta_c: Array  # (a,) the motion chosen by (31)
    dq: Array  # (M,) finger motion for the unit object motion
    phi: float  # |dq|
    nlp_status: str
    generators: Generators | None  # vertices and rays of T (joint space, M); None if too large
    dim_P: int  # dimension of the force polyhedron P behind T
    tau: Array  # (M,) the recommended member
    f_c: Array  # (L_c,) its contact forces
    work: float  # u^T Lambda~_r^T w of the recommended member (> 0)
    # linear description of P in f_c and the map f_c -> tau, for certificates
    A_ub: Array  # (m, L_c)
    b_ub: Array  # (m,)
    A_eq: Array  # (e, L_c)
    b_eq: Array  # (e,)
    T_map: Array  # (M, L_c)
    W_map: Array  # (D, L_c) f_c -> w - w_ex
    friction: KineticFriction | None

    @property
    def vertices(self) -> Array | None:
        return None if self.generators is None else self.generators.vertices

    @property
    def rays(self) -> Array | None:
        return None if self.generators is None else self.generators.all_directions()

    def residuals(self, f_c: Array) -> dict[str, float]:
        """Certificate of a member: inequality violation, equality residual, work."""
        return {
            "inequality": float(np.max(self.A_ub @ f_c - self.b_ub, initial=0.0)),
            "equality": float(np.max(np.abs(self.A_eq @ f_c - self.b_eq), initial=0.0)),
            "work": float(-(self.A_ub[-1] @ f_c) + self.b_ub[-1]) if self.A_ub.shape[0] else 0.0,
        }


def _nlp_data(
    system: GraspSystem, sel: Selection, ms: MotionSpace, st: Statics, fs: FrictionSet, u: Array, with_forces: bool
) -> RedundancyNLP:
    """The data of problem (31) for the unit direction ``u``."""
    a_bar = ms.a_bar
    d = system.d
    return RedundancyNLP(
        u=u,
        N_u=null_space(u[None, :]) if a_bar > 1 else np.zeros((a_bar, 0)),
        Lambda_q_t=ms.Lambda_q_t,
        Lambda_qr_t=ms.Lambda_qr_t,
        Lambda_r_t=ms.Lambda_r_t,
        B=ms.B,
        P_s=ms.P_s,
        C=fs.C,
        G_c=st.G_c,
        G_s_blocks=np.array([system.G_blocks[i] for i in sel.s_index]).reshape(len(sel.s_index), system.D, d),
        s_cols=tuple(sel.c_slices[i].start for i in sel.s_index),
        mu_s=np.array([system.mu[i] for i in sel.s_index]),
        Xi=st.Xi,
        w_ex=system.w_ex,
        with_forces=with_forces,
    )


def planar_slip_patterns(p: RedundancyNLP, T_s: Array) -> list[Array]:
    """The slip-sign patterns ``sigma`` ``(#S,)`` for which problem (31) is feasible, in the plane.

    In 2-D an S-point's slip is tangential, ``P_k dzeta_c = s_k t_k`` (``t_k`` the row ``k`` of
    ``T_s`` ``(#S, 2)``), so its unit slip is ``sigma_k t_k`` and ``|slip_k| >= delta`` is
    ``sigma_k t_k^T P_k [u; dzeta~_r] >= delta``. For a fixed ``sigma`` the friction columns of
    ``w`` (eq. 12) are constants and every constraint of (31) is linear in ``(dzeta~_r, f_c)``:

        B [u; z] <= 0,   sigma_k t_k^T P_k [u; z] >= delta,   C f_c <= 0,
        Xi^T w = 0,   N_u^T Lambda~_r^T w = 0,   u^T Lambda~_r^T w >= w_min,
        w = (G_c - sum_k mu_k sigma_k G_k t_k e_k^T) f_c + w_ex

    (``e_k`` picks the S-point's normal force). Problem (31) is feasible exactly when one of these
    ``2^#S`` LPs is. SolverError when HiGHS decides none of them either way."""
    a_bar, r, L_c = p.u.shape[0], p.Lambda_qr_t.shape[1], p.C.shape[1]
    n_s = len(p.s_cols)
    LrT = p.Lambda_r_t.T  # (a_bar, D)
    rows_ub: list[Array] = [np.hstack([np.zeros((p.C.shape[0], r)), p.C])]  # C f_c <= 0
    rhs_ub: list[Array] = [np.zeros(p.C.shape[0])]
    if p.B.shape[0]:  # allowable: B_r z <= -B_u u
        rows_ub.append(np.hstack([p.B[:, a_bar:], np.zeros((p.B.shape[0], L_c))]))
        rhs_ub.append(-p.B[:, :a_bar] @ p.u)
    slip_rows = np.array([T_s[k] @ p.P_s[2 * k : 2 * k + 2] for k in range(n_s)]).reshape(n_s, -1)  # (#S, a)
    out: list[Array] = []
    for signs in itertools.product((1.0, -1.0), repeat=n_s):
        sigma = np.array(signs)  # (#S,)
        G_eff = p.G_c.copy()  # (D, L_c)
        for k, col in enumerate(p.s_cols):
            G_eff[:, col] -= p.mu_s[k] * sigma[k] * (p.G_s_blocks[k] @ T_s[k])
        W = np.hstack([np.zeros((G_eff.shape[0], r)), G_eff])  # w = W x + w_ex, x = [z; f_c]
        s_rows = -sigma[:, None] * slip_rows  # -sigma t^T P [u; z] <= -delta
        A_ub = np.vstack([*rows_ub, np.hstack([s_rows[:, a_bar:], np.zeros((n_s, L_c))]), -(p.u @ LrT @ W)[None, :]])
        b_ub = np.concatenate([*rhs_ub, -p.slip_min - s_rows[:, :a_bar] @ p.u, [p.u @ LrT @ p.w_ex - p.w_min]])
        eq = [p.Xi.T @ W] if p.Xi.shape[1] else []
        beq = [-p.Xi.T @ p.w_ex] if p.Xi.shape[1] else []
        if p.N_u.shape[1]:
            eq.append(p.N_u.T @ LrT @ W)
            beq.append(-p.N_u.T @ LrT @ p.w_ex)
        res = solve_lp(np.zeros(r + L_c), A_ub, b_ub, np.vstack(eq) if eq else None,
                       np.concatenate(beq) if beq else None)
        if res.found:
            out.append(sigma)
        elif res.status != "infeasible":
            raise SolverError("HiGHS", f"the planar slip-pattern LP of (31) ended '{res.status}'")
    return out


def realisable_direction(
    system: GraspSystem, sel: Selection, ms: MotionSpace, st: Statics, fs: FrictionSet, start: DirectionTest
) -> Array | None:
    """A DAFC direction whose torque set is not empty, searched with IPOPT from the DAFC
    certificate ``start`` (see :func:`analysis.solvers.casadi_nlp.solve_realisable_direction`)."""
    if start.zeta_c is None or start.forces is None or ms.a_bar == 0:
        return None
    p = _nlp_data(system, sel, ms, st, fs, start.u, with_forces=True)
    res = solve_realisable_direction(p, start.u, start.zeta_c[ms.a_bar :], start.forces)
    return ms.Lambda_r_t @ res.u if res.found else None


def _chosen_motion(
    oracle: DAFCOracle, system: GraspSystem, sel: Selection, ms: MotionSpace, st: Statics, fs: FrictionSet,
    u: Array, start: DirectionTest | None = None,
) -> tuple[Array, str, float]:
    """Problem (31): the redundancy minimising phi; returns (zeta_c, IPOPT status, phi)."""
    r = ms.n_redundant
    a_bar = ms.a_bar
    if r == 0:
        zc = ms.zeta_c(u)
        return zc, "no redundancy", float(np.linalg.norm(ms.Lambda_q_t @ u))
    p = _nlp_data(system, sel, ms, st, fs, u, with_forces=oracle.slip_depends_on_redundancy)
    if p.with_forces and system.d == 2 and sel.s_index:
        # exact in the plane: (31) is 2^#S LPs; when none is feasible IPOPT cannot succeed either
        T_s = np.array([system.tangents[i][0] for i in sel.s_index]).reshape(-1, 2)  # (#S, 2)
        if not planar_slip_patterns(p, T_s):
            raise EmptyTorqueSet("problem (31) has no solution for this direction (no slip-sign pattern of the "
                                 "S-points admits it: an LP each)")
    elif p.with_forces and system.d == 3 and sel.s_index:
        # in 3-D a branch and bound over slip sectors can prove (31) infeasible with a few LPs
        T_3 = np.array([system.tangents[i] for i in sel.s_index]).reshape(-1, 2, 3)  # (#S, 2, 3)
        try:
            screen = slip_sector_screen(p, T_3)
        except SolverError:
            screen = None  # undecided: IPOPT decides as before
        if screen is not None and screen.infeasible:
            raise EmptyTorqueSet(f"problem (31) has no solution for this direction ({screen.reason})")
    z0 = oracle.redundancy_for(u)
    res = solve_redundancy(p, zeta0=z0)
    if not res.found and start is not None and start.zeta_c is not None:
        # restart from the DAFC oracle's certificate: a motion and forces with positive work
        res = solve_redundancy(p, zeta0=start.zeta_c[a_bar:], f0=start.forces)
    if not res.found:
        if z0 is not None and not oracle.slip_depends_on_redundancy:
            # the QP is feasible at z0; IPOPT failing to certify it is a solver problem
            return ms.zeta_c(u, z0), f"least-L1 redundancy (IPOPT: {res.status})", float(
                np.linalg.norm(ms.Lambda_q_t @ u + ms.Lambda_qr_t @ z0))
        raise EmptyTorqueSet(f"problem (31) has no solution for this direction (IPOPT: {res.status})")
    return ms.zeta_c(u, res.zeta_r), res.status, res.phi


def torque_set(
    system: GraspSystem,
    sel: Selection,
    ms: MotionSpace,
    st: Statics,
    fs: FrictionSet,
    grasp: StationaryGrasp,
    direction: Array,
    oracle: DAFCOracle | None = None,
    work_target: float | None = None,
) -> TorqueSet:
    """Eq. (29)-(32) for the object direction ``direction`` (any scale, must be in DAFC)."""
    oracle = oracle or DAFCOracle(system, sel, ms, st, fs)
    test = oracle.test(np.asarray(direction, dtype=float))
    if not test.member:
        raise NotInDAFC(f"direction {np.round(direction, 4).tolist()} is not in DAFC: {test.reason}")
    u = test.u
    try:
        zc, status, phi = _chosen_motion(oracle, system, sel, ms, st, fs, u, start=test)
        return _for_motion(system, sel, ms, st, fs, oracle, u, zc, status, phi, work_target)
    except EmptyTorqueSet:
        if test.zeta_c is None:
            raise
        # The phi-minimal motion may reverse an S-point's slip (a different friction direction);
        # the oracle's certificate motion is a member of S with positive work: use it.
        zc = test.zeta_c
        phi = float(np.linalg.norm(ms.Lambda_q_t @ u + ms.Lambda_qr_t @ zc[ms.a_bar :]))
        return _for_motion(system, sel, ms, st, fs, oracle, u, zc, "DAFC certificate motion (phi not minimised)",
                           phi, work_target)


def _for_motion(
    system: GraspSystem, sel: Selection, ms: MotionSpace, st: Statics, fs: FrictionSet, oracle: DAFCOracle,
    u: Array, zc: Array, status: str, phi: float, work_target: float | None,
) -> TorqueSet:
    """The set (32) once the motion ``dzeta_c`` is fixed (all conditions linear in ``f_c``)."""
    motion = ms.Phi_full @ zc  # (M + D,)
    tc = torque_conditions(system, sel, ms, st, fs, u, oracle.slips_of(zc) if sel.s_index else None)
    A_ub, b_ub, A_eq, b_eq, T_map = tc.A_ub, tc.b_ub, tc.A_eq, tc.b_eq, tc.T_map
    f_rec, work = _recommended(fs, tc, system.w_ex, work_target)
    dim_P = tc.L_c - (rank(A_eq) if A_eq.size else 0)
    gens: Generators | None = None
    if dim_P <= MAX_ENUMERATION_DIM and (dim_P <= SMALL_DIM or A_ub.shape[0] <= MAX_ENUMERATION_ROWS):
        raw = polyhedron_generators(A_ub, b_ub, A_eq, b_eq)
        if raw.is_empty:
            raise EmptyTorqueSet("the torque set (32) is empty for this direction")
        if len(raw.vertices) + len(raw.rays) <= MAX_GENERATORS:  # else: its H-representation only
            gens = reduce_generators(raw.map(T_map))
    return TorqueSet(
        direction=ms.Lambda_r_t @ u,
        u=u,
        zeta_c=zc,
        dq=motion[: system.M],
        phi=phi,
        nlp_status=status,
        generators=gens,
        dim_P=dim_P,
        tau=T_map @ f_rec,
        f_c=f_rec,
        work=work,
        A_ub=A_ub,
        b_ub=b_ub,
        A_eq=A_eq,
        b_eq=b_eq,
        T_map=T_map,
        W_map=tc.W_map,
        friction=tc.friction,
    )


def _recommended(
    fs: FrictionSet, tc: TorqueConditions, w_ex: Array, work_target: float | None,
) -> tuple[Array, float]:
    """A member of T well inside the friction set with a definite positive work.

    Target work ``w* = 0.5 (1 + |w_ex|)`` (capped at half the largest achievable work); among the
    forces achieving it, the least total normal force ``N1`` is found, then the friction margin
    ``s`` (distance to every facet and to ``n_f = 0`` of loaded contacts) is maximised with the
    total normal force at most ``2 N1``.
    """
    A_ub, b_ub, A_eq, b_eq, work_row, work0, L_c = tc.A_ub, tc.b_ub, tc.A_eq, tc.b_eq, tc.work_row, tc.work0, tc.L_c
    Nr = fs.N[np.any(fs.N != 0.0, axis=1)]
    n_sum = Nr.sum(axis=0)
    target = 0.5 * (1.0 + float(np.linalg.norm(w_ex))) if work_target is None else work_target
    best = tc.max_work()
    if best.status == "infeasible":
        raise _over_limits(tc, target, w_ex) or EmptyTorqueSet("the torque set (32) is empty for this direction")
    if best.status == "optimal":
        assert best.objective is not None
        max_work = best.objective + work0
        if max_work <= 1e-9 * (1 + float(np.linalg.norm(w_ex))):
            raise _over_limits(tc, target, w_ex) or EmptyTorqueSet(
                "no member of (32) does positive work in this direction")
        target = min(target, 0.5 * max_work)
    A_w = np.vstack([A_ub, -work_row[None, :]])
    b_w = np.concatenate([b_ub, [work0 - target]])
    first = solve_lp(n_sum, A_ub=A_w, b_ub=b_w, A_eq=A_eq, b_eq=b_eq)
    if not first.found:
        raise EmptyTorqueSet(f"no member of (32) reaches work {target:.3g} ({first.status})")
    assert first.objective is not None and first.x is not None
    budget = 2.0 * first.objective + 1e-9
    m = fs.C.shape[0]
    # variables [f, s]
    A2 = np.vstack(
        [
            np.hstack([A_w, np.zeros((A_w.shape[0], 1))]),
            np.hstack([fs.C, np.ones((m, 1))]),
            np.hstack([-Nr, np.ones((Nr.shape[0], 1))]),
            np.hstack([n_sum[None, :], np.zeros((1, 1))]),
        ]
    )
    b2 = np.concatenate([b_w, np.zeros(m + Nr.shape[0]), [budget]])
    A2_eq = np.hstack([A_eq, np.zeros((A_eq.shape[0], 1))])
    second = solve_lp(np.r_[np.zeros(L_c), 1.0], A_ub=A2, b_ub=b2, A_eq=A2_eq, b_eq=b_eq, maximize=True)
    f = second.x[:L_c] if second.found and second.x is not None else first.x
    return f, float(work_row @ f + work0)


def _over_limits(tc: TorqueConditions, target: float, w_ex: Array) -> EmptyTorqueSet | None:
    """The error for a torque set (32) that only the joint torque limits make empty: it names the
    joints and the torques the motion needs (least uniform relaxation of the limits, at the
    target work, else at a work just above zero); ``None`` when the limits are not the cause."""
    if tc.tau_max is None:
        return None
    for work in (target, 1e-6 * (1.0 + float(np.linalg.norm(w_ex)))):
        try:
            excess = tc.limit_excess(work)
        except SolverError:
            # the diagnosis's own LP failed (HiGHS 'Solve error' on a set of zero work, seen on
            # Baxter's lift with sliding forearms): the set stays empty, undiagnosed, so that
            # torque_set still tries the DAFC certificate motion
            return None
        if excess:
            return EmptyTorqueSet(
                "the torque set (32) is empty within the joint torque limits for this direction; moving "
                f"the object needs {'; '.join(e.describe() for e in excess)}")
    return None


@dataclass(frozen=True)
class FrictionUncertainty:
    """End of section IV-C: torques still realising the motion when ``mu -> nu mu``."""

    nu: float
    lambdas: Array  # (L's + 1,) [lambda_0, lambda_1..]
    feasible: bool  # lambda_0 > 0 and lambda_i >= 0
    tau: Array | None  # (M,) lambda_0 tau_mu + sum lambda_i tau_st_i
    reason: str


def friction_uncertainty(
    system: GraspSystem, sel: Selection, st: Statics, fs: FrictionSet, ts: TorqueSet, nu: float
) -> FrictionUncertainty:
    """Solve the paper's ``(L's + 1)`` square system for ``lambda``.

    ``tau_mu`` is the recommended member of T; ``tau_st_j`` (j = 1..L's) are stationary grasps
    (18) that each maximise the normal force of the j-th loaded S-point (normal forces bounded
    by the recommended member's total), ``n_sst_ij`` their normal forces at the S-points.
    """
    if not 0.0 <= nu <= 1.0:
        raise ValueError("nu must lie in [0, 1]")
    n_mu = np.array([ts.f_c[sel.c_slices[i].start] for i in sel.s_index])
    loaded = [k for k, n in enumerate(n_mu) if n > 1e-9]
    if not loaded:
        return FrictionUncertainty(nu, np.array([1.0]), True, ts.tau,
                                   "no loaded S-point: tau_mu and tau_st combine linearly")
    Ls = len(loaded)
    Nr = fs.N[np.any(fs.N != 0.0, axis=1)]
    budget = float(Nr.sum(axis=0) @ ts.f_c) + 1.0
    taus, nss = [], []
    for k in loaded:
        col = sel.c_slices[sel.s_index[k]].start
        c = np.zeros(st.G_c.shape[1])
        c[col] = 1.0
        res = solve_lp(c, A_ub=np.vstack([fs.C, Nr.sum(axis=0)[None, :]]),
                       b_ub=np.r_[np.zeros(fs.C.shape[0]), budget], A_eq=st.G_c, b_eq=-system.w_ex,
                       maximize=True)
        if not res.found or res.x is None:
            return FrictionUncertainty(nu, np.zeros(Ls + 1), False, None, "no stationary grasp (18)")
        taus.append(st.J_c.T @ res.x)
        nss.append([res.x[sel.c_slices[sel.s_index[j]].start] for j in loaded])
    n_sst = np.array(nss).T  # (Ls, Ls): [i, j] normal at S-point i induced by tau_st_j
    Mx = np.zeros((Ls + 1, Ls + 1))
    Mx[:Ls, 0] = (nu - 1.0) * n_mu[loaded]
    Mx[:Ls, 1:] = nu * n_sst
    Mx[Ls, :] = 1.0
    rhs = np.zeros(Ls + 1)
    rhs[-1] = 1.0
    if rank(Mx) == Ls + 1:
        lam = np.linalg.solve(Mx, rhs)
        ok = bool(lam[0] > 1e-12 and np.all(lam[1:] >= -1e-12))
        reason = "solved" if ok else "lambda violates lambda_0 > 0, lambda_i >= 0"
    else:
        # singular (e.g. the stationary grasps load the S-points in proportion): the paper only
        # asks for a solution with lambda_0 > 0, lambda_i >= 0; take the one with the largest lambda_0
        res = solve_lp(np.eye(Ls + 1)[0], A_eq=Mx, b_eq=rhs, lb=0.0, maximize=True)
        ok = bool(res.found and res.x is not None and res.x[0] > 1e-12)
        lam = res.x if ok and res.x is not None else np.zeros(Ls + 1)
        reason = ("solved (singular system: largest lambda_0)" if ok
                  else "the system is singular and has no solution with lambda_0 > 0, lambda_i >= 0")
    tau = lam[0] * ts.tau + sum(lam[j + 1] * taus[j] for j in range(Ls)) if ok else None
    return FrictionUncertainty(nu, lam, ok, tau, reason)
