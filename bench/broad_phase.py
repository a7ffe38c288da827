"""Broad-phase cost per call against body count, for every method (ms per find_pairs).

    python bench/broad_phase.py                               # N = 100 .. 100k on cpu
    python bench/broad_phase.py --counts 1000 10000 --methods grid_sorted grid_hash

The scene is a rain of spheres over a ground plane: N spheres of radius 0.1-0.5 m placed
uniformly at random in a slab 10 m high whose footprint gives one body per 1.5 m^3.  Each
case times ``--repeats`` calls after one warm-up call (kernel compile excluded) and records the
median.  The O(N^2) methods are skipped once the previous size predicts more than
``--budget`` seconds per call (or, for all_pairs, a pair buffer over ``--max-pairs``); the
skipped rows say so.  Every method's pair list is checked against the bounding_sphere one
where both ran, and the grids against each other.
Writes bench/results/broad_phase_<device>.{csv,json,png}.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import RESULTS, machine_info, write_rows  # noqa: E402
from warp_sim.collide.broad_phase import BroadPhaseOverflowError, make_broad_phase  # noqa: E402

METHODS = ["all_pairs", "bounding_sphere", "grid_sorted", "grid_hash"]
QUADRATIC = {"all_pairs", "bounding_sphere"}


def rain_scene(count: int, seed: int = 0, height: float = 10.0, volume_per_body: float = 1.5):
    rng = np.random.default_rng(seed)
    side = np.sqrt(count * volume_per_body / height)
    pos = rng.uniform((0.0, 0.5, 0.0), (side, 0.5 + height, side), size=(count, 3)).astype(np.float32)
    pos[:, [0, 2]] -= 0.5 * side
    radius = rng.uniform(0.1, 0.5, size=count).astype(np.float32)
    inv_mass = np.ones(count, dtype=np.float32)
    return pos, radius, inv_mass


def measure(method: str, pos, radius, inv_mass, margin: float, repeats: int, device: str):
    count = len(pos)
    positions = wp.array(pos, dtype=wp.vec3, device=device)
    radii = wp.array(radius, dtype=float, device=device)
    inv = wp.array(inv_mass, dtype=float, device=device)
    capacity = count * (count - 1) // 2 if method == "all_pairs" else 4 * count
    bp = make_broad_phase(method, count, capacity, device)
    try:
        bp.find_pairs(positions, radii, inv, margin)
    except BroadPhaseOverflowError as e:
        bp = make_broad_phase(method, count, e.demand, device)
        bp.find_pairs(positions, radii, inv, margin)
    times = []
    for _ in range(repeats):
        wp.synchronize_device(device)
        start = time.perf_counter()
        pairs = bp.find_pairs(positions, radii, inv, margin)
        wp.synchronize_device(device)
        times.append(time.perf_counter() - start)
    return float(np.median(times)) * 1e3, pairs, bp.pairs().copy()


def chart(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for method in METHODS:
        pts = [(r["bodies"], r["ms_per_call"]) for r in rows if r["method"] == method and r["status"] == "ok"]
        if pts:
            ax.loglog(*zip(*pts), marker="o", label=method)
    ax.set_xlabel("bodies N")
    ax.set_ylabel("ms per find_pairs")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--counts", type=int, nargs="+", default=[100, 300, 1000, 3000, 10000, 30000, 100000])
    p.add_argument("--methods", nargs="+", default=METHODS, choices=METHODS)
    p.add_argument("--margin", type=float, default=0.02)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--budget", type=float, default=5.0, help="skip O(N^2) sizes predicted slower than this [s]")
    p.add_argument("--max-pairs", type=int, default=20_000_000, help="largest all_pairs buffer")
    p.add_argument("--device", default="cpu")
    p.add_argument("--tag", default="", help="suffix for the result file names")
    args = p.parse_args(argv)
    wp.config.quiet = True
    wp.init()
    meta = machine_info(args.device)
    meta.update(scene="rain of spheres, r 0.1-0.5 m, 1 body / 1.5 m^3, 10 m slab", margin=args.margin)
    rows = []
    last = {}  # method -> (N, ms) of its last run, to predict the next O(N^2) size
    for count in sorted(args.counts):
        pos, radius, inv_mass = rain_scene(count)
        results = {}
        for method in args.methods:
            row = {"method": method, "bodies": count, "ms_per_call": None, "pairs": None, "status": "ok"}
            if method in QUADRATIC and method in last:
                n0, ms0 = last[method]
                predicted = ms0 * (count / n0) ** 2 / 1e3
                if predicted > args.budget:
                    row["status"] = f"skipped: predicted {predicted:.1f} s per call"
            if method == "all_pairs" and count * (count - 1) // 2 > args.max_pairs:
                row["status"] = f"skipped: {count * (count - 1) // 2:,} pairs exceed --max-pairs"
            if row["status"] == "ok":
                ms, pairs, pair_list = measure(method, pos, radius, inv_mass, args.margin, args.repeats, args.device)
                row.update(ms_per_call=round(ms, 3), pairs=pairs)
                results[method] = pair_list
                last[method] = (count, ms)
                print(f"N={count:>7d} {method:16s} {ms:10.3f} ms  {pairs:>10,d} pairs", flush=True)
            else:
                print(f"N={count:>7d} {method:16s} {row['status']}", flush=True)
            rows.append(row)
        reference = results.get("bounding_sphere", results.get("grid_sorted"))
        for method in ("bounding_sphere", "grid_sorted", "grid_hash"):
            if method in results and reference is not None and not np.array_equal(results[method], reference):
                raise SystemExit(f"N={count}: {method} pair list differs from the reference")
    name = f"broad_phase_{args.device.replace(':', '')}{args.tag}"
    csv_path, _ = write_rows(name, rows, meta)
    chart(rows, RESULTS / f"{name}.png", f"broad phase, rain of spheres ({meta['cpu'][:40]}, {meta['cores']} cores)")
    ok = {(r["method"], r["bodies"]): r["ms_per_call"] for r in rows if r["status"] == "ok"}
    for count in sorted(args.counts):
        a, b = ok.get(("grid_sorted", count)), ok.get(("grid_hash", count))
        if a and b:
            faster = "grid_sorted" if a < b else "grid_hash"
            print(f"N={count:>7d}: {faster} faster by {max(a, b) / min(a, b):.2f}x")
    print(f"wrote {csv_path} (+ .json, .png)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
