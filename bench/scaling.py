"""Body-count scaling: steps/s, body-steps/s, per-stage time and memory per body against N.

    python bench/scaling.py                         # full sweep on cpu (N = 1k ... 100k)
    python bench/scaling.py --quick                 # small sizes, a smoke run (to a temporary folder)
    python bench/scaling.py --counts 1000 10000 --shapes sphere --contact off --device cuda

Every case is ``warp_sim.cases.terrain_drop(N, shape)`` (the shared benchmark scene: N bodies
on a grid dropped on the Fourier terrain) in one of these configurations:

* terrain contact only (``contact = off``): dt = 1/240 s, 1 substep (the rate of the
  "10k spheres at >= 100 steps/s" goal), broad phase not used;
* body-body contact (``contact = on``), once per broad phase (grid, grid_hash,
  bounding_sphere): dt = 1/60 s with 4 substeps (Box2D's benchmark rate, the rate of the
  "10k mixed bodies at >= 30 steps/s" goal); bounding_sphere is O(N^2) and is skipped above
  ``--bounding-sphere-max`` bodies, where one call costs seconds (bench/broad_phase.py).

for spheres only, boxes only and a 50/50 mix.  Each case simulates ``--settle`` seconds so the
bodies are on the ground and in contact (compile step excluded), then times steps until about
``--budget`` seconds of wall clock have passed (at least ``--min-steps``, at most
``--max-steps``): slow cases such as 100k bodies in contact time only a few steps.  Further
steps (about half the budget, at least ``--profile-steps``) run with ``sim.profile = True``
for the per-stage split (terrain, pairs, solve, sleep; "other" is the rest of the step: Python
overhead, buffer swaps); they are not part of the throughput figure because profiling
synchronises after every stage.

Memory per body is the sum of the ``nbytes`` of every Warp array owned by the model, both
states, the contact buffers, the solver, the pair pipeline (broad phase included) and the
sleep buffers, divided by N (``wp.HashGrid``'s internal buffers are not arrays and are not
counted).  A case whose final state fails the invalid-state gate (bench.common.state_gate) is
recorded as failed and left out of the charts.

Writes ``<out-dir>/scaling[_<device>][<tag>].{csv,json}``, ``..._throughput.png`` (body-steps/s
against N, log-log, one line per configuration) and ``..._stages.png`` (stacked per-stage time
per step).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import machine_info, output_dir, state_gate  # noqa: E402
from warp_sim import cases  # noqa: E402

STAGES = ("terrain", "pairs", "solve", "sleep")
CONTACT_RATE = {False: (1.0 / 240.0, 1), True: (1.0 / 60.0, 4)}  # (dt, substeps)
FULL_COUNTS = [1000, 3000, 10000, 30000, 100000]
QUICK_COUNTS = [100, 400]


# Result files --------------------------------------------------------------------------------

def write_table(out_dir: Path, name: str, rows: list[dict], meta: dict) -> tuple[Path, Path]:
    """``name``.csv (union of the rows' keys, in first-seen order) and ``name``.json."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fields = list(dict.fromkeys(k for r in rows for k in r))
    csv_path = out_dir / f"{name}.csv"
    with csv_path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields, restval="")
        writer.writeheader()
        writer.writerows(rows)
    json_path = out_dir / f"{name}.json"
    json_path.write_text(json.dumps({"machine": meta, "rows": rows}, indent=2, default=_json_default))
    return csv_path, json_path


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


# Memory ---------------------------------------------------------------------------------------

def array_nbytes(obj, seen: set | None = None) -> int:
    """Bytes of every distinct ``wp.array`` reachable from ``obj``'s attributes.

    Walks instance attributes, lists, tuples and dicts, and follows objects of this project's
    own classes (warp_sim.*); arrays are counted once each (by identity), however many objects
    share them.
    """
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return 0
    seen.add(id(obj))
    if isinstance(obj, wp.array):
        return int(obj.capacity) if obj.capacity else int(obj.size * wp.types.type_size_in_bytes(obj.dtype))
    if isinstance(obj, dict):
        return sum(array_nbytes(v, seen) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(array_nbytes(v, seen) for v in obj)
    module = type(obj).__module__ or ""
    if module.startswith("warp_sim") and hasattr(obj, "__dict__"):
        return sum(array_nbytes(v, seen) for v in vars(obj).values())
    return 0


def memory_breakdown(sim) -> dict[str, int]:
    """Bytes per part of a Simulator (each array counted in the first part that holds it)."""
    seen: set = set()
    parts = {
        "model": sim.model,
        "states": sim.states,
        "contacts": sim.contacts,
        "solver": sim.solver,
        "pairs": sim.pairs,
        "sleep": sim.sleep,
    }
    return {name: array_nbytes(obj, seen) if obj is not None else 0 for name, obj in parts.items()}


# Measurement ----------------------------------------------------------------------------------

def config_label(shape: str, contact: bool, broad_phase: str) -> str:
    return f"{shape} {'+ ' + broad_phase if contact else 'terrain only'}"


def measure(shape: str, count: int, contact: bool, broad_phase: str, device: str, settle: float,
            budget: float, min_steps: int, max_steps: int, profile_steps: int, sleep: bool = False) -> dict:
    dt, substeps = CONTACT_RATE[contact]
    row = {
        "config": config_label(shape, contact, broad_phase),
        "shape": shape,
        "body_contact": contact,
        "broad_phase": broad_phase if contact else "",
        "bodies": count,
        "dt": round(dt, 8),
        "substeps": substeps,
        "device": device,
    }
    build_start = time.perf_counter()
    config = {"broad_phase": broad_phase} if contact else {}
    sim = cases.terrain_drop(count, shape, dt=dt, substeps=substeps, device=device, body_contact=contact,
                             sleep=sleep, **config)
    build_s = time.perf_counter() - build_start
    sim.step(1)  # kernel compile / load
    settle_steps = max(0, int(round(settle / dt)) - 1)
    sim.step(settle_steps, check=False)
    wp.synchronize_device(device)

    # time one step, then as many as fit the budget
    start = time.perf_counter()
    sim.step(1, check=False)
    wp.synchronize_device(device)
    first = time.perf_counter() - start
    steps = int(np.clip(budget / max(first, 1e-9), min_steps, max_steps))
    start = time.perf_counter()
    sim.step(steps, check=False)
    wp.synchronize_device(device)
    wall = time.perf_counter() - start

    profile_steps = int(np.clip(0.5 * budget / max(wall / steps, 1e-9), profile_steps, max(profile_steps, steps)))
    sim.profile = True
    sim.stage_times = {}
    start = time.perf_counter()
    sim.step(profile_steps, check=False)
    wp.synchronize_device(device)
    profiled_wall = time.perf_counter() - start
    sim.profile = False

    sim.check_finite()
    sim.contacts.check_overflow()
    failure = state_gate(sim)
    memory = memory_breakdown(sim)
    stage_ms = {s: 1e3 * sim.stage_times.get(s, 0.0) / profile_steps for s in STAGES}
    other_ms = max(1e3 * profiled_wall / profile_steps - sum(stage_ms.values()), 0.0)
    total_bytes = sum(memory.values())
    row.update({
        "steps": steps,
        "wall_s": round(wall, 4),
        "steps_per_s": round(steps / wall, 3),
        "body_steps_per_s": round(count * steps / wall),
        "ms_per_step": round(1e3 * wall / steps, 4),
        **{f"{s}_ms": round(v, 4) for s, v in stage_ms.items()},
        "other_ms": round(other_ms, 4),
        "profiled_steps": profile_steps,
        "profiled_ms_per_step": round(1e3 * profiled_wall / profile_steps, 4),
        "bytes_per_body": round(total_bytes / count, 1),
        **{f"{k}_bytes": v for k, v in memory.items()},
        "contacts": sim.contact_count(),
        "awake": sim.awake_count(),
        "max_penetration_m": round(sim.max_penetration(), 6),
        "kinetic_energy_j": round(sim.kinetic_energy(), 6),
        "build_s": round(build_s, 3),
        "status": failure or "ok",
    })
    return row


def skipped(shape: str, count: int, contact: bool, broad_phase: str, device: str, reason: str) -> dict:
    dt, substeps = CONTACT_RATE[contact]
    return {"config": config_label(shape, contact, broad_phase), "shape": shape, "body_contact": contact,
            "broad_phase": broad_phase if contact else "", "bodies": count, "dt": round(dt, 8),
            "substeps": substeps, "device": device, "steps": 0, "status": f"skipped: {reason}"}


def plan(counts, shapes, contact_modes, broad_phases, bounding_sphere_max: int) -> list[tuple]:
    """(shape, count, contact, broad_phase, skip_reason) for every case, smallest N first."""
    cases_list = []
    for count in counts:
        for shape in shapes:
            for contact in contact_modes:
                for bp in (broad_phases if contact else ["-"]):
                    reason = ""
                    if contact and bp == "bounding_sphere" and count > bounding_sphere_max:
                        reason = f"O(N^2) bounding_sphere beyond {bounding_sphere_max} bodies"
                    if contact and bp == "all_pairs" and count > 3000:
                        reason = "all_pairs needs N(N-1)/2 pair slots beyond 3000 bodies"
                    cases_list.append((shape, count, contact, bp, reason))
    return cases_list


# Charts ---------------------------------------------------------------------------------------

def chart_throughput(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r["status"] == "ok"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
    styles = {"sphere": "o", "box": "s", "mix": "^"}
    for ax, contact in zip(axes, (False, True)):
        for label in dict.fromkeys(r["config"] for r in ok if r["body_contact"] == contact):
            pts = sorted((r["bodies"], r["body_steps_per_s"]) for r in ok if r["config"] == label)
            shape = label.split()[0]
            ax.loglog(*zip(*pts), marker=styles.get(shape, "o"), label=label)
        dt, sub = CONTACT_RATE[contact]
        ax.set_title(("body-body contact" if contact else "terrain contact only")
                     + f", dt = 1/{round(1 / dt)} s x {sub}")
        ax.set_xlabel("bodies")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    axes[0].set_ylabel("body-steps / s")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def chart_stages(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r["status"] == "ok"]
    counts = sorted({r["bodies"] for r in ok}) or [0]
    fig, axes = plt.subplots(1, len(counts), figsize=(max(4.0, 3.2 * len(counts)), 5.2), squeeze=False)
    colours = {"terrain": "#4c72b0", "pairs": "#dd8452", "solve": "#55a868", "sleep": "#c44e52", "other": "#8c8c8c"}
    for ax, count in zip(axes[0], counts):
        sel = [r for r in ok if r["bodies"] == count]
        labels = [r["config"].replace(" terrain only", "\nterrain").replace(" + ", "\n") for r in sel]
        bottom = np.zeros(len(sel))
        for stage in (*STAGES, "other"):
            values = np.array([float(r.get(f"{stage}_ms", 0.0) or 0.0) for r in sel])
            ax.bar(range(len(sel)), values, bottom=bottom, color=colours[stage], label=stage)
            bottom += values
        ax.set_xticks(range(len(sel)), labels, fontsize=6, rotation=90)
        ax.set_title(f"N = {count:,}", fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0][0].set_ylabel("ms per step (profiled)")
    axes[0][-1].legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# CLI ------------------------------------------------------------------------------------------

def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--counts", type=int, nargs="+", default=None, help=f"default {FULL_COUNTS}")
    p.add_argument("--shapes", nargs="+", default=["sphere", "box", "mix"], choices=["sphere", "box", "mix"])
    p.add_argument("--contact", nargs="+", default=["off", "on"], choices=["off", "on"],
                   help="terrain contact only (off) and/or body-body contact (on)")
    p.add_argument("--broad-phases", nargs="+", default=["grid", "grid_hash", "bounding_sphere"],
                   choices=["grid", "grid_sorted", "grid_hash", "bounding_sphere", "all_pairs"])
    p.add_argument("--bounding-sphere-max", type=int, default=10000)
    p.add_argument("--settle", type=float, default=0.5, help="simulated seconds before timing")
    p.add_argument("--budget", type=float, default=2.0, help="wall seconds of timed steps per case")
    p.add_argument("--min-steps", type=int, default=3)
    p.add_argument("--max-steps", type=int, default=200)
    p.add_argument("--profile-steps", type=int, default=3)
    p.add_argument("--sleep", action="store_true", help="sleeping on (default off: measure the solver)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--quick", action="store_true", help=f"N = {QUICK_COUNTS}, short settle and budget")
    p.add_argument("--out-dir", type=Path, default=None, help="default bench/results; --quick: a temporary folder")
    p.add_argument("--tag", default="", help="suffix for the result file names")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)
    args.out_dir = output_dir(args.out_dir, args.quick, "scaling")
    if args.quick:
        args.counts = args.counts or QUICK_COUNTS
        args.settle = min(args.settle, 0.1)
        args.budget = min(args.budget, 0.2)
        args.max_steps = min(args.max_steps, 20)
        args.profile_steps = min(args.profile_steps, 2)
    counts = args.counts or FULL_COUNTS
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    meta = machine_info(args.device)
    meta.update({"settle_s": args.settle, "budget_s": args.budget, "sleep": args.sleep})
    from tqdm import tqdm

    contact_modes = [m == "on" for m in dict.fromkeys(args.contact)]
    todo = plan(counts, args.shapes, contact_modes, args.broad_phases, args.bounding_sphere_max)
    rows = []
    bar = tqdm(todo, desc="scaling", unit="case", disable=args.no_progress)
    for shape, count, contact, bp, reason in bar:
        bar.set_postfix_str(f"{config_label(shape, contact, bp)} N={count}")
        if reason:
            row = skipped(shape, count, contact, bp, args.device, reason)
        else:
            row = measure(shape, count, contact, bp, args.device, args.settle, args.budget, args.min_steps,
                          args.max_steps, args.profile_steps, args.sleep)
        rows.append(row)
        if not args.no_progress:
            tqdm.write(f"{row['config']:28s} N={count:>7d}: {row.get('steps_per_s', '-')!s:>9} steps/s "
                       f"{row.get('body_steps_per_s', '-')!s:>10} body-steps/s "
                       f"{row.get('bytes_per_body', '-')!s:>7} B/body  [{row['status']}]")
    device_tag = "" if args.device == "cpu" else "_" + args.device.replace(":", "")
    name = f"scaling{device_tag}{args.tag}"
    csv_path, _ = write_table(args.out_dir, name, rows, meta)
    title = f"terrain_drop scaling on {meta['device_name']} ({meta['cpu'][:40]}, {meta['cores']} cores)"
    chart_throughput(rows, args.out_dir / f"{name}_throughput.png", title)
    chart_stages(rows, args.out_dir / f"{name}_stages.png", title)
    print(f"wrote {csv_path} (+ .json, _throughput.png, _stages.png)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
