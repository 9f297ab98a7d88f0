"""Joint torque limits ``|tau_j| <= tau_max_j`` of a hand (bounds on the torques of (18) and (32)).

One place gives the limit vector of a hand, in N m, exactly as the scene states it:

1. the scene's ``joint_torque_limits`` (one positive entry per joint, validated in
   :mod:`analysis.scene`), when given;
2. else, for URDF fingers, the URDF's ``<limit effort=...>`` (pinocchio ``model.effortLimit``);
   an effort of 0, a missing one or a non-finite one means unlimited;
3. else no limit (``inf``).

:func:`hand_torque_limits` returns ``None`` when no joint is limited, so that scenes without
limits pose exactly the LPs they posed before.
"""

from __future__ import annotations

import numpy as np

from analysis._types import Array
from analysis.kinematics import HandKinematics
from analysis.scene import Scene


def urdf_effort_limits(finger: object) -> Array | None:
    """``(n,)`` URDF effort limits [N m] of a URDF finger's chain joints (``inf`` where the URDF
    gives 0 or none); ``None`` for a finger that is not read from a URDF."""
    names = getattr(finger, "joint_names", None)
    path = getattr(finger, "path", None)
    if names is None or path is None:
        return None
    from analysis.urdf import load_urdf_model  # deferred: pinocchio only for URDF fingers

    full = load_urdf_model(path)
    out = np.full(len(names), np.inf)
    for i, n in enumerate(names):
        j = full.joints[int(full.getJointId(n))]
        e = float(full.effortLimit[int(j.idx_v)])
        out[i] = e if np.isfinite(e) and e > 0.0 else np.inf
    return out


def hand_torque_limits(scene: Scene, hand: HandKinematics | None = None) -> Array | None:
    """The limit vector ``tau_max`` ``(M,)`` [N m] of the scene's hand (``inf``: unlimited), or
    ``None`` when no joint is limited. The scene's ``joint_torque_limits`` win over the URDF's."""
    if scene.joint_torque_limits is not None:
        return np.asarray(scene.joint_torque_limits, dtype=float)
    hand = hand or HandKinematics.from_scene(scene)
    out = np.full(hand.M, np.inf)
    for i, f in enumerate(hand.fingers):
        eff = urdf_effort_limits(f)
        if eff is not None:
            out[hand.finger_slice(i)] = eff
    return out if np.any(np.isfinite(out)) else None


__all__ = ["hand_torque_limits", "urdf_effort_limits"]
