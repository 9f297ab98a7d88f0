"""Closure analysis of whole-arm grasps under contact-state transitions (paper sections III-IV)."""

from analysis.blas import pin_kernel

pin_kernel()  # before numpy loads: one BLAS kernel on every x86-64 CPU (analysis/blas.py)

__version__ = "0.1.0"
