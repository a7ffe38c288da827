"""The solver's own kernel-argument structs (the shared ones are in warp_sim/kernel_args.py)."""

import warp as wp


wp.set_module_options({"enable_backward": False})


@wp.struct
class StepSettings:
    """A substep's constants: SolverSettings and the substep length h."""

    # Settings
    gravity: wp.vec3
    h: float
    integrator: int
    rotation: int
    soft: wp.vec4
    soft_load: wp.vec3  # (h omega, zeta, 1 with gravity else 0): contact_rows.loaded_soft
    max_push_velocity: float
    restitution_threshold: float
    impacts_always: int  # SolverSettings.impacts == "always": the impact stage in inelastic scenes too
    face_patch: int  # SolverSettings.face_friction == "patch": friction at the patch's arms (contact_patch.py)
    convergence_tolerance: float
    iterations: int
    relax_iterations: int
    relax_passes: int


@wp.struct
class SolverBodies:
    """The solver's per-body and per-slot scratch (SoftStepSolver's arrays of the same names)."""

    # Solver in/out
    solver_v: wp.array(dtype=wp.vec3)
    solver_w: wp.array(dtype=wp.vec3)
    solver_w0: wp.array(dtype=wp.vec3)
    solver_inv_inertia: wp.array(dtype=wp.mat33)
    solver_rolling: wp.array(dtype=wp.vec3)
    solver_load_mass: wp.array(dtype=float)  # the heaviest body pressing on it (pair_solve.CHAIN_MASS_RATIO)
    solver_shift_v: wp.array(dtype=wp.vec3)
    solver_shift_w: wp.array(dtype=wp.vec3)
    solver_ref_pos: wp.array(dtype=wp.vec3)
    solver_ref_rot: wp.array(dtype=wp.mat33)
    solver_drift_p: wp.array(dtype=wp.vec3)
    solver_drift_r: wp.array(dtype=wp.mat33)
    solver_toi_shift: wp.array(dtype=wp.vec3)
    solver_impact_stamp: wp.array(dtype=wp.int32)
    solver_pair_toi: wp.array(dtype=float)  # the earliest time a pair of the body closes this substep (impact.py)
    solver_event_time: wp.array(dtype=float)  # when the body's last impact of the substep struck (impact.pair_event_start)
    solver_event_partner: wp.array(dtype=wp.int32)  # with which body (NO_EVENT, OTHER_EVENT: impact.py)
    solver_support: wp.array(dtype=float)  # share of gravity the last substep's solve held (staged.support_share)
    solver_twist: wp.array(dtype=wp.vec4)  # terrain patch: centre (arm), friction arm scale (contact_patch.py)
    terrain_row_slot: wp.array(dtype=wp.int32)
    terrain_row_count: wp.array(dtype=wp.int32)
    impact_normal: wp.array(dtype=float)
    impact_tangent: wp.array(dtype=wp.vec3)


@wp.struct
class JointImpacts:
    """The joint phase's scratch (impact_joint.py; SoftStepSolver's arrays of the same names), apart
    from SolverBodies so that the kernels of a scene without it carry none of it."""

    # Solver in/out
    impact_v_start: wp.array(dtype=wp.vec3)  # the impact stage's start velocities
    impact_w_start: wp.array(dtype=wp.vec3)
    impact_terrain_event: wp.array(dtype=wp.vec2)  # a body's terrain member: (t*, e); t* < 0: none
    impact_member_count: wp.array(dtype=wp.int32)  # manifolds of the body closing at the stage's start
    impact_pair_event: wp.array(dtype=wp.vec2)  # per pair: a member's (t*, e)
    impact_pair_acc: wp.array(dtype=wp.vec4)  # per pair: a member's compression impulse at each point
    impact_member_list: wp.array(dtype=wp.int32)  # the members, for the slab schedule (joint_phase_in_order)


@wp.struct
class DomainSlabs:
    """The slabs of solvers/domains.py (collide/pair_pipeline.DomainSchedule's arrays)."""

    # In
    domain_body_start: wp.array(dtype=wp.int32)
    domain_body: wp.array(dtype=wp.int32)
    domain_pair_start: wp.array(dtype=wp.int32)
    domain_pair: wp.array(dtype=wp.int32)
    body_domain: wp.array(dtype=wp.int32)
    body_on_boundary: wp.array(dtype=wp.int32)
    boundary_body_count: wp.array(dtype=wp.int32)
    boundary_body: wp.array(dtype=wp.int32)
