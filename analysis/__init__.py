"""Closure analysis of whole-arm grasps under contact-state transitions (paper sections III-IV)."""

__version__ = "0.1.0"
