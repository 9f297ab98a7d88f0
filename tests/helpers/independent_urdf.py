"""Joint torques of contact forces on URDF arms, computed with pinocchio directly from the scene
file (not through :mod:`analysis.urdf`): the independent side of the torque-limit checks.

For a finger ``{"urdf": {"file", "root_link", "tip_link"}, "base", "q"}`` the chain joints are the
revolute joints on the path from ``tip_link`` up to ``root_link`` (pinocchio's joint parents);
every other joint of the URDF sits at its neutral value. A contact force ``f`` (world, N) at the
world point ``p`` on link ``k`` gives the chain torques ``J_p^T f`` with ``J_p = R (J_v - [p_u -
o_u]x J_w)`` from ``getFrameJacobian(..., LOCAL_WORLD_ALIGNED)``; ``R`` and the URDF-to-world
offset come from the finger's base and the root link's pose.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from analysis.urdf import resolve_urdf_path

Array = NDArray[np.float64]


def _quat(wxyz: list[float]) -> Array:
    w, x, y, z = wxyz
    return np.array(pin.Quaternion(w, x, y, z).normalized().toRotationMatrix())


class IndependentArm:
    """One URDF finger of a scene: chain joints, effort limits and point Jacobians."""

    def __init__(self, finger: dict[str, Any]):
        u = finger["urdf"]
        self.name = finger["name"]
        self.model = pin.buildModelFromUrdf(str(resolve_urdf_path(u["file"])))
        self.data = self.model.createData()
        m = self.model
        tip_joint = m.frames[m.getFrameId(u["tip_link"])].parentJoint
        root_joint = m.frames[m.getFrameId(u["root_link"])].parentJoint
        chain = []
        j = tip_joint
        while j != root_joint and j != 0:
            if m.joints[j].nq == 1:
                chain.append(j)
            j = m.parents[j]
        self.chain = chain[::-1]  # root to tip
        self.joint_names = [m.names[j] for j in self.chain]
        self.effort = np.array([m.effortLimit[m.joints[j].idx_v] for j in self.chain])
        q = pin.neutral(m)
        for j, v in zip(self.chain, finger["q"], strict=True):
            q[m.joints[j].idx_q] = v
        pin.forwardKinematics(m, self.data, q)
        pin.updateFramePlacements(m, self.data)
        pin.computeJointJacobians(m, self.data, q)
        root = self.data.oMf[m.getFrameId(u["root_link"])]
        base_R = _quat(finger["base"]["quat_wxyz"])
        self.R = base_R @ root.rotation.T  # URDF world -> scene world
        self.p = np.asarray(finger["base"]["position"], float) - self.R @ root.translation

    def point_jacobian(self, link: str, point: Array) -> Array:
        """``(3, n_chain)``: world velocity of the world point ``point`` fixed on ``link``."""
        m = self.model
        fid = m.getFrameId(link)
        J = pin.getFrameJacobian(m, self.data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)  # (6, nv)
        p_u = self.R.T @ (np.asarray(point, float) - self.p)
        r = p_u - self.data.oMf[fid].translation
        rx = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        Jp = J[:3] - rx @ J[3:]
        cols = [m.joints[j].idx_v for j in self.chain]
        return self.R @ Jp[:, cols]


def contact_torque_maps(data: dict[str, Any]) -> tuple[list[Array], Array]:
    """Per contact the ``(M, 3)`` map from its world force to the hand's joint torques (zero for
    fixed bodies), and the hand's limit vector ``(M,)`` [N m] (the scene's
    ``joint_torque_limits``, else the URDF efforts; ``inf`` where 0)."""
    arms = [IndependentArm(f) for f in data["fingers"]]
    sizes = [len(a.chain) for a in arms]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    M = int(offsets[-1])
    maps = []
    for c in data["contacts"]:
        T = np.zeros((M, 3))
        if "/" in c["body"]:
            fname, link = c["body"].split("/", 1)
            i = next(k for k, a in enumerate(arms) if a.name == fname)
            T[offsets[i]:offsets[i + 1]] = arms[i].point_jacobian(link, np.asarray(c["point"], float)).T
        maps.append(T)
    if data.get("joint_torque_limits") is not None:
        lim = np.asarray(data["joint_torque_limits"], float)
    else:
        lim = np.concatenate([a.effort for a in arms])
        lim = np.where(lim > 0, lim, np.inf)
    return maps, lim
