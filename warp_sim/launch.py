"""Kernel launches that use every CPU core.

Warp runs one CPU launch on one thread.  Its launch call releases the GIL, so splitting the
index range into chunks launched from a thread pool runs them on separate cores.  Kernels
launched this way take ``tid_offset`` as their first argument and use ``wp.tid() + tid_offset``.
Each index is still handled by exactly one thread, so results do not depend on the thread
count.  Kernels launched this way must not count through shared atomics: Warp's CPU
``atomic_add`` is a plain read-modify-write, so two chunks racing on one counter lose updates
(measured: 4M increments over 2 threads gave 3.29M).  Variable-length outputs use
count / scan / write instead (see collide/broad_phase.py); the one shared write left is the
non-finite flag, which any racing writer still leaves non-zero.

On CUDA it is a single ordinary launch (and so graph-capturable).
``WARP_SIM_CPU_THREADS`` overrides the thread count (default: all cores).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import warp as wp

MIN_CHUNK = 2048  # below this a chunk costs more in thread hand-off than it saves

_pool: ThreadPoolExecutor | None = None
_warm: set = set()


def cpu_threads() -> int:
    value = os.environ.get("WARP_SIM_CPU_THREADS")
    if value:
        try:
            threads = int(value)
        except ValueError:
            raise ValueError(f"WARP_SIM_CPU_THREADS must be a positive integer, got {value!r}") from None
        if threads < 1:
            raise ValueError(f"WARP_SIM_CPU_THREADS must be a positive integer, got {value!r}")
        return threads
    return os.cpu_count() or 1


def _executor(threads: int) -> ThreadPoolExecutor:
    global _pool
    if _pool is None or _pool._max_workers != threads:
        _pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="warp_sim")
    return _pool


def launch(kernel, dim: int, inputs: list, device) -> None:
    device = wp.get_device(device)
    if dim <= 0:
        return
    threads = cpu_threads() if device.is_cpu else 1
    chunks = min(threads, dim // MIN_CHUNK)
    key = (kernel, device.alias)
    if chunks <= 1 or key not in _warm:
        # the first launch compiles and loads the module: do it on this thread, whole
        wp.launch(kernel, dim=dim, inputs=[0, *inputs], device=device)
        _warm.add(key)
        return
    bounds = [dim * k // chunks for k in range(chunks + 1)]
    pool = _executor(threads)
    futures = [
        pool.submit(wp.launch, kernel, bounds[k + 1] - bounds[k], [bounds[k], *inputs], device=device)
        for k in range(chunks)
    ]
    for f in futures:
        f.result()
