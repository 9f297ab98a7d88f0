"""Direction of passive force closure, DPFC (paper eq. 28).

``D_DPFC = {w_p = G_c Gamma xi~_p : f_c,st - Gamma xi~_p in F_f}``: the external wrenches that
internal forces alone (no change of ``tau_st``) can balance. ``F_f`` is the friction set of the
F- and N-points and the normal component of the S-points (their tangential kinetic friction
opposes motion and does not resist wrenches). It is a polyhedron in ``xi~`` space, enumerated with
cdd and mapped to wrench space.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.friction import FrictionSet
from analysis.linalg import rank
from analysis.solvers.cdd import Generators, polyhedron_generators, reduce_generators
from analysis.solvers.highs import solve_lp
from analysis.statics import Statics
from analysis.stationary import StationaryGrasp


@dataclass(frozen=True)
class DPFC:
    """Vertices and rays (wrench space, ``D`` components) of the DPFC polyhedron."""

    generators: Generators
    dim: int  # dimension of its span, <= p = rank(G_c Gamma)

    @property
    def vertices(self) -> Array:
        return self.generators.vertices

    @property
    def rays(self) -> Array:
        return self.generators.all_directions()

    def contains(self, w: Array, st: Statics, fs: FrictionSet, grasp: StationaryGrasp) -> bool:
        """Exact membership by LP: ``w = G_c Gamma xi~`` with ``f_st - Gamma xi~`` in ``F_f``."""
        GG = st.G_c @ st.Gamma  # (D, p_bar)
        res = solve_lp(
            np.zeros(GG.shape[1]),
            A_ub=-fs.C @ st.Gamma,
            b_ub=-(fs.C @ grasp.f_c) + 1e-9,
            A_eq=GG,
            b_eq=np.asarray(w, dtype=float),
        )
        return res.found


def dpfc(st: Statics, fs: FrictionSet, grasp: StationaryGrasp) -> DPFC:
    """Eq. (28): enumerate ``{G_c Gamma xi~ : C (f_st - Gamma xi~) <= 0}``."""
    D = st.G_c.shape[0]
    p_bar = st.Gamma.shape[1]
    if p_bar == 0:
        g = Generators(np.zeros((1, D)), np.zeros((0, D)), np.zeros((0, D)))
        return DPFC(g, 0)
    A_ub = -fs.C @ st.Gamma  # (m, p_bar)
    b_ub = -(fs.C @ grasp.f_c)  # (m,)
    g_xi = polyhedron_generators(A_ub, b_ub)
    g_w = reduce_generators(g_xi.map(st.G_c @ st.Gamma))
    pts = np.vstack([g_w.vertices - g_w.vertices[:1], g_w.all_directions()]) if g_w.vertices.size else g_w.rays
    return DPFC(g_w, rank(pts) if pts.size else 0)
