"""MuJoCo only: a scene as MJCF, torque replay of one combination, whole-plan replay."""

import analysis  # noqa: F401  (first: it pins the BLAS kernel before numpy loads, analysis/blas.py)
