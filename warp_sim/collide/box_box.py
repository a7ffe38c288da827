"""Box against box by the separating-axis test, then a clipped face, an edge, or (apart, with
no face overlap) the nearest vertex or edge points.  Conventions: manifold.py."""

import warp as wp

from .covered_faces import points_through_covered
from .manifold import (
    BOX_FEATURE_COUNT,
    EDGE_AXIS_MIN_LENGTH,
    EDGE_PREFERENCE_ABSOLUTE,
    EDGE_PREFERENCE_RELATIVE,
    NEAREST_TOLERANCE,
    Manifold,
    box_feature_id,
    manifold_empty,
    manifold_single,
    mat83,
    mat_column,
    sign_of,
    unit_axis,
    vec8i,
)

# ----------------------------------------------------------------------------------------------
# Box-box by separating axes


@wp.func
def box_support_radius(rot: wp.mat33, half: wp.vec3, axis: wp.vec3) -> float:
    """Half-width of the box's projection on a unit axis: sum_k h_k |r_k . axis|."""
    local = wp.transpose(rot) * axis
    return half[0] * wp.abs(local[0]) + half[1] * wp.abs(local[1]) + half[2] * wp.abs(local[2])


@wp.func
def box_pair_separation(delta: wp.vec3, rot_a: wp.mat33, half_a: wp.vec3, rot_b: wp.mat33, half_b: wp.vec3,
                        axis: wp.vec3) -> float:
    """Gap between the two projections on a unit axis (< 0: they overlap by that much)."""
    return wp.abs(wp.dot(delta, axis)) - box_support_radius(rot_a, half_a, axis) \
        - box_support_radius(rot_b, half_b, axis)


@wp.struct
class ClipPolygon:
    """The incident face while it is clipped, in reference-face coordinates (x, y, height z).

    ``source`` says what produced a vertex: 0..3 incident vertex v; 4 + 4 e + p the crossing of
    incident edge e with side plane p; 20 + c reference corner c (where two side planes meet,
    bit 0: minus x, bit 1: minus y).  ``edge`` says what the polygon edge leaving a vertex lies
    on: incident edge 0..3 or side plane 4 + p.  Side plane p bounds coordinate p // 2 from the
    side +1 (even p) or -1 (odd p).
    """

    count: int
    point: mat83
    source: vec8i
    edge: vec8i


@wp.func
def polygon_push(poly: ClipPolygon, point: wp.vec3, source: int, edge: int) -> ClipPolygon:
    out = poly
    if out.count < 8:
        out.point[out.count] = point
        out.source[out.count] = source
        out.edge[out.count] = edge
        out.count = out.count + 1
    return out


@wp.func
def crossing_source(edge: int, plane: int) -> int:
    if edge < 4:
        return 4 + 4 * edge + plane
    # A polygon edge lying on side plane edge - 4 meets `plane` at a reference corner.
    x_plane = wp.min(edge - 4, plane)
    y_plane = wp.max(edge - 4, plane)
    return 20 + x_plane % 2 + 2 * (y_plane % 2)


@wp.func
def clip_polygon_plane(poly: ClipPolygon, plane: int, limit: float) -> ClipPolygon:
    """One Sutherland-Hodgman pass against side plane ``plane``: keep side * coord <= limit.

    A crossing is made only when the ends lie strictly on opposite sides, so a vertex lying on
    the plane is kept once, not doubled.  A convex polygon gains at most one vertex per pass,
    so four passes take the incident quad to at most 8 vertices.
    """
    axis = plane // 2
    side = 1.0 - 2.0 * float(plane % 2)
    out = ClipPolygon()
    out.count = 0
    for i in range(poly.count):
        p = poly.point[i]
        q = poly.point[(i + 1) % poly.count]
        fp = side * p[axis] - limit
        fq = side * q[axis] - limit
        if fp <= 0.0:
            out = polygon_push(out, p, poly.source[i], poly.edge[i])
        if (fp < 0.0 and fq > 0.0) or (fp > 0.0 and fq < 0.0):
            x = p + (fp / (fp - fq)) * (q - p)
            # Exactly on the plane, so the later passes see it there.
            x = x + (side * limit - x[axis]) * unit_axis(axis)
            # Leaving: the clipped polygon goes on along the plane; entering: along the edge.
            edge = poly.edge[i]
            if fp < 0.0:
                edge = 4 + plane
            out = polygon_push(out, x, crossing_source(poly.edge[i], plane), edge)
    return out


@wp.func
def area2(a: wp.vec3, b: wp.vec3, c: wp.vec3) -> float:
    """Twice the signed area of triangle abc projected on the x-y plane."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


# A manifold is found up to a step's travel open, and a face landing tilted touches first at its
# deepest point, then turns about it: the next point down is the one that closes first, at a rate
# growing with its distance from the turn, not simply the one farthest away.  So the picks after
# the deepest weigh each point's spread by 1 / (its height over the deepest + CLOSING_LENGTH).
# Points within about CLOSING_LENGTH of the deepest count as touching together (a resting face,
# sagging unevenly by up to column_sag, keeps the widest spread).  Picking by spread alone, a plate
# landing on a corner of another kept four points of its face about that corner and dropped the
# vertex 30 mm up; swung down by the turn, that vertex went 14 mm into the plate within a substep.
CLOSING_LENGTH = 0.01


@wp.func
def closing_weight(height: float, deepest: float) -> float:
    return 1.0 / (height - deepest + CLOSING_LENGTH)


@wp.func
def polygon_pick_four(poly: ClipPolygon) -> wp.vec4i:
    """Four of 5..8 points: the deepest, then by spread weighted to close first (CLOSING_LENGTH):
    the farthest from the deepest, the largest triangle with those two, then the point adding the
    most area outside that triangle.  The four span as much of a resting patch as the points
    allow, which is what keeps a resting box from rocking."""
    i0 = int(0)
    for i in range(1, poly.count):
        if poly.point[i][2] < poly.point[i0][2]:
            i0 = i
    p0 = poly.point[i0]
    i1 = int(-1)
    best = float(-1.0)
    for i in range(poly.count):
        d = poly.point[i] - p0
        weight = closing_weight(poly.point[i][2], p0[2])
        score = (d[0] * d[0] + d[1] * d[1]) * weight * weight
        if i != i0 and score > best:
            best = score
            i1 = i
    p1 = poly.point[i1]
    i2 = int(-1)
    best = float(-1.0)
    for i in range(poly.count):
        score = wp.abs(area2(p0, p1, poly.point[i])) * closing_weight(poly.point[i][2], p0[2])
        if i != i0 and i != i1 and score > best:
            best = score
            i2 = i
    p2 = poly.point[i2]
    # With sigma the triangle's orientation, q lies outside edge (a, b) when
    # sigma * area2(a, b, q) < 0, and adds -sigma * area2(a, b, q) / 2 there.
    sigma = sign_of(area2(p0, p1, p2))
    i3 = int(-1)
    best = float(-1.0e30)
    for i in range(poly.count):
        q = poly.point[i]
        gain = -wp.min(sigma * area2(p0, p1, q), wp.min(sigma * area2(p1, p2, q), sigma * area2(p2, p0, q)))
        if gain > 0.0:
            gain = gain * closing_weight(q[2], p0[2])
        if i != i0 and i != i1 and i != i2 and gain > best:
            best = gain
            i3 = i
    return wp.vec4i(i0, i1, i2, i3)


@wp.func
def face_vertex_signs(axis: int, side: float, vertex: int) -> wp.vec3:
    """Box-frame signs of vertex 0..3 of face (axis, side); going round, the vertices sit at
    (+, +), (-, +), (-, -), (+, -) on axes (axis + 1, axis + 2)."""
    s1 = 1.0
    if vertex == 1 or vertex == 2:
        s1 = -1.0
    s2 = 1.0
    if vertex >= 2:
        s2 = -1.0
    return side * unit_axis(axis) + s1 * unit_axis((axis + 1) % 3) + s2 * unit_axis((axis + 2) % 3)


@wp.func
def clip_source_features(source: int, inc_axis: int, inc_side: float, ref_axis: int,
                         ref_side: float) -> wp.vec2i:
    """(incident feature, reference feature) of a clipped vertex: an incident vertex on the
    reference face, an incident edge across a reference edge, or the incident face under a
    reference corner.  Signs of an edge are the sum of its end vertices' (0 along the edge)."""
    ref_face = ref_side * unit_axis(ref_axis)
    if source < 4:
        inc_vertex = face_vertex_signs(inc_axis, inc_side, source)
        return wp.vec2i(box_feature_id(inc_vertex), box_feature_id(ref_face))
    if source < 20:
        e = (source - 4) // 4
        p = (source - 4) % 4
        inc_edge = face_vertex_signs(inc_axis, inc_side, e) \
            + face_vertex_signs(inc_axis, inc_side, (e + 1) % 4)
        ref_edge = ref_face + (1.0 - 2.0 * float(p % 2)) * unit_axis((ref_axis + 1 + p // 2) % 3)
        return wp.vec2i(box_feature_id(inc_edge), box_feature_id(ref_edge))
    c = source - 20
    ref_corner = ref_face + (1.0 - 2.0 * float(c % 2)) * unit_axis((ref_axis + 1) % 3) \
        + (1.0 - 2.0 * float(c // 2)) * unit_axis((ref_axis + 2) % 3)
    return wp.vec2i(box_feature_id(inc_side * unit_axis(inc_axis)), box_feature_id(ref_corner))


@wp.func
def most_aligned_axis(rot: wp.mat33, direction: wp.vec3) -> int:
    """The box axis (column of ``rot``) most nearly parallel or antiparallel to ``direction``;
    the first of a tie."""
    axis = int(0)
    best = float(-1.0)
    for k in range(3):
        c = wp.abs(wp.dot(mat_column(rot, k), direction))
        if c > best:
            best = c
            axis = k
    return axis


@wp.func
def box_face_contact(ref_pos: wp.vec3, ref_rot: wp.mat33, ref_half: wp.vec3, ref_axis: int,
                     ref_outward: wp.vec3, inc_pos: wp.vec3, inc_rot: wp.mat33, inc_half: wp.vec3,
                     ref_is_b: int, normal: wp.vec3, origin: wp.vec3, margin: float) -> Manifold:
    """Face contact: clip the incident face of one box against the reference face of the other.

    Positions are relative to ``origin`` (B's centre).  The incident face is the one whose
    outward normal is most opposed to the reference face's, ``ref_outward``.  Its vertices are
    written in reference-face coordinates (x, y along the face, z = height above it) and
    clipped to the face, |x| <= h1, |y| <= h2.  Each survivor with depth -z > -margin becomes
    the midpoint of itself and its foot on the reference face, (x, y, z / 2).
    """
    k1 = (ref_axis + 1) % 3
    k2 = (ref_axis + 2) % 3
    t1 = mat_column(ref_rot, k1)
    t2 = mat_column(ref_rot, k2)
    face_centre = ref_pos + ref_half[ref_axis] * ref_outward
    frame = wp.matrix_from_rows(t1, t2, ref_outward)

    inc_axis = most_aligned_axis(inc_rot, ref_outward)
    inc_side = -sign_of(wp.dot(mat_column(inc_rot, inc_axis), ref_outward))
    poly = ClipPolygon()
    poly.count = 0
    for v in range(4):
        local = wp.cw_mul(face_vertex_signs(inc_axis, inc_side, v), inc_half)
        poly = polygon_push(poly, frame * (inc_pos + inc_rot * local - face_centre), v, v)
    for plane in range(4):
        poly = clip_polygon_plane(poly, plane, ref_half[(ref_axis + 1 + plane // 2) % 3])

    kept = ClipPolygon()
    kept.count = 0
    for i in range(poly.count):
        if -poly.point[i][2] > -margin:
            kept = polygon_push(kept, poly.point[i], poly.source[i], poly.edge[i])
    pick = wp.vec4i(0, 1, 2, 3)
    if kept.count > 4:
        pick = polygon_pick_four(kept)

    ref_side = sign_of(wp.dot(mat_column(ref_rot, ref_axis), ref_outward))
    m = manifold_empty()
    m.normal = normal
    m.count = wp.min(kept.count, 4)
    for n in range(m.count):
        p = kept.point[pick[n]]
        m.point[n] = origin + face_centre + p[0] * t1 + p[1] * t2 + (0.5 * p[2]) * ref_outward
        m.depth[n] = -p[2]
        pair = clip_source_features(kept.source[pick[n]], inc_axis, inc_side, ref_axis, ref_side)
        if ref_is_b == 1:
            m.feature[n] = BOX_FEATURE_COUNT * pair[0] + pair[1]
        else:
            m.feature[n] = BOX_FEATURE_COUNT * pair[1] + pair[0]
    return m


@wp.func
def box_support_edge(pos: wp.vec3, rot: wp.mat33, half: wp.vec3, axis: int, direction: wp.vec3):
    """Centre and box-frame signs of the edge along ``axis`` furthest along ``direction``."""
    signs = wp.vec3(0.0)
    for n in range(2):
        k = (axis + 1 + n) % 3
        signs[k] = sign_of(wp.dot(mat_column(rot, k), direction))
    return pos + rot * wp.cw_mul(signs, half), signs


@wp.func
def segment_closest(pa: wp.vec3, u: wp.vec3, ha: float, pb: wp.vec3, v: wp.vec3, hb: float) -> wp.vec2:
    """Parameters (s, t) of the closest points pa + s u, pb + t v, |s| <= ha, |t| <= hb.

    Zeroing the gradient of |r + s u - t v|^2 (r = pa - pb, |u| = |v| = 1):
        s = t (u.v) - u.r,   t = s (u.v) + v.r,
    jointly solved over 1 - (u.v)^2 = |u x v|^2 (the cross product keeps the precision that
    1 - (u.v)^2 would cancel away).  Clamp s, take t from it, clamp t, redo s.
    """
    r = pa - pb
    b = wp.dot(u, v)
    ur = wp.dot(u, r)
    vr = wp.dot(v, r)
    denom = wp.length_sq(wp.cross(u, v))
    s = float(0.0)
    if denom > 1.0e-12:
        s = wp.clamp((b * vr - ur) / denom, -ha, ha)
    t = wp.clamp(s * b + vr, -hb, hb)
    s = wp.clamp(t * b - ur, -ha, ha)
    return wp.vec2(s, t)


@wp.func
def supporting_edge_points(pos_a: wp.vec3, rot_a: wp.mat33, half_a: wp.vec3, edge_a: int, rot_b: wp.mat33,
                           half_b: wp.vec3, edge_b: int, normal: wp.vec3):
    """The closest points of A's edge along ``edge_a`` furthest towards B and B's edge along
    ``edge_b`` furthest towards A (B at the origin, ``normal`` from B into A), and the pair's
    feature id."""
    centre_a, signs_a = box_support_edge(pos_a, rot_a, half_a, edge_a, -normal)
    centre_b, signs_b = box_support_edge(wp.vec3(0.0), rot_b, half_b, edge_b, normal)
    u = mat_column(rot_a, edge_a)
    v = mat_column(rot_b, edge_b)
    st = segment_closest(centre_a, u, half_a[edge_a], centre_b, v, half_b[edge_b])
    feature = BOX_FEATURE_COUNT * box_feature_id(signs_a) + box_feature_id(signs_b)
    return centre_a + st[0] * u, centre_b + st[1] * v, feature


@wp.func
def box_edge_contact(pos_a: wp.vec3, rot_a: wp.mat33, half_a: wp.vec3, edge_a: int, rot_b: wp.mat33,
                     half_b: wp.vec3, edge_b: int, normal: wp.vec3, depth: float,
                     origin: wp.vec3) -> Manifold:
    """Edge contact: one point halfway between the closest points of the supporting edges (A's
    edge furthest towards B, B's furthest towards A); the depth is the axis overlap.  Apart, the
    axis's separation is only a lower bound of the gap (the edges' closest points may be clamped
    to their ends, further apart), and a gap understated would stop the bodies before they touch:
    the gap is then the closest points' distance, a true distance of two surface points."""
    on_a, on_b, feature = supporting_edge_points(pos_a, rot_a, half_a, edge_a, rot_b, half_b, edge_b, normal)
    if depth < 0.0:
        depth = wp.min(depth, -wp.length(on_a - on_b))
    return manifold_single(normal, origin + 0.5 * (on_a + on_b), depth, feature)


@wp.func
def vertex_signs(v: int) -> wp.vec3:
    """Box-frame signs of vertex v = 0..7 (bit k set: minus on axis k)."""
    return wp.vec3(wp.where((v & 1) != 0, -1.0, 1.0), wp.where((v & 2) != 0, -1.0, 1.0),
                   wp.where((v & 4) != 0, -1.0, 1.0))


@wp.func
def clamp_to_box(local: wp.vec3, half: wp.vec3) -> wp.vec3:
    """The point of a box (box-frame coordinates) nearest ``local``."""
    return wp.vec3(wp.clamp(local[0], -half[0], half[0]), wp.clamp(local[1], -half[1], half[1]),
                   wp.clamp(local[2], -half[2], half[2]))


@wp.func
def region_signs(local: wp.vec3, half: wp.vec3) -> wp.vec3:
    """Signs of the feature of a box nearest an outside point (its box-frame coordinates): +-1
    where the point lies beyond the box on that axis, 0 where within."""
    out = wp.vec3(0.0)
    for k in range(3):
        if local[k] > half[k]:
            out[k] = 1.0
        elif local[k] < -half[k]:
            out[k] = -1.0
    return out


@wp.func
def separated_contact(pos_a: wp.vec3, rot_a: wp.mat33, half_a: wp.vec3, edge_a: int, rot_b: wp.mat33,
                      half_b: wp.vec3, edge_b: int, edge_normal: wp.vec3, has_edge_axis: int, origin: wp.vec3,
                      margin: float) -> Manifold:
    """Boxes apart whose face clip is empty: one speculative point between the nearest pair of
    surface points found among every vertex against the other box and the supporting edges of
    the best edge axis, along the line joining them (B at the origin, A at ``pos_a``).

    The axis of largest separation is only a lower bound of the gap while the boxes are apart,
    and when it is a face axis the incident face may lie wholly beside the reference face: its
    clip is empty although the boxes are closing (a plate falling at 9 m/s past another's edge
    had no point for the whole step and went 7.7 cm into it).  Box2D v3's polygon collider
    answers the same case with the closest points of the two edges; for boxes the closest
    features are a vertex and a face, edge or vertex (each vertex clamped into the other box
    gives those exactly) or two edges (the supporting edges when the best edge axis holds them).
    Two surface points are at least the boxes' distance apart, so the gap is never understated:
    no contact acts before the bodies can touch."""
    best = margin
    m = manifold_empty()
    for vertex in range(8):
        # a vertex of A against B, in B's frame (B at the origin)
        signs = vertex_signs(vertex)
        p = pos_a + rot_a * wp.cw_mul(signs, half_a)
        q = wp.transpose(rot_b) * p
        c = clamp_to_box(q, half_b)
        gap = wp.length(q - c)
        if gap < best and gap > 1.0e-6:
            best = gap
            m = manifold_single(rot_b * (q - c) / gap, origin + 0.5 * (p + rot_b * c), -gap,
                                BOX_FEATURE_COUNT * box_feature_id(signs) + box_feature_id(region_signs(q, half_b)))
        # a vertex of B against A, in A's frame; the normal points from B into A
        p = rot_b * wp.cw_mul(signs, half_b)
        q = wp.transpose(rot_a) * (p - pos_a)
        c = clamp_to_box(q, half_a)
        gap = wp.length(q - c)
        if gap < best and gap > 1.0e-6:
            best = gap
            m = manifold_single(-(rot_a * (q - c)) / gap, origin + 0.5 * (p + pos_a + rot_a * c), -gap,
                                BOX_FEATURE_COUNT * box_feature_id(region_signs(q, half_a)) + box_feature_id(signs))
    if has_edge_axis != 0:
        on_a, on_b, feature = supporting_edge_points(pos_a, rot_a, half_a, edge_a, rot_b, half_b, edge_b,
                                                     edge_normal)
        gap = wp.length(on_a - on_b)
        if gap < best and gap > 1.0e-6:
            m = manifold_single((on_a - on_b) / gap, origin + 0.5 * (on_a + on_b), -gap, feature)
    return m


@wp.func
def edge_face_manifold(pos_a: wp.vec3, rot_a: wp.mat33, half_a: wp.vec3, rot_b: wp.mat33, half_b: wp.vec3,
                       normal: wp.vec3, depth: float, origin: wp.vec3, margin: float) -> Manifold:
    """The faces of both boxes that support an edge-axis contact, clipped against each other.

    The separating axis is an edge cross product, but a tilted plate lying across another meets
    it along a strip, not at one point: a single point between the two edges lets the plate
    turn about it, and its far side swings into the other box within a substep.  So (as Jolt's
    face-to-face manifold does) the face of either box best aligned with the edge normal is the
    reference, the other box's incident face is clipped to it (box_face_contact), and the points
    keep the edge normal.  A point a height z off the reference face (unit normal n_f) is
    -z / |n . n_f| deep along the edge normal n; no point may be deeper than the axis overlap
    itself, which is the exact penetration along n.  The caller keeps the single edge point
    when fewer than two points survive (crossing edges touch at a point)."""
    face_a = mat_column(rot_a, most_aligned_axis(rot_a, normal))
    face_b = mat_column(rot_b, most_aligned_axis(rot_b, normal))
    cosine_a = wp.abs(wp.dot(face_a, normal))
    cosine_b = wp.abs(wp.dot(face_b, normal))
    ref_is_b = int(0)
    if cosine_a < cosine_b:
        ref_is_b = 1
    # B lies at the origin; n points from B into A, so A's face towards B is the one against n
    ref_pos = wp.where(ref_is_b == 1, wp.vec3(0.0), pos_a)
    ref_rot = wp.where(ref_is_b == 1, rot_b, rot_a)
    ref_half = wp.where(ref_is_b == 1, half_b, half_a)
    inc_pos = wp.where(ref_is_b == 1, pos_a, wp.vec3(0.0))
    inc_rot = wp.where(ref_is_b == 1, rot_a, rot_b)
    inc_half = wp.where(ref_is_b == 1, half_a, half_b)
    toward_other = wp.where(ref_is_b == 1, normal, -normal)
    ref_axis = most_aligned_axis(ref_rot, normal)
    outward = sign_of(wp.dot(mat_column(ref_rot, ref_axis), toward_other)) * mat_column(ref_rot, ref_axis)
    cosine = wp.max(cosine_a, cosine_b)
    m = box_face_contact(ref_pos, ref_rot, ref_half, ref_axis, outward, inc_pos, inc_rot, inc_half, ref_is_b,
                         normal, origin, margin)
    for n in range(m.count):
        m.depth[n] = wp.min(m.depth[n] / cosine, depth)
    return m


@wp.func
def with_nearest(m: Manifold, extra: Manifold, tolerance: float) -> Manifold:
    """``m`` with the single point of ``extra`` (same normal) added where it is nearer than every
    point of ``m`` by more than ``tolerance``: in the slot of the same feature, else a free slot,
    else that of m's farthest point.  For boxes apart, a clip or a strip holds the incident face's
    corners and crossings, which can all lie further than the nearest features: a plate falling
    past another's edge, its strip's points 96 to 108 mm off while its edges were 51 mm apart,
    went 29 mm into the other before any point closed (bench/thin_rain.py's column of plates).
    Where the clip already holds the nearest features (a face approaching a face), the two
    depths differ by rounding only, and a nearest point winning by an ulp took the slot of a
    face corner chosen by rounding too: a cube sliding into a static step lost the step's top
    corner on one side for a copy of a bottom corner and tripped with 13 % too much turn."""
    if extra.count == 0:
        return m
    if m.count == 0:
        return extra
    nearest = float(-1.0e30)
    far = int(0)
    slot = int(-1)
    for k in range(m.count):
        nearest = wp.max(nearest, m.depth[k])
        if m.depth[k] < m.depth[far]:
            far = k
        if m.feature[k] == extra.feature[0]:
            slot = k
    if extra.depth[0] <= nearest + tolerance:
        return m
    out = m
    if slot < 0:
        slot = far
        if m.count < 4:
            slot = m.count
            out.count = m.count + 1
    out.point[slot] = extra.point[0]
    out.depth[slot] = extra.depth[0]
    out.feature[slot] = extra.feature[0]
    return out


@wp.func
def through_covered(covered_a: int, rot_a: wp.mat33, covered_b: int, rot_b: wp.mat33, delta: wp.vec3,
                    axis: wp.vec3) -> bool:
    """Whether the axis, oriented from B to A (delta = pos_a - pos_b), leaves B out through a covered
    face of B, or A (reversed) out through a covered face of A."""
    if covered_a == 0 and covered_b == 0:
        return False
    normal = sign_of(wp.dot(delta, axis)) * axis
    return points_through_covered(covered_b, rot_b, normal) or points_through_covered(covered_a, rot_a, -normal)


@wp.func
def collide_box_box(pos_a: wp.vec3, rot_a: wp.mat33, half_a: wp.vec3, covered_a: int, pos_b: wp.vec3,
                    rot_b: wp.mat33, half_b: wp.vec3, covered_b: int, margin: float, reference: int) -> Manifold:
    """Box A against box B by the separating-axis test, then a face or an edge manifold.

    Candidate axes: the three face normals of each box and the nine cross products a_i x b_j
    of their edge directions.  For boxes these are all the face normals of the Minkowski
    difference, so the largest separation s = |d.L| - r_A(L) - r_B(L) over them (d = pos_a -
    pos_b) is the exact penetration depth -s, or a lower bound of the gap when separated.  An
    axis with s >= margin proves the pair too far apart for a contact.

    Face/edge ties are common and harmless in exact arithmetic (aligned stacks: a_x x b_z =
    -a_y), but float32 rounding then lets an edge axis win by an ulp, and an edge manifold is a
    single point between two arbitrary parallel edges: a phantom contact (mujoco_warp issue
    #1597).  Nearly flat stacks (a tilt of 1e-3 rad, footprints crossing) have edge axes that
    win by a few tilt-times-size, and one point is a poor support for a resting box there.  So
    an edge axis must beat the best face axis by EDGE_PREFERENCE_ABSOLUTE * (sum of half
    extents) + EDGE_PREFERENCE_RELATIVE * |s_face| (the 5 % of ODE's box-box "fudge factor"),
    which also bounds how much deeper than the true depth a face manifold chosen this way can
    be.  Parallel edge pairs (|a_i x b_j| < EDGE_AXIS_MIN_LENGTH) have no axis.

    Two faces nearly parallel tie between A's face axis and B's to first order in their angle
    alpha, and either normal is within alpha of the other; which one is the reference matters
    where a large load meets a light body.  A 1 kg cube between two of 1e4 kg, without friction:
    the heavy cubes tilt on their own soft supports (tens of microradians under 1e5 N), and with a
    heavy face as the reference the load meets the light cube along a normal alpha off its own, a
    ramp that pushes it out with about F alpha (1 N from 1e-5 rad) and, as it moves, tilts the
    heavy cube further: it was squeezed out at 23 m/s within a second.  So within
    EDGE_PREFERENCE_ABSOLUTE * (sum of half extents) of the best face axis (a few 1e-4 rad across
    the faces) the ``reference`` body's face wins (primitives.reference_body):
    a static body's, which no load tilts, else the lighter body's, whose two loaded faces then
    push it along one axis and cancel but for its weight.  With equal masses (``reference`` 0) the
    first face axis found wins (A's before B's).

    An axis whose normal would leave B, or A, out through one of its covered faces
    (covered_faces.py) is not a candidate: such a contact is the covering box's.  With no face
    axis left there is no contact.
    """
    delta = pos_a - pos_b
    best = wp.vec2(-1.0e30, -1.0e30)
    best_index = wp.vec2i(0, 3)
    for k in range(6):
        axis = mat_column(rot_a, k % 3)
        if k >= 3:
            axis = mat_column(rot_b, k % 3)
        s = box_pair_separation(delta, rot_a, half_a, rot_b, half_b, axis)
        side = k // 3
        if s > best[side] and not through_covered(covered_a, rot_a, covered_b, rot_b, delta, axis):
            best[side] = s
            best_index[side] = k
    # the separating-axis value is the best face axis's; the reference face may be the other's
    face_separation = wp.max(best[0], best[1])
    if face_separation >= margin or face_separation < -1.0e29:
        return manifold_empty()
    size = half_a[0] + half_a[1] + half_a[2] + half_b[0] + half_b[1] + half_b[2]
    tie = EDGE_PREFERENCE_ABSOLUTE * size
    side = wp.where(best[1] > best[0], 1, 0)
    if reference == 1 and best[0] > best[1] - tie:
        side = 0
    if reference == 2 and best[1] > best[0] - tie:
        side = 1
    face_index = best_index[side]
    face_axis = mat_column(rot_a, face_index % 3)
    if face_index >= 3:
        face_axis = mat_column(rot_b, face_index % 3)

    edge_separation = float(-1.0e30)
    edge_axis = wp.vec3(0.0)
    edge_a = int(0)
    edge_b = int(0)
    for i in range(3):
        for j in range(3):
            axis = wp.cross(mat_column(rot_a, i), mat_column(rot_b, j))
            length = wp.length(axis)
            if length >= EDGE_AXIS_MIN_LENGTH:
                s = box_pair_separation(delta, rot_a, half_a, rot_b, half_b, axis / length)
                if s > edge_separation and not through_covered(covered_a, rot_a, covered_b, rot_b, delta,
                                                               axis / length):
                    edge_separation = s
                    edge_axis = axis / length
                    edge_a = i
                    edge_b = j
    if edge_separation >= margin:
        return manifold_empty()

    tolerance = EDGE_PREFERENCE_ABSOLUTE * size + EDGE_PREFERENCE_RELATIVE * wp.abs(face_separation)
    if edge_separation > face_separation + tolerance:
        normal = sign_of(wp.dot(delta, edge_axis)) * edge_axis
        faces = edge_face_manifold(delta, rot_a, half_a, rot_b, half_b, normal, -edge_separation, pos_b, margin)
        if faces.count >= 2 and edge_separation <= 0.0:
            return faces
        edge = box_edge_contact(delta, rot_a, half_a, edge_a, rot_b, half_b, edge_b, normal, -edge_separation, pos_b)
        if faces.count >= 2:
            return with_nearest(faces, edge, NEAREST_TOLERANCE * size)  # apart: the strip may lie further
        return edge
    normal = sign_of(wp.dot(delta, face_axis)) * face_axis
    m = manifold_empty()
    if face_index < 3:
        # A's face towards B is the reference: its outward normal points from A to B.
        m = box_face_contact(delta, rot_a, half_a, face_index, -normal, wp.vec3(0.0), rot_b, half_b, 0,
                             normal, pos_b, margin)
    else:
        m = box_face_contact(wp.vec3(0.0), rot_b, half_b, face_index - 3, normal, delta, rot_a, half_a, 1,
                             normal, pos_b, margin)
    if wp.max(face_separation, edge_separation) > 0.0:
        edge_normal = sign_of(wp.dot(delta, edge_axis)) * edge_axis
        nearest = separated_contact(delta, rot_a, half_a, edge_a, rot_b, half_b, edge_b, edge_normal,
                                    int(edge_separation > -1.0e29), pos_b, margin)
        if m.count == 0:
            return nearest
        # the clip's points keep its normal; the nearest pair's true distance is its gap
        nearest.normal = normal
        return with_nearest(m, nearest, NEAREST_TOLERANCE * size)
    return m
