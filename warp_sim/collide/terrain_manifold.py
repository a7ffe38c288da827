"""A box's terrain contacts reduced to at most four points, after detection on all checkpoints.

Detection runs on every checkpoint (26 on a box by default), so a hill under a face or an edge
is found; but a box resting flat touches with 9 of them (4 corners, 4 edge midpoints, the face
centre), and every extra point costs a row in each solver sweep without adding support: a
rigid body needs three non-collinear points to rest and a fourth to keep that support when it
rocks.  Which four (the selection of Gregorius's and Jolt's manifold reduction, in the contact
plane of the deepest point):

    1. the deepest point, so the solver always sees the worst penetration; depth ties (a flat
       face: all points within float noise) go to the point farthest from the centre of mass
       (a corner), which gives the widest support;
    2. the point farthest from 1;
    3. and 4. the points farthest from line 1-2 on either side (largest triangle areas), so the
       four span the largest quadrilateral the points allow.

Points kept last step win near-ties (a fraction of a millimetre, or 1 % in the geometric
choices), so a resting box keeps the same four slots and their warm-start impulses instead of
flickering between equal candidates.  Dropped slots are deactivated and lose their impulses.
Bodies with at most four active points (every sphere) are left as they are.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

MANIFOLD_POINTS = 4
# depth credit per metre of lever arm when choosing point 1: a corner 0.43 m out wins a tie
# against the face centre within 0.43 mm (float32 depth noise on a tilted face is ~1e-6 m)
LEVER_TIE = 1.0e-3
KEEP_DEPTH = 1.0e-4  # [m] credit for a point kept last step, in the depth ranking
KEEP_FACTOR = 1.01  # the same in the geometric rankings


@wp.func
def in_plane(d: wp.vec3, n: wp.vec3) -> wp.vec3:
    return d - wp.dot(d, n) * n


@wp.kernel
def reduce_terrain_manifold(
    tid_offset: int,
    # Model
    body_checkpoint_start: wp.array(dtype=wp.int32),
    body_checkpoint_count: wp.array(dtype=wp.int32),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # Contacts in/out
    terrain_contact_active: wp.array(dtype=wp.int32),
    terrain_contact_point: wp.array(dtype=wp.vec3),
    terrain_contact_normal: wp.array(dtype=wp.vec3),
    terrain_contact_depth: wp.array(dtype=float),
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
):
    i = wp.tid() + tid_offset
    count = body_checkpoint_count[i]
    if count <= MANIFOLD_POINTS:
        return
    start = body_checkpoint_start[i]
    x = body_pos[i]

    active = int(0)
    first = int(-1)
    best = float(-1.0e30)
    for s in range(start, start + count):
        if terrain_contact_active[s] != 0:
            active += 1
            score = terrain_contact_depth[s] + LEVER_TIE * wp.length(terrain_contact_point[s] - x)
            if terrain_contact_normal_impulse[s] > 0.0:
                score += KEEP_DEPTH
            if score > best:
                best = score
                first = s
    if active <= MANIFOLD_POINTS:
        return

    n = terrain_contact_normal[first]
    p1 = terrain_contact_point[first]
    second = int(-1)
    best = float(-1.0)
    for s in range(start, start + count):
        if terrain_contact_active[s] != 0 and s != first:
            d = in_plane(terrain_contact_point[s] - p1, n)
            score = wp.dot(d, d)
            if terrain_contact_normal_impulse[s] > 0.0:
                score *= KEEP_FACTOR
            if score > best:
                best = score
                second = s

    edge = in_plane(terrain_contact_point[second] - p1, n)
    third = int(-1)
    fourth = int(-1)
    best_left = float(0.0)
    best_right = float(0.0)
    for s in range(start, start + count):
        if terrain_contact_active[s] != 0 and s != first and s != second:
            area = wp.dot(wp.cross(edge, in_plane(terrain_contact_point[s] - p1, n)), n)
            if terrain_contact_normal_impulse[s] > 0.0:
                area *= KEEP_FACTOR
            if area > best_left:
                best_left = area
                third = s
            if -area > best_right:
                best_right = -area
                fourth = s

    for s in range(start, start + count):
        if terrain_contact_active[s] != 0 and s != first and s != second and s != third and s != fourth:
            terrain_contact_active[s] = 0
            terrain_contact_normal_impulse[s] = 0.0
            terrain_contact_tangent_impulse[s] = wp.vec3(0.0)
