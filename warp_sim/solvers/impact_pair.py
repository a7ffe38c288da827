"""One pair manifold's impact, in the pieces both impact phases take (impact.py says the model,
impact_joint.py the phase of simultaneous impacts): which points engage and when the pair
touches (t*), the points' rows at t*, Poisson's compression, restitution e P_c, and Coulomb
friction on the whole normal impulse (1 + e) P_c.  Each piece reads and returns a PairManifold
and writes nothing, so the sequential impact (one call after another) and the simultaneous one
(compression swept over many manifolds, restitution after all have converged) share them."""

import warp as wp

from ..kernel_args import BodyModel, PairContacts
from .impact_point import (coulomb_step, drift_turned, engage_speed, engaged, free_fall_share, gravity_kick,
                           spheres_miss, spheres_touch_time, time_to_contact)
from .impact_terrain import IMPACT_ITERATIONS, IMPACT_SLIP_TOLERANCE, IMPACT_SPEED_TOLERANCE, NOT_ENGAGED
from .pair_geometry import (NO_CONTACT, orthonormalized, pair_point_now, sphere_box_curvature, sphere_box_passes_clear,
                            straight_paths_surely_meet)
from .solver_args import SolverBodies, StepSettings

wp.set_module_options({"enable_backward": False})

POINTS = 4
# A sphere-box impact's time is refined on the contact found again at it (pair_engagement), at
# most this many times, until the gap there is under TOI_GAP_TOLERANCE [m]
SPHERE_BOX_REFINES = 3
TOI_GAP_TOLERANCE = 1.0e-5


@wp.struct
class PairEngagement:
    """Which points of a pair close within the substep (``acc``: 0 where engaged, NOT_ENGAGED
    elsewhere), when the pair touches (``toi``, from the substep's start), whether one closes
    faster than the engage speed (``hit``) and faster than the restitution threshold (``bounces``),
    and whether it is a ball and a spinning box that pass clear instead (``clear``)."""

    acc: wp.vec4
    toi: float
    hit: int
    bounces: int
    clear: int


@wp.struct
class PairManifold:
    """A pair's points at its time of impact (rows k of ``normal``, ``arm_i``, ``arm_j``), each
    point's compression impulse ``acc`` (NOT_ENGAGED: no part in the impact), each point's
    impact friction (rows of ``tangent``), and the two bodies' velocities."""

    normal: wp.mat44
    arm_i: wp.mat44
    arm_j: wp.mat44
    tangent: wp.mat44
    acc: wp.vec4
    vi: wp.vec3
    wi: wp.vec3
    vj: wp.vec3
    wj: wp.vec3


@wp.func
def row3(m: wp.mat44, k: int) -> wp.vec3:
    return wp.vec3(m[k, 0], m[k, 1], m[k, 2])


@wp.func
def sphere_turns(radius: float) -> float:
    """0 for a sphere: its anchor does not turn (soft_step.drift_rotation)."""
    return wp.where(radius > 0.0, 0.0, 1.0)


@wp.func(inline=True)
def pair_kick(i: int, j: int, inv_mi: float, inv_mj: float, settings: StepSettings, solver: SolverBodies) -> wp.vec3:
    """The relative speed the substep's gravity adds: to dynamic bodies, less what their contacts hold."""
    return gravity_kick(free_fall_share(inv_mi, solver.solver_support[i]),
                        free_fall_share(inv_mj, solver.solver_support[j]), settings.gravity, settings.h)


@wp.func(inline=True)
def pair_engagement(
    p: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in
    solver: SolverBodies,
    vi: wp.vec3,
    wi: wp.vec3,
    vj: wp.vec3,
    wj: wp.vec3,
    inv_mi: float,
    inv_mj: float,
    dpi: wp.vec3,
    dpj: wp.vec3,
    t0: float,
) -> PairEngagement:
    """Pair p's engaged points and time of impact, looked at from t0 (impact.impact_pair_velocity
    says when t0 > 0) at the pose the drifts ``dpi``, ``dpj`` (and the bodies' turn drifts) give,
    moving on at the velocities given."""
    out = PairEngagement()
    out.acc = wp.vec4(NOT_ENGAGED)
    out.hit = 0
    out.bounces = 0
    out.clear = 0
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    xi = solver.solver_ref_pos[i]
    xj = solver.solver_ref_pos[j]
    dri = solver.solver_drift_r[i]
    drj = solver.solver_drift_r[j]
    radius_i = model.body_sphere_radius[i]
    radius_j = model.body_sphere_radius[j]
    kick = pair_kick(i, j, inv_mi, inv_mj, settings, solver)
    turns_i = sphere_turns(radius_i)
    turns_j = sphere_turns(radius_j)
    left = settings.h - t0
    dpi0 = dpi + t0 * vi
    dpj0 = dpj + t0 * vj
    dri0 = drift_turned(dri, wi, t0, turns_i)
    drj0 = drift_turned(drj, wj, t0, turns_j)
    toi_left = left
    closest = float(NO_CONTACT)
    closing = float(0.0)
    for k in range(pairs.pair_point_count[p]):
        # (where the point sits follows the bodies' own masses, split or not)
        now = pair_point_now(pairs.pair_normal[p], pairs.pair_point[p * POINTS + k], pairs.pair_depth[p * POINTS + k],
                             pairs.pair_feature[p * POINTS + k], xi, xj, dpi0, dpj0, dri0, drj0, solver.solver_ref_rot,
                             i, j, model)
        vn = wp.dot(vi + wp.cross(wi, now.arm_i) - vj - wp.cross(wj, now.arm_j), now.normal)
        # engaged on the speed the substep's kick leaves, as impact_terrain's points
        if engaged(now.separation, vn + wp.dot(kick, now.normal), left):
            out.acc[k] = 0.0
            toi_left = time_to_contact(now.separation, vn, toi_left)
            closest = wp.min(closest, now.separation)
            closing = wp.max(closing, -vn)
            if vn < -engage_speed(settings.gravity, settings.h):
                out.hit = 1
            if vn < -settings.restitution_threshold:
                out.bounces = 1
    if out.hit == 0:
        return out
    if radius_i > 0.0 and radius_j > 0.0:
        # two balls: the line of centres' gap closes for one flying past the other too
        if spheres_miss(xi + dpi0 - xj - dpj0, vi - vj, radius_i + radius_j, left, left * wp.length(kick)):
            out.hit = 0
            return out
        toi_left = spheres_touch_time(xi + dpi0 - xj - dpj0, vi - vj, radius_i + radius_j, left, toi_left)
    toi = wp.min(t0 + toi_left, settings.h)  # rounding may not carry it past the substep
    # A sphere on a box: its contact found again at t* (pair_geometry.sphere_box_point) turns where
    # it meets an edge, so t* from the substep's start (gap / |v_n| along the normal there) is
    # refined on the geometry at t*, a few Newton steps on the gap
    sphere_box = (radius_i > 0.0) != (radius_j > 0.0)
    if sphere_box and t0 == 0.0 and closest > 0.0:
        # a spinning box whose point closes on its straight path may turn away instead: no impact
        # (pair_geometry.sphere_box_passes_clear), and the solve's rows let go (``clear``)
        sphere_is_i = radius_i > 0.0
        box = wp.where(sphere_is_i, j, i)
        v_ball = wp.where(sphere_is_i, vi, vj)
        v_box = wp.where(sphere_is_i, vj, vi)
        w_box = wp.where(sphere_is_i, wj, wi)
        curvature = sphere_box_curvature(v_ball, v_box, w_box, model.body_size[box], radius_i + radius_j)
        if not straight_paths_surely_meet(closing, toi_left, left, curvature):
            rot_box = orthonormalized((wp.identity(n=3, dtype=float) + wp.where(sphere_is_i, drj0, dri0))
                                      * solver.solver_ref_rot[box])
            if sphere_box_passes_clear(wp.where(sphere_is_i, xi + dpi0, xj + dpj0), v_ball, radius_i + radius_j,
                                       wp.where(sphere_is_i, xj + dpj0, xi + dpi0), v_box, w_box, rot_box,
                                       model.body_size[box], model.body_covered_faces[box], toi_left, curvature,
                                       left):
                out.hit = 0
                out.clear = 1
                return out
    for _refine in range(wp.where(sphere_box, SPHERE_BOX_REFINES, 0)):
        at = pair_point_now(pairs.pair_normal[p], pairs.pair_point[p * POINTS], pairs.pair_depth[p * POINTS],
                            pairs.pair_feature[p * POINTS], xi, xj, dpi + toi * vi, dpj + toi * vj,
                            drift_turned(dri, wi, toi, turns_i), drift_turned(drj, wj, toi, turns_j),
                            solver.solver_ref_rot, i, j, model)
        vn_at = wp.dot(vi + wp.cross(wi, at.arm_i) - vj - wp.cross(wj, at.arm_j), at.normal)
        if at.separation == NO_CONTACT or wp.abs(at.separation) <= TOI_GAP_TOLERANCE or vn_at >= 0.0:
            break
        toi = wp.clamp(toi + at.separation / -vn_at, t0, settings.h)
    out.toi = toi
    return out


@wp.func(inline=True)
def pair_manifold_at(
    p: int,
    toi: float,
    # Model
    model: BodyModel,
    # Contacts in
    pairs: PairContacts,
    # Solver in
    solver: SolverBodies,
    vi: wp.vec3,
    wi: wp.vec3,
    vj: wp.vec3,
    wj: wp.vec3,
    dpi: wp.vec3,
    dpj: wp.vec3,
    acc: wp.vec4,
) -> PairManifold:
    """Pair p's rows where the bodies touch, at t* = ``toi``: the bodies moved on from the drifts
    by toi v and turned by toi w.  A point lost there (NO_CONTACT) takes no part.  The velocities
    are left to the caller."""
    m = PairManifold()
    m.acc = acc
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    xi = solver.solver_ref_pos[i]
    xj = solver.solver_ref_pos[j]
    dpi_t = dpi + toi * vi
    dpj_t = dpj + toi * vj
    dri_t = drift_turned(solver.solver_drift_r[i], wi, toi, sphere_turns(model.body_sphere_radius[i]))
    drj_t = drift_turned(solver.solver_drift_r[j], wj, toi, sphere_turns(model.body_sphere_radius[j]))
    for k in range(pairs.pair_point_count[p]):
        at = pair_point_now(pairs.pair_normal[p], pairs.pair_point[p * POINTS + k], pairs.pair_depth[p * POINTS + k],
                            pairs.pair_feature[p * POINTS + k], xi, xj, dpi_t, dpj_t, dri_t, drj_t, solver.solver_ref_rot,
                            i, j, model)
        if at.separation == NO_CONTACT:
            m.acc[k] = NOT_ENGAGED
        for axis in range(3):
            m.normal[k, axis] = at.normal[axis]
            m.arm_i[k, axis] = at.arm_i[axis]
            m.arm_j[k, axis] = at.arm_j[axis]
    return m


@wp.func(inline=True)
def compress_pair(m: PairManifold, count: int, inv_mi: float, inv_mj: float, inv_ii: wp.mat33,
                  inv_ij: wp.mat33) -> PairManifold:
    """Poisson's compression: projected Gauss-Seidel on the engaged points from the impulses
    they hold, until no point approaches (an update changing no normal speed by more than
    IMPACT_SPEED_TOLERANCE)."""
    for _it in range(IMPACT_ITERATIONS):
        changed = float(0.0)  # as for the terrain: the most normal speed an update changed
        for k in range(count):
            if m.acc[k] >= 0.0:
                n = row3(m.normal, k)
                ri = row3(m.arm_i, k)
                rj = row3(m.arm_j, k)
                rni = wp.cross(ri, n)
                rnj = wp.cross(rj, n)
                k_n = inv_mi + inv_mj + wp.dot(rni, inv_ii * rni) + wp.dot(rnj, inv_ij * rnj)
                vn = wp.dot(m.vi + wp.cross(m.wi, ri) - m.vj - wp.cross(m.wj, rj), n)
                new_acc = wp.max(m.acc[k] - vn / k_n, 0.0)
                d = new_acc - m.acc[k]
                m.acc[k] = new_acc
                m.vi = m.vi + (inv_mi * d) * n
                m.wi = m.wi + inv_ii * (rni * d)
                m.vj = m.vj - (inv_mj * d) * n
                m.wj = m.wj - inv_ij * (rnj * d)
                changed = wp.max(changed, k_n * wp.abs(d))
        if changed < IMPACT_SPEED_TOLERANCE:
            break
    return m


@wp.func(inline=True)
def restitute_pair(m: PairManifold, count: int, e: float, inv_mi: float, inv_mj: float, inv_ii: wp.mat33,
                   inv_ij: wp.mat33) -> PairManifold:
    """Restitution: e times each point's compression impulse."""
    for k in range(count):
        if m.acc[k] > 0.0:
            n = row3(m.normal, k)
            bounce = e * m.acc[k]
            m.vi = m.vi + (inv_mi * bounce) * n
            m.wi = m.wi + inv_ii * (wp.cross(row3(m.arm_i, k), n) * bounce)
            m.vj = m.vj - (inv_mj * bounce) * n
            m.wj = m.wj - inv_ij * (wp.cross(row3(m.arm_j, k), n) * bounce)
    return m


@wp.func(inline=True)
def pair_impact_friction(m: PairManifold, count: int, e: float, mu: float, inv_mi: float, inv_mj: float,
                         inv_ii: wp.mat33, inv_ij: wp.mat33) -> PairManifold:
    """Coulomb friction on the whole normal impulse, |P_t| <= mu (1 + e) P_c per point, against the
    slip the normal impulses left; swept until converged, as for the terrain (impact_terrain)."""
    m.tangent = wp.mat44(0.0)  # rows: the accumulated tangential impulse of each point (x, y, z, -)
    for _it in range(IMPACT_ITERATIONS):
        removed = float(0.0)
        for k in range(count):
            if m.acc[k] > 0.0:
                n = row3(m.normal, k)
                ri = row3(m.arm_i, k)
                rj = row3(m.arm_j, k)
                vr = m.vi + wp.cross(m.wi, ri) - m.vj - wp.cross(m.wj, rj)
                vt = vr - wp.dot(vr, n) * n
                old_t = row3(m.tangent, k)
                k_t = inv_mi + inv_mj
                slip = wp.length(vt)
                if slip > 1.0e-9:
                    c = vt / slip
                    rti = wp.cross(ri, c)
                    rtj = wp.cross(rj, c)
                    k_t = k_t + wp.dot(rti, inv_ii * rti) + wp.dot(rtj, inv_ij * rtj)
                new_t = coulomb_step(old_t, vt, k_t, mu * (1.0 + e) * m.acc[k])
                m.tangent[k, 0] = new_t[0]
                m.tangent[k, 1] = new_t[1]
                m.tangent[k, 2] = new_t[2]
                change = new_t - old_t
                m.vi = m.vi + inv_mi * change
                m.wi = m.wi + inv_ii * wp.cross(ri, change)
                m.vj = m.vj - inv_mj * change
                m.wj = m.wj - inv_ij * wp.cross(rj, change)
                removed = wp.max(removed, k_t * wp.length(change))
        if removed < IMPACT_SLIP_TOLERANCE:
            break
    return m
