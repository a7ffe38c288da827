"""Spatial domains: how the staged solver uses every CPU core without colouring.

Graph colouring (coloring.py) makes a sweep parallel by splitting it into one launch per colour.
On a GPU that is the right trade.  On a CPU each launch that is split across cores pays a thread
hand-off (~90 us here, warp_sim/launch.py), and a colour of a few thousand pairs runs in about
that time: at 10k bodies the six or so colours of a sweep each ran on one core, and the pair
sweeps cost 15 ms of a 53 ms step.

Instead, cut the scene into D slabs (D = CPU threads) along its longer horizontal axis, with
equal solver work in each (work = 1 + active terrain contacts + contact points of a body).  A
pair whose dynamic bodies lie in one slab belongs to that slab; a pair across a cut is a
boundary pair.  One sweep is then

    D threads at once: each walks its slab's bodies (terrain contacts) then its pairs, in order
    one thread:        the boundary pairs, in order

No two threads touch one body in the first stage (a body is in one slab; static bodies are
never written), so there is no race, and each slab's sweep is plain sequential Gauss-Seidel,
which converges at least as fast as the coloured order.  Only the pairs across the D - 1 cuts
wait for the second stage: a few percent of the pairs in a pile.  Two launches per sweep instead
of one per colour plus one for the terrain.

The partition is computed by one thread once per collision pass (weights, a histogram of 1024
bins along the axis, cuts at equal cumulative work, then count / scan / place of bodies and
pairs), in body and pair order, so the schedule and the results are the same on every run with
the same thread count (WARP_SIM_CPU_THREADS); a different thread count is a different, equally
valid, Gauss-Seidel order.
"""

import warp as wp

from .contact_rows import TerrainRow
from .pair_solve import MODE_RELAX, MODE_SOLVE, MODE_WARM_START, solve_one_pair
from .staged import sweep_body_terrain

wp.set_module_options({"enable_backward": False})

BINS = 1024


@wp.func
def pair_domain(ij: wp.vec2i, body_domain: wp.array(dtype=wp.int32), domain_count: int) -> int:
    di = body_domain[ij[0]]
    dj = body_domain[ij[1]]
    if di < 0:
        di = dj
    if dj < 0:
        dj = di
    if di == dj and di >= 0:
        return di
    return domain_count


@wp.func
def bin_of(x: float, origin: float, extent: float) -> int:
    return wp.clamp(int(float(BINS) * (x - origin) / extent), 0, BINS - 1)


@wp.kernel
def partition_domains(
    domain_count: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_checkpoint_start: wp.array(dtype=wp.int32),
    body_checkpoint_count: wp.array(dtype=wp.int32),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # Contacts in
    terrain_contact_active: wp.array(dtype=wp.int32),
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    # Scratch
    body_weight: wp.array(dtype=float),
    body_domain: wp.array(dtype=wp.int32),
    bin_weight: wp.array(dtype=float),
    bin_domain: wp.array(dtype=wp.int32),
    domain_cursor: wp.array(dtype=wp.int32),
    # Out
    domain_body_start: wp.array(dtype=wp.int32),
    domain_body: wp.array(dtype=wp.int32),
    domain_pair_start: wp.array(dtype=wp.int32),
    domain_pair: wp.array(dtype=wp.int32),
):
    n = body_pos.shape[0]
    pairs = pair_count[0]
    big = float(1.0e30)
    lo = wp.vec3(big)
    hi = wp.vec3(-big)
    for i in range(n):
        weight = float(0.0)
        if body_inv_mass[i] > 0.0:
            weight = float(1.0)
            start = body_checkpoint_start[i]
            for slot in range(start, start + body_checkpoint_count[i]):
                weight += float(terrain_contact_active[slot])
            lo = wp.min(lo, body_pos[i])
            hi = wp.max(hi, body_pos[i])
        body_weight[i] = weight
    for p in range(pairs):
        points = float(pair_point_count[p])
        ij = pair_body[p]
        if body_inv_mass[ij[0]] > 0.0:
            body_weight[ij[0]] = body_weight[ij[0]] + points
        if body_inv_mass[ij[1]] > 0.0:
            body_weight[ij[1]] = body_weight[ij[1]] + points

    # the cut axis: the longer horizontal extent (y is up)
    axis = int(0)
    if hi[2] - lo[2] > hi[0] - lo[0]:
        axis = 2
    origin = lo[axis]
    extent = wp.max(hi[axis] - lo[axis], 1.0e-6)
    for b in range(BINS):
        bin_weight[b] = 0.0
    total = float(0.0)
    for i in range(n):
        if body_weight[i] > 0.0:
            b = bin_of(body_pos[i][axis], origin, extent)
            bin_weight[b] = bin_weight[b] + body_weight[i]
            total += body_weight[i]
    running = float(0.0)
    for b in range(BINS):
        # the bin's domain is the share of the total work done before its middle
        middle = running + 0.5 * bin_weight[b]
        bin_domain[b] = wp.min(int(float(domain_count) * middle / wp.max(total, 1.0e-30)), domain_count - 1)
        running += bin_weight[b]

    # bodies: count, scan, place (static bodies belong to no domain: they are never written)
    for d in range(domain_count + 1):
        domain_body_start[d] = 0
    for i in range(n):
        d = int(-1)
        if body_weight[i] > 0.0:
            d = bin_domain[bin_of(body_pos[i][axis], origin, extent)]
            domain_body_start[d + 1] = domain_body_start[d + 1] + 1
        body_domain[i] = d
    for d in range(domain_count):
        domain_body_start[d + 1] = domain_body_start[d + 1] + domain_body_start[d]
        domain_cursor[d] = domain_body_start[d]
    for i in range(n):
        d = body_domain[i]
        if d >= 0:
            domain_body[domain_cursor[d]] = i
            domain_cursor[d] = domain_cursor[d] + 1

    # pairs: the domain of their dynamic bodies, or the boundary set (index domain_count)
    for d in range(domain_count + 2):
        domain_pair_start[d] = 0
    for p in range(pairs):
        if pair_point_count[p] > 0:
            d = pair_domain(pair_body[p], body_domain, domain_count)
            domain_pair_start[d + 1] = domain_pair_start[d + 1] + 1
    for d in range(domain_count + 1):
        domain_pair_start[d + 1] = domain_pair_start[d + 1] + domain_pair_start[d]
        domain_cursor[d] = domain_pair_start[d]
    for p in range(pairs):
        if pair_point_count[p] > 0:
            d = pair_domain(pair_body[p], body_domain, domain_count)
            domain_pair[domain_cursor[d]] = p
            domain_cursor[d] = domain_cursor[d] + 1


@wp.func
def walk(first: int, count: int, k: int, reverse: int) -> int:
    """The k-th index of [first, first + count), from the end when ``reverse``."""
    if reverse != 0:
        return first + count - 1 - k
    return first + k


@wp.kernel
def domain_sweep(
    tid_offset: int,
    first_domain: int,
    domain_count: int,
    mode: int,
    reverse: int,
    warm_start: int,
    domain_body_start: wp.array(dtype=wp.int32),
    domain_body: wp.array(dtype=wp.int32),
    domain_pair_start: wp.array(dtype=wp.int32),
    domain_pair: wp.array(dtype=wp.int32),
    # Model
    body_shape: wp.array(dtype=wp.int32),
    body_size: wp.array(dtype=wp.vec3),
    body_inv_mass: wp.array(dtype=float),
    body_friction: wp.array(dtype=float),
    body_restitution: wp.array(dtype=float),
    body_rolling_resistance: wp.array(dtype=float),
    body_checkpoint_start: wp.array(dtype=wp.int32),
    # Settings
    h: float,
    soft: wp.vec3,
    max_push_velocity: float,
    restitution_threshold: float,
    # Contacts in/out
    terrain_contact_normal_impulse: wp.array(dtype=float),
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    pair_normal: wp.array(dtype=wp.vec3),
    pair_point: wp.array(dtype=wp.vec3),
    pair_depth: wp.array(dtype=float),
    pair_normal_impulse: wp.array(dtype=float),
    pair_tangent_impulse: wp.array(dtype=wp.vec3),
    # Solver in/out
    solver_inv_inertia: wp.array(dtype=wp.mat33),
    solver_ref_pos: wp.array(dtype=wp.vec3),
    solver_drift_p: wp.array(dtype=wp.vec3),
    solver_drift_r: wp.array(dtype=wp.mat33),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_rolling: wp.array(dtype=wp.vec3),
    terrain_row: wp.array(dtype=TerrainRow),
    terrain_row_count: wp.array(dtype=wp.int32),
):
    """One sweep of one slab (d < domain_count: its bodies' terrain contacts, then its pairs) or of
    the boundary pairs (d == domain_count), in the pair_solve mode ``mode``; ``reverse`` walks
    the same sequence backwards (symmetric Gauss-Seidel, see the module docstring)."""
    d = first_domain + wp.tid() + tid_offset
    terrain = d < domain_count and (mode == MODE_SOLVE or mode == MODE_RELAX)
    use_bias = int(mode == MODE_SOLVE)
    body_first = domain_body_start[d]
    body_count = domain_body_start[d + 1] - body_first
    pair_first = domain_pair_start[d]
    pair_count = domain_pair_start[d + 1] - pair_first
    if warm_start != 0:
        # the pairs' warm start rides on the first sweep's launch: a launch split over the
        # cores costs ~90 us of thread hand-off (launch.py), four of them a step
        for k in range(pair_count):
            solve_one_pair(domain_pair[pair_first + k], MODE_WARM_START, body_inv_mass, body_friction,
                           body_restitution, h, soft, max_push_velocity, restitution_threshold, pair_body,
                           pair_point_count, pair_normal, pair_point, pair_depth, pair_normal_impulse,
                           pair_tangent_impulse, solver_inv_inertia, solver_ref_pos, solver_drift_p, solver_drift_r,
                           solver_v, solver_w)
    # forward: terrain, then pairs; backward: the same sequence walked from its end
    for part in range(2):
        if (part == 0) == (reverse == 0):
            if terrain:
                for k in range(body_count):
                    sweep_body_terrain(domain_body[walk(body_first, body_count, k, reverse)], body_shape, body_size,
                                       body_inv_mass, body_friction, body_rolling_resistance, body_checkpoint_start,
                                       h, use_bias, soft, max_push_velocity, terrain_contact_normal_impulse,
                                       terrain_contact_tangent_impulse, solver_inv_inertia, solver_ref_pos,
                                       solver_drift_p, solver_drift_r, solver_v, solver_w, solver_rolling, terrain_row,
                                       terrain_row_count)
        else:
            for k in range(pair_count):
                solve_one_pair(domain_pair[walk(pair_first, pair_count, k, reverse)], mode, body_inv_mass,
                               body_friction, body_restitution, h, soft, max_push_velocity, restitution_threshold,
                               pair_body, pair_point_count, pair_normal, pair_point, pair_depth, pair_normal_impulse,
                               pair_tangent_impulse, solver_inv_inertia, solver_ref_pos, solver_drift_p,
                               solver_drift_r, solver_v, solver_w)
