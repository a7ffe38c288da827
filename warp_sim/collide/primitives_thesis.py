"""The thesis's box-box test (SEED.md 4), kept as a baseline to measure against.

Vertex-face: every vertex of one box against every face of the other (over the face when all
edge-to-vertex dot products are non-negative; a contact when its distance to the face plane is
under the threshold).  Edge-edge: closest points of two edge lines from a 2x2 linear system,
rejected outside either segment.  Conventions as in primitives.py.
"""

import warp as wp

from .primitives import (
    Manifold,
    manifold_empty,
    unit_axis,
    mat_column,
    BOX_EDGE_ID,
    BOX_VERTEX_ID,
    BOX_FEATURE_COUNT,
    mat43,
)

# 8 vertices x 6 faces, both ways round, then 12 x 12 edge pairs: too many to unroll.
THESIS_TEST_COUNT = 8 * 6 * 2 + 12 * 12


@wp.func
def box_vertex(pos: wp.vec3, rot: wp.mat33, half: wp.vec3, index: int) -> wp.vec3:
    """Vertex 0..7 (= box_feature_id - 18): bit k set puts it on the minus side of axis k."""
    signs = wp.vec3(1.0 - 2.0 * float(index % 2), 1.0 - 2.0 * float((index // 2) % 2),
                    1.0 - 2.0 * float((index // 4) % 2))
    return pos + rot * wp.cw_mul(signs, half)


@wp.func
def box_edge(pos: wp.vec3, rot: wp.mat33, half: wp.vec3, index: int):
    """Edge 0..11 (= box_feature_id - 6) as (start, start-to-end vector): along axis
    index // 4, on the minus side of axis + 1 if bit 0 is set, of axis + 2 if bit 1 is."""
    axis = index // 4
    signs = (1.0 - 2.0 * float(index % 2)) * unit_axis((axis + 1) % 3) \
        + (1.0 - 2.0 * float((index // 2) % 2)) * unit_axis((axis + 2) % 3) - unit_axis(axis)
    return pos + rot * wp.cw_mul(signs, half), 2.0 * half[axis] * mat_column(rot, axis)


@wp.func
def thesis_vertex_face(vertex: wp.vec3, box_pos: wp.vec3, box_rot: wp.mat33, box_half: wp.vec3, face: int,
                       margin: float):
    """(hit, signed distance, outward normal) of a vertex against face 0..5 of a box.

    The thesis walks the face's four edges e_k (from corners c_k, running round the face) and
    calls the vertex over the face when every e_k . (v - c_k) >= 0.  For a rectangle those four
    dot products are the slab tests |x| <= h1, |y| <= h2 in the face's own frame, computed here.
    Contact when the distance to the face plane is under the threshold: |distance| < margin.
    """
    axis = face // 2
    side = 1.0 - 2.0 * float(face % 2)
    local = wp.transpose(box_rot) * (vertex - box_pos)
    k1 = (axis + 1) % 3
    k2 = (axis + 2) % 3
    over = wp.abs(local[k1]) <= box_half[k1] and wp.abs(local[k2]) <= box_half[k2]
    distance = side * local[axis] - box_half[axis]
    return over and wp.abs(distance) < margin, distance, side * mat_column(box_rot, axis)


@wp.func
def thesis_edge_edge(start_a: wp.vec3, dir_a: wp.vec3, start_b: wp.vec3, dir_b: wp.vec3, delta: wp.vec3,
                     margin: float):
    """(hit, depth, normal, point) of two edges by the thesis's 2 x 2 system.

    Minimising |r + s da - t db|^2 (r = start_a - start_b) gives
        [a  -b] [s]   [-d]        a = da.da, b = da.db, c = db.db,
        [b  -c] [t] = [-e],       d = da.r,  e = db.r,
    so s = (b e - c d) / (a c - b^2), t = (a e - b d) / (a c - b^2).  Parallel edges make it
    singular and are skipped; closest points outside either segment are rejected.  The normal
    is the difference of the points, turned to point from B to A by the centre offset
    ``delta``; if it had to be turned the edges have passed through each other and the
    distance counts as penetration.  Touching edges have no difference; the edge cross
    product stands in.
    """
    r = start_a - start_b
    a = wp.dot(dir_a, dir_a)
    b = wp.dot(dir_a, dir_b)
    c = wp.dot(dir_b, dir_b)
    det = a * c - b * b
    hit = False
    depth = float(0.0)
    normal = wp.vec3(0.0, 1.0, 0.0)
    point = wp.vec3(0.0)
    if det > 1.0e-6 * a * c:
        s = (b * wp.dot(dir_b, r) - c * wp.dot(dir_a, r)) / det
        t = (a * wp.dot(dir_b, r) - b * wp.dot(dir_a, r)) / det
        if s >= 0.0 and s <= 1.0 and t >= 0.0 and t <= 1.0:
            diff = (start_a + s * dir_a) - (start_b + t * dir_b)
            distance = wp.length(diff)
            if distance < margin:
                hit = True
                point = start_b + t * dir_b + 0.5 * diff
                normal = wp.normalize(wp.cross(dir_a, dir_b))
                if distance > 1.0e-9:
                    normal = diff / distance
                depth = -distance
                if wp.dot(normal, delta) < 0.0:
                    normal = -normal
                    depth = distance
    return hit, depth, normal, point


@wp.func
def collide_box_box_thesis(pos_a: wp.vec3, rot_a: wp.mat33, half_a: wp.vec3, pos_b: wp.vec3, rot_b: wp.mat33,
                           half_b: wp.vec3, margin: float) -> Manifold:
    """Box A against box B by the thesis's tests: vertex-face both ways round, and edge-edge.

    Every test whose distance is under the threshold (``margin``) gives a candidate with its
    own normal; the four deepest candidates are kept.  A manifold has one normal, so it takes
    the deepest candidate's and drops kept candidates whose normal differs.  Feature ids follow
    the module's box-box scheme (vertex-face, edge-edge), so they compare with collide_box_box.

    Known weaknesses (why collide_box_box exists; tests/test_primitives.py shows them):
    * Deep penetration picks wrong faces.  The tests only see features within the threshold
      band of each other: a box pushed in deeper than the threshold loses its true face
      contacts, and whatever vertices happen to lie near a side plane answer with side-face
      normals instead.  The thesis relied on small time steps to keep penetration shallow.
    * Edge-edge normal sign: the difference of the closest points has no sign of its own (it
      flips when the edges pass through each other); it is oriented here by the centre offset,
      which is wrong for off-centre deep contacts.  Exactly touching edges have no difference.
    * Coincident edges (equal boxes stacked flush) lie on each other's side planes, so resting
      stacks also produce side-face candidates of depth ~0.
    * 240 tests per pair, against 15 axes and one clip for the separating-axis method.
    """
    delta = pos_a - pos_b
    zero = wp.vec3(0.0)
    count = int(0)
    points = mat43()
    normals = mat43()
    depths = wp.vec4(0.0)
    features = wp.vec4i(-1, -1, -1, -1)
    for test in range(THESIS_TEST_COUNT):
        hit = False
        distance = float(0.0)
        outward = wp.vec3(0.0)
        depth = float(0.0)
        normal = wp.vec3(0.0)
        point = wp.vec3(0.0)
        feature = int(0)
        vertex = wp.vec3(0.0)
        if test < 96:
            # Vertex of B over a face of A (A moves against the face's outward normal), then
            # vertex of A over a face of B.
            vertex_index = (test % 48) // 6
            face = test % 6
            if test < 48:
                vertex = box_vertex(zero, rot_b, half_b, vertex_index)
                hit, distance, outward = thesis_vertex_face(vertex, delta, rot_a, half_a, face, margin)
                normal = -outward
                feature = BOX_FEATURE_COUNT * face + BOX_VERTEX_ID + vertex_index
            else:
                vertex = box_vertex(delta, rot_a, half_a, vertex_index)
                hit, distance, outward = thesis_vertex_face(vertex, zero, rot_b, half_b, face, margin)
                normal = outward
                feature = BOX_FEATURE_COUNT * (BOX_VERTEX_ID + vertex_index) + face
            depth = -distance
            point = vertex - (0.5 * distance) * outward
        else:
            index_a = (test - 96) // 12
            index_b = (test - 96) % 12
            start_a, dir_a = box_edge(delta, rot_a, half_a, index_a)
            start_b, dir_b = box_edge(zero, rot_b, half_b, index_b)
            hit, depth, normal, point = thesis_edge_edge(start_a, dir_a, start_b, dir_b, delta, margin)
            feature = BOX_FEATURE_COUNT * (BOX_EDGE_ID + index_a) + BOX_EDGE_ID + index_b
        if hit:
            # Keep the four deepest: fill the free slots, then replace the shallowest.
            slot = count
            if count == 4:
                slot = 0
                for n in range(1, 4):
                    if depths[n] < depths[slot]:
                        slot = n
            if count < 4 or depth > depths[slot]:
                points[slot] = point
                normals[slot] = normal
                depths[slot] = depth
                features[slot] = feature
                count = wp.min(count + 1, 4)

    m = manifold_empty()
    if count == 0:
        return m
    deepest = int(0)
    for n in range(1, count):
        if depths[n] > depths[deepest]:
            deepest = n
    m.normal = normals[deepest]
    for n in range(count):
        if wp.dot(normals[n], m.normal) > 0.9999:
            m.point[m.count] = pos_b + points[n]
            m.depth[m.count] = depths[n]
            m.feature[m.count] = features[n]
            m.count = m.count + 1
    return m


# ----------------------------------------------------------------------------------------------
# Dispatch
