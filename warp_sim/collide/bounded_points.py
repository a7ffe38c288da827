"""A support-face checkpoint the face's corners already hold needs no row of its own.

On the Fourier terrain a box carries 3 checkpoints an edge (builder.box_checkpoints): the 4
corners of its support face and, between them, 4 edge midpoints and the face centre, which see a
crest that rises between the corners (face_search.py).  Each active checkpoint is a row of the
solver, swept every substep, and the solver's sweeps are most of a body-contact step.  Where the
ground under a face is flat or hollow, those 5 rows constrain nothing the corners do not.

Why, to first order: the face is rigid, so a point's normal displacement is affine in its place on
the face, and on ground whose depth is affine over the face too (a plane, or curved ground within
the slack below) the depth at a point of local coordinates (t_a, t_b) in [0, 1]^2 is the bilinear
blend of the four corners' depths.  A row keeps its point outside the surface; when the four
corners' rows hold, any blend of them holds, so the point between them holds with no row.  Where
the depth at the point is deeper than the blend (a crest between the corners, which the face
search's climb measured) the corners do not bound it and the row stays.  The rule is therefore:

    keep the row of a non-corner support-face checkpoint only where
        depth > sum_c w_c depth_c + slack,       w_c the bilinear weights of the corners c,

depth_c each corner's depth as the pass found it, whether or not its own row is open, but never
taken below -W_c, its window (the gap it could close within the step: margin + h speed + h^2 g).
Why the corners' depths and not their rows: a rigid motion moves the point's depth as it moves
the blend, so where the corners that lie within reach hold, the point between them holds too; a
rule that asked whether a corner's row was open made the point's row flip with a corner at the
edge of its window, which a still body's carried contacts (still_contacts.py) re-test and the
search may decide the other way.  Why the floor -W_c: the cull (terrain_contact.py) skips a corner
provably deeper out than its window without sampling it, and the rule must not depend on whether
it did (tests/test_terrain.py: the cull changes no contact); a corner further out than its window
is taken at -W_c either way.  Why the floor is safe: it raises the blend only where a corner lies
beyond its window, and a point pruned against that raised blend still cannot reach the surface
within the step.  Between a held corner (depth about 0) and a far one, the point lies at least
w_far W_far out, while the motion the windows allow moves it at most w_far (W_far - margin): the
window's margin is slack beyond the motion bound h speed + h^2 g, so the point stays at least
w_far margin short of the surface (5 mm halfway along an edge at the default 2 cm), which the
next pass sees afresh.

``slack`` is the float32 error of the depths (about k f |u| 2^-24 sum|A| an evaluation,
terrain_contact.CULL_SLACK's reasoning, 1e-7 per metre from the origin) plus FACE_SEARCH_GAIN, the
depth the climb itself does not resolve: without it, rounding would open and close a flat face's
midpoints from step to step.  The normals of the corners and the point differ on curved ground;
that difference is what the slack also covers, and beyond it the point's own row stays.

``SimConfig.prune_face_points = False`` keeps every row (the choice charted against it in the
README's speed-against-accuracy notes).
"""

import warp as wp

from ..kernel_args import TerrainContacts
from .face_search import FACE_SEARCH_GAIN, on_support_face
from .still_contacts import close_slot

BOUND_SLACK_RATE = wp.constant(1.0e-7)  # [m per m of |x| + |z|]: float32 depth error far out


@wp.func
def is_corner(local: wp.vec3, half: wp.vec3) -> bool:
    """A corner of the box: every coordinate is +-half, bit for bit (builder.host_arrays)."""
    return wp.abs(local[0]) == half[0] and wp.abs(local[1]) == half[1] and wp.abs(local[2]) == half[2]


@wp.func
def corner_index(local: wp.vec3, face: wp.vec2i) -> int:
    """Which of the support face's four corners: bit 0 the sign along the face's first axis, bit 1
    along its second."""
    a = (face[0] + 1) % 3
    b = (face[0] + 2) % 3
    return wp.where(local[a] > 0.0, 1, 0) + wp.where(local[b] > 0.0, 2, 0)


@wp.func
def corner_blend(local: wp.vec3, half: wp.vec3, face: wp.vec2i, corner_depth: wp.vec4) -> float:
    """The bilinear blend of the support face's corner depths (indexed by corner_index) at ``local``."""
    a = (face[0] + 1) % 3
    b = (face[0] + 2) % 3
    ta = 0.5 * (local[a] / half[a] + 1.0)
    tb = 0.5 * (local[b] / half[b] + 1.0)
    return ((1.0 - ta) * (1.0 - tb) * corner_depth[0] + ta * (1.0 - tb) * corner_depth[1]
            + (1.0 - ta) * tb * corner_depth[2] + ta * tb * corner_depth[3])


@wp.func
def prune_bounded_points(start: int, count: int, x: wp.vec3, half: wp.vec3, face: wp.vec2i, corner_depth: wp.vec4,
                         checkpoint_local: wp.array(dtype=wp.vec3), contacts: TerrainContacts) -> int:
    """Close the rows of the support face's non-corner checkpoints the corners hold (module
    docstring), from the corners' depths as the pass found them, each at least minus its window
    (``corner_depth``); returns how many were closed."""
    slack = FACE_SEARCH_GAIN + BOUND_SLACK_RATE * (wp.abs(x[0]) + wp.abs(x[2]))
    closed = int(0)
    for slot in range(start, start + count):
        if contacts.terrain_contact_active[slot] == 0:
            continue
        local = checkpoint_local[slot]
        if not on_support_face(local, half, face) or is_corner(local, half):
            continue
        if contacts.terrain_contact_depth[slot] <= corner_blend(local, half, face, corner_depth) + slack:
            close_slot(contacts, slot)
            closed += 1
    return closed
