"""Solver facade: ``step(model, state_in, state_out, contacts, dt)`` advances one substep."""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from ..launch import launch
from ..types import INTEGRATORS, ROTATIONS
from .soft_step import soft_coefficients, solve_and_integrate


@dataclass
class SolverSettings:
    """Contact solver constants; defaults follow Box2D v3 / Solver2D (4 + 2 sweeps, 30 Hz, zeta 10)."""

    integrator: str = "semi_implicit"
    rotation: str = "quaternion"
    iterations: int = 4
    relax_iterations: int = 2
    contact_hertz: float = 30.0
    damping_ratio: float = 10.0
    max_push_velocity: float = 3.0
    restitution_threshold: float = 1.0
    convergence_tolerance: float = 1.0e-5


class SoftStepSolver:
    def __init__(self, settings: SolverSettings, gravity, device):
        self.settings = settings
        self.gravity = wp.vec3(*gravity)
        self.device = device
        self.sim_step = wp.zeros(1, dtype=wp.int32, device=device)

    def step(self, model, state_in, state_out, contacts, dt: float, body_bad_step, bad_count):
        s = self.settings
        launch(
            solve_and_integrate,
            dim=model.body_count,
            inputs=[
                # Model
                model.body_shape, model.body_size, model.body_inv_mass, model.body_inertia,
                model.body_inv_inertia, model.body_restitution, model.body_friction,
                model.body_rolling_resistance, model.body_checkpoint_start, model.body_checkpoint_count,
                # Settings
                self.gravity, dt, INTEGRATORS[s.integrator], ROTATIONS[s.rotation], s.iterations,
                s.relax_iterations, soft_coefficients(dt, s.contact_hertz, s.damping_ratio),
                s.max_push_velocity, s.restitution_threshold, s.convergence_tolerance, self.sim_step,
                # Contacts
                contacts.terrain_contact_active, contacts.terrain_contact_point, contacts.terrain_contact_normal,
                contacts.terrain_contact_depth, contacts.terrain_contact_normal_impulse,
                contacts.terrain_contact_tangent_impulse, contacts.terrain_contact_approach,
                # State in
                *state_in.fields(),
                # State out
                *state_out.fields(),
                # Out
                body_bad_step, bad_count,
            ],
            device=self.device,
        )
