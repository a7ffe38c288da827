"""Soft-step solver stages for scenes with body-body contact.

The same algorithm as soft_step.py (read its docstring for the derivation), split into
launches because a pair couples two bodies: per-body stages run one thread per body, pair
stages one thread per pair of one colour (pairs of a colour share no dynamic body).  One substep:

    [impacts: impact.py, only with restitution in the scene]
    -> prepare (body) -> warm start (pairs, by colour)
    -> iterations x [terrain sweep (body), pair sweep (each colour)]       with soft bias
    -> integrate positions (body)
    -> relax_iterations x [terrain sweep (body), pair sweep (each colour)] no bias
    -> finalize (body)

Contacts found once serve several substeps (Box2D v3's soft step; SimConfig.contact_update):
the pose at which they were found is the reference.  Anchor arms r = p - x_ref stay fixed
("fixed anchors", Solver2D's soft step), and every sweep measures the gap as the one found,
grown by how far the two anchors have since moved apart along n:

    s = -depth + n . ((dp_i + D_i r_i) - (dp_j + D_j r_j)),   dp = x - x_ref

with D from soft_step.drift_rotation (R R_ref^T - I for a box, 0 for a sphere).  This is the
first-order (tangent-plane) gap: on a surface of curvature k a point sliding a distance d
drifts k d^2 / 2 from it until the next collision pass corrects it.

Pair contact algebra, for a point with arms r_i = p - x_i, r_j = p - x_j and normal n (j -> i):

    v_rel = (v_i + w_i x r_i) - (v_j + w_j x r_j),   v_n = v_rel . n
    k_n   = 1/m_i + 1/m_j + (r_i x n) . I_i^-1 (r_i x n) + (r_j x n) . I_j^-1 (r_j x n)

impulse P = lambda n goes +P to i and -P to j.  Friction mixes as mu = sqrt(mu_i mu_j) and
restitution as max(e_i, e_j) (Box2D's rules).
"""

import warp as wp

from ..collide.contact_patch import NO_TWIST, terrain_patch
from ..kernel_args import BadSteps, BodyModel, BodyState, TerrainContacts
from ..integrate import free_drift, integrate_rotation, pre_kick_fraction, same_vector, world_inertia, world_inv_inertia
from ..types import ROTATION_MATRIX, SHAPE_SPHERE
from .contact_rows import solve_terrain_row
from .impact_point import engage_speed
from .body_velocity import BodyVelocity, apply_contact_impulse, apply_impulse
from .rolling import hold_ball, isotropic_inverse, solve_rolling
from .soft_step import drift_rotation, row_meets_an_impact, solve_sweeps, sweep_converged, warm_start_terrain
from .solver_args import SolverBodies, StepSettings

wp.set_module_options({"enable_backward": False})

POINTS = 4

# prepare_body's make_rows: none (the push-out baseline), per collision pass (a body's active slots
# do not change within one, see prepare_body), or every substep (terrain contacts found again, tests)
MAKE_ROWS_NONE = 0
MAKE_ROWS = 1
MAKE_ROWS_ALWAYS = 2


@wp.func
def body_twist(
    i: int,
    first: int,
    count: int,
    listed: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
) -> wp.vec4:
    """Body i's terrain patch (collide/contact_patch.terrain_patch, over its listed rows or its
    active slots), kept in solver_twist for the sweeps; friction at the points themselves under
    ``face_friction = "points"``."""
    twist = NO_TWIST
    if settings.face_patch != 0:
        twist = terrain_patch(first, count, listed, solver.solver_ref_pos[i], solver.solver_ref_rot[i],
                              model.body_friction[i], solver.terrain_row_slot, slots.terrain_contact_active,
                              slots.terrain_contact_point, slots.terrain_contact_normal, slots.terrain_contact_depth,
                              slots.terrain_contact_normal_impulse)
    solver.solver_twist[i] = twist
    return twist


@wp.func(inline=True)
def prepare_body(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    reset_reference: int,
    make_rows: int,
    from_impact: int,
    # State in
    state_in: BodyState,
    # Contacts in/out
    slots: TerrainContacts,
    # Solver out
    solver: SolverBodies,
):
    solver.solver_rolling[i] = wp.vec3(0.0)
    solver.solver_load_mass[i] = 0.0  # the pairs' warm start sets it (pair_solve.CHAIN_MASS_RATIO)
    if reset_reference != 0:
        # the contacts were just found at this pose: anchors are measured from it
        solver.solver_ref_pos[i] = state_in.body_pos[i]
        solver.solver_ref_rot[i] = state_in.body_rot[i]
        solver.solver_drift_p[i] = wp.vec3(0.0)
        solver.solver_drift_r[i] = wp.mat33(0.0)
    inv_mass = model.body_inv_mass[i]
    if inv_mass == 0.0:
        solver.terrain_row_count[i] = 0
        solver.solver_v[i] = wp.vec3(0.0)
        solver.solver_w[i] = wp.vec3(0.0)
        solver.solver_w0[i] = wp.vec3(0.0)
        solver.solver_inv_inertia[i] = wp.mat33(0.0)
        return
    # A sphere or a cube has I^-1 = d 1, so R I^-1 R^T = d 1 for every orthonormal R: taken exactly,
    # it is the same in every substep.  Not under the plain matrix rotation, whose R drifts from
    # orthonormal (R R^T != 1) by design.
    body_d = model.body_inv_inertia[i]
    isotropic = settings.rotation != ROTATION_MATRIX and body_d[0] == body_d[1] and body_d[1] == body_d[2]
    inv_inertia = wp.diag(body_d)
    if not isotropic:
        inv_inertia = world_inv_inertia(state_in.body_rot[i], body_d)
    vel = BodyVelocity()
    solver.solver_w0[i] = inv_inertia * state_in.body_angmom[i]
    if from_impact != 0:
        # impact.py left the post-impact velocities, without this substep's gravity
        vel.v = solver.solver_v[i] + settings.h * settings.gravity
        vel.w = solver.solver_w[i]
    else:
        pre_kick = pre_kick_fraction(settings.integrator) * settings.h
        vel.v = state_in.body_vel[i] + pre_kick * settings.gravity
        vel.w = solver.solver_w0[i]
    x_ref = solver.solver_ref_pos[i]
    start = model.body_checkpoint_start[i]
    count = model.body_checkpoint_count[i]
    # friction acts at the arms of the patch (collide/contact_patch.py) the impulses carried into the
    # contacts make: measured where the rows are made (once a collision pass, over the rows listed),
    # kept for later substeps and the sweeps
    twist = NO_TWIST
    if make_rows != 0 and (reset_reference != 0 or make_rows == MAKE_ROWS_ALWAYS):
        # the active slots listed, then warm-started in the same order as warm_start_terrain; the list
        # holds until the terrain contacts are found again
        rows = int(0)
        for slot in range(start, start + count):
            if slots.terrain_contact_active[slot] != 0:
                solver.terrain_row_slot[start + rows] = slot
                rows += 1
        solver.terrain_row_count[i] = rows
        twist = body_twist(i, start, rows, 1, model, settings, slots, solver)
    elif make_rows != 0:
        twist = solver.solver_twist[i]  # the list of an earlier substep still holds, and its patch
    if make_rows != 0:
        for k in range(solver.terrain_row_count[i]):
            slot = solver.terrain_row_slot[start + k]
            arm = slots.terrain_contact_point[slot] - x_ref
            n = slots.terrain_contact_normal[slot]
            vel = apply_contact_impulse(vel, slots.terrain_contact_normal_impulse[slot] * n,
                                        slots.terrain_contact_tangent_impulse[slot], arm, n, twist, inv_mass,
                                        inv_inertia)
    else:
        solver.terrain_row_count[i] = 0
        twist = body_twist(i, start, count, 0, model, settings, slots, solver)
        vel = warm_start_terrain(start, count, x_ref, vel, inv_mass, inv_inertia, twist,
                                 slots.terrain_contact_active, slots.terrain_contact_point,
                                 slots.terrain_contact_normal, slots.terrain_contact_normal_impulse,
                                 slots.terrain_contact_tangent_impulse)
    solver.solver_v[i] = vel.v
    solver.solver_w[i] = vel.w
    solver.solver_inv_inertia[i] = inv_inertia


@wp.kernel
def prepare_bodies(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    reset_reference: int,
    make_rows: int,
    from_impact: int,
    # State in
    state_in: BodyState,
    # Contacts in/out
    slots: TerrainContacts,
    # Solver out
    solver: SolverBodies,
):
    # a twin of prepare_body (domain_sweep calls it too): the colour schedule launches it per body
    prepare_body(wp.tid() + tid_offset, model, settings, reset_reference, make_rows, from_impact, state_in,
                 slots, solver)


@wp.func
def sweep_body_terrain(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    use_bias: int,
    # Contacts in/out
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
):
    """One terrain sweep of body i over its active contacts, with the rows built by prepare_bodies."""
    count = solver.terrain_row_count[i]
    inv_mass = model.body_inv_mass[i]
    if inv_mass == 0.0 or count == 0:
        return
    rolling = float(0.0)
    if model.body_shape[i] == SHAPE_SPHERE:
        rolling = model.body_rolling_resistance[i] * model.body_size[i][0]
    friction = model.body_friction[i]
    x_ref = solver.solver_ref_pos[i]
    drift_p = solver.solver_drift_p[i]
    drift_r = solver.solver_drift_r[i]
    v = solver.solver_v[i]
    w = solver.solver_w[i]
    rolling_impulse = solver.solver_rolling[i]
    load_mass = solver.solver_load_mass[i]
    start = model.body_checkpoint_start[i]
    # A relax sweep takes the push-out speed back (soft_step.py).  One pass over a box's contacts
    # left 22 % of it (each point can give back only its own share of the impulse; a cube started
    # 2 cm deep without gravity then drifted off at 0.077 m/s), so a relax walks the body's own
    # rows again until a pass moves no point by more than the convergence tolerance.
    passes = wp.where(count == 1, 1, settings.relax_passes)  # one point gives all back in one
    if use_bias > 0 and count > 1:
        # a solve sweep takes one pass, but rows that hold no impulse yet start cold and are swept
        # until converged (soft_step.solve_sweeps)
        holding = int(0)
        for k in range(count):
            if slots.terrain_contact_normal_impulse[solver.terrain_row_slot[start + k]] > 0.0:
                holding = 1
                break
        if holding != 0:
            # only a holding body's rows are asked, and the first that meets a blow settles it
            engage = engage_speed(settings.gravity, settings.h)
            for k in range(count):
                slot = solver.terrain_row_slot[start + k]
                arm = slots.terrain_contact_point[slot] - x_ref
                n = slots.terrain_contact_normal[slot]
                separation = -slots.terrain_contact_depth[slot] + wp.dot(drift_p + drift_r * arm, n)
                if row_meets_an_impact(arm, n, separation, slots.terrain_contact_normal_impulse[slot], v, w,
                                       settings.h, engage):
                    holding = 0
                    break
        passes = solve_sweeps(1, settings.relax_passes, count, holding)
    reach = wp.length(model.body_size[i])
    inv_inertia = solver.solver_inv_inertia[i]
    twist = solver.solver_twist[i]  # where friction acts (contact_patch.py; prepare_body measured it)
    for _pass in range(passes):
        before = BodyVelocity()
        before.v = v
        before.w = w
        for k in range(count):
            # the rows are built from the slot each time (contact_rows.solve_terrain_row says why)
            slot = solver.terrain_row_slot[start + k]
            arm = slots.terrain_contact_point[slot] - x_ref
            n = slots.terrain_contact_normal[slot]
            # the gap found at the reference pose, grown by the anchor's motion since (drift_rotation)
            separation = -slots.terrain_contact_depth[slot] + wp.dot(drift_p + drift_r * arm, n)
            vw = solve_terrain_row(slot, arm, twist, n, separation, v, w, inv_mass, inv_inertia, friction,
                                   settings.h, use_bias, settings.soft, settings.max_push_velocity, load_mass, settings.soft_load,
                                   slots.terrain_contact_normal_impulse, slots.terrain_contact_tangent_impulse)
            w = wp.spatial_top(vw)
            v = wp.spatial_bottom(vw)
            if rolling > 0.0:
                vel = BodyVelocity()
                vel.v = v
                vel.w = w
                vel.rolling_impulse = rolling_impulse
                # held still at once where friction and rolling resistance can (rolling.hold_ball)
                hold = hold_ball(vel, n, arm, inv_mass, isotropic_inverse(inv_inertia), friction, rolling,
                                 slots.terrain_contact_normal_impulse[slot], slots.terrain_contact_tangent_impulse[slot])
                vel = hold.vel
                slots.terrain_contact_tangent_impulse[slot] = hold.tangent_impulse
                if hold.held == 0:
                    vel = solve_rolling(vel, n, solver.solver_inv_inertia[i],
                                        rolling * slots.terrain_contact_normal_impulse[slot])
                v = vel.v
                w = vel.w
                rolling_impulse = vel.rolling_impulse
        after = BodyVelocity()
        after.v = v
        after.w = w
        if sweep_converged(before, after, reach, settings.convergence_tolerance):
            break
    solver.solver_v[i] = v
    solver.solver_w[i] = w
    solver.solver_rolling[i] = rolling_impulse


@wp.kernel
def terrain_sweep(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    use_bias: int,
    # Contacts in/out
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
):
    # a twin of sweep_body_terrain (domain_sweep calls it too): the colour schedule launches it per body
    sweep_body_terrain(wp.tid() + tid_offset, model, settings, use_bias, slots, solver)


@wp.func(inline=True)
def integrate_body(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # State in
    state_in: BodyState,
    # Solver in/out
    solver: SolverBodies,
    # State out
    state_out: BodyState,
):
    x = state_in.body_pos[i]
    q = state_in.body_quat[i]
    rot = state_in.body_rot[i]
    if model.body_inv_mass[i] == 0.0:
        state_out.body_pos[i] = x
        state_out.body_quat[i] = q
        state_out.body_rot[i] = rot
        solver.solver_shift_v[i] = wp.vec3(0.0)
        solver.solver_shift_w[i] = wp.vec3(0.0)
        solver.solver_drift_p[i] = wp.vec3(0.0)
        solver.solver_drift_r[i] = wp.mat33(0.0)
        return
    v = solver.solver_v[i]
    w = solver.solver_w[i]
    # L changes only by what the contacts did (w - w0): free flight keeps L bit-exact
    angmom = state_in.body_angmom[i] + world_inertia(rot, model.body_inertia[i]) * (w - solver.solver_w0[i])
    q_new, rot_new = integrate_rotation(q, rot, model.body_inv_inertia[i], angmom, settings.h,
                                        settings.integrator, settings.rotation)
    # the impacts' time-of-impact shift (impact.py), spent here: zero unless this substep had one;
    # a body nothing touched (its velocity still the kicked one, bit for bit) drifts on the parabola
    kicked = state_in.body_vel[i] + (pre_kick_fraction(settings.integrator) * settings.h) * settings.gravity
    untouched = solver.solver_impact_stamp[i] < 0 and same_vector(v, kicked) and same_vector(w, solver.solver_w0[i])
    step = settings.h * v + solver.solver_toi_shift[i] + free_drift(settings.integrator, untouched, settings.gravity,
                                                                     settings.h)
    solver.solver_toi_shift[i] = wp.vec3(0.0)
    x_new = x + step
    state_out.body_pos[i] = x_new
    state_out.body_quat[i] = q_new
    state_out.body_rot[i] = rot_new
    solver.solver_shift_v[i] = step
    solver.solver_shift_w[i] = settings.h * w
    solver.solver_drift_p[i] = x_new - solver.solver_ref_pos[i]
    solver.solver_drift_r[i] = drift_rotation(model.body_shape[i], rot_new, solver.solver_ref_rot[i])


@wp.kernel
def integrate_positions(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # State in
    state_in: BodyState,
    # Solver in/out
    solver: SolverBodies,
    # State out
    state_out: BodyState,
):
    # a twin of integrate_body (domain_sweep calls it too): the colour schedule launches it per body
    integrate_body(wp.tid() + tid_offset, model, settings, state_in, solver, state_out)



@wp.func
def support_share(v_before: wp.vec3, v_after: wp.vec3, gravity: wp.vec3, h: float) -> float:
    """The share of gravity a body's contacts held in a substep's solve: its velocity change against
    gravity over one substep of gravity, clamped to [0, 1] (0: falling free, 1: resting).

    The impact stage (impact.py) takes an impact at its time t* within the substep, on the
    velocities the bodies have then.  A falling body has gained g t* by then; a body resting on
    the ground or on a stack has not, its contacts hold it.  Counting g t* for a resting body too
    cancelled the striker's own g t* from the closing speed: a cube dropped with e = 0.8 on a
    1000 kg box resting on the plane left at 4.29 m/s where the static box gave 4.35 (the momentum
    the box can take accounts for 0.01 of it), (1 + e) g t* of speed lost.  The last substep's
    solve is the estimate of this one's support (the contact solve that will hold the body runs
    after the impact stage)."""
    gg = wp.dot(gravity, gravity)
    if gg == 0.0:
        return 0.0
    return wp.clamp(-wp.dot(v_after - v_before, gravity) / (gg * h), 0.0, 1.0)


@wp.func(inline=True)
def finalize_body(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # State in
    state_in: BodyState,
    # Solver in/out
    solver: SolverBodies,
    # State in/out (positions written by integrate_positions)
    state_out: BodyState,
    # Out
    bad_steps: BadSteps,
):
    if model.body_inv_mass[i] == 0.0:
        state_out.body_vel[i] = state_in.body_vel[i]
        state_out.body_angmom[i] = state_in.body_angmom[i]
        return
    pre_kick = pre_kick_fraction(settings.integrator)
    if solver.solver_impact_stamp[i] < 0:
        # the solve started from state_in's velocity and this substep's pre-kick (prepare_body; an
        # impact's body kept its last share: its velocity before the solve is not state_in's)
        solver.solver_support[i] = support_share(state_in.body_vel[i] + (pre_kick * settings.h) * settings.gravity,
                                                 solver.solver_v[i], settings.gravity, settings.h)
    v = solver.solver_v[i] + ((1.0 - pre_kick) * settings.h) * settings.gravity
    inertia = world_inertia(state_in.body_rot[i], model.body_inertia[i])
    angmom = state_in.body_angmom[i] + inertia * (solver.solver_w[i] - solver.solver_w0[i])
    state_out.body_vel[i] = v
    state_out.body_angmom[i] = angmom
    x = state_out.body_pos[i]
    rot = state_out.body_rot[i]
    total = wp.dot(x, x) + wp.dot(v, v) + wp.dot(angmom, angmom) + wp.ddot(rot, rot)
    if not wp.isfinite(total):
        if bad_steps.body_bad_step[i] < 0:
            bad_steps.body_bad_step[i] = bad_steps.sim_step[0]
            wp.atomic_add(bad_steps.bad_count, 0, 1)


@wp.kernel
def finalize_bodies(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # State in
    state_in: BodyState,
    # Solver in/out
    solver: SolverBodies,
    # State in/out (positions written by integrate_positions)
    state_out: BodyState,
    # Out
    bad_steps: BadSteps,
):
    # a twin of finalize_body (domain_sweep calls it too): the colour schedule launches it per body
    finalize_body(wp.tid() + tid_offset, model, settings, state_in, solver, state_out, bad_steps)
