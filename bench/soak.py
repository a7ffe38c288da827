"""Soak run: a small mixed scene stepped for a long time on the CPU, checking that nothing drifts.

    python bench/soak.py                      # 1,000,000 steps (hours on a 2-core machine)
    python bench/soak.py --steps 2000         # a quick check

Every ``--check-every`` steps it checks that the state is finite (Simulator.step raises on
non-finite state), that the total energy (kinetic + potential) has not risen by more than
``--energy-slack`` J above the lowest value seen at an earlier check (contacts, friction and
damping only remove energy, so any gain between checks is the solver adding some), that no body is deeper than 1 cm in the terrain or another body, and
that the resident memory (RSS, /proc/self/statm) has not grown by more than ``--rss-slack-mb``
since the first check (leaks of per-step allocations show here).  Sleeping is off so that every
step runs the whole solver.  By default the step is captured once as a graph and replayed (the
path CUDA takes); ``--no-graph`` launches kernel by kernel.  The figures and the verdict go to bench/results/soak.json; the exit
status is 1 when a check failed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import RESULTS, machine_info  # noqa: E402

SCENE = """
name = "soak"
[sim]
dt = 0.016666666666666666
substeps = 4
sleep = false
seed = 7
[terrain]
kind = "fourier"
amplitude = 0.4
[material]
restitution = 0.2
friction = 0.6
rolling_resistance = 0.05
[[layout]]
type = "grid"
count = [4, 2, 4]
shape = "mix"
random_orientation = true
radius = 0.2
half_extents = [0.25, 0.15, 0.2]
spacing = 1.0
[[layout]]
type = "stack"
count = 4
position = [4.0, 0.0]
[[layout]]
type = "chain"
count = 4
start = [-4.0, 1.0]
velocity = [2.0, 0.0, 0.0]
"""


def source_commit() -> str | None:
    """The checkout's commit (``git rev-parse``), or None outside a git checkout."""
    import subprocess

    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).resolve().parent,
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def rss_bytes() -> int:
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * 4096  # resident pages (4 KiB pages on Linux x86-64)


def total_energy(sim) -> float:
    pos = sim.state.body_pos.numpy().astype(np.float64)
    mass = sim.model.body_mass
    dynamic = sim.model.host["body_inv_mass"] > 0
    potential = -float(np.sum((mass * (pos @ np.asarray(sim.config.gravity, np.float64)))[dynamic]))
    return sim.kinetic_energy() + potential


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=1_000_000)
    p.add_argument("--check-every", type=int, default=1000, metavar="K")
    p.add_argument("--energy-slack", type=float, default=0.5, help="allowed energy gain [J] (default 0.5)")
    p.add_argument("--rss-slack-mb", type=float, default=64.0, help="allowed RSS growth [MiB] (default 64)")
    p.add_argument("--graph", action=argparse.BooleanOptionalAction, default=True,
                   help="capture the whole step as one graph and replay it (default on: about 3x fewer "
                        "host calls per step on the CPU; --no-graph steps kernel by kernel)")
    p.add_argument("--out", type=Path, default=RESULTS / "soak.json")
    args = p.parse_args(argv)
    if args.steps < 1 or args.check_every < 1:
        p.error("--steps and --check-every must be >= 1")

    import warp as wp

    wp.config.quiet = True
    from warp_sim.scene import parse_scene

    text = SCENE.replace("sleep = false", f"sleep = false\ngraph = {'true' if args.graph else 'false'}")
    scene = parse_scene(__import__("tomllib").loads(text), "soak")
    sim = scene.build("cpu")
    e0 = total_energy(sim)
    rows, failures = [], []
    rss0 = None
    lowest, gain = e0, float("-inf")
    started = time.perf_counter()
    done = 0
    tty = sys.stderr.isatty()
    try:
        while done < args.steps:
            chunk = min(args.check_every, args.steps - done)
            sim.step(chunk)  # raises NonFiniteStateError naming the body and step
            done += chunk
            energy = total_energy(sim)
            depth = sim.max_penetration()
            rss = rss_bytes()
            rss0 = rss if rss0 is None else rss0
            rows.append({"step": done, "energy_j": energy, "kinetic_j": sim.kinetic_energy(), "max_depth_m": depth,
                         "rss_mb": rss / 2**20})
            if energy > lowest + args.energy_slack:
                failures.append(f"step {done}: energy rose to {energy:.4g} J from {lowest:.4g} J")
            gain = max(gain, energy - lowest)
            lowest = min(lowest, energy)
            if depth > 0.01:
                failures.append(f"step {done}: penetration {depth * 1000:.3g} mm")
            if rss - rss0 > args.rss_slack_mb * 2**20:
                failures.append(f"step {done}: RSS grew by {(rss - rss0) / 2**20:.1f} MiB")
            if failures:
                break
            elapsed = time.perf_counter() - started
            line = (f"{done:,}/{args.steps:,} steps | {done / elapsed:.3g} steps/s | E {energy:.4g} J (start "
                    f"{e0:.4g}) | depth {depth * 1000:.3g} mm | RSS {rss / 2**20:.1f} MiB")
            if tty:
                print("\r" + line, end="", file=sys.stderr, flush=True)
            elif len(rows) % max(1, len(range(0, args.steps, args.check_every)) // 20) == 0:
                print(line, file=sys.stderr, flush=True)
    except Exception as e:  # non-finite state, contact overflow: recorded, not a traceback
        failures.append(f"step {sim.step_count}: {type(e).__name__}: {e}")
    if tty:
        print(file=sys.stderr)
    elapsed = time.perf_counter() - started
    result = {
        "machine": machine_info("cpu"),
        "commit": source_commit(),
        "steps": done,
        "requested_steps": args.steps,
        "bodies": sim.model.body_count,
        "graph": args.graph,
        "wall_s": elapsed,
        "steps_per_s": done / elapsed if elapsed > 0 else None,
        "start_energy_j": e0,
        "max_energy_j": max((r["energy_j"] for r in rows), default=e0),
        "final_energy_j": rows[-1]["energy_j"] if rows else e0,
        "max_depth_m": max((r["max_depth_m"] for r in rows), default=0.0),
        "rss_growth_mb": (rows[-1]["rss_mb"] - rows[0]["rss_mb"]) if rows else 0.0,
        "passed": not failures,
        "failures": failures,
        "largest_energy_gain_j": gain,
        "limits": {"energy_slack_j": args.energy_slack, "rss_slack_mb": args.rss_slack_mb, "depth_m": 0.01},
        "rows": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    verdict = "passed" if not failures else "FAILED: " + "; ".join(failures)
    print(f"soak: {done:,} steps of {sim.model.body_count} bodies in {elapsed:.3g} s, energy {e0:.4g} -> "
          f"{result['final_energy_j']:.4g} J (max {result['max_energy_j']:.4g}), depth <= "
          f"{result['max_depth_m'] * 1000:.3g} mm, RSS growth {result['rss_growth_mb']:.1f} MiB: {verdict}; "
          f"wrote {args.out}")
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
