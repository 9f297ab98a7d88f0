"""Contact-state transition planner (the paper's third research topic): from a grasp to a
desired closure through regrasps (eq. 33) and object motions (eq. 30-32)."""

import analysis  # noqa: F401  (first: it pins the BLAS kernel before numpy loads, analysis/blas.py)
from planner.goals import Goal
from planner.plan import Plan, PlanStep, plan

__all__ = ["Goal", "Plan", "PlanStep", "plan"]
