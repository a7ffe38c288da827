"""Pair stages of the staged soft-step solver: one thread per pair of one colour.

See staged.py for the algebra.  A launch handles one colour; its pair range is read on the
device from ``color_start`` (so the launch sequence can be captured in a CUDA graph).  The
overflow colour's pairs may share bodies, so one thread walks them in order.
"""

import warp as wp

from ..schedule.coloring import color_range
from .impact import impact_pair
from .pair_geometry import pair_point_now

wp.set_module_options({"enable_backward": False})

POINTS = 4

MODE_WARM_START = 0
MODE_SOLVE = 1
MODE_RELAX = 2
MODE_IMPACT = 3  # impact.py: restitution and impact friction, before the warm start
# relax of a scene with restitution: open gaps are left to the next substep's impact stage, which
# bounces them with their full approach speed (a relax impulse would take part of it away)
MODE_RELAX_CLOSED = 4


@wp.struct
class PairVelocity:
    vi: wp.vec3
    wi: wp.vec3
    vj: wp.vec3
    wj: wp.vec3


@wp.func
def apply_pair_impulse(vel: PairVelocity, impulse: wp.vec3, ri: wp.vec3, rj: wp.vec3, inv_mi: float, inv_mj: float,
                       inv_ii: wp.mat33, inv_ij: wp.mat33) -> PairVelocity:
    out = vel
    out.vi = vel.vi + inv_mi * impulse
    out.wi = vel.wi + inv_ii * wp.cross(ri, impulse)
    out.vj = vel.vj - inv_mj * impulse
    out.wj = vel.wj - inv_ij * wp.cross(rj, impulse)
    return out


@wp.func
def relative_velocity(vel: PairVelocity, ri: wp.vec3, rj: wp.vec3) -> wp.vec3:
    return vel.vi + wp.cross(vel.wi, ri) - vel.vj - wp.cross(vel.wj, rj)


@wp.func
def normal_mass_inverse(n: wp.vec3, ri: wp.vec3, rj: wp.vec3, inv_mi: float, inv_mj: float, inv_ii: wp.mat33,
                        inv_ij: wp.mat33) -> float:
    rni = wp.cross(ri, n)
    rnj = wp.cross(rj, n)
    return inv_mi + inv_mj + wp.dot(rni, inv_ii * rni) + wp.dot(rnj, inv_ij * rnj)


@wp.func
def solve_one_pair(
    p: int,
    mode: int,
    body_inv_mass: wp.array(dtype=float),
    body_friction: wp.array(dtype=float),
    body_restitution: wp.array(dtype=float),
    body_rolling_arm: wp.array(dtype=float),
    body_sphere_radius: wp.array(dtype=float),
    h: float,
    gravity: wp.vec3,
    soft: wp.vec3,
    max_push_velocity: float,
    restitution_threshold: float,
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_toi_shift: wp.array(dtype=wp.vec3),
):
    if mode == MODE_IMPACT:
        impact_pair(p, body_inv_mass, body_friction, body_restitution, body_sphere_radius, h, gravity,
                    restitution_threshold,
                    pair_body,
                    pair_point_count, pair_normal, pair_point, pair_depth, solver_inv_inertia, solver_ref_pos,
                    solver_drift_p, solver_drift_r, solver_v, solver_w, solver_toi_shift)
        return
    ij = pair_body[p]
    i = ij[0]
    j = ij[1]
    n = pair_normal[p]
    inv_mi = body_inv_mass[i]
    inv_mj = body_inv_mass[j]
    inv_ii = solver_inv_inertia[i]
    inv_ij = solver_inv_inertia[j]
    xi = solver_ref_pos[i]
    xj = solver_ref_pos[j]
    drift_pi = solver_drift_p[i]
    drift_pj = solver_drift_p[j]
    drift_ri = solver_drift_r[i]
    drift_rj = solver_drift_r[j]
    vel = PairVelocity()
    vel.vi = solver_v[i]
    vel.wi = solver_w[i]
    vel.vj = solver_v[j]
    vel.wj = solver_w[j]
    friction = wp.sqrt(body_friction[i] * body_friction[j])
    count = pair_point_count[p]
    # rolling resistance of a sphere in the pair (terrain contacts: soft_step.solve_rolling); a
    # sphere's pair has one point, so the pair's second slot keeps its accumulated angular impulse
    rolling_arm = wp.max(body_rolling_arm[i], body_rolling_arm[j])
    if mode == MODE_WARM_START and count == 1:
        pair_tangent_impulse[p * POINTS + 1] = wp.vec3(0.0)
    normal_total = float(0.0)

    radius_i = body_sphere_radius[i]
    radius_j = body_sphere_radius[j]

    for k in range(count):
        slot = p * POINTS + k
        # normal, arms and gap now (pair_geometry.py: one point for both bodies keeps angular momentum)
        now = pair_point_now(pair_normal[p], pair_point[slot], pair_depth[slot], xi, xj, drift_pi, drift_pj,
                             drift_ri, drift_rj, radius_i, radius_j, inv_mi, inv_mj)
        n = now.normal
        ri = now.arm_i
        rj = now.arm_j
        acc = pair_normal_impulse[slot]
        if mode == MODE_WARM_START:
            vel = apply_pair_impulse(vel, acc * n + pair_tangent_impulse[slot], ri, rj, inv_mi, inv_mj, inv_ii,
                                     inv_ij)
        else:
            separation = now.separation
            # Non-penetration
            bias = float(0.0)
            mass_scale = float(1.0)
            impulse_scale = float(0.0)
            if separation > 0.0:
                if mode == MODE_RELAX_CLOSED:
                    continue
                bias = separation / h
            elif mode == MODE_SOLVE:
                bias = wp.max(soft[0] * separation, -max_push_velocity)
                mass_scale = soft[1]
                impulse_scale = soft[2]
            vn = wp.dot(relative_velocity(vel, ri, rj), n)
            old_t = pair_tangent_impulse[slot]
            if acc == 0.0 and vn + bias >= 0.0 and old_t[0] == 0.0 and old_t[1] == 0.0 and old_t[2] == 0.0:
                # idle and staying idle: no normal impulse, so a Coulomb disc of radius 0 and no
                # old friction to remove; the point would change nothing (contact_rows.py)
                continue
            k_n = normal_mass_inverse(n, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
            lam = -(mass_scale / k_n) * (vn + bias) - impulse_scale * acc
            new_acc = wp.max(acc + lam, 0.0)
            pair_normal_impulse[slot] = new_acc
            vel = apply_pair_impulse(vel, (new_acc - acc) * n, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
            # Friction: accumulated tangential impulse clamped to the Coulomb disc
            vr = relative_velocity(vel, ri, rj)
            vt = vr - wp.dot(vr, n) * n
            old_t = old_t - wp.dot(old_t, n) * n
            new_t = old_t
            slip = wp.length(vt)
            if slip > 1.0e-9:
                tangent = vt / slip
                k_t = normal_mass_inverse(tangent, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
                new_t = old_t - (slip / k_t) * tangent
            limit = friction * new_acc
            mag = wp.length(new_t)
            if mag > limit:
                new_t = new_t * (limit / mag)
            pair_tangent_impulse[slot] = new_t
            vel = apply_pair_impulse(vel, new_t - old_t, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
            normal_total = normal_total + new_acc

    if rolling_arm > 0.0 and count == 1 and (mode == MODE_SOLVE or mode == MODE_RELAX or mode == MODE_RELAX_CLOSED):
        # against the relative spin, with the mass of its axis, clamped to c_r r J_n
        acc_roll = pair_tangent_impulse[p * POINTS + 1]
        spin = vel.wi - vel.wj
        speed2 = wp.dot(spin, spin)
        new_roll = acc_roll
        if speed2 > 1.0e-18:
            new_roll = acc_roll - (speed2 / (wp.dot(spin, inv_ii * spin) + wp.dot(spin, inv_ij * spin))) * spin
        limit = rolling_arm * normal_total
        mag2 = wp.dot(new_roll, new_roll)
        if mag2 > limit * limit:
            new_roll = new_roll * (limit / wp.sqrt(mag2))
        pair_tangent_impulse[p * POINTS + 1] = new_roll
        vel.wi = vel.wi + inv_ii * (new_roll - acc_roll)
        vel.wj = vel.wj - inv_ij * (new_roll - acc_roll)

    # Only dynamic bodies are written: a static body may sit in many pairs of one colour.
    if inv_mi > 0.0:
        solver_v[i] = vel.vi
        solver_w[i] = vel.wi
    if inv_mj > 0.0:
        solver_v[j] = vel.vj
        solver_w[j] = vel.wj


@wp.func
def warm_start_pair_side(
    p: int,
    side: int,
    reset_reference: int,
    body_inv_mass: wp.array(dtype=float),
    body_sphere_radius: wp.array(dtype=float),
    body_pos: wp.array(dtype=wp.vec3),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
):
    """Pair p's stored impulses applied to one of its bodies (side 0: body i gets +P; side 1: body j
    gets -P).  A warm start touches each body with its own arm and inverse mass only, so the two
    halves of a pair whose bodies belong to two threads can be applied by those two threads
    (solvers/domains.py) and sum to MODE_WARM_START of solve_one_pair.  The other body's reference
    pose is being reset by its own thread when ``reset_reference`` is set: it is then read from
    body_pos (drift zero), as that thread will write it."""
    ij = pair_body[p]
    b = ij[side]
    inv_mass = body_inv_mass[b]
    if inv_mass == 0.0:
        return
    i = ij[0]
    j = ij[1]
    sign = wp.where(side == 0, 1.0, -1.0)
    inv_inertia = solver_inv_inertia[b]
    v = solver_v[b]
    w = solver_w[b]
    x_i = body_pos[i]
    x_j = body_pos[j]
    drift_pi = wp.vec3(0.0)
    drift_pj = wp.vec3(0.0)
    drift_ri = wp.mat33(0.0)
    drift_rj = wp.mat33(0.0)
    if reset_reference == 0:
        x_i = solver_ref_pos[i]
        x_j = solver_ref_pos[j]
        drift_pi = solver_drift_p[i]
        drift_pj = solver_drift_p[j]
        drift_ri = solver_drift_r[i]
        drift_rj = solver_drift_r[j]
    for k in range(pair_point_count[p]):
        slot = p * POINTS + k
        now = pair_point_now(pair_normal[p], pair_point[slot], pair_depth[slot], x_i, x_j, drift_pi, drift_pj,
                             drift_ri, drift_rj, body_sphere_radius[i], body_sphere_radius[j],
                             body_inv_mass[i], body_inv_mass[j])
        arm = wp.where(side == 0, now.arm_i, now.arm_j)
        impulse = sign * (pair_normal_impulse[slot] * now.normal + pair_tangent_impulse[slot])
        v = v + inv_mass * impulse
        w = w + inv_inertia * wp.cross(arm, impulse)
    solver_v[b] = v
    solver_w[b] = w


@wp.kernel
def pair_pass(
    tid_offset: int,
    mode: int,
    color: int,
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_friction: wp.array(dtype=float),
    body_restitution: wp.array(dtype=float),
    body_rolling_arm: wp.array(dtype=float),
    body_sphere_radius: wp.array(dtype=float),
    # Settings
    h: float,
    gravity: wp.vec3,
    soft: wp.vec3,
    max_push_velocity: float,
    restitution_threshold: float,
    # Contacts in/out
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    # Solver in/out
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_toi_shift: wp.array(dtype=wp.vec3),
):
    r = color_range(color, color_start, wp.tid() + tid_offset)
    for index in range(r[0], r[1]):
        solve_one_pair(color_pairs_sorted[index], mode, body_inv_mass, body_friction, body_restitution,
                       body_rolling_arm, body_sphere_radius, h, gravity, soft,
                       max_push_velocity, restitution_threshold, pair_body, pair_point_count,
                       pair_normal, pair_point, pair_depth, pair_normal_impulse, pair_tangent_impulse,
                       solver_inv_inertia, solver_ref_pos, solver_drift_p, solver_drift_r, solver_v, solver_w,
                       solver_toi_shift)
