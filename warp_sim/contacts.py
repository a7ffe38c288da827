"""Preallocated contact storage.

Two parts, because the two kinds of contact have different shapes:

* Terrain contacts live in fixed *slots*, one per checkpoint (SEED.md 4.3): a sphere owns one
  slot (its closest-point query), a box owns one per checkpoint on its surface.  The slot index
  is the contact's persistent identity, so impulses warm-start with no matching step, and the
  per-body solver finds a body's contacts as a contiguous range.  Slots cannot overflow.
* Body-body contacts are appended through an atomic counter into a buffer of ``pair_max``
  entries.  An append past the end is dropped and counted; ``check_overflow`` turns that into
  a ``ContactOverflowError`` naming the capacity and the demand.

Sign convention (shared with the collision functions): ``depth`` > 0 is penetration, < 0 a
speculative gap; ``normal`` points from the other object (terrain or body1) into body0.
"""

from __future__ import annotations

import numpy as np
import warp as wp


class ContactOverflowError(RuntimeError):
    pass


@wp.func
def contact_append(contact_pair_count: wp.array(dtype=wp.int32), pair_max: int) -> int:
    """Reserve one pair-contact index; -1 when the buffer is full (the counter still grows).

    Atomic on CUDA and within one CPU launch; not across the chunks of ``warp_sim.launch``
    (Warp's CPU atomics are plain read-modify-write), so launch appending kernels whole.
    """
    index = wp.atomic_add(contact_pair_count, 0, 1)
    if index >= pair_max:
        return -1
    return index


class Contacts:
    """Terrain contact slots plus the body-body pair buffer.

    Attributes:
        terrain_contact_active: 1 where the slot holds a contact this substep.
        terrain_contact_point: world point on the body [m].
        terrain_contact_normal: unit normal from the terrain into the body.
        terrain_contact_depth: penetration [m] (> 0 inside, < 0 speculative gap).
        terrain_contact_normal_impulse: accumulated normal impulse [N s], kept for warm start.
        terrain_contact_tangent_impulse: accumulated friction impulse, world vec3 [N s].
        terrain_contact_surface: (x, z) of the last closest surface point (sphere warm start).
        terrain_contact_approach: normal velocity before solving [m/s] (restitution target).
        contact_pair_count: pair contacts requested this substep, counted atomically (may
            exceed ``pair_max``; ``check_overflow`` reports that).
    Terrain contacts are counted on demand from the slots (``count``): the physics never needs
    the number, so the kernels pay no atomic for it.
    """

    def __init__(self, slot_count: int, pair_max: int, device):
        self.slot_count = slot_count
        self.pair_max = pair_max
        n = max(slot_count, 1)
        self.terrain_contact_active = wp.zeros(n, dtype=wp.int32, device=device)
        self.terrain_contact_point = wp.zeros(n, dtype=wp.vec3, device=device)
        self.terrain_contact_normal = wp.zeros(n, dtype=wp.vec3, device=device)
        self.terrain_contact_depth = wp.zeros(n, dtype=float, device=device)
        self.terrain_contact_normal_impulse = wp.zeros(n, dtype=float, device=device)
        self.terrain_contact_tangent_impulse = wp.zeros(n, dtype=wp.vec3, device=device)
        self.terrain_contact_surface = wp.zeros(n, dtype=wp.vec2, device=device)
        self.terrain_contact_approach = wp.zeros(n, dtype=float, device=device)
        self.contact_pair_count = wp.zeros(1, dtype=wp.int32, device=device)
        m = max(pair_max, 1)
        self.contact_body0 = wp.zeros(m, dtype=wp.int32, device=device)
        self.contact_body1 = wp.zeros(m, dtype=wp.int32, device=device)
        self.contact_point = wp.zeros(m, dtype=wp.vec3, device=device)
        self.contact_normal = wp.zeros(m, dtype=wp.vec3, device=device)
        self.contact_depth = wp.zeros(m, dtype=float, device=device)

    def clear_counts(self):
        self.contact_pair_count.zero_()

    def count(self) -> int:
        terrain = int(np.count_nonzero(self.terrain_contact_active.numpy()[: self.slot_count]))
        return terrain + min(int(self.contact_pair_count.numpy()[0]), self.pair_max)

    def check_overflow(self):
        requested = int(self.contact_pair_count.numpy()[0])
        if requested > self.pair_max:
            raise ContactOverflowError(
                f"contact buffer overflow: {requested} body-body contacts requested, capacity "
                f"pair_max={self.pair_max}; raise [sim] contact_max"
            )

    def active_terrain_depths(self) -> np.ndarray:
        active = self.terrain_contact_active.numpy()[: self.slot_count] != 0
        return self.terrain_contact_depth.numpy()[: self.slot_count][active]
