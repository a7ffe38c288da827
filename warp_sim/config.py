"""Simulation settings (the ``[sim]`` table of a scene file) and the error a step raises when a body
goes non-finite.  Every field is checked on construction by the [sim] rules
(validation.SIM_SCHEMA), so a bad value is refused naming the field, before any kernel runs."""

from __future__ import annotations

from dataclasses import dataclass

from .solvers.soft_step import CONVERGENCE_GRAVITY_SHARE, RELAX_PASSES
from .solvers.solver import SolverSettings
from .validation import SIM_SCHEMA, check, check_fields


class NonFiniteStateError(RuntimeError):
    """``body``: the lowest scene index among the bodies that went non-finite in the earliest bad
    step; ``others``: the rest of them (a contact in that step can carry NaN from the body that
    caused it to a healthy one of lower index, so all are named)."""

    def __init__(self, body: int, step: int, time: float, shape: str, others: tuple = ()):
        text = f"body {body} ({shape}) became non-finite at step {step} (t = {time:.6g} s)"
        if others:
            listed = ", ".join(str(b) for b in others[:5]) + (", ..." if len(others) > 5 else "")
            text += f", with {len(others)} other{'s' if len(others) > 1 else ''} in that step (bodies {listed})"
        super().__init__(text)
        self.body = body
        self.step = step
        self.others = tuple(others)


# The fields SimConfig hands to the solver under the same names (SimConfig.solver_settings).
SOLVER_FIELDS = ("integrator", "rotation", "iterations", "relax_iterations", "relax_passes", "contact_hertz",
                 "damping_ratio", "max_push_velocity", "restitution_threshold", "convergence_tolerance",
                 "convergence_gravity_share", "solver", "overflow_pairs", "impacts", "face_friction",
                 "simultaneous_impacts")


@dataclass
class SimConfig:
    """Simulation settings, the ``[sim]`` table of a scene file (units SI)."""

    dt: float = 1.0 / 60.0
    substeps: int = 4  # the fewest: auto_substeps may run more (column_sag.py)
    gravity: tuple[float, float, float] = (0.0, -9.81, 0.0)
    duration: float = 5.0
    integrator: str = "semi_implicit"
    rotation: str = "quaternion"
    device: str = "cpu"
    seed: int = 0
    iterations: int = 2
    relax_iterations: int = 1
    relax_passes: int = RELAX_PASSES  # passes a relax sweep may take over one body's or one pair's own points
    contact_hertz: float | None = None  # None: 1/(4 h), 60 Hz at the defaults; a number caps it
    damping_ratio: float = 10.0
    max_push_velocity: float = 3.0
    restitution_threshold: float = 0.0  # [m/s] bounce only above this approach speed; 0: any impact (impact.py)
    # the impact stage (impact.py): "auto" runs it where some body has restitution, "always" in
    # inelastic scenes too (their impacts converged apart from the soft solve, at its cost)
    impacts: str = "auto"
    # where a face's friction acts (collide/contact_patch.py): "patch" turns it about the normal as
    # even pressure over the face does; "points" at the manifold's points (the corners: 1.85 times
    # the torque for a square, and faster)
    face_friction: str = "patch"
    # manifolds struck at once (solvers/impact_joint.py): "joint" takes those closing at the impact
    # stage's start as one Poisson impact (symmetric blows give symmetric outcomes); "sequential" one
    # after another in pair order, the first taking the whole blow, without the joint phase's sweeps
    simultaneous_impacts: str = "joint"
    convergence_tolerance: float = 1.0e-5
    convergence_gravity_share: float = CONVERGENCE_GRAVITY_SHARE  # passes also stop below this share of |g| h
    solver: str = "soft_step"
    auto_substeps: bool = True  # more substeps where the tallest column would sag past column_sag
    # [m] soft-contact sag the auto substep count keeps columns under, and transient depth it keeps
    # landings on piles under (both scaled down for bodies under 0.2 m thick: column_sag.plan_budgets)
    column_sag: float = 0.0075
    landing_depth: float = 0.01
    sleep: bool = True
    sleep_velocity: float = 0.05
    sleep_time: float = 0.5
    speculative_margin: float = 0.02
    # boxes on a Fourier terrain: the support face's checkpoints also see crests between them
    # (collide/face_search.py); False: the checkpoints alone, faster, and blind to those crests
    face_search: bool = True
    # boxes on a Fourier terrain: a checkpoint between the support face's corners holds a row only
    # where it lies deeper than the corners bound it (collide/bounded_points.py); False: every
    # checkpoint in reach holds one
    prune_face_points: bool = True
    # a still body's terrain contacts carried to its new pose instead of searched again
    # (collide/still_contacts.py); False: every body searched every pass
    still_contacts: bool = True
    body_contact: bool = True
    broad_phase: str = "grid"
    contact_max: int = 0
    contact_update: str = "step"  # find body-body scenes' contacts once per step, or every substep
    recollide_outrun: bool = True  # "step" updates: find the pairs again mid-step if a body outruns its reach
    # [m] "step" updates: a pair whose bodies turned (or slid along a static one) this far since the
    # pass is found again; 0: never
    turn_refresh: float = 0.005
    pair_schedule: str = "auto"  # body-body sweeps by slab (CPU) or by colour (CUDA); solvers/domains.py
    overflow_pairs: str = "auto"  # pairs past the colours: "split" (CUDA), "in_order" (CPU); solvers/pair_overflow.py
    allow_initial_overlap: bool = False  # scenes: initial overlaps are a warning instead of an error
    graph: bool | None = None  # capture the whole step as one graph and replay it; None: on CUDA only

    def __post_init__(self):
        self.validate()

    def __setattr__(self, name, value):
        # a field assigned later is held to the same rules (sim.config.dt = -1 ran time backwards,
        # a NaN gravity was ignored); Simulator.update_settings is still the way to change a
        # running simulator's settings, as it also plans the substeps again
        spec = SIM_SCHEMA.get(name)
        if spec is not None and value is not None:
            if name == "device" and not isinstance(value, str):
                value = str(value)  # a wp.Device
            value = check(spec, value, name, "SimConfig")
        object.__setattr__(self, name, value)

    def validate(self):
        """Check every field with the [sim] rules (validation.SIM_SCHEMA); ValueError names the field."""
        if not isinstance(self.device, str) and self.device is not None:
            self.device = str(self.device)  # a wp.Device
        check_fields(self, SIM_SCHEMA, "SimConfig")

    def solver_settings(self) -> SolverSettings:
        """The solver's share of these settings (the substep plan adds the rest, Simulator)."""
        return SolverSettings(**{name: getattr(self, name) for name in SOLVER_FIELDS})
