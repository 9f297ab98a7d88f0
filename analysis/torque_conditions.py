"""The torque set's conditions at a fixed motion (paper eq. 30-32): linear in the contact forces.

Once the motion ``dzeta_c`` (hence the slips of the S-points) is fixed, every condition of the
torque set (32) is linear in the forces ``f_c`` ``(L_c,)``: the friction set ``C f_c <= 0``; the
net wrench ``w = W f_c + w_ex`` (``W = G_c`` plus kinetic friction) balanced in the active
directions (``Xi^T w = 0``) and parallel to the motion in the passive ones
(``N_u^T Lambda~_r^T w = 0``, ``W_3``); and positive work ``u^T Lambda~_r^T w > 0``. The joint
torques are ``tau = T f_c`` (``T = J_c^T`` plus the friction's joint part), and the joint torque
limits of the hand, where it has any, bound them: ``|tau_j| <= tau_max_j``
(:mod:`analysis.torque_limits`).

:func:`torque_conditions` builds them once for both users: the torque set itself
(:mod:`analysis.torques`) and the DAFC oracle's "is this member realisable" test
(:meth:`analysis.dafc.DAFCOracle.realisable`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.friction import FrictionSet, KineticFriction, kinetic_friction
from analysis.linalg import null_space
from analysis.motion import MotionSpace
from analysis.solvers.highs import LPResult, solve_lp
from analysis.statics import Statics
from analysis.torque_limits import JointExcess, least_excess, limit_rows


@dataclass(frozen=True)
class TorqueConditions:
    """Eq. (30)-(32) at a fixed motion, in ``f_c``: ``A_ub f <= b_ub``, ``A_eq f = b_eq``; the
    work is ``work_row f + work0`` (the last row of ``A_ub`` asks it to be >= 0). Rows
    ``m .. m + n_limit`` of ``A_ub`` are the joint torque limits (each divided by its limit)."""

    A_ub: Array  # (m + n_limit + 1, L_c) friction rows, torque limit rows, then -work_row
    b_ub: Array  # (m + n_limit + 1,)
    A_eq: Array  # (p + a_bar - 1, L_c) Xi^T W and N_u^T Lambda~_r^T W
    b_eq: Array  # (p + a_bar - 1,)
    work_row: Array  # (L_c,) u^T Lambda~_r^T W
    work0: float  # u^T Lambda~_r^T w_ex
    W_map: Array  # (D, L_c) wrench of the forces: G_c (+ kinetic friction)
    T_map: Array  # (M, L_c) joint torques of the forces: J_c^T (+ kinetic friction)
    friction: KineticFriction | None  # kinetic friction of the S-points (None without S-points)
    n_limit: int = 0  # rows of joint torque limits in A_ub
    tau_max: Array | None = None  # (M,) the limits [N m]
    joint_labels: tuple[str, ...] = ()

    @property
    def L_c(self) -> int:
        return int(self.A_ub.shape[1])

    def limit_excess(self, work: float) -> tuple[JointExcess, ...] | None:
        """The joints over their limits at the member with work at least ``work`` that needs the
        least relaxation of the limits; ``()`` when the limits hold there, ``None`` when no member
        reaches that work even without limits."""
        if self.tau_max is None:
            return ()
        m = self.A_ub.shape[0] - self.n_limit - 1
        A = np.vstack([self.A_ub[:m], self.A_ub[-1:]])
        b = np.concatenate([self.b_ub[:m], [self.b_ub[-1] - work]])
        return least_excess((A, b), (self.A_eq, self.b_eq), self.T_map, self.tau_max, 1.0, self.joint_labels)

    def max_work(self) -> LPResult:
        """``max work_row f`` subject to the conditions (its optimum plus ``work0`` is the
        largest work; ``infeasible``: the torque set is empty)."""
        return solve_lp(self.work_row, A_ub=self.A_ub, b_ub=self.b_ub, A_eq=self.A_eq, b_eq=self.b_eq,
                        maximize=True)


def torque_conditions(
    system: GraspSystem, sel: Selection, ms: MotionSpace, st: Statics, fs: FrictionSet, u: Array,
    slips: Array | None,
) -> TorqueConditions:
    """The conditions for the object direction with coordinates ``u`` ``(a_bar,)`` on
    ``Lambda~_r`` and the S-points' ``slips`` ``(#S, d)`` of the chosen motion."""
    kf: KineticFriction | None = None
    W_map, T_map = st.G_c, st.J_c.T
    if sel.s_index:
        assert slips is not None
        kf = kinetic_friction(system, sel, slips)
        W_map = st.G_c + kf.G_w
        T_map = st.J_c.T + kf.J_w
    Lr = ms.Lambda_r_t  # (D, a_bar)
    w_ex = system.w_ex
    eq_rows = [st.Xi.T @ W_map]
    eq_rhs = [-(st.Xi.T @ w_ex)]
    if ms.a_bar > 1:
        N_u = null_space(u[None, :])  # (a_bar, a_bar - 1)
        eq_rows.append(N_u.T @ Lr.T @ W_map)
        eq_rhs.append(-(N_u.T @ Lr.T @ w_ex))
    work_row = u @ Lr.T @ W_map  # (L_c,)  work = work_row f + u^T Lr^T w_ex
    work0 = float(u @ Lr.T @ w_ex)
    A_lim, b_lim = limit_rows(T_map, system.tau_max)
    return TorqueConditions(
        A_ub=np.vstack([fs.C, A_lim, -work_row[None, :]]),
        b_ub=np.concatenate([np.zeros(fs.C.shape[0]), b_lim, [work0]]),
        A_eq=np.vstack(eq_rows),  # (p + a_bar - 1, L_c)
        b_eq=np.concatenate(eq_rhs),
        work_row=work_row,
        work0=work0,
        W_map=W_map,
        T_map=T_map,
        friction=kf,
        n_limit=int(A_lim.shape[0]),
        tau_max=system.tau_max,
        joint_labels=system.joint_labels,
    )
