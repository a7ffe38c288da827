"""A still body's terrain contacts are carried to its new pose, not searched for again.

Finding a body's terrain contacts costs Fourier evaluations: a sphere's warm-started closest-point
search, a box's sample under its centre and one or more on every checkpoint of its support face
(face_search.py).  In a pile that has come to rest most bodies move micrometres a step, and the
search finds what it found the step before.  So ``collide_terrain`` keeps, per body, the pose at
which its slots were last found (``terrain_contact_anchor_pos`` / ``_quat``), and a body that is
still at the next pass has its active slots carried to the pose it has now, with no evaluation:

    point' = the slot's point at the new pose (a box's checkpoint x + R p_local; a sphere's
             x - r n),       depth' = depth - n . (point' - point),

the normal kept.  A body is still when (1) every point of it lies within ``STILL_TRAVEL`` of where
it was at the anchor pose, bounded by |x - x_a| + 2 |vec(q_a^-1 q)| R (the chord a turn by the
angle theta sweeps at radius R is 2 sin(theta / 2) R, and |vec(q)| = sin(theta / 2)), and (2) its
points move slower than ``STILL_SPEED``.

Why the carried contacts are the searched ones, to within what:

- Depth.  A point displaced by d along the surface changes (H - p_y) n_y by n . d up to the
  curvature's k |d|^2 / 2, under 1e-9 m at the travel allowed (k below 1 / m on any terrain a
  ball rests on).  A face's climbed depth (face_search.py) is the depth at the cell's deepest
  point, whose displacement differs from the checkpoint's by the turn times their distance, at
  most half a cell's diagonal: under STILL_TRAVEL / 2 = 1e-5 m, the climb's own resolution
  (face_search.FACE_SEARCH_GAIN).
- Slots that stay closed.  A slot is open while depth > -(margin + h a + h^2 g), a the point's
  approach speed (terrain_contact.py).  A point that moved at most STILL_TRAVEL changes its depth
  by at most sqrt(1 + G^2) STILL_TRAVEL (G the slope bound; the closest distance of a sphere by at
  most the travel), so a slot closed at the anchor stays closed if its window was found with an
  approach of at least STILL_SPEED + sqrt(1 + G^2) STILL_TRAVEL / h (``window_floor``) and the
  point now approaches slower than STILL_SPEED.  Every body's windows take that floor while
  carrying is on (0.19 mm more window at dt 1/60 s on a 20 mm margin): a body that was not still
  at its last search may be still at the next.  The cull of a box's checkpoints bounds the same
  window, so it too stays valid.
- Open slots are tested again at the new pose with the new speeds, as a search would test them.

A body that is not dynamic (static, or asleep with its mass hidden) has no anchor, so it is
searched in full when it wakes; so is any body after ``Contacts.forget_anchors`` (the simulator
calls it when the model or the settings change, ``Simulator.invalidate_graph``) and a sphere
whose slots were found again between a step's passes (``refresh_spheres``).  The diagnostics'
own searches (``Simulator.max_penetration``) never carry.  ``SimConfig.still_contacts = false``
searches every body every pass.
"""

import warp as wp

from ..kernel_args import TerrainContacts

wp.set_module_options({"enable_backward": False})

STILL_TRAVEL = wp.constant(2.0e-5)  # [m]
STILL_SPEED = wp.constant(0.01)  # [m/s]
NO_ANCHOR = wp.constant(1.0e30)  # [m] an anchor position no body is within STILL_TRAVEL of


@wp.func
def travel_since(x: wp.vec3, q: wp.quat, anchor_x: wp.vec3, anchor_q: wp.quat, reach: float) -> float:
    """A bound on how far a point of the body within ``reach`` of its centre moved since the anchor."""
    turn = wp.quat_inverse(anchor_q) * q
    return wp.length(x - anchor_x) + 2.0 * wp.length(wp.vec3(turn[0], turn[1], turn[2])) * reach


@wp.func
def window_floor(h: float, gap_scale: float) -> float:
    """The approach speed every window is found with while carrying is on (module docstring)."""
    return STILL_SPEED + gap_scale * STILL_TRAVEL / h


@wp.func
def closable_gap(point_vel: wp.vec3, normal: wp.vec3, reach_speed: float, floor: float, speculative_margin: float,
                 h: float, gravity_length: float) -> float:
    """The gap a slot's point can close within h (terrain_contact.py: its window), its approach
    speed at least the box's reach speed and the floor."""
    approach = wp.max(wp.max(wp.max(-wp.dot(point_vel, normal), 0.0), reach_speed), floor)
    return speculative_margin + h * approach + h * h * gravity_length


@wp.func
def close_slot(contacts: TerrainContacts, slot: int):
    """An idle slot holds no impulse to warm-start from."""
    contacts.terrain_contact_active[slot] = 0
    contacts.terrain_contact_normal_impulse[slot] = 0.0
    contacts.terrain_contact_tangent_impulse[slot] = wp.vec3(0.0)


@wp.func
def carry_still_contacts(
    start: int,
    count: int,
    x: wp.vec3,
    rot: wp.mat33,
    v: wp.vec3,
    omega: wp.vec3,
    radius: float,
    is_sphere: bool,
    reach_speed: float,
    h: float,
    gravity_length: float,
    speculative_margin: float,
    floor: float,
    checkpoint_local: wp.array(dtype=wp.vec3),
    contacts: TerrainContacts,
) -> int:
    """The body's open slots carried to the pose (x, rot) and tested again; returns how many stay open."""
    active = int(0)
    for slot in range(start, start + count):
        if contacts.terrain_contact_active[slot] == 0:
            continue
        normal = contacts.terrain_contact_normal[slot]
        point = x - radius * normal
        if not is_sphere:
            point = x + rot * checkpoint_local[slot]
        depth = contacts.terrain_contact_depth[slot] - wp.dot(normal, point - contacts.terrain_contact_point[slot])
        point_vel = v + wp.cross(omega, point - x)
        if depth > -closable_gap(point_vel, normal, reach_speed, floor, speculative_margin, h, gravity_length):
            active += 1
            contacts.terrain_contact_point[slot] = point
            contacts.terrain_contact_depth[slot] = depth
        else:
            close_slot(contacts, slot)
    return active
