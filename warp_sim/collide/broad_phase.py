"""Body-body broad phase: the candidate pairs whose bounding spheres come within ``margin``.

Every method writes the same output, sorted by (i, j) with i < j:

    pair_body[k] = (i, j)   k < pair_count[0] <= capacity
    pair_demand[0]          pairs found, may exceed ``capacity``; ``check_overflow`` reports that

A pair of static bodies (inverse mass 0) is never emitted when ``inv_mass`` is given.

Methods (``make_broad_phase(name, ...)``):

* ``all_pairs``: the thesis's O(N^2) loop with no pre-test, every non-static pair whatever the
  distance (the narrow phase does all the rejecting).  One thread per pair of the upper
  triangle, each computing its own output slot; the reference baseline, usable for small N.
* ``bounding_sphere``: the same loop with the bounding-sphere test (SEED.md 4, "bounding
  spheres act as a cheap primary collider"), one thread per row i:

      |x_i - x_j| < r_i + r_j + margin

* ``grid_sorted`` / ``grid_hash``: a uniform grid (SEED.md 9).  With cell width
  w >= 2 r_max + margin any pair passing the test above lies in the same or adjacent cells,
  so each body scans only its 27 neighbouring cells and then applies the same exact test.
  Worlds are unbounded: cell coordinates wrap onto a power-of-two table of about 2N buckets
  whose bits per axis follow the bodies' cell bounds, found on the device every call.
  ``grid_sorted`` radix-sorts the bodies by bucket and scans each run of three x-neighbour
  cells as one contiguous range; ``grid_hash`` uses ``wp.HashGrid`` with the same dimensions.
  ``grid`` is the faster of the two on CPU (bench/broad_phase.py).

Deterministic, sorted output without atomics or a global sort.  Each method first counts the
pairs of every row i (the pairs (i, j), j > i), an exclusive scan turns the counts into row
starts, and a second pass writes each row into its own range.  Rows are therefore in order of
i whatever the thread schedule; the O(N^2) methods visit j in increasing order and the grids
sort their (short) rows in place.  This also keeps the result exact when the CPU launch is
split over threads: Warp's CPU ``atomic_add`` is a plain read-modify-write, so a shared atomic
counter would lose increments between concurrent chunks.

Radii are static in the model, so nothing per-step depends on them except through the cell
width, which comes from the largest radius and is cached per radii array
(``invalidate_radii`` after editing radii in place).  Only positions change per step.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from ..launch import launch

# Pairs per row above which the grids sort a row by heapsort instead of insertion sort.
INSERTION_SORT_MAX = 32
# The grid cell is widened by this fraction over 2 r_max + margin so float rounding of the cell
# coordinates can never separate two overlapping bodies by more than one cell.
CELL_SLACK = 1.0e-3
# Cell coordinates are clamped to +-this (monotone, so neighbours stay neighbours).
CELL_COORD_LIMIT = 1.0e9
# all_pairs indexes pairs with 32-bit thread ids: N (N - 1) / 2 < 2^31.
TRIANGLE_BODY_MAX = 65536


class BroadPhaseOverflowError(RuntimeError):
    def __init__(self, method: str, capacity: int, demand: int):
        super().__init__(
            f"broad phase '{method}' found {demand} candidate pairs but its pair buffer holds {capacity}; "
            f"create it with capacity >= {demand}"
        )
        self.capacity = capacity
        self.demand = demand


# Shared functions -------------------------------------------------------------------------------


@wp.func
def spheres_overlap(x_i: wp.vec3, r_i: float, x_j: wp.vec3, r_j: float, margin: float) -> bool:
    """The bounding-sphere test; every method calls it with i < j so all agree bit for bit."""
    d = x_i - x_j
    reach = r_i + r_j + margin
    return wp.dot(d, d) < reach * reach


@wp.func
def cell_coord(v: float, inv_cell: wp.float64) -> int:
    # float64 so the rounding of v / w stays far below CELL_SLACK even far from the origin
    c = wp.floor(wp.float64(v) * inv_cell)
    c = wp.clamp(c, wp.float64(-CELL_COORD_LIMIT), wp.float64(CELL_COORD_LIMIT))
    return wp.int32(c)


@wp.func
def cell_of(x: wp.vec3, inv_cell: wp.float64) -> wp.vec3i:
    return wp.vec3i(cell_coord(x[0], inv_cell), cell_coord(x[1], inv_cell), cell_coord(x[2], inv_cell))


@wp.func
def interleaved_row(t: int, n: int) -> int:
    """Thread t -> row 0, n-1, 1, n-2, ...: any contiguous thread range gets an even share of
    the triangle's work (row i has n - 1 - i pairs), so CPU chunks stay balanced."""
    if t % 2 == 0:
        return t // 2
    return n - 1 - t // 2


@wp.func
def triangle_row_start(i: wp.int64, n: wp.int64) -> wp.int64:
    """Linear index of pair (i, i + 1) in the row-major upper triangle."""
    return i * (wp.int64(2) * n - i - wp.int64(1)) / wp.int64(2)


@wp.func
def triangle_pair(k: wp.int64, n: wp.int64) -> wp.vec2i:
    """Pair (i, j), i < j, at linear index k of the row-major upper triangle of n bodies."""
    b = wp.float64(wp.int64(2) * n - wp.int64(1))
    i = wp.int64((b - wp.sqrt(b * b - wp.float64(8.0) * wp.float64(k))) * wp.float64(0.5))
    i = wp.clamp(i, wp.int64(0), n - wp.int64(2))
    # the float64 root can be one row off near row boundaries
    while i + wp.int64(1) <= n - wp.int64(2) and triangle_row_start(i + wp.int64(1), n) <= k:
        i = i + wp.int64(1)
    while i > wp.int64(0) and triangle_row_start(i, n) > k:
        i = i - wp.int64(1)
    j = k - triangle_row_start(i, n) + i + wp.int64(1)
    return wp.vec2i(wp.int32(i), wp.int32(j))


@wp.func
def sift_down(pair_body: wp.array(dtype=wp.vec2i), base: int, root: int, end: int):
    r = root
    while 2 * r + 1 < end:
        child = 2 * r + 1
        if child + 1 < end and pair_body[base + child + 1][1] > pair_body[base + child][1]:
            child = child + 1
        if pair_body[base + r][1] >= pair_body[base + child][1]:
            break
        top = pair_body[base + r]
        pair_body[base + r] = pair_body[base + child]
        pair_body[base + child] = top
        r = child


@wp.func
def sort_row(pair_body: wp.array(dtype=wp.vec2i), start: int, count: int):
    """Sort pair_body[start:start + count] by j (i is the same throughout a row)."""
    if count <= INSERTION_SORT_MAX:
        for a in range(start + 1, start + count):
            p = pair_body[a]
            b = a - 1
            while b >= start and pair_body[b][1] > p[1]:
                pair_body[b + 1] = pair_body[b]
                b = b - 1
            pair_body[b + 1] = p
    else:
        # heapsort: O(k log k) for the rare long row of a body much larger than the rest
        for r in range(count // 2 - 1, -1, -1):
            sift_down(pair_body, start, r, count)
        for end in range(count - 1, 0, -1):
            top = pair_body[start]
            pair_body[start] = pair_body[start + end]
            pair_body[start + end] = top
            sift_down(pair_body, start, 0, end)


# Shared kernels ---------------------------------------------------------------------------------


@wp.kernel
def mark_static(
    tid_offset: int,
    # In
    body_inv_mass: wp.array(dtype=float),
    # Out
    body_static: wp.array(dtype=wp.int32),
):
    i = wp.tid() + tid_offset
    if body_inv_mass[i] == 0.0:
        body_static[i] = 1
    else:
        body_static[i] = 0


@wp.kernel
def finish_pair_count(
    # In
    body_count: int,
    row_count: wp.array(dtype=wp.int64),
    row_start: wp.array(dtype=wp.int64),
    capacity: int,
    # Out
    pair_demand: wp.array(dtype=wp.int64),
    pair_count: wp.array(dtype=wp.int32),
):
    demand = row_start[body_count - 1] + row_count[body_count - 1]
    pair_demand[0] = demand
    pair_count[0] = wp.int32(wp.min(demand, wp.int64(capacity)))


# all_pairs --------------------------------------------------------------------------------------


@wp.kernel
def all_pairs_row_count(
    tid_offset: int,
    # In
    body_count: int,
    body_static: wp.array(dtype=wp.int32),
    static_before: wp.array(dtype=wp.int32),
    # Out
    row_count: wp.array(dtype=wp.int64),
):
    i = wp.tid() + tid_offset
    n = body_count
    count = n - 1 - i
    if body_static[i] != 0:
        static_total = static_before[n - 1] + body_static[n - 1]
        count = count - (static_total - static_before[i] - 1)  # static bodies after i
    row_count[i] = wp.int64(count)


@wp.kernel
def all_pairs_emit(
    tid_offset: int,
    # In
    body_count: int,
    body_static: wp.array(dtype=wp.int32),
    static_before: wp.array(dtype=wp.int32),
    row_start: wp.array(dtype=wp.int64),
    capacity: int,
    # Out
    pair_body: wp.array(dtype=wp.vec2i),
):
    k = wp.tid() + tid_offset
    p = triangle_pair(wp.int64(k), wp.int64(body_count))
    i = p[0]
    j = p[1]
    offset = j - i - 1
    if body_static[i] != 0:
        if body_static[j] != 0:
            return
        offset = offset - (static_before[j] - static_before[i] - 1)  # static-static pairs skipped
    slot = row_start[i] + wp.int64(offset)
    if slot < wp.int64(capacity):
        pair_body[wp.int32(slot)] = p


# bounding_sphere --------------------------------------------------------------------------------


@wp.kernel
def sphere_rows(
    tid_offset: int,
    # Model
    body_bound_radius: wp.array(dtype=float),
    body_static: wp.array(dtype=wp.int32),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # In
    body_count: int,
    margin: float,
    emit: int,
    row_start: wp.array(dtype=wp.int64),
    capacity: int,
    # Out
    row_count: wp.array(dtype=wp.int64),
    pair_body: wp.array(dtype=wp.vec2i),
):
    """emit = 0: count row i's pairs; emit = 1: write them in increasing j from row_start[i]."""
    i = interleaved_row(wp.tid() + tid_offset, body_count)
    x_i = body_pos[i]
    r_i = body_bound_radius[i]
    static_i = body_static[i]
    start = wp.int64(0)
    if emit != 0:
        start = row_start[i]
    count = int(0)
    for j in range(i + 1, body_count):
        if static_i != 0 and body_static[j] != 0:
            continue
        if spheres_overlap(x_i, r_i, body_pos[j], body_bound_radius[j], margin):
            if emit != 0:
                slot = start + wp.int64(count)
                if slot < wp.int64(capacity):
                    pair_body[wp.int32(slot)] = wp.vec2i(i, j)
            count += 1
    if emit == 0:
        row_count[i] = wp.int64(count)


# Grids: cells, bounds and table layout ----------------------------------------------------------


@wp.kernel
def grid_cells(
    tid_offset: int,
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # In
    inv_cell: wp.float64,
    # Out
    body_cell: wp.array(dtype=wp.vec3i),
):
    i = wp.tid() + tid_offset
    body_cell[i] = cell_of(body_pos[i], inv_cell)


@wp.kernel
def grid_cell_bounds(
    # In
    body_cell: wp.array(dtype=wp.vec3i),
    # Out
    cell_bounds: wp.array(dtype=wp.int32),
):
    """cell_bounds = (min x, y, z, max x, y, z) over the bodies' cells.  Launched as one plain
    launch (never split over CPU threads), since it reduces with atomics."""
    i = wp.tid()
    c = body_cell[i]
    for a in range(3):
        wp.atomic_min(cell_bounds, a, c[a])
        wp.atomic_max(cell_bounds, 3 + a, c[a])


@wp.func
def axis_bits(lo: int, hi: int, table_bits: int) -> int:
    # the occupied cells plus the ring of neighbours the scan visits
    extent = wp.int64(hi) - wp.int64(lo) + wp.int64(3)
    b = int(0)
    while b < table_bits and (wp.int64(1) << wp.int64(b)) < extent:
        b += 1
    return b


@wp.kernel
def grid_table_layout(
    # In
    table_bits: int,
    cell_bounds: wp.array(dtype=wp.int32),
    # Out
    table_layout: wp.array(dtype=wp.vec3i),
):
    """Bits of the bucket index per axis (mirrored by ``table_layout_host``): each axis gets
    enough to hold the occupied cells without wrapping, the widest axes give bits back until
    the total fits the table.  The table then follows the world's shape (a flat rain of
    bodies wraps far less than on a cube of the same size)."""
    bits = wp.vec3i(0)
    for a in range(3):
        bits[a] = axis_bits(cell_bounds[a], cell_bounds[3 + a], table_bits)
    while bits[0] + bits[1] + bits[2] > table_bits:
        a = int(0)
        if bits[1] > bits[a]:
            a = 1
        if bits[2] > bits[a]:
            a = 2
        bits[a] = bits[a] - 1
    table_layout[0] = bits


def table_layout_host(cell_bounds: np.ndarray, table_bits: int) -> tuple[int, int, int]:
    bits = []
    for a in range(3):
        extent = int(cell_bounds[3 + a]) - int(cell_bounds[a]) + 3
        bits.append(min(table_bits, max(0, (extent - 1).bit_length())))
    while sum(bits) > table_bits:
        bits[int(np.argmax(bits))] -= 1
    return bits[0], bits[1], bits[2]


@wp.func
def cell_bucket(c: wp.vec3i, layout: wp.vec3i) -> int:
    """Bucket of an unbounded cell: each coordinate wrapped onto 2^bits buckets (``&`` is the
    modulo, also for negative coordinates), x in the low bits so that cells along x are
    neighbouring buckets."""
    bx = layout[0]
    by = layout[1]
    x = c[0] & ((1 << bx) - 1)
    y = c[1] & ((1 << by) - 1)
    z = c[2] & ((1 << layout[2]) - 1)
    return x | (y << bx) | (z << (bx + by))


# grid_sorted ------------------------------------------------------------------------------------


@wp.kernel
def grid_bucket_keys(
    tid_offset: int,
    # In
    body_cell: wp.array(dtype=wp.vec3i),
    table_layout: wp.array(dtype=wp.vec3i),
    # Out
    cell_key: wp.array(dtype=wp.int32),
    cell_body: wp.array(dtype=wp.int32),
):
    i = wp.tid() + tid_offset
    cell_key[i] = cell_bucket(body_cell[i], table_layout[0])
    cell_body[i] = i


@wp.kernel
def grid_bucket_ranges(
    tid_offset: int,
    # Model
    body_bound_radius: wp.array(dtype=float),
    body_static: wp.array(dtype=wp.int32),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # In
    body_count: int,
    table_size: int,
    body_cell: wp.array(dtype=wp.vec3i),
    cell_key: wp.array(dtype=wp.int32),
    cell_body: wp.array(dtype=wp.int32),
    # Out
    bucket_first: wp.array(dtype=wp.int32),
    sorted_pos: wp.array(dtype=wp.vec3),
    sorted_radius: wp.array(dtype=float),
    sorted_static: wp.array(dtype=wp.int32),
    sorted_cell: wp.array(dtype=wp.vec3i),
):
    """bucket_first[k] = first sorted index with key >= k (bucket k is [first[k], first[k + 1])),
    every entry written exactly once; plus body data gathered into sorted order."""
    s = wp.tid() + tid_offset
    key = cell_key[s]
    previous = int(-1)
    if s > 0:
        previous = cell_key[s - 1]
    for k in range(previous + 1, key + 1):
        bucket_first[k] = s
    if s == body_count - 1:
        for k in range(key + 1, table_size + 1):
            bucket_first[k] = body_count
    b = cell_body[s]
    sorted_pos[s] = body_pos[b]
    sorted_radius[s] = body_bound_radius[b]
    sorted_static[s] = body_static[b]
    sorted_cell[s] = body_cell[b]


@wp.func
def grid_scan_run(
    # In
    t_begin: int,
    t_end: int,
    x_lo: int,
    x_hi: int,
    y: int,
    z: int,
    i: int,
    x_i: wp.vec3,
    r_i: float,
    static_i: int,
    margin: float,
    cell_body: wp.array(dtype=wp.int32),
    sorted_pos: wp.array(dtype=wp.vec3),
    sorted_radius: wp.array(dtype=float),
    sorted_static: wp.array(dtype=wp.int32),
    sorted_cell: wp.array(dtype=wp.vec3i),
    emit: int,
    start: wp.int64,
    count: int,
    capacity: int,
    # Out
    pair_body: wp.array(dtype=wp.vec2i),
) -> int:
    """Test body i against sorted bodies [t_begin, t_end) that lie in cells (x_lo..x_hi, y, z);
    returns the row's pair count so far.  The cell filter drops bodies of other cells that
    share the buckets, so no body is seen twice."""
    n = count
    for t in range(t_begin, t_end):
        j = cell_body[t]
        if j <= i:
            continue
        c = sorted_cell[t]
        if c[0] < x_lo or c[0] > x_hi or c[1] != y or c[2] != z:
            continue
        if static_i != 0 and sorted_static[t] != 0:
            continue
        if spheres_overlap(x_i, r_i, sorted_pos[t], sorted_radius[t], margin):
            if emit != 0:
                slot = start + wp.int64(n)
                if slot < wp.int64(capacity):
                    pair_body[wp.int32(slot)] = wp.vec2i(i, j)
            n += 1
    return n


@wp.kernel
def grid_sorted_rows(
    tid_offset: int,
    # In
    margin: float,
    table_layout: wp.array(dtype=wp.vec3i),
    bucket_first: wp.array(dtype=wp.int32),
    cell_body: wp.array(dtype=wp.int32),
    sorted_pos: wp.array(dtype=wp.vec3),
    sorted_radius: wp.array(dtype=float),
    sorted_static: wp.array(dtype=wp.int32),
    sorted_cell: wp.array(dtype=wp.vec3i),
    emit: int,
    row_start: wp.array(dtype=wp.int64),
    capacity: int,
    # Out
    row_count: wp.array(dtype=wp.int64),
    pair_body: wp.array(dtype=wp.vec2i),
):
    """One thread per body in bucket order; emit = 0 counts row i, emit = 1 writes and sorts it.

    The 27 neighbour cells are 9 runs of three cells along x; unless the run wraps around the
    table they are three consecutive buckets, i.e. one contiguous range of sorted bodies."""
    s = wp.tid() + tid_offset
    i = cell_body[s]
    x_i = sorted_pos[s]
    r_i = sorted_radius[s]
    static_i = sorted_static[s]
    c = sorted_cell[s]
    layout = table_layout[0]
    start = wp.int64(0)
    if emit != 0:
        start = row_start[i]
    count = int(0)
    for dz in range(-1, 2):
        for dy in range(-1, 2):
            y = c[1] + dy
            z = c[2] + dz
            b_lo = cell_bucket(wp.vec3i(c[0] - 1, y, z), layout)
            b_hi = cell_bucket(wp.vec3i(c[0] + 1, y, z), layout)
            if b_hi == b_lo + 2:
                count = grid_scan_run(bucket_first[b_lo], bucket_first[b_hi + 1], c[0] - 1, c[0] + 1, y, z,
                                      i, x_i, r_i, static_i, margin, cell_body, sorted_pos, sorted_radius,
                                      sorted_static, sorted_cell, emit, start, count, capacity, pair_body)
            else:
                for dx in range(-1, 2):
                    b = cell_bucket(wp.vec3i(c[0] + dx, y, z), layout)
                    count = grid_scan_run(bucket_first[b], bucket_first[b + 1], c[0] + dx, c[0] + dx, y, z,
                                          i, x_i, r_i, static_i, margin, cell_body, sorted_pos, sorted_radius,
                                          sorted_static, sorted_cell, emit, start, count, capacity, pair_body)
    if emit == 0:
        row_count[i] = wp.int64(count)
    elif count > 1 and start < wp.int64(capacity):
        end = wp.min(start + wp.int64(count), wp.int64(capacity))
        sort_row(pair_body, wp.int32(start), wp.int32(end - start))


# grid_hash --------------------------------------------------------------------------------------


@wp.kernel
def grid_hash_rows(
    tid_offset: int,
    # Model
    body_bound_radius: wp.array(dtype=float),
    body_static: wp.array(dtype=wp.int32),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # In
    grid: wp.uint64,
    query_radius: float,
    margin: float,
    emit: int,
    row_start: wp.array(dtype=wp.int64),
    capacity: int,
    # Out
    row_count: wp.array(dtype=wp.int64),
    pair_body: wp.array(dtype=wp.vec2i),
):
    """As grid_sorted_rows, with the neighbour cells from wp.hash_grid_query."""
    i = wp.hash_grid_point_id(grid, wp.tid() + tid_offset)
    x_i = body_pos[i]
    r_i = body_bound_radius[i]
    static_i = body_static[i]
    start = wp.int64(0)
    if emit != 0:
        start = row_start[i]
    count = int(0)
    for j in wp.hash_grid_query(grid, x_i, query_radius):
        if j <= i:
            continue
        if static_i != 0 and body_static[j] != 0:
            continue
        if spheres_overlap(x_i, r_i, body_pos[j], body_bound_radius[j], margin):
            if emit != 0:
                slot = start + wp.int64(count)
                if slot < wp.int64(capacity):
                    pair_body[wp.int32(slot)] = wp.vec2i(i, j)
            count += 1
    if emit == 0:
        row_count[i] = wp.int64(count)
    elif count > 1 and start < wp.int64(capacity):
        end = wp.min(start + wp.int64(count), wp.int64(capacity))
        sort_row(pair_body, wp.int32(start), wp.int32(end - start))


# Python side ------------------------------------------------------------------------------------


class BroadPhase:
    """Preallocated pair buffers shared by every method.

    Attributes:
        pair_body: (i, j) per candidate pair, i < j, sorted by (i, j); ``capacity`` entries.
        pair_count: number of valid entries of ``pair_body`` (min(demand, capacity)), int32[1].
        pair_demand: pairs found, int64[1]; greater than ``capacity`` means overflow.
        body_count: the most bodies a call may pass.
    """

    name = ""

    def __init__(self, body_count: int, capacity: int, device=None):
        if body_count < 0 or capacity < 0:
            raise ValueError("body_count and capacity must be >= 0")
        self.device = wp.get_device(device)
        self.body_count = body_count
        self.capacity = capacity
        n = max(body_count, 1)
        self.pair_body = wp.zeros(max(capacity, 1), dtype=wp.vec2i, device=self.device)
        self.pair_count = wp.zeros(1, dtype=wp.int32, device=self.device)
        self.pair_demand = wp.zeros(1, dtype=wp.int64, device=self.device)
        self.body_static = wp.zeros(n, dtype=wp.int32, device=self.device)
        self.row_count = wp.zeros(n, dtype=wp.int64, device=self.device)
        self.row_start = wp.zeros(n, dtype=wp.int64, device=self.device)
        self._radius_key = None
        self._max_radius = 0.0

    # per-step entry points

    def find_pairs(self, positions: wp.array, radii: wp.array, inv_mass: wp.array | None = None,
                   margin: float = 0.0, check: bool = True) -> int:
        """Find the candidate pairs; returns how many (raises BroadPhaseOverflowError if they
        do not fit and ``check`` is set)."""
        self.run(positions, radii, inv_mass, margin)
        demand = int(self.pair_demand.numpy()[0])
        if check:
            self.check_overflow(demand)
        return demand

    def run(self, positions: wp.array, radii: wp.array, inv_mass: wp.array | None = None, margin: float = 0.0):
        """Launch the broad phase.  Reads nothing back, except the largest radius once per radii
        array and, for grid_hash, the cell bounds; grid_sorted and the O(N^2) methods can be
        captured in a CUDA graph once the radius is cached."""
        n = positions.shape[0]
        if n > self.body_count:
            raise ValueError(f"broad phase '{self.name}' was sized for {self.body_count} bodies, got {n}")
        if radii.shape[0] != n or (inv_mass is not None and inv_mass.shape[0] != n):
            raise ValueError("positions, radii and inv_mass must have one entry per body")
        if margin < 0.0:
            raise ValueError(f"margin must be >= 0, got {margin}")
        if n < 2:
            self.pair_demand.zero_()
            self.pair_count.zero_()
            return
        if inv_mass is None:
            self.body_static.zero_()
        else:
            launch(mark_static, dim=n, inputs=[inv_mass, self.body_static], device=self.device)
        self._find_rows(n, positions, radii, float(margin))
        wp.launch(finish_pair_count, dim=1, device=self.device,
                  inputs=[n, self.row_count, self.row_start, self.capacity, self.pair_demand, self.pair_count])

    def check_overflow(self, demand: int | None = None):
        if demand is None:
            demand = int(self.pair_demand.numpy()[0])
        if demand > self.capacity:
            raise BroadPhaseOverflowError(self.name, self.capacity, demand)

    def pairs(self) -> np.ndarray:
        """The valid pairs as an (count, 2) int32 NumPy array."""
        count = int(self.pair_count.numpy()[0])
        return self.pair_body.numpy()[:count].reshape(count, 2)

    # helpers

    def max_radius(self, radii: wp.array) -> float:
        """Largest bounding radius, read once per radii array (radii are static in the model)."""
        key = (radii.ptr, radii.shape[0])
        if key != self._radius_key:
            r = radii.numpy()
            self._max_radius = float(r.max()) if r.size else 0.0
            self._radius_key = key
        return self._max_radius

    def invalidate_radii(self):
        """Call after changing radii in place, so the grid cell width is recomputed."""
        self._radius_key = None

    def cell_width(self, radii: wp.array, margin: float) -> float:
        return (2.0 * self.max_radius(radii) + margin) * (1.0 + CELL_SLACK) + 1.0e-12

    def _scan_rows(self, n: int):
        wp.utils.array_scan(self.row_count[:n], self.row_start[:n], inclusive=False)

    def _find_rows(self, n, positions, radii, margin):
        raise NotImplementedError


class AllPairsBroadPhase(BroadPhase):
    """Every non-static pair, no distance test (the thesis's O(N^2) loop)."""

    name = "all_pairs"

    def __init__(self, body_count: int, capacity: int, device=None):
        if body_count > TRIANGLE_BODY_MAX:
            raise ValueError(f"all_pairs supports at most {TRIANGLE_BODY_MAX} bodies, got {body_count}")
        super().__init__(body_count, capacity, device)
        self.static_before = wp.zeros(max(body_count, 1), dtype=wp.int32, device=self.device)

    def _find_rows(self, n, positions, radii, margin):
        wp.utils.array_scan(self.body_static[:n], self.static_before[:n], inclusive=False)
        launch(all_pairs_row_count, dim=n, device=self.device,
               inputs=[n, self.body_static, self.static_before, self.row_count])
        self._scan_rows(n)
        launch(all_pairs_emit, dim=n * (n - 1) // 2, device=self.device,
               inputs=[n, self.body_static, self.static_before, self.row_start, self.capacity, self.pair_body])


class BoundingSphereBroadPhase(BroadPhase):
    """All pairs with the bounding-sphere pre-test; O(N^2) tests."""

    name = "bounding_sphere"

    def _rows(self, n, positions, radii, margin, emit):
        launch(sphere_rows, dim=n, device=self.device, inputs=[
            radii, self.body_static,  # Model
            positions,  # State in
            n, margin, emit, self.row_start, self.capacity,  # In
            self.row_count, self.pair_body,  # Out
        ])

    def _find_rows(self, n, positions, radii, margin):
        self._rows(n, positions, radii, margin, 0)
        self._scan_rows(n)
        self._rows(n, positions, radii, margin, 1)


class GridBroadPhase(BroadPhase):
    """Shared part of the two grids: cell coordinates, their bounds and the table layout."""

    def __init__(self, body_count: int, capacity: int, device=None):
        super().__init__(body_count, capacity, device)
        n = max(body_count, 1)
        # about two buckets per body, at least 64
        self.table_bits = max(6, math.ceil(math.log2(2 * n)))
        self.table_size = 1 << self.table_bits
        self.body_cell = wp.zeros(n, dtype=wp.vec3i, device=self.device)
        self.cell_bounds = wp.zeros(6, dtype=wp.int32, device=self.device)
        big = np.iinfo(np.int32).max
        self._bounds_empty = wp.array([big, big, big, -big, -big, -big], dtype=wp.int32, device=self.device)
        self.table_layout = wp.zeros(1, dtype=wp.vec3i, device=self.device)

    def _cells(self, n, positions, inv_cell):
        launch(grid_cells, dim=n, device=self.device, inputs=[positions, inv_cell, self.body_cell])
        wp.copy(self.cell_bounds, self._bounds_empty)
        wp.launch(grid_cell_bounds, dim=n, device=self.device, inputs=[self.body_cell, self.cell_bounds])


class SortedGridBroadPhase(GridBroadPhase):
    """Uniform grid: bodies radix-sorted by the bucket of their cell (unbounded worlds)."""

    name = "grid_sorted"

    def __init__(self, body_count: int, capacity: int, device=None):
        super().__init__(body_count, capacity, device)
        n = max(body_count, 1)
        # radix sort needs 2x storage
        self.cell_key = wp.zeros(2 * n, dtype=wp.int32, device=self.device)
        self.cell_body = wp.zeros(2 * n, dtype=wp.int32, device=self.device)
        self.bucket_first = wp.zeros(self.table_size + 1, dtype=wp.int32, device=self.device)
        self.sorted_pos = wp.zeros(n, dtype=wp.vec3, device=self.device)
        self.sorted_radius = wp.zeros(n, dtype=float, device=self.device)
        self.sorted_static = wp.zeros(n, dtype=wp.int32, device=self.device)
        self.sorted_cell = wp.zeros(n, dtype=wp.vec3i, device=self.device)

    def _rows(self, n, margin, emit):
        launch(grid_sorted_rows, dim=n, device=self.device, inputs=[
            margin, self.table_layout, self.bucket_first, self.cell_body,  # In
            self.sorted_pos, self.sorted_radius, self.sorted_static, self.sorted_cell,
            emit, self.row_start, self.capacity,
            self.row_count, self.pair_body,  # Out
        ])

    def _find_rows(self, n, positions, radii, margin):
        self._cells(n, positions, 1.0 / self.cell_width(radii, margin))
        wp.launch(grid_table_layout, dim=1, device=self.device,
                  inputs=[self.table_bits, self.cell_bounds, self.table_layout])
        launch(grid_bucket_keys, dim=n, device=self.device,
               inputs=[self.body_cell, self.table_layout, self.cell_key, self.cell_body])
        wp.utils.radix_sort_pairs(self.cell_key, self.cell_body, n, 0, self.table_bits)
        launch(grid_bucket_ranges, dim=n, device=self.device, inputs=[
            radii, self.body_static,  # Model
            positions,  # State in
            n, self.table_size, self.body_cell, self.cell_key, self.cell_body,  # In
            self.bucket_first, self.sorted_pos, self.sorted_radius, self.sorted_static, self.sorted_cell,  # Out
        ])
        self._rows(n, margin, 0)
        self._scan_rows(n)
        self._rows(n, margin, 1)


class HashGridBroadPhase(GridBroadPhase):
    """Uniform grid on ``wp.HashGrid``.

    The grid's dimensions follow the bodies' cell bounds like grid_sorted's table, which needs
    the 6 bounds on the host each call (a sync on CUDA, so this variant is not graph-capturable).
    HashGrid computes cell coordinates in float32: exact to about 1e4 cell widths from the
    origin (see CELL_SLACK).
    """

    name = "grid_hash"

    def __init__(self, body_count: int, capacity: int, device=None):
        super().__init__(body_count, capacity, device)
        self.grid_dims = None
        self.grid = None

    def _rows(self, n, positions, radii, margin, query_radius, emit):
        launch(grid_hash_rows, dim=n, device=self.device, inputs=[
            radii, self.body_static,  # Model
            positions,  # State in
            self.grid.id, query_radius, margin, emit, self.row_start, self.capacity,  # In
            self.row_count, self.pair_body,  # Out
        ])

    def _find_rows(self, n, positions, radii, margin):
        width = self.cell_width(radii, margin)
        self._cells(n, positions, 1.0 / width)
        dims = tuple(1 << b for b in table_layout_host(self.cell_bounds.numpy(), self.table_bits))
        if dims != self.grid_dims:
            self.grid = wp.HashGrid(*dims, device=self.device)
            self.grid_dims = dims
        self.grid.build(positions[:n], width)
        query_radius = width * (1.0 + CELL_SLACK)
        self._rows(n, positions, radii, margin, query_radius, 0)
        self._scan_rows(n)
        self._rows(n, positions, radii, margin, query_radius, 1)


BROAD_PHASES = {
    "all_pairs": AllPairsBroadPhase,
    "bounding_sphere": BoundingSphereBroadPhase,
    "grid_sorted": SortedGridBroadPhase,
    "grid_hash": HashGridBroadPhase,
}
# bench/broad_phase.py: the sorted grid is the faster one on CPU at 1k-100k bodies
BROAD_PHASES["grid"] = BROAD_PHASES["grid_sorted"]


def make_broad_phase(name: str, body_count: int, capacity: int, device=None) -> BroadPhase:
    """A broad phase by name: all_pairs, bounding_sphere, grid (= the faster grid), grid_sorted, grid_hash."""
    try:
        cls = BROAD_PHASES[name]
    except KeyError:
        raise ValueError(f"unknown broad phase {name!r}; choose one of {', '.join(BROAD_PHASES)}") from None
    return cls(body_count, capacity, device)
