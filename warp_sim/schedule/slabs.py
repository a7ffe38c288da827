"""The CPU slab schedule: the scene cut into one slab per thread (see solvers/domains.py for how
the solver sweeps it).

The partition is computed by one thread once per collision pass (weights, a histogram of 1024
bins along the axis, cuts at equal cumulative work, then count / scan / place of bodies and
pairs), in body and pair order, so the schedule and the results are the same on every run with
the same thread count (WARP_SIM_CPU_THREADS); a different thread count is a different, equally
valid, Gauss-Seidel order.  A cut may move by up to CUT_SLACK of a slab's work to a place that
no touching pair crosses: with no boundary pairs at all the boundary launches are skipped
(a rain of 1k bodies: 117 -> 163 steps/s).
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

BINS = 1024
# A cut may move off its balanced place by this share of a slab's work to where no touching pair
# crosses it.  The boundary pairs are solved by one thread after the slabs, in a launch of its own
# per sweep (~0.1 ms, launch.py): at 10k bodies that is 0.3 ms a substep, against ~3 ms of sweeps
# of which 5 % imbalance costs 0.15 ms; with no pair across any cut there is no such launch.
CUT_SLACK = 0.05


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
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # Contacts in
    terrain_contact_count: wp.array(dtype=wp.int32),
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    # Scratch
    body_weight: wp.array(dtype=float),
    body_domain: wp.array(dtype=wp.int32),
    bin_weight: wp.array(dtype=float),
    bin_work_before: wp.array(dtype=float),
    bin_crossing: wp.array(dtype=wp.int32),
    bin_domain: wp.array(dtype=wp.int32),
    domain_cursor: wp.array(dtype=wp.int32),
    # Out
    domain_body_start: wp.array(dtype=wp.int32),
    domain_body: wp.array(dtype=wp.int32),
    domain_pair_start: wp.array(dtype=wp.int32),
    domain_pair: wp.array(dtype=wp.int32),
    body_on_boundary: wp.array(dtype=wp.int32),
    boundary_body_count: wp.array(dtype=wp.int32),
    boundary_body: wp.array(dtype=wp.int32),
):
    n = body_pos.shape[0]
    pairs = pair_count[0]
    big = float(1.0e30)
    lo = wp.vec3(big)
    hi = wp.vec3(-big)
    for i in range(n):
        weight = float(0.0)
        if body_inv_mass[i] > 0.0:
            weight = float(1 + terrain_contact_count[i])
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
    # Cuts.  Cut k (0 < k < D) at bin c puts bins < c before it; balanced where the work before it
    # is k/D of the total.  The touching pairs between dynamic bodies in bins lo < hi cross the
    # cuts at lo < c <= hi (a difference array, then a running sum).
    for c in range(BINS + 1):
        bin_work_before[c] = 0.0
        bin_crossing[c] = 0
    for b in range(BINS):
        bin_work_before[b + 1] = bin_work_before[b] + bin_weight[b]
    for p in range(pairs):
        ij = pair_body[p]
        if pair_point_count[p] > 0 and body_weight[ij[0]] > 0.0 and body_weight[ij[1]] > 0.0:
            b0 = bin_of(body_pos[ij[0]][axis], origin, extent)
            b1 = bin_of(body_pos[ij[1]][axis], origin, extent)
            if b0 != b1:
                bin_crossing[wp.min(b0, b1) + 1] = bin_crossing[wp.min(b0, b1) + 1] + 1
                bin_crossing[wp.max(b0, b1) + 1] = bin_crossing[wp.max(b0, b1) + 1] - 1
    for c in range(BINS):
        bin_crossing[c + 1] = bin_crossing[c + 1] + bin_crossing[c]
    for b in range(BINS):
        bin_domain[b] = 0
    share = total / float(domain_count)
    for k in range(1, domain_count):
        target = float(k) * share
        balanced = int(1)
        free = int(-1)  # the most balanced cut in reach that no pair crosses
        for c in range(1, BINS):
            off = wp.abs(bin_work_before[c] - target)
            if off < wp.abs(bin_work_before[balanced] - target):
                balanced = c
            if off <= CUT_SLACK * share and bin_crossing[c] == 0:
                if free < 0 or off < wp.abs(bin_work_before[free] - target):
                    free = c
        cut = balanced
        if free >= 0:
            cut = free
        for b in range(cut, BINS):
            bin_domain[b] = k

    # bodies: count, scan, place.  Static bodies belong to no slab (body_domain -1: no sweep writes
    # them); they are listed after the slabs, as list domain_count, for the per-substep copies.
    for d in range(domain_count + 2):
        domain_body_start[d] = 0
    for i in range(n):
        d = int(-1)
        listed = domain_count
        if body_weight[i] > 0.0:
            d = bin_domain[bin_of(body_pos[i][axis], origin, extent)]
            listed = d
        domain_body_start[listed + 1] = domain_body_start[listed + 1] + 1
        body_domain[i] = d
    for d in range(domain_count + 1):
        domain_body_start[d + 1] = domain_body_start[d + 1] + domain_body_start[d]
        domain_cursor[d] = domain_body_start[d]
    for i in range(n):
        listed = body_domain[i]
        if listed < 0:
            listed = domain_count
        domain_body[domain_cursor[listed]] = i
        domain_cursor[listed] = domain_cursor[listed] + 1

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

    # the dynamic bodies of boundary pairs, each once, in pair order: the boundary thread integrates
    # and finalizes them, after the last boundary sweep that moves them
    for i in range(n):
        body_on_boundary[i] = 0
    listed = int(0)
    for q in range(domain_pair_start[domain_count], domain_pair_start[domain_count + 1]):
        ij = pair_body[domain_pair[q]]
        for side in range(2):
            b = ij[side]
            if body_domain[b] >= 0 and body_on_boundary[b] == 0:
                body_on_boundary[b] = 1
                boundary_body[listed] = b
                listed += 1
    boundary_body_count[0] = listed


