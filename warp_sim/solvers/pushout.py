"""The thesis's contact response (SEED.md 3), kept as a baseline to measure against.

Velocity: one impulse per approaching contact closer than the contact threshold (the
speculative margin), no accumulation, no warm start:

    j   = -(1 + e) v_n / k_n                      (Baraff, SEED.md 3)
    j_t = clamp(slip / k_t, -(1 - gamma) j, (1 - gamma) j) along -t   (slipperiness, or mu)

Position: overlapping bodies are pushed apart by their penetration (SEED.md 3.4).  A terrain
contact moves the body out along the normal.  A pair's penetration vector d n is projected on
the world axis where it is largest, and only that component is applied, to the body lying
farther along that axis (or the dynamic one).  ``iterations`` passes walk the push along chains.

Its failure is what it exists to show: with three or more bodies in contact, pushing A out of B
pushes it into C, so a resting stack keeps vibrating (the thesis's "vibration problem"), and the
impulses, which never accumulate, cannot hold a resting load still.
"""

import warp as wp

from ..schedule.coloring import color_range
from .pair_solve import PairVelocity, apply_pair_impulse, normal_mass_inverse, relative_velocity
from .body_velocity import BodyVelocity, apply_impulse

wp.set_module_options({"enable_backward": False})

POINTS = 4


@wp.func
def tangent_impulse(vt: wp.vec3, k_t: float, limit: float) -> wp.vec3:
    """Friction impulse against the slip vt, clamped to ``limit`` (k_t: inverse effective mass)."""
    slip = wp.length(vt)
    if slip < 1.0e-9:
        return wp.vec3(0.0)
    magnitude = wp.min(slip / k_t, limit)
    return -(magnitude / slip) * vt


@wp.kernel
def pushout_terrain_impulse(
    tid_offset: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_restitution: wp.array(dtype=float),
    body_friction: wp.array(dtype=float),
    body_checkpoint_start: wp.array(dtype=wp.int32),
    body_checkpoint_count: wp.array(dtype=wp.int32),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # Contacts in
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    # Solver in/out
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
):
    i = wp.tid() + tid_offset
    inv_mass = body_inv_mass[i]
    if inv_mass == 0.0:
        return
    inv_inertia = solver_inv_inertia[i]
    x = body_pos[i]
    vel = BodyVelocity()
    vel.v = solver_v[i]
    vel.w = solver_w[i]
    start = body_checkpoint_start[i]
    for slot in range(start, start + body_checkpoint_count[i]):
        if terrain_contact_active[slot] != 0:
            n = terrain_contact_normal[slot]
            arm = terrain_contact_point[slot] - x
            vp = vel.v + wp.cross(vel.w, arm)
            vn = wp.dot(vp, n)
            if vn < 0.0:
                rn = wp.cross(arm, n)
                j = -(1.0 + body_restitution[i]) * vn / (inv_mass + wp.dot(rn, inv_inertia * rn))
                vel = apply_impulse(vel, j * n, arm, inv_mass, inv_inertia)
                vp = vel.v + wp.cross(vel.w, arm)
                vt = vp - wp.dot(vp, n) * n
                slip = wp.length(vt)
                if slip > 1.0e-9:
                    rt = wp.cross(arm, vt / slip)
                    k_t = inv_mass + wp.dot(rt, inv_inertia * rt)
                    vel = apply_impulse(vel, tangent_impulse(vt, k_t, body_friction[i] * j), arm, inv_mass,
                                        inv_inertia)
    solver_v[i] = vel.v
    solver_w[i] = vel.w


@wp.kernel
def pushout_terrain_position(
    tid_offset: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_checkpoint_start: wp.array(dtype=wp.int32),
    body_checkpoint_count: wp.array(dtype=wp.int32),
    # State in
    body_pos_in: wp.array(dtype=wp.vec3),
    # Contacts in
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    # Solver in/out
    solver_shift_v: wp.array(dtype=wp.vec3),
    solver_shift_w: wp.array(dtype=wp.vec3),
    # State out
    body_pos_out: wp.array(dtype=wp.vec3),
):
    i = wp.tid() + tid_offset
    if body_inv_mass[i] == 0.0:
        return
    x = body_pos_in[i]
    # push out by the deepest remaining penetration (pushing by each would count shared depth twice)
    deepest = float(0.0)
    normal = wp.vec3(0.0)
    start = body_checkpoint_start[i]
    for slot in range(start, start + body_checkpoint_count[i]):
        if terrain_contact_active[slot] != 0:
            n = terrain_contact_normal[slot]
            arm = terrain_contact_point[slot] - x
            moved = solver_shift_v[i] + wp.cross(solver_shift_w[i], arm)
            depth = terrain_contact_depth[slot] - wp.dot(moved, n)
            if depth > deepest:
                deepest = depth
                normal = n
    if deepest > 0.0:
        body_pos_out[i] = body_pos_out[i] + deepest * normal
        solver_shift_v[i] = solver_shift_v[i] + deepest * normal


@wp.kernel
def pushout_pair(
    tid_offset: int,
    position_pass: int,
    color: int,
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_restitution: wp.array(dtype=float),
    body_friction: wp.array(dtype=float),
    # State in
    body_pos_in: wp.array(dtype=wp.vec3),
    # Contacts in
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    # Solver in/out
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_shift_v: wp.array(dtype=wp.vec3),
    solver_shift_w: wp.array(dtype=wp.vec3),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    # State out
    body_pos_out: wp.array(dtype=wp.vec3),
):
    r = color_range(color, color_start, wp.tid() + tid_offset)
    for index in range(r[0], r[1]):
        p = color_pairs_sorted[index]
        ij = pair_body[p]
        i = ij[0]
        j = ij[1]
        n = pair_normal[p]
        inv_mi = body_inv_mass[i]
        inv_mj = body_inv_mass[j]
        xi = body_pos_in[i]
        xj = body_pos_in[j]
        if position_pass == 0:
            inv_ii = solver_inv_inertia[i]
            inv_ij = solver_inv_inertia[j]
            vel = PairVelocity()
            vel.vi = solver_v[i]
            vel.wi = solver_w[i]
            vel.vj = solver_v[j]
            vel.wj = solver_w[j]
            e = wp.max(body_restitution[i], body_restitution[j])
            mu = wp.sqrt(body_friction[i] * body_friction[j])
            for k in range(pair_point_count[p]):
                slot = p * POINTS + k
                ri = pair_point[slot] - xi
                rj = pair_point[slot] - xj
                vn = wp.dot(relative_velocity(vel, ri, rj), n)
                if vn < 0.0:
                    jn = -(1.0 + e) * vn / normal_mass_inverse(n, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
                    vel = apply_pair_impulse(vel, jn * n, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
                    vr = relative_velocity(vel, ri, rj)
                    vt = vr - wp.dot(vr, n) * n
                    slip = wp.length(vt)
                    if slip > 1.0e-9:
                        k_t = normal_mass_inverse(vt / slip, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
                        vel = apply_pair_impulse(vel, tangent_impulse(vt, k_t, mu * jn), ri, rj, inv_mi, inv_mj,
                                                 inv_ii, inv_ij)
            if inv_mi > 0.0:
                solver_v[i] = vel.vi
                solver_w[i] = vel.wi
            if inv_mj > 0.0:
                solver_v[j] = vel.vj
                solver_w[j] = vel.wj
        else:
            # the deepest remaining penetration of the pair, after what both bodies have moved
            deepest = float(0.0)
            for k in range(pair_point_count[p]):
                slot = p * POINTS + k
                ri = pair_point[slot] - xi
                rj = pair_point[slot] - xj
                moved = solver_shift_v[i] + wp.cross(solver_shift_w[i], ri) - solver_shift_v[j] - wp.cross(
                    solver_shift_w[j], rj)
                deepest = wp.max(deepest, pair_depth[slot] - wp.dot(moved, n))
            if deepest > 0.0:
                push = deepest * n  # moves i out of j
                axis = int(0)
                if wp.abs(push[1]) > wp.abs(push[axis]):
                    axis = 1
                if wp.abs(push[2]) > wp.abs(push[axis]):
                    axis = 2
                # the body with the larger coordinate on that axis moves on along it (away from the
                # other) by the whole component; a static body never moves
                move_i = inv_mi > 0.0 and (inv_mj == 0.0 or xi[axis] >= xj[axis])
                mover = j
                other = i
                if move_i:
                    mover = i
                    other = j
                if body_inv_mass[mover] > 0.0:
                    side = body_pos_in[mover][axis] - body_pos_in[other][axis]
                    if side == 0.0:
                        side = push[axis]
                        if mover == j:
                            side = -side
                    step = wp.vec3(0.0)
                    step[axis] = wp.sign(side) * wp.abs(push[axis])
                    body_pos_out[mover] = body_pos_out[mover] + step
                    solver_shift_v[mover] = solver_shift_v[mover] + step
