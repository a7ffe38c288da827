"""One body's impact on the terrain (impact.py says the model): its engaged terrain contacts are
one manifold, taken in rounds within the substep; and the sweep limits every manifold's impact
shares (the pairs' in impact.py too)."""

import warp as wp

from .impact_point import coulomb_step, engage_speed, engaged, shadowed, time_to_contact

wp.set_module_options({"enable_backward": False})

# Gauss-Seidel sweeps over one manifold's points, until no point's update changes its normal
# speed by more than IMPACT_SPEED_TOLERANCE [m/s], at most IMPACT_ITERATIONS.  Four points of a face
# converge geometrically in a few sweeps; a thin plate's edge gives pairs of points 2t apart, nearly
# one row twice, which converge slowly: at a fixed 16 sweeps a plate (half 0.3 x 0.01 x 0.2) landing
# edge first with e = 1 left with 1 to 2 % more energy than it came with (impact.py's energy identity
# holds at convergence only).  The friction sweeps stop at IMPACT_SLIP_TOLERANCE the same way.
IMPACT_ITERATIONS = 512
IMPACT_SPEED_TOLERANCE = 1.0e-5
# The friction sweeps stop once no point's update takes more slip than this [m/s] (as the relax's
# SimConfig.convergence_tolerance): Coulomb's discs taken in turn converge geometrically too.
IMPACT_SLIP_TOLERANCE = 1.0e-5
# Rounds of one body's terrain impact within a substep (impact_terrain): a second corner brought in
# by the first's bounce is the second round; a box's corners come in at most a few at a time.
IMPACT_ROUNDS = 4
NOT_ENGAGED = -1.0


@wp.struct
class ImpactOutcome:
    """A manifold's impact on one body: its new velocities (without the gravity of t*, which
    the substep's kick adds back) and its time-of-impact position shift."""

    w: wp.vec3
    v: wp.vec3
    shift: wp.vec3
    hit: int


@wp.struct
class TerrainEngagement:
    """Which of a body's terrain slots close within the substep (impact_normal: 0 where engaged,
    NOT_ENGAGED elsewhere), the earliest one's time ``toi``, and whether one closes faster than the
    engage speed (``hit``) and faster than the restitution threshold (``bounces``)."""

    toi: float
    hit: int
    bounces: int


@wp.func
def terrain_engagement(
    start: int,
    count: int,
    x: wp.vec3,
    v: wp.vec3,
    w: wp.vec3,
    drift_p: wp.vec3,
    drift_r: wp.mat33,
    shift: wp.vec3,
    h: float,
    gravity: wp.vec3,
    restitution_threshold: float,
    pair_toi: float,
    shadow_margin: float,
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    impact_normal: wp.array(dtype=float),
    impact_tangent: wp.array(dtype=wp.vec3),
) -> TerrainEngagement:
    """The engaged slots of one body (``shift``: the earlier events' position shifts, motion the
    substep makes too), their impulses reset."""
    out = TerrainEngagement()
    out.toi = h
    out.hit = 0
    out.bounces = 0
    for slot in range(start, start + count):
        impact_normal[slot] = NOT_ENGAGED
        if terrain_contact_active[slot] != 0:
            n = terrain_contact_normal[slot]
            arm = terrain_contact_point[slot] - x
            gap = -terrain_contact_depth[slot] + wp.dot(drift_p + drift_r * arm + shift, n)
            vn = wp.dot(v + wp.cross(w, arm), n)
            # engaged on the speed the substep's kick leaves (the end gap is gap + h (vn + h g.n)):
            # a contact closed by that kick alone was met by the solve's speculative row,
            # inelastically (a cube dropped with e = 0.8 from a band of heights g h^2 wide
            # bounced 11 mm short)
            fall = wp.dot(gravity, n)
            if engaged(gap, vn + h * fall, h) and not shadowed(gap, vn + pair_toi * fall, pair_toi, shadow_margin):
                impact_normal[slot] = 0.0
                impact_tangent[slot] = wp.vec3(0.0)
                out.toi = time_to_contact(gap, vn, out.toi)
                if vn < -engage_speed(gravity, h):
                    out.hit = 1
                if vn < -restitution_threshold:
                    out.bounces = 1
    return out


@wp.func
def compress_terrain(
    start: int,
    count: int,
    x: wp.vec3,
    v: wp.vec3,
    w: wp.vec3,
    inv_mass: float,
    inv_inertia: wp.mat33,
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    impact_normal: wp.array(dtype=float),
) -> ImpactOutcome:
    """Poisson's compression on a body's engaged slots, from the impulses they hold: projected
    Gauss-Seidel until no engaged point approaches.  ``hit`` is 1 when an impulse changed."""
    out = ImpactOutcome()
    out.hit = 0
    for _it in range(IMPACT_ITERATIONS):
        changed = float(0.0)  # the most normal speed a point's update changed this sweep
        for slot in range(start, start + count):
            acc = impact_normal[slot]
            if acc >= 0.0:
                n = terrain_contact_normal[slot]
                arm = terrain_contact_point[slot] - x
                rn = wp.cross(arm, n)
                vn = wp.dot(v + wp.cross(w, arm), n)
                k_n = inv_mass + wp.dot(rn, inv_inertia * rn)
                new_acc = wp.max(acc - vn / k_n, 0.0)
                impact_normal[slot] = new_acc
                v = v + (inv_mass * (new_acc - acc)) * n
                w = w + inv_inertia * (rn * (new_acc - acc))
                changed = wp.max(changed, k_n * wp.abs(new_acc - acc))
        if changed >= IMPACT_SPEED_TOLERANCE:
            out.hit = 1
        if changed < IMPACT_SPEED_TOLERANCE:
            break
    out.v = v
    out.w = w
    return out


@wp.func
def restitute_terrain(
    start: int,
    count: int,
    x: wp.vec3,
    v: wp.vec3,
    w: wp.vec3,
    inv_mass: float,
    inv_inertia: wp.mat33,
    e: float,
    mu: float,
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    impact_normal: wp.array(dtype=float),
    impact_tangent: wp.array(dtype=wp.vec3),
) -> ImpactOutcome:
    """Restitution, e times each slot's compression impulse, then friction on the whole normal
    impulse (1 + e) P_c, swept until converged: two sweeps left a cube landing flat while sliding
    with a sideways drift (0.3 % of its slide) and a spin about the slide."""
    for slot in range(start, start + count):
        acc = impact_normal[slot]
        if acc > 0.0:
            n = terrain_contact_normal[slot]
            rn = wp.cross(terrain_contact_point[slot] - x, n)
            v = v + (inv_mass * e * acc) * n
            w = w + inv_inertia * (rn * (e * acc))
    if mu > 0.0:
        for _it in range(IMPACT_ITERATIONS):
            removed = float(0.0)  # the most slip speed a point's update took this sweep
            for slot in range(start, start + count):
                acc = impact_normal[slot]
                if acc > 0.0:
                    n = terrain_contact_normal[slot]
                    arm = terrain_contact_point[slot] - x
                    vp = v + wp.cross(w, arm)
                    vt = vp - wp.dot(vp, n) * n
                    old_t = impact_tangent[slot]
                    k_t = inv_mass
                    slip = wp.length(vt)
                    if slip > 1.0e-9:
                        rt = wp.cross(arm, vt / slip)
                        k_t = inv_mass + wp.dot(rt, inv_inertia * rt)
                    new_t = coulomb_step(old_t, vt, k_t, mu * (1.0 + e) * acc)
                    impact_tangent[slot] = new_t
                    v = v + inv_mass * (new_t - old_t)
                    w = w + inv_inertia * wp.cross(arm, new_t - old_t)
                    removed = wp.max(removed, k_t * wp.length(new_t - old_t))
            if removed < IMPACT_SLIP_TOLERANCE:
                break
    out = ImpactOutcome()
    out.v = v
    out.w = w
    out.hit = 1
    return out


@wp.func
def impact_terrain(
    start: int,
    count: int,
    x: wp.vec3,
    v: wp.vec3,
    w: wp.vec3,
    inv_mass: float,
    inv_inertia: wp.mat33,
    drift_p: wp.vec3,
    drift_r: wp.mat33,
    e: float,
    mu: float,
    h: float,
    gravity: wp.vec3,
    restitution_threshold: float,
    pair_toi: float,
    shadow_margin: float,
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    impact_normal: wp.array(dtype=float),
    impact_tangent: wp.array(dtype=wp.vec3),
) -> ImpactOutcome:
    """The impact of one body on the terrain: its engaged terrain contacts (slots start ...
    start + count, arms from x) are one manifold.  Taken in rounds (IMPACT_ROUNDS): an impact's
    turn can bring another point in within the substep (a box bouncing off one corner swings the
    next one down), and that point is an impact of its own, on the velocities the first left,
    engaged by the same test; without the rounds the soft solve's speculative row met it
    inelastically (a box tumbling at 4.6 rad/s onto the plane with e = 1 lost 31 % of its energy).
    The rounds' events keep their order in time: each position shift is taken at its own t*."""
    out = ImpactOutcome()
    out.w = w
    out.v = v
    out.shift = wp.vec3(0.0)
    out.hit = 0
    shift = wp.vec3(0.0)
    earliest = float(0.0)  # a later round's event is not before the one that caused it
    for _round in range(IMPACT_ROUNDS):
        # the earlier rounds' shifts are motion the substep makes too (v- until their t*)
        engagement = terrain_engagement(start, count, x, v, w, drift_p, drift_r, shift, h, gravity,
                                        restitution_threshold, pair_toi, shadow_margin, terrain_contact_active,
                                        terrain_contact_point, terrain_contact_normal, terrain_contact_depth,
                                        impact_normal, impact_tangent)
        if engagement.hit == 0:
            break
        toi = wp.max(engagement.toi, earliest)
        earliest = toi
        # the impact acts at t*, on the velocity gravity has grown by then
        v = v + toi * gravity
        v_in = v
        compressed = compress_terrain(start, count, x, v, w, inv_mass, inv_inertia, terrain_contact_point,
                                      terrain_contact_normal, impact_normal)
        bounced = restitute_terrain(start, count, x, compressed.v, compressed.w, inv_mass, inv_inertia,
                                    wp.where(engagement.bounces == 0, 0.0, e), mu, terrain_contact_point,
                                    terrain_contact_normal, impact_normal, impact_tangent)
        v = bounced.v
        w = bounced.w
        shift = shift + toi * (v_in - v)
        v = v - toi * gravity
        out.hit = 1
    out.w = w
    out.v = v
    out.shift = shift
    return out
