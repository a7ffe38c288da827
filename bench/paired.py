"""Two or more settings of one scene, stepped in turn in one process: a speed difference a noisy host
cannot hide.

    python bench/paired.py --variants defaults "every face point"                 # 10k mixed rain
    python bench/paired.py --scene box --variants defaults "every face point"     # boxes on the terrain alone
    python bench/paired.py --quick --variants defaults "every face point"          # smoke size

``bench/versions.py`` times each setting in a fresh process, one after the other; on the shared
2-core hosts this project is measured on, a process's speed swings by up to 2x over minutes as
other tenants come and go, and three runs each cannot tell 5 % apart.  Here every variant's
simulator is built and settled first (the scenes of ``versions.py``: ``--scene rain`` is
``bench/rain.py``'s mixed rain with body contact, dt 1/60 s with 4 substeps, sleeping off;
``box`` and ``sphere`` that shape on the terrain alone at dt 1/240 s, 1 substep), then ``--rounds``
rounds step each of them ``--steps`` steps in turn, the order reversed every other round, timing
each block by process CPU time.  A round's ratio against the first variant compares blocks run
seconds apart, and the table gives the median ratio with its spread.  Accuracy is read from the
same runs: the deepest penetration while the scene settles (probed every 0.1 s) and at the end,
and the terrain and pair contact rows the solver sweeps.

Writes ``bench/results/paired_<scene><tag>.{csv,json,png}`` (or ``--out-dir``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import machine_info, output_dir, write_rows  # noqa: E402
from bench.versions import VARIANTS  # noqa: E402
from warp_sim import cases  # noqa: E402


def build(scene: str, count: int, config: dict):
    if scene == "rain":
        return cases.terrain_drop(count, "mix", body_contact=True, spacing=0.9, sleep=False, rolling_resistance=0.2,
                                  **config)
    return cases.terrain_drop(count, scene, dt=1.0 / 240.0, substeps=1, sleep=False, **config)


def settle(sim, seconds: float) -> float:
    """Step ``seconds`` of simulated time; the deepest penetration probed every 0.1 s."""
    dt = sim.config.dt
    block = max(1, int(round(0.1 / dt)))
    peak = 0.0
    for _ in range(max(1, int(round(seconds / (block * dt))))):
        sim.step(block, check=False)
        peak = max(peak, sim.max_penetration())
    return peak


def measure(scene: str, count: int, variants: list[str], settle_s: float, rounds: int, steps: int) -> list[dict]:
    sims, rows = {}, {}
    for name in variants:
        sim = build(scene, count, VARIANTS[name])
        peak = settle(sim, settle_s)
        sims[name] = sim
        rows[name] = {"scene": scene, "bodies": count, "variant": name, "settle_s": settle_s, "peak_penetration_m":
                      round(peak, 6)}
        print(f"  {name:<34} settled, peak depth {1000 * peak:.2f} mm", flush=True)
    cpu = {name: [] for name in variants}
    for r in range(rounds):
        order = variants if r % 2 == 0 else variants[::-1]
        for name in order:
            start = time.process_time()
            sims[name].step(steps, check=False)
            cpu[name].append((time.process_time() - start) / steps)
        print(f"  round {r + 1}/{rounds}: " + "  ".join(f"{n} {1000 * cpu[n][-1]:.1f}" for n in variants)
              + " ms CPU a step", flush=True)
    base = np.asarray(cpu[variants[0]])
    out = []
    for name in variants:
        sim, times = sims[name], np.asarray(cpu[name])
        ratio = times / base
        terrain_rows = int(sim.contacts.terrain_contact_active.numpy().sum())
        out.append({**rows[name], "rounds": rounds, "steps_per_round": steps,
                    "cpu_ms_per_step_median": round(1000 * float(np.median(times)), 2),
                    "cpu_ms_per_step_min": round(1000 * float(times.min()), 2),
                    "ratio_to_first_median": round(float(np.median(ratio)), 4),
                    "ratio_to_first_q25": round(float(np.percentile(ratio, 25)), 4),
                    "ratio_to_first_q75": round(float(np.percentile(ratio, 75)), 4),
                    "terrain_rows": terrain_rows, "contacts": sim.contact_count(),
                    "max_penetration_m": round(sim.max_penetration(), 6)})
    return out


def chart(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for k, r in enumerate(rows):
        x = r["ratio_to_first_median"]
        err = [[x - r["ratio_to_first_q25"]], [r["ratio_to_first_q75"] - x]]
        y = 1000 * max(r["peak_penetration_m"], 1e-6)
        ax.errorbar([x], [y], xerr=err, fmt="o", color=plt.get_cmap("tab10").colors[k % 10], capsize=3,
                    label=f"{r['variant']} ({r['terrain_rows']} terrain rows)")
    ax.axvline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_xlabel(f"CPU time a step, relative to {rows[0]['variant']} (median of paired rounds, quartiles)")
    ax.set_ylabel("peak penetration while settling [mm]")
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default="rain", choices=["rain", "box", "sphere"])
    p.add_argument("--variants", nargs="+", default=["defaults", "every face point"], choices=list(VARIANTS))
    p.add_argument("--count", type=int, default=10000)
    p.add_argument("--settle", type=float, default=1.5, help="simulated seconds before the timed rounds")
    p.add_argument("--rounds", type=int, default=12)
    p.add_argument("--steps", type=int, default=None, help="steps a block (default: 4 for the rain, 20 alone)")
    p.add_argument("--tag", default="")
    p.add_argument("--quick", action="store_true", help="smoke size: 300 bodies, 0.3 s, 2 rounds")
    p.add_argument("--out-dir", type=Path, default=None)
    args = p.parse_args(argv)
    if len(set(args.variants)) != len(args.variants):
        p.error(f"--variants: each at most once, got {args.variants}")
    for name, value in (("--count", args.count), ("--rounds", args.rounds), ("--steps", args.steps)):
        if value is not None and value < 1:
            p.error(f"{name} must be at least 1, got {value}")
    if args.settle <= 0:
        p.error(f"--settle must be positive, got {args.settle}")
    folder = output_dir(args.out_dir, args.quick, "paired")
    if args.quick:
        args.count, args.settle, args.rounds = 300, 0.3, 2
    steps = args.steps or (4 if args.scene == "rain" else 20)
    rows = measure(args.scene, args.count, args.variants, args.settle, args.rounds, steps)
    name = f"paired_{args.scene}{args.tag}"
    meta = {**machine_info("cpu"), "command": "python bench/paired.py " + " ".join(argv or sys.argv[1:])}
    csv_path, _ = write_rows(name, rows, meta, folder)
    chart(rows, folder / f"{name}.png", f"{args.scene}, {args.count} bodies: paired rounds in one process")
    for r in rows:
        print(f"{r['variant']:<34} {r['cpu_ms_per_step_median']:8.1f} ms CPU a step  x{r['ratio_to_first_median']:.3f} "
              f"[{r['ratio_to_first_q25']:.3f}, {r['ratio_to_first_q75']:.3f}]  peak {1000 * r['peak_penetration_m']:.2f} mm"
              f"  terrain rows {r['terrain_rows']}")
    print(f"wrote {csv_path} (+ .json, .png)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
