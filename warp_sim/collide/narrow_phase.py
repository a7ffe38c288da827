"""Body-body narrow phase over the broad phase's sorted pairs, and impulse carry-over.

``collide_pairs`` runs one thread per candidate pair (i, j), i < j, calls the pure
``collide_pair`` with A = body i and B = body j, and writes the manifold into the pair's four
point slots; the normal points from j into i.

``swept_reach`` grows each bounding radius by the distance the body can travel before the
next collision pass, for the broad phase and the speculative margin.

``carry_pair_impulses`` gives each new point the accumulated impulses of last substep's point
with the same feature id in the same pair (warm starting).  Last substep's pairs are sorted by
(i, j), so the pair is found by binary search.  ``store_pairs`` copies this substep's pairs,
features and impulses into the ``prev_*`` arrays once the solve is done.
"""

import warp as wp

from .contact_patch import NO_TWIST, pair_patch
from .manifold import POINTS
from .primitives import collide_pair, mat43, reference_body

wp.set_module_options({"enable_backward": False})


@wp.kernel
def collide_pairs(
    tid_offset: int,
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_size: wp.array(dtype=wp.vec3),
    body_bound_radius: wp.array(dtype=float),
    body_covered_faces: wp.array(dtype=wp.int32),
    body_inv_mass: wp.array(dtype=float),
    # Settings
    margin: float,
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    # Broad phase in
    body_reach: wp.array(dtype=float),
    broad_pair_body: wp.array(dtype=wp.vec2i),
    broad_pair_count: wp.array(dtype=wp.int32),
    # Out
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_feature: wp.array(dtype=wp.int32),
    pair_refresh_count: wp.array(dtype=wp.int32),
):
    p = wp.tid() + tid_offset
    if p >= broad_pair_count[0]:
        return
    pair_refresh_count[p] = 0
    ij = broad_pair_body[p]
    i = ij[0]
    j = ij[1]
    # each body's sweep (reach - bound radius) widens the speculative margin, see swept_reach
    pair_margin = margin + (body_reach[i] - body_bound_radius[i]) + (body_reach[j] - body_bound_radius[j])
    m = collide_pair(body_shape[i], body_pos[i], body_rot[i], body_size[i], body_covered_faces[i],
                     body_shape[j], body_pos[j], body_rot[j], body_size[j], body_covered_faces[j], pair_margin,
                     reference_body(body_inv_mass[i], body_inv_mass[j]))
    pair_body[p] = ij
    pair_point_count[p] = m.count
    pair_normal[p] = m.normal
    for k in range(POINTS):
        slot = p * POINTS + k
        pair_point[slot] = wp.vec3(m.point[k, 0], m.point[k, 1], m.point[k, 2])
        pair_depth[slot] = m.depth[k]
        pair_feature[slot] = m.feature[k]


@wp.func
def swept_radius(r: float, speed: float, spin: float, sweep_time: float, gravity_magnitude: float,
                 inv_mass: float) -> float:
    """Bounding radius r grown by how far a surface point can move in ``sweep_time``:
    T (|v| + |w| r) + T^2 |g| for a dynamic body (``spin`` = |w| r).  The gravity term bounds what
    the substeps' kicks add: n substeps of h = T / n move a body g h^2 n (n + 1) / 2 <= g T^2
    further than |v| T (without it a sphere falling at g = 100, dt = 1/30 sank 16.7 cm into a box)."""
    fall = float(0.0)
    if inv_mass > 0.0:
        fall = sweep_time * sweep_time * gravity_magnitude
    return r + sweep_time * (speed + spin) + fall


@wp.func
def body_omega(i: int, body_inv_inertia: wp.array(dtype=wp.vec3), body_rot: wp.array(dtype=wp.mat33),
               body_angmom: wp.array(dtype=wp.vec3)) -> wp.vec3:
    return wp.cw_mul(body_inv_inertia[i], wp.transpose(body_rot[i]) * body_angmom[i])


@wp.func
def reach_needed(
    i: int,
    body_bound_radius: wp.array(dtype=float),
    body_inv_mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    sweep_time: float,
    gravity_magnitude: float,
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
) -> float:
    """swept_radius of body i with the state's velocities."""
    r = body_bound_radius[i]
    omega = body_omega(i, body_inv_inertia, body_rot, body_angmom)
    return swept_radius(r, wp.length(body_vel[i]), wp.length(omega) * r, sweep_time, gravity_magnitude,
                        body_inv_mass[i])


@wp.kernel
def swept_reach(
    tid_offset: int,
    # Model
    body_bound_radius: wp.array(dtype=float),
    body_inv_mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    # Settings
    sweep_time: float,
    gravity_magnitude: float,
    # State in
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
    # Out
    body_reach: wp.array(dtype=float),
):
    """Each body's reach until the next collision pass (reach_needed).  Two bodies whose grown
    spheres do not meet cannot touch before then, so pairs found with these radii (and
    speculative points kept within the summed growth) miss no contact the solver needs, however
    few times per step they are found, as long as no body speeds up beyond its reach within the
    step (reach_outrun)."""
    i = wp.tid() + tid_offset
    body_reach[i] = reach_needed(i, body_bound_radius, body_inv_mass, body_inv_inertia, sweep_time,
                                 gravity_magnitude, body_rot, body_vel, body_angmom)


@wp.func
def reach_needed_now(
    i: int,
    body_bound_radius: wp.array(dtype=float),
    body_inv_mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    remaining_time: float,
    gravity_magnitude: float,
    use_solver_velocity: int,
    solver_ref_pos: wp.array(dtype=wp.vec3),
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    with_spin: int,
) -> float:
    """Mid-step: the way the centre has come since the reference pose (a bounding sphere about
    the centre covers any turn) plus reach_needed over the time left.  ``use_solver_velocity``:
    the velocities are the impact stage's (solver_v; solver_w the angular velocity), not the
    state's.  ``with_spin`` 0 leaves out the |w| r T term: the centre's motion alone decides
    which bounding spheres can meet."""
    r = body_bound_radius[i]
    v = body_vel[i]
    omega = body_omega(i, body_inv_inertia, body_rot, body_angmom)
    if use_solver_velocity != 0:
        v = solver_v[i]
        omega = solver_w[i]
    spin = wp.where(with_spin != 0, wp.length(omega) * r, 0.0)
    return swept_radius(r, wp.length(v), spin, remaining_time, gravity_magnitude, body_inv_mass[i]) + wp.length(
        body_pos[i] - solver_ref_pos[i])


@wp.kernel
def swept_reach_from_reference(
    tid_offset: int,
    # Model
    body_bound_radius: wp.array(dtype=float),
    body_inv_mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    # Settings
    remaining_time: float,
    gravity_magnitude: float,
    use_solver_velocity: int,
    # Solver in
    solver_ref_pos: wp.array(dtype=wp.vec3),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
    # Solver in
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    # Out
    body_reach: wp.array(dtype=float),
):
    """The reach of a pass run mid-step at the step's reference pose (reach_needed_now)."""
    i = wp.tid() + tid_offset
    body_reach[i] = reach_needed_now(i, body_bound_radius, body_inv_mass, body_inv_inertia, remaining_time,
                                     gravity_magnitude, use_solver_velocity, solver_ref_pos, body_pos, body_rot,
                                     body_vel, body_angmom, solver_v, solver_w, 1)


@wp.kernel
def reach_outrun(
    # Model
    body_bound_radius: wp.array(dtype=float),
    body_inv_mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    # Settings
    remaining_time: float,
    gravity_magnitude: float,
    margin: float,
    use_solver_velocity: int,
    # Solver in
    solver_ref_pos: wp.array(dtype=wp.vec3),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
    # Solver in
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    # In (the pass's reaches)
    body_reach: wp.array(dtype=float),
    # Out
    outrun: wp.array(dtype=wp.int32),
):
    """Raise ``outrun`` when a dynamic body, since the pass that found the pairs at the reference
    pose, has sped up beyond the reach that pass gave it (a resting ball struck by a fast one):
    its contacts later in the step may lie outside every pair found.  A pair is found while
    |x_i - x_j| < reach_i + reach_j + margin (and its points kept within the same sum, see
    collide_pairs), and the bodies can touch only if |x_i - x_j| < need_i + need_j: so while no
    body needs more than its reach + margin / 2, every contact the rest of the step can make is
    in a pair already found.  Only the centre's motion is checked: a bounding sphere about the
    centre holds the body at every orientation, so a spin picked up mid-step misses no pair; it
    can only swing a corner in by up to h |w| r before the next pass, a depth, not a tunnel
    (checking spin too ran the pass in 24 of 90 substeps of a 10k rain).  atomic_max of 1: the flag's value does not depend on which threads
    raise it, or in what order."""
    i = wp.tid()
    if body_inv_mass[i] == 0.0:
        return
    need = reach_needed_now(i, body_bound_radius, body_inv_mass, body_inv_inertia, remaining_time, gravity_magnitude,
                            use_solver_velocity, solver_ref_pos, body_pos, body_rot, body_vel, body_angmom, solver_v,
                            solver_w, 0)
    if need > body_reach[i] + 0.5 * margin:
        wp.atomic_max(outrun, 0, 1)


@wp.func
def find_pair(pairs: wp.array(dtype=wp.vec2i), count: int, key: wp.vec2i) -> int:
    """Index of ``key`` in the (i, j)-sorted ``pairs[:count]``, or -1."""
    lo = int(0)
    hi = count
    while lo < hi:
        mid = (lo + hi) // 2
        q = pairs[mid]
        if q[0] < key[0] or (q[0] == key[0] and q[1] < key[1]):
            lo = mid + 1
        else:
            hi = mid
    if lo < count:
        q = pairs[lo]
        if q[0] == key[0] and q[1] == key[1]:
            return lo
    return -1


# cos 5 degrees: how far a pair's normal may turn between passes for its points to be matched by place
SAME_FACE_COS = wp.constant(0.9962)


@wp.func
def smallest_spacing(q: int, old_count: int, prev_pair_point: wp.array(dtype=wp.vec3)) -> float:
    spacing = float(1.0e30)
    for a in range(old_count):
        for b in range(a + 1, old_count):
            spacing = wp.min(spacing, wp.length(prev_pair_point[q * POINTS + a] - prev_pair_point[q * POINTS + b]))
    return spacing


@wp.func
def closest_unclaimed(point: wp.vec3, q: int, old_count: int, claimed: int, spacing: float,
                      prev_pair_point: wp.array(dtype=wp.vec3)) -> int:
    """Last pass's point of pair q nearest to ``point`` that no other new point has taken, if it
    lies within half the smallest ``spacing`` of last pass's points (so it is the only candidate),
    else -1."""
    best = int(-1)
    best_distance = 0.5 * spacing
    for kk in range(old_count):
        if (claimed & (1 << kk)) == 0:
            distance = wp.length(point - prev_pair_point[q * POINTS + kk])
            if distance < best_distance:
                best = kk
                best_distance = distance
    return best


@wp.func
def match_old_points(count: int, feature: wp.vec4i, point: mat43, normal: wp.vec3, q: int, old_count: int,
                     prev_pair_feature: wp.array(dtype=wp.int32), prev_pair_normal: wp.array(dtype=wp.vec3),
                     prev_pair_point: wp.array(dtype=wp.vec3)) -> wp.vec4i:
    """For each of ``count`` new points of a pair, the old point of pair q (``old_count`` of
    them) whose impulses it takes, or -1: the same feature id first, then the nearest unclaimed
    old point (``closest_unclaimed``) if the pair's normal has turned by less than SAME_FACE_COS
    (the same faces still meet: a load carried along a normal that turned further would push
    the wrong way).  No old point is taken twice."""
    claimed = int(0)
    source = wp.vec4i(-1, -1, -1, -1)
    for k in range(count):
        for kk in range(old_count):
            if prev_pair_feature[q * POINTS + kk] == feature[k] and (claimed & (1 << kk)) == 0 and source[k] < 0:
                source[k] = kk
                claimed = claimed | (1 << kk)
    same_face = int(0)
    if old_count > 1:  # then q >= 0
        same_face = wp.where(wp.dot(normal, prev_pair_normal[q]) > SAME_FACE_COS, 1, 0)
    if same_face != 0:
        spacing = smallest_spacing(q, old_count, prev_pair_point)
        for k in range(count):
            if source[k] < 0:
                kk = closest_unclaimed(wp.vec3(point[k, 0], point[k, 1], point[k, 2]), q, old_count, claimed, spacing,
                                       prev_pair_point)
                if kk >= 0:
                    source[k] = kk
                    claimed = claimed | (1 << kk)
    return source


@wp.kernel
def carry_pair_impulses(
    tid_offset: int,
    # Contacts in (last pass)
    prev_pair_count: wp.array(dtype=wp.int32),
    prev_pair_body: wp.array(dtype=wp.vec2i),
    prev_pair_point_count: wp.array(dtype=wp.int32),
    prev_pair_feature: wp.array(dtype=wp.int32),
    prev_pair_normal: wp.array(dtype=wp.vec3),
    prev_pair_point: wp.array(dtype=wp.vec3),
    prev_pair_normal_impulse: wp.array(dtype=float),
    prev_pair_tangent_impulse: wp.array(dtype=wp.vec3),
    # Contacts in (this pass)
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_feature: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    measure_patch: int,
    # Out
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    pair_twist: wp.array(dtype=wp.vec4),
):
    """Each new point takes the impulses of last pass's point that ``match_old_points`` gives it,
    and the pair's patch is measured from them (where its friction acts until the next pass or
    refresh: contact_patch.py).

    Why the fallback: two equal boxes resting face on face have their incident corners exactly on
    the reference face's side planes, so a rounding-level turn decides whether a point is a corner
    (one id) or a clipped edge crossing (another id) of the same place.  In a 10-cube column about
    3 % of the pair passes changed ids that way; each change dropped a loaded point's impulse to
    zero, and the stack jolted and drifted sideways."""
    p = wp.tid() + tid_offset
    if p >= pair_count[0]:
        return
    q = find_pair(prev_pair_body, prev_pair_count[0], pair_body[p])
    count = pair_point_count[p]
    old_count = int(0)
    if q >= 0:
        old_count = prev_pair_point_count[q]
    feature = wp.vec4i(-1, -1, -1, -1)
    point = mat43()
    for k in range(count):
        feature[k] = pair_feature[p * POINTS + k]
        point[k] = pair_point[p * POINTS + k]
    source = match_old_points(count, feature, point, pair_normal[p], q, old_count, prev_pair_feature,
                              prev_pair_normal, prev_pair_point)
    for k in range(POINTS):
        slot = p * POINTS + k
        normal_impulse = float(0.0)
        tangent_impulse = wp.vec3(0.0)
        if k < count and source[k] >= 0:
            old = q * POINTS + source[k]
            normal_impulse = prev_pair_normal_impulse[old]
            tangent_impulse = prev_pair_tangent_impulse[old]
        pair_normal_impulse[slot] = normal_impulse
        pair_tangent_impulse[slot] = tangent_impulse
    twist = NO_TWIST
    if measure_patch != 0:
        twist = pair_patch(p, count, pair_normal, pair_point, pair_depth, pair_normal_impulse)
    pair_twist[p] = twist


@wp.kernel
def store_pairs(
    tid_offset: int,
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_feature: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    # Out
    prev_pair_count: wp.array(dtype=wp.int32),
    prev_pair_body: wp.array(dtype=wp.vec2i),
    prev_pair_point_count: wp.array(dtype=wp.int32),
    prev_pair_feature: wp.array(dtype=wp.int32),
    prev_pair_normal: wp.array(dtype=wp.vec3),
    prev_pair_point: wp.array(dtype=wp.vec3),
    prev_pair_normal_impulse: wp.array(dtype=float),
    prev_pair_tangent_impulse: wp.array(dtype=wp.vec3),
):
    p = wp.tid() + tid_offset
    count = pair_count[0]
    if p == 0:
        prev_pair_count[0] = count
    if p >= count:
        return
    prev_pair_body[p] = pair_body[p]
    prev_pair_point_count[p] = pair_point_count[p]
    prev_pair_normal[p] = pair_normal[p]
    for k in range(POINTS):
        slot = p * POINTS + k
        prev_pair_feature[slot] = pair_feature[slot]
        prev_pair_point[slot] = pair_point[slot]
        prev_pair_normal_impulse[slot] = pair_normal_impulse[slot]
        prev_pair_tangent_impulse[slot] = pair_tangent_impulse[slot]
