"""Spatial domains: how the staged solver uses every CPU core without colouring.

Graph colouring (schedule/coloring.py) makes a sweep parallel by splitting it into one launch per colour.
On a GPU that is the right trade.  On a CPU each launch that is split across cores pays a thread
hand-off (~90 us here, warp_sim/launch.py), and a colour of a few thousand pairs runs in about
that time: at 10k bodies the six or so colours of a sweep each ran on one core, and the pair
sweeps cost 15 ms of a 53 ms step.

Instead, cut the scene into D slabs (D = CPU threads) along its longer horizontal axis, with
equal solver work in each (work = 1 + active terrain contacts + contact points of a body).  A
pair whose dynamic bodies lie in one slab belongs to that slab; a pair across a cut is a
boundary pair.  One sweep is then

    D threads at once: each walks its slab's bodies (terrain contacts) then its pairs, in order
    one thread:        the boundary pairs, in order

No two threads touch one body in the first stage (a body is in one slab; static bodies are
never written), so there is no race, and each slab's sweep is plain sequential Gauss-Seidel,
which converges at least as fast as the coloured order.  Only the pairs across the D - 1 cuts
wait for the second stage: a few percent of the pairs in a pile.  Two launches per sweep instead
of one per colour plus one for the terrain.

The per-body stages of a substep ride on the sweep launches instead of paying hand-offs of
their own (solver.py, _step_domains): a slab thread prepares its bodies and warm-starts its
pairs at the start of the first sweep (its side of each boundary pair too: a warm start moves
each body by its own share only, see pair_solve.warm_start_pair_side); after the last solve
sweep it integrates, and after the relax sweep finalizes, its bodies that no boundary pair
touches, and the boundary thread does the others once their pairs are swept.  The static
bodies, listed after the slabs, are prepared, integrated and finalized (copied) by one thread
before the sweeps (domain_sweep with d = D + 1).

The slabs themselves are cut by warp_sim/schedule/slabs.py, once per collision pass.
"""

import warp as wp

from .contact_rows import TerrainRow
from .impact import impact_begin_body, impact_terrain_body
from .pair_solve import MODE_IMPACT, MODE_RELAX, MODE_RELAX_CLOSED, MODE_SOLVE, MODE_WARM_START, solve_one_pair, warm_start_pair_side
from .staged import finalize_body, integrate_body, prepare_body, sweep_body_terrain

wp.set_module_options({"enable_backward": False})

@wp.func
def walk(first: int, count: int, k: int, reverse: int) -> int:
    """The k-th index of [first, first + count), from the end when ``reverse``."""
    if reverse != 0:
        return first + count - 1 - k
    return first + k


@wp.kernel
def domain_sweep(
    tid_offset: int,
    first_domain: int,
    domain_count: int,
    mode: int,
    reverse: int,
    prepare: int,
    integrate: int,
    finalize: int,
    domain_body_start: wp.array(dtype=wp.int32),
    domain_body: wp.array(dtype=wp.int32),
    domain_pair_start: wp.array(dtype=wp.int32),
    domain_pair: wp.array(dtype=wp.int32),
    body_domain: wp.array(dtype=wp.int32),
    body_on_boundary: wp.array(dtype=wp.int32),
    boundary_body_count: wp.array(dtype=wp.int32),
    boundary_body: wp.array(dtype=wp.int32),
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_size: wp.array(dtype=wp.vec3),
    body_inv_mass: wp.array(dtype=float),
    body_inertia: wp.array(dtype=wp.vec3),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    body_friction: wp.array(dtype=float),
    body_restitution: wp.array(dtype=float),
    body_rolling_resistance: wp.array(dtype=float),
    body_rolling_arm: wp.array(dtype=float),
    body_sphere_radius: wp.array(dtype=float),
    body_checkpoint_start: wp.array(dtype=wp.int32),
    body_checkpoint_count: wp.array(dtype=wp.int32),
    # Settings
    gravity: wp.vec3,
    h: float,
    integrator: int,
    rotation: int,
    reset_reference: int,
    make_rows: int,
    from_impact: int,
    soft: wp.vec3,
    max_push_velocity: float,
    restitution_threshold: float,
    sim_step: wp.array(dtype=wp.int32),
    # State in
    body_pos_in: wp.array(dtype=wp.vec3),
    body_quat_in: wp.array(dtype=wp.quat),
    body_rot_in: wp.array(dtype=wp.mat33),
    body_vel_in: wp.array(dtype=wp.vec3),
    body_angmom_in: wp.array(dtype=wp.vec3),
    # Contacts in/out
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    # Solver in/out
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_w0: wp.array(dtype=wp.vec3),
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_rolling: wp.array(dtype=wp.vec3),
    solver_shift_v: wp.array(dtype=wp.vec3),
    solver_shift_w: wp.array(dtype=wp.vec3),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_ref_rot: wp.array(dtype=wp.mat33),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_toi_shift: wp.array(dtype=wp.vec3),
    terrain_row: wp.array(dtype=TerrainRow),
    terrain_row_count: wp.array(dtype=wp.int32),
    impact_normal: wp.array(dtype=float),
    impact_tangent: wp.array(dtype=wp.vec3),
    # State out
    body_pos_out: wp.array(dtype=wp.vec3),
    body_quat_out: wp.array(dtype=wp.quat),
    body_rot_out: wp.array(dtype=wp.mat33),
    body_vel_out: wp.array(dtype=wp.vec3),
    body_angmom_out: wp.array(dtype=wp.vec3),
    # Out
    body_bad_step: wp.array(dtype=wp.int32),
    bad_count: wp.array(dtype=wp.int32),
):
    """One sweep of one slab (d < domain_count: its bodies' terrain contacts, then its pairs) or of
    the boundary pairs (d == domain_count), in the pair_solve mode ``mode``; ``reverse`` walks the
    same sequence backwards (symmetric Gauss-Seidel, see the module docstring).

    The per-body stages ride on the sweeps (see the module docstring): with ``prepare`` a slab
    thread first prepares its bodies (prepare_body) and applies the warm start of its pairs and
    of its side of the boundary pairs; with ``integrate`` or ``finalize`` it integrates or
    finalizes, after its sweep, its bodies that no boundary pair touches, and the boundary thread
    the others after the boundary sweep.  d == domain_count + 1 runs all three stages for the
    static bodies."""
    d = first_domain + wp.tid() + tid_offset
    if d > domain_count:
        # the static bodies (listed after the slabs), before any sweep: the sweeps read their solver
        # state but never write it, and no slab owns them
        first = domain_body_start[domain_count]
        for k in range(domain_body_start[domain_count + 1] - first):
            i = domain_body[first + k]
            prepare_body(i, body_inv_mass, body_inv_inertia, body_checkpoint_start, body_checkpoint_count, gravity, h,
                         integrator, rotation, reset_reference, make_rows, from_impact, body_pos_in, body_rot_in, body_vel_in,
                         body_angmom_in, terrain_contact_active, terrain_contact_point, terrain_contact_normal,
                         terrain_contact_depth, terrain_contact_normal_impulse, terrain_contact_tangent_impulse,
                         solver_v, solver_w, solver_inv_inertia, solver_rolling, solver_w0, solver_ref_pos,
                         solver_ref_rot, solver_drift_p, solver_drift_r, terrain_row, terrain_row_count)
            integrate_body(i, body_shape, body_inv_mass, body_inertia, body_inv_inertia, h, integrator, rotation,
                           body_pos_in, body_quat_in, body_rot_in, body_angmom_in, solver_v, solver_w, solver_w0,
                           solver_shift_v, solver_shift_w, solver_ref_pos, solver_ref_rot, solver_drift_p,
                           solver_drift_r, solver_toi_shift, body_pos_out, body_quat_out, body_rot_out)
            finalize_body(i, body_inv_mass, body_inertia, gravity, h, integrator, sim_step, body_rot_in, body_vel_in,
                          body_angmom_in, solver_v, solver_w, solver_w0, body_pos_out, body_rot_out, body_vel_out,
                          body_angmom_out, body_bad_step, bad_count)
        return
    pair_first = domain_pair_start[d]
    pair_count = domain_pair_start[d + 1] - pair_first
    if d == domain_count:
        for q in range(pair_count):
            solve_one_pair(domain_pair[walk(pair_first, pair_count, q, reverse)], mode, body_inv_mass, body_friction,
                           body_restitution, body_rolling_arm, body_sphere_radius, h, gravity, soft, max_push_velocity, restitution_threshold, pair_body,
                           pair_point_count, pair_normal, pair_point, pair_depth, pair_normal_impulse,
                           pair_tangent_impulse, solver_inv_inertia, solver_ref_pos, solver_drift_p, solver_drift_r,
                           solver_v, solver_w, solver_toi_shift)
        for k in range(boundary_body_count[0]):
            i = boundary_body[k]
            if integrate != 0:
                integrate_body(i, body_shape, body_inv_mass, body_inertia, body_inv_inertia, h, integrator, rotation,
                               body_pos_in, body_quat_in, body_rot_in, body_angmom_in, solver_v, solver_w, solver_w0,
                               solver_shift_v, solver_shift_w, solver_ref_pos, solver_ref_rot, solver_drift_p,
                               solver_drift_r, solver_toi_shift, body_pos_out, body_quat_out, body_rot_out)
            if finalize != 0:
                finalize_body(i, body_inv_mass, body_inertia, gravity, h, integrator, sim_step, body_rot_in,
                              body_vel_in, body_angmom_in, solver_v, solver_w, solver_w0, body_pos_out, body_rot_out,
                              body_vel_out, body_angmom_out, body_bad_step, bad_count)
        return
    body_first = domain_body_start[d]
    body_count = domain_body_start[d + 1] - body_first
    if prepare != 0 and mode == MODE_IMPACT:
        for k in range(body_count):
            impact_begin_body(domain_body[body_first + k], body_inv_mass, body_inv_inertia, gravity, h, integrator,
                              rotation, reset_reference, body_pos_in, body_rot_in, body_vel_in, body_angmom_in,
                              solver_v, solver_w, solver_inv_inertia, solver_ref_pos, solver_ref_rot, solver_drift_p,
                              solver_drift_r, solver_toi_shift)
    elif prepare != 0:
        for k in range(body_count):
            prepare_body(domain_body[body_first + k], body_inv_mass, body_inv_inertia, body_checkpoint_start,
                         body_checkpoint_count, gravity, h, integrator, rotation, reset_reference, make_rows, from_impact,
                         body_pos_in,
                         body_rot_in, body_vel_in, body_angmom_in, terrain_contact_active, terrain_contact_point,
                         terrain_contact_normal, terrain_contact_depth, terrain_contact_normal_impulse,
                         terrain_contact_tangent_impulse, solver_v, solver_w, solver_inv_inertia, solver_rolling,
                         solver_w0, solver_ref_pos, solver_ref_rot, solver_drift_p, solver_drift_r, terrain_row,
                         terrain_row_count)
        for k in range(pair_count):
            solve_one_pair(domain_pair[pair_first + k], MODE_WARM_START, body_inv_mass, body_friction,
                           body_restitution, body_rolling_arm, body_sphere_radius, h, gravity, soft, max_push_velocity, restitution_threshold, pair_body,
                           pair_point_count, pair_normal, pair_point, pair_depth, pair_normal_impulse,
                           pair_tangent_impulse, solver_inv_inertia, solver_ref_pos, solver_drift_p, solver_drift_r,
                           solver_v, solver_w, solver_toi_shift)
        # this slab's side of each boundary pair: before any sweep, like the pairs inside (a
        # boundary impulse applied after the first sweep let a stack split across two slabs sag
        # 27 mm instead of 7)
        boundary_first = domain_pair_start[domain_count]
        for q in range(domain_pair_start[domain_count + 1] - boundary_first):
            p = domain_pair[boundary_first + q]
            ij = pair_body[p]
            for side in range(2):
                if body_domain[ij[side]] == d:
                    warm_start_pair_side(p, side, reset_reference, body_inv_mass, body_sphere_radius, body_pos_in,
                                         pair_body, pair_point_count, pair_normal, pair_point, pair_depth,
                                         pair_normal_impulse, pair_tangent_impulse, solver_inv_inertia,
                                         solver_ref_pos, solver_drift_p, solver_drift_r, solver_v, solver_w)
    terrain = mode == MODE_SOLVE or mode == MODE_RELAX or mode == MODE_RELAX_CLOSED
    use_bias = int(mode == MODE_SOLVE)
    if mode == MODE_RELAX_CLOSED:
        use_bias = -1
    # forward: terrain, then pairs; backward: the same sequence walked from its end
    for part in range(2):
        if (part == 0) == (reverse == 0):
            if mode == MODE_IMPACT:
                for k in range(body_count):
                    impact_terrain_body(domain_body[walk(body_first, body_count, k, reverse)], body_inv_mass,
                                        body_friction, body_restitution, body_checkpoint_start, body_checkpoint_count,
                                        h, gravity, restitution_threshold, terrain_contact_active, terrain_contact_point,
                                        terrain_contact_normal, terrain_contact_depth, solver_inv_inertia,
                                        solver_ref_pos, solver_drift_p, solver_drift_r, solver_v, solver_w,
                                        solver_toi_shift, impact_normal, impact_tangent)
            elif terrain:
                for k in range(body_count):
                    sweep_body_terrain(domain_body[walk(body_first, body_count, k, reverse)], body_shape, body_size,
                                       body_inv_mass, body_friction, body_rolling_resistance, body_checkpoint_start,
                                       h, use_bias, soft, max_push_velocity, terrain_contact_normal_impulse,
                                       terrain_contact_tangent_impulse, solver_inv_inertia, solver_ref_pos,
                                       solver_drift_p, solver_drift_r, solver_v, solver_w, solver_rolling, terrain_row,
                                       terrain_row_count)
        else:
            for k in range(pair_count):
                solve_one_pair(domain_pair[walk(pair_first, pair_count, k, reverse)], mode, body_inv_mass,
                               body_friction, body_restitution, body_rolling_arm, body_sphere_radius, h, gravity, soft, max_push_velocity,
                               restitution_threshold,
                               pair_body, pair_point_count, pair_normal, pair_point, pair_depth, pair_normal_impulse,
                               pair_tangent_impulse, solver_inv_inertia, solver_ref_pos, solver_drift_p,
                               solver_drift_r, solver_v, solver_w, solver_toi_shift)
    if integrate != 0 or finalize != 0:
        for k in range(body_count):
            i = domain_body[body_first + k]
            if body_on_boundary[i] != 0:
                continue  # a boundary pair moves it after this launch: the boundary thread does it
            if integrate != 0:
                integrate_body(i, body_shape, body_inv_mass, body_inertia, body_inv_inertia, h, integrator, rotation,
                               body_pos_in, body_quat_in, body_rot_in, body_angmom_in, solver_v, solver_w, solver_w0,
                               solver_shift_v, solver_shift_w, solver_ref_pos, solver_ref_rot, solver_drift_p,
                               solver_drift_r, solver_toi_shift, body_pos_out, body_quat_out, body_rot_out)
            if finalize != 0:
                finalize_body(i, body_inv_mass, body_inertia, gravity, h, integrator, sim_step, body_rot_in,
                              body_vel_in, body_angmom_in, solver_v, solver_w, solver_w0, body_pos_out, body_rot_out,
                              body_vel_out, body_angmom_out, body_bad_step, bad_count)
