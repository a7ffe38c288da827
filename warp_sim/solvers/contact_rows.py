"""Contact rows: the Jacobians and effective masses of a contact, built once per substep.

Within a substep the anchors' arms r (from the reference pose, see staged.py), the normal n and
the world inverse inertia I^-1 do not change, so everything the sweeps need besides the
velocities can be computed once and read by every sweep (Box2D v3's contact "prepare" stage):

    normal row:    J_n = (n, r x n),              k_n = 1/m + (r x n) . I^-1 (r x n)
    tangent rows:  J_a = (t_a, r x t_a), a = 1, 2, t_1, t_2 an orthonormal basis of the plane
                   K_t = [[1/m + (r x t_a) . I^-1 (r x t_b)]]_ab           (2 x 2, symmetric)

A sweep then costs two dot products per row to read the velocity along it and two scaled adds
to apply an impulse (Delta v = lambda n / m, Delta w = lambda I^-1 (r x n), with I^-1 (r x n)
stored), instead of rebuilding k_n and the arms' cross products every time: in a pile of boxes
on the terrain that halved the terrain sweeps' cost.

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

wp.set_module_options({"enable_backward": False})


@wp.func
def closed_contact_bias(separation: float, h: float, soft: wp.vec4, max_push_velocity: float) -> float:
    """Push-out velocity target of a closed contact (separation s <= 0) in a biased sweep.

    The soft law's bias is biasRate s (soft_step.py), which lets a spring hold a load by sagging
    load / (m_eff omega^2).  The substep plan keeps that sag under ``column_sag`` for a whole
    column (column_sag.py), so no contact carrying a load the plan allows is deeper than
    soft[3] = column_sag.  A contact deeper than that was driven in by a blow the spring was
    never meant to take (a plate struck through a pile of plates), so its excess s + d is pushed
    out within the substep: bias = min(biasRate s, (s + d) / h), capped at max_push_velocity as
    before.  The mass scale and leak stay the soft law's, so loads still find their spring
    equilibrium, and the relax takes the push speed back (RELAX_PASSES), so this adds no energy."""
    bias = wp.max(soft[0] * separation, -max_push_velocity)
    if separation < -soft[3]:
        bias = wp.max(wp.min(bias, (separation + soft[3]) / h), -max_push_velocity)
    return bias


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
    (soft_load[2] = 0) nothing carries a load and nothing is changed."""
    load = load_mass * soft_load[2] / normal_mass  # M / m_eff, or 0 without gravity
    zeta = soft_load[1]
    if load <= zeta * zeta:
        return soft
    h_omega = soft_load[0]
    a1 = 2.0 * wp.sqrt(load) + h_omega
    a2 = h_omega * a1
    a3 = 1.0 / (1.0 + a2)
    # biasRate = omega / a1 = h omega^2 / a2, and h omega^2 = soft[0] a2_old with a2_old = soft[1] / soft[2]
    return wp.vec4(soft[0] * (soft[1] / soft[2]) / a2, a2 * a3, a3, soft[3])


@wp.struct
class TerrainRow:
    """One terrain contact's rows for the current substep (body side only: the terrain is static).

    Built in registers by each sweep (staged.sweep_body_terrain), never stored: a stored row is
    144 bytes a contact that every sweep reads back, against 32 for the slot index, point,
    normal and depth it is rebuilt from (the byte model's figures are in the README).  The
    prepare stage packs each body's active slot indices at the front of its slot range
    (``terrain_row_slot``), in slot order, so a sweep never visits an idle slot."""

    slot: wp.int32  # where the accumulated impulses live
    normal: wp.vec3
    arm: wp.vec3  # r = p - x_ref
    depth: float
    rn: wp.vec3  # r x n
    inv_rn: wp.vec3  # I^-1 (r x n)
    normal_mass: float  # 1 / k_n
    t1: wp.vec3
    t2: wp.vec3
    rt1: wp.vec3  # r x t1
    rt2: wp.vec3
    inv_rt1: wp.vec3  # I^-1 (r x t1)
    inv_rt2: wp.vec3
    tangent_k: wp.vec3  # K_t as (a, b, c) = [[a, b], [b, c]]


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
def make_terrain_row(slot: int, arm: wp.vec3, n: wp.vec3, depth: float, inv_mass: float,
                     inv_inertia: wp.mat33) -> TerrainRow:
    row = TerrainRow()
    row.slot = slot
    row.normal = n
    row.arm = arm
    row.depth = depth
    row.rn = wp.cross(arm, n)
    row.inv_rn = inv_inertia * row.rn
    row.normal_mass = 1.0 / (inv_mass + wp.dot(row.rn, row.inv_rn))
    row.t1 = plane_basis_first(n)
    row.t2 = wp.cross(n, row.t1)
    row.rt1 = wp.cross(arm, row.t1)
    row.rt2 = wp.cross(arm, row.t2)
    row.inv_rt1 = inv_inertia * row.rt1
    row.inv_rt2 = inv_inertia * row.rt2
    row.tangent_k = wp.vec3(inv_mass + wp.dot(row.rt1, row.inv_rt1), wp.dot(row.rt1, row.inv_rt2),
                            inv_mass + wp.dot(row.rt2, row.inv_rt2))
    return row


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
    row: TerrainRow,
    separation: float,
    v: wp.vec3,
    w: wp.vec3,
    inv_mass: float,
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
    """One sweep over one terrain contact: the normal row (soft_step.py gives the soft-constraint
    algebra), then the friction block.  Returns the new (w, v) as a spatial vector."""
    n = row.normal
    slot = row.slot
    bias = float(0.0)
    mass_scale = float(1.0)
    impulse_scale = float(0.0)
    if separation > 0.0:
        if use_bias < 0:
            # relax of a scene with restitution: an open gap is left to the next substep's impact
            # stage, which bounces it with its full approach speed (impact.py)
            return wp.spatial_vector(w, v)
        bias = separation / h
    elif use_bias > 0:
        loaded = soft
        if load_mass > 0.0:
            # a much heavier body rests on this one: its ground contacts carry it (loaded_soft)
            loaded = loaded_soft(load_mass, row.normal_mass, soft, soft_load)
        bias = closed_contact_bias(separation, h, loaded, max_push_velocity)
        mass_scale = loaded[1]
        impulse_scale = loaded[2]
    acc = terrain_contact_normal_impulse[slot]
    vn = wp.dot(v, n) + wp.dot(w, row.rn)
    if acc == 0.0 and vn + bias >= 0.0:
        # An idle contact that stays idle: the normal impulse would stay 0, so the Coulomb disc
        # has radius 0 and friction can only remove an old tangential impulse.  With none, the
        # sweep would change nothing; stop here.  In a settled pile most box checkpoints are
        # such speculative contacts inside the margin (20k of 30k at 10k bodies).
        old_t = terrain_contact_tangent_impulse[slot]
        if old_t[0] == 0.0 and old_t[1] == 0.0 and old_t[2] == 0.0:
            return wp.spatial_vector(w, v)
    new_acc = wp.max(acc - (mass_scale * row.normal_mass) * (vn + bias) - impulse_scale * acc, 0.0)
    terrain_contact_normal_impulse[slot] = new_acc
    d = new_acc - acc
    v = v + (inv_mass * d) * n
    w = w + d * row.inv_rn

    vt1 = wp.dot(v, row.t1) + wp.dot(w, row.rt1)
    vt2 = wp.dot(v, row.t2) + wp.dot(w, row.rt2)
    f = friction_step(vt1, vt2, terrain_contact_tangent_impulse[slot], row.t1, row.t2, row.tangent_k,
                      friction * new_acc)
    terrain_contact_tangent_impulse[slot] = f[2] * row.t1 + f[3] * row.t2
    v = v + inv_mass * (f[0] * row.t1 + f[1] * row.t2)
    w = w + f[0] * row.inv_rt1 + f[1] * row.inv_rt2
    return wp.spatial_vector(w, v)
