"""Soft-step contact solver for terrain contacts (after Box2D v3), one thread per body.

Per substep h, for each body (SEED.md 3 gives the impulse algebra, Baraff's j formula):

    0. impact        bounce and impact friction of the contacts closing fast (impact.py)
    1. pre-kick      v* = v + alpha g h                   (alpha from the integrator)
    2. warm start    re-apply last substep's accumulated impulses (slot = persistent identity)
    3. solve         up to `iterations` Gauss-Seidel sweeps with the soft bias (push-out); a body
                     stops early once a sweep changes its velocity by less than the tolerance
    4. integrate     x' = x + h v*, orientation by the integrator's scheme
    5. relax         `relax_iterations` sweeps without bias: the push-out velocity moved the body
                     out of the terrain but is removed here, so correcting penetration adds no energy
    7. post-kick     v' = v* + (1 - alpha) g h

Restitution is not part of the solve: impacts (contacts closing faster than the restitution
threshold) are resolved before the warm start, on the velocity the last solve left (impact.py).

Normal impulse with accumulation and clamping (Catto's sequential impulses):

    k_n   = 1/m + (r x n) . I^-1 (r x n)                       effective mass^-1 along n
    j     = -(massScale / k_n) (v_n + bias) - impulseScale * J_acc
    J_acc = max(J_acc + j, 0)                                    never pull

Soft constraint (Box2D's b2MakeSoft): a contact is a spring-damper of frequency
f = 1 / (4 h), or contact_hertz if that is lower (60 Hz at 4 substeps of 1/60 s), and damping
ratio zeta = 10.  With omega = 2 pi f,
a1 = 2 zeta + h omega, a2 = h omega a1, a3 = 1 / (1 + a2):
biasRate = omega / a1, massScale = a2 a3, impulseScale = a3.  A speculative contact (gap s > 0)
instead allows v_n >= -s / h, exactly closing the gap in one substep.  Push-out speed is capped.

Friction: Coulomb, the accumulated tangential impulse vector is clamped to the disc
|J_t| <= mu J_n; each sweep pushes it against the current slip direction t with mass 1/k_t.
Rolling resistance (spheres): an angular impulse against the spin (rolling and twisting),
clamped to c_r r J_n, so balls on uneven ground come to rest as real ones do.

Bodies own their slots, terrain is static, so no two threads ever write the same body: the
sweeps are true Gauss-Seidel within a body and need no colouring.
"""

import math
from typing import Any

import warp as wp

from ..collide.contact_patch import NO_TWIST, terrain_patch, twist_arm
from ..column_sag import contact_hertz as contact_frequency
from ..kernel_args import BadSteps, BodyModel, BodyState, TerrainContacts
from ..integrate import (cayley_quat, free_drift, integrate_rotation, pre_kick_fraction, same_vector, world_inertia,
                         world_inv_inertia)
from ..types import INTEGRATOR_SEMI_IMPLICIT, ROTATION_QUATERNION, SHAPE_BOX, SHAPE_SPHERE
from .body_velocity import BodyVelocity, apply_contact_impulse, apply_impulse
from .contact_rows import closed_contact_bias, closed_during_substep
from .impact_point import engage_speed
from .impact_terrain import impact_terrain
from .rolling import hold_ball, isotropic_inverse, solve_rolling
from .solver_args import StepSettings

# No kernel here is differentiated: skip generating (and compiling) the adjoints.
wp.set_module_options({"enable_backward": False})

# Passes over a body's own terrain contacts (a pair's own points) a relax sweep may take; it stops
# once a pass changes no point's velocity by more than convergence_tolerance.  A cube 2 cm deep
# without gravity kept 22 % of its push-out speed after 1 pass, 1 % after 2; thin plates pushed
# out of a box 3 times heavier at the capped 3 m/s (contact_rows.closed_contact_bias) needed up to
# 16 (tests/test_push_out.py).  The default of SimConfig.relax_passes; relax_passes = 1 (Box2D's)
# is the faster choice that leaves part of a push behind (bench/versions.py charts both).
RELAX_PASSES = 16

# When a pass has converged.  A pass that changes no point's velocity by more than the tolerance
# ends the passes (relax, pair relax, chain passes).  A fixed 1e-5 m/s is 4,000 times finer than
# the velocity gravity itself adds in a substep of 1/240 s (|g| h = 0.041 m/s), and a box resting
# on its friction rows converges at 0.5 to 0.9 a pass, so most of the 10k rain's relax went on
# passes that moved its boxes by under a micrometre a substep.  The tolerance is therefore also
# a share of |g| h: a velocity error that small is gone within the next substep, where gravity
# and the contacts change every velocity by |g| h again.  Zero gravity keeps the fixed floor, so
# a push-out there is still given back to 10 x 1e-5 m/s (tests/test_push_out.py).  Its speed and
# depth, measured against the fixed tolerance, are in the README (speed against accuracy).
CONVERGENCE_GRAVITY_SHARE = 0.01


def sweep_tolerance(tolerance: float, gravity_share: float, gravity, h: float) -> float:
    """The velocity change [m/s] under which a pass counts as converged (see above)."""
    g = math.sqrt(sum(float(c) * float(c) for c in gravity))
    return max(tolerance, gravity_share * g * h)


def soft_coefficients(h: float, contact_hertz: float | None, damping_ratio: float, soft_depth: float) -> wp.vec4:
    """(biasRate, massScale, impulseScale) for substep h: a quarter of the substep rate, capped by
    ``contact_hertz`` when one is set (warp_sim/column_sag.py says why the quarter)."""
    hertz = contact_frequency(h, contact_hertz)
    omega = 2.0 * math.pi * hertz
    a1 = 2.0 * damping_ratio + h * omega
    a2 = h * omega * a1
    a3 = 1.0 / (1.0 + a2)
    return wp.vec4(omega / a1, a2 * a3, a3, soft_depth)


HOLD_MARGIN = 2.0  # a body carrying one like it on top


def hold_speed(gravity, h: float, soft) -> float:
    """The push-out speed a resting contact needs to hold its body up.

    A body at rest takes the impulse m g h a substep from its contacts.  The soft update
    (contact_rows: new = acc - massScale m (vn + bias) - impulseScale acc) holds that steady
    with vn = 0 only if impulseScale acc = -massScale m bias, that is at a bias speed of
    g h impulseScale / massScale = g h / a2 (a2 = h omega (2 zeta + h omega): 33.9 at the
    defaults, whatever h)."""
    g = math.sqrt(sum(float(c) * float(c) for c in gravity))
    return g * h * float(soft[2]) / float(soft[1]) if float(soft[1]) > 0.0 else 0.0


def push_cap(max_push_velocity: float, gravity, h: float, soft) -> float:
    """The push-out speed cap of the biased sweeps: ``max_push_velocity``, but never below twice
    the hold speed.  A cap below it cannot hold: the body sinks at the difference for ever, with
    no error (a 0.25 m ball under 2.9e4 m/s^2 went down 8.8 mm a step; the defaults' 3 m/s cap
    holds up to g = 3 a2 / h = 2.4e4 at 4 substeps of 1/60 s).  At 9.81 m/s^2 the hold speed is
    1.2 mm/s, so the cap is the setting."""
    return max(float(max_push_velocity), HOLD_MARGIN * hold_speed(gravity, h, soft))


def resting_sag(gravity, h: float, contact_hertz: float | None, damping_ratio: float) -> float:
    """How deep a resting body settles past the soft depth: its contact must push out at the hold
    speed, which the excess rule of closed_contact_bias, (s + d) / h, reaches at
    s + d = h x hold speed = g h^2 / a2.  Measured on a plane, a 0.25 m ball: 0.05 m at 1e5 m/s^2
    and 0.5 m at 1e6, as this gives, at 4 substeps of 1/60 s."""
    return h * hold_speed(gravity, h, soft_coefficients(h, contact_hertz, damping_ratio, 0.0))


def soft_load(h: float, gravity, contact_hertz: float | None, damping_ratio: float) -> wp.vec3:
    """StepSettings.soft_load = (h omega, zeta, 1 with gravity else 0) for contact_rows.loaded_soft."""
    omega = 2.0 * math.pi * contact_frequency(h, contact_hertz)
    loaded = any(float(c) != 0.0 for c in gravity)
    return wp.vec3(h * omega, damping_ratio, 1.0 if loaded else 0.0)


@wp.func
def drift_rotation(shape: int, rot_now: wp.mat33, rot_ref: wp.mat33) -> wp.mat33:
    """``D`` such that an anchor at arm r (taken when the contact was found) has moved by
    dp + D r since then, dp being the centre's displacement.

    A box's anchor is a point of the body, so it turns with it: D = R_now R_ref^T - I (exact, not
    the linearised w x r, which is off by r (w h)^2 / 2 for a box spinning w).  A sphere's anchor
    is its support point along -n, which a rotation does not move: D = 0.  (Turning it with the
    ball would lift a rolling ball's anchor by r (1 - cos theta) and let the ball sink that much:
    1.4 cm for a 0.25 m ball rolling 5 m/s over a 1/60 s step.)
    """
    if shape == SHAPE_SPHERE:
        return wp.mat33(0.0)
    return rot_now * wp.transpose(rot_ref) - wp.identity(n=3, dtype=float)


@wp.func
def solve_terrain_contact(
    slot: int,
    x: wp.vec3,
    vel: BodyVelocity,
    inv_mass: float,
    inv_inertia: Any,
    friction: float,
    h: float,
    use_bias: int,
    soft: wp.vec4,
    max_push_velocity: float,
    gap_shift: float,
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
    twist: wp.vec4,
) -> BodyVelocity:
    n = terrain_contact_normal[slot]
    arm = terrain_contact_point[slot] - x
    separation = -terrain_contact_depth[slot] + gap_shift

    # Non-penetration
    vn = wp.dot(vel.v + wp.cross(vel.w, arm), n)
    rn = wp.cross(arm, n)
    k_n = inv_mass + wp.dot(rn, inv_inertia * rn)
    bias = float(0.0)
    mass_scale = float(1.0)
    impulse_scale = float(0.0)
    if use_bias < 0 and closed_during_substep(separation, vn, h):
        # relax of a scene with restitution: a gap open at the substep's start is left to the next
        # substep's impact stage, which bounces it with its full approach speed (impact.py)
        return vel
    if separation > 0.0:
        bias = separation / h
    elif use_bias > 0:
        bias = closed_contact_bias(separation, h, soft, max_push_velocity)
        mass_scale = soft[1]
        impulse_scale = soft[2]
    acc = terrain_contact_normal_impulse[slot]
    j = -(mass_scale / k_n) * (vn + bias) - impulse_scale * acc
    new_acc = wp.max(acc + j, 0.0)
    terrain_contact_normal_impulse[slot] = new_acc
    vel = apply_impulse(vel, (new_acc - acc) * n, arm, inv_mass, inv_inertia)

    # Friction: clamp the accumulated tangential impulse to the Coulomb disc, at the patch's
    # friction arm (contact_patch.py)
    friction_arm = twist_arm(arm, arm, n, twist)
    vp = vel.v + wp.cross(vel.w, friction_arm)
    vt = vp - wp.dot(vp, n) * n
    old_t = terrain_contact_tangent_impulse[slot]
    old_t = old_t - wp.dot(old_t, n) * n
    new_t = old_t
    slip = wp.length(vt)
    if slip > 1.0e-9:
        t = vt / slip
        rt = wp.cross(friction_arm, t)
        k_t = inv_mass + wp.dot(rt, inv_inertia * rt)
        new_t = old_t - (slip / k_t) * t
    limit = friction * new_acc
    mag = wp.length(new_t)
    if mag > limit:
        new_t = new_t * (limit / mag)
    terrain_contact_tangent_impulse[slot] = new_t
    return apply_impulse(vel, new_t - old_t, friction_arm, inv_mass, inv_inertia)


@wp.func
def sweep(
    start: int,
    count: int,
    x: wp.vec3,
    vel: BodyVelocity,
    inv_mass: float,
    inv_inertia: Any,
    friction: float,
    rolling_limit_per_impulse: float,
    h: float,
    use_bias: int,
    soft: wp.vec4,
    max_push_velocity: float,
    drift_p: wp.vec3,
    drift_r: Any,
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
    twist: wp.vec4,
) -> BodyVelocity:
    for slot in range(start, start + count):
        if terrain_contact_active[slot] != 0:
            # Since the contact was found the body has moved: the gap has grown by the anchor's
            # displacement along n (see ``drift_rotation``).
            arm = terrain_contact_point[slot] - x
            gap_shift = wp.dot(drift_p + drift_r * arm, terrain_contact_normal[slot])
            vel = solve_terrain_contact(slot, x, vel, inv_mass, inv_inertia, friction, h, use_bias, soft,
                                  max_push_velocity, gap_shift, terrain_contact_point, terrain_contact_normal,
                                  terrain_contact_depth, terrain_contact_normal_impulse,
                                  terrain_contact_tangent_impulse, twist)
            if rolling_limit_per_impulse > 0.0:
                hold = hold_ball(vel, terrain_contact_normal[slot], terrain_contact_point[slot] - x, inv_mass,
                                 isotropic_inverse(inv_inertia), friction, rolling_limit_per_impulse,
                                 terrain_contact_normal_impulse[slot], terrain_contact_tangent_impulse[slot])
                vel = hold.vel
                terrain_contact_tangent_impulse[slot] = hold.tangent_impulse
                if hold.held == 0:
                    vel = solve_rolling(vel, terrain_contact_normal[slot], inv_inertia,
                                        rolling_limit_per_impulse * terrain_contact_normal_impulse[slot])
    return vel


@wp.func
def warm_start_terrain(
    start: int,
    count: int,
    x: wp.vec3,
    vel: BodyVelocity,
    inv_mass: float,
    inv_inertia: Any,
    twist: wp.vec4,
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
) -> BodyVelocity:
    """Re-apply last substep's accumulated impulses of the body's active terrain slots (friction at
    the arms of the patch ``twist``, contact_patch.py)."""
    for slot in range(start, start + count):
        if terrain_contact_active[slot] != 0:
            n = terrain_contact_normal[slot]
            vel = apply_contact_impulse(vel, terrain_contact_normal_impulse[slot] * n,
                                        terrain_contact_tangent_impulse[slot], terrain_contact_point[slot] - x,
                                        n, twist, inv_mass, inv_inertia)
    return vel


@wp.func
def row_meets_an_impact(arm: wp.vec3, n: wp.vec3, separation: float, carried: float, v: wp.vec3, w: wp.vec3,
                        h: float, engage: float) -> bool:
    """Whether a warm-started row is not holding a load but meeting a blow: its point closes faster
    than its open gap allows within the substep, or the impulse it carries throws it apart, either
    by more than ``engage`` (impact_point.engage_speed: one substep of gravity, the most a row
    holding a load moves by).  A row that holds its body reads about zero here, its carried
    impulse having taken the substep's kick back."""
    vn = wp.dot(v + wp.cross(w, arm), n)
    return vn + wp.max(separation, 0.0) / h < -engage or (carried > 0.0 and vn > engage)


@wp.func
def solve_sweeps(iterations: int, passes: int, count: int, holding: int) -> int:
    """How many solve sweeps a body's terrain rows may take (each stops early once converged,
    sweep_converged).  A body whose several rows hold no impulse yet (set down, or landing flat)
    starts them cold, and two Gauss-Seidel sweeps in row order leave an uneven share between its
    corners: a cube set on a level plane under g = 100 at dt 1/30 with 1 substep moved 10 mm
    sideways in its first step (8 sweeps: 0.25 mm).  Such a body sweeps until converged, up to
    ``passes`` times the iterations; a warm body (every step after) keeps ``iterations``.
    "Holding" is the carried impulses holding the body, not merely some row carrying one: a
    cube dropped flat (e = 0) closed one row by a hair in the substep before it landed, met the
    landing itself with two sweeps, and left it spinning at 0.17 rad/s and sliding at 3.5 cm/s
    (half 0.2 m, 1 m drop, mu 0.6); so a row that still meets a blow after the warm start
    (row_meets_an_impact) makes its body cold."""
    if holding == 0 and count > 1:
        return iterations * passes
    return iterations


@wp.func
def sweep_converged(before: BodyVelocity, after: BodyVelocity, reach: float, tolerance: float) -> bool:
    """A sweep that moved no point of the body by more than ``tolerance`` [m/s] has converged:
    Gauss-Seidel changes shrink geometrically, so further sweeps would change less still."""
    change = wp.length(after.v - before.v) + reach * wp.length(after.w - before.w)
    return change < tolerance


@wp.func
def as_matrix(inv_inertia: float) -> wp.mat33:
    """The inverse inertia as a matrix, for impact_terrain (which takes one whatever the shape)."""
    return wp.diag(wp.vec3(inv_inertia))


@wp.func
def as_matrix(inv_inertia: wp.mat33) -> wp.mat33:
    return inv_inertia


@wp.func
def no_turn(inv_inertia: float) -> float:
    """A zero drift_rotation of the inertia's type: for the scalar of a sphere, the scalar 0."""
    return 0.0


@wp.func
def no_turn(inv_inertia: wp.mat33) -> wp.mat33:
    return wp.mat33(0.0)


@wp.func
def turn_since(inv_inertia: float, rot_now: wp.mat33, rot_ref: wp.mat33) -> float:
    """drift_rotation by the inertia's type: a sphere's anchor does not turn with it (0)."""
    return 0.0


@wp.func
def turn_since(inv_inertia: wp.mat33, rot_now: wp.mat33, rot_ref: wp.mat33) -> wp.mat33:
    return drift_rotation(SHAPE_BOX, rot_now, rot_ref)


@wp.func
def turn_body(inv_inertia: float, q: wp.quat, rot: wp.mat33, body_inv_inertia: wp.vec3, angmom: wp.vec3, h: float,
              integrator: int, rotation: int) -> tuple[wp.quat, wp.mat33]:
    """integrate_rotation for a sphere: with an isotropic inertia the gyroscopic term of the
    midpoint rule, (I^-1 m) x m, vanishes, so the midpoint angular velocity is I^-1 R^T L itself
    and its Newton solve (integrate.midpoint_body_omega) is skipped."""
    if integrator == INTEGRATOR_SEMI_IMPLICIT and rotation == ROTATION_QUATERNION:
        q_mid = wp.normalize(q * cayley_quat(inv_inertia * (wp.transpose(rot) * angmom), h))
        return q_mid, wp.quat_to_matrix(q_mid)
    return integrate_rotation(q, rot, body_inv_inertia, angmom, h, integrator, rotation)


@wp.func
def turn_body(inv_inertia: wp.mat33, q: wp.quat, rot: wp.mat33, body_inv_inertia: wp.vec3, angmom: wp.vec3, h: float,
              integrator: int, rotation: int) -> tuple[wp.quat, wp.mat33]:
    return integrate_rotation(q, rot, body_inv_inertia, angmom, h, integrator, rotation)


@wp.func(inline=True)
def step_body(
    i: int,
    x: wp.vec3,
    q: wp.quat,
    rot: wp.mat33,
    angmom: wp.vec3,
    inv_mass: float,
    inv_inertia: Any,
    inertia: Any,
    model: BodyModel,
    settings: StepSettings,
    slots: TerrainContacts,
    impact_normal: wp.array(dtype=float),
    impact_tangent: wp.array(dtype=wp.vec3),
    state_in: BodyState,
    state_out: BodyState,
    bad_steps: BadSteps,
):
    """One body's substep (the sequence of the module docstring), its world inertia and inverse
    either matrices or, for a sphere, the scalars they are: a sphere's inertia is isotropic, so
    each I^-1 r product is three multiplications instead of a matrix product (R I^-1 R^T is not
    formed at all), and the overloads below drop a sphere's drift and midpoint-rotation matrices.
    A sphere's rows are the same algebra, differing from the matrix form by rounding only."""
    alpha = pre_kick_fraction(settings.integrator)
    vel = BodyVelocity()
    vel.v = state_in.body_vel[i] + (alpha * settings.h) * settings.gravity
    omega_free = inv_inertia * angmom
    vel.w = omega_free
    vel.rolling_impulse = wp.vec3(0.0)

    start = model.body_checkpoint_start[i]
    count = model.body_checkpoint_count[i]
    friction = model.body_friction[i]
    rolling = float(0.0)
    if model.body_shape[i] == SHAPE_SPHERE:
        rolling = model.body_rolling_resistance[i] * model.body_size[i][0]

    touching = int(0)
    holding = int(0)
    for slot in range(start, start + count):
        touching = touching | slots.terrain_contact_active[slot]
        if slots.terrain_contact_active[slot] != 0 and slots.terrain_contact_normal_impulse[slot] > 0.0:
            holding = 1
    zero = wp.vec3(0.0)
    still = no_turn(inv_inertia)
    toi_shift = wp.vec3(0.0)
    struck = int(0)
    e = model.body_restitution[i]
    if touching != 0 and (e > 0.0 or settings.impacts_always != 0):
        # impacts act on the velocity the last solve left, without this substep's gravity
        v_last = state_in.body_vel[i] - ((1.0 - alpha) * settings.h) * settings.gravity
        hit = impact_terrain(start, count, x, v_last, omega_free, inv_mass, as_matrix(inv_inertia), zero,
                             wp.mat33(0.0), e, friction,
                             settings.h, settings.gravity, settings.restitution_threshold,
                             settings.h, 0.0,  # no pairs on this path: nothing shadows a terrain point
                             slots.terrain_contact_active, slots.terrain_contact_point,
                             slots.terrain_contact_normal, slots.terrain_contact_depth, impact_normal,
                             impact_tangent)
        vel.v = hit.v + settings.h * settings.gravity
        vel.w = hit.w
        toi_shift = hit.shift  # the body reaches the contact at t*, not at the substep's start (impact.py)
        struck = hit.hit
    kicked = vel  # what the contact rows below start from

    # Warm start
    # friction acts at the arms of the patch the carried impulses make (contact_patch.py), for the substep
    twist = NO_TWIST
    if settings.face_patch != 0:
        twist = terrain_patch(start, count, 0, x, rot, friction, slots.terrain_contact_active,
                              slots.terrain_contact_active, slots.terrain_contact_point, slots.terrain_contact_normal,
                              slots.terrain_contact_depth, slots.terrain_contact_normal_impulse)
    vel = warm_start_terrain(start, count, x, vel, inv_mass, inv_inertia, twist, slots.terrain_contact_active,
                             slots.terrain_contact_point, slots.terrain_contact_normal,
                             slots.terrain_contact_normal_impulse, slots.terrain_contact_tangent_impulse)
    if holding != 0 and count > 1:
        engage = engage_speed(settings.gravity, settings.h)
        for slot in range(start, start + count):
            if slots.terrain_contact_active[slot] != 0 and row_meets_an_impact(
                    slots.terrain_contact_point[slot] - x, slots.terrain_contact_normal[slot],
                    -slots.terrain_contact_depth[slot], slots.terrain_contact_normal_impulse[slot], vel.v, vel.w,
                    settings.h, engage):
                holding = 0

    reach = model.body_size[i][0]
    if model.body_shape[i] != SHAPE_SPHERE:
        reach = wp.length(model.body_size[i])
    if touching != 0:
        for _it in range(solve_sweeps(settings.iterations, settings.relax_passes, count, holding)):
            before = vel
            vel = sweep(start, count, x, vel, inv_mass, inv_inertia, friction, rolling, settings.h, 1,
                        settings.soft, settings.max_push_velocity, zero, still, slots.terrain_contact_active,
                        slots.terrain_contact_point, slots.terrain_contact_normal, slots.terrain_contact_depth,
                        slots.terrain_contact_normal_impulse, slots.terrain_contact_tangent_impulse, twist)
            if sweep_converged(before, vel, reach, settings.convergence_tolerance):
                break

    # Drift: positions and orientation move with the solved velocity
    new_angmom = angmom
    if touching != 0:
        new_angmom = angmom + inertia * (vel.w - omega_free)
    # a body no contact touched (no impact, its rows left its velocity as it was, bit for bit) has
    # only gravity acting: its drift is the parabola's
    untouched = struck == 0 and same_vector(vel.v, kicked.v) and same_vector(vel.w, kicked.w)
    step = settings.h * vel.v + toi_shift + free_drift(settings.integrator, untouched, settings.gravity, settings.h)
    x_new = x + step
    q_new, rot_new = turn_body(inv_inertia, q, rot, model.body_inv_inertia[i], new_angmom, settings.h,
                               settings.integrator, settings.rotation)

    if touching != 0:
        relax_bias = wp.where(e > 0.0, -1, 0)
        shift_v = step
        shift_r = turn_since(inv_inertia, rot_new, rot)
        # a box's points give back their push speed in several passes (staged.sweep_body_terrain)
        relax_sweeps = wp.where(count > 1, settings.relax_iterations * settings.relax_passes, settings.relax_iterations)
        for _it in range(relax_sweeps):
            before = vel
            vel = sweep(start, count, x, vel, inv_mass, inv_inertia, friction, rolling, settings.h, relax_bias,
                        settings.soft, settings.max_push_velocity, shift_v, shift_r, slots.terrain_contact_active,
                        slots.terrain_contact_point, slots.terrain_contact_normal, slots.terrain_contact_depth,
                        slots.terrain_contact_normal_impulse, slots.terrain_contact_tangent_impulse, twist)
            if sweep_converged(before, vel, reach, settings.convergence_tolerance):
                break
        new_angmom = angmom + inertia * (vel.w - omega_free)

    v_new = vel.v + ((1.0 - alpha) * settings.h) * settings.gravity
    state_out.body_pos[i] = x_new
    state_out.body_quat[i] = q_new
    state_out.body_rot[i] = rot_new
    state_out.body_vel[i] = v_new
    state_out.body_angmom[i] = new_angmom

    total = wp.dot(x_new, x_new) + wp.dot(v_new, v_new) + wp.dot(new_angmom, new_angmom) + wp.ddot(rot_new, rot_new)
    if not wp.isfinite(total):
        if bad_steps.body_bad_step[i] < 0:
            bad_steps.body_bad_step[i] = bad_steps.sim_step[0]
            wp.atomic_add(bad_steps.bad_count, 0, 1)


@wp.kernel
def solve_and_integrate(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in/out
    slots: TerrainContacts,
    # Scratch
    impact_normal: wp.array(dtype=float),
    impact_tangent: wp.array(dtype=wp.vec3),
    # State in
    state_in: BodyState,
    # State out
    state_out: BodyState,
    # Out
    bad_steps: BadSteps,
):
    i = wp.tid() + tid_offset
    x = state_in.body_pos[i]
    q = state_in.body_quat[i]
    rot = state_in.body_rot[i]
    angmom = state_in.body_angmom[i]
    inv_mass = model.body_inv_mass[i]
    if inv_mass == 0.0:
        state_out.body_pos[i] = x
        state_out.body_quat[i] = q
        state_out.body_rot[i] = rot
        state_out.body_vel[i] = state_in.body_vel[i]
        state_out.body_angmom[i] = angmom
        return

    if model.body_shape[i] == SHAPE_SPHERE:
        step_body(i, x, q, rot, angmom, inv_mass, model.body_inv_inertia[i][0], model.body_inertia[i][0], model,
                  settings, slots, impact_normal, impact_tangent, state_in, state_out, bad_steps)
    else:
        step_body(i, x, q, rot, angmom, inv_mass, world_inv_inertia(rot, model.body_inv_inertia[i]),
                  world_inertia(rot, model.body_inertia[i]), model, settings, slots, impact_normal, impact_tangent,
                  state_in, state_out, bad_steps)
