"""Body-terrain contact: the cheapest exact query per shape (SEED.md 4.3).

Conventions: ``depth`` > 0 is penetration, < 0 a gap; the normal points out of the terrain.

Spheres: one closest-point query against the analytic surface y = H(x, z).  The closest point
minimises F(x, z) = |(x, H, z) - c|^2 / 2; Newton's method on F uses the terrain Hessian that
the Fourier evaluation gives for free:

    grad F = (x - cx + dy Hx,  z - cz + dy Hz),            dy = H - cy
    hess F = [[1 + Hx^2 + dy Hxx,  Hx Hz + dy Hxz],
              [Hx Hz + dy Hxz,     1 + Hz^2 + dy Hzz]]

When that Hessian is not positive definite (the sphere centre lies beyond a centre of
curvature) the Gauss-Newton part [[1 + Hx^2, Hx Hz], [Hx Hz, 1 + Hz^2]] is used instead, which
always is.  The search starts from last substep's closest point (stored in the slot), so a
resting sphere converges in one or two iterations, and a rolling one, whose first step is its
centre's travel since, takes its second point from the third-order jet of the first sample where
that is provably as near as the search's tolerance (closest_jet.py): one series evaluation
instead of two or three.  A sphere whose vertical gap divided by sqrt(1 + G^2) (G bounds
|grad H| everywhere) already exceeds r + margin cannot touch the surface and skips the search.

Spheres wider than the terrain's tightest curve: the distance from the centre can have several
local minima (the two walls of a trough narrower than the ball) and the point under the centre
can be a stationary point between them (the trough's bottom, a saddle or maximum of F, where
Newton starts and stops).  A sphere whose radius reaches 1 / kappa, kappa bounding the surface's
curvature (FourierTerrain.curvature_bound), is given ``WIDE_SPHERE_SLOTS`` slots: slot 0 as
above, and four more whose searches start from the points half a radius to the +-x and +-z of
the centre (then from their own last closest point), so each finds a local minimum of F on its
side.  Newton stops wherever F's gradient vanishes, and a seed on a line of symmetry (the +x seed
over a pit whose four contacts lie on the diagonals) reaches the saddle between two minima: a
further slot that ends where F's Hessian is not positive definite searches again from a quarter
radius down its most negative curvature direction (``saddle_escape``) and keeps the nearer point.
A slot that lands within ``DUPLICATE_SHARE`` r of an earlier slot's point is closed, so a surface
point is held once.  Every stationary point found is a valid constraint (that surface
point stays outside the sphere, linearised along its normal), so a slot at a saddle never
holds the ball wrongly; it only lies further than the minima and is usually inactive.  A sphere
under 1 / kappa touches a smooth surface at one point (a curve that leaves a circle tangentially
and meets it again tangentially bends more than the circle in between), so it keeps its one
slot and the search below is unchanged.

Boxes: the thesis's checkpoints.  A checkpoint p is compared with the
surface directly below it: depth = (H(p.x, p.z) - p.y) n_y with n the unit normal from the
gradient, the first-order distance to the surface (exact on planes).  On the Fourier terrain the
checkpoints of the face turned to the ground also see a crest between them (face_search.py,
``SimConfig.face_search``).

Most of a box's 26 checkpoints cannot reach the surface (those on its upper half, when it rests
on a face), and each costs a 25-term Fourier evaluation.  One thread handles one body, samples
the surface once under the centre c (height, gradient g, Hessian K) and skips a checkpoint p at
horizontal offset d from c when it provably lies too high.  By Taylor's theorem with the
Lagrange remainder, along the segment from c to c + d

    H(c + d) <= H(c) + g . d + d^T K d / 2 + T |d|^3 / 6,

T bounding every third directional derivative (FourierTerrain.cubic_bound).  The depth the full
test would find is (H - p_y) n_y with n_y >= 1 / sqrt(1 + G^2), G the slope bound, so when
p_y - (that bound) exceeds gap sqrt(1 + G^2) the slot is certainly inactive; gap uses the
point's whole speed |v + w x r|, which is at least its approach speed.  ``CULL_SLACK`` (1 mm,
growing 1e-7 per metre from the origin) covers the float32 error of the two evaluations, which
is about k f |u| 2^-24 sum|A| (tests/test_terrain.py).  The skip changes no result; a test runs
both ways and compares.  In the settled rain of 10k bodies about 8 of a box's 26 checkpoints
are sampled, and the terrain collision pass went from 8.5 to 4.5 ms a step.

Speculative margin: a slot is active while depth > -(margin + h |v_n| + h^2 |g|), the gap the
point can close in one substep (h the whole step when contacts are found once per step); the
solver then lets it close exactly that gap (v_n >= -gap/h), so a fast body stops on the surface
instead of passing through it.  For a box, |v_n| is at least the fastest any of its points could
move after contact events that add no energy (struck_reach.py): its slots stay open for the
whole step, and a pivot on one edge mid-step swings the far edge at up to about twice the fall.
"""

import numpy as np
import warp as wp

from ..integrate import world_inv_inertia
from ..kernel_args import BodyModel, BodyState, TerrainContacts, TerrainModel
from ..terrain import (TERRAIN_FOURIER, TERRAIN_PLANE, FourierTerrain, HeightSample, fourier_evaluate,
                       fourier_height_slope, fourier_normal, fourier_sample)
from ..types import SHAPE_SPHERE
from .closest_jet import jet_step
from .bounded_points import corner_index, is_corner, prune_bounded_points
from .face_search import cell_rise, deepest_in_cell, on_support_face, support_face
from .still_contacts import (NO_ANCHOR, STILL_SPEED, STILL_TRAVEL, carry_still_contacts, closable_gap, close_slot,
                             travel_since, window_floor)
from .struck_reach import reachable_speed

# No kernel here is differentiated: skip generating (and compiling) the adjoints.
wp.set_module_options({"enable_backward": False})

NEWTON_ITERATIONS = 6
WIDE_SPHERE_SLOTS = 5
SEED_OFFSET = wp.constant(0.5)  # [radii] the extra slots' cold starts, off the centre
DUPLICATE_SHARE = wp.constant(0.05)  # [radii] slots closer than this hold one surface point
ESCAPE_OFFSET = wp.constant(0.25)  # [radii] a further slot's restart off a saddle


def sphere_terrain_slots(terrain, radius) -> np.ndarray:
    """Terrain contact slots per sphere of ``radius`` (array): WIDE_SPHERE_SLOTS where the radius
    reaches the terrain's curvature radius bound, else 1 (see the module docstring)."""
    radius = np.asarray(radius, dtype=np.float64)
    curvature = terrain.curvature_bound() if isinstance(terrain, FourierTerrain) else 0.0
    return np.where(radius * curvature >= 1.0, WIDE_SPHERE_SLOTS, 1).astype(np.int32)


@wp.func
def saddle_escape(s: HeightSample, center: wp.vec3, k: int) -> wp.vec2:
    """Where F's Hessian at the sample is not positive definite (a saddle or maximum of the distance,
    such as a point between two walls on a line of symmetry), its most negative curvature direction,
    signed towards slot k's seed direction turned a quarter (+x to +z, +z to -x, ...), so the four
    slots leave the saddles of a symmetric pit for four different minima; else zero."""
    dy = s.height - center[1]
    a = 1.0 + s.grad[0] * s.grad[0] + dy * s.hess[0]
    b = s.grad[0] * s.grad[1] + dy * s.hess[1]
    c = 1.0 + s.grad[1] * s.grad[1] + dy * s.hess[2]
    if a > 0.0 and c > 0.0 and a * c - b * b > 0.0:
        return wp.vec2(0.0, 0.0)
    lowest = 0.5 * (a + c) - wp.sqrt(0.25 * (a - c) * (a - c) + b * b)
    # (lowest - c, b) and (b, lowest - a) are both eigenvectors; take the longer (one can vanish)
    e = wp.vec2(lowest - c, b)
    other = wp.vec2(b, lowest - a)
    if wp.length(other) > wp.length(e):
        e = other
    if wp.length(e) < 1.0e-12:
        e = wp.vec2(1.0, 0.0)  # a multiple of the identity: every direction is as low
    d = seed_direction(k)
    side = wp.vec2(-d[1], d[0])
    e = wp.normalize(e)
    if wp.dot(e, side) < 0.0:
        e = -e
    return e


@wp.func
def seed_direction(k: int) -> wp.vec2:
    """Slot k's cold-start direction: +x, -x, +z, -z for k = 1 to 4."""
    if k == 1:
        return wp.vec2(1.0, 0.0)
    if k == 2:
        return wp.vec2(-1.0, 0.0)
    if k == 3:
        return wp.vec2(0.0, 1.0)
    return wp.vec2(0.0, -1.0)


CULL_SLACK = 1.0e-3  # [m]
CULL_SLACK_RATE = 1.0e-7  # [m per m of |x| + |z|]


@wp.func
def search_resolution(x: float, z: float) -> float:
    """[m] What the closest-point search resolves at (x, z): a few float32 ulps of the coordinates.
    A step under it ends the search, and two distances closer than it cannot be told apart."""
    return 1.0e-6 + 2.0e-7 * (wp.abs(x) + wp.abs(z))


@wp.func
def sphere_fourier_closest(
    terrain_coef: wp.array(dtype=wp.vec2),
    terrain_terms: int,
    terrain_frequency: float,
    terrain_scale: wp.vec3,
    terrain_offset: wp.vec3,
    center: wp.vec3,
    start: wp.vec2,
    start_sample: HeightSample,
    reach: float,
    jet: int,
    bounds: wp.vec4,
) -> tuple[wp.vec2, HeightSample]:
    """Surface point closest to ``center`` and its sample, by damped Newton from ``start``.

    ``reach`` is the distance from the centre to some surface point (the one straight below, or
    last substep's closest point); the closest point can be no farther, so iterates are kept
    inside that horizontal disc and no step is longer than half of it.  This stops Newton from
    running off to a distant stationary point of F when it starts cold on steep ground.  The
    search stops once a step falls below a few float32 ulps of the coordinates, so a resting
    sphere costs a single terrain evaluation.  With ``jet`` (a warm start whose sample carries the
    third derivatives) a moving sphere's second evaluation is replaced by the jet's prediction
    where that is as near the closest point as the tolerance asks (closest_jet.py; ``bounds`` =
    the terrain's directional bounds of order 1 to 4).
    """
    xz = start
    s = start_sample
    max_step = 0.5 * reach + 1.0e-6
    for _it in range(NEWTON_ITERATIONS):
        hx = s.grad[0]
        hz = s.grad[1]
        dy = s.height - center[1]
        gx = xz[0] - center[0] + dy * hx
        gz = xz[1] - center[2] + dy * hz
        a = 1.0 + hx * hx + dy * s.hess[0]
        b = hx * hz + dy * s.hess[1]
        c = 1.0 + hz * hz + dy * s.hess[2]
        det = a * c - b * b
        gauss_newton = a <= 0.0 or det <= 1.0e-12
        if gauss_newton:
            a = 1.0 + hx * hx
            b = hx * hz
            c = 1.0 + hz * hz
            det = a * c - b * b
        step = wp.vec2((c * gx - b * gz) / det, (a * gz - b * gx) / det)
        length = wp.length(step)
        tolerance = search_resolution(xz[0], xz[1])
        if length < tolerance:
            break
        full_newton = not gauss_newton
        if length > max_step:
            step = step * (max_step / length)
            full_newton = False
        offset = wp.vec2(xz[0] - step[0] - center[0], xz[1] - step[1] - center[2])
        off_len = wp.length(offset)
        if off_len > reach:
            offset = offset * (reach / off_len)
            full_newton = False
        if jet != 0 and _it == 0 and full_newton:
            predicted = jet_step(s, xz, dy, -step, wp.vec3(a, b, c), tolerance, bounds)
            if predicted.accepted != 0:
                xz = predicted.point
                s = predicted.sample
                break
        xz = wp.vec2(center[0] + offset[0], center[2] + offset[1])
        s = fourier_sample(terrain_coef, terrain_terms, terrain_frequency, terrain_scale, terrain_offset, xz[0], xz[1])
    return xz, s


@wp.func
def sample_at(terrain: TerrainModel, xz: wp.vec2) -> HeightSample:
    return fourier_sample(terrain.terrain_coef, terrain.terrain_terms, terrain.terrain_frequency,
                          terrain.terrain_scale, terrain.terrain_offset, xz[0], xz[1])


@wp.func
def jet_at(terrain: TerrainModel, xz: wp.vec2) -> HeightSample:
    """sample_at with the third derivatives too (closest_jet.py)."""
    return fourier_evaluate(terrain.terrain_coef, terrain.terrain_terms, terrain.terrain_frequency,
                            terrain.terrain_scale, terrain.terrain_offset, xz[0], xz[1], 3)


@wp.func
def closest_from(terrain: TerrainModel, center: wp.vec3, start: wp.vec2, start_sample: HeightSample,
                 jet: int) -> tuple[wp.vec2, HeightSample]:
    """sphere_fourier_closest from ``start``, its reach the distance from the centre to that point;
    ``jet`` where ``start_sample`` came from jet_at."""
    reach = wp.length(center - wp.vec3(start[0], start_sample.height, start[1]))
    bounds = wp.vec4(terrain.terrain_slope_bound, terrain.terrain_curvature_bound, terrain.terrain_cubic_bound,
                     terrain.terrain_quartic_bound)
    return sphere_fourier_closest(terrain.terrain_coef, terrain.terrain_terms, terrain.terrain_frequency,
                                  terrain.terrain_scale, terrain.terrain_offset, center, start, start_sample, reach,
                                  jet, bounds)


@wp.func
def closest_or_start(terrain: TerrainModel, center: wp.vec3, start: wp.vec2, start_sample: HeightSample,
                     jet: int) -> tuple[wp.vec2, HeightSample]:
    """closest_from, or the start itself where the search ended farther from the centre than the
    start lies (it did not improve on it).  Within float32's resolution of the coordinates the two
    distances cannot be told apart (a step of 0.2 mm shortens a 0.25 m ball's by 1e-7 m), and
    keeping the start there left its normal up to 0.3 mm of surface behind."""
    xz, s = closest_from(terrain, center, start, start_sample, jet)
    reach = wp.length(center - wp.vec3(start[0], start_sample.height, start[1]))
    if wp.length(center - wp.vec3(xz[0], s.height, xz[1])) > reach + search_resolution(center[0], center[2]):
        return start, start_sample
    return xz, s


@wp.struct
class Touch:
    """A sphere's contact at its touch (touch_ahead): surface point (x, z), normal, depth now."""

    point: wp.vec2
    normal: wp.vec3
    depth: float


@wp.func
def touch_ahead(terrain: TerrainModel, x: wp.vec3, v: wp.vec3, h: float, xz: wp.vec2, s: HeightSample,
                normal: wp.vec3, depth: float, radius: float) -> Touch:
    """A sphere's contact where it will touch within the substep, not where its centre is now.

    A ball a gap g above the ground closing at v_n reaches it at t* = g / v_n.  Taken at the
    substep's start, the contact's normal is the surface's under the centre's present place, which
    lies up to h |v_t| from where the ball touches: its rebound on curved ground was off by up to
    2 k h |v| (0.39 degrees at 20 m/s and h = 1/240 s on the egg crate of
    tests/test_curved_rebound.py).  The closest point to
    the centre at t*, x + v t* (gravity's h^2 |g| / 2 left out), is where it touches, up to the
    curvature's second-order error in t*; its tangent plane, measured from the centre now, keeps
    the gap g' = -(v . n') t* the ball closes by t*, so the speculative row and the impact stage
    (which times the impact at g' / v_n') both see the touch.  Only a gap closed within the
    substep, and a travel past the search's resolution, search again."""
    out = Touch()
    out.point = xz
    out.normal = normal
    out.depth = depth
    closing = -wp.dot(v, normal)
    if depth >= 0.0 or closing <= 0.0 or -depth >= closing * h:
        return out
    t_touch = -depth / closing
    if t_touch * wp.length(v) <= search_resolution(x[0], x[2]):
        return out
    ahead = x + t_touch * v
    point, sample = closest_or_start(terrain, ahead, xz, s, 0)
    surface = wp.vec3(point[0], sample.height, point[1])
    out.point = point
    out.normal = fourier_normal(sample.grad)
    out.depth = radius - wp.dot(x - surface, out.normal)
    return out


@wp.func
def box_rise_bound(center: HeightSample, dx: float, dz: float, cubic_bound: float) -> float:
    """An upper bound of H(c + d) - H(c) for the horizontal offset d = (dx, dz) (Taylor, see above)."""
    quadratic = dx * dx * center.hess[0] + 2.0 * dx * dz * center.hess[1] + dz * dz * center.hess[2]
    r = wp.sqrt(dx * dx + dz * dz)
    return center.grad[0] * dx + center.grad[1] * dz + 0.5 * quadratic + cubic_bound * r * r * r / 6.0


REFRESH_MIN_TRAVEL = wp.constant(1.0e-3)


@wp.kernel
def collide_terrain(
    tid_offset: int,
    # Model
    model: BodyModel,
    terrain: TerrainModel,
    # Settings
    h: float,
    gravity_length: float,
    speculative_margin: float,
    cull: int,
    refresh_spheres: int,
    struck: int,
    face_search: int,
    prune_face_points: int,
    jet_search: int,
    still_contacts: int,
    # State in
    state_in: BodyState,
    # Solver in (the pose of the step's pass)
    reference_pos: wp.array(dtype=wp.vec3),
    # In
    body_struck_reach: wp.array(dtype=float),
    # Contacts in/out
    contacts: TerrainContacts,
):
    """One thread per body, over its slots: the body's velocity and, for a box on the Fourier
    terrain, the surface sample under its centre are computed once and serve every checkpoint.

    ``refresh_spheres``: between the collision passes of a step (contacts found once per step), the
    spheres' contacts are found again at the current pose and stored as the staged solver reads
    them, relative to the pose of the step's pass (``reference_pos``): point - (x - x_ref) and
    depth + n . (x - x_ref), so that its gap -depth + n . (x - x_ref) and arm p - x_ref are those of
    now.  A sphere's tangent-plane gap is otherwise off by k d^2 / 2 after sliding d over ground of
    curvature k, which made a ball rolling in a valley gain 16 % of its energy in 20 s.  Boxes are
    left as they are (their slots and count).

    ``struck``: a pass whose pairs were found first: a box takes the reach a partner's blow could give
    its points where that exceeds its own (struck_reach.py, ``body_struck_reach``)."""
    body = wp.tid() + tid_offset
    if refresh_spheres != 0:
        # only spheres touching the terrain since the step's pass, and only once they have moved:
        # a sphere whose slot the pass left idle cannot reach the surface within the step (the
        # pass's window covered it), and one that moved under 1 mm has a tangent-plane gap error
        # under k (1 mm)^2 / 2
        start = model.body_checkpoint_start[body]
        if model.body_shape[body] != SHAPE_SPHERE:
            return
        touching = int(0)
        for slot in range(start, start + model.body_checkpoint_count[body]):
            touching = touching | contacts.terrain_contact_active[slot]
        if touching == 0:
            return
        if wp.length(state_in.body_pos[body] - reference_pos[body]) < REFRESH_MIN_TRAVEL:
            return
    start = model.body_checkpoint_start[body]
    count = model.body_checkpoint_count[body]
    x = state_in.body_pos[body]
    rot = state_in.body_rot[body]
    v = state_in.body_vel[body]
    is_sphere = model.body_shape[body] == SHAPE_SPHERE
    omega = wp.vec3(0.0)
    if is_sphere:
        omega = model.body_inv_inertia[body][0] * state_in.body_angmom[body]  # isotropic: no R I^-1 R^T
    else:
        omega = world_inv_inertia(rot, model.body_inv_inertia[body]) * state_in.body_angmom[body]
    radius = model.body_size[body][0]
    dynamic = model.body_inv_mass[body] > 0.0
    fourier_box = dynamic and terrain.terrain_kind == TERRAIN_FOURIER and not is_sphere
    gap_scale = wp.sqrt(1.0 + terrain.terrain_slope_bound * terrain.terrain_slope_bound)
    center = HeightSample()
    face = wp.vec2i(0, 0)
    half = model.body_size[body]
    cell = wp.vec3(0.0)
    if fourier_box:
        cell = model.body_checkpoint_cell[body]  # a sphere's thread does not read it
    reach_speed = float(0.0)  # a box's points: the fastest a contact event could make them (struck_reach.py)
    if dynamic and not is_sphere:
        reach_speed = reachable_speed(v, state_in.body_angmom[body], rot, model.body_inertia[body],
                                      model.body_inv_inertia[body], model.body_inv_mass[body], half)
    if struck != 0 and dynamic and not is_sphere:
        # before the still test: the windows, found afresh or carried (still_contacts.py), open with it
        reach_speed = wp.max(reach_speed, body_struck_reach[body])
    floor = float(0.0)  # the windows' least approach speed while still bodies are carried (still_contacts.py)
    if still_contacts != 0 and terrain.terrain_kind == TERRAIN_FOURIER:
        floor = window_floor(h, gap_scale)
        if refresh_spheres == 0 and dynamic:
            reach = float(0.0)
            spin = wp.length(omega)
            quiet = wp.length(v)
            if not is_sphere:
                reach = wp.length(half)
                quiet = wp.max(reach_speed, quiet + spin * reach) + spin * (cell[0] + cell[1] + cell[2])
            travel = travel_since(x, state_in.body_quat[body], contacts.terrain_contact_anchor_pos[body],
                                  contacts.terrain_contact_anchor_quat[body], reach)
            if quiet <= STILL_SPEED and travel <= STILL_TRAVEL:
                contacts.terrain_contact_count[body] = carry_still_contacts(
                    start, count, x, rot, v, omega, radius, is_sphere, reach_speed, h, gravity_length,
                    speculative_margin, floor, model.checkpoint_local, contacts)
                return
    if fourier_box:
        center = fourier_sample(terrain.terrain_coef, terrain.terrain_terms, terrain.terrain_frequency,
                                terrain.terrain_scale, terrain.terrain_offset,
                                x[0], x[2])
        # the support face's checkpoints climb to the crests within their cells (face_search.py)
        face = support_face(rot, -fourier_normal(center.grad))
    slack = CULL_SLACK + CULL_SLACK_RATE * (wp.abs(x[0]) + wp.abs(x[2]))

    # A sphere's window, measured in the tangent plane of its closest point, misses ground that curves up
    # ahead: over a travel d the surface rises at most k d^2 / 2 above that plane (k the curvature
    # bound).  A ball at 150 m/s crosses 2.5 m in the window of a once-a-step pass; on the shipped
    # terrain the plane saw the ground 0.9 m off and closing too slowly to touch, the slot stayed idle,
    # and the ball ended the step with its centre under the surface.  The refreshes between passes keep
    # an open slot whatever its gap, so the window is widened only here.
    curve_rise = float(0.0)
    if is_sphere and dynamic and refresh_spheres == 0 and terrain.terrain_kind == TERRAIN_FOURIER:
        travel = h * wp.length(v) + 0.5 * h * h * gravity_length
        curve_rise = 0.5 * terrain.terrain_curvature_bound * travel * travel

    active = int(0)
    corner_depth = wp.vec4(0.0)  # the support face's corners, as found (bounded_points.py)
    for slot in range(start, start + count):
        if refresh_spheres != 0 and contacts.terrain_contact_active[slot] == 0:
            continue  # a wide sphere's idle slot stays idle until the next pass
        depth = float(-1.0e30)
        normal = wp.vec3(0.0, 1.0, 0.0)
        point = x
        if dynamic:
            if terrain.terrain_kind == TERRAIN_PLANE:
                n = wp.vec3(terrain.terrain_plane[0], terrain.terrain_plane[1], terrain.terrain_plane[2])
                normal = n
                if is_sphere:
                    point = x - radius * n
                else:
                    point = x + rot * model.checkpoint_local[slot]
                depth = terrain.terrain_plane[3] - wp.dot(n, point)
            elif terrain.terrain_kind == TERRAIN_FOURIER:
                if is_sphere:
                    # Start from last substep's closest point when there was one, else from the
                    # point straight below, which also gives the cheap can't-reach test.
                    # A wide sphere's further slots start off the centre (module docstring).
                    k = slot - start
                    seed = float(0.0)
                    start_xz = wp.vec2(x[0], x[2])
                    warm = contacts.terrain_contact_active[slot]
                    if warm != 0:
                        start_xz = contacts.terrain_contact_surface[slot]
                    elif k > 0:
                        seed = SEED_OFFSET * radius
                        start_xz = start_xz + seed * seed_direction(k)
                    s0 = HeightSample()
                    if warm != 0 and jet_search != 0:
                        s0 = jet_at(terrain, start_xz)
                    else:
                        s0 = sample_at(terrain, start_xz)
                    can_touch = True
                    if contacts.terrain_contact_active[slot] == 0:
                        # the ground under the centre is at most slope_bound * seed above the seed's
                        lower_bound = (x[1] - s0.height - terrain.terrain_slope_bound * seed) / gap_scale
                        can_touch = lower_bound - radius < (speculative_margin + h * wp.max(wp.length(v), floor)
                                                                   + h * h * gravity_length)
                    if can_touch:
                        xz, s = closest_or_start(terrain, x, start_xz, s0, warm * jet_search)
                        surface = wp.vec3(xz[0], s.height, xz[1])
                        if k > 0:
                            escape = saddle_escape(s, x, k)
                            if wp.length(escape) > 0.0:
                                # a further slot stopped at a saddle of F: search again from its
                                # downhill side and keep what lies nearer
                                start_2 = xz + (ESCAPE_OFFSET * radius) * escape
                                xz_2, s_3 = closest_from(terrain, x, start_2, sample_at(terrain, start_2), 0)
                                surface_2 = wp.vec3(xz_2[0], s_3.height, xz_2[1])
                                if wp.length(x - surface_2) < wp.length(x - surface):
                                    xz = xz_2
                                    s = s_3
                                    surface = surface_2
                        normal = fourier_normal(s.grad)
                        depth = radius - wp.dot(x - surface, normal)
                        if count == 1:
                            touch = touch_ahead(terrain, x, v, h, xz, s, normal, depth, radius)
                            xz = touch.point
                            normal = touch.normal
                            depth = touch.depth
                        point = x - radius * normal
                        contacts.terrain_contact_surface[slot] = xz
                        if k > 0 and refresh_spheres == 0:
                            # the earlier slots were written by this thread in this pass
                            for other in range(start, slot):
                                if contacts.terrain_contact_active[other] != 0:
                                    apart = wp.length(contacts.terrain_contact_surface[other] - xz)
                                    if apart < DUPLICATE_SHARE * radius:
                                        depth = float(-1.0e30)
                else:
                    local = model.checkpoint_local[slot]
                    point = x + rot * local
                    searched = face_search != 0 and on_support_face(local, half, face)
                    arm = point - x
                    # the gap the checkpoint (anywhere in its cell, when searched: face_search.py) can
                    # close in one substep
                    speed = wp.max(wp.max(wp.length(v + wp.cross(omega, arm)), reach_speed), floor)
                    if searched:
                        speed += wp.length(omega) * (cell[0] + cell[1] + cell[2])
                    window = speculative_margin + h * speed + h * h * gravity_length
                    reachable = True
                    face_corner = on_support_face(local, half, face) and is_corner(local, half)
                    if face_corner:
                        # bounded_points.py: a corner counts as lying at least at its window's edge
                        corner_depth[corner_index(local, face)] = -window
                    if cull != 0:
                        rise = box_rise_bound(center, arm[0], arm[2], terrain.terrain_cubic_bound)
                        if searched:
                            rise += cell_rise(center, arm, rot, face, cell, terrain.terrain_cubic_bound)
                        reachable = point[1] - (center.height + rise) <= window * gap_scale + slack
                    if reachable:
                        if searched:
                            # a checkpoint whose cell cannot come within the window skips the climb
                            deepest = deepest_in_cell(terrain, point, rot, local, half, cell, face, window)
                            normal = fourier_normal(deepest.start_sample.grad)
                            depth = deepest.start_depth + wp.min(deepest.depth - deepest.start_depth,
                                                                 deepest.chord_bound)
                        else:
                            s = fourier_height_slope(terrain.terrain_coef, terrain.terrain_terms,
                                                     terrain.terrain_frequency, terrain.terrain_scale,
                                                     terrain.terrain_offset, point[0], point[2])
                            normal = fourier_normal(s.grad)
                            depth = (s.height - point[1]) * normal[1]
                        if face_corner:
                            corner_depth[corner_index(local, face)] = wp.max(depth, -window)

        point_vel = v + wp.cross(omega, point - x)
        gap_closable = closable_gap(point_vel, normal, reach_speed, floor, speculative_margin, h, gravity_length)
        gap_closable += curve_rise
        # a refreshed sphere keeps its slot whatever the gap: the step's pass opened it for the
        # whole step, and closing it here would hide the surface from the later substeps
        if depth > -gap_closable or refresh_spheres != 0:
            active += 1
            if refresh_spheres != 0:
                shift = x - reference_pos[body]
                point = point - shift
                depth = depth + wp.dot(normal, shift)
            contacts.terrain_contact_active[slot] = 1
            contacts.terrain_contact_point[slot] = point
            contacts.terrain_contact_normal[slot] = normal
            contacts.terrain_contact_depth[slot] = depth
        else:
            close_slot(contacts, slot)
    if fourier_box and prune_face_points != 0:
        # the rows between the support face's corners that the corners already hold (bounded_points.py)
        active -= prune_bounded_points(start, count, x, half, face, corner_depth, model.checkpoint_local, contacts)
    contacts.terrain_contact_count[body] = active
    if still_contacts != 0:
        # the pose these slots were found at; none where they were found mid-step or for a body
        # without mass (a sleeper's slots are searched in full when it wakes)
        anchor = wp.vec3(NO_ANCHOR)
        if dynamic and refresh_spheres == 0:
            anchor = x
        contacts.terrain_contact_anchor_pos[body] = anchor
        contacts.terrain_contact_anchor_quat[body] = state_in.body_quat[body]
