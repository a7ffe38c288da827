"""Headless runner: step a Simulator, record frames, time the stepping.

    result = run(sim, steps=600, record_every=10)
    print(format_summary(result["summary"]))

Frames are taken at the step ``sim`` starts in, at every step that is a multiple of
``record_every`` (counted from step 0 of the simulation, so a resumed run records the same steps
as one that ran straight through), and at the last step.  Between frames the simulator runs whole
chunks (``sim.step(count)``), which checks for non-finite state once per chunk and raises
NonFiniteStateError naming the first bad body and its step.

With a ``writer`` (recording.RunWriter) the frames go to disk in chunks as the run goes and the
file is finished whatever stops the run: completion, Ctrl-C (``stop_reason = "interrupted"``; the
run stops at the end of the chunk it is in, recording that step, a second Ctrl-C at once),
non-finite state (``"non_finite"``), contact overflow (``"contact_overflow"``) or another
exception (``"error"``); the exception is then raised again.  Without one, the frames are
returned as arrays (the in-memory API).

Only ``sim.step`` is timed, with the device synchronised before each clock reading, and the
first step is left out: it compiles or loads the kernels (and captures the CUDA graph).

Frames and per-body arrays are recorded in scene order (``Model.to_scene_order``), whatever order
the Model stores the bodies in (``[sim] body_order``, body_order.py): body s of a run file is
always the scene's body s.
"""

from __future__ import annotations

import math
import signal
import sys
import threading
import time

import numpy as np
import warp as wp
from tqdm import tqdm

from .recording import FRAME_DTYPES, FRAME_KEYS, FRAME_WIDTH

# Progress updates at least this many times per run (each update ends a chunk).
PROGRESS_TICKS = 100


def record_steps(steps: int, record_every: int, start: int = 0) -> list[int]:
    """Steps at which frames are taken: ``start``, the multiples of k after it, and ``start + steps``."""
    first = (start // record_every + 1) * record_every
    return [start, *range(first, start + steps, record_every), start + steps]


def _next_multiple(value: int, k: int) -> int:
    return (value // k + 1) * k


class _MemorySink:
    """Frames kept in memory (run() without a writer)."""

    def __init__(self, bodies: int):
        self.bodies = bodies
        self.frames = {key: [] for key in FRAME_KEYS}

    def add(self, frame: dict):
        for key in FRAME_KEYS:
            self.frames[key].append(frame[key])

    def arrays(self) -> dict:
        out = {}
        for key in FRAME_KEYS:
            a = np.asarray(self.frames[key], dtype=FRAME_DTYPES[key])
            if key in FRAME_WIDTH:
                a = a.reshape(len(self.frames["time"]), self.bodies, FRAME_WIDTH[key])
            out[key] = a
        return out


class _DeferredInterrupt:
    """Ctrl-C during a run stops it at the end of the current chunk, with the state whole and its
    frame recorded; a second Ctrl-C interrupts at once.  Only in the main thread, and only when
    SIGINT has Python's default handler (an application's own handler is left alone)."""

    def __enter__(self):
        self.requested = False
        self._previous = None
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def _handle(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __exit__(self, *exc):
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return False


def static_record(sim) -> dict:
    """Per-body and terrain arrays of a run: shape, size (in scene order), terrain_*."""
    scene = sim.model.to_scene_order
    return {"shape": scene(sim.model.host["body_shape"]).astype(np.int32),
            "size": scene(sim.model.host["body_size"]).astype(np.float32), **sim.terrain_record()}


def run(sim, steps: int, record_every: int = 1, progress: bool = True, writer=None,
        checkpoint_every: int | None = None, on_checkpoint=None, summary_extra: dict | None = None) -> dict:
    """Advance ``sim`` by ``steps`` steps; return the recorded frames and a summary.

    Arrays (F frames, N bodies): time (F), position (F, N, 3), orientation (F, N, 4; x y z w),
    velocity (F, N, 3), angular_velocity (F, N, 3; world frame), kinetic_energy (F),
    max_penetration (F), contact_count (F), shape (N; 0 sphere, 1 box), size (N, 3; sphere
    (r, 0, 0), box half extents), the terrain description of ``sim.terrain_record()``, and
    ``summary`` (a dict, see ``summarize``).  With ``writer`` the frames go to it instead and
    only ``summary`` is returned.  ``on_checkpoint(sim)`` is called after every step that is a
    multiple of ``checkpoint_every``.  ``summary_extra`` is merged into the summary (scene name,
    settings).
    """
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
    if isinstance(record_every, bool) or not isinstance(record_every, (int, np.integer)) or record_every < 1:
        raise ValueError(f"record_every must be an integer >= 1, got {record_every!r}")
    if checkpoint_every is not None and checkpoint_every < 1:
        raise ValueError(f"checkpoint_every must be an integer >= 1, got {checkpoint_every!r}")
    n = sim.model.body_count
    if writer is None:  # every frame stays in memory: refuse what will not fit before stepping
        from .limits import check_memory
        from .recording import frame_bytes

        frames = int(steps) // record_every + 2
        check_memory(frames * frame_bytes(n), f"steps = {steps} with record_every = {record_every} "
                     f"({frames:,} frames of {n:,} bodies kept in memory; stream them with a RunWriter)")
    sink = writer if writer is not None else _MemorySink(n)
    stats = {"frames": 0, "time": 0.0, "ke": 0.0, "pen": 0.0}

    scene = sim.model.to_scene_order  # copies too: on the CPU .numpy() is a view of the live state buffer

    def record():
        s = sim.state
        frame = {
            "time": sim.time, "position": scene(s.body_pos), "orientation": scene(s.body_quat),
            "velocity": scene(s.body_vel), "angular_velocity": scene(sim.angular_velocity()),
            "kinetic_energy": sim.kinetic_energy(), "max_penetration": sim.max_penetration(),
            "contact_count": sim.contact_count(),
        }
        sink.add(frame)
        stats["frames"] += 1
        stats["time"], stats["ke"] = frame["time"], frame["kinetic_energy"]
        stats["pen"] = max(stats["pen"], frame["max_penetration"])

    start = sim.step_count
    end_step = start + int(steps)
    tick = max(1, int(steps) // PROGRESS_TICKS)
    show_bar = progress and sys.stderr.isatty()
    bar = tqdm(total=int(steps), unit="step", file=sys.stderr, disable=not show_bar, dynamic_ncols=True)
    record()
    started = time.perf_counter()
    wall = 0.0
    done = start
    stop_reason, stop_detail = "completed", ""
    with _DeferredInterrupt() as interrupt:
        try:
            while done < end_step:
                # chunk ends: frames, progress ticks, checkpoints, and the untimed warm-up step
                end = min(end_step, _next_multiple(done, record_every), start + _next_multiple(done - start, tick))
                if checkpoint_every:
                    end = min(end, _next_multiple(done, checkpoint_every))
                timed = done > start
                if not timed:
                    end = start + 1
                if timed:
                    wp.synchronize_device(sim.device)
                    t0 = time.perf_counter()
                sim.step(end - done)
                if timed:
                    wp.synchronize_device(sim.device)
                    wall += time.perf_counter() - t0
                bar.update(end - done)
                done = end
                recorded = done % record_every == 0 or done == end_step
                if recorded:
                    record()
                if checkpoint_every and on_checkpoint is not None and done % checkpoint_every == 0:
                    on_checkpoint(sim)
                if interrupt.requested:
                    if not recorded:
                        record()  # the step the run stops at
                    raise KeyboardInterrupt
        except BaseException as e:
            from .contacts import ContactOverflowError
            from .simulator import NonFiniteStateError

            done = sim.step_count
            if isinstance(e, KeyboardInterrupt):
                stop_reason = "interrupted"
            elif isinstance(e, NonFiniteStateError):
                stop_reason = "non_finite"
            elif isinstance(e, ContactOverflowError):
                stop_reason = "contact_overflow"
            else:
                stop_reason = "error"
            stop_detail = str(e) or type(e).__name__
            if writer is not None:
                summary = summarize(done - start, max(done - start - 1, 0), wall, n, stats, start,
                                    stop_reason, stop_detail)
                summary.update(summary_extra or {})
                writer.finish(summary)
            raise
        finally:
            bar.close()
    if progress and not show_bar:
        print(f"{steps} steps ({sim.time:.4g} s simulated) in {time.perf_counter() - started:.2f} s",
              file=sys.stderr)

    summary = summarize(int(steps), int(steps) - 1, wall, n, stats, start, stop_reason, stop_detail)
    summary.update(summary_extra or {})
    if writer is not None:
        writer.finish(summary)
        return {"summary": summary}
    out = sink.arrays()
    out.update(static_record(sim))
    out["summary"] = summary
    return out


def summarize(steps: int, timed_steps: int, wall: float, bodies: int, stats: dict, start: int = 0,
              stop_reason: str = "completed", stop_detail: str = "") -> dict:
    """JSON-ready figures of a run.

    wall_s is the time spent in ``sim.step`` after the first step, over ``timed_steps`` steps;
    the rates are None when no step was timed (steps == 1).  max_penetration is the deepest
    over the recorded frames.  stop_reason is completed, interrupted, non_finite,
    contact_overflow or error (stop_detail says more); stop_step is the simulation step the run
    ended at and start_step the one it began at (not 0 for a resumed run).
    """
    rate = timed_steps / wall if timed_steps > 0 and wall > 0 else None
    return {
        "steps": int(steps),
        "bodies": int(bodies),
        "timed_steps": int(timed_steps),
        "wall_s": float(wall),
        "steps_per_s": rate,
        "body_steps_per_s": rate * bodies if rate is not None else None,
        "sim_time_s": float(stats["time"]),
        "final_kinetic_energy": float(stats["ke"]),
        "max_penetration": float(stats["pen"]),
        "recorded_frames": int(stats["frames"]),
        "start_step": int(start),
        "stop_step": int(start + steps),
        "stop_reason": stop_reason,
        "stop_detail": stop_detail,
    }


def format_rate(value: float) -> str:
    """At least three significant figures: 0.412, 12.3, 2,345 (never a bare 0)."""
    if value >= 100:
        return f"{value:,.0f}"
    if value == 0:
        return "0"
    digits = max(0, 2 - int(math.floor(math.log10(abs(value)))))
    return f"{value:.{digits}f}"


def format_summary(summary: dict) -> str:
    """One line: steps, rates (three significant figures at least), final kinetic energy, max penetration."""
    rate = summary.get("steps_per_s")
    body_rate = summary.get("body_steps_per_s")
    parts = [
        f"steps {summary['steps']:,}",
        f"{format_rate(rate)} steps/s" if rate is not None else "n/a steps/s",
        f"{format_rate(body_rate)} body-steps/s" if body_rate is not None else "n/a body-steps/s",
        f"final KE {summary['final_kinetic_energy']:.3g} J",
        f"max penetration {summary['max_penetration'] * 1000.0:.3g} mm",
    ]
    reason = summary.get("stop_reason", "completed")
    if reason != "completed":
        parts.append(f"stopped: {reason} at step {summary.get('stop_step')}")
    return " | ".join(parts)
