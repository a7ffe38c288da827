"""What a launch split across the CPU threads pays to hand its chunk to another thread.

    python bench/handoff.py                  # chunks of about 0.05, 0.5 and 2 ms
    python bench/handoff.py --repeats 500

warp_sim.launch splits a launch into one chunk per CPU thread; the calling thread runs the
first chunk and a pool thread the second.  Each chunk is a Python call into Warp (the GIL is
held to start it and released inside), so the pool thread must wake up, take the GIL and start
its chunk, and the caller must wake up again when it ends.  This script times the same kernel
(a fixed amount of arithmetic per thread index) launched whole on one thread and split in two
through warp_sim.launch, and reports the split's wall time against half the whole one: the
difference is the hand-off, paid once per split launch; then the same split with the workers
spinning (``launch.hot``, what a simulator's steps use).  A step of the 10k rain makes about
26 split launches (its 12 sweeps among them).

Writes bench/results/handoff.{json,csv}.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import RESULTS, machine_info, write_rows  # noqa: E402
from warp_sim.launch import cpu_threads, hot, launch  # noqa: E402

wp.set_module_options({"enable_backward": False})


@wp.kernel
def arithmetic(tid_offset: int, work: int, out: wp.array(dtype=float)):
    i = wp.tid() + tid_offset
    s = float(0.0)
    for k in range(work):
        s = s + wp.sin(float(k) * 1.0e-3 + float(i))
    out[i] = s


def timed(dim: int, work: int, out, min_chunk: int, repeats: int) -> list[float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        launch(arithmetic, dim, [work, out], "cpu", key=out, min_chunk=min_chunk)  # recorded, as the steps launch
        times.append(time.perf_counter() - start)
        time.sleep(2.0e-4)  # the gap a step leaves between launches (its Python between them)
    return times


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--works", type=int, nargs="+", default=[3000, 30000, 120000], help="sines per thread index")
    p.add_argument("--dim", type=int, default=8, help="thread indices a launch")
    p.add_argument("--repeats", type=int, default=300)
    p.add_argument("--out-dir", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if cpu_threads() < 2:
        raise SystemExit("handoff.py: one CPU thread, nothing is handed off")
    out = wp.zeros(args.dim, dtype=float, device="cpu")
    rows = []
    for work in args.works:
        launch(arithmetic, args.dim, [work, out], "cpu", min_chunk=1)  # compiles and loads
        whole = float(np.median(timed(args.dim, work, out, args.dim + 1, args.repeats)))
        split = timed(args.dim, work, out, 1, args.repeats)
        os.environ["WARP_SIM_HOT"] = "1"
        with hot():
            spun = timed(args.dim, work, out, 1, args.repeats)
        row = {"work": work, "whole_us": 1e6 * whole, "split_us": 1e6 * float(np.median(split)),
               "split_p90_us": 1e6 * float(np.percentile(split, 90)),
               "handoff_us": 1e6 * (float(np.median(split)) - whole / 2),
               "hot_split_us": 1e6 * float(np.median(spun)), "hot_split_p90_us": 1e6 * float(np.percentile(spun, 90)),
               "hot_handoff_us": 1e6 * (float(np.median(spun)) - whole / 2)}
        rows.append(row)
        print(f"one thread {row['whole_us']:7.0f} us | split in two: pool {row['split_us']:7.0f} us (p90 "
              f"{row['split_p90_us']:.0f}), hand-off {row['handoff_us']:4.0f} us | spinning workers "
              f"{row['hot_split_us']:7.0f} us (p90 {row['hot_split_p90_us']:.0f}), hand-off {row['hot_handoff_us']:4.0f} us")
    write_rows("handoff", rows, {**machine_info("cpu"), "command": "python bench/handoff.py " + " ".join(sys.argv[1:] if argv is None else argv)}, args.out_dir)


if __name__ == "__main__":
    main()
