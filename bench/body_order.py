"""Speed of the 10k mixed rain in four body orders (warp_sim/body_order.py), timed back to back.

    python bench/body_order.py                       # 10k bodies, 3 repeats of every order
    python bench/body_order.py --count 20000 --repeats 5
    python bench/body_order.py --quick               # 400 bodies, a short settle: a smoke run

The scene is bench/rain.py's and bench/versions.py's (``cases.terrain_drop(N, "mix",
body_contact=True)``, spacing 0.9, rolling resistance 0.2, dt 1/60 with 4 substeps, grid broad
phase, contacts once per step, slab schedule on the CPU, sleeping off), stored in:

- ``scene``: the order terrain_drop adds the bodies in (row by row: already local);
- ``shape_morton``: sorted at build, ``[sim] body_order = "shape_morton"``;
- ``random``: the same bodies added in a random order (seeded), nothing sorted, as a scene
  assembled from an unordered source would be;
- ``random + shape_morton``: that random order, sorted at build.

Each run is a fresh process (no cache or allocator state carried over), the orders alternate
within each repeat so a slow spell of the shared machine hits every order, and each run settles
the rain ``--settle`` s (probing ``sim.max_penetration()`` every 6 steps: the accuracy figure,
which the order must not change beyond rounding) before timing ``--steps`` steps: wall time,
process CPU time (both cores' work) and the build's own time (``finalize``, with the sort).
Writes ``body_order.csv``/``.json``/``.png`` to bench/results (``--out-dir``; a ``--quick`` run to
a temporary folder).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import common  # noqa: E402

# order name -> (bodies added in a random order, the body_order the Model is built with)
ORDERS = {
    "scene": (False, "scene"),
    "shape_morton": (False, "shape_morton"),
    "random": (True, "scene"),
    "random + shape_morton": (True, "shape_morton"),
}
SHUFFLE_SEED = 1
RAIN = {"spacing": 0.9, "rolling_resistance": 0.2}
SETTINGS = {"body_contact": True, "broad_phase": "grid", "sleep": False, "contact_update": "step"}


def shuffled(builder, seed: int):
    """A new ModelBuilder with ``builder``'s bodies added in a random order (bulk add: the same
    bodies bit for bit, ModelBuilder.add_bodies)."""
    import numpy as np

    from warp_sim import ModelBuilder

    c = builder.columns()
    perm = np.random.default_rng(seed).permutation(len(c["shape"]))
    out = ModelBuilder(builder.material)
    out.set_terrain(builder.terrain)
    out.add_bodies(c["shape"][perm], c["size"][perm], mass=c["mass"][perm], position=c["position"][perm],
                   orientation=c["orientation"][perm], velocity=c["velocity"][perm],
                   angular_velocity=c["angular_velocity"][perm], restitution=c["restitution"][perm],
                   friction=c["friction"][perm], static=c["static"][perm])
    return out


def child(order: str, count: int, settle: float, steps: int, device: str) -> dict:
    """One timed run (in its own process): the JSON line the parent reads."""
    import warp as wp

    from warp_sim import SimConfig, Simulator, cases
    from warp_sim.quiet import init_warp

    init_warp()

    shuffle, mode = ORDERS[order]
    builder = cases.terrain_drop_builder(count, "mix", **RAIN)
    if shuffle:
        builder = shuffled(builder, SHUFFLE_SEED)
    schedule = "domains" if device == "cpu" else "colors"
    start = time.perf_counter()
    model = builder.finalize(device, body_order=mode)
    build_s = time.perf_counter() - start
    sim = Simulator(model, SimConfig(device=device, pair_schedule=schedule, **SETTINGS))
    sim.step(1)
    peak = 0.0
    for _ in range(int(round(settle * 10))):  # 6 steps of 1/60 s: a probe every 0.1 s
        sim.step(6, check=False)
        peak = max(peak, sim.max_penetration())
    wp.synchronize_device(device)
    cpu_start, start = time.process_time(), time.perf_counter()
    sim.step(steps, check=False)
    wp.synchronize_device(device)
    wall = time.perf_counter() - start
    cpu = time.process_time() - cpu_start
    sim.check_finite()
    return {"status": common.state_gate(sim) or "ok", "ms_per_step": 1000.0 * wall / steps,
            "cpu_ms_per_step": 1000.0 * cpu / steps, "steps_per_s": steps / wall, "build_s": build_s,
            "peak_penetration_m": peak, "substeps": sim.substeps, "pairs": int(sim.contacts.pair_count.numpy()[0])}


def run_once(order: str, count: int, settle: float, steps: int, device: str) -> dict:
    return common.run_child([sys.executable, __file__, "--child", order, "--count", str(count), "--settle", str(settle),
                             "--steps", str(steps), "--device", device])


def chart(rows: list[dict], path: Path, title: str):
    import statistics

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    palette = plt.get_cmap("tab10").colors
    for k, order in enumerate(ORDERS):
        ok = [r for r in rows if r["order"] == order and r["status"] == "ok"]
        if not ok:
            continue
        for field, marker, offset in (("ms_per_step", "o", -0.12), ("cpu_ms_per_step", "s", 0.12)):
            values = [r[field] for r in ok]
            ax.scatter([k + offset] * len(values), values, color=palette[k], marker=marker, s=24,
                       label=("wall ms" if field == "ms_per_step" else "CPU ms (all threads)") if k == 0 else None)
            ax.hlines(statistics.median(values), k + offset - 0.08, k + offset + 0.08, color=palette[k])
    ax.set_xticks(range(len(ORDERS)), list(ORDERS), fontsize=8)
    ax.set_ylabel("ms a step (each dot one run; bar: median)")
    ax.set_ylim(bottom=0)
    ax.set_title(title, fontsize=9)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def summary(rows: list[dict]) -> list[str]:
    import statistics

    lines = []
    for order in ORDERS:
        ok = [r for r in rows if r["order"] == order and r["status"] == "ok"]
        if ok:
            lines.append(f"{order:22s} wall {statistics.median(r['ms_per_step'] for r in ok):7.1f} ms  cpu "
                         f"{statistics.median(r['cpu_ms_per_step'] for r in ok):7.1f} ms a step  build "
                         f"{statistics.median(r['build_s'] for r in ok):.2f} s  peak depth "
                         f"{1000 * max(r['peak_penetration_m'] for r in ok):.1f} mm  ({len(ok)} runs)")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--count", type=int, default=None, help="bodies (default 10000, quick 400)")
    p.add_argument("--repeats", type=int, default=None, help="runs of every order (default 3, quick 1)")
    p.add_argument("--settle", type=float, default=None, help="simulated seconds before timing (default 1.5)")
    p.add_argument("--steps", type=int, default=None, help="timed steps (default 40, quick 5)")
    p.add_argument("--orders", nargs="+", default=list(ORDERS), choices=list(ORDERS))
    p.add_argument("--device", default="cpu")
    p.add_argument("--quick", action="store_true", help="a smoke run: small rain, short settle, one repeat")
    p.add_argument("--out-dir", default=None)
    p.add_argument("--child", choices=list(ORDERS), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    count = args.count or (400 if args.quick else 10000)
    repeats = args.repeats or (1 if args.quick else 3)
    settle = args.settle if args.settle is not None else (0.2 if args.quick else 1.5)
    steps = args.steps or (5 if args.quick else 40)
    if count < 2 or repeats < 1 or steps < 1 or settle < 0:
        p.error(f"--count must be >= 2, --repeats and --steps >= 1 and --settle >= 0, got {count}, {repeats}, "
                f"{steps}, {settle}")
    if args.child:
        print(json.dumps(child(args.child, count, settle, steps, args.device)))
        return 0
    out_dir = common.output_dir(args.out_dir, args.quick, "body_order")
    from warp_sim.quiet import init_warp

    init_warp()
    meta = {**common.machine_info(args.device), "count": count, "settle_s": settle, "steps": steps,
            "shuffle_seed": SHUFFLE_SEED}
    rows = []
    total = repeats * len(args.orders)
    for repeat in range(repeats):
        for order in args.orders:  # alternating: a slow spell of the machine hits every order
            result = run_once(order, count, settle, steps, args.device)
            rows.append({"order": order, "repeat": repeat, "bodies": count,
                         **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in result.items()}})
            r = rows[-1]
            print(f"[{len(rows)}/{total}] {order:22s} {r.get('ms_per_step', float('nan')):8.1f} ms a step  cpu "
                  f"{r.get('cpu_ms_per_step', float('nan')):8.1f} ms  build {r.get('build_s', float('nan')):.2f} s  "
                  f"peak {1000 * r.get('peak_penetration_m', float('nan')):.1f} mm  [{r['status']}]", flush=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    rows = [{k: r.get(k, "") for k in keys} for r in rows]  # failed runs lack the figures
    csv_path, _ = common.write_rows("body_order", rows, meta, out_dir)
    chart(rows, out_dir / "body_order.png",
          f"{count:,} mixed bodies raining, by body order ({meta['cpu'][:40]}, {meta['cores']} cores)")
    return common.finish_report(summary(rows), csv_path, rows)


if __name__ == "__main__":
    raise SystemExit(main())
