"""Preallocated contact storage.

Two parts, because the two kinds of contact have different shapes:

* Terrain contacts live in fixed *slots*, one per checkpoint (SEED.md 4.3): a sphere owns one
  slot (its closest-point query), a box owns one per checkpoint on its surface.  The slot index
  is the contact's persistent identity, so impulses warm-start with no matching step, and the
  per-body solver finds a body's contacts as a contiguous range.  Slots cannot overflow.
* Body-body contacts follow the broad phase's sorted candidate pairs: pair p owns point slots
  4p .. 4p+3 (a manifold has at most 4 points), so the narrow phase writes without any shared
  counter (Warp's CPU atomics are not safe across the chunks of ``warp_sim.launch``).  The
  buffer holds ``pair_max`` pairs; the Simulator grows it when more candidates are found
  (``grow_pairs``), or, with an explicit ``contact_max``, stops with a ``ContactOverflowError``
  naming the capacity and the demand.  Last substep's pairs, features and impulses are kept in
  ``prev_*`` arrays so new points inherit the impulses of the same features (warm starting).

Sign convention (shared with the collision functions): ``depth`` > 0 is penetration, < 0 a
speculative gap; ``normal`` points from the other object (terrain, or body j of pair (i, j))
into the body (body i).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .collide.still_contacts import NO_ANCHOR
from .schedule.coloring import COLOR_COUNT

POINTS_PER_PAIR = 4


class ContactOverflowError(RuntimeError):
    pass


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
        terrain_contact_count: active slots per body (the CPU slab partition weighs bodies by it).
        pair_body: (i, j), i < j, per candidate pair (a copy of the broad phase's sorted list).
        pair_count: candidate pairs this substep, int32[1]; pair_point_count: points per pair.
        pair_normal: per pair, from body j into body i.
        pair_point, pair_depth, pair_feature: per point slot (4 per pair).
        pair_normal_impulse, pair_tangent_impulse: solver accumulators per point.
    Terrain contacts are counted on demand from the slots (``count``): the physics never needs
    the number, so the kernels pay no atomic for it.
    """

    def __init__(self, slot_count: int, pair_max: int, device, body_count: int = 0):
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
        self.terrain_contact_count = wp.zeros(max(body_count, 1), dtype=wp.int32, device=device)
        self.terrain_contact_anchor_pos = wp.full(max(body_count, 1), wp.vec3(NO_ANCHOR), dtype=wp.vec3, device=device)
        self.terrain_contact_anchor_quat = wp.zeros(max(body_count, 1), dtype=wp.quat, device=device)
        self.device = device
        self._alloc_pairs(pair_max)

    def _alloc_pairs(self, pair_max: int):
        device = self.device
        self.pair_max = pair_max
        m = max(pair_max, 1)
        k = m * POINTS_PER_PAIR
        self.pair_count = wp.zeros(1, dtype=wp.int32, device=device)
        self.pair_demand = wp.zeros(1, dtype=wp.int64, device=device)
        self.pair_body = wp.zeros(m, dtype=wp.vec2i, device=device)
        self.pair_point_count = wp.zeros(m, dtype=wp.int32, device=device)
        self.pair_normal = wp.zeros(m, dtype=wp.vec3, device=device)
        self.pair_point = wp.zeros(k, dtype=wp.vec3, device=device)
        self.pair_depth = wp.zeros(k, dtype=float, device=device)
        self.pair_feature = wp.zeros(k, dtype=wp.int32, device=device)
        self.pair_normal_impulse = wp.zeros(k, dtype=float, device=device)
        self.pair_tangent_impulse = wp.zeros(k, dtype=wp.vec3, device=device)
        # 1 where the pair's last relax let go of enough push to walk it down to the ground
        # (pair_solve.relax_chain_needed; written by pair_pass, read by chain_pass)
        self.pair_relax_chain = wp.zeros(m, dtype=wp.int32, device=device)
        # 1 where the substep's impact stage found that a ball and a spinning box the rows see
        # closing pass clear in free motion (pair_geometry.sphere_box_passes_clear): its solve
        # rows let go.  Reset by pair_contact_times, written by the pair's impact thread.
        self.pair_passes_clear = wp.zeros(m, dtype=wp.int32, device=device)
        # the patch of the pair's points for the substep, written by its warm start: centre and the
        # scale of its friction rows' arms (collide/contact_patch.py)
        self.pair_twist = wp.zeros(m, dtype=wp.vec4, device=device)
        # times the pair was found again mid-step since the pass that found it (solvers/
        # pair_refresh.py; the pass writes 0): one writer per pair, a sum and not a shared counter
        self.pair_refresh_count = wp.zeros(m, dtype=wp.int32, device=device)
        self.prev_pair_count = wp.zeros(1, dtype=wp.int32, device=device)
        self.prev_pair_body = wp.zeros(m, dtype=wp.vec2i, device=device)
        self.prev_pair_point_count = wp.zeros(m, dtype=wp.int32, device=device)
        self.prev_pair_feature = wp.zeros(k, dtype=wp.int32, device=device)
        self.prev_pair_normal = wp.zeros(m, dtype=wp.vec3, device=device)
        self.prev_pair_point = wp.zeros(k, dtype=wp.vec3, device=device)
        self.prev_pair_normal_impulse = wp.zeros(k, dtype=float, device=device)
        self.prev_pair_tangent_impulse = wp.zeros(k, dtype=wp.vec3, device=device)
        # graph colouring of the pairs (schedule/coloring.py): colour c holds
        # color_pairs_sorted[color_start[c]:color_start[c + 1]]; the last colour is the overflow set
        self.color_start = wp.zeros(COLOR_COUNT + 2, dtype=wp.int32, device=device)
        self.color_pairs_sorted = wp.zeros(m, dtype=wp.int32, device=device)

    def grow_pairs(self, pair_max: int):
        """Room for ``pair_max`` pairs; last pass's pairs (the warm-start source) move over."""
        keep = [self.prev_pair_count, self.prev_pair_body, self.prev_pair_point_count, self.prev_pair_feature,
                self.prev_pair_normal, self.prev_pair_point, self.prev_pair_normal_impulse, self.prev_pair_tangent_impulse]
        self._alloc_pairs(pair_max)
        for dst, src in zip([self.prev_pair_count, self.prev_pair_body, self.prev_pair_point_count,
                             self.prev_pair_feature, self.prev_pair_normal, self.prev_pair_point, self.prev_pair_normal_impulse,
                             self.prev_pair_tangent_impulse],
                            keep):
            wp.copy(dst, src, count=min(dst.size, src.size))

    def forget_anchors(self):
        """No body's terrain slots are carried at the next pass: every one is searched in full
        (collide/still_contacts.py; after the model or the settings changed)."""
        self.terrain_contact_anchor_pos.fill_(wp.vec3(NO_ANCHOR))

    def count(self) -> int:
        terrain = int(np.count_nonzero(self.terrain_contact_active.numpy()[: self.slot_count]))
        pairs = int(self.pair_count.numpy()[0]) if self.pair_max > 0 else 0
        return terrain + int(self.pair_point_count.numpy()[:pairs].sum())

    def check_overflow(self):
        if self.pair_max == 0:
            return
        demand = int(self.pair_demand.numpy()[0])
        if demand > self.pair_max:
            raise ContactOverflowError(
                f"contact buffer overflow: {demand} body-body candidate pairs found, capacity "
                f"contact_max={self.pair_max}; raise [sim] contact_max"
            )

    def active_terrain_depths(self) -> np.ndarray:
        active = self.terrain_contact_active.numpy()[: self.slot_count] != 0
        return self.terrain_contact_depth.numpy()[: self.slot_count][active]
