"""URDF fingers: a serial chain cut out of a URDF robot and evaluated with pinocchio.

A scene finger of type :class:`analysis.scene.FingerURDF` names a URDF file, a ``root_link``
and a ``tip_link``. :class:`UrdfFinger` keeps the joints on the kinematic path from the root
link down to the tip link; every other joint of the robot is locked at its neutral value
(``0``) with ``pin.buildReducedModel``. The finger's ``base`` (position and ``quat_wxyz``) is
the world pose of ``root_link``, so the world pose of a link ``L`` is

    ``T_world_L(q) = T_base * inv(T_root) * T_L(q)``

with ``T_root`` and ``T_L(q)`` the poses pinocchio computes in the URDF's own world frame
(``T_root`` does not depend on the chain's ``q``: the root is above every chain joint).

Bodies are the URDF links on the path below the root, labelled by link name: a contact on
link ``link_2.0`` of finger ``index`` names the body ``"index/link_2.0"``. Each link is
modelled as a capsule of radius ``link_radius`` about the segment from its frame origin to the
origin of the next link on the path (for a revolute or fixed joint, the child link's frame
origin is the joint origin); the tip link's segment ends at ``tip_offset`` (by default the
origin of its only child link in the URDF, if it has exactly one, else the tip frame origin:
a sphere).

Only the revolute joints on the path are chain joints (``q`` has one angle per joint, in path
order from the root). Continuous (unbounded revolute) joints are chain joints too: pinocchio
represents them by ``(cos q, sin q)``. Prismatic or other joints on the path are locked at 0.
With ``"link_geometry": "urdf"`` the links' geometry is the URDF's own ``<collision>`` elements
instead of the capsules: pinocchio builds the collision GeometryModel (meshes found through
``urdf.package_dirs`` and example-robot-data's ``share`` folder), and :meth:`UrdfFinger.
collision_shapes` hands each chain link's coal objects, placed in the link's frame, to
:mod:`analysis.detect` (the one place that computes with them). Geometry of links off the chain
(side links fixed to a chain link, other fingers) is not part of the finger.
"""

from __future__ import annotations

import functools
import importlib.metadata
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.rotations import quat_wxyz_to_matrix, skew
from analysis.scene import FingerURDF

#: Prefix of ``urdf.file`` that resolves inside example-robot-data's ``robots`` directory.
ERD_PREFIX = "example-robot-data:"

_REVOLUTE = {"JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"}
_CONTINUOUS = {"JointModelRUBX", "JointModelRUBY", "JointModelRUBZ", "JointModelRevoluteUnboundedUnaligned"}


# --------------------------------------------------------------------------------------------
# File resolution


def example_robot_data_dir() -> Path | None:
    """The ``robots`` directory of the installed example-robot-data, or ``None``.

    Looked up, in order: the ``EXAMPLE_ROBOT_DATA_MODEL_DIR`` environment variable (the one
    example-robot-data's own loader honours), the files of the installed ``example-robot-data``
    distribution (a cmeel wheel: ``cmeel.prefix/share/example-robot-data/robots``), then
    ``share/example-robot-data/robots`` under ``sys.prefix`` and under every ``cmeel.prefix``
    next to a ``sys.path`` entry.
    """
    candidates: list[Path] = []
    env = os.environ.get("EXAMPLE_ROBOT_DATA_MODEL_DIR")
    if env:
        candidates.append(Path(env))
    rel = Path("share") / "example-robot-data" / "robots"
    try:
        dist = importlib.metadata.distribution("example-robot-data")
        candidates.append(Path(str(dist.locate_file(Path("cmeel.prefix") / rel))))
    except importlib.metadata.PackageNotFoundError:
        pass
    candidates.append(Path(sys.prefix) / rel)
    candidates.extend(Path(p) / "cmeel.prefix" / rel for p in sys.path if p)
    for c in candidates:
        if c.is_dir():
            return c
    return None


def resolve_urdf_path(file: str) -> Path:
    """Resolve ``urdf.file``: an absolute path, a path relative to the current directory,
    ``"example-robot-data:<path inside robots/>"``, or ``"robot:<sha256>/<path inside the
    archive>"``: a robot uploaded to the service (``POST /robots``), kept in
    ``<data folder>/robots/<sha256>/``, the data folder being the ``CTP_DATA_DIR`` environment
    variable (the service's ``data_dir`` setting, which it exports) or ``ctp-data`` in the current
    directory. Raise :class:`SceneError` at ``("urdf", "file")`` when the file does not exist
    or would leave its folder (symbolic links resolved); the message never shows a server folder."""
    if file.startswith(ERD_PREFIX):
        sub = file[len(ERD_PREFIX) :].lstrip("/")
        root = example_robot_data_dir()
        if root is None:
            raise SceneError(
                ("urdf", "file"), f"'{file}': the example-robot-data package is not installed"
            )
        where = "example-robot-data's robots folder"
    elif file.startswith("robot:"):
        digest, _, sub = file[len("robot:") :].partition("/")
        if len(digest) != 64 or any(c not in "0123456789abcdef" for c in digest) or not sub:
            raise SceneError(("urdf", "file"), f"'{file}': an uploaded robot's file is "
                                               "'robot:<sha256 of the archive, 64 hex digits>/<path inside it>'")
        root = Path(os.environ.get("CTP_DATA_DIR") or "ctp-data").expanduser() / "robots" / digest
        if not root.is_dir():
            raise SceneError(("urdf", "file"), f"URDF file not found: '{file}' (no robot uploaded with "
                                               f"the hash {digest})")
        where = "the uploaded robot"
    else:
        path = Path(file).expanduser()
        if not path.is_absolute():
            path = Path.cwd() / path
        if not path.is_file():
            raise SceneError(("urdf", "file"), f"URDF file not found: '{file}' (looked at {path})")
        return path
    path = root / sub
    # the file must stay inside its folder, symbolic links resolved (no '..', no absolute path,
    # no link out of it); the message never shows the server's folders
    try:
        inside = path.resolve().is_relative_to(root.resolve())
    except (OSError, RuntimeError):  # a symbolic-link loop
        inside = False
    if not inside or not path.is_file():
        raise SceneError(("urdf", "file"), f"URDF file not found: '{file}' (no such file in {where})")
    return path


def _upload_package_dirs(file: str, path: Path) -> list[str]:
    """For an uploaded robot (``robot:<sha256>/...``): the folders in which its ``package://``
    meshes are looked up, its archive's top folder and the folders one and two levels below it
    (``package://<name>/...`` is found where a folder ``<name>`` lies), up to the URDF's own."""
    if not file.startswith("robot:"):
        return []
    digest = file[len("robot:"):].partition("/")[0]
    root = path.resolve()
    while root.parent.name != "robots" or root.name != digest:
        if root.parent == root:
            return []
        root = root.parent
    dirs = [root] + [d for d in sorted(root.iterdir()) if d.is_dir() and not d.is_symlink()]
    dirs += [e for d in dirs[1:] for e in sorted(d.iterdir()) if e.is_dir() and not e.is_symlink()]
    return [str(d) for d in dirs[:64]]


@functools.lru_cache(maxsize=32)
def _load_model(path: str, mtime_ns: int) -> Any:
    """The full pinocchio model of a URDF file (cached by path and modification time; the
    cached model is never modified)."""
    del mtime_ns  # part of the cache key only
    return pin.buildModelFromUrdf(path)


@functools.lru_cache(maxsize=32)
def _load_collision(path: str, mtime_ns: int, package_dirs: tuple[str, ...]) -> Any:
    """The collision GeometryModel of a URDF file for its full model (cached; never modified)."""
    del mtime_ns
    return pin.buildGeomFromUrdf(_load_model(path, Path(path).stat().st_mtime_ns), path,
                                 pin.GeometryType.COLLISION, package_dirs=list(package_dirs))


def load_collision_model(path: Path, package_dirs: list[str]) -> Any:
    """The URDF's collision geometry (pinocchio ``GeometryModel`` of coal objects); meshes are
    looked up in ``package_dirs`` and in example-robot-data's ``share`` folder. A mesh that
    cannot be found or read is a SceneError at ``("urdf", "file")``."""
    dirs = [str(Path(d).expanduser()) for d in package_dirs]
    erd = example_robot_data_dir()
    if erd is not None:
        dirs += [str(erd.parent.parent), str(erd)]
    try:
        return _load_collision(str(path), path.stat().st_mtime_ns, tuple(dirs))
    except (RuntimeError, ValueError) as e:
        why = " ".join(str(e).replace(str(path.parent), "").split())
        raise SceneError(("urdf", "file"), f"cannot load the collision geometry of '{path.name}': {why}") from None


def load_urdf_model(path: Path) -> Any:
    """``pin.buildModelFromUrdf(path)`` with caching; parse errors become :class:`SceneError`."""
    try:
        return _load_model(str(path), path.stat().st_mtime_ns)
    except (RuntimeError, ValueError) as e:  # the file's name only: no server folder in the message
        why = " ".join(str(e).replace(str(path), path.name).replace(str(path.parent), "").split())
        raise SceneError(("urdf", "file"), f"cannot read URDF '{path.name}': {why}") from None


# --------------------------------------------------------------------------------------------
# The finger


def _body_frame(model: Any, link: str) -> int | None:
    """Frame id of the URDF link ``link`` (a BODY frame), or ``None``."""
    for fid, f in enumerate(model.frames):
        if f.name == link and f.type == pin.FrameType.BODY:
            return fid
    return None


def _link_names(model: Any) -> list[str]:
    return [f.name for f in model.frames if f.type == pin.FrameType.BODY]


class UrdfFinger:
    """One finger (serial chain root link -> tip link) of a URDF robot; a :class:`FingerModel`.

    Attributes: ``name``, ``n_joints``, ``q0`` ``(n,)`` (the scene's configuration),
    ``joint_names`` (URDF names of the chain joints, in path order), ``links`` (body labels =
    URDF link names below the root, in path order), ``lower``/``upper`` ``(n,)`` joint limits
    from the URDF (``-inf``/``inf`` for continuous joints). Not thread-safe (one pinocchio
    ``Data`` per finger).
    """

    def __init__(
        self,
        name: str,
        path: Path,
        root_link: str,
        tip_link: str,
        q0: Array,  # (n,)
        base_R: Array | None = None,  # (3, 3)
        base_p: Array | None = None,  # (3,)
        link_radius: float = 0.0,
        tip_offset: Array | None = None,  # (3,) in the tip link's frame
        link_geometry: str = "capsule",
        package_dirs: list[str] | None = None,
    ):
        full = load_urdf_model(path)
        root_f = _body_frame(full, root_link)
        if root_f is None:
            raise SceneError(
                ("urdf", "root_link"),
                f"unknown link '{root_link}' in {path.name} (links: {', '.join(_link_names(full))})",
            )
        tip_f = _body_frame(full, tip_link)
        if tip_f is None:
            raise SceneError(
                ("urdf", "tip_link"),
                f"unknown link '{tip_link}' in {path.name} (links: {', '.join(_link_names(full))})",
            )

        # Walk the frame tree from the tip up to the root: BODY frames are links, JOINT frames
        # are moving joints (FIXED_JOINT frames are fixed joints).
        links_up: list[str] = []
        joints_up: list[int] = []  # pinocchio joint ids (full model)
        fid = tip_f
        while fid != root_f:
            f = full.frames[fid]
            if f.type == pin.FrameType.BODY:
                links_up.append(f.name)
            elif f.type == pin.FrameType.JOINT:
                joints_up.append(int(f.parentJoint))
            if fid == 0:  # reached the universe without meeting the root
                raise SceneError(
                    ("urdf", "tip_link"), f"link '{tip_link}' is not below root_link '{root_link}'"
                )
            fid = int(f.parentFrame)
        links = links_up[::-1]
        path_joints = joints_up[::-1]
        chain = [
            j for j in path_joints if full.joints[j].shortname() in _REVOLUTE | _CONTINUOUS
        ]
        if not chain:
            raise SceneError(
                ("urdf", "tip_link"),
                f"no revolute joint between root_link '{root_link}' and tip_link '{tip_link}'",
            )

        # Lock every joint that is not a chain joint at its neutral value.
        lock = [j for j in range(1, full.njoints) if j not in chain]
        q_neutral = pin.neutral(full)
        model = pin.buildReducedModel(full, lock, q_neutral) if lock else full.copy()

        self.name = name
        self.path = path
        self.root_link = root_link
        self.tip_link = tip_link
        self.links = links
        self.joint_names = [str(full.names[j]) for j in chain]
        self.n_joints = len(chain)
        self.link_radius = float(link_radius)
        self._model = model
        self._data = model.createData()

        # Chain joint -> reduced model joint (nq, idx_q, idx_v).
        self._jid = [int(model.getJointId(n)) for n in self.joint_names]
        self._nq = [int(model.joints[j].nq) for j in self._jid]
        self._idx_q = [int(model.joints[j].idx_q) for j in self._jid]
        self._idx_v = [int(model.joints[j].idx_v) for j in self._jid]
        assert model.nv == self.n_joints
        self.lower = np.array(
            [full.lowerPositionLimit[full.joints[j].idx_q] if full.joints[j].nq == 1 else -np.inf
             for j in chain]
        )  # (n,)
        self.upper = np.array(
            [full.upperPositionLimit[full.joints[j].idx_q] if full.joints[j].nq == 1 else np.inf
             for j in chain]
        )  # (n,)

        # Frames of the links (reduced model) and the joints that move each link.
        self._fid = [int(model.getFrameId(lk, pin.FrameType.BODY)) for lk in links]
        self._moving: list[list[int]] = []
        for fid_k in self._fid:
            parent = int(model.frames[fid_k].parentJoint)  # reduced joint id moving this link
            self._moving.append([i for i, j in enumerate(self._jid) if j <= parent])
        self._root_fid = int(model.getFrameId(root_link, pin.FrameType.BODY))

        # World pose of the root link: T_base * inv(T_root); T_root is independent of q.
        pin.framesForwardKinematics(model, self._data, pin.neutral(model))
        root = self._data.oMf[self._root_fid]
        base_R = np.eye(3) if base_R is None else np.asarray(base_R, dtype=float)
        base_p = np.zeros(3) if base_p is None else np.asarray(base_p, dtype=float)
        self._R_wu = base_R @ root.rotation.T  # (3, 3) URDF world -> scene world
        self._p_wu = base_p - self._R_wu @ root.translation  # (3,)

        # Tip segment end, in the tip link's frame.
        if tip_offset is None:
            tip_offset = self._default_tip_offset(full, tip_f, q_neutral)
        self.tip_offset = np.asarray(tip_offset, dtype=float)  # (3,)

        self.q0 = self._check_q(q0, ("q",))  # (n,)
        self.link_geometry = link_geometry
        self._shapes: list[list[tuple[Any, Array, Array]]] | None = None
        if link_geometry == "urdf":
            self._shapes = self._link_shapes(full, load_collision_model(path, package_dirs or []), q_neutral)

    def _link_shapes(self, full: Any, geom: Any, q_neutral: Array) -> list[list[tuple[Any, Array, Array]]]:
        """Per chain link, its collision objects: ``(coal geometry, R (3, 3), p (3,))`` in the link's
        frame (a geometry's placement is given relative to its parent joint)."""
        data = full.createData()
        pin.framesForwardKinematics(full, data, q_neutral)
        by_link: dict[str, list[tuple[Any, Array, Array]]] = {lk: [] for lk in self.links}
        for o in geom.geometryObjects:
            link = str(full.frames[int(o.parentFrame)].name)
            if link not in by_link:
                continue
            rel = data.oMf[int(o.parentFrame)].actInv(data.oMi[int(o.parentJoint)] * o.placement)
            scale = np.asarray(o.meshScale, dtype=float)
            if not np.allclose(scale, 1.0):
                raise SceneError(("urdf", "file"), f"link '{link}': scaled collision meshes are not supported "
                                 f"(scale {scale.tolist()})")
            by_link[link].append((o.geometry, np.asarray(rel.rotation, dtype=float).copy(),
                                  np.asarray(rel.translation, dtype=float).copy()))
        return [by_link[lk] for lk in self.links]

    def collision_shapes(self, k: int) -> list[tuple[Any, Array, Array]] | None:
        """The URDF collision objects of link ``k`` in its frame (``(coal geometry, R, p)``), or
        ``None`` when the finger's links are capsules (``link_geometry`` ``"capsule"``)."""
        return None if self._shapes is None else list(self._shapes[k])

    @classmethod
    def from_spec(cls, finger: FingerURDF) -> UrdfFinger:
        """Build from a scene finger (errors are :class:`SceneError` relative to the finger)."""
        path = resolve_urdf_path(finger.urdf.file)
        return cls(
            finger.name,
            path,
            finger.urdf.root_link,
            finger.urdf.tip_link,
            np.asarray(finger.q, dtype=float),
            base_R=quat_wxyz_to_matrix(finger.base.quat_wxyz),
            base_p=np.asarray(finger.base.position, dtype=float),
            link_radius=finger.link_radius,
            link_geometry=finger.link_geometry,
            package_dirs=list(finger.urdf.package_dirs) + _upload_package_dirs(finger.urdf.file, path),
        )

    @staticmethod
    def _default_tip_offset(full: Any, tip_f: int, q_neutral: Array) -> Array:
        """Origin ``(3,)`` (in the tip link's frame) of the tip link's only child link, or 0."""
        children = []
        for f in full.frames:
            if f.type != pin.FrameType.BODY:
                continue
            parent = full.frames[int(f.parentFrame)]  # the joint frame above the link
            is_joint = parent.type in (pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT)
            if is_joint and int(parent.parentFrame) == tip_f:
                children.append(full.getFrameId(f.name, pin.FrameType.BODY))
        if len(children) != 1:
            return np.zeros(3)
        data = full.createData()
        pin.framesForwardKinematics(full, data, q_neutral)
        rel = data.oMf[tip_f].actInv(data.oMf[children[0]])
        return np.asarray(rel.translation, dtype=float).copy()

    # -- configuration --------------------------------------------------------------------

    def _check_q(self, q: Array, loc: tuple[str | int, ...] = ("q",)) -> Array:
        q = np.asarray(q, dtype=float).reshape(-1)  # (n,)
        if q.shape[0] != self.n_joints:
            raise SceneError(
                loc,
                f"has {q.shape[0]} values but the chain {self.root_link} -> {self.tip_link} has "
                f"{self.n_joints} revolute joints ({', '.join(self.joint_names)})",
            )
        return q

    def pin_q(self, q: Array) -> Array:
        """Pinocchio configuration ``(nq,)`` of the reduced model for chain angles ``q``."""
        q = self._check_q(q)
        qp = np.zeros(self._model.nq)  # (nq,)
        for i in range(self.n_joints):
            k = self._idx_q[i]
            if self._nq[i] == 1:
                qp[k] = q[i]
            else:
                qp[k], qp[k + 1] = np.cos(q[i]), np.sin(q[i])
        return qp

    # -- bodies ---------------------------------------------------------------------------

    def body_names(self) -> list[str]:
        return [f"{self.name}/{lk}" for lk in self.links]

    def body_index(self, label: str) -> int | None:
        """Index of the link named ``label`` (a URDF link name on the chain), or ``None``."""
        try:
            return self.links.index(label)
        except ValueError:
            return None

    def joints_moving(self, k: int) -> list[int]:
        """Chain joints (indices into ``q``) between the root and link ``k``."""
        return list(self._moving[k])

    def body_radius(self, k: int) -> float:
        return self.link_radius

    # -- kinematics -----------------------------------------------------------------------

    def body_pose(self, k: int, q: Array) -> tuple[Array, Array]:
        """World rotation ``(3, 3)`` and origin ``(3,)`` of link ``k``:
        ``T_base * inv(T_root) * T_k(q)``."""
        pin.framesForwardKinematics(self._model, self._data, self.pin_q(q))
        M = self._data.oMf[self._fid[k]]
        R = self._R_wu @ M.rotation  # (3, 3)
        p = self._p_wu + self._R_wu @ M.translation  # (3,)
        return R, p

    def point_jacobian(self, k: int, x: Array, q: Array) -> Array:
        """``(3, n)`` world Jacobian of the world point ``x`` rigidly attached to link ``k``.

        From pinocchio's frame Jacobian in ``LOCAL_WORLD_ALIGNED`` (linear velocity of the frame
        origin ``p_k`` and angular velocity ``omega``, both in world axes):
        ``dx/dq = R_wu (J_v - [x_u - p_k] x J_omega)`` with ``x_u`` the point in URDF world
        coordinates and ``R_wu`` the rotation from the URDF world to the scene world.
        """
        fid = self._fid[k]
        J6 = pin.computeFrameJacobian(
            self._model, self._data, self.pin_q(q), fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )  # (6, nv): [linear; angular]
        p_k = self._data.oMf[fid].translation  # (3,) URDF world
        x_u = self._R_wu.T @ (np.asarray(x, dtype=float) - self._p_wu)  # (3,) URDF world
        J_u = J6[:3] - skew(x_u - p_k) @ J6[3:]  # (3, nv)
        J = np.zeros((3, self.n_joints))  # (3, n)
        J[:, :] = (self._R_wu @ J_u)[:, self._idx_v]
        return J

    def body_segment(self, k: int, q: Array) -> tuple[Array, Array]:
        """World end points ``(3,)``, ``(3,)`` of link ``k``'s axis: its frame origin and the
        origin of the next link on the chain (the tip link: ``tip_offset`` in its frame)."""
        R, a = self.body_pose(k, q)
        if k + 1 < len(self.links):
            _, b = self.body_pose(k + 1, q)
        else:
            b = a + R @ self.tip_offset
        return a, b


__all__ = ["ERD_PREFIX", "UrdfFinger", "example_robot_data_dir", "load_collision_model", "load_urdf_model",
           "resolve_urdf_path"]
