"""Contact-state transition planner (the paper's third research topic): from a grasp to a
desired closure through regrasps (eq. 33) and object motions (eq. 30-32)."""

from planner.goals import Goal
from planner.plan import Plan, PlanStep, plan

__all__ = ["Goal", "Plan", "PlanStep", "plan"]
