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

The grids' cell width comes from the largest radius, reduced on the device (an atomic max,
whose result does not depend on the order of the writers) whenever the radii array changes or
the caller says its radii vary (the pair pipeline's swept radii); nothing is read back, so the
sorted grid and the O(N^2) methods can be captured in a graph.  ``grid_hash`` still needs the
width and its bounds on the host (wp.HashGrid's dimensions and build radius are host values).
"""

from __future__ import annotations


import numpy as np
import warp as wp

from ..launch import LIGHT_CHUNK, gpu_blocks, launch
from ..prefix_sum import ExclusiveScan

# No kernel here is differentiated: skip generating (and compiling) the adjoints.
wp.set_module_options({"enable_backward": False})

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


@wp.kernel
def radius_max(
    # In
    radii: wp.array(dtype=float),
    # Out: atomic max, one plain launch (Warp's CPU atomics are not atomic across launch chunks)
    max_radius: wp.array(dtype=float),
):
    wp.atomic_max(max_radius, 0, radii[wp.tid()])


@wp.kernel
def grid_scale(
    # In
    margin: float,
    max_radius: wp.array(dtype=float),
    # Out
    inv_cell: wp.array(dtype=wp.float64),
):
    width = (wp.float64(2.0) * wp.float64(max_radius[0]) + wp.float64(margin)) * wp.float64(1.0 + CELL_SLACK)
    inv_cell[0] = wp.float64(1.0) / (width + wp.float64(1.0e-12))


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
    # In (mark_static: 1 where the inverse mass is 0)
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
        self.row_scan = ExclusiveScan(n, self.device, wp.int64)  # capturable, no temporary allocation
        self._radius_key = None
        self._max_radius = 0.0
        self._device_radius_key = None
        self._radii_vary = False
        self.max_radius_device = wp.zeros(1, dtype=float, device=self.device)
        self.inv_cell = wp.zeros(1, dtype=wp.float64, device=self.device)

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

    def run(self, positions: wp.array, radii: wp.array, inv_mass: wp.array | None = None, margin: float = 0.0,
            radii_vary: bool = False):
        """Launch the broad phase.  Reads nothing back except, for grid_hash, the largest radius
        and the cell bounds; the others can be captured in a graph.  ``radii_vary``: the radii
        change between calls (the largest is then reduced again every call)."""
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
            launch(mark_static, dim=n, inputs=[inv_mass, self.body_static], device=self.device,
                   min_chunk=LIGHT_CHUNK)
        self._radii_vary = radii_vary
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
        self._device_radius_key = None

    def device_inv_cell(self, radii: wp.array, n: int, margin: float, radii_vary: bool) -> wp.array:
        """1 / cell width as a float64[1] device array (the host formula of cell_width)."""
        key = (radii.ptr, n)
        if radii_vary or key != self._device_radius_key:
            self.max_radius_device.zero_()
            wp.launch(radius_max, dim=n, device=self.device, **gpu_blocks(self.device),
                      inputs=[radii[:n], self.max_radius_device])
            self._device_radius_key = key
        wp.launch(grid_scale, dim=1, device=self.device, inputs=[margin, self.max_radius_device, self.inv_cell])
        return self.inv_cell

    def cell_width(self, radii: wp.array, margin: float) -> float:
        return (2.0 * self.max_radius(radii) + margin) * (1.0 + CELL_SLACK) + 1.0e-12

    def _scan_rows(self, n: int):
        self.row_scan.run(self.row_count, self.row_start, n)

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
        self.static_scan = ExclusiveScan(max(body_count, 1), self.device, wp.int32)

    def _find_rows(self, n, positions, radii, margin):
        self.static_scan.run(self.body_static, self.static_before, n)
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


BROAD_PHASES = ("all_pairs", "bounding_sphere", "grid_sorted", "grid_hash", "grid")


def make_broad_phase(name: str, body_count: int, capacity: int, device=None) -> BroadPhase:
    """A broad phase by name: all_pairs, bounding_sphere, grid (= the faster grid), grid_sorted, grid_hash."""
    from .broad_phase_grid import HashGridBroadPhase, SortedGridBroadPhase  # the grids build on this module

    classes = {
        "all_pairs": AllPairsBroadPhase,
        "bounding_sphere": BoundingSphereBroadPhase,
        "grid_sorted": SortedGridBroadPhase,
        "grid_hash": HashGridBroadPhase,
        # bench/broad_phase.py: the sorted grid is the faster one on CPU at 1k-100k bodies
        "grid": SortedGridBroadPhase,
    }
    if name not in classes:
        raise ValueError(f"unknown broad phase {name!r}; choose one of {', '.join(BROAD_PHASES)}")
    return classes[name](body_count, capacity, device)
