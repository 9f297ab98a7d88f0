"""Forward kinematics and point Jacobians of the hand (paper eq. 1: ``dp_CF = J_ij dq_i``).

Every finger is a serial chain of revolute joints. Planar fingers (``dim = 2``) are chains in
the xy-plane whose joints turn about z; spatial fingers give each joint an ``axis`` and an
``origin`` in the previous joint's frame; URDF fingers are read with pinocchio
(:mod:`analysis.urdf`). Body ``"<finger>/k"`` is the body moved by joints ``0..k``; a fixed body
(palm, table) has no joints and ``J = 0``.

All poses are computed in 3-D; a 2-D scene keeps the x and y rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.pose import Pose
from analysis.rotations import skew
from analysis.scene import Finger2D, Finger3D, FingerURDF, Scene

_EYE3 = np.eye(3)


class FingerModel(Protocol):
    """What the analysis needs from one finger (a serial chain)."""

    name: str
    n_joints: int
    q0: Array

    def body_names(self) -> list[str]: ...

    def body_index(self, label: str) -> int | None: ...

    def body_pose(self, k: int, q: Array) -> tuple[Array, Array]:
        """World rotation ``(3, 3)`` and origin ``(3,)`` of body ``k``."""
        ...

    def point_jacobian(self, k: int, x: Array, q: Array) -> Array:
        """``(3, n_joints)`` Jacobian of the world point ``x`` fixed on body ``k``."""
        ...

    def body_segment(self, k: int, q: Array) -> tuple[Array, Array]:
        """End points ``(3,)``, ``(3,)`` of the axis of body ``k`` (its link)."""
        ...

    def body_radius(self, k: int) -> float: ...

    def joints_moving(self, k: int) -> list[int]:
        """Indices of the joints that move body ``k``."""
        ...


class SerialChain:
    """A chain of revolute joints: ``T_k = T_base * prod_j (Trans(origin_j) Rot(axis_j, q_j))``.

    Body ``k`` is the frame after joint ``k``; its link runs from joint ``k`` to the origin of
    joint ``k + 1`` (or to ``tip`` for the last body).
    """

    def __init__(
        self,
        name: str,
        base_R: Array,
        base_p: Array,
        axes: Array,  # (n, 3) in each joint's frame
        origins: Array,  # (n, 3) in the previous joint's frame
        tip: Array,  # (3,) in the last joint's frame
        radii: Array,  # (n,)
        q0: Array,  # (n,)
    ):
        self.name = name
        self.base_R = np.asarray(base_R, dtype=float)
        self.base_p = np.asarray(base_p, dtype=float)
        self.axes = np.asarray(axes, dtype=float)
        self.origins = np.asarray(origins, dtype=float)
        self.tip = np.asarray(tip, dtype=float)
        self.radii = np.asarray(radii, dtype=float)
        self.q0 = np.asarray(q0, dtype=float)
        self.n_joints = len(self.q0)
        # Rodrigues' formula per joint (analysis.rotations.axis_angle_matrix), its constant parts
        self._K = [skew(a) for a in self.axes]  # (3, 3) each
        self._KK = [K @ K for K in self._K]

    def body_names(self) -> list[str]:
        return [f"{self.name}/{k}" for k in range(self.n_joints)]

    def body_index(self, label: str) -> int | None:
        if label.isascii() and label.isdigit() and int(label) < self.n_joints:
            return int(label)
        return None

    def frames(self, q: Array) -> tuple[list[Array], list[Array]]:
        """World rotations and origins of the frames after each joint (read-only arrays). The
        last ``q`` asked for is remembered: a body pose, a point Jacobian and a link segment at
        one configuration (a contact's rows, a clearance) share one pass along the chain."""
        key = np.asarray(q, dtype=float)[: self.n_joints].tobytes()
        last = self.__dict__.get("_frames_last")
        if last is not None and last[0] == key:
            return last[1]
        R, p = self.base_R, self.base_p
        Rs, ps = [], []
        for j in range(self.n_joints):
            p = p + R @ self.origins[j]
            # axis_angle_matrix(axes[j], q_j), its skew matrices computed once
            a = float(q[j])
            R = R @ (_EYE3 + np.sin(a) * self._K[j] + (1.0 - np.cos(a)) * self._KK[j])
            R.setflags(write=False)
            p.setflags(write=False)
            Rs.append(R)
            ps.append(p)
        self.__dict__["_frames_last"] = (key, (Rs, ps))
        self.__dict__.pop("_axes_last", None)
        return Rs, ps

    def _world_axes(self, q: Array) -> tuple[Array, Array]:
        """The joint axes ``(n, 3)`` and origins ``(n, 3)`` in the world at ``q`` (remembered with
        :meth:`frames`)."""
        Rs, ps = self.frames(q)
        got = self.__dict__.get("_axes_last")
        if got is None:
            got = (np.array([Rs[j] @ self.axes[j] for j in range(self.n_joints)]).reshape(-1, 3), np.array(ps))
            self.__dict__["_axes_last"] = got
        return got

    def body_pose(self, k: int, q: Array) -> tuple[Array, Array]:
        Rs, ps = self.frames(q)
        return Rs[k], ps[k]

    def point_jacobian(self, k: int, x: Array, q: Array) -> Array:
        A, P = self._world_axes(q)  # (n, 3) each
        m = k + 1
        A = A[:m]
        r = np.asarray(x, dtype=float) - P[:m]  # (k + 1, 3)
        J = np.zeros((3, self.n_joints))  # (3, n): column j = a_j x (x - p_j), as np.cross computes it
        J[0, :m] = A[:, 1] * r[:, 2] - A[:, 2] * r[:, 1]
        J[1, :m] = A[:, 2] * r[:, 0] - A[:, 0] * r[:, 2]
        J[2, :m] = A[:, 0] * r[:, 1] - A[:, 1] * r[:, 0]
        return J

    def point_jacobians(self, k: int, X: Array, q: Array) -> Array:
        """``(p, 3, n)``: :meth:`point_jacobian` of each world point of ``X`` ``(p, 3)`` fixed on body
        ``k``, in one pass (the same products, element by element)."""
        A, P = self._world_axes(q)  # (n, 3) each
        m = k + 1
        A = A[:m]
        R = np.asarray(X, dtype=float)[:, None, :] - P[:m]  # (p, k + 1, 3)
        J = np.zeros((R.shape[0], 3, self.n_joints))  # (p, 3, n)
        J[:, 0, :m] = A[:, 1] * R[:, :, 2] - A[:, 2] * R[:, :, 1]
        J[:, 1, :m] = A[:, 2] * R[:, :, 0] - A[:, 0] * R[:, :, 2]
        J[:, 2, :m] = A[:, 0] * R[:, :, 1] - A[:, 1] * R[:, :, 0]
        return J

    def body_segment(self, k: int, q: Array) -> tuple[Array, Array]:
        Rs, ps = self.frames(q)
        end_local = self.origins[k + 1] if k + 1 < self.n_joints else self.tip
        return ps[k], ps[k] + Rs[k] @ end_local

    def body_radius(self, k: int) -> float:
        return float(self.radii[k])

    def joints_moving(self, k: int) -> list[int]:
        return list(range(k + 1))


def base_frame(finger: Finger2D | Finger3D) -> tuple[Array, Array]:
    """World rotation ``(3, 3)`` and origin ``(3,)`` of a finger's base (2-D: in the plane z = 0)."""
    base = finger.base
    pose = Pose.from_fields(base.position, len(base.position), angle=getattr(base, "angle", None),
                            quat_wxyz=getattr(base, "quat_wxyz", None))
    return pose.rotation, _as3(pose.position)


def chain_from_finger(finger: object) -> FingerModel:
    """Build the kinematic model of one scene finger."""
    if isinstance(finger, Finger2D):
        n = len(finger.links)
        origins = np.zeros((n, 3))
        for k in range(1, n):
            origins[k] = [finger.links[k - 1].length, 0.0, 0.0]
        base_R, base_p = base_frame(finger)
        return SerialChain(
            finger.name,
            base_R,
            base_p,
            np.tile([0.0, 0.0, 1.0], (n, 1)),
            origins,
            np.array([finger.links[-1].length, 0.0, 0.0]),
            np.array([lk.radius for lk in finger.links]),
            np.asarray(finger.q, dtype=float),
        )
    if isinstance(finger, Finger3D):
        base_R, base_p = base_frame(finger)
        return SerialChain(
            finger.name,
            base_R,
            base_p,
            np.array([j.axis for j in finger.joints], dtype=float),
            np.array([j.origin for j in finger.joints], dtype=float),
            np.asarray(finger.tip, dtype=float),
            np.array([j.radius for j in finger.joints], dtype=float),
            np.asarray(finger.q, dtype=float),
        )
    if isinstance(finger, FingerURDF):
        # deferred: the URDF model imports pinocchio, which only URDF fingers need
        from analysis.urdf import UrdfFinger

        return UrdfFinger.from_spec(finger)
    raise TypeError(f"unknown finger type {type(finger).__name__}")


@dataclass(frozen=True)
class BodyRef:
    """A body that a contact can lie on: link ``link`` of finger ``finger``, or a fixed body."""

    name: str
    finger: int | None = None  # index in HandKinematics.fingers; None for a fixed body
    link: int = -1

    @property
    def is_fixed(self) -> bool:
        return self.finger is None


def joint_count(scene: Scene) -> int:
    """Total number of joints ``M`` of the hand."""
    return scene.M


class HandKinematics:
    """The whole hand: fingers stacked in scene order, ``q = col[q_i]`` (length ``M``)."""

    def __init__(self, dim: int, fingers: list[FingerModel], fixed_names: list[str]):
        self.dim = dim
        self.fingers = fingers
        self.fixed_names = list(fixed_names)
        sizes = [f.n_joints for f in fingers]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.M = int(self.offsets[-1])
        self.q0 = np.concatenate([f.q0 for f in fingers]) if fingers else np.zeros(0)

    @classmethod
    def from_scene(cls, scene: Scene) -> HandKinematics:
        fingers = []
        for i, f in enumerate(scene.fingers):
            try:
                fingers.append(chain_from_finger(f))
            except SceneError as e:
                raise SceneError(("fingers", i, *e.loc), e.reason) from None
        return cls(scene.dim, fingers, [b.name for b in scene.fixed_bodies])

    def joint_labels(self) -> list[str]:
        """``(M,)`` names of the joints in ``q`` order: ``finger/<URDF joint name>`` for URDF
        fingers, ``finger/j<k>`` (``k`` from 0) for chains."""
        out: list[str] = []
        for f in self.fingers:
            names = getattr(f, "joint_names", None) or [f"j{k}" for k in range(f.n_joints)]
            out.extend(f"{f.name}/{n}" for n in names)
        return out

    # -- bodies -------------------------------------------------------------------------------

    def body_names(self) -> list[str]:
        names = list(self.fixed_names)
        for f in self.fingers:
            names.extend(f.body_names())
        return names

    def resolve_body(self, name: str) -> BodyRef | None:
        if name in self.fixed_names:
            return BodyRef(name=name)
        if "/" in name:
            fname, label = name.split("/", 1)
            for i, f in enumerate(self.fingers):
                if f.name == fname:
                    k = f.body_index(label)
                    return None if k is None else BodyRef(name=name, finger=i, link=k)
        return None

    def finger_of(self, name: str) -> int | None:
        """Index of the finger that carries body ``name``; None for a fixed or unknown body."""
        ref = self.resolve_body(name)
        return None if ref is None else ref.finger

    def finger_slice(self, i: int) -> slice:
        return slice(int(self.offsets[i]), int(self.offsets[i + 1]))

    # -- kinematics ---------------------------------------------------------------------------

    def body_pose(self, ref: BodyRef, q: Array) -> tuple[Array, Array]:
        """World rotation ``(3, 3)`` and origin ``(3,)`` of a body (identity for fixed ones)."""
        if ref.finger is None:
            return np.eye(3), np.zeros(3)
        f = self.fingers[ref.finger]
        return f.body_pose(ref.link, q[self.finger_slice(ref.finger)])

    def to_local(self, ref: BodyRef, x: Array, q: Array) -> Array:
        """Coordinates ``(3,)`` in the body frame of the world point ``x`` (2-D: z = 0)."""
        R, p = self.body_pose(ref, q)
        return R.T @ (_as3(x) - p)

    def point_position(self, ref: BodyRef, x_local: Array, q: Array) -> Array:
        """World position ``(d,)`` of the point fixed on the body at ``x_local``."""
        R, p = self.body_pose(ref, q)
        return (p + R @ x_local)[: self.dim]

    def point_jacobian(self, ref: BodyRef, x: Array, q: Array) -> Array:
        """``J_ij``: ``(d, M)`` Jacobian of the world point ``x`` fixed on the body (eq. 1)."""
        J = np.zeros((3, self.M))  # (3, M)
        if ref.finger is not None:
            f = self.fingers[ref.finger]
            sl = self.finger_slice(ref.finger)
            J[:, sl] = f.point_jacobian(ref.link, _as3(x), q[sl])
        return J[: self.dim]

    def point_jacobians(self, ref: BodyRef, X: Array, q: Array) -> Array:
        """``(p, d, M)``: :meth:`point_jacobian` of each world point of ``X`` ``(p, d)`` fixed on the
        body (one pass for a finger that has ``point_jacobians``, as :class:`SerialChain`)."""
        X = np.asarray(X, dtype=float)
        J = np.zeros((X.shape[0], 3, self.M))  # (p, 3, M)
        if ref.finger is not None:
            f = self.fingers[ref.finger]
            sl = self.finger_slice(ref.finger)
            X3 = X if X.shape[1] == 3 else np.column_stack([X, np.zeros(X.shape[0])])  # (p, 3)
            many = getattr(f, "point_jacobians", None)
            if many is not None:
                J[:, :, sl] = many(ref.link, X3, q[sl])
            else:
                for i, x in enumerate(X3):
                    J[i, :, sl] = f.point_jacobian(ref.link, x, q[sl])
        return J[:, : self.dim]

    def body_segment(self, ref: BodyRef, q: Array) -> tuple[Array, Array]:
        assert ref.finger is not None
        f = self.fingers[ref.finger]
        a, b = f.body_segment(ref.link, q[self.finger_slice(ref.finger)])
        return a[: self.dim], b[: self.dim]

    def body_radius(self, ref: BodyRef) -> float:
        return 0.0 if ref.finger is None else self.fingers[ref.finger].body_radius(ref.link)

    def moving_joints(self, ref: BodyRef) -> list[int]:
        """Global indices of the joints that move the body."""
        if ref.finger is None:
            return []
        off = int(self.offsets[ref.finger])
        return [off + j for j in self.fingers[ref.finger].joints_moving(ref.link)]


def _as3(x: Array) -> Array:
    x = np.asarray(x, dtype=float)
    return x if x.shape[0] == 3 else np.array([x[0], x[1], 0.0])


def segment_distance(p: Array, a: Array, b: Array) -> float:
    """Distance from point ``p`` to the segment ``[a, b]``."""
    ab = b - a
    L2 = float(ab @ ab)
    t = 0.0 if L2 == 0.0 else float(np.clip((p - a) @ ab / L2, 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))
