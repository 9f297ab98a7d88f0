"""Physical scales of a grasp: the units in which its LPs are posed and its verdicts certified.

Every verdict of the analysis rests on a solution (contact forces) that is re-checked in
physical units, never on a threshold relative to the largest value of that solution:

* the **force scale** ``F0`` [N] is the size of the external wrench, ``max(|f_ex|, |m_ex| / l)``
  (1 N when the external wrench is zero);
* the **length scale** ``l`` [m] is the object's characteristic size (its radius or
  half-diagonal), or the largest lever arm ``|p_C - p_o|`` of the contacts when no object size
  is known;
* wrenches are compared in ``(f / F0, m / (F0 l))`` and object motions in ``(v, l omega)``, so
  that a force of ``FORCE_TOL * F0`` and a moment of ``FORCE_TOL * F0 * l`` are the same error;
* the total normal force of a certificate is at most ``GRIP_BOUND * F0``: a grasp that needs more
  than a thousand times the load is reported as not holding it (eq. 18 without that bound is
  scale-free, and a solver then returns forces of 1e11 N on near-singular contact geometry, which
  no robot applies and no floating-point residual check can certify).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from analysis._types import Array

#: Residual of an equilibrium or a friction row that still counts as satisfied, in units of F0.
FORCE_TOL = 1e-6
#: Primal feasibility tolerance of the force LPs, in units of F0 (their rows are scaled so): above
#: the effect of a 1e-9 change of the contact data on forces of order F0, so that such a change
#: decides no verdict, and far below FORCE_TOL.
LP_FEAS_TOL = 1e-8
#: Residual a cached certificate may have when it is reused for another combination, in units
#: of F0: the LPs' own feasibility tolerance, so that a reused certificate is a point that
#: combination's own LP accepts (its verdict does not depend on the cache).
REUSE_TOL = LP_FEAS_TOL
#: A contact force below this (in units of F0) carries no load (a D-point is allowed it).
ZERO_FORCE = 1e-11
#: The largest total normal force of a certificate, in units of F0.
GRIP_BOUND = 1e3
#: Positive work: above this, in units of F0 times the scaled size |(v, l omega)| of the motion.
WORK_TOL = 1e-6
#: Work below this (same units) is zero; between it and WORK_TOL the verdict is degenerate.
WORK_ZERO = 1e-9


#: Entries of a scaled LP row (order one) below this are zero: a lever arm or a normal component
#: of 1e-9 is a rounding or a perturbation of exact structure (a normal through the centre), and
#: HiGHS would scale such a row up until its feasibility tolerance no longer covers that noise.
SNAP_TOL = 1e-8


def snap(A: Array, tol: float = SNAP_TOL) -> Array:
    """``A`` with the entries of magnitude below ``tol`` set to zero (a copy)."""
    out = np.array(A, dtype=float)
    out[np.abs(out) < tol] = 0.0
    return out


@dataclass(frozen=True)
class Scales:
    """Force and length scales of one grasp (see the module docstring)."""

    force: float  # F0 [N]
    length: float  # l [m]
    dim: int  # 2 or 3

    @property
    def n_force(self) -> int:
        """Number of force components of a wrench (the first rows)."""
        return self.dim

    def wrench_weights(self) -> Array:
        """``(D,)`` weights turning a wrench into units of F0: ``1/F0`` on forces, ``1/(F0 l)`` on moments."""
        D = 3 if self.dim == 2 else 6
        w = np.full(D, 1.0 / self.force)
        w[self.dim :] /= self.length
        return w

    def motion_weights(self) -> Array:
        """``(D,)`` weights of an object motion ``(v, omega)`` in metres: ``1`` and ``l``."""
        D = 3 if self.dim == 2 else 6
        w = np.ones(D)
        w[self.dim :] = self.length
        return w

    def wrench_error(self, w: Array) -> float:
        """Largest component of a wrench residual, in units of F0."""
        return float(np.max(np.abs(np.asarray(w, dtype=float) * self.wrench_weights()), initial=0.0))

    @cached_property
    def _motion_weights(self) -> Array:
        """:meth:`motion_weights`, computed once (the work thresholds are asked per direction)."""
        w = self.motion_weights()  # (D,)
        w.setflags(write=False)
        return w

    def motion_size(self, dr: Array) -> float:
        """``|(v, l omega)|`` of the object motion ``dr`` [m] (the Euclidean norm, as ``np.linalg.norm``)."""
        v = np.asarray(dr, dtype=float) * self._motion_weights  # (D,)
        return math.sqrt(float(v @ v))

    def motion_sizes(self, DR: Array) -> Array:
        """:meth:`motion_size` of each row of ``DR`` ``(m, D)``: ``(m,)``."""
        V = np.asarray(DR, dtype=float) * self._motion_weights  # (m, D)
        return np.sqrt((V * V).sum(axis=1))

    def work_tol(self, dr: Array) -> float:
        """Positive-work threshold [J per unit motion] for the object motion ``dr``."""
        return WORK_TOL * self.force * self.motion_size(dr)

    def work_zero(self, dr: Array) -> float:
        """Work below which a supremum is zero for ``dr`` (same units as :meth:`work_tol`)."""
        return WORK_ZERO * self.force * self.motion_size(dr)

    @property
    def force_tol(self) -> float:
        """Absolute force tolerance [N]."""
        return FORCE_TOL * self.force

    @property
    def zero_force(self) -> float:
        """A contact force at most this [N] carries no load."""
        return ZERO_FORCE * self.force

    @property
    def grip_bound(self) -> float:
        """Largest total normal force of a certificate [N]."""
        return GRIP_BOUND * self.force


def grasp_scales(dim: int, w_ex: Array, lever_arms: Array, object_size: float | None = None) -> Scales:
    """The scales of a grasp from its external wrench ``(D,)``, the lever arms ``(L, d)`` of its
    contacts and (when known) the object's characteristic size."""
    arms = np.asarray(lever_arms, dtype=float)
    length = float(object_size) if object_size is not None and object_size > 0 else 0.0
    if length <= 0.0:
        length = float(np.max(np.linalg.norm(arms, axis=1), initial=0.0)) if arms.size else 0.0
    if not np.isfinite(length) or length <= 0.0:
        length = 1.0
    w = np.asarray(w_ex, dtype=float)
    force = max(float(np.linalg.norm(w[:dim])), float(np.linalg.norm(w[dim:])) / length)
    if not np.isfinite(force) or force <= 0.0:
        force = 1.0
    return Scales(force=force, length=length, dim=dim)
