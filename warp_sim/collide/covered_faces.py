"""Faces of static boxes that another static box covers: internal edges of floors laid in tiles.

Each box is collided on its own, so where two static boxes meet flush (a floor of two slabs) the
far box's side face and its top edge along the seam are features to the narrow phase, though the
near box covers them.  A body resting on the near box sits the soft contact's sag below the far
box's top; the far box's edge is then the nearest feature, its normal tilted back towards the
body, and with the step's motion in the speculative margin that contact is a ramp: a ball
rolling across the seam at 8 m/s was thrown 0.87 m up, a cube sliding at 5 m/s stopped at it.

So at build, for every static box, each of its six faces is marked covered when a face of
another static box lies on it, facing it, and contains it (within COVER_TOLERANCE): no body can
touch a covered face without first passing into the box that covers it, which has its own
contacts.  The narrow phase then keeps its normals off covered faces (primitives.py: a sphere's
offset loses its components through them; box-box drops separating axes that point through
them), the way Jolt's active edges and Bullet's internal-edge utility do for meshes.  A face
only partly covered (a step between slabs of different heights, a smaller tile) stays a face.
Static bodies never move, so the mask is computed once; dynamic boxes have none.

Mask bits: bit 2 k is the face at +half_k along the box's axis k, bit 2 k + 1 the one at -half_k.
"""

from __future__ import annotations

import numpy as np
import warp as wp

COVER_TOLERANCE = 1.0e-4  # [m] two faces closer than this, and corners this far outside, still meet


def face_bit(axis: int, side: float) -> int:
    return 1 << (2 * axis + (0 if side > 0 else 1))


def covered_faces(shape: np.ndarray, half: np.ndarray, position: np.ndarray, rot: np.ndarray,
                  static: np.ndarray, box_shape: int, ground_plane=None) -> np.ndarray:
    """The covered-face mask of every body (0 for spheres and dynamic bodies).  Candidates are
    found by sorting the static boxes along x, so a floor of N tiles costs about N^1.5 tests.
    ``ground_plane`` (a PlaneTerrain, or None): a face lying wholly in its solid half-space, to
    within COVER_TOLERANCE, is covered by the ground, like a box's sides where it is set flush
    into the plane (a ball rolling from the plane onto such a box hopped 19 mm at 2 m/s).  On the
    Fourier terrain no face counts as covered by the ground: between sample points the surface
    could rise above it."""
    n = len(shape)
    mask = np.zeros(n, np.int32)
    boxes = np.flatnonzero((shape == box_shape) & static)
    if ground_plane is not None:
        for b in boxes:
            mask[b] |= _under_ground(half[b], position[b], rot[b], ground_plane)
    if len(boxes) < 2:
        return mask
    centre = position[boxes].astype(np.float64)
    radius = np.linalg.norm(half[boxes].astype(np.float64), axis=1)
    order = np.argsort(centre[:, 0], kind="stable")
    sorted_x = centre[order, 0]
    reach = radius.max() + COVER_TOLERANCE
    for a in range(len(boxes)):
        lo = np.searchsorted(sorted_x, centre[a, 0] - radius[a] - reach, "left")
        hi = np.searchsorted(sorted_x, centre[a, 0] + radius[a] + reach, "right")
        near = order[lo:hi]
        near = near[(near != a) & (np.linalg.norm(centre[near] - centre[a], axis=1)
                                   <= radius[near] + radius[a] + COVER_TOLERANCE)]
        if len(near):
            mask[boxes[a]] |= _covered_by(boxes[a], boxes[near], half, position, rot)
    return mask


def _under_ground(half, position, rot, plane) -> int:
    """Which faces of one box lie wholly in the plane's solid half-space n . p <= offset."""
    bits = 0
    for axis in range(3):
        for side in (1.0, -1.0):
            face = _face(half, position, rot, axis, side)
            if np.all(plane.signed_distance(_corners(*face)) <= COVER_TOLERANCE):
                bits |= face_bit(axis, side)
    return bits


def _face(half: np.ndarray, position: np.ndarray, rot: np.ndarray, axis: int, side: float):
    """Centre, outward normal, in-plane axes (two columns) and their half lengths of one face."""
    r = rot.astype(np.float64)
    h = half.astype(np.float64)
    normal = side * r[:, axis]
    u, v = [(axis + 1) % 3, (axis + 2) % 3]
    return position.astype(np.float64) + h[axis] * normal, normal, (r[:, u], r[:, v]), (h[u], h[v])


def _corners(centre, normal, axes, halves) -> np.ndarray:
    """The four corners of a face given as _face returns it."""
    (u, v), (hu, hv) = axes, halves
    return np.array([centre + su * hu * u + sv * hv * v for su in (-1, 1) for sv in (-1, 1)])


def _covered_by(b: int, neighbours: np.ndarray, half, position, rot) -> int:
    """Which faces of box b a face of one of ``neighbours`` covers (see the module docstring)."""
    bits = 0
    for axis in range(3):
        for side in (1.0, -1.0):
            face = _face(half[b], position[b], rot[b], axis, side)
            centre, normal = face[0], face[1]
            corners = _corners(*face)
            for a in neighbours:
                if _one_face_covers(a, centre, normal, corners, half, position, rot):
                    bits |= face_bit(axis, side)
                    break
    return bits


def _one_face_covers(a: int, centre, normal, corners, half, position, rot) -> bool:
    for axis in range(3):
        for side in (1.0, -1.0):
            c, n, (u, v), (hu, hv) = _face(half[a], position[a], rot[a], axis, side)
            if np.dot(n, normal) > -1.0 + 1.0e-6 or abs(np.dot(centre - c, n)) > COVER_TOLERANCE:
                continue  # not facing it, or not on its plane
            if all(abs(np.dot(p - c, u)) <= hu + COVER_TOLERANCE and abs(np.dot(p - c, v)) <= hv + COVER_TOLERANCE
                   for p in corners):
                return True
    return False


# A separating axis leaning this little out through a covered face is still allowed: rounding of
# an aligned box's axes, not a feature of the covered face.
COVERED_COMPONENT = wp.constant(1.0e-3)


@wp.func
def face_covered(mask: int, axis: int, side: float) -> bool:
    """Whether the face at side * half_axis along the box's axis ``axis`` is covered."""
    bit = 2 * axis
    if side < 0.0:
        bit += 1
    return (mask >> bit) & 1 != 0


@wp.func
def points_through_covered(mask: int, rot: wp.mat33, normal: wp.vec3) -> bool:
    """Whether the world direction ``normal``, leaving the box, has a component out through one of
    its covered faces: such a normal would come from a covered face or from an edge it bounds."""
    if mask == 0:
        return False
    local = wp.transpose(rot) * normal
    for k in range(3):
        if wp.abs(local[k]) > COVERED_COMPONENT and face_covered(mask, k, local[k]):
            return True
    return False
