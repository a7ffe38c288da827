"""Headless runner: step a Simulator, record frames, time the stepping.

    result = run(sim, steps=600, record_every=10)
    print(format_summary(result["summary"]))

Frames are taken at step 0 (the state ``sim`` starts in), every ``record_every`` steps, and at
the last step.  Between frames the simulator runs whole chunks (``sim.step(count)``), which
checks for non-finite state once per chunk and raises NonFiniteStateError naming the first bad
body and its step.

Only ``sim.step`` is timed, with the device synchronised before each clock reading, and the
first step is left out: it compiles or loads the kernels (and captures the CUDA graph).
"""

from __future__ import annotations

import sys
import time

import numpy as np
import warp as wp
from tqdm import tqdm

# Progress updates at least this many times per run (each update ends a chunk).
PROGRESS_TICKS = 100


def record_steps(steps: int, record_every: int) -> list[int]:
    """Steps at which frames are taken: 0, k, 2k, ..., and ``steps``."""
    return sorted(set(range(0, steps + 1, record_every)) | {steps})


def run(sim, steps: int, record_every: int = 1, progress: bool = True) -> dict:
    """Advance ``sim`` by ``steps`` steps; return the recorded frames and a summary.

    Arrays (F frames, N bodies): time (F), position (F, N, 3), orientation (F, N, 4; x y z w),
    velocity (F, N, 3), angular_velocity (F, N, 3; world frame), kinetic_energy (F),
    max_penetration (F), contact_count (F), shape (N; 0 sphere, 1 box), size (N, 3; sphere
    (r, 0, 0), box half extents), the terrain description of ``sim.terrain_record()``, and
    ``summary`` (a dict, see ``summarize``).
    """
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    if record_every < 1:
        raise ValueError(f"record_every must be >= 1, got {record_every}")
    n = sim.model.body_count
    frames = record_steps(steps, record_every)
    f = len(frames)
    out = {
        "time": np.zeros(f, np.float64),
        "position": np.zeros((f, n, 3), np.float32),
        "orientation": np.zeros((f, n, 4), np.float32),
        "velocity": np.zeros((f, n, 3), np.float32),
        "angular_velocity": np.zeros((f, n, 3), np.float32),
        "kinetic_energy": np.zeros(f, np.float64),
        "max_penetration": np.zeros(f, np.float64),
        "contact_count": np.zeros(f, np.int32),
    }

    def record(frame: int):
        s = sim.state
        out["time"][frame] = sim.time
        out["position"][frame] = s.body_pos.numpy()
        out["orientation"][frame] = s.body_quat.numpy()
        out["velocity"][frame] = s.body_vel.numpy()
        out["angular_velocity"][frame] = sim.angular_velocity()
        out["kinetic_energy"][frame] = sim.kinetic_energy()
        out["max_penetration"][frame] = sim.max_penetration()
        out["contact_count"][frame] = sim.contact_count()

    # Chunk ends: frames, progress ticks, and step 1 (the untimed warm-up step).
    tick = max(1, steps // PROGRESS_TICKS)
    ends = sorted(set(frames[1:]) | set(range(tick, steps + 1, tick)) | {1})
    frame_of = {step: i for i, step in enumerate(frames)}

    show_bar = progress and sys.stderr.isatty()
    bar = tqdm(total=steps, unit="step", file=sys.stderr, disable=not show_bar, dynamic_ncols=True)
    record(0)
    started = time.perf_counter()
    wall = 0.0
    done = 0
    try:
        for end in ends:
            timed = done > 0
            if timed:
                wp.synchronize_device(sim.device)
                t0 = time.perf_counter()
            sim.step(end - done)
            if timed:
                wp.synchronize_device(sim.device)
                wall += time.perf_counter() - t0
            bar.update(end - done)
            done = end
            if done in frame_of:
                record(frame_of[done])
    finally:
        bar.close()
    if progress and not show_bar:
        print(f"{steps} steps ({sim.time:.4g} s simulated) in {time.perf_counter() - started:.2f} s",
              file=sys.stderr)

    out["shape"] = sim.model.host["body_shape"].astype(np.int32)
    out["size"] = sim.model.host["body_size"].astype(np.float32)
    out.update(sim.terrain_record())
    out["summary"] = summarize(steps, steps - 1, wall, n, out)
    return out


def summarize(steps: int, timed_steps: int, wall: float, bodies: int, frames: dict) -> dict:
    """JSON-ready figures of a run.

    wall_s is the time spent in ``sim.step`` after the first step, over ``timed_steps`` steps;
    the rates are None when no step was timed (steps == 1).  max_penetration is the deepest
    over the recorded frames.
    """
    rate = timed_steps / wall if timed_steps > 0 and wall > 0 else None
    return {
        "steps": int(steps),
        "bodies": int(bodies),
        "timed_steps": int(timed_steps),
        "wall_s": float(wall),
        "steps_per_s": rate,
        "body_steps_per_s": rate * bodies if rate is not None else None,
        "sim_time_s": float(frames["time"][-1]),
        "final_kinetic_energy": float(frames["kinetic_energy"][-1]),
        "max_penetration": float(frames["max_penetration"].max()),
    }


def format_summary(summary: dict) -> str:
    """One line: steps, rates, final kinetic energy, max penetration."""
    rate = summary.get("steps_per_s")
    body_rate = summary.get("body_steps_per_s")
    parts = [
        f"steps {summary['steps']:,}",
        f"{rate:,.0f} steps/s" if rate is not None else "n/a steps/s",
        f"{body_rate:,.0f} body-steps/s" if body_rate is not None else "n/a body-steps/s",
        f"final KE {summary['final_kinetic_energy']:.3g} J",
        f"max penetration {summary['max_penetration'] * 1000.0:.3g} mm",
    ]
    return " | ".join(parts)

