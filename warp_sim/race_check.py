"""GPU races caught on the CPU: every launch made through ``warp_sim.launch`` checked three ways.

On a GPU the threads of a launch run in any order and at once; on the CPU Warp runs them in
index order, which hides two kinds of bug: a thread that reads what another thread of the same
launch writes, and two threads that write one element.  While a ``RaceCheck`` is active each
launch is run

1. whole, in index order (the result that is kept);
2. in chunks, in reversed and in shuffled chunk order, from the same inputs: each must give
   the same bytes as 1;
3. thread by thread, each alone from the same inputs, recording which elements each thread
   changed: no element may be changed by two threads, and laying every thread's changes over
   the inputs must give the bytes of 1 (so no thread depended on another's writes).

Every array argument is checked, and every array field of a struct argument (kernel_args.py),
named ``parameter.field``.  Arrays that a kernel writes from many threads on purpose are
declared in ``SHARED_WRITES`` by kernel and by that name (flags that every writer sets to the
same value); they are exempt from the two-writer rule and from the comparison in 3.  Launches
made with ``wp.launch`` directly (atomics, one-thread bookkeeping) are not checked: Warp's CPU
atomics are not atomic across chunks, so those kernels are never split.  An element changed
to the value it already had is invisible to 3; the orders of 2 still see such a thread if it
reads another's output.

Slow (a launch per thread): tiny scenes only.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import launch as launch_module
from .solvers.pair_solve import SWEEP_MODE_NAMES

# kernel name -> parameters several threads may write (each writer stores the same value)
SHARED_WRITES = {
    "color_pick": {"pending", "overflow"},
    "finalize_bodies": {"bad_steps.bad_count"},
    "solve_and_integrate": {"bad_steps.bad_count"},
}
SHARED_WRITES.update({"domain_sweep_" + name: {"bad_steps.bad_count"} for name in SWEEP_MODE_NAMES.values()})


class RaceError(AssertionError):
    pass


class RaceCheck:
    any_device = False  # CPU launches only

    def __init__(self, chunks: int = 4, seed: int = 0, isolate: bool = True):
        self.chunks = chunks
        self.rng = np.random.default_rng(seed)
        self.isolate = isolate
        self.checked: dict[str, int] = {}  # kernel name -> launches checked
        self.isolated: dict[str, int] = {}  # kernel name -> launches of more than one thread

    def __enter__(self):
        launch_module.set_checker(self)
        return self

    def __exit__(self, *exc):
        launch_module.set_checker(None)
        return False

    def launch(self, kernel, dim: int, inputs: list, device):
        name = kernel.key
        shared = SHARED_WRITES.get(name, set())
        params, arrays = _arrays([arg.label for arg in kernel.adj.args], inputs)
        views = {index: _bytes(a.numpy()) for index, a in enumerate(arrays)}
        before = {k: v.copy() for k, v in views.items()}

        def run(start: int, count: int):
            wp.launch(kernel, dim=count, inputs=[start, *inputs[1:]], device=device)

        def reset(to):
            for k, v in views.items():
                v[...] = to[k]

        run(0, dim)
        normal = {k: v.copy() for k, v in views.items()}
        chunks = max(1, min(self.chunks, dim))
        bounds = [dim * c // chunks for c in range(chunks + 1)]
        if chunks > 1:
            shuffled = list(self.rng.permutation(chunks))
            for label, order in (("reversed", list(range(chunks))[::-1]), ("shuffled", shuffled)):
                reset(before)
                for c in order:
                    run(bounds[c], bounds[c + 1] - bounds[c])
                for k, v in views.items():
                    if not np.array_equal(v, normal[k]):
                        raise RaceError(f"{name}: argument {params[k]!r} differs when the chunks run {label} "
                                        f"(dim {dim}, {chunks} chunks)")
        if self.isolate and dim > 1:
            self._isolate(name, params, shared, dim, views, before, normal, run, reset)
            self.isolated[name] = self.isolated.get(name, 0) + 1
        reset(normal)
        self.checked[name] = self.checked.get(name, 0) + 1

    def _isolate(self, name, params, shared, dim, views, before, normal, run, reset):
        writer = {k: np.full(v.shape[0], -1, dtype=np.int64) for k, v in views.items()}
        composed = {k: v.copy() for k, v in before.items()}
        reset(before)
        for t in range(dim):
            run(t, 1)
            for k, v in views.items():
                changed = np.flatnonzero((v != before[k]).any(axis=1))
                if changed.size == 0:
                    continue
                if params[k] not in shared:
                    clash = changed[writer[k][changed] >= 0]
                    if clash.size:
                        e = int(clash[0])
                        raise RaceError(f"{name}: element {e} of {params[k]!r} written by threads "
                                        f"{int(writer[k][e])} and {t}")
                    writer[k][changed] = t
                composed[k][changed] = v[changed]
                v[changed] = before[k][changed]
        for k in views:
            if params[k] in shared:
                continue
            if not np.array_equal(composed[k], normal[k]):
                bad = int(np.flatnonzero((composed[k] != normal[k]).any(axis=1))[0])
                raise RaceError(f"{name}: element {bad} of {params[k]!r} depends on other threads of the launch "
                                f"(each thread alone from the same inputs gives another value)")


def _arrays(labels: list, inputs: list) -> tuple[list, list]:
    """The names and arrays of a launch's array arguments, struct fields included, each storage
    once (restoring one view of an array twice would undo the other's record of a write)."""
    names, arrays, seen = [], [], set()
    for label, value in zip(labels, inputs):
        if isinstance(value, wp.array):
            found = [(label, value)]
        elif hasattr(value, "_cls") and hasattr(value._cls, "vars"):  # a wp.struct instance
            found = [(f"{label}.{field}", getattr(value, field)) for field in value._cls.vars]
        else:
            continue
        for name, a in found:
            if isinstance(a, wp.array) and a.size > 0 and a.ptr not in seen:
                seen.add(a.ptr)
                names.append(name)
                arrays.append(a)
    return names, arrays


def _bytes(a: np.ndarray) -> np.ndarray:
    """A writable (elements, bytes) view of a CPU array's storage (a zero-copy view)."""
    a = a.reshape(a.shape[0], -1) if a.dtype.fields is None else a.reshape(a.shape[0])
    return a.view(np.uint8).reshape(a.shape[0], -1)
