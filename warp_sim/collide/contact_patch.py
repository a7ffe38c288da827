"""Friction about the contact normal of a face: where a manifold's friction rows act.

A box resting on a face is held at a few points (its corners on the terrain, the clipped
polygon's vertices against another box), and each point's friction is Coulomb's, |f_k| <=
mu N_k.  Spinning about the normal, every point slips across its own radius, so the friction
torque is sum mu N_k |u_k|, u_k the point's offset in the contact plane from the patch's centre:
for a cube (half a) on its four corners mu N sqrt(2) a.  A face pressed evenly over its area
resists with the mean distance of its area instead (Coulomb friction integrated over the
rectangle of half sides a >= b, d = sqrt(a^2 + b^2)):

    M = mu N r_e,   r_e = (2 a b d + a^3 ln((b + d) / a) + b^3 ln((a + d) / b)) / (6 a b)

(a square: r_e = a (sqrt 2 + ln(1 + sqrt 2)) / 3 = 0.765 a; a segment, b -> 0: a / 2).  The corners
overstate it by sqrt(2) a / r_e = 1.85 for a square, so a spinning cube stopped 1.85 times too
soon.

The fix moves where the friction rows act, not how much they may carry: each friction row of the
manifold acts at the point whose offset in the contact plane is scaled by s = r_e / D about the
patch's centre, D = sum N_k |u_k| / sum N_k the points' own mean radius.  Its relative velocity is
measured at that same point, so the row is still an exact Coulomb row of a rigid body (friction at
any point only dissipates), and with every point slipping in a spin the torque is s mu N D =
mu N r_e.  The offset along the normal is kept, so friction's tipping moment (arm along n, force in
the plane) and a straight slide (the in-plane torques of symmetric points cancel) are unchanged:
only the moment about the normal changes.  The normal rows keep the true points.

The patch is the points that hold a normal impulse, weighted by it (in a cold contact, where none
holds one yet, the deepest points, equally: point_weight).  A body's terrain patch is measured
along the two axes of the body most nearly in the contact plane (terrain_patch): a face's corners,
edge midpoints and centre span the rectangle it presses with, an edge a segment (b = 0); on
curved ground that bounding rectangle is an approximation.  Its centre is the points' weighted
mean, the centre of pressure, which follows the impulses continuously.  (It was the middle of the
loaded points' extents, which jumps as a point takes or drops load, however little: a plate
rocking on a curved slope had its carried friction re-applied at arms that jumped with it every
collision pass, kept rocking, and walked down a 10 degree slope 69 mm in 6 s, well within its
friction angle; tests/test_twist_friction.py.)  A pair's patch is the polygon of its
at most four points in the contact plane, about their centroid (pair_patch): a face inside the
other's is its rectangle exactly, a clipped polygon is itself, and no body's axes are needed (a
pair found again mid-step, pair_refresh.py, stores points at its bodies' turned pose).  A
manifold of one point, or none loaded, keeps its point (s = 1): spheres are untouched.

Both are measured once a collision pass, from the impulses carried into it: the pair's in
narrow_phase.carry_pair_impulses (and pair_refresh.py), the terrain's where prepare_body lists the
body's rows; the warm start and every sweep read the stored centre and s (pair_twist,
solver_twist).  Measured in every sweep instead, from the impulses of the moment, it cost more
than all the rest of this (a pair's polygon takes angles and logarithms).  ``SimConfig.face_friction = "points"`` keeps the points (bit for bit the
former solve, and a few per cent faster: README).  Impacts (solvers/impact.py) keep the true points
for their friction.
"""

import warp as wp

from .manifold import POINTS

wp.set_module_options({"enable_backward": False})

# a cold patch's points count within this share of its size of the deepest one (tilts under 1e-3 rad
# are flat)
COLD_BAND = 1.0e-3
# below this ratio of its sides a patch is a segment (r_e = a / 2 to a relative 1e-8 of a)
SEGMENT_RATIO = 1.0e-4


@wp.func
def even_pressure_radius(a: float, b: float) -> float:
    """Mean distance from the centre of a rectangle of half sides a, b (module docstring)."""
    big = wp.max(a, b)
    small = wp.min(a, b)
    if big <= 0.0:
        return 0.0
    if small < SEGMENT_RATIO * big:
        return 0.5 * big
    d = wp.sqrt(big * big + small * small)
    return (2.0 * big * small * d + big * big * big * wp.log((small + d) / big)
            + small * small * small * wp.log((big + d) / small)) / (6.0 * big * small)


@wp.func
def cold_floor(deepest: float, size: float) -> float:
    """The depth a point of a cold patch (none holds an impulse yet: a box just landed or set down)
    must reach to count: within COLD_BAND of the patch's size of the deepest point, so a face set
    down flat counts whole and an edge landing first counts alone."""
    return deepest - COLD_BAND * size


@wp.func
def point_weight(cold: int, floor: float, impulse: float, depth: float) -> float:
    """A point's weight in its patch: the normal impulse it holds; in a cold patch 1 for the
    deepest points (cold_floor), so the first sweep's friction acts at the arms later ones use
    (its impulse is clamped where it was applied, so the corners' torque taken there stays: a plate
    set down spinning on a box lost 17 % more spin in its first step)."""
    if cold != 0:
        return wp.where(depth >= floor, 1.0, 0.0)
    return impulse


@wp.func
def in_plane(offset: wp.vec3, n: wp.vec3) -> wp.vec3:
    return offset - wp.dot(offset, n) * n


NO_TWIST = wp.constant(wp.vec4(0.0, 0.0, 0.0, 1.0))  # a patch of one point: friction at the point itself


@wp.func
def twist_centre(twist: wp.vec4) -> wp.vec3:
    return wp.vec3(twist[0], twist[1], twist[2])


@wp.func
def twist_arm(arm: wp.vec3, point: wp.vec3, n: wp.vec3, twist: wp.vec4) -> wp.vec3:
    """The arm a friction row acts at: ``arm`` less (1 - s) of the offset of ``point`` (in the
    frame the patch was measured in) from the patch's centre, taken in the contact plane; ``twist``
    is (centre, s) as terrain_patch and pair_patch give it."""
    scale = twist[3]
    if scale >= 1.0:
        return arm
    return arm - (1.0 - scale) * in_plane(point - twist_centre(twist), n)


@wp.func
def terrain_row(first: int, k: int, listed: int, terrain_row_slot: wp.array(dtype=wp.int32)) -> int:
    """The slot of a body's k-th row: listed (staged.py), or its k-th slot (soft_step.py)."""
    return wp.where(listed != 0, terrain_row_slot[first + k], first + k)


@wp.func
def terrain_patch(
    first: int,
    count: int,
    listed: int,
    origin: wp.vec3,
    rot: wp.mat33,
    friction: float,
    # Solver in
    terrain_row_slot: wp.array(dtype=wp.int32),
    # Contacts in
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    terrain_contact_normal_impulse: wp.array(dtype=float),
) -> wp.vec4:
    """(centre as an arm from ``origin``, s) of a body's terrain patch: its rows
    terrain_row_slot[first + k], k < count, where ``listed`` (staged.py), else its active slots
    first .. first + count (soft_step.py), weighted by point_weight.  Extents along the body's axes
    (``rot``'s columns); the face is the one whose axis lies nearest the weighted normal."""
    if count < 2 or friction <= 0.0:
        return NO_TWIST
    rot_t = wp.transpose(rot)
    lo = wp.vec3(1.0e30)
    hi = wp.vec3(-1.0e30)
    along = wp.vec3(0.0)
    normal = wp.vec3(0.0)
    weight = float(0.0)
    points = int(0)
    cold = int(0)
    floor = float(0.0)
    for attempt in range(2):
        cold = attempt
        if attempt == 1:
            deepest = float(-1.0e30)
            size = float(0.0)
            for k in range(count):
                slot = terrain_row(first, k, listed, terrain_row_slot)
                if listed != 0 or terrain_contact_active[slot] != 0:
                    deepest = wp.max(deepest, terrain_contact_depth[slot])
                    size = wp.max(size, wp.length(terrain_contact_point[slot] - origin))
            floor = cold_floor(deepest, size)
        for k in range(count):
            slot = terrain_row(first, k, listed, terrain_row_slot)
            if listed != 0 or terrain_contact_active[slot] != 0:
                w = point_weight(cold, floor, terrain_contact_normal_impulse[slot], terrain_contact_depth[slot])
                if w > 0.0:
                    local = rot_t * (terrain_contact_point[slot] - origin)
                    lo = wp.min(lo, local)
                    hi = wp.max(hi, local)
                    along = along + w * local
                    normal = normal + w * terrain_contact_normal[slot]
                    weight = weight + w
                    points += 1
        if points > 0:
            break
    if points < 2:
        return NO_TWIST
    # the face: the axis nearest the mean normal (its extents give r_e); the centre: the points'
    # weighted mean, the centre of pressure, which moves with the impulses continuously (module
    # docstring: the middle of the extents jumped as points took and dropped load)
    n_local = rot_t * normal
    face = int(0)
    if wp.abs(n_local[1]) > wp.abs(n_local[0]) and wp.abs(n_local[1]) >= wp.abs(n_local[2]):
        face = 1
    elif wp.abs(n_local[2]) > wp.abs(n_local[0]) and wp.abs(n_local[2]) > wp.abs(n_local[1]):
        face = 2
    centre_local = along / weight
    centre = rot * centre_local
    spread = float(0.0)
    for k in range(count):
        slot = terrain_row(first, k, listed, terrain_row_slot)
        if listed != 0 or terrain_contact_active[slot] != 0:
            w = point_weight(cold, floor, terrain_contact_normal_impulse[slot], terrain_contact_depth[slot])
            if w > 0.0:
                offset = in_plane(terrain_contact_point[slot] - origin - centre, terrain_contact_normal[slot])
                spread = spread + w * wp.length(offset)
    if spread <= 0.0:
        return NO_TWIST
    half = 0.5 * (hi - lo)
    r_e = even_pressure_radius(half[(face + 1) % 3], half[(face + 2) % 3])
    return wp.vec4(centre[0], centre[1], centre[2], wp.clamp(r_e * weight / spread, 0.0, 1.0))


@wp.func
def triangle_radius_integral(x1: float, y1: float, x2: float, y2: float) -> float:
    """Integral of |r| over the triangle (origin, P1, P2), signed by its orientation: in polar
    coordinates about the origin, the edge at distance d, points at t along it from the foot of
    the perpendicular, rho = sqrt(d^2 + t^2):

        int rho(psi)^3 / 3 dpsi = [d rho t / 6 + (d^3 / 6) ln(rho + t)]  from P1 to P2

    (ln(rho + t) taken as ln(d^2 / (rho - t)) for t < 0, where rho + t cancels)."""
    ex = x2 - x1
    ey = y2 - y1
    length = wp.sqrt(ex * ex + ey * ey)
    if length <= 0.0:
        return 0.0
    d = (x1 * ey - y1 * ex) / length  # signed: positive for a counter-clockwise triangle
    t1 = (x1 * ex + y1 * ey) / length
    t2 = (x2 * ex + y2 * ey) / length
    ad = wp.abs(d)
    rho1 = wp.sqrt(x1 * x1 + y1 * y1)
    rho2 = wp.sqrt(x2 * x2 + y2 * y2)
    out = ad * (rho2 * t2 - rho1 * t1) / 6.0
    if ad > 1.0e-12 * length:
        log1 = wp.where(t1 >= 0.0, wp.log(rho1 + t1), wp.log(ad * ad / (rho1 - t1)))
        log2 = wp.where(t2 >= 0.0, wp.log(rho2 + t2), wp.log(ad * ad / (rho2 - t2)))
        out = out + ad * ad * ad * (log2 - log1) / 6.0
    return wp.where(d >= 0.0, out, -out)


@wp.func
def quad_mean_radius(xs: wp.vec4, ys: wp.vec4, m: int) -> wp.vec3:
    """Up to four points (coordinates about their centroid) as a convex polygon taken in angle
    order: (mean |r| over its area about the origin, its area, and the farthest point's distance:
    where the area is nil the patch is a segment, pair_patch)."""
    angle = wp.vec4(0.0)
    order = wp.vec4i(0, 1, 2, 3)
    for k in range(m):
        angle[k] = wp.atan2(ys[k], xs[k])
    for a in range(1, m):  # insertion sort of at most four
        b = a
        while b > 0 and angle[order[b - 1]] > angle[order[b]]:
            swap = order[b - 1]
            order[b - 1] = order[b]
            order[b] = swap
            b -= 1
    integral = float(0.0)
    area = float(0.0)
    far = float(0.0)
    for k in range(m):
        a = order[k]
        b = order[(k + 1) % m]
        integral += triangle_radius_integral(xs[a], ys[a], xs[b], ys[b])
        area += 0.5 * (xs[a] * ys[b] - ys[a] * xs[b])
        far = wp.max(far, wp.sqrt(xs[k] * xs[k] + ys[k] * ys[k]))
    mean = float(0.0)
    if area > 0.0:
        mean = integral / area
    return wp.vec3(mean, area, far)


@wp.func
def pair_patch(
    p: int,
    count: int,
    # Contacts in
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_normal_impulse: wp.array(dtype=float),
) -> wp.vec4:
    """(centre in the world, s) of the patch of pair p's points (at most four, in the world as stored by the last pass or
    refresh, which may have turned since the bodies' reference poses: so no body's axes) as the
    polygon they span in the contact plane, about their centroid; weighted by the impulses they
    hold now (point_weight).  Where they span no area (an edge on a face) it is the segment
    between the farthest two: r_e = half its half length."""
    if count < 2:
        return NO_TWIST
    n = pair_normal[p]
    t1 = wp.normalize(wp.cross(n, wp.where(wp.abs(n[0]) < 0.9, wp.vec3(1.0, 0.0, 0.0), wp.vec3(0.0, 1.0, 0.0))))
    t2 = wp.cross(n, t1)
    origin = pair_point[p * POINTS]
    xs = wp.vec4(0.0)
    ys = wp.vec4(0.0)
    ws = wp.vec4(0.0)
    m = int(0)
    cold = int(0)
    floor = float(0.0)
    for attempt in range(2):
        cold = attempt
        if attempt == 1:
            deepest = float(-1.0e30)
            size = float(0.0)
            for k in range(count):
                deepest = wp.max(deepest, pair_depth[p * POINTS + k])
                size = wp.max(size, wp.length(pair_point[p * POINTS + k] - origin))
            floor = cold_floor(deepest, size)
        for k in range(count):
            slot = p * POINTS + k
            weight = point_weight(cold, floor, pair_normal_impulse[slot], pair_depth[slot])
            if weight > 0.0:
                offset = pair_point[slot] - origin
                xs[m] = wp.dot(offset, t1)
                ys[m] = wp.dot(offset, t2)
                ws[m] = weight
                m += 1
        if m > 0:
            break
    if m < 2:
        return NO_TWIST
    cx = float(0.0)
    cy = float(0.0)
    for k in range(m):
        cx += xs[k] / float(m)
        cy += ys[k] / float(m)
    for k in range(m):
        xs[k] = xs[k] - cx
        ys[k] = ys[k] - cy
    polygon = quad_mean_radius(xs, ys, m)
    r_e = polygon[0]
    if polygon[1] <= 1.0e-6 * polygon[2] * polygon[2]:
        # a segment: along its widest direction, about its middle
        ux = float(1.0)
        uy = float(0.0)
        for k in range(m):
            if wp.sqrt(xs[k] * xs[k] + ys[k] * ys[k]) >= polygon[2] and polygon[2] > 0.0:
                ux = xs[k] / polygon[2]
                uy = ys[k] / polygon[2]
        lo = float(1.0e30)
        hi = float(-1.0e30)
        for k in range(m):
            along = xs[k] * ux + ys[k] * uy
            lo = wp.min(lo, along)
            hi = wp.max(hi, along)
        middle = 0.5 * (lo + hi)
        cx += middle * ux
        cy += middle * uy
        for k in range(m):
            xs[k] = xs[k] - middle * ux
            ys[k] = ys[k] - middle * uy
        r_e = 0.25 * (hi - lo)
    spread = float(0.0)
    weight = float(0.0)
    for k in range(m):
        spread += ws[k] * wp.sqrt(xs[k] * xs[k] + ys[k] * ys[k])
        weight += ws[k]
    if spread <= 0.0:
        return NO_TWIST
    centre = origin + cx * t1 + cy * t2
    return wp.vec4(centre[0], centre[1], centre[2], wp.clamp(r_e * weight / spread, 0.0, 1.0))
