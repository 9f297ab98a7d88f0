"""Small rotation helpers (numpy only)."""

from __future__ import annotations

import numpy as np

from analysis._types import Array


def quat_wxyz_to_matrix(q: list[float] | Array) -> Array:
    """Rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat_wxyz(R: Array) -> Array:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix (w >= 0)."""
    tr = float(np.trace(R))
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.empty(4)
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q = q / np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def axis_angle_matrix(axis: Array, angle: float) -> Array:
    """Rodrigues' formula: rotation by ``angle`` about the unit ``axis``."""
    a = np.asarray(axis, dtype=float)
    K = skew(a)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def rotz(angle: float) -> Array:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def skew(a: Array) -> Array:
    """``[a x]``: the matrix with ``skew(a) @ b == cross(a, b)``."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def rotvec_to_matrix(w: Array) -> Array:
    """Rotation by the rotation vector ``w`` (axis * angle)."""
    th = float(np.linalg.norm(w))
    if th < 1e-15:
        return np.eye(3) + skew(np.asarray(w, dtype=float))
    return axis_angle_matrix(np.asarray(w) / th, th)


def matrix_to_rotvec(R: Array) -> Array:
    """Rotation vector (axis * angle, angle in [0, pi]) of a rotation matrix."""
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])  # 2 sin(th) axis
    c = (float(np.trace(R)) - 1.0) / 2.0
    s = float(np.linalg.norm(v)) / 2.0
    th = float(np.arctan2(s, c))  # well conditioned for every angle, unlike arccos(c) near pi
    if s < 1e-300:
        return 0.5 * v if c > 0 else _half_turn_axis(R, c, v) * th
    if c > -0.5:  # th < 2 pi / 3: the axis is v / |v|
        return th / (2.0 * s) * v
    # near pi, v is small: axis from the symmetric part (R + R^T) / 2 = c I + (1 - c) a a^T,
    # its sign from v
    return _half_turn_axis(R, c, v) * th


def _half_turn_axis(R: Array, c: float, v: Array) -> Array:
    A = ((R + R.T) / 2.0 - c * np.eye(3)) / (1.0 - c)
    i = int(np.argmax(np.diag(A)))
    ax = A[:, i] / np.sqrt(max(A[i, i], 1e-300))
    return -ax if ax @ v < 0 else ax
