"""Byte model: bytes read and written per body-step, per kernel, counted from one real step.

Every launch made through ``warp_sim.launch`` during one step is recorded with its dimension
and its array arguments.  The model charges each launch, for each array argument, the elements
its live threads own, read and written once:

    bytes = sum over arrays  itemsize x min(length, live x ceil(length / dim))

``live`` is the launch's dimension, except for launches sized by the pair capacity or a colour
bound, whose live threads are the pairs found (the rest return after reading one counter).
``ceil(length / dim)`` is the elements a thread owns (1 for a per-body array in a per-body
launch, the slots of a body for the terrain slots, 4 points for a pair's point arrays).
What it leaves out: launches made with ``wp.launch`` directly (one-thread bookkeeping, the
atomic colouring claims, the radix sorts and scans), reads of other bodies through the pair
list beyond one element a thread, and caches: it is a model of the traffic a GPU has to move
at least once, the floor that ``bench/gpu.py`` divides by the measured time.

    python bench/byte_model.py [--count 2000] [--device cpu]
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import warp as wp  # noqa: E402

from warp_sim import FourierTerrain, cases  # noqa: E402
from warp_sim import launch as launch_module  # noqa: E402


class ByteCounter:
    """A launch.py checker that runs each launch unchanged and records its arguments."""

    any_device = True

    def __init__(self, pair_live: int, pair_dims: set[int]):
        self.pair_live = pair_live
        self.pair_dims = pair_dims
        self.kernels: dict[str, dict] = defaultdict(lambda: {"launches": 0, "bytes": 0})

    def launch(self, kernel, dim, inputs, device):
        wp.launch(kernel, dim=dim, inputs=inputs, device=device)
        live = min(dim, self.pair_live) if dim in self.pair_dims else dim
        total = 0
        for value in inputs:
            if isinstance(value, wp.array) and value.size > 0:
                per_thread = math.ceil(value.size / dim)
                total += wp.types.type_size_in_bytes(value.dtype) * min(value.size, live * per_thread)
        entry = self.kernels[kernel.key]
        entry["launches"] += 1
        entry["bytes"] += total

    def __enter__(self):
        launch_module.set_checker(self)
        return self

    def __exit__(self, *exc):
        launch_module.set_checker(None)
        return False


def count_step(sim) -> dict[str, dict]:
    """Per-kernel launches and bytes of one step of ``sim`` (run it a little first)."""
    pair_live, pair_dims = 0, set()
    if sim.pairs is not None:
        pair_live = int(sim.contacts.pair_count.numpy()[0])
        pair_dims = {sim.pairs.capacity, max(1, min(sim.pairs.capacity, sim.model.body_count))}
    with ByteCounter(pair_live, pair_dims) as counter:
        sim.step(check=False)
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
    mixed bodies with body contact; both settled for 30 steps."""
    terrain = FourierTerrain(amplitude=0.5)
    spheres = cases.terrain_drop(count, "sphere", terrain=terrain, device=device, sleep=False)
    mixed = cases.terrain_drop(count, "mix", terrain=terrain, spacing=0.9, body_contact=True, device=device,
                               sleep=False, pair_schedule="colors")  # the GPU schedule
    for sim in (spheres, mixed):
        sim.step(30)
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
