"""Direction of active force closure, DAFC (paper eq. 22).

For a FIXED motion ``dzeta_c`` the slip of every S-point is fixed, so kinetic friction is linear
in the normal forces and every condition of (22) is linear in the contact forces. Membership of
an object direction ``dr`` is then one LP over the total contact forces ``f_c``:

    sup  dr^T (G_c f_c + w_s(f_c) + w_ex)
    s.t. f_c in F (16),   Xi^T (G_c f_c + w_s(f_c) + w_ex) = 0      [(I - P) part of (22), W_2]

``w_s`` is the S-point friction (12). ``dr`` is a member iff the supremum is positive, possibly
unbounded (scale-free). The sum ``G_c f_c + w_s + w_ex`` equals the added wrench
``D tau_ad + Xi xi_ad + w_s`` of (25) because ``G_c f_st = -w_ex``, so membership does not depend
on which stationary solution was picked. DAFC is existential over the finger redundancy
``dzeta~_r``: the direction must be allowable (``A_d Phi_full dzeta_c <= 0``, eq. 20) for some
redundancy, and every S-point must really slide (non-zero slip).

Exactness: with no S-point whose slip depends on the redundancy, the redundancy only enters
through the linear allowability constraints, so the oracle is exact. Otherwise the oracle tests
the least-L1 redundancy and a seeded set of alternatives (a local, not a global, search) and
reports ``exact = False``.
"""

from __future__ import annotations

import functools
import heapq
import math
import weakref
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import nnls

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.exceptions import SolverError
from analysis.friction import FrictionSet, kinetic_friction
from analysis.linalg import rank
from analysis.motion import NULL_ROW_TOL, MotionSpace
from analysis.scales import FORCE_TOL, GRIP_BOUND, LP_FEAS_TOL, WORK_TOL, WORK_ZERO, snap
from analysis.solvers.cdd import Generators, cone_generators, polyhedron_generators
from analysis.solvers.highs import LPModel, LPResult
from analysis.statics import Statics
from analysis.torque_conditions import torque_conditions

#: Relative tolerance on non-penetration (positive work: :mod:`analysis.scales`); the rows of
#: ``B`` below it are zero (:attr:`analysis.motion.MotionSpace.B`).
ALLOW_TOL = NULL_ROW_TOL
#: An S-point "really slides" when its slip exceeds this fraction of the motion size.
SLIP_TOL = 1e-7
#: Earlier relaxed-LP maximisers kept per oracle as lower bounds (:meth:`DAFCOracle.relaxed_positive`),
#: and the margin (units of the force scale per unit motion) by which such a bound must clear the
#: work threshold to decide without an LP.
RELAXED_POINTS = 32
RELAXED_MARGIN = 1e-3
#: Farkas certificates of non-allowable directions kept per oracle (:meth:`DAFCOracle.redundancy_for`),
#: and by how much (relative to the motion's size) ``y^T b`` must be negative to decide without an LP.
FARKAS_POINTS = 16
FARKAS_MARGIN = 1e-6
#: Optimal vertices of the force LP kept per set of rows (:meth:`DAFCOracle._vertex_sup`), the
#: slack (relative to the bound) below which a row counts as active there, and the tolerance
#: (relative to the objective) of the multipliers' sign and residual that certify a vertex optimal.
VERTEX_POINTS = 48
VERTEX_ACTIVE_TOL = 1e-9
VERTEX_DUAL_TOL = 1e-12
#: The key of the relaxed LP's vertices among the force LP's (:meth:`DAFCOracle._vertex_sup`; the
#: force LP's keys are empty or whole float64 arrays, never 1 byte long).
_RELAXED_KEY = b"R"
#: :meth:`DAFCOracle.test_many` tests fewer directions than this one by one (the steps done for
#: all rows at once cost more than the per-direction work they save below about a dozen rows).
BATCH_MIN = 12
#: Optimal bases kept per redundancy LP (:class:`_RhsBases`), the least multiplier (relative to the
#: objective) that makes a basis's optimum unique, and the primal slack (relative to the
#: right-hand side) a reused basis point may have.
BASES_KEPT = 16
BASIS_DUAL_MIN = 1e-7
BASIS_PRIMAL_TOL = 1e-12

SEMANTICS: dict[str, str] = {
    "dafc_unknowns": "total contact forces f_c; membership does not depend on the stationary solution",
    "dafc_scale": "member iff admissible forces with a total normal force of at most 1000 x the force scale "
    "(|w_ex|) do positive work above 1e-6 x the force scale per unit motion (moments per object size)",
    "dafc_redundancy": "existential over the finger redundancy dzeta~_r; the torque problem (31) then "
    "picks the motion minimising phi = |dq|",
    "dafc_w3": "DAFC has no W_3 condition; the torque set (30)-(32) does",
    "s_point": "an S-point must slide (non-zero slip); its kinetic friction is exactly mu n against the "
    "slip (no pyramid); in the stationary state (18) it carries a normal force only",
    "d_point": "a D-point carries no force and must not penetrate (A_d [dq; dr] <= 0, equality allowed)",
    "n_point": "N is the state of a contact with mu = 0 (normal force only)",
    "torque_limits": "joint-torque limits (the scene's joint_torque_limits, else the URDF's efforts) bound the "
    "stationary grasp (18) and the torque sets (32), not DAFC",
    "friction_cone_3d": "F-point cones in 3-D are inscribed k-sided pyramids (k = friction_cone_sides)",
}


@dataclass(frozen=True)
class DirectionTest:
    """The DAFC oracle's answer for one object direction."""

    direction: Array  # (D,) unit object motion dr
    u: Array  # (a_bar,) its coordinates on Lambda~_r
    zeta_c: Array | None  # (a,) the motion tested (None when not allowable)
    member: bool
    work: float  # supremum of the work within the grip bound (finite; nan when not tested or undecided)
    reason: str
    exact: bool
    forces: Array | None = None  # (L_c,) a maximiser of the work (None when unbounded)

    def __post_init__(self) -> None:
        assert not self.member or abs(_norm(self.direction) - 1.0) < 1e-6


@dataclass
class _VertexCache:
    """Optimal vertices of the force LP for one set of rows (mutable: grows per oracle)."""

    X: Array  # (k, L_c) vertices, units of F0
    certs: list[tuple[Array, Array, int]]  # per vertex: pinv(A_act^T) (k_act, L_c), A_act^T (L_c, k_act), #ub rows


class _RhsBases:
    """Certified optimal bases of ``min c^T x  s.t.  A x <= b,  lb <= x <= ub`` where only ``b``
    changes between solves (the redundancy LPs of one oracle, solved cold per direction).

    The bounds are rows too: ``Abar x <= bbar`` with ``Abar = [A; -I_lb; I_ub]`` (finite bounds
    only). A basis is a set ``I`` of ``n`` rows with ``Abar_I`` invertible whose multipliers
    ``y_I = -Abar_I^{-T} c`` all exceed :data:`BASIS_DUAL_MIN` ``max(1, |c|)``: ``y`` does not depend
    on ``b``, so for a new ``b`` the point ``x = Abar_I^{-1} bbar_I``, when it satisfies every row
    (to :data:`BASIS_PRIMAL_TOL`), is optimal (``c^T x' >= -y^T Abar x' >= -y^T bbar = c^T x``
    for every feasible ``x'``), and it is the only optimum (every optimum meets the rows of ``I``,
    where ``y > 0``, with equality), so a cold LP returns the same point: the answer does not
    depend on which earlier direction left the basis. Bases are harvested from optimal LP
    results (:meth:`harvest`); degenerate ones (a zero multiplier) are not kept."""

    def __init__(self, c: Array, A: Array, lb: Array, ub: Array):
        n = A.shape[1]
        lo, up = np.isfinite(lb), np.isfinite(ub)
        I = np.eye(n)
        self.c = c  # (n,)
        self.m = A.shape[0]
        self.Abar = np.vstack([A, -I[lo], I[up]])  # (m + #lb + #ub, n)
        self.fixed = np.r_[-lb[lo], ub[up]]  # right-hand sides of the bound rows
        self._lo, self._up = np.flatnonzero(lo), np.flatnonzero(up)
        self.bases: list[tuple[Array, Array]] = []  # (I (n,), Abar_I^{-1} (n, n))
        self.hits = 0

    def solve(self, b: Array) -> Array | None:
        """The unique optimum for the inequality right-hand side ``b`` from a kept basis, or None."""
        bbar = np.concatenate([b, self.fixed])  # (m + #lb + #ub,)
        tol = BASIS_PRIMAL_TOL * max(1.0, float(np.max(np.abs(bbar), initial=0.0)))
        for k, (rows, inv) in enumerate(self.bases):
            x = inv @ bbar[rows]  # (n,)
            if bool(np.all(self.Abar @ x <= bbar + tol)):
                if k:  # the last basis used first: neighbouring directions share their basis
                    self.bases.insert(0, self.bases.pop(k))
                self.hits += 1
                return x
        return None

    def solve_many(self, b: Array) -> tuple[Array, Array]:
        """:meth:`solve` for the right-hand sides ``b`` ``(k, m)``: the optima ``(k, n)`` and which
        rows have one ``(k,)`` (a row takes the first kept basis whose point satisfies every row;
        the optimum is unique, so it does not matter which)."""
        k = b.shape[0]
        bbar = np.hstack([b, np.broadcast_to(self.fixed, (k, len(self.fixed)))])  # (k, m + #lb + #ub)
        tol = BASIS_PRIMAL_TOL * np.maximum(1.0, np.abs(bbar).max(axis=1, initial=0.0))  # (k,)
        X = np.zeros((k, self.Abar.shape[1]))
        found = np.zeros(k, bool)
        for rows, inv in self.bases:
            todo = np.flatnonzero(~found)
            if not todo.size:
                break
            x = bbar[todo][:, rows] @ inv.T  # (t, n)
            ok = (x @ self.Abar.T <= bbar[todo] + tol[todo, None]).all(axis=1)
            X[todo[ok]] = x[ok]
            found[todo[ok]] = True
        self.hits += int(found.sum())
        return X, found

    def harvest(self, res: LPResult) -> None:
        """Keep the basis of the optimal result ``res`` when its multipliers certify it (above)."""
        if len(self.bases) >= BASES_KEPT or res.y_ub is None or res.z is None:
            return
        n = self.Abar.shape[1]
        # multipliers of Abar's rows: y_ub, then -z at lower bounds, z at upper bounds
        y = np.concatenate([res.y_ub, -res.z[self._lo], res.z[self._up]])
        floor = BASIS_DUAL_MIN * max(1.0, float(np.max(np.abs(self.c), initial=0.0)))
        rows = np.flatnonzero(y > floor)
        if len(rows) != n:
            return  # degenerate (or not a vertex): several optima possible, the LP decides
        A_I = self.Abar[rows]  # (n, n)
        try:
            inv = np.linalg.inv(A_I)
        except np.linalg.LinAlgError:
            return
        if not np.all(np.isfinite(inv)) or np.linalg.cond(A_I) > 1e10:
            return
        y_I = -(inv.T @ self.c)  # (n,) recomputed from the basis itself
        if float(np.min(y_I)) <= floor or float(np.max(np.abs(A_I.T @ y_I + self.c))) > 1e-12 * max(
                1.0, float(np.max(np.abs(self.c)))):
            return
        if not any(np.array_equal(rows, r) for r, _ in self.bases):
            self.bases.append((rows, inv))


class DAFCOracle:
    """Exact LP membership test of eq. (22) for one combination."""

    def __init__(self, system: GraspSystem, sel: Selection, ms: MotionSpace, st: Statics, fs: FrictionSet):
        self.system, self.sel, self.ms, self.st, self.fs = system, sel, ms, st, fs
        self.Xi = st.Xi  # (D, p)
        self.B = ms.B  # (#D, a)
        self.Ps = ms.P_s  # (d #S, a)
        a_bar = ms.a_bar
        d = system.d
        # Does the slip of some S-point depend on the redundancy?
        self.slip_depends_on_redundancy = bool(
            len(sel.s_index) and ms.n_redundant and np.abs(self.Ps[:, a_bar:]).max() > 1e-9
        )
        self.exact = not self.slip_depends_on_redundancy
        self._lp: LPModel | None = None
        self._redundancy: LPModel | None = None
        self._relaxed: LPModel | None = None
        self._aligned: LPModel | None = None  # the friction-aligned redundancy LP (_aligned_allowable)
        # certified optimal bases of the two redundancy LPs (their right-hand sides change per direction)
        self._redundancy_bases: _RhsBases | None = None
        self._aligned_bases: _RhsBases | None = None
        self._G_relaxed = np.zeros((system.D, 0))
        self._d = d
        self.lp_count = 0
        self.undecided = 0  # force LPs that ended numerically undecided (degenerate data)
        self.sector_boxes = 0  # boxes of the slip-sector search (:func:`slip_sector_search`)
        self.sector_open = 0  # of them, left open (resolution or budget): emptiness not proven there
        # per-combination constants of the direction loop (they do not change between directions)
        self._Lr = ms.Lambda_r_t  # (D, a_bar)
        self._B_u, self._B_r = self.B[:, :a_bar], self.B[:, a_bar:]  # (#D, a_bar), (#D, r)
        self._B_r_any = bool(np.any(self._B_r))
        self._s_cols = np.array([sel.c_slices[i].start for i in sel.s_index], dtype=int)  # (#S,)
        # friction per unit normal force and unit slip of each S-point on the object: G_i (D, d)
        self._XiT = np.ascontiguousarray(self.Xi.T)  # (p, D)
        # optimal points of the relaxed LP solved so far, as wrenches in units of F0: a lower bound
        # of the relaxed supremum for every other direction (:meth:`relaxed_positive`)
        self._relaxed_W = np.zeros((system.D, 0))  # (D, k)
        # Farkas certificates y (k, #D) of directions the redundancy cannot make allowable
        self._farkas = np.zeros((0, self.B.shape[0]))
        self._farkas_lp: LPModel | None = None
        # optimal vertices of the force LP per constraint data (key: the S columns of G_eff), each
        # with what certifies it optimal for another objective (:meth:`_vertex_sup`); None: infeasible
        self._vertices: dict[bytes, _VertexCache | None] = {}
        self.vertex_hits = 0  # force or relaxed LPs decided by a certified earlier vertex (no HiGHS call)
        self.box_vertex_hits = 0  # slip-sector bounds decided by a certified earlier optimum (:func:`_box_vertex`)
        # planar S-points: the unit slip is +-t (the slip is tangential: the motion space keeps the
        # normal velocity zero), so the friction columns take one of 2^#S values, one per sign pattern
        self._T_s = (np.array([system.tangents[i][0] for i in sel.s_index]).reshape(-1, d) if d == 2
                     else np.zeros((0, d)))  # (#S, 2)
        self._pattern_G: dict[bytes, tuple[Array, Array]] = {}  # sign pattern -> (G_eff (D, L_c), E (p, #S))
        self._lp_key: bytes | None = None  # the sign pattern whose S columns the force LP holds
        self._noise: list[Array] = []  # seeded redundancy draws (:meth:`_seeded_noise`)

    # -- kinematics -----------------------------------------------------------------------------

    def redundancy_for(self, u: Array) -> Array | None:
        """Least-L1 redundancy ``dzeta~_r`` making ``[u; dzeta~_r]`` allowable (eq. 20), or None."""
        ms = self.ms
        nr = ms.n_redundant
        B_r = self._B_r
        rhs = -(self._B_u @ u)  # (#D,)
        if self.B.shape[0] == 0:
            return np.zeros(nr)
        tol = ALLOW_TOL * max(1.0, _norm(u))
        if bool((rhs >= -tol).all()):
            return np.zeros(nr)  # zero redundancy is allowable: the least-L1 choice
        if nr == 0 or not self._B_r_any:
            return None
        # z = [z+ ; z-] >= 0, zeta = z+ - z-, minimise sum(z); one model per oracle, solved cold
        # so that the redundancy chosen for a direction does not depend on earlier directions
        b = rhs + tol / 2  # (#D,) half the tolerance: the check below has slack
        margin = FARKAS_MARGIN * max(1.0, _norm(u))
        if self._farkas.shape[0] and float(np.min(self._farkas @ b)) < -margin:
            return None  # an earlier Farkas certificate proves B_r z <= b infeasible (no LP needed)
        if self._redundancy_bases is None:
            self._redundancy_bases = _RhsBases(np.ones(2 * nr), np.hstack([B_r, -B_r]), np.zeros(2 * nr),
                                               np.full(2 * nr, np.inf))
        x = self._redundancy_bases.solve(b)  # the LP's unique optimum from a certified basis
        if x is not None:
            return x[:nr] - x[nr:]
        if self._redundancy is None:
            self._redundancy = LPModel(2 * nr, A_ub=np.hstack([B_r, -B_r]), b_ub=b, lb=0.0)
        else:
            self._redundancy.set_ub_rhs(b)
        res = self._redundancy.solve_cold(np.ones(2 * nr))
        self.lp_count += 1
        if res.status != "optimal":
            self._harvest_farkas(b, margin)
            return None
        assert res.x is not None
        self._redundancy_bases.harvest(res)
        return res.x[:nr] - res.x[nr:]

    def _harvest_farkas(self, b: Array, margin: float) -> None:
        """Keep a Farkas certificate of the infeasible ``B_r z <= b`` (z free) for later directions:
        ``y >= 0``, ``sum y = 1``, ``B_r^T y = 0`` with ``y^T b < 0`` (then no ``z`` exists, since
        ``0 = y^T B_r z <= y^T b < 0``), the minimiser of ``y^T b`` (an LP). Stored only when it clears
        ``-margin`` and its residual ``|B_r^T y|_inf`` is at rounding level."""
        if self._farkas.shape[0] >= FARKAS_POINTS:
            return
        B_r = self._B_r  # (#D, r)
        m = B_r.shape[0]
        if self._farkas_lp is None:
            self._farkas_lp = LPModel(m, A_eq=np.vstack([B_r.T, np.ones((1, m))]),
                                      b_eq=np.r_[np.zeros(B_r.shape[1]), 1.0], lb=0.0)
        try:
            res = self._farkas_lp.solve(b)
        except SolverError:
            return  # no certificate: later directions are decided by their own LP
        self.lp_count += 1
        if res.status != "optimal" or res.x is None:
            return
        y = np.maximum(res.x, 0.0)  # (#D,)
        y = y / float(y.sum())
        if float(np.max(np.abs(B_r.T @ y), initial=0.0)) <= 1e-12 and float(y @ b) < -margin:
            self._farkas = np.vstack([self._farkas, y[None, :]])

    def slips_of(self, zeta_c: Array) -> Array:
        """Slip of each S-point ``(#S, d)`` for the motion ``dzeta_c`` (eq. 21)."""
        return (self.Ps @ zeta_c).reshape(len(self.sel.s_index), self._d)

    # -- forces ---------------------------------------------------------------------------------

    def _relaxed_model(self) -> LPModel:
        """LP over ``[f_c; t_s]`` where every S-point's friction ``t_s`` may take any tangential
        direction with ``|t| <= mu n`` (a circumscribed pyramid in 3-D): a relaxation of the
        kinetic friction of (22) valid for every slip, hence for every redundancy."""
        if self._relaxed is None:
            sy, sel, st, fs = self.system, self.sel, self.st, self.fs
            d, L_c, nS = sy.d, st.G_c.shape[1], len(sel.s_index)
            n_var = L_c + d * nS
            rows: list[Array] = [np.hstack([fs.C, np.zeros((fs.C.shape[0], d * nS))])]
            eq_rows: list[Array] = []
            G_S = np.zeros((sy.D, d * nS))
            k_sides = sy.friction_sides
            for k, i in enumerate(sel.s_index):
                n, T = sy.normals[i], sy.tangents[i]
                col_n = sel.c_slices[i].start
                cols = slice(L_c + d * k, L_c + d * (k + 1))
                G_S[:, d * k : d * (k + 1)] = sy.G_blocks[i]
                e = np.zeros(n_var)
                e[cols] = n
                eq_rows.append(e)
                if d == 2:
                    dirs = [T[0], -T[0]]
                    mu = sy.mu[i]
                else:
                    ang = 2 * np.pi * np.arange(k_sides) / k_sides
                    dirs = [np.cos(a) * T[0] + np.sin(a) * T[1] for a in ang]
                    mu = sy.mu[i]  # sides at distance mu n: the k-gon circumscribing the disc
                for c in dirs:
                    r = np.zeros(n_var)
                    r[cols] = c
                    r[col_n] = -mu
                    rows.append(r[None, :])
            self._G_relaxed = np.hstack([st.G_c, G_S])  # (D, n_var), unknowns in units of F0
            grip = np.zeros(n_var)
            grip[:L_c] = fs.N.sum(axis=0)
            rows.append(grip[None, :])
            A_eq = np.vstack([self.Xi.T @ self._G_relaxed, *[e[None, :] for e in eq_rows]])
            b_eq = np.concatenate([-(self.Xi.T @ sy.w_ex) / sy.scales.force, np.zeros(len(eq_rows))])
            A_ub = np.vstack(rows)
            b_ub = np.zeros(A_ub.shape[0])
            b_ub[-1] = GRIP_BOUND
            self._relaxed = LPModel(n_var, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq)
        return self._relaxed

    def relaxed_work_sup(self, dr: Array) -> float:
        """Upper bound of the work over every slip choice (see :meth:`_relaxed_model`)."""
        model = self._relaxed_model()
        res = model.solve(self._G_relaxed.T @ dr, maximize=True)
        self.lp_count += 1
        if res.status == "infeasible":
            self._vertices[_RELAXED_KEY] = None  # its rows do not depend on dr: infeasible for every one
            return -np.inf
        if res.status != "optimal":  # the grip bound bounds every force
            raise SolverError("HiGHS", f"relaxed DAFC LP ended '{res.status}' although its forces are bounded")
        assert res.objective is not None and res.x is not None
        self._keep_vertex(_RELAXED_KEY, model, res.x)
        if self._relaxed_W.shape[1] < RELAXED_POINTS:
            w = self._G_relaxed @ res.x  # (D,) the maximiser's wrench, units of F0
            if not np.any(np.all(np.abs(self._relaxed_W - w[:, None]) <= 1e-12, axis=0)):
                self._relaxed_W = np.hstack([self._relaxed_W, w[:, None]])
        return float(res.objective * self.system.scales.force + dr @ self.system.w_ex)

    def relaxed_positive(self, dr: Array) -> bool:
        """``relaxed_work_sup(dr) > work_tol(dr)``, decided without an LP where possible.

        Every maximiser of an earlier relaxed LP is a feasible point of the same LP (its rows do
        not depend on ``dr``), so its work along ``dr`` bounds the supremum from below. When that
        bound exceeds the threshold by a margin (:data:`RELAXED_MARGIN` x the force scale per unit
        motion, far above the LP tolerances' effect on the work) the answer is yes, exactly as the
        LP's. Otherwise an earlier optimal vertex of the relaxed LP whose multipliers certify it
        optimal for ``dr`` gives the supremum itself (:meth:`_vertex_sup`, the same margin either
        way); failing both, the LP decides."""
        sc = self.system.scales
        tol = sc.work_tol(dr)
        if self._relaxed_W.shape[1]:
            lower = float(np.max(dr @ self._relaxed_W)) * sc.force + float(dr @ self.system.w_ex)
            if lower > tol + RELAXED_MARGIN * sc.force * sc.motion_size(dr):
                return True
        known = self._vertex_sup(_RELAXED_KEY, self._G_relaxed.T @ dr, dr)
        if known is not None:
            return known[0] > tol
        return self.relaxed_work_sup(dr) > tol

    def _force_lp(self) -> LPModel:
        """The force LP of (22), built once per combination: friction rows and the passive
        equalities ``Xi^T G_c f_c = -Xi^T w_ex``. With S-points only the S columns of the
        equality rows change with the slips (``Xi^T G_eff``); they are overwritten in place per
        motion, so every solve is warm-started."""
        if self._lp is None:
            st, fs = self.st, self.fs
            self._lp = LPModel(
                st.G_c.shape[1],
                A_ub=np.vstack([fs.C, fs.N.sum(axis=0)[None, :]]),
                b_ub=np.r_[np.zeros(fs.C.shape[0]), GRIP_BOUND],
                A_eq=snap(self.Xi.T @ st.G_c),
                b_eq=snap(-(self.Xi.T @ self.system.w_ex) / self.system.scales.force),
                feasibility=LP_FEAS_TOL,
            )
        return self._lp

    def work_sup(self, dr: Array, zeta_c: Array, witness: bool = True) -> tuple[float, Array | None]:
        """``sup dr^T (G_c f + w_s + w_ex)`` over the admissible forces for the motion ``zeta_c``."""
        return self._work_sup(dr, zeta_c, witness)

    def _work_sup(self, dr: Array, zeta_c: Array, witness: bool,
                  planar: tuple[Array, Array, bytes] | None = None, keep: bool = True) -> tuple[float, Array | None]:
        """:meth:`work_sup`; ``planar``: the motion's :meth:`_planar_friction`, when known;
        ``keep``: store the optimal vertex for later objectives of the same rows (:meth:`_keep_vertex`)."""
        st = self.st
        w_ex = self.system.w_ex
        if st.G_c.shape[1] == 0:  # no contact carries force (all D): only w_ex can do work
            return float(dr @ w_ex), np.zeros(0)
        E: Array | None = None
        if not self.sel.s_index:
            G_eff = st.G_c
            key = b""
        elif self._d == 2:
            G_eff, E, key = self._planar_friction(zeta_c) if planar is None else planar
        else:
            G_eff = st.G_c + kinetic_friction(self.system, self.sel, self.slips_of(zeta_c)).G_w
            key = G_eff[:, self._s_cols].tobytes()  # the LP's rows and objective map depend on these only
        model = self._force_lp()
        c = G_eff.T @ dr  # (L_c,) work per unit force (units of F0)
        if not witness:
            known = self._vertex_sup(key, c, dr)
            if known is not None:
                return known
        if self.sel.s_index and (E is None or key != self._lp_key):
            s_cols = self._s_cols
            if E is None:
                E = snap(self._XiT @ G_eff[:, s_cols])  # (p, #S), noise-level entries zero as in the base rows
            rows, cols = np.indices(E.shape)
            model.change_coefficients(rows.ravel() + model.n_ub, s_cols[cols.ravel()], E.ravel())
            self._lp_key = key if self._d == 2 else None
        try:
            res = model.solve(c, maximize=True)
        except SolverError:
            # every HiGHS method (warm, cold, defaults, interior point) ended undecided: this motion
            # is not a member, and the combination's verdict says the data are degenerate
            self.undecided += 1
            model.use_defaults()  # leave no half-solved state for the next direction
            return np.nan, None
        self.lp_count += 1
        if res.status == "infeasible":
            self._vertices[key] = None  # the rows do not depend on dr: infeasible for every direction
            return -np.inf, None
        if res.status != "optimal":  # the grip bound bounds every force
            raise SolverError("HiGHS", f"DAFC force LP ended '{res.status}' although its forces are bounded")
        assert res.objective is not None and res.x is not None
        if keep:
            self._keep_vertex(key, model, res.x)
        f = res.x * self.system.scales.force
        return float(G_eff.T @ dr @ f + dr @ w_ex), f

    def _planar_friction(self, zeta_c: Array, slips: Array | None = None) -> tuple[Array, Array, bytes]:
        """``G_eff = G_c + G_w`` (eq. 12) of a planar motion, its S columns of the passive equalities
        ``E = Xi^T G_eff[:, S]`` ``(p, #S)`` and its key: the sign pattern of the slips along the
        tangents. In 2-D an S-point's slip is tangential (the motion space keeps its normal velocity
        zero; the null-space basis leaves ~1e-12 of normal component), so its unit slip is exactly
        ``+-t``: the force LP depends on the motion through these signs only, and one set of rows
        (with its certified vertices, :meth:`_vertex_sup`) serves every motion of a pattern."""
        sl = self.slips_of(zeta_c) if slips is None else slips  # (#S, 2)
        return self._pattern_friction(np.where((sl * self._T_s).sum(axis=1) >= 0.0, 1.0, -1.0))

    def _pattern_friction(self, sig: Array) -> tuple[Array, Array, bytes]:
        """:meth:`_planar_friction` of the slip-sign pattern ``sig`` ``(#S,)`` (+-1 along the tangents)."""
        key = sig.tobytes()
        known = self._pattern_G.get(key)
        if known is None:
            G_eff = self.st.G_c + kinetic_friction(self.system, self.sel, sig[:, None] * self._T_s).G_w  # (D, L_c)
            known = G_eff, snap(self._XiT @ G_eff[:, self._s_cols])
            self._pattern_G[key] = known
        return known[0], known[1], key

    def _keep_vertex(self, key: bytes, model: LPModel, x: Array) -> None:
        """Store the force LP's optimal point ``x`` (units of F0) for the rows ``key`` with the
        pseudo-inverse of its active rows ``A_act`` (the inequality rows within
        :data:`VERTEX_ACTIVE_TOL` of their bound and every equality row): for another objective
        ``c`` the multipliers ``y = pinv(A_act^T) c`` certify ``x`` optimal (:meth:`_vertex_sup`)."""
        cache = self._vertices.get(key)
        if key in self._vertices and cache is None:
            return  # cannot happen for one set of rows (infeasible there); kept as decided
        if cache is not None and cache.X.shape[0] >= VERTEX_POINTS:
            return
        if cache is not None and bool(np.any(np.all(np.abs(cache.X - x) <= 1e-12, axis=1))):
            return
        if np.isfinite(model.lb).any() or np.isfinite(model.ub).any():
            return  # the certificate below knows the rows only (the force LP has free variables)
        slack = model.b_ub - model.A_ub @ x  # (m_ub,)
        active = slack <= VERTEX_ACTIVE_TOL * np.maximum(1.0, np.abs(model.b_ub))
        A_act = np.vstack([model.A_ub[active], model.A_eq])  # (k, L_c)
        if A_act.shape[0] < model.n:
            return  # not a vertex: no unique multipliers to certify it with
        U, s, Vt = np.linalg.svd(A_act.T, full_matrices=False)  # (L_c, L_c), (L_c,), (L_c, k): one SVD
        if float(s[-1]) <= 1e-10 * max(1.0, float(s[0])):
            return  # rank below L_c: not a vertex
        entry = ((Vt.T / s) @ U.T, np.ascontiguousarray(A_act.T), int(active.sum()))  # pinv(A_act^T) (k, L_c)
        if cache is None:
            self._vertices[key] = _VertexCache(x[None, :].copy(), [entry])
        else:
            cache.X = np.vstack([cache.X, x[None, :]])
            cache.certs.append(entry)

    def _vertex_sup(self, key: bytes, c: Array, dr: Array) -> tuple[float, Array | None] | None:
        """The force LP's answer for the objective ``c = G_eff^T dr`` from an earlier optimal
        vertex of the same rows, or None (then the LP decides).

        Among the stored vertices only the one of largest ``c^T x`` can be optimal. It is when
        multipliers ``y = pinv(A_act^T) c`` of its active rows satisfy ``A_act^T y = c`` and
        ``y >= 0`` on the inequality rows (LP duality: then ``c^T x' <= y^T b_act = c^T x`` for every
        feasible ``x'``), both checked to :data:`VERTEX_DUAL_TOL` relative to ``|c|``. The answer is
        used only when the work clears the threshold ``work_tol(dr)`` by
        :data:`RELAXED_MARGIN` x the force scale per unit motion either way (far above the
        tolerances' effect), so the verdict is the LP's; the value is the supremum itself."""
        if key not in self._vertices:
            return None
        cache = self._vertices[key]
        sy = self.system
        if cache is None:
            self.vertex_hits += 1
            return -np.inf, None
        vals = cache.X @ c  # (k,)
        j = int(vals.argmax())
        M, AT, n_ub = cache.certs[j]
        y = M @ c  # (k_act,)
        scale = VERTEX_DUAL_TOL * max(1.0, float(np.abs(c).max()) if c.size else 0.0)
        if (n_ub and float(y[:n_ub].min()) < -scale) or float(np.abs(AT @ y - c).max()) > scale:
            return None
        x = cache.X[j]
        f = x * sy.scales.force
        sup = float(c @ f + dr @ sy.w_ex)
        sc = sy.scales
        size = sc.motion_size(dr)
        if abs(sup - WORK_TOL * sc.force * size) <= RELAXED_MARGIN * sc.force * size:
            return None  # too close to the threshold (work_tol(dr)): the LP decides
        self.vertex_hits += 1
        return sup, f

    def _vertex_sups(self, key: bytes, C: Array, DR: Array, sizes: Array) -> tuple[Array, Array]:
        """:meth:`_vertex_sup` for many objectives at once: the rows of ``C`` ``(m, n)``, of the
        directions ``DR`` ``(m, D)`` whose motion sizes are ``sizes`` ``(m,)``. Returns the suprema
        ``(m,)`` and per row the index of the certified vertex (``-1``: the rows are infeasible,
        supremum ``-inf``; ``-2``: not decided, the LP decides). The same checks, row by row."""
        m = C.shape[0]
        sup = np.full(m, np.nan)
        idx = np.full(m, -2)
        if m == 0 or key not in self._vertices:
            return sup, idx
        cache = self._vertices[key]
        if cache is None:
            self.vertex_hits += m
            return np.full(m, -np.inf), np.full(m, -1)
        sc = self.system.scales
        scale = VERTEX_DUAL_TOL * np.maximum(1.0, np.abs(C).max(axis=1) if C.shape[1] else 0.0)  # (m,)
        thr = WORK_TOL * sc.force * sizes  # (m,) work_tol of each direction
        margin = RELAXED_MARGIN * sc.force * sizes  # (m,)
        w0 = DR @ self.system.w_ex  # (m,)
        best = (C @ cache.X.T).argmax(axis=1)  # (m,) only the vertex of largest c^T x can be optimal
        for j in np.unique(best):
            rows = np.flatnonzero(best == j)
            M, AT, n_ub = cache.certs[int(j)]
            Cj, sj = C[rows], scale[rows]  # (r, n), (r,)
            Y = Cj @ M.T  # (r, k_act) multipliers of the active rows
            ok = np.abs(Y @ AT.T - Cj).max(axis=1) <= sj
            if n_ub:
                ok &= Y[:, :n_ub].min(axis=1) >= -sj
            s = Cj @ (cache.X[j] * sc.force) + w0[rows]  # (r,)
            ok &= np.abs(s - thr[rows]) > margin[rows]  # not too close to the threshold
            sup[rows[ok]] = s[ok]
            idx[rows[ok]] = j
        self.vertex_hits += int((idx >= 0).sum())
        return sup, idx

    def certify(self, t: DirectionTest) -> bool:
        """Re-check a member in newtons: its forces lie in the friction set, satisfy the passive
        equalities ``Xi^T w = 0`` (W_2) and the grip bound, and do positive work along ``dr``."""
        if not t.member or t.forces is None or t.zeta_c is None:
            return False
        sy, st, fs = self.system, self.st, self.fs
        sc = sy.scales
        f = t.forces
        G_eff = st.G_c
        if self.sel.s_index:
            G_eff = G_eff + kinetic_friction(sy, self.sel, self.slips_of(t.zeta_c)).G_w
        w = (G_eff @ f if f.size else np.zeros(sy.D)) + sy.w_ex
        passive = float(np.max(np.abs(self.Xi.T @ w), initial=0.0)) / sc.force
        friction = float(np.max(fs.C @ f, initial=0.0)) / sc.force if fs.C.shape[0] else 0.0
        grip = float(fs.N.sum(axis=0) @ f) if f.size else 0.0
        return bool(passive <= FORCE_TOL * (1.0 + sc.length) and friction <= FORCE_TOL
                    and grip <= sc.grip_bound * (1.0 + FORCE_TOL) and float(t.direction @ w) > sc.work_tol(t.direction))

    def realisable(self, t: DirectionTest) -> bool:
        """Has the member ``t`` a non-empty torque set (32) for its tested motion ``t.zeta_c``?

        DAFC (22) has no ``W_3`` condition; T also asks the net wrench in the motion space to be
        parallel to the motion (``N_u^T Lambda~_r^T w = 0``) with positive work. With the slips
        of ``t.zeta_c`` fixed this is the largest-work LP of the torque set's conditions
        (:mod:`analysis.torque_conditions`, the one :mod:`analysis.torques` solves first). A
        member can fail it robustly (SSSSS, or DDSSS away from the realisable sub-cone), so the
        example direction of a combination prefers members that pass it.
        """
        if not t.member or t.zeta_c is None:
            return False
        sy = self.system
        tc = torque_conditions(sy, self.sel, self.ms, self.st, self.fs, t.u,
                               self.slips_of(t.zeta_c) if self.sel.s_index else None)
        tol = sy.scales.work_tol(self.ms.Lambda_r_t @ t.u)
        if tc.L_c == 0:  # no forces: the external wrench alone must do it
            return bool(tc.work0 > tol and np.all(np.abs(tc.b_eq) <= tol))
        try:
            res = tc.max_work()
        except SolverError:
            return False  # undecided: only a preference among members hangs on it
        self.lp_count += 1
        if res.status == "unbounded":
            return True
        return bool(res.found and res.objective is not None and res.objective + tc.work0 > tol)

    # -- membership -----------------------------------------------------------------------------

    def test(
        self, dr: Array, zeta_r: Array | None = None, screen: bool = True, quick: bool = False, witness: bool = True,
        keep: bool = True,
    ) -> DirectionTest:
        """Is the object direction ``dr`` (any scale, in the motion space) in DAFC?

        ``screen``: with S-points, first try to prove non-membership with the relaxation
        (:meth:`relaxed_work_sup`), which is exact when it says no. ``quick``: when the slips
        depend on the redundancy, try only the friction-aligned and the least-L1 redundancies
        (not the seeded random ones). ``witness``: for an unbounded supremum, also return forces
        with positive work (one more LP); sampling the set does without. ``keep=False``: the force
        LP's optimum is not stored for later directions (:meth:`_vertex_sup`), for motions that do
        not recur (in 3-D the rows depend on the exact slips).
        """
        ms = self.ms
        dr = np.asarray(dr, dtype=float)
        Lr = self._Lr  # (D, a_bar)
        u = Lr.T @ dr  # (a_bar,) coordinates (MotionSpace.coordinates)
        nu = _norm(u)
        if ms.a_bar == 0:
            return DirectionTest(dr, u, None, False, np.nan, "object cannot move (motion space is {0})", True)
        if nu < 1e-12:
            return DirectionTest(dr, u, None, False, np.nan, "direction is outside the motion space", True)
        if _norm(Lr @ u - dr) > 1e-6 * max(1.0, _norm(dr)):
            return DirectionTest(dr, u, None, False, np.nan, "direction is outside the motion space", True)
        u = u / nu
        dr = Lr @ u
        sc = self.system.scales
        if screen and self.sel.s_index and zeta_r is None and not self.relaxed_positive(dr):
            return DirectionTest(dr, u, None, False, np.nan,
                                 "the fingers cannot do positive work, whatever the S-points' slip", True)
        candidates: list[Array] | Iterator[Array]
        if zeta_r is not None:
            candidates = [np.asarray(zeta_r, dtype=float)]
        else:
            z0 = self.redundancy_for(u)
            if z0 is None:
                return DirectionTest(dr, u, None, False, np.nan, "not allowable: a D-point would penetrate",
                                     True)
            if self.slip_depends_on_redundancy:
                # the first allowable alternative, the least-L1 one, the other alternatives: computed
                # lazily, so a member among the first ones costs no further redundancy LPs
                candidates = _first_then(self._iter_alternatives(u, z0, count=0 if quick else 4), z0)
            else:
                candidates = [z0]
        last: DirectionTest | None = None
        work_tol = sc.work_tol(dr)
        # planar: the force LP depends on the motion through the slip signs only
        # (:meth:`_planar_friction`), so candidates of one sign pattern share its answer
        planar = self._d == 2 and bool(self.sel.s_index)
        answered: dict[bytes, tuple[float, Array | None]] = {}
        for zr in candidates:
            zc = ms.zeta_c(u, zr)
            n_zc = _norm(zc)
            if self.B.shape[0] and bool((self.B @ zc > ALLOW_TOL * max(1.0, n_zc)).any()):
                last = DirectionTest(dr, u, zc, False, np.nan, "not allowable: a D-point would penetrate",
                                     self.exact)
                continue
            if self.sel.s_index:
                sl = self.slips_of(zc)
                small = np.sqrt((sl * sl).sum(axis=1)) <= SLIP_TOL * n_zc  # (#S,) |slip| as np.linalg.norm(axis=1)
                if small.any():
                    still = self.sel.s_index[int(np.flatnonzero(small)[0])]
                    last = DirectionTest(dr, u, zc, False, np.nan,
                                         f"S-point {still} does not slide for this motion", self.exact)
                    continue
                if planar:
                    friction = self._planar_friction(zc, sl)
                    key = friction[2]
                    if key in answered:
                        sup, f = answered[key]
                    else:
                        sup, f = self._work_sup(dr, zc, witness, friction, keep)
                        if not np.isnan(sup):  # an undecided LP is tried again (HiGHS' defaults) for the next
                            answered[key] = (sup, f)
                else:
                    sup, f = self._work_sup(dr, zc, witness, keep=keep)
            else:
                sup, f = self._work_sup(dr, zc, witness, keep=keep)
            if np.isnan(sup):
                last = DirectionTest(dr, u, zc, False, np.nan, "degenerate: the force LP is numerically undecided",
                                     False)
                continue
            if sup > work_tol:
                return DirectionTest(dr, u, zc, True, sup, "member", self.exact, f)
            why = ("the fingers cannot do positive work" if sup <= sc.work_zero(dr) else
                   "degenerate: the largest work is positive but below the tolerance "
                   f"({sup:.3g} <= {work_tol:.3g})")
            last = DirectionTest(dr, u, zc, False, sup, why, self.exact, f)
        assert last is not None
        return last

    def test_many(self, U: Array) -> list[DirectionTest]:
        """``[self.test(Lambda~_r @ u, witness=False) for u in U]`` for the unit coordinates ``U``
        ``(n, a_bar)``, each step of :meth:`test` done for all directions at once.

        The screen (:meth:`relaxed_positive`) and the force LP (:meth:`_work_sup`) are first
        answered for every direction from what earlier LPs left (the relaxation's maximisers, the
        certified vertices: :meth:`_vertex_sups`); where that does not decide, the LP of the first
        open direction is solved (as :meth:`test` would), which stores its vertex, and the open
        directions are tried again. Every shortcut gives the LP's own answer, so no answer depends
        on the order in which the LPs were solved. The directions are tested one by one where the
        slips depend on the redundancy (several candidate motions per direction, each from its own
        LPs: batching their first candidate, the friction-aligned one, from certified bases saved
        nothing on the planar scene), with S-points in 3-D (the force LP's rows depend on the exact
        slips there), and below :data:`BATCH_MIN` directions."""
        ms, sy, sel = self.ms, self.system, self.sel
        Lr = self._Lr  # (D, a_bar)
        U = np.asarray(U, dtype=float).reshape(-1, ms.a_bar)
        if U.shape[0] < BATCH_MIN or ms.a_bar == 0 or self.slip_depends_on_redundancy or (sel.s_index and self._d != 2):
            return [self.test(Lr @ u, witness=False) for u in U]
        sc = sy.scales
        out: list[DirectionTest | None] = [None] * U.shape[0]
        # the direction and its coordinates row by row, as test() computes them (a matrix product
        # rounds differently, and the refinement of dafc_set compares coordinates to 1e-12)
        LrT = Lr.T  # (a_bar, D)
        live: list[int] = []
        rows_u: list[Array] = []
        rows_dr: list[Array] = []
        DR0 = U @ LrT  # (n, D): only to find the directions outside the motion space (a 1e-6 test)
        res = DR0 @ Lr @ LrT - DR0  # (n, D)
        outside = np.sqrt((res * res).sum(axis=1)) > 0.5e-6 * np.maximum(1.0, np.sqrt((DR0 * DR0).sum(axis=1)))
        for k, u0 in enumerate(U):
            dr0 = Lr @ u0  # (D,)
            u1 = LrT @ dr0  # (a_bar,)
            nu = _norm(u1)
            if nu < 1e-12 or (outside[k] and _norm(Lr @ u1 - dr0) > 1e-6 * max(1.0, _norm(dr0))):
                out[k] = DirectionTest(dr0, u1, None, False, np.nan, "direction is outside the motion space", True)
                continue
            u = u1 / nu
            live.append(k)
            rows_u.append(u)
            rows_dr.append(Lr @ u)
        idx = np.array(live, dtype=int)  # (k,) the rows still open, by their index in U
        Uu = np.array(rows_u).reshape(-1, ms.a_bar)  # (k, a_bar)
        DR = np.array(rows_dr).reshape(-1, ms.D)  # (k, D)
        sizes = sc.motion_sizes(DR)  # (k,)
        is_open = np.ones(len(idx), bool)
        if sel.s_index:
            positive = self._screen_many(DR, sizes)
            for r in np.flatnonzero(~positive):
                out[idx[r]] = DirectionTest(DR[r], Uu[r], None, False, np.nan,
                                            "the fingers cannot do positive work, whatever the S-points' slip", True)
            is_open &= positive
        # the least-L1 redundancy (redundancy_for): zero where that is allowable, else its LP
        Z = np.zeros((len(idx), ms.n_redundant))  # (k, r)
        if self.B.shape[0]:
            size_u = np.maximum(1.0, np.sqrt((Uu * Uu).sum(axis=1)))  # (k,) max(1, |u|)
            tol_a = ALLOW_TOL * size_u  # (k,)
            need = np.flatnonzero(is_open & ~(Uu @ self._B_u.T <= tol_a[:, None]).all(axis=1))
            none = np.zeros(len(need), bool)  # no redundancy makes the motion allowable
            known = np.zeros(len(need), bool)
            nr = ms.n_redundant
            if nr == 0 or not self._B_r_any:
                none[:] = True
            elif need.size:
                b = -(Uu[need] @ self._B_u.T) + tol_a[need, None] / 2  # (k_n, #D) as redundancy_for's LP
                if self._farkas.shape[0]:
                    none = (b @ self._farkas.T).min(axis=1) < -FARKAS_MARGIN * size_u[need]
                if self._redundancy_bases is not None and not none.all():
                    X, known = self._redundancy_bases.solve_many(b)
                    known &= ~none
                    Z[need[known]] = X[known, :nr] - X[known, nr:]
            for q, r in enumerate(need):
                if none[q]:
                    z = None
                elif known[q]:
                    continue
                else:
                    z = self.redundancy_for(Uu[r])  # its LP (or a certificate harvested since)
                if z is None:
                    out[idx[r]] = DirectionTest(DR[r], Uu[r], None, False, np.nan,
                                                "not allowable: a D-point would penetrate", True)
                    is_open[r] = False
                else:
                    Z[r] = z
        ZC = np.hstack([Uu, Z])  # (k, a) the motion tested
        nzc = np.sqrt((ZC * ZC).sum(axis=1))  # (k,)
        if self.B.shape[0]:
            bz = ZC @ self.B.T  # (k, #D) the D-points' normal velocities
            pen = is_open & (bz > (ALLOW_TOL * np.maximum(1.0, nzc))[:, None]).any(axis=1)
            for r in np.flatnonzero(pen):
                out[idx[r]] = DirectionTest(DR[r], Uu[r], ZC[r], False, np.nan,
                                            "not allowable: a D-point would penetrate", self.exact)
            is_open &= ~pen
        rows = np.flatnonzero(is_open)
        groups: list[tuple[Array, tuple[Array, Array, bytes] | None]] = []  # (rows, the pattern's friction)
        if sel.s_index:
            nS = len(sel.s_index)
            SL = (ZC[rows] @ self.Ps.T).reshape(len(rows), nS, self._d)  # (k', #S, 2) slips
            small = np.sqrt((SL * SL).sum(axis=2)) <= SLIP_TOL * nzc[rows, None]  # (k', #S)
            still = small.any(axis=1)
            for r, q in zip(rows[still], small[still].argmax(axis=1), strict=True):
                out[idx[r]] = DirectionTest(DR[r], Uu[r], ZC[r], False, np.nan,
                                            f"S-point {sel.s_index[int(q)]} does not slide for this motion", self.exact)
            rows, SL = rows[~still], SL[~still]
            SIG = np.where((SL * self._T_s[None]).sum(axis=2) >= 0.0, 1.0, -1.0)  # (k'', #S) sign patterns
            pats, inv = np.unique(SIG, axis=0, return_inverse=True)
            for q, sig in enumerate(pats):
                groups.append((rows[inv.reshape(-1) == q], self._pattern_friction(np.ascontiguousarray(sig))))
        elif rows.size:
            groups.append((rows, None))
        for g_rows, friction in groups:
            G_eff = self.st.G_c if friction is None else friction[0]  # (D, L_c)
            key = b"" if friction is None else friction[2]
            if G_eff.shape[1] == 0:  # no contact carries force: only w_ex can do work
                for r in g_rows:
                    out[idx[r]] = self._verdict(DR[r], Uu[r], ZC[r], float(DR[r] @ sy.w_ex), np.zeros(0))
                continue
            C = DR[g_rows] @ G_eff  # (k_g, L_c) work per unit force
            pend = np.arange(len(g_rows))
            solved = False
            while pend.size:
                sup, j = self._vertex_sups(key, C[pend], DR[g_rows[pend]], sizes[g_rows[pend]])
                cache = self._vertices.get(key)
                for p, s, jj in zip(pend, sup, j, strict=True):
                    if jj != -2:
                        r = g_rows[p]
                        f = cache.X[jj] * sc.force if jj >= 0 and cache is not None else None
                        out[idx[r]] = self._verdict(DR[r], Uu[r], ZC[r], float(s), f)
                if solved and bool((j == -2).all()):
                    # the last LP's vertex certified no other direction (as in 3-D, where the optima
                    # rarely recur): the rest one by one, each with its own vertex check first
                    for p in pend:
                        r = g_rows[p]
                        s, f = self._work_sup(DR[r], ZC[r], False, friction)
                        out[idx[r]] = self._verdict(DR[r], Uu[r], ZC[r], s, f)
                    break
                pend = pend[j == -2]
                if pend.size:  # the LP of the first open direction (it keeps its optimal vertex)
                    r = g_rows[pend[0]]
                    s, f = self._work_sup(DR[r], ZC[r], False, friction)
                    out[idx[r]] = self._verdict(DR[r], Uu[r], ZC[r], s, f)
                    pend = pend[1:]
                    solved = True
        assert all(t is not None for t in out)
        return [t for t in out if t is not None]

    def _screen_many(self, DR: Array, sizes: Array) -> Array:
        """:meth:`relaxed_positive` of each row of ``DR`` ``(k, D)`` (motion sizes ``sizes``):
        ``(k,)`` bool. The stored maximisers and certified vertices answer at once; the relaxed LP
        of the first open row adds a maximiser and a vertex, and the others are tried again."""
        sy = self.system
        sc = sy.scales
        tol = WORK_TOL * sc.force * sizes  # (k,) work_tol
        positive = np.zeros(DR.shape[0], bool)
        pend = np.arange(DR.shape[0])
        solved = False  # an LP was solved since the first pass
        while pend.size:
            D_p = DR[pend]  # (k', D)
            done = np.zeros(len(pend), bool)
            if self._relaxed_W.shape[1]:
                lower = (D_p @ self._relaxed_W).max(axis=1) * sc.force + D_p @ sy.w_ex  # (k',)
                done = lower > tol[pend] + RELAXED_MARGIN * sc.force * sizes[pend]
                positive[pend[done]] = True
            rest = np.flatnonzero(~done)
            sup, j = self._vertex_sups(_RELAXED_KEY, D_p[rest] @ self._G_relaxed, D_p[rest], sizes[pend[rest]])
            known = rest[j != -2]
            positive[pend[known]] = sup[j != -2] > tol[pend[known]]
            done[known] = True
            if solved and not done.any():  # the last LP decided no other direction: one by one
                for r in pend:
                    positive[r] = self.relaxed_positive(DR[r])
                break
            pend = pend[~done]
            if pend.size:
                positive[pend[0]] = self.relaxed_positive(DR[pend[0]])
                pend = pend[1:]
                solved = True
        return positive

    def _verdict(self, dr: Array, u: Array, zc: Array, sup: float, f: Array | None) -> DirectionTest:
        """:meth:`test`'s answer for the motion ``zc`` whose force LP gave the supremum ``sup``."""
        sc = self.system.scales
        if np.isnan(sup):
            return DirectionTest(dr, u, zc, False, np.nan, "degenerate: the force LP is numerically undecided", False)
        size = sc.motion_size(dr)
        work_tol = WORK_TOL * sc.force * size  # sc.work_tol(dr), the same product
        if sup > work_tol:
            return DirectionTest(dr, u, zc, True, sup, "member", self.exact, f)
        why = ("the fingers cannot do positive work" if sup <= WORK_ZERO * sc.force * size else
               "degenerate: the largest work is positive but below the tolerance "
               f"({sup:.3g} <= {work_tol:.3g})")
        return DirectionTest(dr, u, zc, False, sup, why, self.exact, f)

    def _aligned_allowable(self, u: Array, base: Array, Pr: Array, target: Array, scale: float) -> Array | None:
        """The allowable redundancy whose slips come closest (L1) to the friction-aligned ones
        ``scale * target / |target|``: ``min sum e`` s.t. ``|base + Pr z - slip*| <= e``,
        ``B [u; z] <= 0`` (an LP, so the answer does not depend on the basis of the redundancy
        and a mirrored scene gets the mirrored motion)."""
        tn = float(np.linalg.norm(target))
        nr, k = Pr.shape[1], Pr.shape[0]
        if tn < 1e-12 or nr == 0:
            return None
        goal = scale * target / tn - base  # (d #S,)
        a_bar = self.ms.a_bar
        B_u, B_r = self.B[:, :a_bar], self.B[:, a_bar:]
        tol = ALLOW_TOL * max(1.0, float(np.linalg.norm(u)))
        b_ub = np.concatenate([goal, -goal, -(B_u @ u) + tol])
        cost = np.concatenate([np.zeros(nr), np.ones(k)])
        if self._aligned_bases is None:
            # the rows depend on the combination only: one model per oracle, only b_ub changes
            I = np.eye(k)
            A_ub = np.vstack([np.hstack([Pr, -I]), np.hstack([-Pr, -I]),
                              np.hstack([B_r, np.zeros((B_r.shape[0], k))])])  # (2 k + #D, r + k)
            self._aligned_bases = _RhsBases(cost, A_ub, np.r_[np.full(nr, -np.inf), np.zeros(k)],
                                            np.full(nr + k, np.inf))
        x = self._aligned_bases.solve(b_ub)  # the LP's unique optimum from a certified basis
        if x is not None:
            return x[:nr]
        if self._aligned is None:
            bb = self._aligned_bases
            self._aligned = LPModel(nr + k, A_ub=bb.Abar[:bb.m], b_ub=b_ub, lb=np.r_[np.full(nr, -np.inf), np.zeros(k)])
        else:
            self._aligned.set_ub_rhs(b_ub)
        try:
            # solved cold: the redundancy chosen for a direction does not depend on earlier ones
            res = self._aligned.solve_cold(cost)
        except SolverError:
            self._aligned = None  # leave no half-solved model for the next direction
            return None  # one candidate fewer; the others are still tried
        self.lp_count += 1
        if res.x is None:
            return None
        self._aligned_bases.harvest(res)
        return res.x[:nr]

    def _seeded_noise(self, count: int) -> list[Array]:
        """The first ``count`` draws ``np.random.default_rng(0).standard_normal(r)`` (the same for
        every direction: kept instead of seeding a generator per test)."""
        if len(self._noise) < count:
            rng = np.random.default_rng(0)
            self._noise = [rng.standard_normal(self.ms.n_redundant) for _ in range(count)]
        return self._noise[:count]

    def _alternative_redundancies(self, u: Array, z0: Array, count: int = 4) -> list[Array]:
        """Every alternative of :meth:`_iter_alternatives`, as a list."""
        return list(self._iter_alternatives(u, z0, count))

    def _iter_alternatives(self, u: Array, z0: Array, count: int = 4) -> Iterator[Array]:
        """Alternatives to the least-L1 redundancy that stay allowable, computed as they are asked
        for (a member found with the first needs none of the others; the order is the same).

        First the allowable redundancy closest to friction-aligned slips (slip of the object
        relative to the finger opposite to the object point's tangential velocity, so kinetic
        friction drags the object along its motion, eq. 11; an LP), then the friction-aligned
        redundancy and its opposite by least squares, then seeded random ones.
        """
        ms, sy, sel = self.ms, self.system, self.sel
        a_bar, d = ms.a_bar, self._d
        dr = ms.Lambda_r_t @ u
        base = self.Ps[:, :a_bar] @ u  # (d #S,) slip with zero redundancy
        Pr = self.Ps[:, a_bar:]  # (d #S, r)
        target = np.zeros_like(base)
        for k, i in enumerate(sel.s_index):
            v = sy.G_blocks[i].T @ dr  # object point velocity
            n = sy.normals[i]
            vt = v - (v @ n) * n
            target[k * d : (k + 1) * d] = -vt
        scale = max(1.0, float(np.linalg.norm(ms.Lambda_q_t @ u)))

        def cands() -> Iterator[Array]:
            aligned = self._aligned_allowable(u, base, Pr, target, scale)
            if aligned is not None:
                yield aligned
            for sign in (1.0, -1.0):
                tn = float(np.linalg.norm(target))
                if tn < 1e-12:
                    break
                z, *_ = np.linalg.lstsq(Pr, sign * scale * target / tn - base, rcond=None)
                yield z
            for noise in self._seeded_noise(count):
                yield z0 + scale * noise

        for z in cands():
            zc = ms.zeta_c(u, z)
            if not self.B.shape[0] or np.all(self.B @ zc <= ALLOW_TOL * max(1.0, float(np.linalg.norm(zc)))):
                yield z


def _first_then(rest: Iterator[Array], second: Array) -> Iterator[Array]:
    """The first item of ``rest``, then ``second``, then the remaining items of ``rest``."""
    first = next(rest, None)
    if first is not None:
        yield first
    yield second
    yield from rest


def _norm(v: Array) -> float:
    """``float(np.linalg.norm(v))`` of a real vector (the same ``sqrt(v . v)``), without its overhead."""
    return math.sqrt(float(v @ v))


# ------------------------------------------------------------------------------------------------
# A complete search over the S-points' slip directions, for one object direction

#: Slip-sector search (:func:`slip_sector_search`): sector boxes examined per direction at most,
#: and the smallest sector half-width (radians, 3-D) refined before a box counts as undecided.
SECTOR_BUDGET = 400
SECTOR_MIN_HALF = np.pi / 128
#: Bound of the redundancy coordinates in the sector LPs, relative to the motion's size.
SECTOR_ZMAX = 1e2
#: Sides of the polygon circumscribing a free S-point's friction disc (3-D).
SECTOR_FREE_SIDES = 8
#: :func:`_tighten`: a generator's slip (tangent coordinates, unit generator) at or below this is
#: zero when a sector is narrowed to the slips of its box's cone (rounding: a slip that vanishes
#: in exact arithmetic comes out near 1e-16), and the angle (radians) by which a narrowed sector is
#: widened on each side (far above the rounding of the generators' angles). With 1e-10 instead
#: the wrap's table is the same; with exactly 0 its searches leave no box open either, at twice
#: the LPs.
SECTOR_ZERO_SLIP = 1e-14
SECTOR_WIDEN = 1e-6

Sector = tuple[float, float] | None  # an interval of slip angles in the tangent basis; None = any


@dataclass(frozen=True)
class SectorSearch:
    """The answer of :func:`slip_sector_search` for one object direction."""

    test: DirectionTest | None  # a member (motion, forces), or None
    boxes: int  # sector boxes examined
    open_boxes: int  # boxes neither pruned nor refined further (budget, resolution); 0 = decided
    bound: float  # the largest upper bound of the work over the open boxes (-inf when none)
    dim: int = 0  # rank of the object parts of the member's box cone (the member lies inside it)

    @property
    def decided(self) -> bool:
        return self.test is not None or self.open_boxes == 0


def unit_angle(theta: float, d: int) -> Array:
    """Unit slip direction at angle ``theta`` in tangent coordinates ``(d - 1,)``."""
    return np.array([np.cos(theta)]) if d == 2 else np.array([np.cos(theta), np.sin(theta)])


def sector_half(sec: Sector) -> float:
    return np.pi if sec is None else 0.5 * (sec[1] - sec[0])


def split_sector(sec: Sector, d: int) -> list[Sector]:
    """Children of a sector: a free point becomes the two signs (2-D) or four quarter turns (3-D)
    centred on the tangent axes; an interval is halved."""
    if sec is None:
        if d == 2:
            return [(0.0, 0.0), (np.pi, np.pi)]
        return [(q * np.pi / 2 - np.pi / 4, q * np.pi / 2 + np.pi / 4) for q in range(4)]
    a, b = sec
    m = 0.5 * (a + b)
    return [(a, m), (m, b)]


def sector_rows(sec: Sector, d: int, margin: float) -> tuple[Array, Array]:
    """Rows ``R sigma >= r`` (tangent coordinates) putting the slip ``sigma`` in the sector, at
    least ``margin`` along its bisector (so the point really slides); none for a free point."""
    if sec is None:
        return np.zeros((0, d - 1)), np.zeros(0)
    a, b = sec
    c = unit_angle(0.5 * (a + b), d)
    rows, rhs = [c], [margin]
    if d == 3 and b > a:
        rows += [np.array([-np.sin(a), np.cos(a)]), np.array([np.sin(b), -np.cos(b)])]
        rhs += [0.0, 0.0]
    return np.array(rows), np.array(rhs)


@functools.cache
def _free_dirs(d: int) -> Array:
    """Outward normals ``(k, d-1)`` (tangent coordinates) of the sides of the polygon that
    circumscribes a free S-point's friction disc in :func:`_relaxed_box_model`: the two signs in
    2-D, :data:`SECTOR_FREE_SIDES` directions in 3-D (read-only)."""
    if d == 2:
        out = np.array([[1.0], [-1.0]])
    else:
        ang = 2 * np.pi * np.arange(SECTOR_FREE_SIDES) / SECTOR_FREE_SIDES
        out = np.array([unit_angle(t, 3) for t in ang])
    out.setflags(write=False)
    return out


def _relaxed_box_model(oracle: DAFCOracle, fixed_G: Array, dep: list[int], box: tuple[Sector, ...]
                       ) -> tuple[LPModel, Array, list[tuple[int, ...]]]:
    """The LP of :func:`_relaxed_box_lp` for the sector ``box``: (model, ``G`` ``(D, n)``, the
    friction unknowns of each dependent point). Its rows do not depend on the object direction.

    Unknowns ``[f_c; friction of the dependent S-points]`` in units of the force scale. The
    friction ``t = -mu n s/|s|`` of a dependent S-point with slip angle in ``[a, b]`` (half-width
    ``h``) is ``-(alpha_a e(a) + alpha_b e(b))`` with ``alpha >= 0`` and
    ``mu n <= alpha_a + alpha_b <= mu n / cos h`` (the band between the arc's chord and its
    tangent at the bisector, exact as ``h -> 0``); a sign in 2-D is exact; a free point has any
    tangential friction inside a circumscribed polygon of ``mu n``. ``fixed_G`` ``(D, L_c)`` is
    ``G_c`` plus the kinetic friction of the S-points whose slip does not depend on the
    redundancy."""
    sy, sel, st, fs = oracle.system, oracle.sel, oracle.st, oracle.fs
    d, L_c = sy.d, st.G_c.shape[1]
    cols: list[Array] = []  # (D,) per friction unknown
    # rows over [f_c; t] <= 0: (their non-zero columns, their values (k, #columns)), in row order
    rows: list[tuple[list[int], Array]] = []
    slots: list[tuple[int, ...]] = []
    free_dirs = _free_dirs(d)  # (k, d-1) outward normals of the circumscribed polygon's sides
    for k, sec in zip(dep, box, strict=True):
        i = sel.s_index[k]
        T = sy.tangents[i]  # (d-1, d)
        n_col = sel.c_slices[i].start
        mu = float(sy.mu[i])
        first = L_c + len(cols)
        h = sector_half(sec)
        if sec is None:
            r_mu = mu  # sides at distance mu n: the k-gon circumscribing the disc
            for j in range(d - 1):
                cols.append(sy.G_blocks[i] @ T[j])
            vals = np.empty((free_dirs.shape[0], d))
            vals[:, : d - 1] = free_dirs
            vals[:, d - 1] = -r_mu
            rows.append(([*range(first, first + d - 1), n_col], vals))
            slots.append(tuple(range(first, first + d - 1)))
        elif h <= 0.0:
            e = T.T @ unit_angle(sec[0], d)  # (d,) world slip direction
            fixed_G = fixed_G.copy()
            fixed_G[:, n_col] = fixed_G[:, n_col] - mu * (sy.G_blocks[i] @ e)
            slots.append(())
        else:
            for th in sec:
                cols.append(-(sy.G_blocks[i] @ (T.T @ unit_angle(th, d))))
            rows.append(([first, first + 1, n_col], np.array([[-1.0, -1.0, mu], [1.0, 1.0, -mu / np.cos(h)]])))
            slots.append((first, first + 1))
    n_t = len(cols)
    n = L_c + n_t
    G = np.hstack([fixed_G, np.array(cols).T.reshape(sy.D, n_t)])  # (D, n)
    m_C = fs.C.shape[0]
    A_ub = np.zeros((m_C + 1 + sum(v.shape[0] for _, v in rows), n))
    A_ub[:m_C, :L_c] = fs.C
    A_ub[m_C, :L_c] = fs.N.sum(axis=0)
    b_ub = np.zeros(A_ub.shape[0])
    b_ub[m_C] = GRIP_BOUND
    r = m_C + 1
    for where, vals in rows:
        A_ub[r : r + vals.shape[0], where] = vals
        r += vals.shape[0]
    lb = np.r_[np.full(L_c, -np.inf), [0.0 if sector_half(sec) < np.pi else -np.inf
                                         for sec, sl in zip(box, slots, strict=True) for _ in sl]]
    model = LPModel(n, A_ub=A_ub, b_ub=b_ub, A_eq=snap(oracle.Xi.T @ G),
                    b_eq=snap(-(oracle.Xi.T @ sy.w_ex) / sy.scales.force), lb=lb, feasibility=LP_FEAS_TOL)
    return model, G, slots


#: :func:`_relaxed_box_lp`: the least multiplier (relative to the objective) of an active
#: inequality row by which an earlier optimum of the box's LP is certified the unique optimum for
#: another direction (:func:`_box_vertex`).
BOX_DUAL_MIN = 1e-7


def _keep_box_vertex(store: dict[str, object], model: LPModel, x: Array) -> None:
    """Keep the optimum ``x`` of the box's LP (units of the force scale) with its active rows, for
    other objectives (:func:`_box_vertex`): the inequality rows and finite lower bounds within
    :data:`VERTEX_ACTIVE_TOL` of their bound ``A_in`` ``(k, n)`` (a lower bound as ``-x_j <=
    -lb_j``) and the equality rows ``A_eq``. Not kept when there are fewer of them than unknowns
    (not a vertex; the rank is checked where it is used) or the point is known already."""
    X = store.get("X")
    if isinstance(X, np.ndarray) and (X.shape[0] >= VERTEX_POINTS
                                      or bool(np.any(np.all(np.abs(X - x) <= 1e-12, axis=1)))):
        return
    n = model.n
    slack = model.b_ub - model.A_ub @ x  # (m_ub,)
    active = slack <= VERTEX_ACTIVE_TOL * np.maximum(1.0, np.abs(model.b_ub))
    lo = np.isfinite(model.lb)
    lb0 = np.where(lo, model.lb, 0.0)  # (n,)
    at_lb = np.flatnonzero(lo & (x - lb0 <= VERTEX_ACTIVE_TOL * np.maximum(1.0, np.abs(lb0))))
    bound_rows = np.zeros((len(at_lb), n))
    bound_rows[np.arange(len(at_lb)), at_lb] = -1.0
    A_in = np.vstack([model.A_ub[active], bound_rows])  # (k, n)
    A_eq = model.A_eq  # (p, n)
    if n == 0 or A_in.shape[0] + A_eq.shape[0] < n:
        return  # fewer active rows than unknowns: not a vertex
    entry = (A_in, A_eq, np.ascontiguousarray(np.vstack([A_in, A_eq, -A_eq]).T))  # last: (n, k + 2 p)
    if isinstance(X, np.ndarray):
        store["X"] = np.vstack([X, x[None, :]])
        certs = store["certs"]
        assert isinstance(certs, list)
        certs.append(entry)
    else:
        store["X"], store["certs"] = x[None, :].copy(), [entry]


def _box_vertex(store: dict[str, object], c: Array) -> Array | None:
    """An earlier optimum of the box's LP that is the unique maximiser of ``c^T x``, or None.

    The LP's rows do not depend on the objective (:func:`_relaxed_box_model`), so every earlier
    optimum ``x`` is feasible. Only the one of largest ``c^T x`` can be optimal. It is when
    multipliers ``y_in >= 0`` of its active inequality rows and ``y_eq`` of the equality rows give
    ``A_in^T y_in + A_eq^T y_eq = c`` (non-negative least squares, residual within
    :data:`VERTEX_DUAL_TOL` ``max(1, |c|)``): then ``c^T x' <= y_in^T b_in + y_eq^T b_eq = c^T x``
    for every feasible ``x'`` (LP duality). It is the only optimum when the rows with ``y_i``
    above :data:`BOX_DUAL_MIN` ``max(1, |c|)`` and the equality rows have full column rank: an
    optimum ``x'`` meets each row with ``y_i > 0`` with equality (else ``c^T x' < c^T x``), and
    those equations determine ``x' = x``. A vertex that is degenerate (more active rows than
    unknowns, as at a contact carrying no force) is certified as well. An LP solved from scratch
    returns that same point (to rounding), so the search does not depend on whether it was solved."""
    X = store.get("X")
    if not isinstance(X, np.ndarray):
        return None
    certs = store["certs"]
    assert isinstance(certs, list)
    j = int((X @ c).argmax())
    A_in, A_eq, M = certs[j]
    scale = max(1.0, float(np.abs(c).max()) if c.size else 0.0)
    try:
        y, resid = nnls(M, c)
    except RuntimeError:  # no convergence: the LP decides
        return None
    if resid > VERTEX_DUAL_TOL * scale:
        return None
    rows = np.vstack([A_in[y[:A_in.shape[0]] > BOX_DUAL_MIN * scale], A_eq])
    if rows.shape[0] < A_in.shape[1] or rank(rows) < A_in.shape[1]:
        return None
    return np.asarray(X[j])


def _relaxed_box_lp(oracle: DAFCOracle, dr: Array, fixed_G: Array, dep: list[int], box: tuple[Sector, ...],
                    store: dict[str, object] | None = None) -> tuple[float, list[Array]]:
    """Upper bound of the work of (22) over every motion whose slips lie in the sector ``box``
    (the LP of :func:`_relaxed_box_model`, maximising ``dr^T G x``).

    ``store``: a dict the caller keeps for one box (same ``fixed_G``, ``dep``, ``box``); its model
    is built on the first call and re-solved from scratch (no warm start, so the maximiser does
    not depend on the order of the directions) on later ones, unless an earlier optimum is
    certified the unique maximiser for ``dr`` (:func:`_box_vertex`; not used where the bound is
    within :data:`RELAXED_MARGIN` x the force scale per unit motion of the work threshold, so a
    box is pruned on an LP's answer there). Returns the bound and the friction directions of a
    maximiser (tangent coordinates, per dependent point; empty when the box admits no forces)."""
    sy, d = oracle.system, oracle.system.d
    sc = sy.scales
    x: Array | None = None
    if store is not None and "model" in store:
        model, G, slots = store["model"], store["G"], store["slots"]
        assert isinstance(model, LPModel) and isinstance(G, np.ndarray) and isinstance(slots, list)
        c = G.T @ dr  # (n,)
        known = _box_vertex(store, c)
        if known is not None:
            sup = float(c @ known) * sc.force + float(dr @ sy.w_ex)
            size = sc.motion_size(dr)
            if abs(sup - WORK_TOL * sc.force * size) > RELAXED_MARGIN * sc.force * size:
                x, objective = known, float(c @ known)
                oracle.box_vertex_hits += 1
        if x is None:
            res = model.solve_cold(c, maximize=True)
    else:
        model, G, slots = _relaxed_box_model(oracle, fixed_G, dep, box)
        if store is not None:
            store.update(model=model, G=G, slots=slots)
        res = model.solve(G.T @ dr, maximize=True)
    if x is None:
        oracle.lp_count += 1
        if res.status == "infeasible":
            return -np.inf, []
        if res.status != "optimal":  # the grip bound bounds every force
            raise SolverError("HiGHS", f"slip-sector LP ended '{res.status}' although its forces are bounded")
        assert res.objective is not None and res.x is not None
        x, objective = res.x, res.objective
        if store is not None:
            _keep_box_vertex(store, model, x)
    targets: list[Array] = []
    for sec, sl in zip(box, slots, strict=True):
        if sec is None:
            t = x[list(sl)]  # friction in tangent coordinates; the slip opposes it
            targets.append(-t if _norm(t) > 1e-12 else np.zeros(d - 1))
        elif not sl:
            targets.append(unit_angle(sec[0], d))
        else:
            targets.append(x[sl[0]] * unit_angle(sec[0], d) + x[sl[1]] * unit_angle(sec[1], d))
    return float(objective * sc.force + dr @ sy.w_ex), targets


def _box_motion(oracle: DAFCOracle, u: Array, dep: list[int], box: tuple[Sector, ...], targets: list[Array],
                store: dict[str, object] | None = None) -> Array | None:
    """An allowable redundancy whose dependent slips lie in the sector ``box`` and come closest
    (L1, tangent coordinates) to the directions ``targets``, or None when no allowable motion has
    its slips in the box (an LP).

    The LP's matrix depends on the box only (the object direction ``u`` and the targets enter its
    right-hand side and the bounds of ``z``): ``store``, a dict the caller keeps for one box (same
    ``dep``, ``box``), holds the model for its later calls, which change those and solve from
    scratch: the optimum of a new model, to rounding (HiGHS keeps some state of a model across a
    cold start, so the last bits of the point may differ; test_solvers checks it)."""
    ms, sy, sel = oracle.ms, oracle.system, oracle.sel
    a_bar, nr, d = ms.a_bar, ms.n_redundant, sy.d
    scale = max(1.0, _norm(ms.Lambda_q_t @ u))
    zmax = SECTOR_ZMAX * scale
    margin = 2.0 * SLIP_TOL * (1.0 + zmax * np.sqrt(nr))
    k_dev = (d - 1) * len(dep)
    n = nr + k_dev
    B_u, B_r = oracle.B[:, :a_bar], oracle.B[:, a_bar:]
    kept = store.get("motion") if store is not None else None
    build = not isinstance(kept, LPModel)
    A: list[Array] = []  # rows over [z; deviations] (n,), built only with the model
    b: list[float] = []

    def row(z_part: Array, dev: int | None = None, sign: float = 0.0) -> None:
        """Append ``[z_part, sign e_dev]`` ``(n,)`` to the rows (when the model is built)."""
        if build:
            out = np.zeros(n)
            out[:nr] = z_part
            if dev is not None:
                out[nr + dev] = sign
            A.append(out)

    for r in range(B_r.shape[0]):
        row(B_r[r])
        b.append(float(-(B_u[r] @ u)) + 0.5 * ALLOW_TOL)
    for q, (k, sec, g) in enumerate(zip(dep, box, targets, strict=True)):
        T = sy.tangents[sel.s_index[k]]
        rows = slice(k * d, (k + 1) * d)
        S_z = T @ oracle.Ps[rows, a_bar:]  # (d-1, nr): sigma = S_0 + S_z z
        S_0 = T @ (oracle.Ps[rows, :a_bar] @ u)  # (d-1,)
        R, rhs = sector_rows(sec, d, margin)
        for rr, v in zip(R, rhs, strict=True):
            row(-(rr @ S_z))
            b.append(float(rr @ S_0 - v))
        gn = _norm(g)
        goal = scale * g / gn if gn > 1e-12 else np.zeros(d - 1)
        for j in range(d - 1):
            row(S_z[j], q * (d - 1) + j, -1.0)
            b.append(float(goal[j] - S_0[j]))
            row(-S_z[j], q * (d - 1) + j, -1.0)
            b.append(float(S_0[j] - goal[j]))
    lb, ub = np.zeros(n), np.full(n, np.inf)  # (n,): |z| <= zmax, deviations >= 0
    lb[:nr], ub[:nr] = -zmax, zmax
    cost = np.zeros(n)
    cost[nr:] = 1.0
    if isinstance(kept, LPModel):
        model = kept
        model.set_ub_rhs(np.array(b))
        model.set_bounds(lb, ub)
    else:
        model = LPModel(n, A_ub=np.array(A).reshape(-1, n), b_ub=np.array(b), lb=lb, ub=ub)
        if store is not None:
            store["motion"] = model
    try:
        res = model.solve_cold(cost)
    except SolverError:
        oracle.undecided += 1
        if store is not None:
            store.pop("motion", None)  # no half-solved model for the next call
        return None
    oracle.lp_count += 1
    if res.status != "optimal" or res.x is None:
        return None
    return np.asarray(res.x[:nr])


def _box_cone(oracle: DAFCOracle, box: tuple[Sector, ...]) -> Array:
    """Generators ``(k, a)`` (unit rows, both signs of lines) of the cone of allowable motions
    ``dzeta_c`` whose S-point slips lie in the sector ``box`` (edges included): ``B dzeta_c <= 0``
    (eq. 20) and the sector rows of :func:`sector_rows` on ``T_k P_s dzeta_c`` (cdd)."""
    ms, sy, sel = oracle.ms, oracle.system, oracle.sel
    d = sy.d
    rows = [oracle.B] if oracle.B.shape[0] else []
    for k, sec in enumerate(box):
        T = sy.tangents[sel.s_index[k]]
        R, _ = sector_rows(sec, d, 0.0)
        if R.shape[0]:
            rows.append(-(R @ T @ oracle.Ps[k * d:(k + 1) * d]))  # R sigma >= 0
    if not rows:
        return np.vstack([np.eye(ms.a), -np.eye(ms.a)])
    return cone_generators(np.vstack(rows)).all_directions()


def _slip_maps(oracle: DAFCOracle) -> tuple[Array, Array]:
    """The slip of each S-point per unit motion ``dzeta_c`` (eq. 21): ``P_k`` ``(#S, d, a)`` and
    in its tangent coordinates ``T_k P_k`` ``(#S, d-1, a)``."""
    sy, sel, d, a = oracle.system, oracle.sel, oracle.system.d, oracle.ms.a
    nS = len(sel.s_index)
    P = oracle.Ps.reshape(nS, d, a)
    return P, np.array([sy.tangents[i] @ P[k] for k, i in enumerate(sel.s_index)]).reshape(nS, d - 1, a)


def _tighten(P: Array, S: Array, box: tuple[Sector, ...], Z: Array) -> tuple[Sector, ...] | None:
    """The sectors of ``box`` narrowed to the slips its cone ``K`` really has, or None when some
    S-point slides for no motion of ``K``.

    ``Z`` ``(k, a)`` generates ``K`` (unit rows, both signs of lines); ``P`` ``(#S, d, a)`` and ``S``
    ``(#S, d-1, a)`` map a motion to the slips (:func:`_slip_maps`). The slips of an S-point over
    ``K`` form the cone generated by its slips at the generators, ``Y = Z S_k^T``:

    * every motion ``dzeta_c`` of ``K`` lies in the row space of ``Z``, so
      ``dzeta_c = Z^T lambda`` with ``|lambda| <= |dzeta_c| / s_min`` (``s_min`` the least non-zero
      singular value of ``Z``) and its slip ``(Z P_k^T)^T lambda`` is at most
      ``|Z P_k^T|_F / s_min`` times ``|dzeta_c|``. At or below :data:`SLIP_TOL` no motion of ``K``
      makes the point slide as a member must (:meth:`DAFCOracle.test`): the box holds no member;
    * in 3-D, when the generators' non-zero slips (above :data:`SECTOR_ZERO_SLIP`) span an arc of
      half-width below the sector's (below pi/4 for a free point), the sector becomes that arc,
      widened by :data:`SECTOR_WIDEN` on each side (and kept inside the old sector). The friction
      of every motion of ``K`` is still inside the box's relaxed force set (:func:`_relaxed_box_lp`),
      whose band is now tighter: exact where the slips lie on one ray (an S-point on a fixed body
      when the object direction is fixed, ``a~ = 1``), and such a sector is never split again.
      The generators counted as zero contribute at most :data:`SECTOR_ZERO_SLIP` per unit weight,
      so a motion whose slip leaves the widened arc slides by less than
      ``SECTOR_ZERO_SLIP / sin(SECTOR_WIDEN)`` (1e-8) times its total weight on those generators:
      below the member test's :data:`SLIP_TOL` unless that weight exceeds ten times the motion's
      size (generators cancelling each other); such motions are not searched.
    """
    d = S.shape[1] + 1
    sv = np.linalg.svd(Z, compute_uv=False)  # (min(k, a),)
    s_min = float(sv[sv > 1e-12 * sv[0]].min()) if sv.size and sv[0] > 0.0 else 0.0
    out = list(box)
    for k, sec in enumerate(box):
        W = Z @ P[k].T  # (k, d) slips at the generators (world frame, as the member test measures them)
        if s_min > 0.0 and float(np.sqrt((W * W).sum())) <= SLIP_TOL * s_min:
            return None
        if d != 3:
            continue
        Y = Z @ S[k].T  # (k, d-1) in tangent coordinates
        big = np.sqrt((Y * Y).sum(axis=1)) > SECTOR_ZERO_SLIP
        if not big.any():
            continue
        theta = np.arctan2(Y[big, 1], Y[big, 0])  # (k',)
        if sec is None:
            t = np.sort(np.mod(theta, 2 * np.pi))
            gaps = np.diff(np.r_[t, t[0] + 2 * np.pi])  # gap after each angle
            g = int(gaps.argmax())
            lo = float(t[(g + 1) % len(t)])
            hi = lo + 2 * np.pi - float(gaps[g])
            if 0.5 * (hi - lo) + SECTOR_WIDEN <= np.pi / 4:
                out[k] = (lo - SECTOR_WIDEN, hi + SECTOR_WIDEN)
            continue
        a, b = sec
        if b <= a:
            continue  # a fixed sign or direction already
        m = 0.5 * (a + b)
        phi = np.mod(theta - m + np.pi, 2 * np.pi) - np.pi  # (k',) angle from the bisector
        lo, hi = max(a, m + float(phi.min()) - SECTOR_WIDEN), min(b, m + float(phi.max()) + SECTOR_WIDEN)
        if lo < hi and (lo > a or hi < b):
            out[k] = (lo, hi)
    return tuple(out)


def slip_sector_search(oracle: DAFCOracle, budget: int = SECTOR_BUDGET) -> SectorSearch:
    """Is DAFC (22) non-empty, for some object direction and finger redundancy? A branch and
    bound over the slip directions of the S-points, on the whole allowable cone.

    A sector box confines the slip of every S-point to an interval of angles in its tangent plane
    (a sign in 2-D; "free" at the root). The allowable motions ``dzeta_c`` with slips in the box
    form a polyhedral cone ``K`` (:func:`_box_cone`, generators ``g_j``), and every admissible
    force of such a motion lies in the box's relaxed force set (:func:`_relaxed_box_lp`), which
    does not depend on the motion. The work ``dr^T w`` is linear in ``dr`` for a fixed force, so
    if no relaxed force does positive work along any generator's object part, no motion of ``K``
    is a member: the box is pruned (the argument of :class:`DAFCSet` with the friction fixed to
    the box). Before that, a box in which some S-point slides for no motion of ``K`` is dropped,
    and each sector is narrowed to the slips ``K`` really has (:func:`_tighten`): an S-point whose
    slip lies on one ray over ``K`` (on a fixed body with the object direction fixed) gets its
    friction direction to within :data:`SECTOR_WIDEN` and is not split further. Otherwise the
    centroid of ``K`` and points just inside ``K`` next to the generators with the largest bound
    are tested exactly; a member ends the search; else the widest sector is
    split (a free point first into signs or quarter turns), best bound first. In 2-D the leaves
    fix every friction direction, so the bound is exact there and the search is a complete
    decision; in 3-D it is complete down to the half-width ``SECTOR_MIN_HALF``. A box left open
    there (or past the budget, or whose cone cdd cannot enumerate) is reported as open, never as
    empty.
    """
    ms, sy = oracle.ms, oracle.system
    a_bar, d = ms.a_bar, sy.d
    nS = len(oracle.sel.s_index)
    for k in range(nS):  # an S-point whose slip is zero for every motion never slides
        if float(np.abs(oracle.Ps[k * d:(k + 1) * d]).max(initial=0.0)) <= 1e-9:
            return SectorSearch(None, 0, 0, -np.inf)
    G0 = oracle.st.G_c
    P_slip, S_slip = _slip_maps(oracle)  # (#S, d, a), (#S, d-1, a)
    heap: list[tuple[float, int, tuple[Sector, ...]]] = []
    counter = boxes = open_boxes = 0
    open_bound = -np.inf
    pending: list[tuple[Sector, ...]] = [tuple(None for _ in range(nS))]
    leaf_half = 0.0 if d == 2 else SECTOR_MIN_HALF
    while pending or heap:
        if not pending:
            neg, _, box = heapq.heappop(heap)
            if boxes >= budget:
                open_boxes += 1
                open_bound = max(open_bound, -neg)
                continue
            widest = max(range(nS), key=lambda q: sector_half(box[q]))
            pending.extend((*box[:widest], child, *box[widest + 1:]) for child in split_sector(box[widest], d))
            continue
        box = pending.pop()
        boxes += 1
        try:
            Z = _box_cone(oracle, box)  # (k, a)
        except SolverError:
            open_boxes += 1  # cdd could not enumerate this box's cone: left open, never called empty
            continue
        tight = _tighten(P_slip, S_slip, box, Z)
        if tight is None:
            continue  # some S-point slides for no motion of this box: no member here
        box = tight
        U = Z[:, :a_bar]
        moving = np.linalg.norm(U, axis=1) > 1e-9
        if not moving.any():
            continue  # no motion with these slips moves the object
        Z, U = Z[moving], U[moving]
        bounds = np.full(len(U), -np.inf)
        targets: list[list[Array]] = []
        store: dict[str, object] = {}  # the box's relaxed LP and motion LP, built once for all its directions
        try:
            for j, u in enumerate(U):
                dr = ms.Lambda_r_t @ (u / _norm(u))
                ub, tg = _relaxed_box_lp(oracle, dr, G0, list(range(nS)), box, store)
                bounds[j] = ub - sy.scales.work_tol(dr)
                targets.append(tg)
        except SolverError:
            open_boxes += 1  # HiGHS left a bound of this box undecided: open, never called empty
            open_bound = np.inf
            continue
        if bounds.max() <= 0.0:
            continue  # no relaxed force does positive work along any generator: no member here
        centre = Z.sum(axis=0)
        order = [int(j) for j in np.argsort(-bounds)[:3] if bounds[j] > 0.0]
        cands = [centre] + [Z[j] + 0.01 * centre / max(1e-12, _norm(centre)) for j in order]
        if ms.n_redundant:
            # the best generator's direction with the redundancy whose slips come closest to the
            # relaxed maximiser's friction directions
            j = order[0]
            u_j = U[j] / _norm(U[j])
            z = _box_motion(oracle, u_j, list(range(nS)), box, targets[j], store)
            if z is not None:
                cands.append(np.r_[u_j, z])
            elif a_bar > 1:
                # no motion of that direction slides in the box (an S-point's slip vanishes there,
                # as a fixed-body point's on the line of object motions it does not move along):
                # the same friction targets a step inside the cone, where the points slide. The
                # wrap's FFDSDDDDS family has members that only this candidate finds
                u_in = U[j] + 0.01 * centre[:a_bar] / max(1e-12, _norm(centre))
                if _norm(u_in) > 1e-9:
                    u_in = u_in / _norm(u_in)
                    z = _box_motion(oracle, u_in, list(range(nS)), box, targets[j], store)
                    if z is not None:
                        cands.append(np.r_[u_in, z])
            # and the same at the centroid's object direction
            u_c = centre[:a_bar]
            if a_bar > 1 and _norm(u_c) > 1e-9:
                u_c = u_c / _norm(u_c)
                try:
                    _, tg = _relaxed_box_lp(oracle, ms.Lambda_r_t @ u_c, G0, list(range(nS)), box, store)
                except SolverError:
                    tg = []  # undecided: this one candidate is not tried
                z = _box_motion(oracle, u_c, list(range(nS)), box, tg, store) if tg else None
                if z is not None:
                    cands.append(np.r_[u_c, z])
        for zc in cands:
            nu = _norm(zc[:a_bar])
            if nu <= 1e-9:
                continue
            # in 3-D a candidate's force LP rows (its exact slips) recur for no later direction:
            # its optimum is not stored (:meth:`DAFCOracle._keep_vertex`, an SVD each)
            t = oracle.test(ms.Lambda_r_t @ (zc[:a_bar] / nu), zeta_r=zc[a_bar:] / nu, screen=False, keep=d == 2)
            if t.member:
                dim = int(np.linalg.matrix_rank(U, tol=1e-9))
                return SectorSearch(t, boxes, 0, float(bounds.max()), dim)
        widest = max(range(nS), key=lambda q: sector_half(box[q]))
        if sector_half(box[widest]) <= leaf_half:
            open_boxes += 1  # a leaf: the bound is above the tolerance, no tested motion is a member
            open_bound = max(open_bound, float(bounds.max()))
            continue
        counter += 1
        heapq.heappush(heap, (-float(bounds.max()), counter, box))
    return SectorSearch(None, boxes, open_boxes, open_bound)


# ------------------------------------------------------------------------------------------------
# The set of DAFC directions


@dataclass(frozen=True)
class DAFCSet:
    """DAFC over the unit sphere of the motion space.

    ``directions`` are unit object motions (world frame, paper coordinates) with their oracle
    answers; ``allowable`` generates the allowable cone ``A_r`` (eq. 20) in object coordinates.
    Where there are no S-points DAFC is exactly ``A_r`` minus the closed convex cone of directions
    in which no admissible force does positive work, so it is non-empty iff a generator of ``A_r``
    is a member, and then has the dimension of ``A_r``.
    """

    directions: Array  # (n, D)
    member: Array  # (n,) bool
    work: Array  # (n,)
    allowable: Generators  # generators of A_r in R^D (rays, lines)
    dim: int
    exact: bool
    tests: tuple[DirectionTest, ...] = field(default=(), repr=False)
    description: DAFCExact | None = None  # exact description (no S-points, small enough)
    description_error: str | None = None  # why the exact description is missing when cdd failed

    @property
    def empty(self) -> bool:
        return not bool(np.any(self.member))

    def members(self) -> Array:
        return self.directions[self.member]

    def best(self) -> DirectionTest | None:
        """The member with the largest work margin (finite margins first normalised)."""
        cands = [t for t in self.tests if t.member]
        if not cands:
            return None
        return max(cands, key=lambda t: (np.isinf(t.work), t.work if np.isfinite(t.work) else 0.0))


#: The exact description enumerates the force polyhedron Q; attempted up to this dimension.
MAX_EXACT_DIM = 8


@dataclass(frozen=True)
class DAFCExact:
    """DAFC without S-points, exactly: ``{dr in A_r : k_j^T dr > 0 for some j}``.

    ``A_r`` is generated by ``allowable`` (rays and lines, object coordinates, eq. 20). The
    ``k_j`` (rows of ``work_generators``) generate the cone of the net wrenches
    ``G_c f_c + w_ex`` the admissible forces can apply in the motion space (the images of the
    vertices and rays of ``Q = {f_c in F : Xi^T (G_c f_c + w_ex) = 0}``); the directions with
    ``k_j^T dr <= 0`` for every ``j`` form the closed convex cone in which no force does positive
    work, so DAFC is ``A_r`` minus that cone (not convex in general).
    """

    allowable: Generators  # in R^D
    work_generators: Array  # (n_k, D), rows k_j (projected on the motion space)

    def contains(self, dr: Array, tol: float = 1e-9) -> bool:
        """Exact membership of a direction ``dr`` that lies in ``A_r``."""
        dr = np.asarray(dr, dtype=float)
        scale = max(1.0, float(np.max(np.linalg.norm(self.work_generators, axis=1), initial=0.0)))
        return bool(np.any(self.work_generators @ dr > tol * scale * float(np.linalg.norm(dr))))


def dafc_exact(oracle: DAFCOracle) -> DAFCExact | None:
    """The exact description of DAFC (see :class:`DAFCExact`), or ``None`` with S-points (whose
    friction direction varies with the motion) or when ``Q`` has dimension above
    ``MAX_EXACT_DIM`` (vertex enumeration by cdd would be too large)."""
    ms, st, fs, sy = oracle.ms, oracle.st, oracle.fs, oracle.system
    if oracle.sel.s_index or ms.a_bar == 0:
        return None
    A_eq = oracle.Xi.T @ st.G_c  # (p, L_c)
    b_eq = -(oracle.Xi.T @ sy.w_ex)
    L_c = st.G_c.shape[1]
    if L_c - (rank(A_eq) if A_eq.size else 0) > MAX_EXACT_DIM:
        return None
    P = ms.Lambda_r_t @ ms.Lambda_r_t.T  # (D, D) projector on the motion space
    if L_c == 0:
        K = (P @ sy.w_ex)[None, :]
    else:
        Q = polyhedron_generators(fs.C, np.zeros(fs.C.shape[0]), A_eq, b_eq)  # may raise SolverError
        if Q.is_empty:
            K = np.zeros((0, ms.D))
        else:
            verts = (Q.vertices @ st.G_c.T + sy.w_ex) @ P.T  # (nv, D)
            dirs = Q.all_directions() @ st.G_c.T @ P.T  # (nr, D)
            K = np.vstack([verts, dirs])
    K = K[np.linalg.norm(K, axis=1) > 1e-12] if K.size else K.reshape(0, ms.D)
    return DAFCExact(allowable_cone(ms).map(ms.Lambda_r_t), K)


#: :func:`allowable_cone` per motion space alive (by ``id``, with a weak reference that drops the
#: entry with its motion space): a report asks for it four times (the sample, the faces, the exact
#: description, the table's search), each a cdd enumeration.
_ALLOWABLE: dict[int, tuple[weakref.ref[MotionSpace], Generators]] = {}


def allowable_cone(ms: MotionSpace) -> Generators:
    """Generators of the allowable object motions ``A_r`` (eq. 20), in ``dzeta~`` coordinates
    (read-only arrays: one result per motion space, shared by its callers)."""
    kept = _ALLOWABLE.get(id(ms))
    if kept is not None and kept[0]() is ms:
        return kept[1]
    g = _allowable_cone(ms)
    for a in (g.vertices, g.rays, g.lines):
        a.setflags(write=False)
    key = id(ms)

    def forget(_ref: weakref.ref[MotionSpace]) -> None:
        _ALLOWABLE.pop(key, None)

    _ALLOWABLE[key] = (weakref.ref(ms, forget), g)
    return g


def _allowable_cone(ms: MotionSpace) -> Generators:
    if ms.a == 0:
        return Generators(np.zeros((1, ms.a_bar)), np.zeros((0, ms.a_bar)), np.zeros((0, ms.a_bar)))
    g = cone_generators(ms.B) if ms.B.shape[0] else Generators(
        np.zeros((1, ms.a)), np.zeros((0, ms.a)), np.eye(ms.a)
    )
    P = np.hstack([np.eye(ms.a_bar), np.zeros((ms.a_bar, ms.n_redundant))])
    return g.map(P)


def _dedupe(U: Array) -> Array:
    out: list[Array] = []
    for u in U:
        if not any(float(u @ v) > 1 - 1e-9 for v in out):
            out.append(u)
    return np.array(out).reshape(-1, U.shape[1] if U.ndim == 2 else 0)


def _prefer_realisable(oracle: DAFCOracle, dirs: list[Array], screen: bool = True, quick: bool = False,
                       witness: bool = True, prefer: bool = True) -> DirectionTest | None:
    """Test the coordinates ``dirs`` in order (options of :meth:`DAFCOracle.test`); the first
    member whose torque set (32) is non-empty (:meth:`DAFCOracle.realisable`), else the first
    member, else None. ``prefer=False``: the first member."""
    first: DirectionTest | None = None
    for u in dirs:
        t = oracle.test(oracle.ms.Lambda_r_t @ u, screen=screen, quick=quick, witness=witness)
        if t.member:
            if not prefer or oracle.realisable(t):
                return t
            first = first or t
    return first


#: Redundancy draws per direction and scale of :func:`_redundancy_draws`.
REDUNDANCY_DRAWS = 24


def _redundancy_draws(oracle: DAFCOracle, dirs: list[Array]) -> DirectionTest | None:
    """The first member among seeded allowable redundancies ``z0 + s N(0, I)`` (``z0`` least-L1,
    ``s`` 0.1, 1 and 10 times the motion's size) for each direction of ``dirs``, or None."""
    ms = oracle.ms
    if not ms.n_redundant:
        return None
    rng = np.random.default_rng(9)
    for u in dirs:
        z0 = oracle.redundancy_for(u)
        if z0 is None:
            continue
        size = max(1.0, float(np.linalg.norm(ms.Lambda_q_t @ u)))
        for s in (0.1, 1.0, 10.0):
            for _ in range(REDUNDANCY_DRAWS):
                z = z0 + s * size * rng.standard_normal(ms.n_redundant)
                zc = ms.zeta_c(u, z)
                if oracle.B.shape[0] and np.any(oracle.B @ zc > ALLOW_TOL * max(1.0, float(np.linalg.norm(zc)))):
                    continue
                t = oracle.test(ms.Lambda_r_t @ u, zeta_r=z, screen=False, witness=False)
                if t.member:
                    return t
    return None


def _sector_verdict(oracle: DAFCOracle, cone_dim: int) -> tuple[DirectionTest | None, int, bool] | None:
    """Step (2b) of :func:`dafc_nonempty`: the slip-sector search's answer in its return form (a
    member, or exact emptiness), or None when it left boxes open (counted on the oracle)."""
    found = slip_sector_search(oracle)
    oracle.sector_boxes += found.boxes
    if found.test is not None:
        return found.test, cone_dim, False
    if found.decided:
        return None, 0, True
    oracle.sector_open += found.open_boxes
    return None


def dafc_nonempty(oracle: DAFCOracle, extra_samples: int = 16, realisable: bool = True
                  ) -> tuple[DirectionTest | None, int, bool]:
    """Decide whether DAFC is empty; return (a member or None, dim DAFC, exact).

    Without S-points: test the generators of the allowable cone; exact (see :class:`DAFCSet`).
    With S-points: (0) the centroid of the cone and seeded interior samples are tested exactly
    (friction-aligned and least-L1 redundancy), stopping at the first member; (1) failing that,
    the relaxation with free friction directions is tested on the generators, which proves
    emptiness exactly when none does positive work; (2) otherwise the samples and then the
    generators are tested with the full redundancy search. A member (its work above the threshold,
    its S-points sliding) has, for non-degenerate data, a neighbourhood of members in ``A_r`` (the
    slips and the LP data vary continuously with the motion), so DAFC then has the dimension of
    ``A_r``, wherever in ``A_r`` the member was found. (2b) Failing those, the branch and bound over the
    S-points' slip directions (:func:`slip_sector_search`) either finds a member, or closes every
    box, which proves emptiness (``exact = True``); (2c) where it leaves boxes open (3-D sectors at
    the resolution or past the budget; ``oracle.sector_open`` counts them and the table's reason
    says so), seeded redundancies and then (3) the report's sample are tried. Members are marked
    ``exact = False`` (the dimension rests on the non-degeneracy above).

    The returned member (the combination's example direction) is, within each stage, the first
    one whose torque set (32) is non-empty (:meth:`DAFCOracle.realisable`), else the first
    member: the samples live in the coordinates of ``Lambda~_r``, whose column signs are LAPACK's
    choice, so "the first member" alone may be a direction with no W_3-admissible forces on one
    machine and a realisable one on another. ``realisable=False`` (the enumeration's table, whose
    verdict and dimension do not depend on it) returns the first member of each stage, without
    the torque-set LPs, skips (0) and runs (2b) before (2): the same verdict, dimension and
    exactness, with (2) (whose candidates include those of (0)) only where the slip-sector search
    leaves boxes open.
    """
    ms = oracle.ms
    if ms.a_bar == 0:
        return None, 0, True
    gen = allowable_cone(ms)
    dirs = gen.all_directions()  # (k, a_bar)
    if dirs.shape[0] == 0:
        return None, 0, True
    cone_dim = int(np.linalg.matrix_rank(dirs, tol=1e-9))
    generators = list(_dedupe(dirs))
    if not oracle.sel.s_index or (oracle.exact and ms.a_bar == 1):
        # without S-points: A_r minus a convex cone, decided on the generators; with a_bar = 1 the
        # only directions are the (at most two) generators, each decided by the exact oracle. The
        # table (``realisable=False``) skips the relaxed screen: with one redundancy candidate per
        # direction the force LP decides alone, and the screen's LP mostly did not prune
        t = _prefer_realisable(oracle, generators, screen=realisable, witness=False, prefer=realisable)
        return (t, cone_dim, True) if t is not None else (None, 0, True)
    # (0) the centroid of the cone (the likeliest member), then seeded interior samples
    rng = np.random.default_rng(1)
    interior: list[Array] = []
    centroid = dirs.sum(axis=0)
    if np.linalg.norm(centroid) > 1e-9:
        interior.append(centroid / np.linalg.norm(centroid))
    for _ in range(extra_samples):
        v = rng.random(len(dirs)) @ dirs
        if np.linalg.norm(v) > 1e-9:
            interior.append(v / np.linalg.norm(v))
    if realisable:  # the table goes from (1) to the slip-sector search (2b) below
        t = _prefer_realisable(oracle, interior, screen=False, quick=True, witness=False, prefer=realisable)
        if t is not None:
            return t, cone_dim, False
    # (1) relaxation: exact emptiness certificate
    positive = [u for u in generators if oracle.relaxed_positive(ms.Lambda_r_t @ u)]
    if not positive:
        return None, 0, True
    best: DirectionTest | None = None
    searched = False
    if not realisable:
        # the table: the slip-sector search (2b) first, which decides most combinations at once;
        # the samples (0) and the full redundancy search (2) only where it leaves boxes open. The
        # verdict is the same either way (a member of (0) or (2) is a member, which (2b) never
        # calls empty; (2b) runs after an empty (2) in the other order), and so are the dimension
        # and exactness
        decided = _sector_verdict(oracle, cone_dim)
        if decided is not None:
            return decided
        searched = True
    # (2) the interior samples again with the full redundancy search, then the generators
    t = _prefer_realisable(oracle, interior, screen=False, witness=False, prefer=realisable)
    if t is not None:
        return t, cone_dim, False
    best_ok = False
    for u in positive:  # the first member whose torque set is non-empty, else the first member
        t = oracle.test(ms.Lambda_r_t @ u, screen=False, witness=False)
        if t.member:
            ok = oracle.realisable(t) if realisable else True
            if best is None or ok:
                best, best_ok = t, ok
            if best_ok:
                break
    if best is None:
        if not searched:
            # (2b) the branch and bound over the S-points' slip directions on the whole allowable
            # cone (:func:`slip_sector_search`): a member, or a proof of emptiness when it closes
            # every box
            decided = _sector_verdict(oracle, cone_dim)
            if decided is not None:
                return decided
        # (2c) the search left boxes open: seeded redundancies at three scales around the least-L1
        # one, on the generators with positive relaxed work and the centroid (sampling, not a proof)
        t = _redundancy_draws(oracle, positive + ([centroid / np.linalg.norm(centroid)]
                                                  if np.linalg.norm(centroid) > 1e-9 else []))
        if t is not None:
            return t, cone_dim, False
    if best is None:
        # (3) the directions the full report samples (:func:`dafc_set`), so that a combination the
        # table calls empty never shows members in its own report
        for u in sample_directions(ms, default_samples(ms.a_bar)):
            t = oracle.test(ms.Lambda_r_t @ u, witness=False)
            if t.member:
                best = t
                break
    if best is None:
        return None, 0, False
    return best, cone_dim, False


def default_samples(a_bar: int) -> int:
    """Directions sampled by the full report: the circle/sphere densely, higher dimensions coarsely."""
    return 120 if a_bar <= 3 else 48


def sample_directions(ms: MotionSpace, samples: int, seed: int = 0) -> Array:
    """The seeded sample of unit coordinates ``(n, a_bar)`` :func:`dafc_set` tests: both
    directions (``a_bar = 1``), a circle (2), a Fibonacci sphere (3) or Gaussian directions
    (more), then the generators of the allowable cone."""
    a_bar = ms.a_bar
    rng = np.random.default_rng(seed)
    U: Array
    if a_bar == 1:
        U = np.array([[1.0], [-1.0]])
    elif a_bar == 2:
        th = np.linspace(0, 2 * np.pi, samples, endpoint=False)
        U = np.stack([np.cos(th), np.sin(th)], axis=1)
    elif a_bar == 3:
        i = np.arange(samples) + 0.5
        phi = np.arccos(1 - 2 * i / samples)
        lon = np.pi * (1 + 5**0.5) * i
        U = np.stack([np.cos(lon) * np.sin(phi), np.sin(lon) * np.sin(phi), np.cos(phi)], axis=1)
    else:
        U = rng.standard_normal((samples, a_bar))
        U /= np.linalg.norm(U, axis=1, keepdims=True)
    extra = allowable_cone(ms).all_directions()
    return np.vstack([U, extra]) if extra.size else U


#: How :func:`dafc_set` refines the boundaries of the sampled set (the full report says it).
REFINEMENT = ("a (member, non-member) pair whose non-member is not allowable is resolved where the great circle "
              "between them leaves the allowable cone (one test; bisected only if that point is not a member); "
              "every other pair is bisected 6 times")


def _allowable_faces(ms: MotionSpace) -> Array | None:
    """Unit rows ``H`` ``(m, a_bar)`` of the allowable cone ``A_r = {u : H u <= 0}`` (eq. 20) in
    motion coordinates, or None when it has no proper face (the whole space), lies in a
    hyperplane, or cdd fails (then every boundary is bisected)."""
    from analysis.solvers.cdd import generators_to_inequalities  # here: the module's head is another room's

    try:
        H, b, flat = generators_to_inequalities(allowable_cone(ms))  # (m, a_bar), (m,)
    except SolverError:
        return None
    if flat or H.shape[0] == 0 or np.any(np.abs(b) > 1e-9):
        return None
    return H / np.linalg.norm(H, axis=1, keepdims=True)


def _face_crossing(H: Array, inner: Array, outer: Array) -> Array | None:
    """The unit direction where the great-circle arc from ``inner`` (in ``A_r``) to ``outer`` (not
    allowable) leaves ``{u : H u <= 0}``: ``(1 - t) inner + t outer`` for the least ``t`` at
    which a row becomes active (the arc and the chord meet the same faces: ``A_r`` is a cone);
    None when the rows do not separate them."""
    hi, ho = H @ inner, H @ outer  # (m,)
    rising = ho > hi + 1e-12
    if not np.any(rising & (ho > 0)):
        return None
    t = float(np.min(np.clip(-hi[rising] / (ho[rising] - hi[rising]), 0.0, 1.0)))
    m = (1 - t) * inner + t * outer  # (a_bar,)
    nm = float(np.linalg.norm(m))
    return None if nm < 1e-12 or t <= 0.0 or t >= 1.0 else m / nm


def _face_step(arc: list[Array], in_a: bool, m: Array, t: DirectionTest, active: list[bool], q: int) -> None:
    """:func:`dafc_set`'s refinement at the point ``m`` where the arc ``[a, b]`` of pair ``q``
    leaves the allowable cone, tested as ``t``: a member there ends the pair (the boundary is the
    face); otherwise ``m`` replaces the arc's non-allowable end, and the bisection goes on."""
    if t.member:
        active[q] = False
    elif in_a:
        arc[1] = m
    else:
        arc[0] = m


def dafc_set(oracle: DAFCOracle, samples: int = 200, refine: int = 6, seed: int = 0) -> DAFCSet:
    """Sample the unit sphere of the motion space, test every direction, refine boundaries.

    ``a_bar = 1``: both directions; ``a_bar = 2``: a circle of ``samples`` angles; more: a seeded
    Fibonacci/Gaussian sample plus the allowable cone's generators. Each adjacent (member,
    non-member) pair on the circle (``a_bar = 2``) or nearest-neighbour pair is refined along
    the great circle (:data:`REFINEMENT`): where the non-member is not allowable (eq. 20) and the
    arc leaves ``A_r`` through a face at a member, that point is the boundary, found with one
    test; otherwise the pair is bisected ``refine`` times.
    """
    ms = oracle.ms
    a_bar = ms.a_bar
    gen_u = allowable_cone(ms)
    gen = gen_u.map(ms.Lambda_r_t) if a_bar else Generators(np.zeros((1, ms.D)), np.zeros((0, ms.D)),
                                                             np.zeros((0, ms.D)))
    if a_bar == 0:
        return DAFCSet(np.zeros((0, ms.D)), np.zeros(0, bool), np.zeros(0), gen, 0, True)
    U = sample_directions(ms, samples, seed)
    tests = oracle.test_many(U)
    member = np.array([t.member for t in tests])
    # boundary refinement
    if refine and member.any() and (~member).any() and a_bar >= 2:
        Ut = np.array([t.u for t in tests])
        pairs: list[tuple[int, int]] = []
        if a_bar == 2:
            pairs = [(k, (k + 1) % samples) for k in range(samples) if member[k] != member[(k + 1) % samples]]
        else:
            cos = Ut @ Ut.T
            others = np.flatnonzero(~member)
            for km in np.flatnonzero(member):
                jm = int(others[int(np.argmax(cos[km, others]))])
                pairs.append((int(km), jm))
        faces = _allowable_faces(ms)
        # each pair's arc (a, b), which end is the member, its new tests; the pairs are refined
        # side by side, one step of all of them tested at once (test_many), their tests kept per pair
        arcs: list[list[Array]] = []
        ends: list[bool] = []
        new: list[list[DirectionTest]] = []
        active: list[bool] = []
        crossing: list[tuple[int, Array]] = []  # (pair, the point where its arc leaves A_r)
        for k, j in pairs[:64]:
            a, b = Ut[k], Ut[j]
            in_a = bool(member[k])
            arcs.append([a, b])
            ends.append(in_a)
            new.append([])
            active.append(True)
            # a boundary on a face of the allowable cone is resolved exactly: one test where the
            # arc leaves the cone; the bisection is only needed when that point is not a member
            if faces is not None and tests[j if in_a else k].reason.startswith("not allowable"):
                inner, outer = (a, b) if in_a else (b, a)
                m = _face_crossing(faces, inner, outer)
                if m is not None:
                    seen = np.flatnonzero(Ut @ m > 1 - 1e-12)  # (a_bar = 2: a generator of A_r, tested)
                    if seen.size:
                        _face_step(arcs[-1], in_a, m, tests[int(seen[0])], active, len(active) - 1)
                    else:
                        crossing.append((len(arcs) - 1, m))
        if crossing:
            for (q, m), t in zip(crossing, oracle.test_many(np.array([m for _, m in crossing])), strict=True):
                new[q].append(t)
                _face_step(arcs[q], ends[q], m, t, active, q)
        for _ in range(refine):
            step: list[tuple[int, Array]] = []
            for q, (a, b) in enumerate(arcs):
                if not active[q]:
                    continue
                m = a + b
                if np.linalg.norm(m) < 1e-12:
                    active[q] = False
                    continue
                step.append((q, m / np.linalg.norm(m)))
            if not step:
                break
            for (q, m), t in zip(step, oracle.test_many(np.array([m for _, m in step])), strict=True):
                new[q].append(t)
                arcs[q][0 if t.member == ends[q] else 1] = m
        for ts in new:
            tests.extend(ts)
    member = np.array([t.member for t in tests])
    dirs = np.array([t.direction for t in tests]).reshape(-1, ms.D)
    work = np.array([t.work for t in tests])
    if not member.any():
        dim = 0
    elif not oracle.sel.s_index:
        dim = int(np.linalg.matrix_rank(gen_u.all_directions(), tol=1e-9))
    else:
        dim = int(np.linalg.matrix_rank(dirs[member], tol=1e-6))
    try:
        description, why = dafc_exact(oracle), None
    except SolverError as e:
        # the description is an extra of the report; membership above was decided by the LPs
        description, why = None, f"exact description of DAFC not available: {e}"
    return DAFCSet(dirs, member, work, gen, dim, oracle.exact and not oracle.sel.s_index, tuple(tests),
                   description, why)
