"""The torque that holds the object after a plan: ``tau_st`` (eq. 18) of the final grasp.

A plan (:class:`planner.plan.Plan`) carries it as ``final_tau`` (the file's
``final_holding_torque``), computed by the planner on the final grasp state. Plan files written
before that field existed lack it; :func:`final_holding_torque` then rebuilds it from the state
after the step that :meth:`planner.plan.Plan.from_json` reconstructs from the file (bodies
``contacts_after`` at ``contact_points_after``, hand at ``joint_path[-1]``, object at
``object_path[-1]``, each contact with the object's inward surface normal there and the scene's
``mu`` of its body, else the smallest scene ``mu``).
"""

from __future__ import annotations

import numpy as np

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from planner.plan import Plan, PlanStep
from planner.state import StateAnalysis, all_f, state_from_scene, state_scene


def final_holding_torque(scene: Scene, hand: HandKinematics, step: PlanStep) -> Array | None:
    """``tau_st`` ``(M,)`` of (18) (most interior, every contact sticking) of the grasp after
    ``step`` (a step of a plan read by :meth:`Plan.from_json`, whose state after it is rebuilt from
    the file). ``None`` when that grasp is not a valid scene (no contacts, no surface normal at a
    point, e.g. on a mesh, or a file without ``contact_points_after``) or has no stationary grasp."""
    if not step.after.contacts:
        return None
    try:
        final = state_scene(scene, step.after, hand)
        fh = HandKinematics.from_scene(final)
        state = state_from_scene(final, fh)
        grasp = StateAnalysis.of(final, state, fh).stationary(all_f(state))
    except SceneError:
        return None
    return None if grasp is None else np.asarray(grasp.tau, dtype=float)


def holding_torque_after(plan: Plan, scene: Scene, hand: HandKinematics, step: PlanStep) -> Array | None:
    """The holding torque ``(M,)`` once ``step`` is done and no later step gives one: the plan's
    ``final_tau`` (the planner's) when it has it, else :func:`final_holding_torque`."""
    if plan.final_tau is not None:
        return plan.final_tau
    return final_holding_torque(scene, hand, step)


__all__ = ["final_holding_torque", "holding_torque_after"]
