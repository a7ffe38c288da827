"""Contact solvers. ``SoftStepSolver`` is the default (see soft_step.py for the derivation);
``PushoutSolver`` is the thesis's response, the baseline."""

from .solver import PushoutSolver, SoftStepSolver, make_solver

__all__ = ["PushoutSolver", "SoftStepSolver", "make_solver"]
