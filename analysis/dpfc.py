"""Direction of passive force closure, DPFC (paper eq. 28).

``D_DPFC = {w_p = G_c Gamma xi~_p : f_c,st - Gamma xi~_p in F_f}``: the external wrenches that
internal forces alone (no change of ``tau_st``) can balance. ``F_f`` is the friction set of the
F- and N-points and the normal component of the S-points (their tangential kinetic friction
opposes motion and does not resist wrenches). It is a polyhedron in ``xi~`` space, enumerated with
cdd and mapped to wrench space while that is cheap (few internal-force coordinates or few friction
facets, see ``MAX_ENUMERATION_DIM``); otherwise (a wrap of twelve F-points: 192 facets in 24 dimensions, whose vertex
enumeration does not finish) DPFC is reported by its inequalities, its dimension and the extreme
wrenches along ``+-`` each axis of its span (one LP each), and says so (``enumerated = False``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.exceptions import SolverError
from analysis.friction import FrictionSet
from analysis.linalg import rank
from analysis.solvers.cdd import Generators, polyhedron_generators, reduce_generators
from analysis.solvers.highs import solve_lp
from analysis.statics import Statics
from analysis.stationary import StationaryGrasp

#: Vertex enumeration of DPFC is attempted up to this many internal-force coordinates ``p_bar``,
#: and above ``SMALL_DIM`` only with at most ``MAX_ENUMERATION_ROWS`` friction facets (eight
#: coordinates and 98 facets, six 16-sided pyramids, took cdd over a minute).
MAX_ENUMERATION_DIM = 8
SMALL_DIM = 4
MAX_ENUMERATION_ROWS = 64


@dataclass(frozen=True)
class DPFC:
    """DPFC in wrench space (``D`` components): vertices and rays when enumerated, else its
    H-representation ``{G_c Gamma xi~ : A_xi xi~ <= b_xi}`` and extreme wrenches."""

    generators: Generators  # enumerated: vertices and rays; else the extreme wrenches as vertices
    dim: int  # dimension of its span, <= p = rank(G_c Gamma)
    enumerated: bool = True
    A_xi: Array | None = None  # (m, p_bar) inequalities on xi~ (not enumerated)
    b_xi: Array | None = None  # (m,)
    W_xi: Array | None = None  # (D, p_bar) the map xi~ -> wrench, G_c Gamma
    unbounded_axes: int = 0  # axes along which the LP found DPFC unbounded (not enumerated)

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


def dpfc(st: Statics, fs: FrictionSet, grasp: StationaryGrasp, enumerate_up_to: int = MAX_ENUMERATION_DIM) -> DPFC:
    """Eq. (28): ``{G_c Gamma xi~ : C (f_st - Gamma xi~) <= 0}``, enumerated with cdd up to
    ``enumerate_up_to`` internal-force coordinates, else described (see the module docstring)."""
    D = st.G_c.shape[0]
    p_bar = st.Gamma.shape[1]
    if p_bar == 0:
        g = Generators(np.zeros((1, D)), np.zeros((0, D)), np.zeros((0, D)))
        return DPFC(g, 0)
    A_ub = -fs.C @ st.Gamma  # (m, p_bar)
    b_ub = -(fs.C @ grasp.f_c)  # (m,)
    W = st.G_c @ st.Gamma  # (D, p_bar)
    if p_bar > enumerate_up_to or (p_bar > SMALL_DIM and A_ub.shape[0] > MAX_ENUMERATION_ROWS):
        return _described(A_ub, b_ub, W, st.Xi)
    try:
        g_xi = polyhedron_generators(A_ub, b_ub)
    except SolverError:  # cdd's floating point gave up: the H-representation is still exact
        return _described(A_ub, b_ub, W, st.Xi)
    g_w = reduce_generators(g_xi.map(W))
    pts = np.vstack([g_w.vertices - g_w.vertices[:1], g_w.all_directions()]) if g_w.vertices.size else g_w.rays
    return DPFC(g_w, rank(pts) if pts.size else 0)


def _described(A_ub: Array, b_ub: Array, W: Array, Xi: Array) -> DPFC:
    """DPFC by its inequalities and the extreme wrenches along ``+-`` each column of ``Xi`` (an
    orthonormal basis of its span): ``max +-Xi_k^T W xi~`` s.t. ``A_ub xi~ <= b_ub``."""
    D, p = W.shape[0], Xi.shape[1]
    ext: list[Array] = []
    unbounded = 0
    box = 1e3 * max(1.0, float(np.max(np.abs(b_ub), initial=0.0)))  # keeps unbounded axes finite
    for k in range(p):
        for sign in (1.0, -1.0):
            res = solve_lp(sign * (W.T @ Xi[:, k]), A_ub=A_ub, b_ub=b_ub, lb=-box, ub=box, maximize=True)
            if res.x is None:
                continue
            ext.append(W @ res.x)
            unbounded += bool(np.max(np.abs(res.x), initial=0.0) >= box * (1 - 1e-9))
    V = np.array(ext).reshape(-1, D)
    dim = rank(V - V[:1]) if len(V) > 1 else 0
    g = Generators(V, np.zeros((0, D)), np.zeros((0, D)))
    return DPFC(g, dim, enumerated=False, A_xi=A_ub, b_xi=b_ub, W_xi=W, unbounded_axes=unbounded)
