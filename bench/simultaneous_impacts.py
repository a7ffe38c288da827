"""Simultaneous impacts taken in sequence or as one Poisson impact: accuracy against cost.

``simultaneous_impacts = "sequential"`` (the default, solvers/impact.py) takes manifolds struck at
once one after another in pair order; ``"joint"`` (solvers/impact_joint.py) compresses the ones
closing at the impact stage's start together, then bounces them.  For each choice and pair
schedule this measures, on cases.seam_drop (a ball dropped onto the seam of two touching balls,
zero gravity, e = 1, mu = 0), the striker's sideways speed (0 by symmetry) and the kinetic energy
error, and the milliseconds a step of the shipped mixed rain (examples/scenes/mixed_rain.toml,
1000 bodies, e = 0.1) takes from 1 s to 2 s, after it has landed (three runs of each, alternating;
the median).  Writes
``simultaneous_impacts.csv``/``.json`` and ``simultaneous_impacts.png`` (cost against asymmetry).

    python bench/simultaneous_impacts.py           # about 3 minutes on 2 cores
    python bench/simultaneous_impacts.py --quick   # the seam only (a smoke run)
    python bench/simultaneous_impacts.py --depth-seeds 16 25   # about 15 minutes

``--depth-seeds FIRST LAST`` instead runs the mixed rain and the audit's plate rain for 5 s under
both models with each seed, probing the deepest body-body penetration after every step (as
bench/audit.py's check, whose goal is 1 cm), and writes ``simultaneous_impacts_depth.csv``/``.json``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import common  # noqa: E402

MODELS = ("sequential", "joint")
REPEATS = 3
SCHEDULES = ("domains", "colors")


def seam(model: str, schedule: str) -> tuple[float, float]:
    """(striker's sideways speed [m/s], relative kinetic energy error) after the seam drop, e = 1."""
    import numpy as np

    from warp_sim import cases

    sim = cases.seam_drop(1.0, True, 1.0, pair_schedule=schedule, simultaneous_impacts=model)
    sim.step(10)
    v = sim.state.body_vel.numpy().astype(np.float64)
    energy = 0.5 * float((v**2).sum())
    return abs(float(v[2, 0])), energy / 4.5 - 1.0


def rain_step_ms(model: str, schedule: str) -> float:
    import warp as wp

    from warp_sim.scene import load_scene

    scene = load_scene(ROOT / "examples" / "scenes" / "mixed_rain.toml")
    scene.config = replace(scene.config, simultaneous_impacts=model, pair_schedule=schedule)
    sim = scene.build("cpu")
    sim.step(60)
    start = time.perf_counter()
    sim.step(60)
    wp.synchronize()
    return 1e3 * (time.perf_counter() - start) / 60


def depth_seeds(first: int, last: int, out_dir: Path) -> int:
    from bench.audit_stacks import rain_depth, thin_box_rains

    mixed, plates = thin_box_rains()
    rows = []
    for seed in range(first, last + 1):
        for rain, base in (("mixed_rain.toml", mixed), ("plates 6 x 10 x 6", plates)):
            for model in MODELS:
                scene = {**base, "sim": {**base["sim"], "seed": seed, "simultaneous_impacts": model}}
                deepest, _ = rain_depth(scene, 5.0, 1)
                rows.append({"rain": rain, "seed": seed, "simultaneous_impacts": model,
                             "deepest_body_body_mm": round(1e3 * deepest, 2)})
                print(f"{rain:18s} seed {seed:3d} {model:10s} deepest body-body {1e3 * deepest:.2f} mm", flush=True)
    for rain in ("mixed_rain.toml", "plates 6 x 10 x 6"):
        for model in MODELS:
            depths = [r["deepest_body_body_mm"] for r in rows if r["simultaneous_impacts"] == model and r["rain"] == rain]
            print(f"{rain:18s} {model:10s} mean {statistics.mean(depths):.2f} mm, max {max(depths):.2f} mm over "
                  f"{len(depths)} seeds")
    common.write_rows("simultaneous_impacts_depth", rows, common.machine_info("cpu"), out_dir)
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="the seam only (a smoke run)")
    p.add_argument("--out-dir", type=Path, default=None)
    p.add_argument("--depth-seeds", type=int, nargs=2, metavar=("FIRST", "LAST"), default=None,
                   help="the mixed rain's deepest body-body penetration under both models, seeds FIRST..LAST")
    args = p.parse_args(argv)
    import warp as wp

    wp.config.quiet = True
    out_dir = common.output_dir(args.out_dir, args.quick, "simultaneous_impacts")
    if args.depth_seeds is not None:
        return depth_seeds(*args.depth_seeds, out_dir)
    # the rain timed on the CPU's slab schedule, the two models alternating, REPEATS times each (this
    # machine's speed drifts by 5 to 20 %); the median is reported
    timings = {model: [] for model in MODELS}
    for _ in range(0 if args.quick else REPEATS):
        for model in MODELS:
            timings[model].append(rain_step_ms(model, "domains"))
            print(f"mixed rain, {model}: {timings[model][-1]:.1f} ms a step", flush=True)
    rows = []
    for schedule in SCHEDULES:
        for model in MODELS:
            sideways, energy = seam(model, schedule)
            runs = timings[model] if schedule == "domains" else []
            ms = statistics.median(runs) if runs else float("nan")
            rows.append({"simultaneous_impacts": model, "pair_schedule": schedule,
                         "seam_striker_sideways_m_s": round(sideways, 5), "seam_energy_error": f"{energy:.2e}",
                         "mixed_rain_ms_per_step": round(ms, 2),
                         "mixed_rain_runs_ms": " ".join(f"{t:.1f}" for t in runs)})
            print(f"{model:10s} {schedule:8s} striker sideways {sideways:.4f} m/s, energy {energy:+.2e}, "
                  f"mixed rain {ms:.1f} ms a step (median)", flush=True)
    common.write_rows("simultaneous_impacts", rows, common.machine_info("cpu"), out_dir)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 3.8))
    for row in rows:
        if row["pair_schedule"] == "domains" and row["mixed_rain_ms_per_step"] == row["mixed_rain_ms_per_step"]:
            ax.scatter(row["mixed_rain_ms_per_step"], max(row["seam_striker_sideways_m_s"], 1e-6), s=60)
            ax.annotate(row["simultaneous_impacts"], (row["mixed_rain_ms_per_step"],
                                                      max(row["seam_striker_sideways_m_s"], 1e-6)),
                        textcoords="offset points", xytext=(6, 4), fontsize=8)
    ax.set_yscale("log")
    ax.set_xlabel("mixed rain (1000 bodies, e 0.1): ms a step, slab schedule")
    ax.set_ylabel("seam drop: striker's sideways speed [m/s]", fontsize=8)
    ax.set_title("Simultaneous impacts: cost against symmetry\n(a speed under 1e-6, 0 exactly, drawn at 1e-6)",
                 fontsize=9)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / "simultaneous_impacts.png", dpi=120)
    print(f"wrote {out_dir / 'simultaneous_impacts.csv'} (.json, .png)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
