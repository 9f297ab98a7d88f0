"""Planned paths in the continuous plan replay: finger joint profiles and the object's deviation.

A plan step gives joint waypoints ``joint_path`` ``(n, M)`` and object pose vectors
``object_path`` ``(k, D)`` (2-D ``(x, y, theta)``, 3-D ``(p, rotation vector)``; the object
motions of eq. 30-32). :func:`driven_profile` turns the joint path into a smooth motion in time
for the fingers that :mod:`sim.plan_replay` drives kinematically, :func:`move_time` says how long
that motion takes, and :func:`path_deviation` measures how far the simulated object is from its
planned path in the metric ``|dp| + s |dtheta|`` (:meth:`analysis.pose.Pose.distance`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.pose import Pose
from sim.torque_replay import smooth_ramp

#: Joints ``(M,)`` selected (e.g. those of the driven fingers).
Mask = NDArray[np.bool_]


def joint_speed_ratio(q_path: Array, object_path: Array) -> float | None:
    """``phi`` of an object motion (eq. 31: joint speed per unit object speed): the joint path's
    length ``sum |dq|`` ``(n, M)`` over the object path's ``sum |dr|`` ``(k, D)``, pose-vector
    differences (the paper's metric of ``dr``); ``None`` when the object does not move."""
    L_r = float(np.sum(np.linalg.norm(np.diff(np.asarray(object_path, dtype=float), axis=0), axis=1)))
    L_q = float(np.sum(np.linalg.norm(np.diff(np.asarray(q_path, dtype=float), axis=0), axis=1)))
    return L_q / L_r if L_r > 0 else None


def path_deviation(pose: Pose, path: Array, s: float) -> float:
    """Distance of ``pose`` from the polyline of pose vectors ``path`` ``(k, D)``: on every segment
    the nearest point is found in the weighted coordinates ``(p, s rot)``, the distance is
    :meth:`Pose.distance` ``|dp| + s |dtheta|`` (``s`` the object size) to it, and the smallest
    over the segments is returned (vectorised over the segments: it runs at every MuJoCo step of
    the continuous replay)."""
    dim = pose.dim
    path = np.asarray(path, dtype=float)
    if len(path) == 1 or np.allclose(path, path[0]):
        return pose.distance(Pose.from_vector(path[0], dim), s)
    w = np.ones(path.shape[1])
    w[dim:] = s
    x = pose.vector() * w  # (D,)
    A, B = path[:-1], path[1:]  # (k - 1, D)
    seg = (B - A) * w
    n2 = np.einsum("ij,ij->i", seg, seg)
    u = np.clip(np.einsum("ij,ij->i", x - A * w, seg) / np.where(n2 > 0, n2, 1.0), 0.0, 1.0)
    P = A + np.where(n2 > 0, u, 0.0)[:, None] * (B - A)  # (k - 1, D) nearest pose vectors
    dp = np.linalg.norm(P[:, :dim] - pose.position, axis=1)
    return float(np.min(dp + s * rotation_angles(pose, P[:, dim:])))


def rotation_angles(pose: Pose, rot: Array) -> Array:
    """Angles ``(k,)`` of the rotations from the poses' orientations ``rot`` (2-D: angles ``(k, 1)``;
    3-D: rotation vectors ``(k, 3)``) to ``pose``'s (:meth:`Pose.rotation_angle_to`, vectorised)."""
    if pose.dim == 2:
        diff = pose.angle - rot[:, 0]
        return np.asarray(np.abs(diff - 2.0 * math.pi * np.round(diff / (2.0 * math.pi))))
    th = np.linalg.norm(rot, axis=1)  # (k,)
    k = rot / np.where(th > 0, th, 1.0)[:, None]
    K = np.zeros((len(rot), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    R = np.eye(3) + np.sin(th)[:, None, None] * K + (1.0 - np.cos(th))[:, None, None] * (K @ K)  # (k, 3, 3)
    E = pose.rotation @ np.transpose(R, (0, 2, 1))  # R_pose R_i^T
    cos = (np.trace(E, axis1=1, axis2=2) - 1.0) / 2.0
    sin = 0.5 * np.linalg.norm(np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0],
                                         E[:, 1, 0] - E[:, 0, 1]], axis=1), axis=1)
    return np.asarray(np.arctan2(sin, cos))


def arc_fractions(path: Array) -> Array:
    """Cumulative arc length ``(n,)`` of a polyline ``(n, k)``, as a fraction of the total (0..1)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)  # (n - 1,)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    return cum / cum[-1] if cum[-1] > 0 else np.linspace(0.0, 1.0, len(path))


def interp_rows(path: Array, frac: Array, u: float) -> Array:
    """Point ``(k,)`` at arc-length fraction ``u`` of a polyline ``(n, k)`` with fractions ``frac``."""
    if len(path) == 1:
        return np.asarray(path[0])
    return np.array([np.interp(u, frac, path[:, j]) for j in range(path.shape[1])])


def move_time(q_path: Array, mask: Mask, joint_speed: float, min_time: float) -> float:
    """Duration of a driven move along ``q_path`` ``(n, M)`` (joints ``mask``): 1.5 x length /
    ``joint_speed`` (the smooth profile's mean speed is 2/3 of its peak), at least ``min_time``."""
    length = float(np.sum(np.linalg.norm(np.diff(q_path[:, mask], axis=0), axis=1)))
    return max(min_time, 1.5 * length / joint_speed)


def driven_profile(q_path: Array, mask: Mask, q_start: Array, duration: float) -> Callable[[float], Array]:
    """``q(t)`` ``(M,)`` along the joint path ``q_path`` ``(n, M)`` (smooth in time, uniform in arc
    length of the joints in ``mask``), blended from the simulated start ``q_start`` ``(M,)`` into
    the planned path."""
    frac = arc_fractions(q_path[:, mask])
    offset = q_start - q_path[0]  # (M,)

    def q_of(t: float) -> Array:
        u = smooth_ramp(t, duration)
        return interp_rows(q_path, frac, u) + (1.0 - u) * offset

    return q_of


__all__ = ["Mask", "arc_fractions", "driven_profile", "interp_rows", "move_time", "path_deviation", "rotation_angles"]
