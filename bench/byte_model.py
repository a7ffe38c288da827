"""Byte model: bytes read and written per body-step, per kernel, counted from one real step.

Every launch made through ``warp_sim.launch`` during one step is recorded with its dimension
and its array arguments (a struct argument, warp_sim/kernel_args.py, contributes the fields that
the kernel's code, or a package func it calls, names).  The model charges each launch, for each array argument, the elements
its live threads own, read and written once:

    bytes = sum over arrays  itemsize x min(length, live x per_thread)

Per-body launches: ``live`` is the dimension and ``per_thread`` = ceil(length / dim) (1 for a
per-body array, a body's slots for the terrain slot arrays).  Per-pair launches (the narrow
phase, warm-start carry and store, the colouring, and the colour launches of the solver and of
sleeping): ``live`` is the pairs found (for a colour launch, the pairs of that colour; for the
split sweeps of the pairs past the colours, that set; for a colouring round after the last busy
one, none), a pair owns ceil(length / capacity) elements of a pair array (4 points) and 2 of a
per-body array.  Threads past the live count read one counter and are not charged.
Launches made with ``wp.launch`` directly because they use atomics (which launch.py must not
split across CPU threads) are recorded too when they are per-body or per-pair work: the
mid-step reach check (reach_outrun), sleeping's pair passes and the split sweeps (DIRECT_KERNELS).  What it
leaves out: the other direct launches (one-thread bookkeeping, the atomic colouring claims, the
radix sorts and scans), neighbour reads in the broad phase beyond
one element a thread, and caches: it is a model of the traffic a GPU has to move at least once,
the floor that ``bench/gpu.py`` divides by the measured time.

    python bench/byte_model.py [--count 2000] [--device cpu]
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import warp as wp  # noqa: E402

from warp_sim import FourierTerrain, cases  # noqa: E402
from warp_sim import launch as launch_module  # noqa: E402
from warp_sim.schedule.coloring import COLOR_COUNT  # noqa: E402


PAIR_KERNELS = {"collide_pairs", "carry_pair_impulses", "store_pairs", "color_init", "color_pick", "color_keys",
                "color_bounds", "pair_pass", "pushout_pair", "gather_neighbour_timers", "struck_reach"}


# the split sweeps of the pairs past the colours (solvers/pair_overflow.py): live = that set's size
OVERFLOW_KERNELS = {"overflow_count", "overflow_impact_pass", "overflow_pair_pass", "overflow_apply"}

# per-body or per-pair kernels launched with wp.launch directly (atomics: never split)
DIRECT_KERNELS = {"reach_outrun", "mark_touched_sleepers", "gather_neighbour_timers", "overflow_count",
                  "overflow_impact_pass", "overflow_pair_pass", "struck_reach", "impacts_travelling"}


def _function_sources() -> dict[str, str]:
    """Source of every @wp.func of the package, by name."""
    import importlib
    import inspect
    import pkgutil

    import warp_sim

    sources = {}
    for info in pkgutil.walk_packages(warp_sim.__path__, "warp_sim."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for value in vars(module).values():
            if type(value).__name__ == "Function" and getattr(value, "func", None) is not None:
                try:
                    sources.setdefault(value.key, inspect.getsource(value.func))
                except (OSError, TypeError):
                    pass
    return sources


_FUNCTIONS: dict[str, str] | None = None
_FIELDS_USED: dict[str, str] = {}


def kernel_source(kernel) -> str:
    """The kernel's source with that of every package func it calls, transitively: the struct
    fields it can touch are those named in it (``.field``)."""
    global _FUNCTIONS
    if kernel.key in _FIELDS_USED:
        return _FIELDS_USED[kernel.key]
    if _FUNCTIONS is None:
        _FUNCTIONS = _function_sources()
    text, pending, seen = kernel.adj.source, [kernel.adj.source], set()
    while pending:
        for name in re.findall(r"(\w+)\(", pending.pop()):
            if name in _FUNCTIONS and name not in seen:
                seen.add(name)
                text += _FUNCTIONS[name]
                pending.append(_FUNCTIONS[name])
    _FIELDS_USED[kernel.key] = text
    return text


def launch_arrays(kernel, inputs) -> list:
    """The array arguments of a launch: plain arrays, and the fields of struct arguments
    (warp_sim/kernel_args.py) that the kernel's code names; each storage once."""
    found, seen = [], set()
    source = None
    for value in inputs:
        if isinstance(value, wp.array):
            candidates = [value]
        elif hasattr(value, "_cls") and hasattr(value._cls, "vars"):  # a wp.struct instance
            source = source or kernel_source(kernel)
            candidates = [getattr(value, field) for field in value._cls.vars
                          if re.search(r"\." + field + r"\b", source)]
        else:
            continue
        for a in candidates:
            if isinstance(a, wp.array) and a.size > 0 and a.ptr not in seen:
                seen.add(a.ptr)
                found.append(a)
    return found


class ByteCounter:
    """A launch.py checker that runs each launch unchanged and records its arguments."""

    any_device = True

    def __init__(self, sim):
        self.body_count = sim.model.body_count
        self.pair_live = 0
        self.capacity = 1
        if sim.pairs is not None:
            self.capacity = sim.pairs.capacity
        self.kernels: dict[str, dict] = defaultdict(lambda: {"launches": 0, "bytes": 0})

    def launch(self, kernel, dim, inputs, device):
        self._wp_launch(kernel, dim=dim, inputs=inputs, device=device)
        self.count(kernel, dim, inputs)

    def direct_launch(self, kernel, dim=None, inputs=None, device=None, **kwargs):
        self._wp_launch(kernel, dim=dim, inputs=inputs, device=device, **kwargs)
        if kernel.key in DIRECT_KERNELS:
            dims = dim if isinstance(dim, int) else math.prod(dim)
            self.count(kernel, dims, list(inputs or []))

    def count(self, kernel, dim, inputs):
        # the colour sweep is one kernel per mode (pair_solve.PAIR_PASS), counted as one
        name = "pair_pass" if kernel.key.startswith("pair_pass_") else kernel.key
        params = [arg.label for arg in kernel.adj.args]
        args = dict(zip(params, inputs))
        total = 0
        if name == "chain_pass":
            total = self.chain_bytes(kernel, args, inputs)
        elif name in PAIR_KERNELS or name in OVERFLOW_KERNELS:
            live = dim
            for counter in ("pair_count", "broad_pair_count"):
                if counter in args:
                    live = int(args[counter].numpy()[0])
            if "color" in args and "color_start" in args:
                starts = args["color_start"].numpy()
                live = int(starts[args["color"] + 1] - starts[args["color"]])
            if name in OVERFLOW_KERNELS:
                starts = args["color_start"].numpy()
                live = int(starts[COLOR_COUNT + 1] - starts[COLOR_COUNT])
            if "pending" in args and "round_index" in args:
                if int(args["pending"].numpy()[int(args["round_index"].numpy()[0])]) == 0:
                    live = 0  # a colouring round after the last busy one: each thread reads one flag
            live = min(live, dim)
            for value in launch_arrays(kernel, inputs):
                if value.size > 0:
                    per_pair = 2 if value.size == max(self.body_count, 1) else math.ceil(value.size / self.capacity)
                    total += wp.types.type_size_in_bytes(value.dtype) * min(value.size, live * per_pair)
        else:
            for value in launch_arrays(kernel, inputs):
                if value.size > 0:
                    per_thread = math.ceil(value.size / dim)
                    total += wp.types.type_size_in_bytes(value.dtype) * min(value.size, dim * per_thread)
        entry = self.kernels[name]
        entry["launches"] += 1
        entry["bytes"] += total

    def chain_bytes(self, kernel, args, inputs) -> int:
        """chain_pass over one colour: every pair reads its flag (relax) and only the pairs that walk
        touch their two bodies' terrain slots and velocities and their own points; after a solve
        every pair of the colour walks (heavy-on-light scenes)."""
        from warp_sim.solvers.pair_solve import MODE_SOLVE

        starts = args["color_start"].numpy()
        first, last = int(starts[args["color"]]), int(starts[args["color"] + 1])
        pairs = args["color_pairs_sorted"].numpy()[first:last]
        flags = args["pairs"].pair_relax_chain
        total = 0
        walking = len(pairs)
        if args["mode"] != MODE_SOLVE:
            walking = int(flags.numpy()[pairs].sum())
            total += wp.types.type_size_in_bytes(flags.dtype) * len(pairs)
        slot_count = args["slots"].terrain_contact_active.size
        for value in launch_arrays(kernel, inputs):
            if value.size > 0 and value.ptr != flags.ptr:
                if value.size == slot_count:  # terrain slots: both bodies' ranges
                    per_pair = 2 * math.ceil(slot_count / max(self.body_count, 1))
                elif value.size == max(self.body_count, 1):
                    per_pair = 2
                else:  # per pair or per point
                    per_pair = math.ceil(value.size / self.capacity)
                total += wp.types.type_size_in_bytes(value.dtype) * min(value.size, walking * per_pair)
        return total

    def __enter__(self):
        self._wp_launch = wp.launch
        wp.launch = self.direct_launch
        launch_module.set_checker(self)
        return self

    def __exit__(self, *exc):
        launch_module.set_checker(None)
        wp.launch = self._wp_launch
        return False


def count_step(sim) -> dict[str, dict]:
    """Per-kernel launches and bytes of one step of ``sim`` (run it a little first); the step
    runs directly (not replayed from a graph) so that every launch passes through launch.py."""
    graph, sim.use_graph = sim.use_graph, False
    try:
        with ByteCounter(sim) as counter:
            sim.step(check=False)
    finally:
        sim.use_graph = graph
    return dict(counter.kernels)


def per_body_step(sim) -> dict[str, float]:
    """Bytes per body-step per kernel, plus 'total'."""
    kernels = count_step(sim)
    n = sim.model.body_count
    out = {name: k["bytes"] / n for name, k in sorted(kernels.items(), key=lambda kv: -kv[1]["bytes"])}
    out["total"] = sum(k["bytes"] for k in kernels.values()) / n
    return out


def scenes(count: int, device: str = "cpu"):
    """The two scenes of the issue's paper model: spheres on the terrain (terrain contact only),
    mixed bodies with body contact; both run for 90 steps (1.5 s: landed and piled)."""
    terrain = FourierTerrain(amplitude=0.5)
    spheres = cases.terrain_drop(count, "sphere", terrain=terrain, device=device, sleep=False)
    mixed = cases.terrain_drop(count, "mix", terrain=terrain, spacing=0.9, body_contact=True, device=device,
                               sleep=False, pair_schedule="colors")  # the GPU schedule
    for sim in (spheres, mixed):
        sim.step(90)
    return {"spheres_terrain": spheres, "mixed_body_contact": mixed}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--count", type=int, default=2000)
    p.add_argument("--device", default="cpu")
    args = p.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    for name, sim in scenes(args.count, args.device).items():
        model = per_body_step(sim)
        print(f"{name}: {model['total']:.0f} bytes per body-step")
        for kernel, b in model.items():
            if kernel != "total":
                print(f"  {kernel:32s} {b:10.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
