"""A box's checkpoints on its support face see the crests of a curved terrain between them.

The checkpoints (builder.box_checkpoints) sample a box's surface on a lattice of spacing
2 w = 2 h / (per_edge - 1) per axis.  Against a Fourier surface the depth under a face,

    d(a, b) = H(p_x, p_z) - p_y,      p = p0 + a e_a + b e_b,

is not linear between them: where the face spans a crest, d peaks between checkpoints and the
crest passes into the face unseen.  A plank over two crests of H = 0.3 cos x sank 138 mm between
its checkpoints 4.1 m apart; 100 cubes of half 0.25 m dropped on the default terrain rested up
to 4.7 mm deep (half 0.5 m: 13.6 mm) by a NumPy oracle over their faces, while their contacts
reported under 0.2 mm (tests/test_face_search.py).

The face whose outward normal points most along the surface's downward normal under the centre
is the box's support face.  Each checkpoint on it owns the cell of the face within w of it along
the face's two axes (clamped to the face, so the cells tile it).  Where d is concave along a face
axis at the checkpoint, the checkpoint climbs over its cell towards the crest, and the deepest
depth reached raises its own.  The derivatives come with the surface sample (its gradient g and
Hessian K, along the face directions' horizontal parts e_h):

    d_a = g . e_a,h - e_a,y,      d_ab = e_a,h^T K e_b,h.

A climb step is one projected Gauss-Seidel pass over the two axes, each clamped to the cell (a
2-D step clamped to the cell is not the cell's top when the crest's own top lies outside it).
Along an axis of slope g and curvature k the step is the one that maximises what Taylor's
theorem promises the depth gains, g t + k t^2 / 2 - T |t|^3 / 6 (T bounding the third
derivatives, ``sure_step``): where the curvature dominates it is the quadratic model's Newton
step, and where the curvature is weak it is no longer than the bound still promises a climb.
The Newton step alone went to the cell's end along a barely concave axis, towards a top the
model imagines beyond it: a cube of half 0.25 m resting on the default terrain moved its
checkpoint 0.125 m into the face that way, off the face's edge, under which a crest stood 0.87
mm deep while its contacts said 0.05.  A step that does not climb is cut to a quarter and tried
again.

Directions climb where d is concave, or where it is convex but turns soon enough that a top can
stand within the cell (``may_climb``: its slope g can vanish within the cell's reach r only if
|g| + k r <= T r^2 / 2).  Along any other direction d rises all the way to one of the cell's
ends, which the neighbouring checkpoints (or the face's edge, where the cell is clamped) already
bound from above, so a box on flat or hollow ground is solved as before.

The contact stays at the checkpoint, with the checkpoint's normal; only its depth grows.  Moving
the contact to the crest instead let its point slide between cells as a box rocked, carrying the
warm-started impulses with it: 5 to 40 % of 100 resting cubes crept on, 1 to 40 mm a second
(tests/test_face_search.py).  The rise is also capped by the chord bound 1/2 k_a r_a^2 +
1/2 k_b r_b^2, k the larger concave curvature of the checkpoint and the top found along each axis
and r the cell's reach that way: what a curvature of that size can hide between checkpoints.
Without the cap a nearly flat, barely concave face would climb to the end of its cell along its
tilt, and the depth would jump where the curvature's sign flips.  Neither the rise nor the cap
jumps as the pose changes, up to the climb's own convergence.

A checkpoint whose cell cannot come within the speculative window of the surface skips the climb
(its contact would stay idle): the cap there uses the checkpoint's curvature plus the most any
point of the cell can add, T (r_a + r_b), T bounding the third derivatives.

The climb starts at the checkpoint every pass: a checkpoint on flat or hollow ground costs one
surface sample with its Hessian, one on a crest up to FACE_SEARCH_ITERATIONS more.
"""

import warp as wp

from ..kernel_args import TerrainModel
from ..terrain import HeightSample, fourier_sample

FACE_SEARCH_ITERATIONS = 6  # surface samples a climb may take after the checkpoint's
# [m] a climb step that gains less ends the climb, and one the quadratic model predicts within it
# is taken from the model: 1/7 of the depth a resting contact sags (0.07 mm at the defaults), a
# tenth of what tests/test_face_search.py allows a contact's depth beside the oracle's.
FACE_SEARCH_GAIN = wp.constant(1.0e-5)


@wp.func
def body_axis(rot: wp.mat33, k: int) -> wp.vec3:
    return wp.vec3(rot[0, k], rot[1, k], rot[2, k])


@wp.func
def support_face(rot: wp.mat33, down: wp.vec3) -> wp.vec2i:
    """(axis, sign) of the box face whose outward normal sign R e_axis points most along ``down``."""
    axis = int(0)
    sign = int(1)
    best = float(-1.0)
    for k in range(3):
        c = wp.dot(body_axis(rot, k), down)
        if wp.abs(c) > best:
            best = wp.abs(c)
            axis = k
            sign = wp.where(c > 0.0, 1, -1)
    return wp.vec2i(axis, sign)


@wp.func
def on_support_face(local: wp.vec3, half: wp.vec3, face: wp.vec2i) -> bool:
    """Whether a checkpoint lies on the face: its coordinate is the face's, bit for bit (both are
    the float32 half extent times +-1, builder.host_arrays)."""
    return local[face[0]] == float(face[1]) * half[face[0]]


@wp.func
def cell_bounds(local: float, half: float, cell: float) -> wp.vec2:
    """The cell's offsets along one face axis: within ``cell`` of the checkpoint, inside the face."""
    return wp.vec2(wp.max(-cell, -half - local), wp.min(cell, half - local))


@wp.func
def hessian_norm(s: HeightSample) -> float:
    """|K|: the largest absolute eigenvalue of the Hessian [[Hxx, Hxz], [Hxz, Hzz]]."""
    mean = 0.5 * (s.hess[0] + s.hess[2])
    half_gap = 0.5 * (s.hess[0] - s.hess[2])
    return wp.abs(mean) + wp.sqrt(half_gap * half_gap + s.hess[1] * s.hess[1])


@wp.func
def along(s: HeightSample, e: wp.vec3) -> float:
    """The depth's slope along the face direction e: g . e_h - e_y."""
    return s.grad[0] * e[0] + s.grad[1] * e[2] - e[1]


@wp.func
def curvature(s: HeightSample, e: wp.vec3, f: wp.vec3) -> float:
    """e_h^T K f_h."""
    return s.hess[0] * e[0] * f[0] + s.hess[1] * (e[0] * f[2] + e[2] * f[0]) + s.hess[2] * e[2] * f[2]


@wp.func
def cell_rise(center: HeightSample, arm: wp.vec3, rot: wp.mat33, face: wp.vec2i, cell: wp.vec3,
              cubic_bound: float) -> float:
    """How much deeper than the Taylor bound at the checkpoint (terrain_contact.box_rise_bound) any
    point of its cell can be: for the cell's point p + a e_a + b e_b, with v = arm_h + delta_h,

        d <= d_bound(arm) + a (g . e_a,h - e_a,y) + b (g . e_b,h - e_b,y) + arm_h^T K delta_h
             + delta_h^T K delta_h / 2 + T (|v|^3 - |arm_h|^3) / 6

    (g, K the centre's gradient and Hessian), each term bounded over |a| <= w_a, |b| <= w_b.  The
    slopes are the depth's along the face, so a face lying along the ground adds little."""
    ea = body_axis(rot, (face[0] + 1) % 3)
    eb = body_axis(rot, (face[0] + 2) % 3)
    wa = cell[(face[0] + 1) % 3]
    wb = cell[(face[0] + 2) % 3]
    reach = wa * wp.sqrt(ea[0] * ea[0] + ea[2] * ea[2]) + wb * wp.sqrt(eb[0] * eb[0] + eb[2] * eb[2])
    r = wp.sqrt(arm[0] * arm[0] + arm[2] * arm[2])
    k_norm = hessian_norm(center)
    k_arm = wp.vec2(center.hess[0] * arm[0] + center.hess[1] * arm[2], center.hess[1] * arm[0] + center.hess[2] * arm[2])
    return (wa * wp.abs(along(center, ea)) + wb * wp.abs(along(center, eb)) + wp.length(k_arm) * reach
            + 0.5 * k_norm * reach * reach + cubic_bound * ((r + reach) * (r + reach) * (r + reach) - r * r * r) / 6.0)


@wp.func
def may_climb(slope: float, curvature: float, cubic: float, reach: float) -> bool:
    """Whether d can rise to a top within ``reach`` along an axis: concave, or convex yet turning
    soon enough that its slope can vanish there (|g| + k r <= T r^2 / 2, T bounding the third
    derivatives).  Otherwise d climbs all the way to the cell's end, which the neighbouring
    checkpoint or the face's edge bounds."""
    return curvature < 0.0 or wp.abs(slope) + curvature * reach <= 0.5 * cubic * reach * reach


@wp.func
def sure_step(slope: float, curvature: float, cubic: float) -> float:
    """The step along an axis that maximises the least the depth can gain by Taylor's theorem,
    g t + k t^2 / 2 - T |t|^3 / 6 (t along the slope g; T bounds the third derivative): t =
    (k + sqrt(k^2 + 2 T |g|)) / T.  Where the curvature dominates it is the quadratic model's
    Newton step -g / k; where it is weak, or convex, it is as far as the bound still promises a
    climb, never to a top the model only imagines beyond it."""
    if slope == 0.0 or cubic <= 0.0:
        return wp.where(curvature < 0.0 and cubic <= 0.0, -slope / curvature, 0.0)
    t = (curvature + wp.sqrt(curvature * curvature + 2.0 * cubic * wp.abs(slope))) / cubic
    return wp.where(slope > 0.0, t, -t)


@wp.struct
class CellPoint:
    """What a cell's climb found: the depth of the deepest point it reached, the checkpoint's own
    sample and depth, and the chord bound that caps the rise (module docstring)."""

    start_sample: HeightSample
    depth: float
    start_depth: float
    chord_bound: float


@wp.func
def normal_y(s: HeightSample) -> float:
    """n_y of the surface normal at the sample: 1 / sqrt(1 + |grad H|^2)."""
    return 1.0 / wp.sqrt(1.0 + s.grad[0] * s.grad[0] + s.grad[1] * s.grad[1])


@wp.func
def depth_at(s: HeightSample, p: wp.vec3) -> float:
    """(H - p_y) n_y: the first-order distance of p below the surface (terrain_contact.py)."""
    return (s.height - p[1]) * normal_y(s)


@wp.func
def deepest_in_cell(terrain: TerrainModel, base: wp.vec3, rot: wp.mat33, local: wp.vec3, half: wp.vec3,
                    cell: wp.vec3, face: wp.vec2i, window: float) -> CellPoint:
    """The climb of the checkpoint at ``base`` (world) over its cell (module docstring).  No climb
    where even the chord bound leaves the cell further than ``window`` from the surface: its contact
    stays idle whatever the climb finds."""
    a_axis = (face[0] + 1) % 3
    b_axis = (face[0] + 2) % 3
    ea = body_axis(rot, a_axis)
    eb = body_axis(rot, b_axis)
    bounds_a = cell_bounds(local[a_axis], half[a_axis], cell[a_axis])
    bounds_b = cell_bounds(local[b_axis], half[b_axis], cell[b_axis])
    offset = wp.vec2(0.0, 0.0)
    p = base
    s = fourier_sample(terrain.terrain_coef, terrain.terrain_terms, terrain.terrain_frequency,
                       terrain.terrain_scale, terrain.terrain_offset, p[0], p[2])
    best = CellPoint()
    best.start_sample = s
    best.depth = depth_at(s, p)
    best.start_depth = best.depth
    reach_a = wp.max(-bounds_a[0], bounds_a[1])
    reach_b = wp.max(-bounds_b[0], bounds_b[1])
    k_a = curvature(s, ea, ea)
    k_b = curvature(s, eb, eb)
    concave_a = wp.max(-k_a, 0.0)
    concave_b = wp.max(-k_b, 0.0)
    best.chord_bound = 0.5 * (concave_a * reach_a * reach_a + concave_b * reach_b * reach_b)
    cubic = terrain.terrain_cubic_bound
    if not may_climb(along(s, ea), k_a, cubic, reach_a) and not may_climb(along(s, eb), k_b, cubic, reach_b):
        return best
    # no point of the cell is more concave than the checkpoint by over T (reach_a + reach_b)
    spread = cubic * (reach_a + reach_b)
    if best.depth + 0.5 * ((concave_a + spread) * reach_a * reach_a + (concave_b + spread) * reach_b * reach_b) < -window:
        return best
    best_sample = s
    scale = float(1.0)
    for _it in range(FACE_SEARCH_ITERATIONS):
        ga = along(s, ea)
        gb = along(s, eb)
        haa = curvature(s, ea, ea)
        hab = curvature(s, ea, eb)
        hbb = curvature(s, eb, eb)
        # one projected Gauss-Seidel pass, an axis that may climb at a time (a 2-D Newton step
        # clamped to a corner's cell went to the cell's far end, 0.8 mm short of its top)
        moved = offset
        if may_climb(ga, haa, cubic, reach_a):
            moved = wp.vec2(wp.clamp(offset[0] + sure_step(ga, haa, cubic), bounds_a[0], bounds_a[1]), offset[1])
        slope_b = gb + hab * (moved[0] - offset[0])
        if may_climb(slope_b, hbb, cubic, reach_b):
            moved = wp.vec2(moved[0], wp.clamp(offset[1] + sure_step(slope_b, hbb, cubic), bounds_b[0], bounds_b[1]))
        step = scale * (moved - offset)
        # the quadratic model's gain over the step, and how far the model can be off over it
        # (T |step|^3 / 6, T bounding the third derivatives): a step that gains under
        # FACE_SEARCH_GAIN ends the climb, and one the model predicts that closely is taken from
        # the model, without a sample
        gain = ga * step[0] + gb * step[1] + 0.5 * (haa * step[0] * step[0] + 2.0 * hab * step[0] * step[1]
                                                     + hbb * step[1] * step[1])
        if gain < FACE_SEARCH_GAIN:
            break
        reach = wp.length(step)
        if terrain.terrain_cubic_bound * reach * reach * reach < 6.0 * FACE_SEARCH_GAIN:
            best.depth = best.depth + gain * normal_y(s)
            break
        # a step that does not climb is cut to a quarter (a cube resting on its edge over a crest
        # stepped 0.1 m off the edge along an axis of curvature -0.002 / m and reported 0.03 of its
        # 1 mm); the trial stays in the cell, between two points of it
        trial = offset + step
        p = base + trial[0] * ea + trial[1] * eb
        trial_sample = fourier_sample(terrain.terrain_coef, terrain.terrain_terms, terrain.terrain_frequency,
                                      terrain.terrain_scale, terrain.terrain_offset, p[0], p[2])
        d = depth_at(trial_sample, p)
        if d > best.depth:
            offset = trial
            s = trial_sample
            best.depth = d
            best_sample = s
            scale = 1.0
        else:
            scale = 0.25 * scale
    # the chord bound takes the larger concave curvature of the checkpoint and the top: a crest
    # bends more at its top than on its flank (a cube of half 0.5 resting over one: -0.30 against
    # -0.21 / m, and capped at the checkpoint's it stayed 0.6 mm in)
    concave_a = wp.max(concave_a, -curvature(best_sample, ea, ea))
    concave_b = wp.max(concave_b, -curvature(best_sample, eb, eb))
    best.chord_bound = 0.5 * (concave_a * reach_a * reach_a + concave_b * reach_b * reach_b)
    return best
