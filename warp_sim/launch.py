"""Kernel launches that use every CPU core.

Warp runs one CPU launch on one thread.  Its launch call releases the GIL, so splitting the
index range into chunks launched from a thread pool runs them on separate cores.  Kernels
launched this way take ``tid_offset`` as their first argument and use ``wp.tid() + tid_offset``.
Each index is still handled by exactly one thread, so a launch's results do not depend on the
thread count (the CPU pair schedule of solvers/domains.py does: it cuts the scene into one slab
per thread).  Kernels launched this way must not count through shared atomics: Warp's CPU
``atomic_add`` is a plain read-modify-write, so two chunks racing on one counter lose updates
(measured: 4M increments over 2 threads gave 3.29M).  Variable-length outputs use
count / scan / write instead (see collide/broad_phase.py); the one shared write left is the
non-finite flag, which any racing writer still leaves non-zero.

On CUDA it is a single ordinary launch (and so graph-capturable), of at most ``BLOCKS_PER_SM``
blocks a multiprocessor: Warp's kernels loop over their index range in grid strides, so a launch
sized by a capacity (12 pairs a body, of which a rain uses about one) walks its idle tail inside
resident threads instead of scheduling a block for every 256 of them.  On an H200 with 1M bodies
the cap more than halved the colouring's time, nearly all of which had been blocks whose threads
returned at once, but slowed collide_pairs, whose capped threads run several heavy pairs in a
row; that kernel launches uncapped (``capped = False``; figures in the README's GPU path and
bench/results/gpu_h200*.json).  During a CPU graph capture
(Warp records the launches for replay, ``wp.ScopedCapture(device="cpu")``) it is one launch too,
recorded in order on the calling thread.  ``race_check.RaceCheck`` replaces every launch made
through here with checked ones (chunk orders shuffled and reversed, each thread run alone).
``WARP_SIM_CPU_THREADS`` overrides the thread count (default: all cores).  While a simulator runs
its steps the extra threads wait for their chunks spinning instead of sleeping (``hot``, below).

Packing 20-30 kernel arguments costs ~30 us per ``wp.launch`` in Python, more than a small
kernel runs.  A call site that passes ``key`` keeps recorded launch commands (one per chunk) and
afterwards resets only the arguments that changed (by identity, or by value for plain numbers),
which brings a launch down to a few microseconds.  ``key`` is the owning object (a solver, a
contact buffer); the commands are dropped with it.
"""

from __future__ import annotations

import os
import threading
import weakref
from concurrent.futures import ThreadPoolExecutor

import warp as wp

LIGHT_CHUNK = 1 << 16  # for kernels of a few loads and stores a thread (cell keys, flags): at
#                        10k bodies one such launch ran 0.2 ms split in two, nearly all hand-off
MIN_CHUNK = 4096  # below this a chunk costs more in thread hand-off than it saves (rain of 1k bodies:
#                   43 steps/s on one thread, 38 split in two; 10k: 5.3 on one, 8.1 split)
PAIR_CHUNK = 256  # for the colour schedule's pair sweeps, a pair's solve a thread: a few hundred pairs
#                   outweigh a hand-off, and at MIN_CHUNK each colour of the 10k rain (600 to 1,500
#                   pairs) ran on one core (its pair sweeps 12.4 ms a step on one, 9.4 split in two)

BLOCKS_PER_SM = 8  # 2048 resident threads a multiprocessor at 256 a block: a full machine, no more
_CPU_COUNT = os.cpu_count() or 1  # asked once: the call costs ~9 us, and launches ask per launch
_pool: ThreadPoolExecutor | None = None
_warm: set = set()
_recorded: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # owner -> {(kernel, device): _Recorded}
_checker = None  # a race_check.RaceCheck while one is active
_hot = None  # a _HotWorkers while hot() is active


def set_checker(checker) -> None:
    global _checker
    _checker = checker


class _Recorded:
    def __init__(self):
        self.inputs: list = []
        self.commands: list = []


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
    return _CPU_COUNT


def _executor(threads: int) -> ThreadPoolExecutor:
    global _pool
    if _pool is None or _pool._max_workers != threads:
        _pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="warp_sim")
    return _pool


def gpu_blocks(device) -> dict:
    """``wp.launch`` keywords capping a CUDA launch's blocks (module docstring); none on the CPU."""
    device = wp.get_device(device)
    if device.is_cuda and device.sm_count > 0:
        return {"max_blocks": device.sm_count * BLOCKS_PER_SM}
    return {}


def launch(kernel, dim: int, inputs: list, device, key=None, min_chunk: int = MIN_CHUNK,
           capped: bool = True) -> None:
    """``min_chunk``: the fewest indices worth a thread of their own (1 for kernels whose
    threads each carry a large share of the work, such as solvers/domains.py's slabs).
    ``capped = False``: no block cap on CUDA (module docstring), for a heavy kernel whose threads
    run several of its items in a row when capped (collide_pairs)."""
    device = wp.get_device(device)
    blocks = gpu_blocks(device) if capped and device.is_cuda else {}
    if dim <= 0:
        return
    if _checker is not None and (device.is_cpu or _checker.any_device):
        _checker.launch(kernel, dim, [0, *inputs], device)
        return
    if device.is_cpu and device.is_capturing:
        wp.launch(kernel, dim=dim, inputs=[0, *inputs], device=device)
        return
    threads = cpu_threads() if device.is_cpu else 1
    chunks = min(threads, dim // min_chunk)
    warm_key = (kernel, device.alias)
    if warm_key not in _warm:
        # the first launch compiles and loads the module: do it on this thread, whole
        wp.launch(kernel, dim=dim, inputs=[0, *inputs], device=device, **blocks)
        _warm.add(warm_key)
        return
    chunks = max(chunks, 1)
    bounds = [dim * k // chunks for k in range(chunks + 1)]
    if key is None:
        jobs = [(wp.launch, (kernel, bounds[k + 1] - bounds[k], [bounds[k], *inputs]),
                 {"device": device, **blocks}) for k in range(chunks)]
    else:
        commands = _commands(key, kernel, inputs, device, chunks, blocks)
        jobs = []
        for k in range(chunks):
            cmd = commands[k]
            cmd.set_dim(bounds[k + 1] - bounds[k])
            cmd.set_param_at_index(0, bounds[k])
            jobs.append((cmd.launch, (), {}))
    if chunks == 1:
        fn, args, kwargs = jobs[0]
        fn(*args, **kwargs)
        return
    if _hot is not None and _hot.width >= chunks and _hot_owner == threading.get_ident():
        _hot.run(jobs)
        return
    # the calling thread runs the first chunk itself: one hand-off fewer per launch
    pool = _executor(threads)
    futures = [pool.submit(fn, *args, **kwargs) for fn, args, kwargs in jobs[1:]]
    fn, args, kwargs = jobs[0]
    fn(*args, **kwargs)
    for f in futures:
        f.result()


def _same(old, new) -> bool:
    if old is new:
        return True
    return type(old) in (int, float, bool) and type(new) is type(old) and old == new


def _commands(key, kernel, inputs: list, device, chunks: int, blocks: dict) -> list:
    """Recorded launch commands for this call site, with their arguments brought up to date."""
    site = _recorded.setdefault(key, {})
    entry = site.get((kernel, device.alias))
    if entry is None or len(entry.inputs) != len(inputs):
        entry = _Recorded()
        site[(kernel, device.alias)] = entry
    if len(entry.commands) < chunks or not entry.inputs:
        entry.inputs = list(inputs)
        entry.commands = [wp.launch(kernel, dim=1, inputs=[0, *inputs], device=device, record_cmd=True,
                                    **blocks) for _ in range(max(chunks, len(entry.commands)))]
        return entry.commands
    for index, (old, new) in enumerate(zip(entry.inputs, inputs)):
        if not _same(old, new):
            for cmd in entry.commands:
                cmd.set_param_at_index(index + 1, new)
            entry.inputs[index] = new
    return entry.commands


# Hot workers ---------------------------------------------------------------------------------
# A pool thread waiting for its next chunk sleeps in the kernel, and waking it costs more than the
# Python it runs: on a virtual machine whose idle CPUs halt at once, the CPU must be woken too,
# and the scheduler may start the woken thread on the launching thread's CPU, where the two
# chunks then share one core (bench/handoff.py measures the hand-off either way).  During a run
# of steps (Simulator._run_steps enters ``hot``) each extra thread instead waits for its next
# chunk in pthread_spin_lock: a C call that holds no GIL, so the launching thread runs Python
# freely while it spins.  The chunks, their order and their results are those of the pool (each
# chunk is a whole launch of its own index range); between runs the threads are parked on an
# Event and use no CPU.  Only the thread that entered ``hot`` hands chunks to them.  Off where
# libc has no pthread spinlocks, with ``WARP_SIM_HOT=0`` (the tests set it: two test processes
# on two cores would each spin a core away from the other), and with one CPU thread.


def _spin_library():
    """libc's pthread spinlock calls, or None where there are none (not glibc)."""
    import ctypes

    try:
        libc = ctypes.CDLL(None)
        calls = {name: getattr(libc, "pthread_spin_" + name) for name in ("init", "lock", "unlock", "trylock")}
    except (OSError, AttributeError, TypeError):  # no libc to load (Windows), or no spinlocks in it (macOS)
        return None
    for name, call in calls.items():
        call.argtypes = [ctypes.POINTER(ctypes.c_int)] + ([ctypes.c_int] if name == "init" else [])
        call.restype = ctypes.c_int
    return calls


_PARK = object()


class _HotWorker:
    """One spinning thread: ``go`` unlocked hands it a job (or _PARK), ``done`` unlocked says the
    job ran; both are locked while nothing is pending."""

    def __init__(self, spin):
        import ctypes
        import threading

        self.spin = spin
        self.locks = (ctypes.c_int(), ctypes.c_int())
        self.go, self.done = (ctypes.byref(lock) for lock in self.locks)
        for lock in (self.go, self.done):
            spin["init"](lock, 0)
            spin["lock"](lock)
        self.job = None
        self.error = None
        self.wake = threading.Event()
        self.parked = threading.Event()
        threading.Thread(target=self._loop, name="warp_sim_hot", daemon=True).start()

    def _loop(self):
        while True:
            self.wake.wait()
            self.wake.clear()
            while True:
                self.spin["lock"](self.go)
                job = self.job
                if job is _PARK:
                    break
                try:
                    fn, args, kwargs = job
                    fn(*args, **kwargs)
                except BaseException as error:  # noqa: BLE001 - raised again on the launching thread
                    self.error = error
                self.spin["unlock"](self.done)
            self.parked.set()

    def start(self, job):
        self.job = job
        self.spin["unlock"](self.go)

    def finish(self):
        self.spin["lock"](self.done)
        error, self.error = self.error, None
        if error is not None:
            raise error

    def park(self):
        self.job = _PARK
        self.spin["unlock"](self.go)
        self.parked.wait()
        self.parked.clear()
        self.spin["trylock"](self.done)  # locked again, whether or not an interrupted launch took its signal


class _HotWorkers:
    def __init__(self, width: int, spin):
        self.width = width
        self.pid = os.getpid()  # threads do not survive a fork: a child makes its own
        self.workers = [_HotWorker(spin) for _ in range(width - 1)]

    def run(self, jobs):
        started = []
        try:
            for worker, job in zip(self.workers, jobs[1:]):
                worker.start(job)
                started.append(worker)
            fn, args, kwargs = jobs[0]
            fn(*args, **kwargs)
        finally:
            for worker in started:
                worker.finish()


_hot_pool: _HotWorkers | None = None
_hot_owner: int | None = None  # the thread whose launches use _hot
_hot_depth = 0


class hot:
    """While active, the calling thread's split launches hand their chunks to spinning workers
    (the section comment); nests, and is a no-op on other threads meanwhile."""

    def __enter__(self):
        global _hot, _hot_pool, _hot_owner, _hot_depth
        me = threading.get_ident()
        if _hot_owner not in (None, me):
            return self
        _hot_owner = me
        _hot_depth += 1
        threads = cpu_threads()
        if _hot_depth == 1 and os.environ.get("WARP_SIM_HOT", "1") != "0" and threads > 1:
            if _hot_pool is None or _hot_pool.width != threads or _hot_pool.pid != os.getpid():
                spin = _spin_library()
                _hot_pool = _HotWorkers(threads, spin) if spin is not None else None
            if _hot_pool is not None:
                for worker in _hot_pool.workers:
                    worker.wake.set()
                _hot = _hot_pool
        return self

    def __exit__(self, *exc):
        global _hot, _hot_owner, _hot_depth
        if _hot_owner != threading.get_ident():
            return False
        _hot_depth -= 1
        if _hot_depth == 0:
            _hot_owner = None
            if _hot is not None:
                _hot = None
                for worker in _hot_pool.workers:
                    worker.park()
        return False

