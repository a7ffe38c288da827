"""Exclusive prefix sums of integer counts (int32 or int64) from preallocated scratch: capturable.

Why not ``wp.utils.array_scan``: on CUDA it allocates CUB's temporary storage on every call.
Inside a captured graph that becomes an allocation node, and a conditional body
(``wp.capture_if``: the mid-step pair pass, the pass after a wake) may hold none; the capture
then fails with "Conditional body graph contains an unsupported operation (memory allocation)".
On an H200 every scene with body contact failed this way at its first captured step.

The scan here is two sweeps over chunks of ``SCAN_CHUNK`` values per thread:

- up: thread t sums its chunk of level l into level l + 1 (ceil(n / 32) values), repeated until a
  level fits in one chunk (log_32 n levels: 5 for 32M);
- top: one thread scans that last level, at most ``SCAN_CHUNK`` values whatever the scene;
- down: thread t writes its chunk's running sums, starting from its chunk's offset.

Integer sums, each written by one thread: the result is exact and the same on every device and
thread count.  Every array is sized once, for ``capacity`` values; ``run`` takes the live count
``n <= capacity`` as a launch dimension (fixed per scene: the callers scan per-body rows).
"""

from __future__ import annotations

from typing import Any

import warp as wp

from .launch import launch

SCAN_CHUNK = wp.constant(32)


@wp.kernel
def chunk_sums(tid_offset: int, values: wp.array(dtype=Any), count: int, sums: wp.array(dtype=Any)):
    t = wp.tid() + tid_offset
    first = t * SCAN_CHUNK
    last = wp.min(first + SCAN_CHUNK, count)
    total = values.dtype(0)
    for i in range(first, last):
        total += values[i]
    sums[t] = total


@wp.kernel
def scan_last_level(tid_offset: int, sums: wp.array(dtype=Any), count: int, offsets: wp.array(dtype=Any)):
    running = sums.dtype(0)
    for i in range(count):  # count <= SCAN_CHUNK: bounded whatever the scene
        offsets[i] = running
        running += sums[i]


@wp.kernel
def chunk_running_sums(tid_offset: int, values: wp.array(dtype=Any), count: int,
                       chunk_offsets: wp.array(dtype=Any), out: wp.array(dtype=Any)):
    t = wp.tid() + tid_offset
    first = t * SCAN_CHUNK
    last = wp.min(first + SCAN_CHUNK, count)
    running = chunk_offsets[t]
    for i in range(first, last):
        out[i] = running
        running += values[i]


# the two widths the broad phases scan, declared up front: the module's content (and so its
# kernel-cache entry) is then fixed at import, and it compiles ahead of time for CUDA
for _t in (wp.int32, wp.int64):
    _a = wp.array(dtype=_t)
    wp.overload(chunk_sums, {"values": _a, "sums": _a})
    wp.overload(scan_last_level, {"sums": _a, "offsets": _a})
    wp.overload(chunk_running_sums, {"values": _a, "chunk_offsets": _a, "out": _a})


def level_sizes(n: int) -> list[int]:
    """Values per level above the input: ceil(n / 32), ceil of that / 32, ... down to <= 32."""
    sizes = []
    while n > SCAN_CHUNK:
        n = (n + SCAN_CHUNK - 1) // SCAN_CHUNK
        sizes.append(n)
    return sizes


class ExclusiveScan:
    """``run(values, out, n)``: out[i] = values[0] + ... + values[i - 1] for i < n."""

    def __init__(self, capacity: int, device, dtype=wp.int32):
        self.capacity = capacity
        self.device = wp.get_device(device)
        self.dtype = dtype
        # per level: the chunk sums and their exclusive scan
        self.sums = [wp.zeros(m, dtype=dtype, device=self.device) for m in level_sizes(max(capacity, 1))]
        self.offsets = [wp.zeros(m, dtype=dtype, device=self.device) for m in level_sizes(max(capacity, 1))]

    def run(self, values: wp.array, out: wp.array, n: int):
        if n > self.capacity or values.dtype != self.dtype or out.dtype != self.dtype:
            raise ValueError(f"ExclusiveScan of {n} values of {values.dtype.__name__} into {out.dtype.__name__}, "
                             f"built for {self.capacity} of {self.dtype.__name__}")
        if n <= 0:
            return
        sizes = level_sizes(n)
        inputs = [values] + self.sums[:len(sizes)]
        counts = [n] + sizes
        for level, m in enumerate(sizes):
            launch(chunk_sums, dim=m, device=self.device, inputs=[inputs[level], counts[level], self.sums[level]])
        top_out = self.offsets[len(sizes) - 1] if sizes else out
        launch(scan_last_level, dim=1, device=self.device, inputs=[inputs[-1], counts[-1], top_out])
        for level in range(len(sizes) - 1, -1, -1):
            target = out if level == 0 else self.offsets[level - 1]
            launch(chunk_running_sums, dim=sizes[level], device=self.device,
                   inputs=[inputs[level], counts[level], self.offsets[level], target])
