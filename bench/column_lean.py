"""Leaning columns set down cold: which stand, against the margin the substep plan asks for.

A staircase of boxes, each carrying the centre of mass of all above it ``margin`` inside its own
top face's edge (the book-stacking overhang), is set down touching and at rest; statics says it
stands at any positive margin.  Soft contacts tip it unless the margin exceeds about sqrt(e S)
(warp_sim/column_lean.py: e the load's offset, S the static shift the springs allow).  Each run
here fixes the substeps (``auto_substeps`` off), runs 4 s and records the largest sideways move of
any box; it fell if that passed FELL = 0.2 m.  The
calibration family is unit cubes, 3 to 8 high, 4 to 32 substeps, margins 5 to 160 mm; the
check family, not used to set the constant, varies masses (0.5 to 2 kg), shapes (plates and
bars), turns the column about the vertical, and stands it on a static table's edge.  Writes
``column_lean.csv``/``.json`` (one row a run: the margin over sqrt(e S) of the plan's estimate,
and what happened) and ``column_lean.png`` (that ratio per run, stood or fell, with the plan's
LEAN_SAFETY drawn).

    python bench/column_lean.py            # about 10 min on 2 cores
    python bench/column_lean.py --quick    # 3 cubes at 4 and 8 substeps (a smoke run)
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import common  # noqa: E402

FELL = 0.2  # [m] a box that moved this far sideways has fallen (a standing one moved 65 mm at most)
SECONDS = 4.0


def staircase(count: int, margin: float, half=(0.5, 0.5, 0.5), masses=None, yaw_deg: float = 0.0,
              table: bool = False):
    """A ModelBuilder of ``count`` boxes, each carrying the centre of mass of those above it
    ``margin`` inside its top face's edge, leaning along the boxes' own x axis (turned ``yaw_deg``
    about the vertical); on the plane, or with the bottom box overhanging a static table's edge
    by the same rule (``table``)."""
    from warp_sim import ModelBuilder, PlaneTerrain
    from warp_sim.builder import Material

    masses = np.ones(count) if masses is None else np.asarray(masses, dtype=np.float64)
    hx, hy, _ = half
    xs = np.zeros(count)
    for i in range(count - 2, -1, -1):
        above = slice(i + 1, count)
        xs[i] = np.dot(masses[above], xs[above]) / masses[above].sum() - (hx - margin)
    yaw = math.radians(yaw_deg)
    axis = np.array([math.cos(yaw), 0.0, -math.sin(yaw)])
    quat = (0.0, math.sin(yaw / 2.0), 0.0, math.cos(yaw / 2.0))
    b = ModelBuilder(Material(restitution=0.0, friction=0.5))
    b.set_terrain(PlaneTerrain())
    base = 0.0
    if table:
        # the table's edge lies margin outside the centre of mass of the whole column
        com = float(np.dot(masses, xs) / masses.sum())
        edge = com + margin
        b.add_box((1.0, 0.5, 1.0), 1.0, position=tuple((edge - 1.0) * axis + np.array([0.0, 0.5, 0.0])),
                  orientation=quat, static=True)
        base = 1.0
    for i in range(count):
        b.add_box(half, float(masses[i]), position=tuple(xs[i] * axis + np.array([0.0, base + hy * (2 * i + 1), 0.0])),
                  orientation=quat)
    return b


def run(builder, substeps: int | None, seconds: float) -> tuple[float, object]:
    """(the largest sideways move of any box [m], the substep plan) over ``seconds`` at
    ``substeps`` (None: the defaults' plan)."""
    from warp_sim import SimConfig, Simulator

    config = SimConfig(sleep=False) if substeps is None else SimConfig(sleep=False, substeps=substeps,
                                                                       auto_substeps=False)
    sim = Simulator(builder.finalize("cpu"), config)
    return largest_move(sim, seconds), sim


def largest_move(sim, seconds: float, fell: float = FELL) -> float:
    """The largest sideways move of any dynamic box over ``seconds`` [m], probed every 0.1 s; it
    stops once one has moved ``fell``."""
    dynamic = sim.model.host["body_inv_mass"] > 0
    start = sim.state.body_pos.numpy()[dynamic].copy()
    worst = 0.0
    for _ in range(int(round(seconds * 10))):
        sim.step(int(round(0.1 / sim.config.dt)))
        moved = sim.state.body_pos.numpy()[dynamic] - start
        worst = max(worst, float(np.max(np.hypot(moved[:, 0], moved[:, 2]))))
        if worst > fell:
            break
    return worst


def estimate(builder, substeps: int) -> tuple[float, float]:
    """(the tightest checked margin, sqrt(e S) there) [m] of the plan at ``substeps``."""
    from warp_sim import SimConfig
    from warp_sim.column_lean import LEAN_SAFETY
    from warp_sim.column_sag import contact_omega, lean_need, scene_lean

    config = SimConfig(sleep=False, substeps=substeps, auto_substeps=False)
    model = builder.finalize("cpu")
    margin, need = lean_need(scene_lean(model, config), 9.81, contact_omega(config.dt / substeps, None))
    return margin, need / LEAN_SAFETY


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="3 cubes at 4 and 8 substeps (a smoke run)")
    p.add_argument("--out-dir", type=Path, default=None)
    args = p.parse_args(argv)
    import warp as wp

    wp.config.quiet = True
    from warp_sim.column_lean import LEAN_SAFETY

    out_dir = common.output_dir(args.out_dir, args.quick, "column_lean")
    seconds = 1.0 if args.quick else SECONDS
    runs = []
    counts, substep_list = ((3,), (4, 8)) if args.quick else ((3, 4, 6, 8), (4, 8, 16, 32))
    margins = (0.01, 0.02) if args.quick else (0.005, 0.01, 0.02, 0.04, 0.08, 0.16)
    for count in counts:
        for substeps in substep_list:
            for margin in margins:
                runs.append(("calibration", f"{count} unit cubes", dict(count=count, margin=margin), substeps))
    if not args.quick:
        rng = np.random.default_rng(7)
        for k, (label, kwargs) in enumerate([
                ("5 cubes, masses 0.5-2 kg", dict(count=5, masses=rng.uniform(0.5, 2.0, 5))),
                ("6 cubes, masses 0.5-2 kg", dict(count=6, masses=rng.uniform(0.5, 2.0, 6))),
                ("5 plates 1 x 0.2 x 0.6 m", dict(count=5, half=(0.5, 0.1, 0.3))),
                ("4 bars 0.4 x 0.8 x 0.4 m", dict(count=4, half=(0.2, 0.4, 0.2))),
                ("5 cubes turned 30 degrees", dict(count=5, yaw_deg=30.0)),
                ("4 cubes over a table's edge", dict(count=4, table=True))]):
            for substeps in (4, 16):
                for margin in (0.01, 0.02, 0.04, 0.08):
                    # margins in proportion to the boxes' half length (0.5 m for the cubes)
                    scale = kwargs.get("half", (0.5,))[0] / 0.5
                    runs.append(("check", label, dict(kwargs, margin=margin * scale), substeps))
    rows = []
    total = len(runs)
    for index, (family, label, kwargs, substeps) in enumerate(runs, 1):
        builder = staircase(**kwargs)
        margin, reach = estimate(builder, substeps)
        worst, _ = run(builder, substeps, seconds)
        stood = worst < FELL
        ratio = margin / reach if reach > 0.0 else math.inf
        rows.append({"family": family, "column": label, "margin_m": round(kwargs["margin"], 5),
                     "substeps": substeps, "sqrt_e_S_m": round(reach, 6), "margin_over_sqrt_e_S": round(ratio, 4),
                     "largest_sideways_move_m": round(worst, 5), "stood": bool(stood), "seconds": seconds})
        print(f"[{index:3d}/{total}] {label:28s} {substeps:2d} substeps, margin {kwargs['margin'] * 1000:5.1f} mm "
              f"= {ratio:5.2f} sqrt(e S): {'stood' if stood else 'FELL '} (moved {worst * 1000:6.1f} mm)", flush=True)
    # the defaults' plan on the check family, one margin each: does the column stand?
    if not args.quick:
        for label, kwargs in [("6 cubes, masses 0.5-2 kg", dict(count=6, masses=np.random.default_rng(8).uniform(0.5, 2.0, 6))),
                              ("5 plates 1 x 0.2 x 0.6 m", dict(count=5, half=(0.5, 0.1, 0.3))),
                              ("8 unit cubes", dict(count=8))]:
            builder = staircase(**kwargs, margin=0.02)
            worst, sim = run(builder, None, seconds)
            rows.append({"family": "defaults", "column": label, "margin_m": 0.02, "substeps": sim.substeps,
                         "sqrt_e_S_m": round(sim.substep_plan.lean_need / LEAN_SAFETY, 6),
                         "margin_over_sqrt_e_S": round(0.02 * LEAN_SAFETY / sim.substep_plan.lean_need, 4),
                         "largest_sideways_move_m": round(worst, 5), "stood": bool(worst < FELL), "seconds": seconds})
            print(f"defaults: {label}, margin 20 mm: {sim.substep_plan.describe()}; moved {worst * 1000:.1f} mm")
    common.write_rows("column_lean", rows, common.machine_info("cpu"), out_dir)
    fell = [r["margin_over_sqrt_e_S"] for r in rows if not r["stood"]]
    stood = [r["margin_over_sqrt_e_S"] for r in rows if r["stood"]]
    print(f"fell up to {max(fell, default=0):.2f} sqrt(e S), stood from {min(stood, default=0):.2f}; "
          f"the plan asks for {LEAN_SAFETY:g}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10.5, 4.6))
    labels = list(dict.fromkeys(r["column"] for r in rows))
    for y, label in enumerate(labels):
        for r in rows:
            if r["column"] == label:
                ax.scatter(min(r["margin_over_sqrt_e_S"], 50.0), y, marker="o" if r["stood"] else "x",
                           color="#2ca02c" if r["stood"] else "#d62728", s=36)
    ax.axvline(LEAN_SAFETY, color="k", ls="--", lw=1, label=f"the plan's LEAN_SAFETY = {LEAN_SAFETY:g}")
    ax.axvline(1.0, color="k", ls=":", lw=1, alpha=0.6, label="sqrt(e S)")
    ax.set_xscale("log")
    ax.set_yticks(range(len(labels)), labels, fontsize=7)
    ax.set_xlabel("margin / sqrt(e S) at the substeps run (o stood, x fell)")
    ax.set_title(f"Leaning columns set down cold, {seconds:g} s (o stood, x fell)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(out_dir / "column_lean.png", dpi=120)
    print(f"wrote {out_dir / 'column_lean.csv'} (.json, .png)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
