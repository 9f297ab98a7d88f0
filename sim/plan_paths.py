"""Planned paths in the continuous plan replay: finger joint profiles and the object's deviation.

A plan step gives joint waypoints ``joint_path`` ``(n, M)`` and object pose vectors
``object_path`` ``(k, D)`` (2-D ``(x, y, theta)``, 3-D ``(p, rotation vector)``; the object
motions of eq. 30-32). :func:`driven_profile` turns the joint path into a smooth motion in time
for the fingers that :mod:`sim.plan_replay` drives kinematically, :func:`move_time` says how long
that motion takes, and :func:`path_deviation` measures how far the simulated object is from its
planned path in the metric ``|dp| + s |dtheta|`` (:meth:`analysis.pose.Pose.distance`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.pose import Pose
from sim.torque_replay import smooth_ramp

#: Joints ``(M,)`` selected (e.g. those of the driven fingers).
Mask = NDArray[np.bool_]


def path_deviation(pose: Pose, path: Array, s: float) -> float:
    """Distance of ``pose`` from the polyline of pose vectors ``path`` ``(k, D)``: the nearest
    point is found in the weighted coordinates ``(p, s rot)``, the distance is
    :meth:`Pose.distance` ``|dp| + s |dtheta|`` (``s`` the object size)."""
    dim = pose.dim
    if len(path) == 1 or np.allclose(path, path[0]):
        return pose.distance(Pose.from_vector(path[0], dim), s)
    w = np.ones(path.shape[1])
    w[dim:] = s
    x = pose.vector() * w  # (D,)
    best = math.inf
    for a, b in itertools.pairwise(path):
        seg = (b - a) * w
        n2 = float(seg @ seg)
        u = 0.0 if n2 == 0 else float(np.clip((x - a * w) @ seg / n2, 0.0, 1.0))
        best = min(best, pose.distance(Pose.from_vector(a + u * (b - a), dim), s))
    return best


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


__all__ = ["Mask", "arc_fractions", "driven_profile", "interp_rows", "move_time", "path_deviation"]
