"""Speed against depth in the layered rains of thin boxes (issue 12, item 11).

The two rains of the physics audit (``bench/audit_stacks.py``: ``examples/scenes/mixed_rain.toml``
and 360 plates of 0.6 x 0.2 x 0.6 m in 10 layers), each run 5 s under the settings that trade
speed for depth: the turned-pair refresh on (default) or off, 4 or 7 substeps, contacts once per
step or every substep.  For each: simulated steps per wall second (stepping only; the depth
probes are not timed) and the deepest body-body penetration, probed every 0.1 s as the audit
does.  At the defaults the rains run the substeps their landings need (column_sag.py: 12 for the
mixed rain, 11 for the plates); "4 substeps (auto off)" is the faster variant, and "7 substeps
(auto off)" what the plan ran before its landing constant was calibrated over 15 seeds.  Writes
``thin_rain.csv``/``.json`` and ``thin_rain.png`` (depth against steps/s, the 1 cm goal drawn).

    python bench/thin_rain.py                      # both rains, every variant (a few minutes on 2 cores)
    python bench/thin_rain.py --seeds 1 2 3 4 5    # each on five layouts (the scenes' [sim] seed)
    python bench/thin_rain.py --quick              # small rains, 1 s, two variants (a smoke run)

The deepest pair of a rain is one rare blow, so it scatters from layout to layout (by 2x between
seeds, warp_sim/column_sag.py): one layout per setting can pass a setting that fails on others.
With ``--seeds`` every setting runs on each layout; the chart draws every layout's dot and names
the setting at its worst one, and the table in the README gives the worst.
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import common  # noqa: E402
from bench.audit_cases import pair_depth  # noqa: E402
from bench.audit_stacks import thin_box_rains  # noqa: E402

VARIANTS = {
    "defaults": {},
    "4 substeps (auto off)": {"auto_substeps": False},
    "turn_refresh 0": {"turn_refresh": 0.0},
    "7 substeps (auto off)": {"substeps": 7, "auto_substeps": False},
    "contacts every substep": {"contact_update": "substep"},
}
GOAL = 0.01  # [m] the body-body depth goal


def scenes(quick: bool) -> dict:
    mixed, plates = thin_box_rains()
    if quick:
        mixed["layout"][0]["count"] = [3, 4, 3]
        plates["layout"][0]["count"] = [2, 4, 2]
    return {"mixed_rain.toml": mixed, "plates": plates}


def build(scene: dict, changes: dict):
    """The Simulator of ``scene`` with ``changes`` to its [sim] table (a seed: another layout)."""
    from warp_sim.scene import parse_scene

    scene = copy.deepcopy(scene)
    scene["sim"].update(changes)
    return parse_scene(scene, "<thin_rain>").build("cpu")


def run_one(scene: dict, changes: dict, seconds: float, probe_every: int = 6) -> dict:
    sim = build(scene, changes)
    sim.step(1)  # compile and first pass outside the clock
    deepest, wall = 0.0, 0.0
    steps = int(round(seconds / sim.config.dt)) // probe_every * probe_every
    for _ in range(steps // probe_every):
        start = time.perf_counter()
        sim.step(probe_every)
        wall += time.perf_counter() - start
        deepest = max(deepest, pair_depth(sim))
    return {"steps_per_s": steps / wall, "deepest_m": deepest, "substeps": sim.substeps,
            "bodies": sim.model.body_count, "gate": common.state_gate(sim, depth_slop=1.0)}


def chart(rows: list[dict], path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=False)
    palette = plt.get_cmap("tab10").colors
    names = list(dict.fromkeys(r["variant"] for r in rows))
    for ax, rain in zip(axes, sorted({r["rain"] for r in rows})):
        for k, name in enumerate(names):
            runs = [r for r in rows if r["rain"] == rain and r["variant"] == name]
            if not runs:
                continue
            ax.scatter([r["steps_per_s"] for r in runs], [1000 * r["deepest_m"] for r in runs], s=28,
                       color=palette[k % len(palette)])
            worst = max(runs, key=lambda r: r["deepest_m"])  # one dot per layout; named at its worst
            ax.annotate(name, (worst["steps_per_s"], 1000 * worst["deepest_m"]), fontsize=8,
                        xytext=(4, 3), textcoords="offset points")
        ax.axhline(1000 * GOAL, color="#c0392b", lw=1, ls="--", label="1 cm goal")
        ax.set_title(f"{rain} ({rows[0]['dt_label']})")
        ax.set_xlabel("steps / s (wall, stepping only)")
        ax.set_ylabel("deepest body-body penetration [mm]")
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="small rains, 1 s, two variants (a smoke run)")
    p.add_argument("--seconds", type=float, default=None, help="simulated seconds per run (default 5, quick 1)")
    p.add_argument("--seeds", type=int, nargs="+", default=None,
                   help="layouts to run each setting on (the scenes' [sim] seed); default: the scenes' own")
    p.add_argument("--out-dir", default=None)
    args = p.parse_args(argv)
    if args.seconds is not None and args.seconds <= 0:
        p.error(f"--seconds must be > 0, got {args.seconds}")
    if args.seeds is not None and any(s < 0 for s in args.seeds):
        p.error(f"--seeds must be integers >= 0, got {args.seeds}")
    out_dir = common.output_dir(args.out_dir, args.quick, "thin_rain")
    seconds = args.seconds or (1.0 if args.quick else 5.0)
    variants = {k: VARIANTS[k] for k in ("defaults", "4 substeps (auto off)")} if args.quick else VARIANTS
    from tqdm import tqdm

    import warp as wp

    wp.config.quiet = True
    rows = []
    jobs = [(rain, scene, name, changes, seed) for rain, scene in scenes(args.quick).items()
            for name, changes in variants.items() for seed in (args.seeds or [scene["sim"].get("seed", 0)])]
    for rain, scene, name, changes, seed in tqdm(jobs, desc="thin_rain", unit="run"):
        result = run_one(scene, {**changes, "seed": seed}, seconds)
        rows.append({"rain": rain, "variant": name, "seed": seed, "seconds": seconds, "dt_label": "dt 1/60 s",
                     **result})
        tqdm.write(f"{rain:16s} {name:26s} seed {seed:3d} {result['steps_per_s']:7.2f} steps/s  deepest "
                   f"{1000 * result['deepest_m']:6.1f} mm  ({result['substeps']} substeps)")
        common.write_rows("thin_rain", rows, common.machine_info("cpu"), out_dir)
        chart(rows, out_dir / "thin_rain.png")
    print(f"wrote {out_dir / 'thin_rain.csv'}, .json and .png")


if __name__ == "__main__":
    main()
