"""Joint torque limits ``|tau_j| <= tau_max_j`` of a hand (bounds on the torques of (18) and (32)).

One place gives the limit vector of a hand, in N m, exactly as the scene states it:

1. the scene's ``joint_torque_limits`` (one positive entry per joint, validated in
   :mod:`analysis.scene`), when given;
2. else, for URDF fingers, the URDF's ``<limit effort=...>`` (pinocchio ``model.effortLimit``);
   an effort of 0, a missing one or a non-finite one means unlimited;
3. else no limit (``inf``).

:func:`hand_torque_limits` returns ``None`` when no joint is limited, so that scenes without
limits pose exactly the LPs they posed before. The limits bound the stationary grasp (18)
(:mod:`analysis.stationary`) and the torque set (32) with its recommended member
(:mod:`analysis.torque_conditions`) by the rows of :func:`limit_rows`; when a grasp or a motion
needs more, :func:`least_excess` names the joints and the torques they need.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from analysis.solvers.highs import solve_lp

#: A torque within this fraction of its limit still counts as within it (the LPs' tolerance).
LIMIT_TOL = 1e-6


def urdf_effort_limits(finger: object) -> Array | None:
    """``(n,)`` URDF effort limits [N m] of a URDF finger's chain joints (``inf`` where the URDF
    gives 0 or none); ``None`` for a finger that is not read from a URDF."""
    names = getattr(finger, "joint_names", None)
    path = getattr(finger, "path", None)
    if names is None or path is None:
        return None
    from analysis.urdf import load_urdf_model  # deferred: pinocchio only for URDF fingers

    full = load_urdf_model(path)
    out = np.full(len(names), np.inf)
    for i, n in enumerate(names):
        j = full.joints[int(full.getJointId(n))]
        e = float(full.effortLimit[int(j.idx_v)])
        out[i] = e if np.isfinite(e) and e > 0.0 else np.inf
    return out


def hand_torque_limits(scene: Scene, hand: HandKinematics | None = None) -> Array | None:
    """The limit vector ``tau_max`` ``(M,)`` [N m] of the scene's hand (``inf``: unlimited), or
    ``None`` when no joint is limited. The scene's ``joint_torque_limits`` win over the URDF's."""
    if scene.joint_torque_limits is not None:
        return np.asarray(scene.joint_torque_limits, dtype=float)
    hand = hand or HandKinematics.from_scene(scene)
    out = np.full(hand.M, np.inf)
    for i, f in enumerate(hand.fingers):
        eff = urdf_effort_limits(f)
        if eff is not None:
            out[hand.finger_slice(i)] = eff
    return out if np.any(np.isfinite(out)) else None


@dataclass(frozen=True)
class JointExcess:
    """A joint whose torque must exceed its limit, and the torque it needs [N m]: the least
    ``|tau_j|`` with every other joint within its limit (``alone``), or, when no single joint's
    limit is what stands in the way, its torque where all limits are relaxed by one factor."""

    joint: int
    label: str
    needed: float  # [N m]
    limit: float  # [N m]
    alone: bool

    def describe(self) -> str:
        if self.alone:
            return (f"{self.label} at least {self.needed:.4g} N m (limit {self.limit:.4g} N m, the other joints "
                    "within theirs)")
        return f"{self.label} {self.needed:.4g} N m (limit {self.limit:.4g} N m, every limit relaxed by one factor)"


def limit_rows(T_map: Array, tau_max: Array | None, scale: float = 1.0) -> tuple[Array, Array]:
    """``|T_j x| <= tau_max_j / scale`` for the limited joints as ``A x <= b`` with rows divided by
    the limit (so each row is in units of its own limit): ``A (2 n_lim, n)``, ``b = 1``.

    ``T_map`` ``(M, n)`` maps the LP's unknowns ``x`` to joint torques in units of ``scale``
    (``J_c^T`` on scaled forces ``f / F0`` with ``scale = F0``; ``T`` of (32) in newtons with 1)."""
    n = T_map.shape[1]
    if tau_max is None:
        return np.zeros((0, n)), np.zeros(0)
    lim = np.flatnonzero(np.isfinite(tau_max))
    rows = T_map[lim] * (scale / tau_max[lim])[:, None]  # (n_lim, n)
    return np.vstack([rows, -rows]), np.ones(2 * lim.size)


def least_excess(
    c_rows: tuple[Array, Array], eq_rows: tuple[Array, Array], T_map: Array, tau_max: Array, scale: float,
    labels: tuple[str, ...] = (),
) -> tuple[JointExcess, ...] | None:
    """Which joints' limits make ``{A x <= b, A_eq x = b_eq, |tau_j| <= tau_max_j}`` empty, and
    the torques they need (``tau = scale T_map x``).

    First the least uniform relaxation ``|tau_j| <= (1 + t) tau_max_j`` (an LP in ``[x, t]``)
    names the joints over their limits; then, for each of them, the least ``|tau_j|`` with every
    other limit kept (one LP each). Returns ``()`` when the limits hold (``t <= 0``), ``None``
    when the set is empty even without limits."""
    A, b = c_rows
    A_eq, b_eq = eq_rows
    n = T_map.shape[1]
    L, ones = limit_rows(T_map, tau_max, scale)
    A_ub = np.vstack([np.hstack([A, np.zeros((A.shape[0], 1))]), np.hstack([L, -np.ones((L.shape[0], 1))])])
    A_e = np.hstack([A_eq, np.zeros((A_eq.shape[0], 1))])
    res = solve_lp(np.r_[np.zeros(n), 1.0], A_ub=A_ub, b_ub=np.concatenate([b, ones]), A_eq=A_e, b_eq=b_eq,
                   lb=np.r_[np.full(n, -np.inf), -1.0])
    if res.status != "optimal" or res.x is None:
        return None
    tau = T_map @ res.x[:n] * scale  # (M,) [N m]
    over = np.flatnonzero(np.abs(tau) > tau_max * (1.0 + LIMIT_TOL))
    out = []
    for j in over:
        others = tau_max.copy()
        others[j] = np.inf
        L_o, ones_o = limit_rows(T_map, others, scale)
        row = T_map[j] * scale  # |row x| <= s  [N m]
        A_j = np.vstack([np.hstack([A, np.zeros((A.shape[0], 1))]), np.hstack([L_o, np.zeros((L_o.shape[0], 1))]),
                         np.r_[row, -1.0][None, :], np.r_[-row, -1.0][None, :]])
        b_j = np.concatenate([b, ones_o, [0.0, 0.0]])
        alone = solve_lp(np.r_[np.zeros(n), 1.0], A_ub=A_j, b_ub=b_j, A_eq=A_e, b_eq=b_eq,
                         lb=np.r_[np.full(n, -np.inf), 0.0])
        label = labels[j] if j < len(labels) else str(j)
        if alone.status == "optimal" and alone.objective is not None:
            out.append(JointExcess(int(j), label, float(alone.objective), float(tau_max[j]), True))
        else:
            out.append(JointExcess(int(j), label, float(abs(tau[j])), float(tau_max[j]), False))
    return tuple(out)


def over_limit(tau: Array, tau_max: Array | None, tol: float = 0.0) -> Array:
    """Indices of the joints with ``|tau_j| > (1 + tol) tau_max_j``."""
    if tau_max is None:
        return np.zeros(0, dtype=int)
    return np.flatnonzero(np.abs(tau) > tau_max * (1.0 + tol))


__all__ = ["JointExcess", "hand_torque_limits", "least_excess", "limit_rows", "over_limit", "urdf_effort_limits"]
