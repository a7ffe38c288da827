"""Body-body contact, found once per step or per substep (SimConfig.contact_update):
broad phase -> narrow phase -> warm-start carry -> colouring.

Owned by the Simulator when the scene has body-body contact.  Every stage is a kernel.  With
``capturable`` set (graph capture, and always on CUDA) nothing is read back: every launch is
sized by the capacity and the solver's colour launches by per-colour upper bounds
(coloring.PairColoring.launch_bounds), their threads past the live count returning at once.
Direct CPU stepping reads the live pair count and the colour sizes back instead, which is
cheap there and spares launches of idle threads; the CPU slab schedule (solvers/domains.py)
reads its two slab counts back and so is never captured.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..launch import LIGHT_CHUNK, launch
from ..schedule.coloring import COLOR_COUNT, PairColoring
from ..schedule.slabs import BINS, partition_domains
from .broad_phase import make_broad_phase
from .narrow_phase import carry_pair_impulses, collide_pairs, store_pairs, swept_reach, swept_reach_from_reference


class PairContactPipeline:
    def __init__(self, model, broad_phase: str, capacity: int, device, domain_count: int = 0, colors: bool = True):
        """``domain_count`` > 0 also cuts the scene into that many slabs for the CPU solver
        schedule (solvers/domains.py); 0 leaves the colouring as the only schedule.  ``colors``:
        colour the pairs even then (for sleeping and push-out, which walk colours)."""
        self.model = model
        self.device = device
        self.capacity = capacity
        self.broad = make_broad_phase(broad_phase, model.body_count, capacity, device)
        n = max(model.body_count, 1)
        self.coloring = PairColoring(model.body_count, capacity, device)
        self.capturable = not wp.get_device(device).is_cpu
        self.live_dim = self.capacity  # threads of the pair launches (the live count when not capturable)
        self.body_reach = wp.zeros(n, dtype=float, device=device)
        self.domain_count = domain_count
        self.colors = colors or domain_count == 0
        self.color_overflow_reported = False
        self.schedule = None
        # each pair's patch, where its friction acts (contact_patch.py; SimConfig.face_friction)
        self.measure_patch = True
        if domain_count > 0:
            d = domain_count
            self.body_weight = wp.zeros(n, dtype=float, device=device)
            self.body_domain = wp.zeros(n, dtype=wp.int32, device=device)
            self.bin_weight = wp.zeros(BINS, dtype=float, device=device)
            self.bin_work_before = wp.zeros(BINS + 1, dtype=float, device=device)
            self.bin_crossing = wp.zeros(BINS + 1, dtype=wp.int32, device=device)
            self.bin_domain = wp.zeros(BINS, dtype=wp.int32, device=device)
            self.domain_cursor = wp.zeros(d + 1, dtype=wp.int32, device=device)
            self.domain_body_start = wp.zeros(d + 2, dtype=wp.int32, device=device)
            self.domain_body = wp.zeros(n, dtype=wp.int32, device=device)
            self.domain_pair_start = wp.zeros(d + 2, dtype=wp.int32, device=device)
            self.domain_pair = wp.zeros(max(capacity, 1), dtype=wp.int32, device=device)
            self.body_on_boundary = wp.zeros(n, dtype=wp.int32, device=device)
            self.boundary_body_count = wp.zeros(1, dtype=wp.int32, device=device)
            self.boundary_body = wp.zeros(n, dtype=wp.int32, device=device)
            self.schedule = DomainSchedule(d, 0, 0, self.domain_body_start, self.domain_body, self.domain_pair_start,
                                           self.domain_pair, self.body_domain, self.body_on_boundary,
                                           self.boundary_body_count, self.boundary_body)

    def collide(self, state, contacts, margin: float, sweep_time: float = 0.0, gravity: float = 0.0,
                on_overflow=None, moved=None, partition: bool = True) -> list[int]:
        """Find the pairs and manifolds of ``state``; returns the pair count of each colour.

        ``on_overflow(demand)``: when not capturable, called once the broad phase has found more
        candidates than the buffer holds, before anything is written to ``contacts``; its result
        is returned instead (the Simulator grows the buffers and collides again).

        ``sweep_time`` is the time until the next collision pass: each body's bounding sphere
        grows by how far it can move in it (narrow_phase.swept_reach; ``gravity`` is |g|), so a
        pair found once per step still covers contacts made late in the step.

        ``moved``: a pass run mid-step (Simulator._recollide_outrun).  ``state`` then holds the
        poses at which the step's contacts were found (the solver's reference) and ``moved`` the
        bodies now (a MovedBodies); the pairs are found at the reference pose, so that every manifold of the step
        is measured from one pose, with reaches grown by the way each body has come since.

        ``partition = False``: the slabs are cut later, by ``partition`` (a pass that finds the terrain
        slots after the pairs: their counts weigh the slabs' work).
        """
        m = self.model
        if moved is None:
            launch(swept_reach, m.body_count, key=self, min_chunk=LIGHT_CHUNK, inputs=[
                m.body_bound_radius, m.body_inv_mass, m.body_inv_inertia, float(sweep_time), float(gravity),
                state.body_rot, state.body_vel, state.body_angmom, self.body_reach], device=self.device)
        else:
            launch(swept_reach_from_reference, m.body_count, key=self, min_chunk=LIGHT_CHUNK, inputs=[
                m.body_bound_radius, m.body_inv_mass, m.body_inv_inertia, float(sweep_time), float(gravity),
                moved.use_solver_velocity, state.body_pos, moved.body_pos, moved.body_rot, moved.body_vel,
                moved.body_angmom, moved.solver_v, moved.solver_w, self.body_reach], device=self.device)
        # the grid cell follows the largest swept radius, found on the device
        self.broad.run(state.body_pos, self.body_reach, m.body_inv_mass, margin, radii_vary=True)
        # direct stepping: threads for the pairs found only (capturable: for the capacity)
        self.live_dim = self.capacity
        if not self.capturable:
            demand = int(self.broad.pair_demand.numpy()[0])
            if demand > self.capacity and on_overflow is not None:
                return on_overflow(demand)
            self.live_dim = max(1, min(demand, self.capacity))
        wp.copy(contacts.pair_count, self.broad.pair_count)
        wp.copy(contacts.pair_demand, self.broad.pair_demand)
        launch(collide_pairs, self.live_dim, key=self, capped=False, inputs=[
            m.body_shape, m.body_size, m.body_bound_radius, m.body_covered_faces, m.body_inv_mass, margin, state.body_pos,
            state.body_rot, self.body_reach,
            self.broad.pair_body, self.broad.pair_count,
            contacts.pair_body, contacts.pair_point_count, contacts.pair_normal, contacts.pair_point,
            contacts.pair_depth, contacts.pair_feature, contacts.pair_refresh_count], device=self.device)
        launch(carry_pair_impulses, self.live_dim, key=self, inputs=[
            contacts.prev_pair_count, contacts.prev_pair_body, contacts.prev_pair_point_count,
            contacts.prev_pair_feature, contacts.prev_pair_normal, contacts.prev_pair_point,
            contacts.prev_pair_normal_impulse, contacts.prev_pair_tangent_impulse,
            contacts.pair_count, contacts.pair_body, contacts.pair_point_count, contacts.pair_feature,
            contacts.pair_normal, contacts.pair_point, contacts.pair_depth, int(self.measure_patch),
            contacts.pair_normal_impulse, contacts.pair_tangent_impulse, contacts.pair_twist],
            device=self.device)
        if self.colors:
            self.coloring.run(m.body_inv_mass, contacts, None if self.capturable else self.live_dim)
        if partition:
            self.partition(state, contacts)
        if not self.colors:
            return [0] * (COLOR_COUNT + 1)  # not coloured: the slabs schedule every pair
        if self.capturable:
            return self.coloring.launch_bounds()
        starts = contacts.color_start.numpy()
        return [int(starts[k + 1] - starts[k]) for k in range(COLOR_COUNT + 1)]

    def partition(self, state, contacts):
        """Cut the slabs of the CPU pair schedule (schedule/slabs.py) for the pairs and terrain slots of
        ``contacts``; nothing without slabs."""
        if self.domain_count == 0:
            return
        m = self.model
        wp.launch(partition_domains, dim=1, device=self.device, inputs=[
            self.domain_count, m.body_inv_mass, state.body_pos,
            contacts.terrain_contact_count, contacts.pair_count, contacts.pair_body, contacts.pair_point_count,
            self.body_weight, self.body_domain, self.bin_weight, self.bin_work_before, self.bin_crossing,
            self.bin_domain, self.domain_cursor,
            self.domain_body_start, self.domain_body, self.domain_pair_start, self.domain_pair,
            self.body_on_boundary, self.boundary_body_count, self.boundary_body])
        bounds = self.domain_pair_start.numpy()
        self.schedule.boundary_pairs = int(bounds[-1] - bounds[-2])
        listed = self.domain_body_start.numpy()
        self.schedule.static_bodies = int(listed[-1] - listed[-2])

    def report_color_overflow(self):
        """Says once (a RuntimeWarning) when a colouring since the last call left pairs to the
        overflow set (solvers/pair_overflow.py)."""
        if not self.colors or not self.coloring.take_overflow() or self.color_overflow_reported:
            return
        self.color_overflow_reported = True
        warnings.warn(f"body-body pairs whose two bodies touch {COLOR_COUNT} or more others between them found "
                      f"no colour of the colour schedule's {COLOR_COUNT}; they are solved after the colours, walked "
                      "in order by one thread or swept with split masses, which converges more slowly "
                      "(SimConfig.overflow_pairs, solvers/pair_overflow.py)",
                      RuntimeWarning, stacklevel=3)

    def domain_schedule(self):
        """What the solver needs to sweep by slab, or None when this pipeline only colours."""
        return self.schedule

    def probe_depth(self, state, probe) -> float:
        """Deepest body-body penetration of ``state`` [m], found afresh (broad + narrow phase only)."""
        m = self.model
        self.broad.run(state.body_pos, m.body_bound_radius, m.body_inv_mass, 0.0)
        launch(collide_pairs, self.capacity, [
            m.body_shape, m.body_size, m.body_bound_radius, m.body_covered_faces, m.body_inv_mass, 0.0, state.body_pos, state.body_rot,
            m.body_bound_radius,
            self.broad.pair_body, self.broad.pair_count,
            probe.pair_body, probe.pair_point_count, probe.pair_normal, probe.pair_point,
            probe.pair_depth, probe.pair_feature, probe.pair_refresh_count], self.device, capped=False)
        count = min(int(self.broad.pair_count.numpy()[0]), self.capacity)
        if count == 0:
            return 0.0
        points = probe.pair_point_count.numpy()[:count]
        depth = probe.pair_depth.numpy()[: 4 * count].reshape(count, 4)
        valid = np.arange(4)[None, :] < points[:, None]
        return float(max(depth[valid].max(), 0.0)) if valid.any() else 0.0

    def store(self, contacts):
        """Keep this substep's pairs and impulses as the next substep's warm-start source."""
        launch(store_pairs, self.live_dim, key=self, inputs=[
            contacts.pair_count, contacts.pair_body, contacts.pair_point_count, contacts.pair_feature,
            contacts.pair_normal, contacts.pair_point, contacts.pair_normal_impulse, contacts.pair_tangent_impulse,
            contacts.prev_pair_count, contacts.prev_pair_body, contacts.prev_pair_point_count,
            contacts.prev_pair_feature, contacts.prev_pair_normal, contacts.prev_pair_point,
            contacts.prev_pair_normal_impulse, contacts.prev_pair_tangent_impulse],
            device=self.device)


@dataclass
class MovedBodies:
    """The bodies mid-step, for a pass at the reference pose (PairContactPipeline.collide):
    poses now, and velocities either the state's or (``use_solver_velocity`` = 1) the impact
    stage's solver_v / solver_w."""

    body_pos: wp.array
    body_rot: wp.array
    body_vel: wp.array
    body_angmom: wp.array
    solver_v: wp.array
    solver_w: wp.array
    use_solver_velocity: int


@dataclass
class DomainSchedule:
    """The slabs of solvers/domains.py: bodies of slab d at domain_body[domain_body_start[d]:
    domain_body_start[d + 1]], static bodies after the last slab; pairs likewise, boundary pairs
    after the last slab."""

    domain_count: int
    boundary_pairs: int
    static_bodies: int
    domain_body_start: wp.array
    domain_body: wp.array
    domain_pair_start: wp.array
    domain_pair: wp.array
    body_domain: wp.array
    body_on_boundary: wp.array
    boundary_body_count: wp.array
    boundary_body: wp.array


def default_pair_capacity(body_count: int) -> int:
    """Room for 12 candidate pairs a body: a lattice of touching cubes has 13 neighbours a body
    within reach (6 faces, 12 edges, 8 corners, each pair shared by two), 10.5 a body for a
    10x10x10 block.  Running out is not fatal: the Simulator redoes the step with more room."""
    return int(12 * body_count + 64)
