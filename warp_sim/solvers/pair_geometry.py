"""Where a pair's impulse acts: normal, arms and gap of one contact point at the current pose.

Contacts found once serve several substeps (staged.py): the point and normal were found at the
reference pose and the gap is grown by how far the two anchors have moved apart since,

    moved = (dp_i + D_i r_i) - (dp_j + D_j r_j),   s = -depth + n . moved.

An impulse P must act at one point for both bodies, or it adds a torque (x_i - x_j + r_i - r_j) x P
to the pair and angular momentum is not kept in free space.  Applied at arms measured from the
reference pose, r = p - x_ref, it acts at two points that have drifted apart by ``moved``: a
glancing elastic hit of two spheres changed L by 5 %.  So the point moves with a weighted mean w,
1 - w of the two centres' displacements since, and each body's arm runs from its current centre
to it:

    r_i' = r_i - (1 - w) (dp_i - dp_j),   r_j' = r_j + w (dp_i - dp_j),

and x_i + r_i' = x_j + r_j' exactly: every pair impulse keeps linear and angular momentum.  The
weight says which anchor is the true contact: a sphere's (its support point) when one body is a
sphere (w = 1 for i), else by inverse mass, so a body on a static one keeps its own anchor (a
ball rolling on a static box floor decelerated 3.5x too fast with midpoint arms).  (Arms
turned with the bodies as well, (I + D) r - moved / 2, keep it too, but let a 10-box stack built
top-down drift 12.9 mm sideways in 9 s instead of under 1 cm.)

The narrow phase reports a point midway across the gap s_0 it found (speculative contacts are
found open, up to a step's travel apart).  The anchor it stands for lies on the surfaces, so the
arms end at p + (w - 1/2) s_0 n, the same shift along n for both: on a sphere's support point,
on a body's own face when the other is static, w and 1 - w of the way between the faces otherwise.
A shift along n leaves r x n, the normal rows and the gap as they were; it is the tangent rows'
arm: a 0.25 m cube sliding at 3 m/s onto a static box 5 cm below took its impact friction about
an arm 2.5 cm too long (10 % too much spin), and a ball struck its floor sticking 3 to 5 % fast
(Coulomb's stick needs the support point's own slip stopped: v_x = 5/7 v_t for a solid ball).

Two spheres need no stored geometry at all: their normal is the line of their current centres,
n = (c_i - c_j) / |c_i - c_j|, the gap s = |c_i - c_j| - (R_i + R_j), and the arms
-(R_i + s / 2) n, +(R_j + s / 2) n end at one point of that line, midway between the surfaces,
so a frictionless impulse turns neither ball (midpoint arms of the stored anchors would: they
leave the line when the balls slide past each other).

A sphere at a box's edge or corner needs none either: the box's point nearest the sphere's
current centre, found as the narrow phase finds it (collide_sphere_box, covered faces included),
gives the normal, the gap and one point for both arms, the sphere's support point.  The stored
normal is the one of the pass's pose, and where the ball meets an edge or a corner the contact
turns as it moves: a ball rolling at 4 m/s into a 3 cm step was pushed along the edge-to-centre
line of a substep's travel before it touched, and lost 11 % of its speed with e = 0 and mu = 0
(23 % where its impact used it too).  A contact the pass found on a face keeps the stored one (a
face's normal stays the face's, and finding it again in every sweep cost the CPU's solve sweeps
more than the rest of this change).  A centre beyond covered faces only (the covering box's to
touch) has no contact here: the separation is NO_CONTACT, which no row or impact acts on.
"""

import warp as wp

from ..collide.manifold import BOX_EDGE_ID
from ..collide.primitives import collide_sphere_box
from ..kernel_args import BodyModel
from .solver_args import SolverBodies

wp.set_module_options({"enable_backward": False})


@wp.struct
class PairVelocity:
    vi: wp.vec3
    wi: wp.vec3
    vj: wp.vec3
    wj: wp.vec3


@wp.func
def read_pair_velocity(solver: SolverBodies, i: int, j: int) -> PairVelocity:
    """Both bodies' velocities as the solver holds them now."""
    vel = PairVelocity()
    vel.vi = solver.solver_v[i]
    vel.wi = solver.solver_w[i]
    vel.vj = solver.solver_v[j]
    vel.wj = solver.solver_w[j]
    return vel


@wp.struct
class PairPoint:
    normal: wp.vec3  # from j to i
    arm_i: wp.vec3  # from body i's current centre to the point the impulse acts at
    arm_j: wp.vec3
    separation: float  # gap now (negative: penetration)


@wp.func
def anchor_weight(sphere_radius_i: float, sphere_radius_j: float, inv_mass_i: float, inv_mass_j: float) -> float:
    """w: the point follows a sphere's anchor (its support point, exact), else the bodies'
    anchors weighted by inverse mass (a static body's not at all, equal masses: the midpoint)."""
    follow_i = float(0.5)
    if sphere_radius_i > 0.0:
        follow_i = 1.0
    elif sphere_radius_j > 0.0:
        follow_i = 0.0
    elif inv_mass_i + inv_mass_j > 0.0:
        follow_i = inv_mass_i / (inv_mass_i + inv_mass_j)
    return follow_i


NO_CONTACT = 1.0e30  # the separation of a sphere-box pair whose contact has gone (covered faces)


@wp.func
def orthonormalized(m: wp.mat33) -> wp.mat33:
    """A rotation within second order of a first-order turned one, (1 + D) R: Gram-Schmidt on its
    columns.  A box turned on by t w from its drift (impact_point.drift_turned) is stretched by
    1 + (t |w|)^2 / 2, and a face normal taken from it was as much over unit length: the impact's
    friction then read the normal speed left in v - (v . n) n as slip and pushed the bodies apart
    through it (a ball glancing off a box spinning at 8 rad/s, 7 % of the pair's energy gained)."""
    a = wp.normalize(wp.vec3(m[0, 0], m[1, 0], m[2, 0]))
    b = wp.vec3(m[0, 1], m[1, 1], m[2, 1])
    b = wp.normalize(b - wp.dot(a, b) * a)
    c = wp.cross(a, b)
    return wp.matrix_from_cols(a, b, c)


@wp.func
def sphere_box_point(
    c_sphere: wp.vec3,
    radius: float,
    c_box: wp.vec3,
    rot_box: wp.mat33,
    half: wp.vec3,
    covered: int,
    sphere_is_i: bool,
) -> PairPoint:
    """A sphere's contact with a box at the given poses (module docstring); the normal from j to i."""
    out = PairPoint()
    out.separation = NO_CONTACT
    out.normal = wp.vec3(0.0, 1.0, 0.0)
    m = collide_sphere_box(c_sphere, radius, c_box, rot_box, half, covered, NO_CONTACT)
    if m.count == 0:
        return out
    # the anchor is the sphere's support point (anchor_weight: w = 1 for the sphere), so friction
    # acts at arm R across a speculative gap too
    point = c_sphere - radius * m.normal
    out.separation = -m.depth[0]
    if sphere_is_i:
        out.normal = m.normal  # from the box into the sphere
        out.arm_i = point - c_sphere
        out.arm_j = point - c_box
    else:
        out.normal = -m.normal
        out.arm_i = point - c_box
        out.arm_j = point - c_sphere
    return out


@wp.func(inline=True)
def pair_point_now(
    n_ref: wp.vec3,
    point: wp.vec3,
    depth: float,
    feature: int,
    x_ref_i: wp.vec3,
    x_ref_j: wp.vec3,
    drift_p_i: wp.vec3,
    drift_p_j: wp.vec3,
    drift_r_i: wp.mat33,
    drift_r_j: wp.mat33,
    rot_ref: wp.array(dtype=wp.mat33),
    i: int,
    j: int,
    # Model
    model: BodyModel,
) -> PairPoint:
    """Pair (i, j)'s point (stored at the pass's pose: ``n_ref``, ``point``, ``depth``, ``feature``)
    at the pose the drifts give from the reference (x_ref, and the rotations in ``rot_ref``, read
    only for a sphere on a box's edge or corner)."""
    out = PairPoint()
    sphere_radius_i = model.body_sphere_radius[i]
    sphere_radius_j = model.body_sphere_radius[j]
    # a sphere found at a box's edge or corner (its stored normal turns as it moves; a face's
    # stays the face's): its contact found again here
    if (sphere_radius_i > 0.0) != (sphere_radius_j > 0.0) and feature >= BOX_EDGE_ID:
        sphere_is_i = sphere_radius_i > 0.0
        box = wp.where(sphere_is_i, j, i)
        radius = wp.max(sphere_radius_i, sphere_radius_j)
        found = sphere_box_point(wp.where(sphere_is_i, x_ref_i + drift_p_i, x_ref_j + drift_p_j), radius,
                                 wp.where(sphere_is_i, x_ref_j + drift_p_j, x_ref_i + drift_p_i),
                                 orthonormalized((wp.identity(n=3, dtype=float)
                                                  + wp.where(sphere_is_i, drift_r_j, drift_r_i)) * rot_ref[box]),
                                 model.body_size[box], model.body_covered_faces[box], sphere_is_i)
        # only while the centre is outside the box and on the stored normal's side: a centre that
        # has sunk into a thin box past its middle finds the far face nearest, and would be pushed
        # on through it (a ball struck at 40 m/s into a 4 cm wall went through); the stored
        # contact keeps its side there
        if found.separation == NO_CONTACT or (found.separation > -radius and wp.dot(found.normal, n_ref) > 0.0):
            return found
    if sphere_radius_i > 0.0 and sphere_radius_j > 0.0:
        d = (x_ref_i + drift_p_i) - (x_ref_j + drift_p_j)
        dist = wp.length(d)
        n = n_ref
        if dist > 1.0e-9:
            n = d / dist
        gap = dist - (sphere_radius_i + sphere_radius_j)
        out.normal = n
        out.separation = gap
        # both arms end at the midpoint between the two surfaces: x_i + r_i = x_j + r_j exactly
        # whatever the gap, so a friction impulse keeps angular momentum too (arms -R_i n and
        # +R_j n end a gap apart, and a tangential impulse there turned L by gap x P_t: 3e-3 of it
        # over a glancing hit with mu 0.5)
        # (A gap beyond the two diameters keeps the surface arms: no impulse acts there at sane
        # speeds, and an arm of half an overflowing gap turned a runaway body's neighbour
        # non-finite through 0 x inf in the friction mass.)
        half_gap = wp.where(wp.abs(gap) <= sphere_radius_i + sphere_radius_j, 0.5 * gap, 0.0)
        out.arm_i = -(sphere_radius_i + half_gap) * n
        out.arm_j = (sphere_radius_j + half_gap) * n
        return out
    ri = point - x_ref_i
    rj = point - x_ref_j
    moved = (drift_p_i + drift_r_i * ri) - (drift_p_j + drift_r_j * rj)
    out.normal = n_ref
    out.separation = -depth + wp.dot(moved, n_ref)
    follow_i = anchor_weight(sphere_radius_i, sphere_radius_j, model.body_inv_mass[i], model.body_inv_mass[j])
    relative = drift_p_i - drift_p_j
    # the found point lies midway across the gap s_0 = -depth; the anchor it stands for lies on
    # the surfaces, w on i's (s_0 / 2 along n) and 1 - w on j's (module docstring)
    onto_surface = ((follow_i - 0.5) * -depth) * n_ref
    out.arm_i = ri - (1.0 - follow_i) * relative + onto_surface
    out.arm_j = rj + follow_i * relative + onto_surface
    return out


@wp.func
def sphere_box_clear_at(t: float, c_sphere: wp.vec3, v_sphere: wp.vec3, radius: float, c_box: wp.vec3,
                        v_box: wp.vec3, w_box: wp.vec3, rot_box: wp.mat33, half: wp.vec3, covered: int,
                        margin: float) -> bool:
    """Whether a sphere and a box moving freely at the given velocities are more than ``margin``
    apart a time t on, the box turned by the exact rotation w t (not the linearised one of the rows)."""
    turn = wp.identity(n=3, dtype=float)
    speed = wp.length(w_box)
    if speed > 0.0:
        turn = wp.quat_to_matrix(wp.quat_from_axis_angle(w_box / speed, speed * t))
    at = sphere_box_point(c_sphere + t * v_sphere, radius, c_box + t * v_box, turn * rot_box, half, covered, True)
    return at.separation > margin


@wp.func
def sphere_box_curvature(v_sphere: wp.vec3, v_box: wp.vec3, w_box: wp.vec3, half: wp.vec3, radius: float) -> float:
    """A bound on the second derivative of a sphere-box gap in free motion: |w|^2 |half| (the
    box's turn) + u^2 / R (a point passing the ball's surface at the relative speed u, at most
    |v_s - v_b| + |w| |half|)."""
    reach = wp.length(half)
    turn = wp.length(w_box)
    speed = wp.length(v_sphere - v_box) + turn * reach
    return turn * turn * reach + speed * speed / radius


@wp.func
def straight_paths_surely_meet(closing: float, toi: float, left: float, curvature: float) -> bool:
    """Whether a pair whose straight paths close at ``closing`` and touch at ``toi`` overlap at the
    substep's end by more than the free motion can bend away from them, curvature left^2 / 2: then
    it meets whatever its turn (most closing rows of a landing rain), and
    sphere_box_passes_clear is not asked."""
    return closing * (left - toi) > 0.5 * curvature * left * left


@wp.func
def sphere_box_passes_clear(
    c_sphere: wp.vec3,
    v_sphere: wp.vec3,
    radius: float,
    c_box: wp.vec3,
    v_box: wp.vec3,
    w_box: wp.vec3,
    rot_box: wp.mat33,
    half: wp.vec3,
    covered: int,
    toi: float,
    curvature: float,
    left: float,
) -> bool:
    """Whether a sphere and a spinning box that the rows see closing (touching at ``toi`` on their
    straight paths) pass each other clear within the ``left`` of the substep; ``curvature`` is
    sphere_box_curvature's bound a.

    A speculative row reads the closing speed of the box's point on its straight path, v + w x r,
    and a fast-turning box's point sweeps an arc away from where that line goes (a face tilts
    away, a corner swings past the ball): pairs that in a float64 torque-free reference pass 1.9
    to 5.7 mm apart were stopped by the row, an inelastic impulse where nothing touched (0.5 to
    3 % of a ball-box pair's energy lost at e = 1).  The free motion (the box turned by the exact
    rotation w t) is sampled at ``toi`` and at each quarter of the substep (a corner at 40 rad/s
    turns 0.17 rad a substep of 1/240 s, a sample every 0.04 rad).  Between two samples dt apart
    the gap can dip a dt^2 / 8 below both, so each must clear that margin plus 4 float32 roundings
    of the centres (a ball grazing a box 0.03 mm clear 300 m from the origin, where a float32
    position steps 0.03 mm, was let through and then half stopped by the next substep's rows: 2 %
    of its energy lost; held, its impact bounces it)."""
    sample = 0.25 * left
    margin = curvature * sample * sample / 8.0 + 4.0 * 1.2e-7 * (wp.length(c_sphere) + wp.length(c_box))
    # one call site for the five samples (k = 0: toi): each inlined copy of the narrow phase grows
    # the impact kernels that carry it
    for k in range(5):
        t = wp.where(k == 0, wp.clamp(toi, 0.0, left), float(k) * sample)
        if not sphere_box_clear_at(t, c_sphere, v_sphere, radius, c_box, v_box, w_box, rot_box, half, covered,
                                   margin):
            return False
    return True
