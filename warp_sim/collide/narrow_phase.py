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

from .primitives import collide_pair

wp.set_module_options({"enable_backward": False})

POINTS = 4


@wp.kernel
def collide_pairs(
    tid_offset: int,
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_size: wp.array(dtype=wp.vec3),
    body_bound_radius: wp.array(dtype=float),
    margin: float,
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    body_reach: wp.array(dtype=float),
    # Broad phase in
    broad_pair_body: wp.array(dtype=wp.vec2i),
    broad_pair_count: wp.array(dtype=wp.int32),
    # Out
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_feature: wp.array(dtype=wp.int32),
):
    p = wp.tid() + tid_offset
    if p >= broad_pair_count[0]:
        return
    ij = broad_pair_body[p]
    i = ij[0]
    j = ij[1]
    # each body's sweep (reach - bound radius) widens the speculative margin, see swept_reach
    pair_margin = margin + (body_reach[i] - body_bound_radius[i]) + (body_reach[j] - body_bound_radius[j])
    m = collide_pair(body_shape[i], body_pos[i], body_rot[i], body_size[i],
                     body_shape[j], body_pos[j], body_rot[j], body_size[j], pair_margin)
    pair_body[p] = ij
    pair_point_count[p] = m.count
    pair_normal[p] = m.normal
    for k in range(POINTS):
        slot = p * POINTS + k
        pair_point[slot] = wp.vec3(m.point[k, 0], m.point[k, 1], m.point[k, 2])
        pair_depth[slot] = m.depth[k]
        pair_feature[slot] = m.feature[k]


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
    """Bounding radius grown by how far a surface point can move before the next collision pass:
    T (|v| + |w| r) + T^2 |g| for a dynamic body (T = sweep_time).  The gravity term bounds what the
    substeps' kicks add: n substeps of h = T / n move a body g h^2 n (n + 1) / 2 <= g T^2 further
    than |v| T (without it a sphere falling at g = 100, dt = 1/30 sank 16.7 cm into a box).  Two bodies whose grown spheres do not meet cannot touch before
    then, so pairs found with these radii (and speculative points kept within the summed
    growth) miss no contact the solver needs, however few times per step they are found."""
    i = wp.tid() + tid_offset
    r = body_bound_radius[i]
    rot = body_rot[i]
    local_angmom = wp.transpose(rot) * body_angmom[i]
    omega = wp.cw_mul(body_inv_inertia[i], local_angmom)
    fall = float(0.0)
    if body_inv_mass[i] > 0.0:
        fall = sweep_time * sweep_time * gravity_magnitude
    body_reach[i] = r + sweep_time * (wp.length(body_vel[i]) + wp.length(omega) * r) + fall


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


@wp.kernel
def carry_pair_impulses(
    tid_offset: int,
    # Contacts in (last substep)
    prev_pair_count: wp.array(dtype=wp.int32),
    prev_pair_body: wp.array(dtype=wp.vec2i),
    prev_pair_point_count: wp.array(dtype=wp.int32),
    prev_pair_feature: wp.array(dtype=wp.int32),
    prev_pair_normal_impulse: wp.array(dtype=float),
    prev_pair_tangent_impulse: wp.array(dtype=wp.vec3),
    # Contacts in (this substep)
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_feature: wp.array(dtype=wp.int32),
    # Out
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
):
    p = wp.tid() + tid_offset
    if p >= pair_count[0]:
        return
    q = find_pair(prev_pair_body, prev_pair_count[0], pair_body[p])
    for k in range(POINTS):
        slot = p * POINTS + k
        normal_impulse = float(0.0)
        tangent_impulse = wp.vec3(0.0)
        if q >= 0 and k < pair_point_count[p]:
            feature = pair_feature[slot]
            for kk in range(prev_pair_point_count[q]):
                old = q * POINTS + kk
                if prev_pair_feature[old] == feature:
                    normal_impulse = prev_pair_normal_impulse[old]
                    tangent_impulse = prev_pair_tangent_impulse[old]
        pair_normal_impulse[slot] = normal_impulse
        pair_tangent_impulse[slot] = tangent_impulse


@wp.kernel
def store_pairs(
    tid_offset: int,
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_feature: wp.array(dtype=wp.int32),
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    # Out
    prev_pair_count: wp.array(dtype=wp.int32),
    prev_pair_body: wp.array(dtype=wp.vec2i),
    prev_pair_point_count: wp.array(dtype=wp.int32),
    prev_pair_feature: wp.array(dtype=wp.int32),
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
    for k in range(POINTS):
        slot = p * POINTS + k
        prev_pair_feature[slot] = pair_feature[slot]
        prev_pair_normal_impulse[slot] = pair_normal_impulse[slot]
        prev_pair_tangent_impulse[slot] = pair_tangent_impulse[slot]
