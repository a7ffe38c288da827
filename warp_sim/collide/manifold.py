"""What every pair function returns: the Manifold, its conventions, and the small helpers they share.

Conventions (the same as ``contacts.py``):

* A pair is (A, B), ordered so that A has the lower shape type (sphere before box);
  ``collide_pair`` handles (box, sphere) by swapping the two and flipping the normal.
* ``normal`` is a unit vector from B into A, the direction A must move to separate.  All points
  of one manifold share it.
* ``depth`` > 0 is penetration, < 0 a gap.  Contacts are speculative: a point is reported while
  depth > -margin.  Moving A by (largest depth) * normal brings the pair to touching.
* A contact point is the midpoint of the two surfaces' deepest (or closest) points, in world
  space.
* ``feature`` names the features that produced a point, so a solver can match last step's
  impulses to this step's points.  A box has 26 features (``box_feature_id``): faces 0..5,
  edges 6..17, vertices 18..25.  A box-box point is 26 * (feature of A) + (feature of B),
  whichever box held the reference face and whichever method found it, so an id survives a
  swap of reference face and a switch between face and edge contact.  A sphere-box point
  carries the box feature whose Voronoi region holds the centre; sphere-sphere points 0.

Boxes are (centre, rotation whose columns are the body axes in world, half extents); spheres
are (centre, radius).

Precision: every function works with positions relative to B's centre and adds that centre back
to the output points only.  The difference of two nearby float32 numbers is exact, so boxes
stacked at x = 1000 m get the same depths and normals as at the origin.
"""

import warp as wp


POINTS = 4  # a manifold's point slots: the rows of mat43, a pair's slots in Contacts
mat43 = wp.types.matrix(shape=(POINTS, 3), dtype=float)
mat83 = wp.types.matrix(shape=(8, 3), dtype=float)
vec8i = wp.types.vector(length=8, dtype=wp.int32)

# Centres closer than this fraction of r_a + r_b: their direction is float32 noise.
COINCIDENT_TOLERANCE = 1.0e-6
# Edge pairs with |a_i x b_j| below this are parallel: their axis would be rounding noise.
EDGE_AXIS_MIN_LENGTH = 1.0e-6
# An edge axis must beat the best face axis by more than this (see collide_box_box).
EDGE_PREFERENCE_ABSOLUTE = 1.0e-4
EDGE_PREFERENCE_RELATIVE = 0.05
# The nearest pair of features of boxes apart joins a face manifold only where it is nearer than
# all its points by more than this share of the boxes' summed half extents: rounding (float32,
# about 1e-7 of the size) is not nearness (box_box.with_nearest).
NEAREST_TOLERANCE = 2.0e-6
BOX_EDGE_ID = 6
BOX_VERTEX_ID = 18
BOX_FEATURE_COUNT = 26


@wp.struct
class Manifold:
    """Up to four contact points of one pair, sharing one normal (see the module docstring).

    Attributes:
        count: number of valid points, 0..4.
        normal: unit normal from B into A.
        point: row i is point i, world [m].
        depth: penetration per point [m] (< 0: speculative gap).
        feature: persistent id per point (-1 in unused slots).
    """

    count: int
    normal: wp.vec3
    point: mat43
    depth: wp.vec4
    feature: wp.vec4i


@wp.func
def manifold_empty() -> Manifold:
    m = Manifold()
    m.count = 0
    m.normal = wp.vec3(0.0, 1.0, 0.0)
    m.feature = wp.vec4i(-1, -1, -1, -1)
    return m


@wp.func
def manifold_single(normal: wp.vec3, point: wp.vec3, depth: float, feature: int) -> Manifold:
    m = manifold_empty()
    m.count = 1
    m.normal = normal
    m.point[0] = point
    m.depth[0] = depth
    m.feature[0] = feature
    return m


@wp.func
def sign_of(x: float) -> float:
    """+1 for x >= 0, else -1: a tie picks +, so every choice below is deterministic."""
    if x < 0.0:
        return -1.0
    return 1.0


@wp.func
def unit_axis(axis: int) -> wp.vec3:
    e = wp.vec3(0.0)
    e[axis] = 1.0
    return e


@wp.func
def mat_column(m: wp.mat33, k: int) -> wp.vec3:
    return wp.vec3(m[0, k], m[1, k], m[2, k])


@wp.func
def box_feature_id(signs: wp.vec3) -> int:
    """The box feature at box-frame signs (-1, 0 or +1 per axis; only the sign is read).

    A zero means the feature spans that axis.  Two zeros: a face, 2 axis + (1 on the minus
    side).  One zero: an edge along that axis, 6 + 4 axis + (1 if minus on axis + 1) + (2 if
    minus on axis + 2).  No zero: a vertex, 18 + (1, 2, 4 for minus on x, y, z).
    """
    zeros = int(signs[0] == 0.0) + int(signs[1] == 0.0) + int(signs[2] == 0.0)
    minus = wp.vec3i(int(signs[0] < 0.0), int(signs[1] < 0.0), int(signs[2] < 0.0))
    if zeros == 0:
        return BOX_VERTEX_ID + minus[0] + 2 * minus[1] + 4 * minus[2]
    # The edge's axis is its zero; the face's axis is its non-zero.
    axis = int(0)
    for k in range(3):
        if (signs[k] == 0.0) == (zeros == 1):
            axis = k
    if zeros == 1:
        return BOX_EDGE_ID + 4 * axis + minus[(axis + 1) % 3] + 2 * minus[(axis + 2) % 3]
    return 2 * axis + minus[axis]

