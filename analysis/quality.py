"""Grasp quality beside closure: the DPFC wrench ball (paper eq. 28) and the Ferrari-Canny epsilon.

Both radii are measured in the wrench metric of the object's characteristic length ``l``
(:class:`analysis.scales.Scales`): ``|w|_l = |(f, m / l)|_2`` [N], so that scaling the scene by
a length factor leaves them unchanged.

* **DPFC wrench ball** ``r_p``: with the joint torques held at ``tau_st`` (18), the external
  perturbations resisted are exactly ``P = D_DPFC = {G_c Gamma xi~ : C (f_st - Gamma xi~) <= 0}``
  (28) (by (27) ``-w_p - w_ex = G_c (f_st - Gamma xi~_p)``; the set depends on ``tau_st`` only).
  ``r_p = max {r : |w|_l <= r  =>  w in P}``, the distance in ``|.|_l`` from ``0`` (the scene's
  own external wrench) to the boundary of ``P``: ``min_i b_i / |S^-1 a_i|_2`` over the facets
  ``a_i^T w <= b_i`` of ``P`` (``S = diag(1, 1/l)``), ``0`` when ``P`` has empty interior. The
  facets come from cdd (the V-representation of an enumerated DPFC converted to inequalities in
  wrench space; redundant rows cannot lower the minimum). A DPFC given only by its description
  in ``xi~`` is handled when ``W_xi = G_c Gamma`` is square and invertible; otherwise ``None``.
* **Ferrari-Canny epsilon** (L1, "sum" version as in GraspIt!): the radius of the largest
  origin-centred ``|.|_l`` ball in ``conv{G_c e_j}``, ``e_j`` the columns of the friction-set
  generators ``E`` (16) of the combination (F-point: the pyramid edges ``n + mu t_j`` of
  :mod:`analysis.friction_cone`, unit normal force; N/S-point: the normal; D-point: none), via
  qhull (scipy ``ConvexHull``); ``0`` when the origin is not interior. The all-F combination
  gives the classic epsilon of the contact set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from analysis._types import Array
from analysis.contacts import GraspSystem, selection
from analysis.dpfc import DPFC, dpfc
from analysis.exceptions import NoStationaryGrasp
from analysis.friction import FrictionSet, friction_set
from analysis.scales import Scales
from analysis.solvers.cdd import generators_to_inequalities
from analysis.statics import Statics, statics
from analysis.stationary import stationary_grasp

#: Relative rank tolerance (singular values / largest) below which a point set has empty interior.
RANK_TOL = 1e-9


@dataclass(frozen=True)
class BallRadius:
    """A ball radius ``r`` [N in the ``l`` metric] and the unit (``|.|_l``) wrench of its nearest facet."""

    radius: float | None  # None: not computed (reason says why)
    weakest: Array | None  # (D,) unit direction in which the boundary is nearest
    reason: str


def _metric(sc: Scales, D: int) -> Array:
    """``(D,)`` diagonal of ``S``: ``|w|_l = |S w|_2`` (1 on forces, 1/l on moments)."""
    s = np.ones(D)
    s[sc.dim :] = 1.0 / sc.length
    return s


def _radius_from_facets(A: Array, b: Array, s: Array) -> tuple[float, Array]:
    """``min_i b_i / |S^-1 a_i|`` over facets ``A w <= b`` ``(m, D)``, and the nearest point's
    direction in ``|.|_l`` (unit)."""
    An = A / s[None, :]  # rows of A S^-1: facets in the scaled coordinates u = S w
    nrm = np.linalg.norm(An, axis=1)
    keep = nrm > 0.0
    d = b[keep] / nrm[keep]
    k = int(np.argmin(d))
    u = An[keep][k] / nrm[keep][k]
    return max(float(d[k]), 0.0), u


def wrench_ball(dp: DPFC, sc: Scales) -> BallRadius:
    """The DPFC wrench ball radius ``r_p`` around the scene's external wrench (module docstring)."""
    D = dp.generators.vertices.shape[1] if dp.generators.vertices.size else 3 if sc.dim == 2 else 6
    s = _metric(sc, D)
    if dp.dim < D:
        return BallRadius(0.0, None, f"DPFC has dimension {dp.dim} < {D}: empty interior")
    if dp.enumerated:
        A, b, flat = generators_to_inequalities(dp.generators)
        if flat:
            return BallRadius(0.0, None, "DPFC lies in a hyperplane: empty interior")
        if not len(b):
            return BallRadius(np.inf, None, "DPFC is the whole wrench space")
        r, u = _radius_from_facets(A, b, s)
        return BallRadius(r, u, "facets of the enumerated DPFC (cdd)")
    assert dp.A_xi is not None and dp.b_xi is not None and dp.W_xi is not None
    W = dp.W_xi
    if W.shape[0] == W.shape[1] and np.linalg.matrix_rank(W) == D:
        A = dp.A_xi @ np.linalg.inv(W)  # xi~ = W^-1 w
        r, u = _radius_from_facets(A, dp.b_xi, s)
        return BallRadius(r, u, "inequalities of the DPFC description mapped by W_xi^-1")
    return BallRadius(None, None, "not computed: DPFC not enumerated and G_c Gamma not invertible")


def primitive_wrenches(st: Statics, fs: FrictionSet) -> Array:
    """``(g, D)`` contact wrenches of unit normal force: ``(G_c E)^T``."""
    return (st.G_c @ fs.E).T


def epsilon(st: Statics, fs: FrictionSet, sc: Scales) -> BallRadius:
    """Ferrari-Canny epsilon, L1 ("sum") version: the largest origin-centred ``|.|_l`` ball in the
    convex hull of :func:`primitive_wrenches` (qhull); 0 when the origin is not interior."""
    Wp = primitive_wrenches(st, fs)
    D = st.G_c.shape[0]
    U = Wp * _metric(sc, D)[None, :]  # scaled coordinates: the ball is Euclidean there
    if U.shape[0] <= D:
        return BallRadius(0.0, None, f"{U.shape[0]} primitive wrenches cannot span {D} dimensions")
    sv = np.linalg.svd(U - U.mean(axis=0), compute_uv=False)
    if sv[-1] <= RANK_TOL * sv[0]:
        return BallRadius(0.0, None, "the primitive wrenches span less than the wrench space")
    try:
        hull = ConvexHull(U)
    except QhullError as e:  # degenerate input qhull cannot triangulate
        return BallRadius(0.0, None, f"qhull: {str(e).splitlines()[0]}")
    dist = -hull.equations[:, -1]  # unit outward normals n, n^T u + c <= 0 inside: distance of 0 is -c
    k = int(np.argmin(dist))
    if dist[k] <= 0.0:
        return BallRadius(0.0, hull.equations[k, :-1], "the origin is not interior to the hull")
    return BallRadius(float(dist[k]), hull.equations[k, :-1], "qhull facets of the primitive wrenches")


@dataclass(frozen=True)
class GraspQuality:
    """Both radii of one combination [N in the ``l`` metric]: the DPFC wrench ball around the
    interior stationary grasp and the Ferrari-Canny epsilon of its friction set."""

    combination: str
    wrench_ball: BallRadius
    epsilon: BallRadius
    length: float  # l [m], the metric's length

    def to_json(self) -> dict[str, object]:
        r = self.wrench_ball.radius
        return {"wrench_ball": None if r is None or not np.isfinite(r) else r,
                "wrench_ball_reason": self.wrench_ball.reason, "epsilon": self.epsilon.radius,
                "epsilon_reason": self.epsilon.reason, "metric_length": self.length}


def combination_quality(system: GraspSystem, combination: str) -> GraspQuality | None:
    """:class:`GraspQuality` of a combination with a stationary grasp (18); ``None`` without one."""
    sel = selection(system, combination)
    st, fs = statics(system, sel), friction_set(system, sel)
    try:
        grasp = stationary_grasp(system, sel, st, fs)
    except NoStationaryGrasp:
        return None
    sc = system.scales
    return GraspQuality(sel.combination, wrench_ball(dpfc(st, fs, grasp), sc), epsilon(st, fs, sc), sc.length)
