"""Uniform-grid broad phases (see broad_phase.py for the shared contract and the derivation).

``grid_sorted`` radix-sorts the bodies by cell bucket and scans each run of three x-neighbour
cells as one contiguous range; ``grid_hash`` queries ``wp.HashGrid`` with the same dimensions.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from ..launch import LIGHT_CHUNK, launch
from .broad_phase import (
    BroadPhase,
    CELL_SLACK,
    cell_of,
    sort_row,
    spheres_overlap,
)

# No kernel here is differentiated: skip generating (and compiling) the adjoints.
wp.set_module_options({"enable_backward": False})

# The sorted grid's rows are counted and placed in two passes over the neighbour cells; the
# first keeps up to ROW_STASH pairs a body so the second can copy them (rows are short: 0.7
# pairs a body in a settled rain of 10k).  The stash costs 8 bytes x ROW_STASH a body.
ROW_STASH = 8

# Grids: cells, bounds and table layout ----------------------------------------------------------


@wp.kernel
def grid_cells(
    tid_offset: int,
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    # In
    inv_cell: wp.array(dtype=wp.float64),
    # Out
    body_cell: wp.array(dtype=wp.vec3i),
):
    i = wp.tid() + tid_offset
    body_cell[i] = cell_of(body_pos[i], inv_cell[0])


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
    # In (mark_static: 1 where the inverse mass is 0)
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


@wp.func
def grid_sorted_row(
    s: int,
    margin: float,
    layout: wp.vec3i,
    bucket_first: wp.array(dtype=wp.int32),
    cell_body: wp.array(dtype=wp.int32),
    sorted_pos: wp.array(dtype=wp.vec3),
    sorted_radius: wp.array(dtype=float),
    sorted_static: wp.array(dtype=wp.int32),
    sorted_cell: wp.array(dtype=wp.vec3i),
    emit: int,
    start: wp.int64,
    limit: int,
    out: wp.array(dtype=wp.vec2i),
) -> int:
    """Row of the body at sorted index s: its pairs (i, j > i), written from out[start] (below
    index ``limit``) when ``emit``; returns how many there are.

    The 27 neighbour cells are 9 runs of three cells along x; unless the run wraps around the
    table they are three consecutive buckets, i.e. one contiguous range of sorted bodies."""
    i = cell_body[s]
    x_i = sorted_pos[s]
    r_i = sorted_radius[s]
    static_i = sorted_static[s]
    c = sorted_cell[s]
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
                                      sorted_static, sorted_cell, emit, start, count, limit, out)
            else:
                for dx in range(-1, 2):
                    b = cell_bucket(wp.vec3i(c[0] + dx, y, z), layout)
                    count = grid_scan_run(bucket_first[b], bucket_first[b + 1], c[0] + dx, c[0] + dx, y, z,
                                          i, x_i, r_i, static_i, margin, cell_body, sorted_pos, sorted_radius,
                                          sorted_static, sorted_cell, emit, start, count, limit, out)
    return count


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
    stash: int,
    # Out
    row_count: wp.array(dtype=wp.int64),
    row_stash: wp.array(dtype=wp.vec2i),
):
    """One thread per body in bucket order: counts row i and keeps its first ``stash`` pairs in
    row_stash[s * stash:], so grid_sorted_place can usually copy instead of scanning again."""
    s = wp.tid() + tid_offset
    first = wp.int64(s) * wp.int64(stash)
    count = grid_sorted_row(s, margin, table_layout[0], bucket_first, cell_body, sorted_pos, sorted_radius,
                            sorted_static, sorted_cell, 1, first, int(first) + stash, row_stash)
    row_count[cell_body[s]] = wp.int64(count)


@wp.kernel
def grid_sorted_place(
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
    stash: int,
    row_stash: wp.array(dtype=wp.vec2i),
    row_count: wp.array(dtype=wp.int64),
    row_start: wp.array(dtype=wp.int64),
    capacity: int,
    # Out
    pair_body: wp.array(dtype=wp.vec2i),
):
    """Row i into its place from row_start[i], sorted by j: copied from the stash when it fit
    there, else scanned again (the same scan, so the same pairs)."""
    s = wp.tid() + tid_offset
    i = cell_body[s]
    start = row_start[i]
    count = int(row_count[i])
    if start >= wp.int64(capacity) or count == 0:
        return
    if count <= stash:
        first = s * stash
        for k in range(count):
            if start + wp.int64(k) < wp.int64(capacity):
                pair_body[int(start) + k] = row_stash[first + k]
    else:
        grid_sorted_row(s, margin, table_layout[0], bucket_first, cell_body, sorted_pos, sorted_radius,
                        sorted_static, sorted_cell, 1, start, capacity, pair_body)
    if count > 1:
        end = wp.min(start + wp.int64(count), wp.int64(capacity))
        sort_row(pair_body, wp.int32(start), wp.int32(end - start))


# grid_hash --------------------------------------------------------------------------------------


@wp.kernel
def grid_hash_rows(
    tid_offset: int,
    # Model
    body_bound_radius: wp.array(dtype=float),
    # In (mark_static: 1 where the inverse mass is 0)
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
        launch(grid_cells, dim=n, device=self.device, inputs=[positions, inv_cell, self.body_cell],
               min_chunk=LIGHT_CHUNK)
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
        self.row_stash = wp.zeros(n * ROW_STASH, dtype=wp.vec2i, device=self.device)

    def _rows(self, n, margin):
        """Count every row, stashing its first ROW_STASH pairs; scan; then place the rows."""
        grid = [margin, self.table_layout, self.bucket_first, self.cell_body,
                self.sorted_pos, self.sorted_radius, self.sorted_static, self.sorted_cell, ROW_STASH]
        launch(grid_sorted_rows, dim=n, device=self.device, inputs=[*grid, self.row_count, self.row_stash])
        self._scan_rows(n)
        launch(grid_sorted_place, dim=n, device=self.device, inputs=[
            *grid, self.row_stash, self.row_count, self.row_start, self.capacity, self.pair_body])

    def _find_rows(self, n, positions, radii, margin):
        self._cells(n, positions, self.device_inv_cell(radii, n, margin, self._radii_vary))
        wp.launch(grid_table_layout, dim=1, device=self.device,
                  inputs=[self.table_bits, self.cell_bounds, self.table_layout])
        launch(grid_bucket_keys, dim=n, device=self.device, min_chunk=LIGHT_CHUNK,
               inputs=[self.body_cell, self.table_layout, self.cell_key, self.cell_body])
        wp.utils.radix_sort_pairs(self.cell_key, self.cell_body, n, 0, self.table_bits)
        launch(grid_bucket_ranges, dim=n, device=self.device, min_chunk=LIGHT_CHUNK, inputs=[
            radii, self.body_static,  # Model
            positions,  # State in
            n, self.table_size, self.body_cell, self.cell_key, self.cell_body,  # In
            self.bucket_first, self.sorted_pos, self.sorted_radius, self.sorted_static, self.sorted_cell,  # Out
        ])
        self._rows(n, margin)


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
        if self._radii_vary:
            self.invalidate_radii()
        width = self.cell_width(radii, margin)
        self.inv_cell.fill_(1.0 / width)
        self._cells(n, positions, self.inv_cell)
        dims = tuple(1 << b for b in table_layout_host(self.cell_bounds.numpy(), self.table_bits))
        if dims != self.grid_dims:
            self.grid = wp.HashGrid(*dims, device=self.device)
            self.grid_dims = dims
        self.grid.build(positions[:n], width)
        query_radius = width * (1.0 + CELL_SLACK)
        self._rows(n, positions, radii, margin, query_radius, 0)
        self._scan_rows(n)
        self._rows(n, positions, radii, margin, query_radius, 1)
