"""Pairs found again mid-step where their bodies have turned or slid (``SimConfig.turn_refresh``).

Contacts found once per step serve every substep as a linearisation about the step's reference
pose (pair_geometry.py): each point is a material point of both bodies, the normal is fixed and
the gap grows by how far the two anchors have moved apart along it.  That is exact for a
translation and good for small turns, but a body turning by theta swings its far side by
theta r, and the points found at the start are the wrong ones by then: a thin plate landing on
a corner spins up, its opposite edge swings down into the plate below, and that edge was never a
point of the manifold (or was dropped as too far).  In a rain of plates (half 0.3 x 0.1 x 0.3)
that is most of the depth the once-per-step contacts leave: contacts found every substep
cut the deepest pair in a 10-plate column drop from 1.4-1.8 cm to 0.9-1.3 cm, and at 8 substeps
from 1.3-2.8 cm to 0.2-0.5 cm, while more substeps or sweeps with the step's manifold did not help.

So before each later substep, a pair whose bodies have turned or slid by more than the tolerance
since the pass (theta_i r_i + theta_j r_j, r the bounding radius: how far a surface point can have
swung, plus, for a sphere or along a static body, how far the two centres have moved relative to
each other: a point slid along a face stays right, but not once it passes the face's edge, where a
ball rolling off a table was held at the table's height for a whole step; between two dynamic
boxes, the part of that motion along the contact plane, which leaves each body's anchors behind
its face) is collided again at the
current pose, and only that pair: in a settled pile nothing turns or slides and nothing is found
again. Two spheres are never refreshed (their normal and gap follow the centres, exactly), and a
sphere's own turn counts for nothing; a box turning under or beside a sphere does count: its face
tilts under the sphere's fixed normal and the point slides off the face the pass found (in
`mixed_rain.toml`, boxes 0.5 x 0.3 x 0.2 m and balls r 0.2, every pair deeper than 2 cm was a
sphere-box pair until these were refreshed too: 75 mm -> 20 mm).
A sphere's pair keeps its second slot's rolling-resistance impulse through the refresh.

The drift that places a refreshed point is the one the solver reads (soft_step.drift_rotation): a
box's points turn with it, a sphere's anchor is its support point, which the ball's own spin does
not move. Turning it with the ball had lifted a ball rolling on a refreshed pair by r (1 - cos
theta), theta its spin since the pass: 17 mm at 8 m/s on a plank turning 0.5 rad/s, 12 to 45 mm for
fast balls leaving a table's edge. In the mixed rain that lift had also acted as a spurious margin
between spinning balls and boxes: without it the deepest pair while landing is about what contacts
found every substep give (7 to 8 mm against 4.3 to 4.8 mm; every substep 5.6 to 8.4).

The new manifold is written in the reference representation the solver reads, so nothing else
changes: for a point p found now with depth d and normal n, with the bodies displaced by dp_i,
dp_j and turned by D_i, D_j (D = R R_ref^T - I) since the reference pose, store

    point   p_ref = p - (w dp_i + (1 - w) dp_j)        (w: pair_geometry.anchor_weight)
    depth   d_ref = d + n . moved(p_ref),   moved(p) = (dp_i + D_i (p - x_i)) - (dp_j + D_j (p - x_j))

(x the reference centres).  pair_point_now then gives exactly the arms p - x_i', p - x_j' from
the current centres and the gap -d now, and tracks later motion from there.  Each new point
takes the accumulated impulses of the old point with its feature id, else the nearest unclaimed
one on the same faces (narrow_phase.match_old_points), so the warm start survives the refresh.
"""

import warp as wp

from ..launch import launch
from ..collide.contact_patch import pair_patch
from ..collide.narrow_phase import POINTS, match_old_points
from ..collide.primitives import SHAPE_SPHERE, collide_pair, mat43, reference_body
from .pair_geometry import anchor_weight
from .soft_step import drift_rotation

wp.set_module_options({"enable_backward": False})


@wp.func
def turn_angle(rot: wp.mat33, ref_rot: wp.mat33) -> float:
    """Angle of the rotation R R_ref^T: its trace is the sum of the columns' dot products."""
    trace = float(0.0)
    for k in range(3):
        trace += wp.dot(wp.vec3(rot[0, k], rot[1, k], rot[2, k]), wp.vec3(ref_rot[0, k], ref_rot[1, k], ref_rot[2, k]))
    return wp.acos(wp.clamp(0.5 * (trace - 1.0), -1.0, 1.0))


@wp.func
def anchor_shift(w: float, closing: float, turn_along_n: float) -> float:
    """How far along n to move a refreshed point so that pair_point_now's anchor, (w - 1/2) of the
    stored gap off the point, is (w - 1/2) of the gap found now: with c = n . (D_i - D_j) n the
    stored gap grows by c per unit shift, so delta = (w - 1/2) (n . moved + c delta), solved
    exactly.  (|w - 1/2| c reaches 1 only for a body turned half a revolution in one step.)"""
    den = 1.0 - (w - 0.5) * turn_along_n
    if den < 0.5:
        return 0.0
    return (w - 0.5) * closing / den


@wp.kernel
def refresh_turned_pairs(
    tid_offset: int,
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_size: wp.array(dtype=wp.vec3),
    body_bound_radius: wp.array(dtype=float),
    body_covered_faces: wp.array(dtype=wp.int32),
    body_inv_mass: wp.array(dtype=float),
    # Settings
    margin: float,
    turn_tolerance: float,
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    # Solver in
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_ref_rot: wp.array(dtype=wp.mat33),
    # Broad phase in
    body_reach: wp.array(dtype=float),
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    # Contacts in and out (this pair's own slots only)
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_feature: wp.array(dtype=wp.int32),
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    pair_refresh_count: wp.array(dtype=wp.int32),
    measure_patch: int,
    pair_twist: wp.array(dtype=wp.vec4),
):
    p = wp.tid() + tid_offset
    if p >= pair_count[0]:
        return
    if pair_point_count[p] == 0:
        # the schedules leave out pairs the pass found no point for: beyond the pair margin,
        # which covers the step's motion, they cannot touch before the next pass
        return
    ij = pair_body[p]
    i = ij[0]
    j = ij[1]
    sphere_i = body_shape[i] == SHAPE_SPHERE
    sphere_j = body_shape[j] == SHAPE_SPHERE
    if sphere_i and sphere_j:
        return
    # a sphere's own turn moves none of its surface; the two centres' relative slide moves the
    # contact along the features the pass found, exact on a face but not past its edge (a ball
    # rolling off a table at 2 m/s was held at the table's height for a whole step after its
    # centre had passed the edge, 40 mm above the parabola).  For a sphere on anything and a box on
    # a static body the whole relative motion counts.  Between two dynamic boxes only its part
    # along the contact plane: a point is anchored partly on each body (anchor_weight), so a slide
    # leaves it behind on each by that body's share, while motion along n is the gap itself, which
    # the rows follow exactly.  Not counted, a 4 cm cube that had slid 12 cm along a free plate since
    # the pass was pushed at points outside its own face, spun at 380 rad/s and went through it
    slide = (body_pos[i] - solver_ref_pos[i]) - (body_pos[j] - solver_ref_pos[j])
    if body_inv_mass[i] > 0.0 and body_inv_mass[j] > 0.0 and not sphere_i and not sphere_j:
        n = pair_normal[p]
        slide = slide - wp.dot(slide, n) * n
    swing = wp.length(slide)
    if not sphere_i:
        swing += turn_angle(body_rot[i], solver_ref_rot[i]) * body_bound_radius[i]
    if not sphere_j:
        swing += turn_angle(body_rot[j], solver_ref_rot[j]) * body_bound_radius[j]
    if swing <= turn_tolerance:
        return
    # the pass's margin (collide_pairs): the reaches still cover the rest of the step
    pair_margin = margin + (body_reach[i] - body_bound_radius[i]) + (body_reach[j] - body_bound_radius[j])
    m = collide_pair(body_shape[i], body_pos[i], body_rot[i], body_size[i], body_covered_faces[i],
                     body_shape[j], body_pos[j], body_rot[j], body_size[j], body_covered_faces[j], pair_margin,
                     reference_body(body_inv_mass[i], body_inv_mass[j]))
    xi = solver_ref_pos[i]
    xj = solver_ref_pos[j]
    dpi = body_pos[i] - xi
    dpj = body_pos[j] - xj
    # as the solver reads them (soft_step.drift_rotation): a sphere's anchor is its support point,
    # which its own turn does not move
    turn_i = drift_rotation(body_shape[i], body_rot[i], solver_ref_rot[i])
    turn_j = drift_rotation(body_shape[j], body_rot[j], solver_ref_rot[j])
    w = anchor_weight(wp.where(sphere_i, 1.0, 0.0), wp.where(sphere_j, 1.0, 0.0), body_inv_mass[i], body_inv_mass[j])
    point = mat43()
    depth = wp.vec4(0.0)
    for k in range(m.count):
        at = wp.vec3(m.point[k, 0], m.point[k, 1], m.point[k, 2]) - (w * dpi + (1.0 - w) * dpj)
        moved = (dpi + turn_i * (at - xi)) - (dpj + turn_j * (at - xj))
        at = at + anchor_shift(w, wp.dot(moved, m.normal), wp.dot(m.normal, (turn_i - turn_j) * m.normal)) * m.normal
        moved = (dpi + turn_i * (at - xi)) - (dpj + turn_j * (at - xj))
        point[k] = at
        depth[k] = m.depth[k] + wp.dot(moved, m.normal)
    # the warm start: the old points are this pair's own slots, read before they are rewritten
    source = match_old_points(m.count, m.feature, point, m.normal, p, pair_point_count[p], pair_feature,
                              pair_normal, pair_point)
    normal_impulse = wp.vec4(0.0)
    tangent_impulse = mat43()
    for k in range(m.count):
        if source[k] >= 0:
            normal_impulse[k] = pair_normal_impulse[p * POINTS + source[k]]
            tangent_impulse[k] = pair_tangent_impulse[p * POINTS + source[k]]
    if sphere_i or sphere_j:
        # a sphere's pair has one point; its second slot keeps the rolling resistance's impulse
        tangent_impulse[1] = pair_tangent_impulse[p * POINTS + 1]
    pair_point_count[p] = m.count
    pair_normal[p] = m.normal
    for k in range(POINTS):
        slot = p * POINTS + k
        pair_point[slot] = wp.vec3(point[k, 0], point[k, 1], point[k, 2])
        pair_depth[slot] = depth[k]
        pair_feature[slot] = m.feature[k]
        pair_normal_impulse[slot] = normal_impulse[k]
        pair_tangent_impulse[slot] = wp.vec3(tangent_impulse[k, 0], tangent_impulse[k, 1], tangent_impulse[k, 2])
    pair_refresh_count[p] = pair_refresh_count[p] + 1
    # the new points' patch (collide/contact_patch.py), from the impulses they took over
    if measure_patch != 0:
        pair_twist[p] = pair_patch(p, m.count, pair_normal, pair_point, pair_depth, pair_normal_impulse)


def refresh_turned(model, state, solver, pairs, contacts, margin: float, tolerance: float):
    """Before a later substep of a once-per-step scene: every pair whose bodies have turned by
    more than ``tolerance`` since the step's pass, collided again at ``state``'s pose.  The pair
    list, colours and slabs do not change; ``contacts.pair_refresh_count`` counts each pair's
    refreshes since the pass that found it."""
    c = contacts
    launch(refresh_turned_pairs, pairs.live_dim, key=pairs, inputs=[
        model.body_shape, model.body_size, model.body_bound_radius, model.body_covered_faces, model.body_inv_mass, margin,
        tolerance,
        state.body_pos, state.body_rot, solver.solver_ref_pos, solver.solver_ref_rot, pairs.body_reach,
        c.pair_count, c.pair_body, c.pair_point_count, c.pair_normal, c.pair_point, c.pair_depth, c.pair_feature,
        c.pair_normal_impulse, c.pair_tangent_impulse, c.pair_refresh_count,
        int(solver.settings.face_friction == "patch"), c.pair_twist], device=state.body_pos.device)
