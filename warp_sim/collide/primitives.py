"""Narrow phase: pure contact functions for sphere and box pairs (SEED.md 4), and the table
that dispatches a pair to its function.  The conventions every function keeps (normal from B
into A, depth > 0 penetrating, speculative points within the margin, feature ids) are written
in manifold.py; box against box is box_box.py.
"""

import warp as wp

from ..types import SHAPE_BOX, SHAPE_SPHERE
from .box_box import collide_box_box
from .covered_faces import face_covered
from .manifold import (  # noqa: F401  (re-exported: the pair functions' common vocabulary)
    BOX_EDGE_ID,
    BOX_FEATURE_COUNT,
    BOX_VERTEX_ID,
    COINCIDENT_TOLERANCE,
    Manifold,
    box_feature_id,
    manifold_empty,
    manifold_single,
    mat43,
    mat_column,
    sign_of,
    unit_axis,
)

# ----------------------------------------------------------------------------------------------
# Spheres


@wp.func
def collide_sphere_sphere(pos_a: wp.vec3, radius_a: float, pos_b: wp.vec3, radius_b: float,
                          margin: float) -> Manifold:
    """One point on the line of centres; coincident centres separate along +y."""
    delta = pos_a - pos_b
    distance = wp.length(delta)
    normal = wp.vec3(0.0, 1.0, 0.0)
    if distance > COINCIDENT_TOLERANCE * (radius_a + radius_b):
        normal = delta / distance
    else:
        distance = 0.0
    depth = radius_a + radius_b - distance
    if depth <= -margin:
        return manifold_empty()
    # Surfaces at pos_a - r_a n and pos_b + r_b n; their midpoint, built relative to B.
    point = pos_b + 0.5 * (delta + (radius_b - radius_a) * normal)
    return manifold_single(normal, point, depth, 0)


@wp.func
def slab_side(x: float, half: float) -> float:
    if x > half:
        return 1.0
    if x < -half:
        return -1.0
    return 0.0


@wp.func
def collide_sphere_box(sphere_pos: wp.vec3, radius: float, box_pos: wp.vec3, box_rot: wp.mat33,
                       box_half: wp.vec3, box_covered: int, margin: float) -> Manifold:
    """Sphere A against box B, in the box frame.

    Outside the box the closest box point to the centre q is clamp(q, -h, h); the normal is
    the unit offset from it and depth = r - |offset|.  Per axis the centre lies below, within
    or above the box's slab; those three-way signs name the face, edge or vertex whose Voronoi
    region holds it, which is the feature.

    Inside, the clamp returns q itself (no direction), so the sphere is pushed out through the
    face of least slack h_k - |q_k|: depth = r + slack, feature that face, so a sphere sinking
    through a face keeps its id.

    Covered faces (``box_covered``, covered_faces.py) are not surfaces: outside, the offset loses
    its components out through them, so the normal of the edge a covered face bounds is the other
    face's (a ball crossing the seam of two flush slabs touches the far slab's top, extended, not
    its edge); a centre beyond covered faces only is the covering box's to touch, and gets no
    contact here.  Inside, the sphere leaves by the uncovered face of least slack.
    """
    local = wp.transpose(box_rot) * (sphere_pos - box_pos)
    closest = wp.vec3(wp.clamp(local[0], -box_half[0], box_half[0]),
                      wp.clamp(local[1], -box_half[1], box_half[1]),
                      wp.clamp(local[2], -box_half[2], box_half[2]))
    region = wp.vec3(slab_side(local[0], box_half[0]), slab_side(local[1], box_half[1]),
                     slab_side(local[2], box_half[2]))
    if box_covered != 0 and wp.length(region) > 0.0:  # outside
        for k in range(3):
            if region[k] != 0.0 and face_covered(box_covered, k, region[k]):
                closest[k] = local[k]
                region[k] = 0.0
        if wp.length(region) == 0.0:
            return manifold_empty()
    offset = local - closest
    distance = wp.length(offset)
    normal_local = wp.vec3(0.0, 1.0, 0.0)
    surface = closest
    depth = float(0.0)
    if distance > 0.0:
        normal_local = offset / distance
        depth = radius - distance
    else:
        axis = int(-1)
        slack = float(1.0e30)
        for k in range(3):
            if box_half[k] - wp.abs(local[k]) < slack and not face_covered(box_covered, k, sign_of(local[k])):
                slack = box_half[k] - wp.abs(local[k])
                axis = k
        if axis < 0:
            return manifold_empty()  # every face it could leave by is covered: it is inside the others
        side = sign_of(local[axis])
        normal_local = side * unit_axis(axis)
        region = normal_local
        surface = local + (side * box_half[axis] - local[axis]) * unit_axis(axis)
        depth = radius + slack
    if depth <= -margin:
        return manifold_empty()
    # Midpoint of the box surface point and the sphere's deepest point.
    point_local = 0.5 * (surface + local - radius * normal_local)
    return manifold_single(box_rot * normal_local, box_pos + box_rot * point_local, depth,
                           box_feature_id(region))


# ----------------------------------------------------------------------------------------------
# Dispatch (the thesis's box-box method, a baseline, is in primitives_thesis.py)

PAIR_FUNCTIONS = {
    (SHAPE_SPHERE, SHAPE_SPHERE): collide_sphere_sphere,
    (SHAPE_SPHERE, SHAPE_BOX): collide_sphere_box,
    (SHAPE_BOX, SHAPE_BOX): collide_box_box,
}
"""Pair functions by (shape A, shape B), A the lower type; (box, sphere) is (sphere, box) swapped."""


@wp.func
def reference_body(inv_mass_a: float, inv_mass_b: float) -> int:
    """Whose face a box pair's near tie between face axes takes as the reference
    (box_box.collide_box_box): 1 for A, 2 for B, 0 for neither (the first axis found).  A static
    body's, which no load tilts; else the lighter body's (see there)."""
    if inv_mass_a == 0.0 and inv_mass_b > 0.0:
        return 1
    if inv_mass_b == 0.0 and inv_mass_a > 0.0:
        return 2
    if inv_mass_a > inv_mass_b:
        return 1
    if inv_mass_b > inv_mass_a:
        return 2
    return 0


@wp.func
def collide_pair(shape_a: int, pos_a: wp.vec3, rot_a: wp.mat33, size_a: wp.vec3, covered_a: int, shape_b: int,
                 pos_b: wp.vec3, rot_b: wp.mat33, size_b: wp.vec3, covered_b: int, margin: float,
                 reference: int) -> Manifold:
    """Any pair through one call; ``size`` is the radius in [0] for a sphere, the half extents
    for a box.  (box, sphere) runs as (sphere, box) and flips the normal back, so the result
    keeps this pair's (A, B) convention; points, depths and features are unchanged.  ``covered``:
    the box's covered-face mask (covered_faces.py; 0 for a sphere or a dynamic box).  ``reference``:
    whose face a box pair's near tie takes (reference_body)."""
    if shape_a == SHAPE_SPHERE and shape_b == SHAPE_SPHERE:
        return collide_sphere_sphere(pos_a, size_a[0], pos_b, size_b[0], margin)
    if shape_a == SHAPE_SPHERE and shape_b == SHAPE_BOX:
        return collide_sphere_box(pos_a, size_a[0], pos_b, rot_b, size_b, covered_b, margin)
    if shape_a == SHAPE_BOX and shape_b == SHAPE_SPHERE:
        m = collide_sphere_box(pos_b, size_b[0], pos_a, rot_a, size_a, covered_a, margin)
        m.normal = -m.normal
        return m
    if shape_a == SHAPE_BOX and shape_b == SHAPE_BOX:
        return collide_box_box(pos_a, rot_a, size_a, covered_a, pos_b, rot_b, size_b, covered_b, margin, reference)
    return manifold_empty()
