"""Friction sets (paper eq. 11-17) as linear constraints on ``f_c``.

``f_c`` stacks, per contact in scene order, the full force of an F-point (``d`` components,
world frame) and the normal component of an S- or N-point (one scalar); D-points carry no
force. The friction set ``F`` (16) is ``{f_c : C f_c <= 0}``:

* F-point (13): 2-D exactly, ``|t^T f| <= mu n^T f``; 3-D the ``k``-sided pyramid inscribed in
  the cone (facets and generators in :mod:`analysis.friction_cone`);
* N-point and the normal of an S-point (14): ``n_f >= 0``;
* the tangential force of an S-point (15, 11) is kinetic friction ``t = -mu n_f s`` against the
  unit slip ``s`` of the object relative to the finger; it is linear in ``n_f`` once ``s`` is
  fixed (:func:`kinetic_friction`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis._types import Array
from analysis.contacts import GraspSystem, Selection
from analysis.friction_cone import friction_pyramid
from analysis.scales import snap


@dataclass(frozen=True)
class FrictionSet:
    """``F = {f_c : C f_c <= 0}`` (eq. 16), its generators, and normal-force read-out."""

    C: Array  # (m, L_c) friction rows, each of unit norm
    row_contact: Array  # (m,) contact index of each row
    E: Array  # (L_c, g) generators: F = {E lam, lam >= 0}
    N: Array  # (L, L_c) normal force of each contact: n_f = N f_c (zero rows for D-points)

    def contains(self, f_c: Array, tol: float = 1e-7) -> bool:
        scale = max(1.0, float(np.max(np.abs(f_c), initial=0.0)))
        return bool(np.all(self.C @ f_c <= tol * scale))

    def violation(self, f_c: Array) -> float:
        """Largest violation ``max(C f_c)`` (<= 0 inside)."""
        return float(np.max(self.C @ f_c, initial=0.0))


def friction_set(system: GraspSystem, sel: Selection, mu_scale: float = 1.0) -> FrictionSet:
    """Eq. (13), (14), (16) for the combination ``sel``; ``mu_scale`` (``nu``) scales every mu."""
    d, k = system.d, system.friction_sides
    L_c = sel.L_c
    row_blocks: list[Array] = []
    owners: list[Array] = []
    gen_blocks: list[Array] = []
    N = np.zeros((system.L, L_c))
    for i, s in enumerate(sel.combination):
        sl = sel.c_slices[i]
        if s == "D":
            continue
        n = system.normals[i]
        mu = mu_scale * system.mu[i]
        if s == "F":
            N[i, sl] = snap(n)  # the grip rows of the LPs: noise-level components 0
            if mu == 0.0:
                # a frictional contact at nu = 0: normal force >= 0, tangential force zero
                T = system.tangents[i]
                facets = np.vstack([-n[None, :], T, -T])
                gdirs = n[None, :]
            elif mu_scale == 1.0:
                facets, gdirs = system.pyramid[0][i], system.pyramid[1][i]
            else:
                facets, gdirs = friction_pyramid(n, system.tangents[i], mu, d, k)
            rows = np.zeros((len(facets), L_c))
            rows[:, sl] = snap(facets / np.linalg.norm(facets, axis=1, keepdims=True))  # noise-level entries 0
            gens = np.zeros((len(gdirs), L_c))
            gens[:, sl] = gdirs
        else:  # S or N: scalar normal force >= 0
            N[i, sl] = 1.0
            rows = np.zeros((1, L_c))
            rows[0, sl] = -1.0
            gens = np.zeros((1, L_c))
            gens[0, sl] = 1.0
        row_blocks.append(rows)
        owners.append(np.full(len(rows), i, dtype=int))
        gen_blocks.append(gens)
    C = np.vstack(row_blocks) if row_blocks else np.zeros((0, L_c))
    E = np.vstack(gen_blocks).T if gen_blocks else np.zeros((L_c, 0))
    return FrictionSet(C, np.concatenate(owners) if owners else np.zeros(0, dtype=int), E, N)


@dataclass(frozen=True)
class KineticFriction:
    """Kinetic friction of the S-points for a fixed slip (eq. 11-12), per unit normal force.

    The friction force on the object at S-point ``i`` is ``t_i = -mu_i n_i s_i`` with ``s_i``
    the unit slip of the object relative to the finger; it adds ``G_w @ f_c`` to the wrench
    on the object and ``J_w @ f_c`` to the joint torque (``tau = J^T f``).
    """

    slips: Array  # (#S, d) unit slip directions, scene order of S-points
    mu_s: Array  # (#S,) friction coefficients used (nu * mu)
    G_w: Array  # (D, L_c)  wrench of the friction forces, linear in the S normal forces
    J_w: Array  # (M, L_c)  joint torque that balances them

    def forces(self, system: GraspSystem, sel: Selection, f_c: Array) -> Array:
        """Tangential friction forces ``(#S, d)`` for the normal forces in ``f_c``."""
        out = np.zeros((len(sel.s_index), system.d))
        for k, i in enumerate(sel.s_index):
            n_f = float(f_c[sel.c_slices[i]][0])
            out[k] = -self.mu_s[k] * n_f * self.slips[k]
        return out


def slips(system: GraspSystem, sel: Selection, A_full_motion: Array) -> Array:
    """Slip ``dp_C = dp_CO - dp_CF = -A_i [dq; dr]`` of each S-point: ``(#S, d)``."""
    out = np.zeros((len(sel.s_index), system.d))
    for k, i in enumerate(sel.s_index):
        out[k] = -system.contact_A(i) @ A_full_motion
    return out


def kinetic_friction(
    system: GraspSystem, sel: Selection, slip: Array, mu_scale: float = 1.0
) -> KineticFriction:
    """Friction columns of eq. (12) for given slips ``(#S, d)`` (normalised here)."""
    L_c = sel.L_c
    G_w = np.zeros((system.D, L_c))
    J_w = np.zeros((system.M, L_c))
    units = np.zeros((len(sel.s_index), system.d))
    mu_s = np.zeros(len(sel.s_index))
    for k, i in enumerate(sel.s_index):
        s = np.asarray(slip[k], dtype=float)
        norm = float(np.linalg.norm(s))
        if norm == 0.0:
            raise ValueError(f"S-point {i} has zero slip: kinetic friction direction undefined")
        s = s / norm
        units[k] = s
        col = sel.c_slices[i].start
        mu_s[k] = mu_scale * system.mu[i]
        t = -mu_s[k] * s  # friction force per unit normal force
        G_w[:, col] = system.G_blocks[i] @ t
        J_w[:, col] = system.J_blocks[i].T @ t
    return KineticFriction(units, mu_s, G_w, J_w)
