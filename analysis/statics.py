"""Statics of the grasp (paper eq. 8-10): ``f_c = W_f x``, ``w = D tau + Xi xi``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis import memo
from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.linalg import null_space, orth, pinv


@dataclass(frozen=True)
class Statics:
    """Quantities of eq. (8)-(10) for one combination.

    ``tau = J_c^T f_c`` and ``w = G_c f_c`` (8); ``f_c = (J_c^T)^+ tau + Gamma xi~ = W_f x``
    with ``x = [tau; xi~]`` (9); ``w = D tau + Xi xi`` (10).
    """

    J_c: Array  # (L_c, M)
    G_c: Array  # (D, L_c)
    JcT_pinv: Array  # (L_c, M)   (J_c^T)^+
    Gamma: Array  # (L_c, p_bar) orthonormal basis of null(J_c^T): internal forces
    D: Array  # (D, M)        G_c (J_c^T)^+
    Xi: Array  # (D, p)        orthonormal basis of range(G_c Gamma)

    @property
    def W_f(self) -> Array:
        """``W_f = [(J_c^T)^+, Gamma]``: ``(L_c, M + p_bar)``."""
        return np.hstack([self.JcT_pinv, self.Gamma])

    @property
    def p(self) -> int:
        return int(self.Xi.shape[1])

    def x_of(self, f_c: Array) -> Array:
        """``x = [tau; xi~]`` of contact forces ``f_c`` (inverse of eq. 9)."""
        return np.concatenate([self.J_c.T @ f_c, self.Gamma.T @ f_c])


def statics(system: GraspSystem, sel: Selection) -> Statics:
    """Build ``J_c = H_c J``, ``G_c = G H_c^T``, ``(J_c^T)^+``, ``Gamma``, ``D``, ``Xi``."""
    J_c = sel.H_c @ system.J  # (L_c, M)
    G_c = system.G @ sel.H_c.T  # (D, L_c)

    def bases() -> tuple[Array, Array, Array, Array]:
        if system.M:
            JcT_pinv = pinv(J_c.T)  # (L_c, M)
            Gamma = null_space(J_c.T)  # (L_c, p_bar)
        else:
            JcT_pinv = np.zeros((sel.L_c, 0))
            Gamma = np.eye(sel.L_c)
        return JcT_pinv, Gamma, G_c @ JcT_pinv, orth(G_c @ Gamma)  # ..., D (D, M), Xi (D, p)

    # a function of J_c and G_c only: remembered within a planner's search (analysis.memo)
    JcT_pinv, Gamma, D, Xi = memo.remembered(("statics", memo.exact_key(J_c, G_c), system.M, sel.L_c), bases,
                                             lambda r: r)
    return Statics(J_c, G_c, JcT_pinv, Gamma, D, Xi)
