"""Contact rows: the Jacobians and effective masses of a contact, built where a sweep needs them.

Within a substep the anchors' arms r (from the reference pose, see staged.py), the normal n and
the world inverse inertia I^-1 do not change:

    normal row:    J_n = (n, r x n),              k_n = 1/m + (r x n) . I^-1 (r x n)
    tangent rows:  J_a = (t_a, r x t_a), a = 1, 2, t_1, t_2 an orthonormal basis of the plane
                   K_t = [[1/m + (r x t_a) . I^-1 (r x t_b)]]_ab           (2 x 2, symmetric)

Box2D v3 computes these once per substep in a "prepare" stage and stores them for every sweep.
For terrain contacts they are built again in registers by each sweep instead
(solve_terrain_row): a stored row is 144 bytes a contact that every sweep reads back, which on
a GPU costs more than the arithmetic, and on the CPU measured slower too (README, byte model).

Friction pushes the accumulated tangential impulse against the slip direction c (a unit vector
of the plane, in the t_1, t_2 basis) with mass 1 / (c . K_t c), then clamps it to the Coulomb
disc |J_t| <= mu J_n: the same impulse as computing k_t = 1/m + (r x c) . I^-1 (r x c) afresh.
(Solving the 2-D block exactly, lambda_t = -K_t^-1 v_t, was tried: a stack of 10 boxes then
drifted sideways 10.6 mm in 9 s instead of 2.6 mm, the coupling term amplifying rounding noise.)

Body-body contacts (pair_solve.py) keep computing their effective masses in every sweep: rows
with both bodies' angular parts (16 vectors a point) measured slower there than the arithmetic
they save.
"""

import warp as wp

from ..collide.contact_patch import twist_arm

wp.set_module_options({"enable_backward": False})


@wp.func
def closed_during_substep(separation: float, vn: float, h: float) -> bool:
    """Whether a contact was open at the start of the substep that just integrated: its separation
    then was s - h vn (the positions moved by h v).  The relax of a scene with restitution holds
    only contacts closed before the substep; one that closed during it is an impact, left to the
    next substep's impact stage (impact.py), which sees it closed and approaching.  Testing the
    end separation alone (s > 0) let a contact that closed during the substep by a rounding the
    impact stage could not see, or by a turn its linear prediction missed, be held: stopped dead,
    its bounce lost (a ball 900 m from the origin hitting another at 3 m/s with e = 1: both left
    at 1.5 m/s)."""
    return separation > h * vn


@wp.func
def closed_contact_bias(separation: float, h: float, soft: wp.vec4, max_push_velocity: float) -> float:
    """Push-out velocity target of a closed contact (separation s <= 0) in a biased sweep.

    The soft law's bias is biasRate s (soft_step.py), which lets a spring hold a load by sagging
    load / (m_eff omega^2).  The substep plan keeps that sag under ``column_sag`` (less for thin
    bodies: column_sag.plan_budgets) for a whole column, so no contact carrying a load the plan
    allows is deeper than soft[3] = column_sag.  A contact deeper than
    that was driven in by a blow the spring was never meant to take (a plate struck through a pile
    of plates), so its excess s + d is pushed
    out within the substep: bias = min(biasRate s, (s + d) / h), capped at max_push_velocity as
    before.  The mass scale and leak stay the soft law's, so loads still find their spring
    equilibrium, and the relax takes the push speed back (RELAX_PASSES), so this adds no energy."""
    bias = wp.max(soft[0] * separation, -max_push_velocity)
    if separation < -soft[3]:
        bias = wp.max(wp.min(bias, (separation + soft[3]) / h), -max_push_velocity)
    return bias


# [m] the depth past which a contact is pushed back within the substep, for a loaded one (loaded_soft)
NO_PUSH_DEPTH = wp.constant(1.0e30)


@wp.func
def loaded_soft(load_mass: float, normal_mass: float, soft: wp.vec4, soft_load: wp.vec3) -> wp.vec4:
    """The soft coefficients (biasRate, massScale, impulseScale, soft_depth) of a closed body-body
    contact whose heavier body has the mass ``load_mass``: damped for that body.

    The soft law (soft_step.py) makes a contact a spring-damper scaled by the point's own
    effective mass m_eff = 1 / k_n (about the lighter body's mass): stiffness m_eff omega^2,
    damping 2 zeta m_eff omega.  A heavy body M resting on a light one swings on that spring with
    the damping ratio zeta sqrt(m_eff / M): 0.07 for 1e4 kg on 1 kg, and the pair rode down and
    up together for a second (13 mm deep, the light cube at up to 0.22 m/s) before it settled at
    its sag.  So the damping ratio of such a contact is raised to

        zeta' = max(zeta, sqrt(M / m_eff))

    which damps the heavy body's mode critically and changes nothing else: the stiffness
    m_eff omega^2, and with it the sag (column_sag.py), does not depend on zeta.  Bodies of equal
    mass have M / m_eff of about 8 (4 points of a face, the reduced mass half of either), under
    zeta^2 = 100 at the default zeta 10, so only mass ratios above about 12 are changed.  Two
    variants were tried first: the load read from the accumulated impulse (acc / (|g| h)) also
    rose at every landing, so a rain's terrain contacts changed too; and a stiffness following
    that load lagged it by a substep and pumped a rocking mode of a 100:1 pair.  Without gravity
    (soft_load[2] = 0) nothing carries a load and nothing is changed.

    Such a contact is also not pushed back past the budget (closed_contact_bias; soft[3] becomes
    NO_PUSH_DEPTH).  Its depth is the load's: the substep plan sets the sag just under the budget
    (a 1e4 kg cube on a 1 kg cube between two 1e4 kg cubes: 7.3 mm planned against 7.5), and the
    load settling overshoots it by a fraction of a millimetre.  Pushed back within the substep at
    up to max_push_velocity, through a body 1e4 times lighter that two sweeps cannot converge, the
    overshoot rang: the light cube was thrown out at 10 m/s (50 m/s with mu = 0), the heavy one
    above rising off it.  A blow driving a light body deep into a heavy one is still met by the
    soft law's own push, biasRate s up to max_push_velocity."""
    load = load_mass * soft_load[2] / normal_mass  # M / m_eff, or 0 without gravity
    zeta = soft_load[1]
    if load <= zeta * zeta:
        return soft
    h_omega = soft_load[0]
    a1 = 2.0 * wp.sqrt(load) + h_omega
    a2 = h_omega * a1
    a3 = 1.0 / (1.0 + a2)
    # biasRate = omega / a1 = h omega^2 / a2, and h omega^2 = soft[0] a2_old with a2_old = soft[1] / soft[2];
    # no push-back past the budget (NO_PUSH_DEPTH, docstring)
    return wp.vec4(soft[0] * (soft[1] / soft[2]) / a2, a2 * a3, a3, NO_PUSH_DEPTH)


@wp.func
def plane_basis_first(n: wp.vec3) -> wp.vec3:
    """A unit vector perpendicular to the unit vector n (Duff et al. 2017, "Building an
    orthonormal basis, revisited"): no normalisation, exact to rounding for every unit n.  The
    basis jumps where n_z changes sign; harmless, as the accumulated friction impulse is kept as a
    world vector and the basis is rebuilt every substep."""
    sign = wp.where(n[2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return wp.vec3(1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])


@wp.func
def friction_step(vt1: float, vt2: float, old_t: wp.vec3, t1: wp.vec3, t2: wp.vec3, tangent_k: wp.vec3,
                  limit: float) -> wp.vec4:
    """(d1, d2, a1, a2): the impulse change along t1, t2 and the new accumulated impulse.

    Against the slip v_t with mass 1 / (c . K_t c), c = v_t / |v_t|:  Delta = -(|v_t| / c . K_t c) c
    = -(|v_t|^2 / v_t . K_t v_t) v_t, which needs no square root; the disc clamp takes one only
    when the contact slides."""
    o1 = wp.dot(old_t, t1)
    o2 = wp.dot(old_t, t2)
    a1 = o1
    a2 = o2
    slip2 = vt1 * vt1 + vt2 * vt2
    if slip2 > 1.0e-18:
        kq = vt1 * vt1 * tangent_k[0] + 2.0 * vt1 * vt2 * tangent_k[1] + vt2 * vt2 * tangent_k[2]
        scale = slip2 / kq
        a1 = o1 - scale * vt1
        a2 = o2 - scale * vt2
    mag2 = a1 * a1 + a2 * a2
    if mag2 > limit * limit:
        shrink = limit / wp.sqrt(mag2)
        a1 = a1 * shrink
        a2 = a2 * shrink
    return wp.vec4(a1 - o1, a2 - o2, a1, a2)


@wp.func
def solve_terrain_row(
    slot: int,
    arm: wp.vec3,
    twist: wp.vec4,
    n: wp.vec3,
    separation: float,
    v: wp.vec3,
    w: wp.vec3,
    inv_mass: float,
    inv_inertia: wp.mat33,
    friction: float,
    h: float,
    use_bias: int,
    soft: wp.vec4,
    max_push_velocity: float,
    load_mass: float,
    soft_load: wp.vec3,
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
) -> wp.spatial_vector:
    """One sweep over one terrain contact (slot, arm r = p - x_ref, normal n): the normal row
    (soft_step.py gives the soft-constraint algebra), then the friction block, acting at the arm
    the body's patch ``twist`` gives (collide/contact_patch.py: r with its offset in the plane from
    the patch's centre scaled).
    Returns the new (w, v) as a spatial vector.

    The rows are built here, in registers, and never stored: a stored row is 144 bytes a contact
    that every sweep reads back, against 32 for the slot index, point, normal and depth it is
    built from (the byte model's figures are in the README).  Each part is built only once the
    contact is known to need it: most checkpoints of a settled box are speculative contacts that
    stay idle (20k of 30k in the 10k rain), and they need r x n alone to find that out.  Every
    quantity is the same expression whenever it is built, so where it is built changes no bit."""
    bias = float(0.0)
    mass_scale = float(1.0)
    impulse_scale = float(0.0)
    rn = wp.cross(arm, n)
    vn = wp.dot(v, n) + wp.dot(w, rn)
    if use_bias < 0 and closed_during_substep(separation, vn, h):
        # relax of a scene with restitution: a gap open at the substep's start is left to the next
        # substep's impact stage, which bounces it with its full approach speed (impact.py)
        return wp.spatial_vector(w, v)
    if separation > 0.0:
        bias = separation / h
    elif use_bias > 0:
        loaded = soft
        if load_mass > 0.0:
            # a much heavier body rests on this one: its ground contacts carry it (loaded_soft)
            loaded = loaded_soft(load_mass, 1.0 / (inv_mass + wp.dot(rn, inv_inertia * rn)), soft, soft_load)
        bias = closed_contact_bias(separation, h, loaded, max_push_velocity)
        mass_scale = loaded[1]
        impulse_scale = loaded[2]
    acc = terrain_contact_normal_impulse[slot]
    if acc == 0.0 and vn + bias >= 0.0:
        # An idle contact that stays idle: the normal impulse would stay 0, so the Coulomb disc
        # has radius 0 and friction can only remove an old tangential impulse.  With none, the
        # sweep would change nothing; stop here.
        old_t = terrain_contact_tangent_impulse[slot]
        if old_t[0] == 0.0 and old_t[1] == 0.0 and old_t[2] == 0.0:
            return wp.spatial_vector(w, v)
    # normal row: J_n = (n, r x n), k_n = 1/m + (r x n) . I^-1 (r x n)
    inv_rn = inv_inertia * rn
    normal_mass = 1.0 / (inv_mass + wp.dot(rn, inv_rn))
    new_acc = wp.max(acc - (mass_scale * normal_mass) * (vn + bias) - impulse_scale * acc, 0.0)
    terrain_contact_normal_impulse[slot] = new_acc
    d = new_acc - acc
    v = v + (inv_mass * d) * n
    w = w + d * inv_rn

    # tangent rows: t1, t2 an orthonormal basis of the plane, K_t the 2 x 2 block (module docstring),
    # at the patch's friction arm (built only here: most rows are idle and returned above)
    friction_arm = twist_arm(arm, arm, n, twist)
    t1 = plane_basis_first(n)
    t2 = wp.cross(n, t1)
    rt1 = wp.cross(friction_arm, t1)
    rt2 = wp.cross(friction_arm, t2)
    inv_rt1 = inv_inertia * rt1
    inv_rt2 = inv_inertia * rt2
    tangent_k = wp.vec3(inv_mass + wp.dot(rt1, inv_rt1), wp.dot(rt1, inv_rt2), inv_mass + wp.dot(rt2, inv_rt2))
    vt1 = wp.dot(v, t1) + wp.dot(w, rt1)
    vt2 = wp.dot(v, t2) + wp.dot(w, rt2)
    f = friction_step(vt1, vt2, terrain_contact_tangent_impulse[slot], t1, t2, tangent_k, friction * new_acc)
    terrain_contact_tangent_impulse[slot] = f[2] * t1 + f[3] * t2
    v = v + inv_mass * (f[0] * t1 + f[1] * t2)
    w = w + f[0] * inv_rt1 + f[1] * inv_rt2
    return wp.spatial_vector(w, v)
