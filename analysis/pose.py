"""The object pose: one type for the plane and for space.

A :class:`Pose` is the object frame's origin ``p_o`` ``(d,)`` and its rotation ``R`` ``(3, 3)``
(about ``z`` in 2-D). Its coordinates, and the displacement ``dr`` of the paper's object motions
(eq. 30-32), are ``D``-vectors:

* 2-D: ``(x, y, theta)``, a displacement ``(dx, dy, dtheta)`` with ``R = rotz(dtheta) R_0``;
* 3-D: ``(x, y, z, r)`` with ``r`` the rotation vector of ``R``, a displacement ``(dp, w)`` with
  ``w`` a world rotation vector, ``R = exp([w]x) R_0``.

So ``pose.displaced(s).displacement_from(pose) == s`` (for rotations below pi), and the ``if dim
== 2`` branches live here only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis._types import Array
from analysis.rotations import matrix_to_quat_wxyz, matrix_to_rotvec, quat_wxyz_to_matrix, rotvec_to_matrix, rotz


@dataclass(frozen=True)
class Pose:
    """Object pose: ``position`` ``(d,)`` (``p_o``) and ``rotation`` ``(3, 3)``, for ``dim`` 2 or 3."""

    position: Array  # (d,)
    rotation: Array  # (3, 3)
    dim: int

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, not {self.dim}")
        p = np.asarray(self.position, dtype=float).reshape(-1)
        R = np.asarray(self.rotation, dtype=float)
        if p.shape != (self.dim,) or R.shape != (3, 3):
            raise ValueError(f"a {self.dim}-D pose needs position ({self.dim},) and rotation (3, 3), "
                             f"not {p.shape} and {R.shape}")
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "rotation", R)

    # -- construction ---------------------------------------------------------------------------

    @classmethod
    def identity(cls, dim: int) -> Pose:
        return cls(np.zeros(dim), np.eye(3), dim)

    @classmethod
    def from_vector(cls, v: Array | list[float], dim: int) -> Pose:
        """From coordinates ``(D,)``: 2-D ``(x, y, theta)``, 3-D ``(x, y, z, r)`` (rotation vector)."""
        v = np.asarray(v, dtype=float).reshape(-1)
        if v.shape != (3 * (dim - 1),):
            raise ValueError(f"a {dim}-D pose has {3 * (dim - 1)} coordinates, not {v.size}")
        return cls(v[:dim], cls._rotation(v[dim:]), dim)

    @classmethod
    def from_fields(cls, position: list[float] | Array, dim: int, angle: float | None = None,
                    quat_wxyz: list[float] | Array | None = None) -> Pose:
        """From a scene's ``pose`` fields: ``position`` with ``angle`` (2-D) or ``quat_wxyz`` (3-D)."""
        if dim == 2:
            R = rotz(float(angle or 0.0))
        else:
            R = quat_wxyz_to_matrix(quat_wxyz if quat_wxyz is not None else [1.0, 0.0, 0.0, 0.0])
        return cls(np.asarray(position, dtype=float), R, dim)

    @staticmethod
    def _rotation(w: Array) -> Array:
        """``R`` of a rotation ``(1,)`` (angle about z) or ``(3,)`` (rotation vector)."""
        return rotz(float(w[0])) if w.size == 1 else rotvec_to_matrix(w)

    # -- coordinates ----------------------------------------------------------------------------

    @property
    def D(self) -> int:
        """Number of object coordinates: 3 in the plane, 6 in space."""
        return 3 * (self.dim - 1)

    @property
    def R_d(self) -> Array:
        """The rotation's ``(d, d)`` block (acts on points and normals of the object frame)."""
        return self.rotation[: self.dim, : self.dim]

    @property
    def angle(self) -> float:
        """2-D: the rotation angle about z in (-pi, pi]."""
        return float(np.arctan2(self.rotation[1, 0], self.rotation[0, 0]))

    def rotation_coordinates(self) -> Array:
        """2-D ``(theta,)``; 3-D the rotation vector ``(3,)`` (angle in [0, pi])."""
        return np.array([self.angle]) if self.dim == 2 else matrix_to_rotvec(self.rotation)

    def vector(self) -> Array:
        """Coordinates ``(D,)``: 2-D ``(x, y, theta)``; 3-D ``(x, y, z, r)``."""
        return np.concatenate([self.position, self.rotation_coordinates()])

    def fields(self) -> dict[str, Any]:
        """The scene's ``pose`` fields (``position`` and ``angle`` or ``quat_wxyz``), JSON-ready."""
        out: dict[str, Any] = {"position": [float(x) for x in self.position]}
        if self.dim == 2:
            out["angle"] = self.angle
        else:
            out["quat_wxyz"] = [float(x) for x in matrix_to_quat_wxyz(self.rotation)]
        return out

    # -- displacements (the paper's dr) -----------------------------------------------------------

    def displaced(self, s: Array) -> Pose:
        """The pose moved by the displacement ``s`` ``(D,)``: ``p = p_0 + dp``, ``R = exp(w) R_0``."""
        s = np.asarray(s, dtype=float).reshape(-1)
        if s.shape != (self.D,):
            raise ValueError(f"a {self.dim}-D displacement has {self.D} values, not {s.size}")
        d = self.dim
        return Pose(self.position + s[:d], self._rotation(s[d:]) @ self.rotation, d)

    def displacement_from(self, start: Pose) -> Array:
        """The displacement ``s`` ``(D,)`` with ``start.displaced(s) == self`` (3-D: rotation below pi;
        2-D: the angle difference as given, not wrapped)."""
        d = self.dim
        dp = self.position - start.position
        if d == 2:
            return np.array([*dp, self.angle - start.angle])
        return np.concatenate([dp, matrix_to_rotvec(self.rotation @ start.rotation.T)])

    def shortest_displacement_from(self, start: Pose) -> Array:
        """The displacement ``s`` ``(D,)`` from ``start`` by the shortest rotation: ``dp`` and the
        rotation coordinates of ``R R_start^T`` (3-D: the same as :meth:`displacement_from`; 2-D: the
        angle difference wrapped into (-pi, pi], so a small turn across ``theta = pi`` stays small)."""
        turn = Pose(np.zeros(self.dim), self.rotation @ start.rotation.T, self.dim)
        return np.concatenate([self.position - start.position, turn.rotation_coordinates()])

    def rotation_angle_to(self, other: Pose) -> float:
        """The angle ``(>= 0)`` of the rotation from ``other`` to this pose (2-D: wrapped to pi)."""
        if self.dim == 2:
            return abs(math.remainder(self.angle - other.angle, 2 * math.pi))
        return float(np.linalg.norm(matrix_to_rotvec(self.rotation @ other.rotation.T)))

    def distance(self, other: Pose, size: float) -> float:
        """``|dp| + size |dtheta|``: metres and radians made one length by the object size."""
        return float(np.linalg.norm(self.position - other.position)) + size * self.rotation_angle_to(other)

    # -- frames -----------------------------------------------------------------------------------

    def to_world(self, p_local: Array) -> Array:
        """World point ``(d,)`` of a point ``(d,)`` in the object frame."""
        return self.position + self.R_d @ np.asarray(p_local, dtype=float)

    def to_local(self, p_world: Array) -> Array:
        """Object-frame point ``(d,)`` of a world point ``(d,)``."""
        return self.R_d.T @ (np.asarray(p_world, dtype=float) - self.position)
