"""One contact point in an impact (impact.py): whether it takes part, when it touches, and its
Coulomb step.  Pure functions of the point's gap, normal speed and impulses."""

import warp as wp

wp.set_module_options({"enable_backward": False})


# A contact that closes within this share of the substep's travel before its end is engaged too.
# Its predicted end gap, gap + h vn, and the separation the relax finds after integrating are the
# same quantity rounded differently: a hit timed to close exactly at a substep's end (30 m/s over
# a gap of four substeps' travel) ended at gap + h vn = 0 here, not engaged, and a hair closed
# after integration, so the relax, which held closed contacts, stopped it dead: a ball hitting a
# wall with e = 1 stuck to it, two equal balls left together at v / 2.  Engaging early by 1e-4 of
# the travel bounces at the computed contact time (time_to_contact), off by at most that share of
# a substep.  float32 separations round at about 6e-8 of the positions' size, so this covers a
# 3 m/s approach at h = 1/240 up to 20 m from the origin; farther, the relax leaves a contact that
# closed during the substep to the next substep's impact (contact_rows.closed_during_substep),
# which bounces it one substep late instead.
ENGAGE_EARLY_SHARE = 1.0e-4


@wp.func
def engaged(gap: float, vn: float, h: float) -> bool:
    return gap <= 0.0 or gap + h * vn < ENGAGE_EARLY_SHARE * h * wp.abs(vn)


@wp.func
def shadowed(gap: float, vn: float, pair_toi: float, margin: float) -> bool:
    """A terrain point still more than ``margin`` (the plan's sag budget) from the ground when one of the body's
    pairs closes (``pair_toi``, pair_contact_times): the body meets that other body first.  Nearer,
    the two are one contact at the soft contact's scale: a plate resting on the ground against
    another has its pair touching and terrain points microns open, and holding those back (any
    margin up to 1 mm) changed how piles of plates settle, one rain's deepest pair 6.5 -> 15.9 mm."""
    return gap + vn * pair_toi > margin


@wp.func
def engage_speed(gravity: wp.vec3, h: float) -> float:
    """The closing speed from which a contact takes part in the impact stage: one substep of
    gravity, the most a contact holding a load approaches by before the solve (1 mm/s without
    gravity, under which a substep closes less than a micrometre)."""
    return wp.max(wp.length(gravity) * h, 1.0e-3)


@wp.func
def time_to_contact(gap: float, vn: float, toi: float) -> float:
    """The earlier of ``toi`` and when a point at ``gap`` closing at ``vn`` touches (0 when it
    already touches: the body is in contact from the substep's start)."""
    if gap <= 0.0:
        return 0.0
    if vn < 0.0:
        return wp.min(toi, gap / (-vn))
    return toi


@wp.func
def free_fall_share(inv_mass: float, support: float) -> float:
    """The share of gravity that moves a body within the substep: none for a static body, and for a
    dynamic one what its contacts do not hold (staged.support_share: 0 falling, 1 resting)."""
    return wp.where(inv_mass > 0.0, 1.0 - support, 0.0)


@wp.func
def gravity_kick(fall_i: float, fall_j: float, gravity: wp.vec3, h: float) -> wp.vec3:
    """The relative velocity (i minus j) the substep's kick leaves, the bodies falling by the shares
    ``fall`` (free_fall_share).  A contact is engaged on the speed it leaves (impact.py), so one
    closed by the kick alone is an impact too."""
    return h * (fall_i - fall_j) * gravity


@wp.func
def drift_turned(drift_r: wp.mat33, w: wp.vec3, t: float, turns: float) -> wp.mat33:
    """An anchor drift (soft_step.drift_rotation) carried on by a turn at w for a time t; ``turns``
    0 for a sphere, whose support point does not turn."""
    return drift_r + (turns * t) * wp.skew(w) * (wp.identity(n=3, dtype=float) + drift_r)


@wp.func
def spheres_touch_time(d: wp.vec3, dv: wp.vec3, reach: float, h: float, toi: float) -> float:
    """When two spheres whose centres are ``d`` apart (i minus j), closing at the relative velocity
    ``dv``, touch: the earlier root of |d + t dv| = reach (their radii summed), exact for straight
    motion where time_to_contact's gap / |v_n| takes the normal of the start (a glancing approach
    closes along a curve in the normal); 0 when they touch already, ``toi`` where they miss."""
    c = wp.dot(d, d) - reach * reach
    if c <= 0.0:
        return 0.0
    a = wp.dot(dv, dv)
    b = wp.dot(d, dv)
    disc = b * b - a * c
    if a == 0.0 or b >= 0.0 or disc < 0.0:
        return toi
    return wp.min(c / (-b + wp.sqrt(disc)), h)  # (-b - sqrt(disc)) / a, without the cancellation


@wp.func
def spheres_miss(d: wp.vec3, dv: wp.vec3, reach: float, h: float, margin: float) -> bool:
    """Whether two spheres whose centres are ``d`` apart (i minus j), moving at the relative velocity
    ``dv``, pass each other within the substep without touching: their straight paths' closest
    approach over [0, h] stays more than ``margin`` beyond reach (``margin``: what the substep's
    gravity kick may bend the paths by).  The gap along the start's line of centres, which the
    engagement and the speculative rows read, closes for a ball flying past another too: a ball
    at two diameters a step passing 5 % of a diameter clear knocked the other away at 0.12 of its
    speed (0.31 at five diameters a step)."""
    a = wp.dot(dv, dv)
    t = float(0.0)
    if a > 0.0:
        t = wp.clamp(-wp.dot(d, dv) / a, 0.0, h)
    return wp.length(d + t * dv) > reach + margin


@wp.func
def coulomb_step(old_t: wp.vec3, vt: wp.vec3, k_t: float, limit: float) -> wp.vec3:
    """The accumulated tangential impulse after pushing against the slip vt, clamped to the disc."""
    new_t = old_t
    slip = wp.length(vt)
    if slip > 1.0e-9:
        new_t = old_t - (slip / k_t) * (vt / slip)
    mag = wp.length(new_t)
    if mag > limit:
        new_t = new_t * (limit / mag)
    return new_t
