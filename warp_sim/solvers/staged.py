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

from ..integrate import integrate_rotation, pre_kick_fraction, world_inertia, world_inv_inertia
from ..types import ROTATION_MATRIX, SHAPE_SPHERE
from .contact_rows import TerrainRow, make_terrain_row, solve_terrain_row
from .soft_step import BodyVelocity, apply_impulse, drift_rotation, solve_rolling, warm_start_terrain

wp.set_module_options({"enable_backward": False})

POINTS = 4

# prepare_body's make_rows: none (the push-out baseline), per collision pass for bodies whose rows
# cannot change within it (spheres and cubes, see prepare_body), or every substep (for tests)
MAKE_ROWS_NONE = 0
MAKE_ROWS = 1
MAKE_ROWS_ALWAYS = 2


@wp.func(inline=True)
def prepare_body(
    i: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.vec3),
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
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
    # Contacts in/out
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
    # Out
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_rolling: wp.array(dtype=wp.vec3),
    solver_w0: wp.array(dtype=wp.vec3),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_ref_rot: wp.array(dtype=wp.mat33),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    terrain_row: wp.array(dtype=TerrainRow),
    terrain_row_count: wp.array(dtype=wp.int32),
):
    solver_rolling[i] = wp.vec3(0.0)
    if reset_reference != 0:
        # the contacts were just found at this pose: anchors are measured from it
        solver_ref_pos[i] = body_pos[i]
        solver_ref_rot[i] = body_rot[i]
        solver_drift_p[i] = wp.vec3(0.0)
        solver_drift_r[i] = wp.mat33(0.0)
    inv_mass = body_inv_mass[i]
    if inv_mass == 0.0:
        terrain_row_count[i] = 0
        solver_v[i] = wp.vec3(0.0)
        solver_w[i] = wp.vec3(0.0)
        solver_w0[i] = wp.vec3(0.0)
        solver_inv_inertia[i] = wp.mat33(0.0)
        return
    # A sphere or a cube has I^-1 = d 1, so R I^-1 R^T = d 1 for every orthonormal R: taken exactly,
    # it is the same in every substep, and so are its contact rows (arms, normals and depths are
    # fixed from the collision pass on).  Their rows are built once per collision pass.  Not under
    # the plain matrix rotation, whose R drifts from orthonormal (R R^T != 1) by design.
    body_d = body_inv_inertia[i]
    isotropic = rotation != ROTATION_MATRIX and body_d[0] == body_d[1] and body_d[1] == body_d[2]
    inv_inertia = wp.diag(body_d)
    if not isotropic:
        inv_inertia = world_inv_inertia(body_rot[i], body_d)
    vel = BodyVelocity()
    solver_w0[i] = inv_inertia * body_angmom[i]
    if from_impact != 0:
        # impact.py left the post-impact velocities, without this substep's gravity
        vel.v = solver_v[i] + h * gravity
        vel.w = solver_w[i]
    else:
        vel.v = body_vel[i] + (pre_kick_fraction(integrator) * h) * gravity
        vel.w = solver_w0[i]
    x_ref = solver_ref_pos[i]
    start = body_checkpoint_start[i]
    count = body_checkpoint_count[i]
    if make_rows != 0 and (reset_reference != 0 or not isotropic or make_rows == MAKE_ROWS_ALWAYS):
        # rows and warm start in one pass over the slots (the same impulses, in the same order,
        # as warm_start_terrain)
        rows = int(0)
        for slot in range(start, start + count):
            if terrain_contact_active[slot] != 0:
                arm = terrain_contact_point[slot] - x_ref
                n = terrain_contact_normal[slot]
                terrain_row[start + rows] = make_terrain_row(slot, arm, n, terrain_contact_depth[slot], inv_mass,
                                                             inv_inertia)
                rows += 1
                warm = terrain_contact_normal_impulse[slot] * n + terrain_contact_tangent_impulse[slot]
                vel = apply_impulse(vel, warm, arm, inv_mass, inv_inertia)
        terrain_row_count[i] = rows
    elif make_rows != 0:
        # the rows of an earlier substep still hold: warm-start from them, same impulses, same order
        for k in range(terrain_row_count[i]):
            row = terrain_row[start + k]
            warm = terrain_contact_normal_impulse[row.slot] * row.normal + terrain_contact_tangent_impulse[row.slot]
            vel = apply_impulse(vel, warm, row.arm, inv_mass, inv_inertia)
    else:
        terrain_row_count[i] = 0
        vel = warm_start_terrain(start, count, x_ref, vel, inv_mass,
                                 inv_inertia, terrain_contact_active, terrain_contact_point, terrain_contact_normal,
                                 terrain_contact_normal_impulse, terrain_contact_tangent_impulse)
    solver_v[i] = vel.v
    solver_w[i] = vel.w
    solver_inv_inertia[i] = inv_inertia


@wp.kernel
def prepare_bodies(
    tid_offset: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.vec3),
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
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
    # Contacts in/out
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
    # Out
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_rolling: wp.array(dtype=wp.vec3),
    solver_w0: wp.array(dtype=wp.vec3),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_ref_rot: wp.array(dtype=wp.mat33),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    terrain_row: wp.array(dtype=TerrainRow),
    terrain_row_count: wp.array(dtype=wp.int32),
):
    prepare_body(wp.tid() + tid_offset, body_inv_mass, body_inv_inertia, body_checkpoint_start, body_checkpoint_count,
                 gravity, h, integrator, rotation, reset_reference, make_rows, from_impact, body_pos, body_rot, body_vel,
                 body_angmom,
                 terrain_contact_active, terrain_contact_point, terrain_contact_normal, terrain_contact_depth,
                 terrain_contact_normal_impulse, terrain_contact_tangent_impulse, solver_v, solver_w, solver_inv_inertia,
                 solver_rolling, solver_w0, solver_ref_pos, solver_ref_rot, solver_drift_p, solver_drift_r, terrain_row,
                 terrain_row_count)


@wp.func
def sweep_body_terrain(
    i: int,
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_size: wp.array(dtype=wp.vec3),
    body_inv_mass: wp.array(dtype=float),
    body_friction: wp.array(dtype=float),
    body_rolling_resistance: wp.array(dtype=float),
    body_checkpoint_start: wp.array(dtype=wp.int32),
    # Settings
    h: float,
    use_bias: int,
    soft: wp.vec3,
    max_push_velocity: float,
    # Contacts in/out
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
    # Solver in/out
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_rolling: wp.array(dtype=wp.vec3),
    terrain_row: wp.array(dtype=TerrainRow),
    terrain_row_count: wp.array(dtype=wp.int32),
):
    """One terrain sweep of body i over its active contacts, with the rows built by prepare_bodies."""
    count = terrain_row_count[i]
    inv_mass = body_inv_mass[i]
    if inv_mass == 0.0 or count == 0:
        return
    rolling = float(0.0)
    if body_shape[i] == SHAPE_SPHERE:
        rolling = body_rolling_resistance[i] * body_size[i][0]
    friction = body_friction[i]
    x_ref = solver_ref_pos[i]
    drift_p = solver_drift_p[i]
    drift_r = solver_drift_r[i]
    v = solver_v[i]
    w = solver_w[i]
    rolling_impulse = solver_rolling[i]
    start = body_checkpoint_start[i]
    for k in range(count):
        row = terrain_row[start + k]
        # the gap found at the reference pose, grown by the anchor's motion since (drift_rotation)
        separation = -row.depth + wp.dot(drift_p + drift_r * row.arm, row.normal)
        vw = solve_terrain_row(row, separation, v, w, inv_mass, friction, h, use_bias, soft, max_push_velocity,
                               terrain_contact_normal_impulse, terrain_contact_tangent_impulse)
        w = wp.spatial_top(vw)
        v = wp.spatial_bottom(vw)
        if rolling > 0.0:
            vel = BodyVelocity()
            vel.v = v
            vel.w = w
            vel.rolling_impulse = rolling_impulse
            vel = solve_rolling(vel, row.normal, solver_inv_inertia[i],
                                rolling * terrain_contact_normal_impulse[row.slot])
            w = vel.w
            rolling_impulse = vel.rolling_impulse
    solver_v[i] = v
    solver_w[i] = w
    solver_rolling[i] = rolling_impulse


@wp.kernel
def terrain_sweep(
    tid_offset: int,
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_size: wp.array(dtype=wp.vec3),
    body_inv_mass: wp.array(dtype=float),
    body_friction: wp.array(dtype=float),
    body_rolling_resistance: wp.array(dtype=float),
    body_checkpoint_start: wp.array(dtype=wp.int32),
    # Settings
    h: float,
    use_bias: int,
    soft: wp.vec3,
    max_push_velocity: float,
    # Contacts in/out
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
    # Solver in/out
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_rolling: wp.array(dtype=wp.vec3),
    terrain_row: wp.array(dtype=TerrainRow),
    terrain_row_count: wp.array(dtype=wp.int32),
):
    sweep_body_terrain(wp.tid() + tid_offset, body_shape, body_size, body_inv_mass, body_friction,
                       body_rolling_resistance, body_checkpoint_start, h, use_bias, soft, max_push_velocity,
                       terrain_contact_normal_impulse, terrain_contact_tangent_impulse, solver_inv_inertia,
                       solver_ref_pos, solver_drift_p, solver_drift_r, solver_v, solver_w, solver_rolling,
                       terrain_row, terrain_row_count)


@wp.func(inline=True)
def integrate_body(
    i: int,
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_inv_mass: wp.array(dtype=float),
    body_inertia: wp.array(dtype=wp.vec3),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    # Settings
    h: float,
    integrator: int,
    rotation: int,
    # State in
    body_pos_in: wp.array(dtype=wp.vec3),
    body_quat_in: wp.array(dtype=wp.quat),
    body_rot_in: wp.array(dtype=wp.mat33),
    body_angmom_in: wp.array(dtype=wp.vec3),
    # Solver in/out
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_w0: wp.array(dtype=wp.vec3),
    solver_shift_v: wp.array(dtype=wp.vec3),
    solver_shift_w: wp.array(dtype=wp.vec3),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_ref_rot: wp.array(dtype=wp.mat33),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_toi_shift: wp.array(dtype=wp.vec3),
    # State out
    body_pos_out: wp.array(dtype=wp.vec3),
    body_quat_out: wp.array(dtype=wp.quat),
    body_rot_out: wp.array(dtype=wp.mat33),
):
    x = body_pos_in[i]
    q = body_quat_in[i]
    rot = body_rot_in[i]
    if body_inv_mass[i] == 0.0:
        body_pos_out[i] = x
        body_quat_out[i] = q
        body_rot_out[i] = rot
        solver_shift_v[i] = wp.vec3(0.0)
        solver_shift_w[i] = wp.vec3(0.0)
        solver_drift_p[i] = wp.vec3(0.0)
        solver_drift_r[i] = wp.mat33(0.0)
        return
    v = solver_v[i]
    w = solver_w[i]
    # L changes only by what the contacts did (w - w0): free flight keeps L bit-exact
    angmom = body_angmom_in[i] + world_inertia(rot, body_inertia[i]) * (w - solver_w0[i])
    q_new, rot_new = integrate_rotation(q, rot, body_inv_inertia[i], angmom, h, integrator, rotation)
    # the impacts' time-of-impact shift (impact.py), spent here: zero unless this substep had one
    step = h * v + solver_toi_shift[i]
    solver_toi_shift[i] = wp.vec3(0.0)
    x_new = x + step
    body_pos_out[i] = x_new
    body_quat_out[i] = q_new
    body_rot_out[i] = rot_new
    solver_shift_v[i] = step
    solver_shift_w[i] = h * w
    solver_drift_p[i] = x_new - solver_ref_pos[i]
    solver_drift_r[i] = drift_rotation(body_shape[i], rot_new, solver_ref_rot[i])


@wp.kernel
def integrate_positions(
    tid_offset: int,
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_inv_mass: wp.array(dtype=float),
    body_inertia: wp.array(dtype=wp.vec3),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    # Settings
    h: float,
    integrator: int,
    rotation: int,
    # State in
    body_pos_in: wp.array(dtype=wp.vec3),
    body_quat_in: wp.array(dtype=wp.quat),
    body_rot_in: wp.array(dtype=wp.mat33),
    body_angmom_in: wp.array(dtype=wp.vec3),
    # Solver in/out
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_w0: wp.array(dtype=wp.vec3),
    solver_shift_v: wp.array(dtype=wp.vec3),
    solver_shift_w: wp.array(dtype=wp.vec3),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_ref_rot: wp.array(dtype=wp.mat33),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_toi_shift: wp.array(dtype=wp.vec3),
    # State out
    body_pos_out: wp.array(dtype=wp.vec3),
    body_quat_out: wp.array(dtype=wp.quat),
    body_rot_out: wp.array(dtype=wp.mat33),
):
    integrate_body(wp.tid() + tid_offset, body_shape, body_inv_mass, body_inertia, body_inv_inertia, h, integrator,
                   rotation, body_pos_in, body_quat_in, body_rot_in, body_angmom_in, solver_v, solver_w, solver_w0,
                   solver_shift_v, solver_shift_w, solver_ref_pos, solver_ref_rot, solver_drift_p, solver_drift_r,
                   solver_toi_shift, body_pos_out, body_quat_out, body_rot_out)



@wp.func(inline=True)
def finalize_body(
    i: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_inertia: wp.array(dtype=wp.vec3),
    # Settings
    gravity: wp.vec3,
    h: float,
    integrator: int,
    sim_step: wp.array(dtype=wp.int32),
    # State in
    body_rot_in: wp.array(dtype=wp.mat33),
    body_vel_in: wp.array(dtype=wp.vec3),
    body_angmom_in: wp.array(dtype=wp.vec3),
    # Solver in
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_w0: wp.array(dtype=wp.vec3),
    # State in/out (positions written by integrate_positions)
    body_pos_out: wp.array(dtype=wp.vec3),
    body_rot_out: wp.array(dtype=wp.mat33),
    body_vel_out: wp.array(dtype=wp.vec3),
    body_angmom_out: wp.array(dtype=wp.vec3),
    # Out
    body_bad_step: wp.array(dtype=wp.int32),
    bad_count: wp.array(dtype=wp.int32),
):
    if body_inv_mass[i] == 0.0:
        body_vel_out[i] = body_vel_in[i]
        body_angmom_out[i] = body_angmom_in[i]
        return
    v = solver_v[i] + ((1.0 - pre_kick_fraction(integrator)) * h) * gravity
    angmom = body_angmom_in[i] + world_inertia(body_rot_in[i], body_inertia[i]) * (solver_w[i] - solver_w0[i])
    body_vel_out[i] = v
    body_angmom_out[i] = angmom
    x = body_pos_out[i]
    rot = body_rot_out[i]
    total = wp.dot(x, x) + wp.dot(v, v) + wp.dot(angmom, angmom) + wp.ddot(rot, rot)
    if not wp.isfinite(total):
        if body_bad_step[i] < 0:
            body_bad_step[i] = sim_step[0]
            wp.atomic_add(bad_count, 0, 1)


@wp.kernel
def finalize_bodies(
    tid_offset: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_inertia: wp.array(dtype=wp.vec3),
    # Settings
    gravity: wp.vec3,
    h: float,
    integrator: int,
    sim_step: wp.array(dtype=wp.int32),
    # State in
    body_rot_in: wp.array(dtype=wp.mat33),
    body_vel_in: wp.array(dtype=wp.vec3),
    body_angmom_in: wp.array(dtype=wp.vec3),
    # Solver in
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_w0: wp.array(dtype=wp.vec3),
    # State in/out (positions written by integrate_positions)
    body_pos_out: wp.array(dtype=wp.vec3),
    body_rot_out: wp.array(dtype=wp.mat33),
    body_vel_out: wp.array(dtype=wp.vec3),
    body_angmom_out: wp.array(dtype=wp.vec3),
    # Out
    body_bad_step: wp.array(dtype=wp.int32),
    bad_count: wp.array(dtype=wp.int32),
):
    finalize_body(wp.tid() + tid_offset, body_inv_mass, body_inertia, gravity, h, integrator, sim_step, body_rot_in,
                  body_vel_in, body_angmom_in, solver_v, solver_w, solver_w0, body_pos_out, body_rot_out, body_vel_out,
                  body_angmom_out, body_bad_step, bad_count)
