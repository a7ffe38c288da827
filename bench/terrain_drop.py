"""Throughput of N spheres / N boxes dropped on the Fourier terrain (terrain contact only).

    python bench/terrain_drop.py                       # N = 1k, 10k, 100k spheres and boxes on cpu
    python bench/terrain_drop.py --counts 1000 --shapes sphere --device cuda
    python bench/terrain_drop.py --counts 10000 --shapes box --checkpoints-per-edge 2 --tag _corners

Each case builds ``warp_sim.cases.terrain_drop`` (the scene the tests use; terrain contact
only unless ``--body-contact``), simulates
``--settle`` seconds so the bodies are on the ground and in contact, then times ``--steps``
steps (wall clock around sim.step with a device sync, kernel compile excluded).  A run whose
final state fails the invalid-state gate is recorded as failed, never as fast.
Writes bench/results/terrain_drop_<device>.{csv,json,png}.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import RESULTS, machine_info, state_gate, write_rows  # noqa: E402
from warp_sim import cases  # noqa: E402


def measure(shape: str, count: int, dt: float, substeps: int, settle: float, steps: int, device: str,
            body_contact: bool = False, per_edge: int | None = None) -> dict:
    sim = cases.terrain_drop(count, shape, dt=dt, substeps=substeps, device=device, body_contact=body_contact,
                             checkpoints_per_edge=per_edge)
    sim.step(1)  # compile
    settle_steps = int(round(settle / dt))
    for _ in range(settle_steps):
        sim.step(check=False)
    wp.synchronize_device(device)
    start = time.perf_counter()
    sim.step(steps, check=False)
    wp.synchronize_device(device)
    wall = time.perf_counter() - start
    sim.check_finite()
    failure = state_gate(sim)
    return {
        "shape": shape,
        "bodies": count,
        "body_contact": body_contact,
        "checkpoints_per_edge": sim.model.host["checkpoints_per_edge"],
        "dt": dt,
        "substeps": substeps,
        "steps": steps,
        "wall_s": round(wall, 4),
        "steps_per_s": round(steps / wall, 2),
        "body_steps_per_s": round(count * steps / wall),
        "contacts": sim.contact_count(),
        "max_penetration_m": round(sim.max_penetration(), 6),
        "status": failure or "ok",
    }


def chart(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for shape in sorted({r["shape"] for r in rows}):
        pts = [(r["bodies"], r["body_steps_per_s"]) for r in rows if r["shape"] == shape and r["status"] == "ok"]
        if pts:
            ax.loglog(*zip(*pts), marker="o", label=shape)
    ax.set_xlabel("bodies")
    ax.set_ylabel("body-steps / s")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--counts", type=int, nargs="+", default=[1000, 10000, 100000])
    p.add_argument("--shapes", nargs="+", default=["sphere", "box"], choices=["sphere", "box", "mix"])
    p.add_argument("--dt", type=float, default=1.0 / 240.0)
    p.add_argument("--substeps", type=int, default=1)
    p.add_argument("--settle", type=float, default=1.5, help="simulated seconds before timing")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--device", default="cpu")
    p.add_argument("--body-contact", action="store_true", help="also collide bodies with each other")
    p.add_argument("--checkpoints-per-edge", type=int, default=None, metavar="N",
                   help="box terrain points per edge (the builder's default: 3 on the Fourier terrain)")
    p.add_argument("--tag", default="", help="suffix for the result file names")
    args = p.parse_args(argv)
    wp.config.quiet = True
    wp.init()
    meta = machine_info(args.device)
    rows = []
    from tqdm import tqdm

    cases_list = [(s, n) for n in args.counts for s in args.shapes]
    for shape, count in tqdm(cases_list, desc="terrain_drop", unit="case"):
        row = measure(shape, count, args.dt, args.substeps, args.settle, args.steps, args.device, args.body_contact,
                      args.checkpoints_per_edge)
        rows.append(row)
        tqdm.write(f"{shape:6s} N={count:>7d}: {row['steps_per_s']:>9.1f} steps/s "
                   f"{row['body_steps_per_s']:>12,d} body-steps/s  [{row['status']}]")
    name = f"terrain_drop_{args.device.replace(':', '')}{args.tag}"
    csv_path, _ = write_rows(name, rows, meta)
    chart(rows, RESULTS / f"{name}.png", f"terrain contact, dt={args.dt:.4g} s x{args.substeps} ({meta['cpu'][:40]})")
    print(f"wrote {csv_path} (+ .json, .png)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
