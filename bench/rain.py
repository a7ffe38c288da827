"""Rain of N mixed spheres and boxes on the Fourier terrain, with body-body contact, per broad phase.

    python bench/rain.py                                   # N = 1k, 10k, 100k; every broad phase
    python bench/rain.py --counts 10000 --broad-phases grid --sleep
    python bench/rain.py --contact-updates step                 # the default mode only
    python bench/rain.py --counts 1000 10000 --broad-phases grid --contact-updates step \
        --impacts auto always --tag _impacts                    # the impact stage on this inelastic rain
    python bench/rain.py --counts 10000 --broad-phases grid --contact-updates step \
        --checkpoints-per-edge 3 2 --tag _checkpoints           # the boxes' terrain points: 26 or the 8 corners

The scene is ``warp_sim.cases.terrain_drop(N, "mix", body_contact=True)`` at dt = 1/60 with 4
substeps (Box2D's benchmark rate), with contacts found once per step (the default) and every
substep; bodies are simulated ``--settle`` seconds so they are piled and in contact (the deepest
penetration meanwhile is the row's accuracy figure), then ``--steps`` steps are timed.  Sleeping is off unless ``--sleep`` (a
benchmark of the solver, not of how soon it may stop).  The O(N^2) broad phases are skipped
where their pair buffer (all_pairs: N^2/2 pairs) or their per-call time (bounding_sphere) makes
a run unusable; the row says so.  A run that fails the invalid-state gate is marked failed.
Writes bench/results/rain_<device>.{csv,json,png}.
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

# Beyond these the method is not usable: all_pairs needs N(N-1)/2 pair slots (10k bodies: 50M
# pairs, 400 MB of pair indices alone) and bounding_sphere's O(N^2) test costs ~0.1 s per call
# at 10k bodies (bench/broad_phase.py), i.e. seconds per step with 4 substeps.
LIMITS = {"all_pairs": 3000, "bounding_sphere": 10000}


def measure(count: int, broad_phase: str, contact_update: str, settle: float, steps: int, device: str,
            sleep: bool, pair_schedule: str = "auto", impacts: str = "auto", per_edge: int | None = None) -> dict:
    row = {"bodies": count, "broad_phase": broad_phase, "contact_update": contact_update,
           "pair_schedule": pair_schedule, "impacts": impacts, "dt": 1 / 60, "substeps": 4, "sleep": sleep}
    if per_edge is not None:
        row["checkpoints_per_edge"] = per_edge
    if count > LIMITS.get(broad_phase, count):
        return {**row, "steps": 0, "wall_s": "", "steps_per_s": "", "body_steps_per_s": "", "contacts": "",
                "awake": "", "peak_penetration_m": "", "max_penetration_m": "",
                "status": f"skipped: O(N^2) beyond {LIMITS[broad_phase]}"}
    capacity = count * (count - 1) // 2 + 64 if broad_phase == "all_pairs" else 0
    sim = cases.terrain_drop(count, "mix", body_contact=True, broad_phase=broad_phase, device=device,
                             spacing=0.9, sleep=sleep, contact_max=capacity, rolling_resistance=0.2,
                             contact_update=contact_update, pair_schedule=pair_schedule, impacts=impacts,
                             checkpoints_per_edge=per_edge)
    # the schedule "auto" resolved to: slabs on the CPU, colours on CUDA (solvers/domains.py)
    row["pair_schedule"] = "domains" if sim.pairs.domain_count else "colors"
    sim.step(1)
    # the deepest penetration while the rain lands and piles (probed every 0.1 s): the accuracy
    # side of the speed / accuracy trade between the contact_update modes
    peak = 0.0
    for _ in range(int(round(settle * 10))):
        sim.step(6, check=False)
        peak = max(peak, sim.max_penetration())
    wp.synchronize_device(device)
    start = time.perf_counter()
    sim.step(steps, check=False)
    wp.synchronize_device(device)
    wall = time.perf_counter() - start
    sim.check_finite()
    failure = state_gate(sim)
    return {**row, "steps": steps, "wall_s": round(wall, 4), "steps_per_s": round(steps / wall, 2),
            "body_steps_per_s": round(count * steps / wall), "contacts": sim.contact_count(),
            "awake": sim.awake_count(), "peak_penetration_m": round(peak, 6),
            "max_penetration_m": round(sim.max_penetration(), 6),
            "status": failure or "ok"}


def chart(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    def key(r):  # the checkpoints, where a run varies them, count as impacts do: a series of their own
        edge = f", {r['checkpoints_per_edge']} per edge" if "checkpoints_per_edge" in r else ""
        return r["broad_phase"], r["contact_update"], r["pair_schedule"], r.get("impacts", "auto") + edge

    series = dict.fromkeys(key(r) for r in rows)
    schedules = {r["pair_schedule"] for r in rows}
    # one colour per (broad phase, contact update); the colour schedule dashed
    palette = plt.get_cmap("tab10").colors
    stages = {k[3] for k in series}
    hues = {key: palette[k % len(palette)] for k, key in enumerate(dict.fromkeys(k[:2] + k[3:] for k in series))}
    for bp, update, schedule, impacts in series:
        ok = [r for r in rows if key(r) == (bp, update, schedule, impacts) and r["status"] == "ok"]
        if ok:
            label = (f"{bp}, contacts per {update}" + (f", {schedule}" if len(schedules) > 1 else "")
                     + (f", impacts {impacts}" if len(stages) > 1 else ""))
            style = {"color": hues[(bp, update, impacts)], "ls": "--" if schedule == "colors" else "-", "marker": "o"}
            ax.loglog([r["bodies"] for r in ok], [r["steps_per_s"] for r in ok], label=label, **style)
            ax2.loglog([r["steps_per_s"] for r in ok], [1000 * max(r["peak_penetration_m"], 1e-6) for r in ok],
                       label=label, **style)
            for r in ok:
                ax2.annotate(f"{r['bodies'] // 1000}k", (r["steps_per_s"], 1000 * max(r["peak_penetration_m"], 1e-6)),
                             fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.axhline(30, color="grey", ls="--", lw=0.8, label="30 steps/s")
    ax.set_xlabel("bodies (mixed spheres and boxes)")
    ax.set_ylabel("steps / s (dt 1/60, 4 substeps)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax2.set_xlabel("steps / s")
    ax2.set_ylabel("peak penetration while landing [mm]")
    ax2.set_title("speed against accuracy (labels: bodies)", fontsize=9)
    ax2.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--counts", type=int, nargs="+", default=[1000, 10000, 100000])
    p.add_argument("--broad-phases", nargs="+", default=["grid", "grid_hash", "bounding_sphere", "all_pairs"])
    p.add_argument("--settle", type=float, default=1.5, help="simulated seconds before timing")
    p.add_argument("--steps", type=int, default=30)
    p.add_argument("--contact-updates", nargs="+", default=["step", "substep"], choices=["step", "substep"],
                   help="find contacts once per step (default mode) and/or every substep")
    p.add_argument("--pair-schedules", nargs="+", default=["auto"], choices=["auto", "domains", "colors"],
                   help="how the body-body sweeps run in parallel (SimConfig.pair_schedule)")
    p.add_argument("--impacts", nargs="+", default=["auto"], choices=["auto", "always"],
                   help="SimConfig.impacts: the impact stage only with restitution (this rain has none), or always")
    p.add_argument("--checkpoints-per-edge", type=int, nargs="+", default=[None], metavar="N",
                   help="box terrain points per edge (the builder's default: 3 on the Fourier terrain)")
    p.add_argument("--sleep", action="store_true")
    p.add_argument("--device", default="cpu")
    p.add_argument("--tag", default="")
    p.add_argument("--out-dir", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    meta = machine_info(args.device)
    from tqdm import tqdm

    rows = []
    cases_ = [(n, b, u, s, i, e) for n in args.counts for b in args.broad_phases for u in args.contact_updates
              for s in args.pair_schedules for i in args.impacts for e in args.checkpoints_per_edge]
    for count, bp, update, schedule, impacts, per_edge in tqdm(cases_, desc="rain", unit="case"):
        row = measure(count, bp, update, args.settle, args.steps, args.device, args.sleep, schedule, impacts, per_edge)
        rows.append(row)
        edge = "" if per_edge is None else f" {per_edge} per edge"
        tqdm.write(f"N={count:>7d} {bp:16s} per {update:8s} {row['pair_schedule']:8s} impacts {impacts:6s}{edge} "
                   f"{row['steps_per_s']!s:>9} steps/s  "
                   f"peak depth {row['peak_penetration_m']!s:>9} m  [{row['status']}]")
    name = f"rain_{args.device.replace(':', '')}{args.tag}"
    csv_path, _ = write_rows(name, rows, meta, args.out_dir)
    chart(rows, args.out_dir / f"{name}.png", f"rain on terrain with body contact ({meta['cpu'][:32]})")
    print(f"wrote {csv_path} (+ .json, .png)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
