"""Contact solvers. ``SoftStepSolver`` is the default (see soft_step.py for the derivation)."""

from .solver import SoftStepSolver

__all__ = ["SoftStepSolver"]
