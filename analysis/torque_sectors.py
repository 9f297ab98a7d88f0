"""A certificate that problem (31) has no solution for one object direction, in 3-D.

Problem (31) (:mod:`analysis.solvers.casadi_nlp`) asks, for the unit direction ``u``, for a
redundancy ``dzeta~_r`` and contact forces ``f_c`` with

    B [u; dzeta~_r] <= 0,   |slip_k| >= delta,   C f_c <= 0,
    Xi^T w = 0,   N_u^T Lambda~_r^T w = 0,   u^T Lambda~_r^T w >= w_min,
    w = G_c f_c - sum_k mu_k n_k G_k slip_k / |slip_k| + w_ex          (eq. 12)

(``slip_k = P_k [u; dzeta~_r]``, ``n_k`` the S-point's normal force). In the plane a unit slip
is one of two tangents and (31) is ``2^#S`` LPs (:func:`analysis.torques.planar_slip_patterns`).
In 3-D the unit slip ranges over a circle; :func:`slip_sector_screen` is a branch and bound over
arcs of it (sectors, as the DAFC search :func:`analysis.dafc.slip_sector_search`). A box gives
each S-point's slip angle (tangent coordinates ``sigma_k = T_k slip_k``) an interval; (31) with
the slips in the box implies two LPs, each a necessary condition:

* **motion**: ``B_r z <= -B_u u`` and every ``sigma_k`` in its sector at least
  ``delta cos h_k`` along the bisector (``|sigma_k| >= delta`` and half-width ``h_k``);
* **forces**: the friction of an S-point with slip angle in ``[a, b]`` is
  ``-G_k T_k^T (alpha_a e(a) + alpha_b e(b))`` with ``alpha >= 0`` and
  ``c mu n <= alpha_a + alpha_b <= mu n / cos h`` (the band between the arc's chord and its
  tangents, which holds every point of the arc; a free point: a polygon circumscribing the
  disc ``mu n``), with the rows of (31) on ``w``. ``c = 1 / sqrt(1 + SLIP_SMOOTH / delta^2)``
  (``1 - 5e-5``) also admits the slightly shorter unit slip IPOPT is given
  (:data:`analysis.solvers.casadi_nlp.SLIP_SMOOTH`), so a proof covers both forms of (31).

If either is infeasible the box holds no solution of (31). Before the force LP each sector is
narrowed to the angles the box's motions really have: the generators of the motion polyhedron
(cdd) map to the slips, whose cone is the cone of their non-zero images; the arc they span,
widened by :data:`analysis.dafc.SECTOR_WIDEN`, holds every slip of the box of length at least
``delta`` (the images at or below :data:`ZERO_SLIP` are dropped; the angle they can move a slip
of length ``delta`` by is below ``ZERO_SLIP / delta``, under the widening; rays are unit, and a
ray whose image is that small lies in the slip map's null space to rounding: the same caveat as
:func:`analysis.dafc._tighten`). An S-point whose slip does not depend on the redundancy gets its
friction direction exactly.

**Which problem is decided.** Every row is given IPOPT's own slack
(:data:`analysis.solvers.casadi_nlp.CONSTR_VIOL_TOL`, absolute, as IPOPT applies it), so the
proof covers every point IPOPT can return as ``Solve_Succeeded``, not only the exact (31). This
matters for the slip: ``|s|^2 >= delta^2 = 1e-8`` within 1e-9 lets ``|s|`` go down to
``0.95 delta``, and IPOPT's answers do use that (allegro_right_box SDFDFS: a palm slip fixed by
the direction at ``0.9487e-4``). With ``delta`` exact the screen would prove such directions
infeasible and the reports would change; with the slack they do not. (IPOPT's
``Solved_To_Acceptable_Level`` tolerates more; the screen does not follow it there.)

Every box pruned: ``infeasible = True``. Otherwise (a leaf of half-width :data:`MIN_HALF` still
feasible, or :data:`SCREEN_BUDGET` boxes) the screen decides nothing and IPOPT runs as before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.dafc import SECTOR_FREE_SIDES, SECTOR_WIDEN, Sector, sector_half, sector_rows, split_sector, unit_angle
from analysis.exceptions import SolverError
from analysis.solvers.casadi_nlp import CONSTR_VIOL_TOL, SLIP_SMOOTH, RedundancyNLP
from analysis.solvers.cdd import polyhedron_generators
from analysis.solvers.highs import solve_lp

#: Boxes examined per direction at most: a direction with a solution of (31) costs at most this
#: many pairs of LPs before IPOPT runs (the infeasible directions met in 3-D reports took 1 to 9).
SCREEN_BUDGET = 10
#: Half-width (radians) below which a box whose LPs are feasible is a leaf: the screen stops.
MIN_HALF = np.pi / 64
#: Slip images (tangent coordinates, per unit generator) at or below this count as zero.
ZERO_SLIP = 1e-12
#: Slack of every row of (31) in both LPs: IPOPT's own tolerance (it accepts points that violate
#: a constraint by this much), so that a proof covers every point IPOPT could return as solved.
ROW_SLACK = CONSTR_VIOL_TOL


@dataclass(frozen=True)
class SlipScreen:
    """The answer of :func:`slip_sector_screen` for one direction."""

    infeasible: bool  # every box pruned: (31) has no solution for this direction
    boxes: int  # sector boxes examined
    lps: int  # LPs solved
    reason: str


def _slip_floor(p: RedundancyNLP) -> float:
    """The least slip IPOPT may accept for ``|slip|^2 >= slip_min^2`` (its slack :data:`ROW_SLACK`
    is absolute: ``sqrt(1e-8 - 1e-9)``, 5 % below ``slip_min = 1e-4``, which IPOPT's answers do use)."""
    return float(np.sqrt(max(p.slip_min**2 - ROW_SLACK, 0.0)))


def _narrow(images: Array, sec: Sector) -> tuple[Sector, bool]:
    """The sector ``sec`` narrowed to the cone of the non-zero slip ``images`` ``(k, 2)`` (tangent
    coordinates), and whether no angle of ``sec`` is left. A free point is narrowed only to an
    arc of half-width at most pi/4 (the band of a wider arc is loose)."""
    big = np.sqrt((images * images).sum(axis=1)) > ZERO_SLIP
    if not big.any():
        return sec, False  # every slip is zero: the motion LP's margin has excluded that already
    theta = np.arctan2(images[big, 1], images[big, 0])  # (k',)
    if sec is None:
        t = np.sort(np.mod(theta, 2 * np.pi))
        gaps = np.diff(np.r_[t, t[0] + 2 * np.pi])  # the gap after each angle
        g = int(gaps.argmax())
        if gaps[g] <= np.pi:
            return None, False  # the images' cone is not pointed: any angle
        lo = float(t[(g + 1) % len(t)])
        hi = lo + 2 * np.pi - float(gaps[g])
        if 0.5 * (hi - lo) + SECTOR_WIDEN <= np.pi / 4:
            return (lo - SECTOR_WIDEN, hi + SECTOR_WIDEN), False
        return None, False
    a, b = sec
    if b <= a:
        return sec, False
    m = 0.5 * (a + b)
    phi = np.mod(theta - m + np.pi, 2 * np.pi) - np.pi  # (k',) angle from the bisector
    lo, hi = max(a, m + float(phi.min()) - SECTOR_WIDEN), min(b, m + float(phi.max()) + SECTOR_WIDEN)
    if lo > hi:
        return sec, True
    return (lo, hi), False


def _force_lp(p: RedundancyNLP, T: Array, box: tuple[Sector, ...]) -> bool:
    """Is the force LP of the box (module docstring) feasible? ``T`` ``(#S, 2, 3)`` tangents."""
    L_c, D = p.C.shape[1], p.G_c.shape[0]
    cols: list[Array] = []  # (D,) per friction unknown
    rows: list[dict[int, float]] = []  # sparse rows over [f_c; t] <= 0
    c_min = 1.0 / np.sqrt(1.0 + SLIP_SMOOTH / _slip_floor(p) ** 2)  # the shortest unit slip IPOPT may use
    for k, sec in enumerate(box):
        G, mu, n_col = p.G_s_blocks[k], float(p.mu_s[k]), p.s_cols[k]  # (D, 3)
        first = L_c + len(cols)
        if sec is None:
            ang = 2 * np.pi * np.arange(SECTOR_FREE_SIDES) / SECTOR_FREE_SIDES
            r_mu = mu / np.cos(np.pi / SECTOR_FREE_SIDES)
            cols += [G @ T[k][0], G @ T[k][1]]  # the friction itself, tangent coordinates
            rows += [{first: float(np.cos(t)), first + 1: float(np.sin(t)), n_col: -r_mu} for t in ang]
        else:
            h = sector_half(sec)
            cols += [-(G @ (T[k].T @ unit_angle(th, 3))) for th in sec]  # against the slip
            rows.append({first: -1.0, first + 1: -1.0, n_col: c_min * mu})
            rows.append({first: 1.0, first + 1: 1.0, n_col: -mu / np.cos(h)})
    n = L_c + len(cols)
    W = np.hstack([p.G_c, np.array(cols).T.reshape(D, -1)])  # (D, n): w = W x + w_ex
    LrT = p.Lambda_r_t.T  # (a_bar, D)
    m_c = p.C.shape[0]
    E = np.vstack([p.Xi.T @ W, p.N_u.T @ LrT @ W])  # (p + a_bar - 1, n): E x = e within the slack
    e = np.concatenate([-(p.Xi.T @ p.w_ex), -(p.N_u.T @ LrT @ p.w_ex)])
    A_ub = np.zeros((m_c + len(rows) + 1, n))
    b_ub = np.zeros(A_ub.shape[0])
    A_ub[:m_c, :L_c] = p.C
    b_ub[:m_c] = ROW_SLACK
    for i, entries in enumerate(rows):
        for j, v in entries.items():
            A_ub[m_c + i, j] = v
    A_ub[-1] = -(p.u @ LrT @ W)  # u^T Lambda~_r^T w >= w_min
    b_ub[-1] = float(p.u @ LrT @ p.w_ex) - p.w_min + ROW_SLACK
    A_ub = np.vstack([A_ub, E, -E])
    b_ub = np.concatenate([b_ub, e + ROW_SLACK, -e + ROW_SLACK])
    lb = np.r_[np.full(L_c, -np.inf), [0.0 if sec is not None else -np.inf for sec in box for _ in range(2)]]
    res = solve_lp(np.zeros(n), A_ub, b_ub, lb=lb)
    if res.status not in ("optimal", "infeasible"):
        raise SolverError("HiGHS", f"the force LP of the (31) screen ended '{res.status}'")
    return res.found


def slip_sector_screen(p: RedundancyNLP, T: Array, budget: int = SCREEN_BUDGET) -> SlipScreen:
    """Is problem (31) for the direction ``p.u`` infeasible? (module docstring). ``T`` ``(#S, 2, 3)``
    are the S-points' tangent bases. The answer ``infeasible = True`` is a proof (both LPs of
    every box are relaxations); ``False`` decides nothing. Not for the plane, nor for S-points
    whose slip has a normal component (the sector rows measure the tangential part)."""
    a_bar, r = p.u.shape[0], p.Lambda_qr_t.shape[1]
    nS = len(p.s_cols)
    P = p.P_s.reshape(nS, 3, -1)  # (#S, 3, a)
    normal = np.array([float(np.linalg.norm(P[k] - T[k].T @ (T[k] @ P[k]))) for k in range(nS)])
    if P.size and float(normal.max()) > 1e-9 * max(1.0, float(np.abs(P).max())):
        return SlipScreen(False, 0, 0, "an S-point's slip has a normal component: not screened")
    S0 = np.einsum("kij,kja->kia", T, P[:, :, :a_bar]) @ p.u  # (#S, 2) slip at zero redundancy
    Sz = np.einsum("kij,kja->kia", T, P[:, :, a_bar:])  # (#S, 2, r)
    B_u, B_r = p.B[:, :a_bar], p.B[:, a_bar:]
    stack: list[tuple[Sector, ...]] = [tuple(None for _ in range(nS))]
    boxes = lps = 0
    while stack:
        if boxes >= budget:
            return SlipScreen(False, boxes, lps, f"budget of {budget} boxes spent")
        box = stack.pop()
        boxes += 1
        A: list[Array] = [B_r]
        b: list[Array] = [-(B_u @ p.u) + ROW_SLACK]
        for k, sec in enumerate(box):
            h = min(sector_half(sec), 0.5 * np.pi)
            R, rhs = sector_rows(sec, 3, _slip_floor(p) * np.cos(h))
            if R.shape[0]:
                A.append(-(R @ Sz[k]))  # R (S0 + Sz z) >= rhs
                b.append(R @ S0[k] - rhs)
        A_z, b_z = np.vstack(A).reshape(-1, r), np.concatenate(b)
        res = solve_lp(np.zeros(r), A_z, b_z)
        lps += 1
        if res.status not in ("optimal", "infeasible"):
            raise SolverError("HiGHS", f"the motion LP of the (31) screen ended '{res.status}'")
        if not res.found:
            continue  # no allowable motion slides with these slip angles
        try:
            g = polyhedron_generators(A_z, b_z)
        except SolverError:
            g = None  # cdd failed: the sectors stay as they are (a weaker, still valid force LP)
        narrowed: list[Sector] = []
        dead = False
        for k, sec in enumerate(box):
            if g is None:
                narrowed.append(sec)
                continue
            images = np.vstack([S0[k] + g.vertices @ Sz[k].T, g.rays @ Sz[k].T, g.lines @ Sz[k].T,
                                -(g.lines @ Sz[k].T)])  # (k, 2)
            new, gone = _narrow(images, sec)
            narrowed.append(new)
            dead = dead or gone
        if dead:
            continue
        box = tuple(narrowed)
        lps += 1
        if not _force_lp(p, T, box):
            continue  # no forces balance with friction in these sectors
        widest = max(range(nS), key=lambda q: sector_half(box[q]))
        if sector_half(box[widest]) <= MIN_HALF:
            return SlipScreen(False, boxes, lps, "a leaf box is feasible")
        stack.extend((*box[:widest], child, *box[widest + 1:]) for child in split_sector(box[widest], 3))
    return SlipScreen(True, boxes, lps, f"no slip-sector box admits a solution ({boxes} boxes, {lps} LPs)")
