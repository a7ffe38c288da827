"""A sweep of scene configurations, each one task: locally (a loop or a process pool) or on Ray.

    python bench/sweep.py                                   # default grid, one process
    python bench/sweep.py --jobs 2                          # a local process pool
    python bench/sweep.py --ray-address local               # ray.init() on this machine
    python bench/sweep.py --ray-address ray://head:10001    # an existing Ray cluster
    python bench/sweep.py --counts 1000 4000 --integrators semi_implicit verlet rk4 \\
        --solvers soft_step pushout --broad-phases grid grid_hash --dts 1/60 1/120 --substeps 4

A configuration is one ``warp_sim.cases.terrain_drop`` scene (body count, shape, body contact)
with one method (integrator, solver, broad phase) at one step (dt, substeps).  ``run_config``
builds it, simulates ``settle`` seconds, times ``steps`` steps and returns one row: the
configuration, timing columns (TIMING_COLUMNS: wall clock, they differ run to run) and
measurements that do not depend on the machine (penetration, kinetic energy, contact count, a
hash of the final positions, the invalid-state gate).  CPU runs are bit-reproducible, so the
non-timing columns of a row are the same whichever runner produced it.

Runners (rows come back in configuration order and go into the same CSV whichever is used):

* default: a loop in this process;
* ``--jobs N``: a process pool of N workers (spawned; each worker splits its kernel launches
  over cores / N threads).  Jobs share the machine, so their timings are lower than a lone
  run's: use it for the accuracy columns, or where cores are plentiful;
* ``--ray-address ADDR``: Ray is imported only then (``pip install -e ".[ray]"``); each
  configuration is a ``ray.remote`` task (``--ray-cpus`` CPUs each).  ``local`` starts Ray on
  this machine (``ray.init()``); any other value is passed to ``ray.init(address=...)``.  The
  cluster's workers need this package importable: install it on every node, or pass
  ``--ray-working-dir .`` to ship the checkout with the job (Ray's ``runtime_env``).

Writes ``<out-dir>/<name>.{csv,json,png}`` (default name ``sweep``).
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import os
import sys
import time
from fractions import Fraction
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

TIMING_COLUMNS = ("wall_s", "steps_per_s", "body_steps_per_s", "ms_per_step", "build_s", "worker")
CONFIG_KEYS = ("bodies", "shape", "body_contact", "integrator", "solver", "broad_phase", "dt", "substeps",
               "settle", "steps")


def parse_dt(text: str) -> float:
    """'1/60', '0.004' -> seconds."""
    return float(Fraction(text)) if "/" in text else float(text)


def configurations(counts, shapes, contact_modes, integrators, solvers, broad_phases, dts, substeps,
                   settle: float, steps: int) -> list[dict]:
    out = []
    for count, shape, contact, integ, solver, dt, sub in itertools.product(
            counts, shapes, contact_modes, integrators, solvers, dts, substeps):
        for bp in (broad_phases if contact else ["grid"]):
            out.append({"bodies": count, "shape": shape, "body_contact": contact, "integrator": integ,
                        "solver": solver, "broad_phase": bp, "dt": dt, "substeps": sub, "settle": settle,
                        "steps": steps})
    return out


def run_config(config: dict, device: str = "cpu") -> dict:
    """One configuration, start to finish, in this process; returns its row."""
    import numpy as np
    import warp as wp

    from bench.common import state_gate
    from warp_sim import cases

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    c = dict(config)
    row = {k: c[k] for k in CONFIG_KEYS}
    start = time.perf_counter()
    sim = cases.terrain_drop(c["bodies"], c["shape"], dt=c["dt"], substeps=c["substeps"], device=device,
                             body_contact=c["body_contact"], integrator=c["integrator"], solver=c["solver"],
                             broad_phase=c["broad_phase"])
    build_s = time.perf_counter() - start
    try:
        sim.step(1)
        sim.step(max(int(round(c["settle"] / c["dt"])) - 1, 0), check=False)
        wp.synchronize_device(device)
        start = time.perf_counter()
        sim.step(c["steps"], check=False)
        wp.synchronize_device(device)
        wall = time.perf_counter() - start
        sim.check_finite()
        sim.contacts.check_overflow()
    except Exception as exc:  # a configuration that blows up is a result
        return {**row, "status": f"error: {type(exc).__name__}: {exc}"[:200]}
    pos = sim.state.body_pos.numpy()
    row.update({
        "wall_s": round(wall, 4),
        "steps_per_s": round(c["steps"] / wall, 3),
        "body_steps_per_s": round(c["bodies"] * c["steps"] / wall),
        "ms_per_step": round(1e3 * wall / c["steps"], 4),
        "build_s": round(build_s, 3),
        "worker": f"{os.uname().nodename}:{os.getpid()}",
        "max_penetration_m": round(sim.max_penetration(), 7),
        "kinetic_energy_j": round(sim.kinetic_energy(), 7),
        "contacts": sim.contact_count(),
        "mean_height_m": round(float(np.mean(pos[:, 1], dtype=np.float64)), 7),
        "state_hash": hashlib.sha256(np.ascontiguousarray(pos).tobytes()).hexdigest()[:16],
        "status": state_gate(sim) or "ok",
    })
    return row


# Runners ---------------------------------------------------------------------------------------

def run_local(configs: list[dict], jobs: int = 1, device: str = "cpu", progress: bool = True) -> list[dict]:
    from tqdm import tqdm

    if jobs <= 1:
        return [run_config(c, device) for c in tqdm(configs, desc="sweep", unit="config", disable=not progress)]
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    threads = max(1, (os.cpu_count() or 1) // jobs)
    with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn"),
                             initializer=_worker_init, initargs=(threads,)) as pool:
        futures = [pool.submit(run_config, c, device) for c in configs]
        for f in tqdm(futures, desc="sweep", unit="config", disable=not progress):
            f.result()
    return [f.result() for f in futures]


def _worker_init(threads: int):
    os.environ.setdefault("WARP_SIM_CPU_THREADS", str(threads))
    sys.path.insert(0, str(ROOT))


def run_ray(configs: list[dict], address: str, device: str = "cpu", cpus_per_task: float = 1.0,
            working_dir: str | None = None, progress: bool = True) -> list[dict]:
    import ray  # optional extra: imported only on this path

    runtime_env = {"working_dir": working_dir} if working_dir else None
    env_vars = {"WARP_SIM_CPU_THREADS": str(max(1, int(cpus_per_task)))}
    runtime_env = {**(runtime_env or {}), "env_vars": env_vars}
    if address == "local":
        ray.init(runtime_env=runtime_env, include_dashboard=False, ignore_reinit_error=True)
    else:
        ray.init(address=address, runtime_env=runtime_env, ignore_reinit_error=True)
    try:
        task = ray.remote(num_cpus=cpus_per_task)(_ray_task)
        refs = [task.remote(c, device, str(ROOT)) for c in configs]
        from tqdm import tqdm

        pending = list(refs)
        with tqdm(total=len(refs), desc="sweep (ray)", unit="config", disable=not progress) as bar:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                bar.update(len(done))
        return ray.get(refs)
    finally:
        ray.shutdown()


def _ray_task(config: dict, device: str, root: str) -> dict:
    if root not in sys.path and Path(root).is_dir():
        sys.path.insert(0, root)
    return run_config(config, device)


# Output ----------------------------------------------------------------------------------------

def chart(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r.get("status") == "ok"]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    groups = dict.fromkeys((r["integrator"], r["solver"], r["broad_phase"], r["body_contact"]) for r in ok)
    for g in groups:
        sel = [r for r in ok if (r["integrator"], r["solver"], r["broad_phase"], r["body_contact"]) == g]
        ax.scatter([r["body_steps_per_s"] for r in sel], [max(r["max_penetration_m"], 1e-7) for r in sel],
                   label=f"{g[0]} / {g[1]} / {g[2] if g[3] else 'terrain only'}", s=24)
        for r in sel:
            ax.annotate(f"N={r['bodies']} dt=1/{round(1 / r['dt'])}x{r['substeps']}",
                        (r["body_steps_per_s"], max(r["max_penetration_m"], 1e-7)), fontsize=5)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("body-steps / s")
    ax.set_ylabel("max penetration [m]")
    ax.grid(True, which="both", alpha=0.3)
    if groups:
        ax.legend(fontsize=7)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--counts", type=int, nargs="+", default=[1000, 4000])
    p.add_argument("--shapes", nargs="+", default=["mix"], choices=["sphere", "box", "mix"])
    p.add_argument("--contact", nargs="+", default=["on"], choices=["on", "off"])
    p.add_argument("--integrators", nargs="+", default=["semi_implicit", "verlet"],
                   choices=["explicit_euler", "semi_implicit", "verlet", "rk4"])
    p.add_argument("--solvers", nargs="+", default=["soft_step"], choices=["soft_step", "pushout"])
    p.add_argument("--broad-phases", nargs="+", default=["grid"],
                   choices=["grid", "grid_sorted", "grid_hash", "bounding_sphere", "all_pairs"])
    p.add_argument("--dts", nargs="+", default=["1/60", "1/120"], help="steps, e.g. 1/60 0.004")
    p.add_argument("--substeps", type=int, nargs="+", default=[4])
    p.add_argument("--settle", type=float, default=0.5, help="simulated seconds before timing")
    p.add_argument("--steps", type=int, default=30, help="timed steps per configuration")
    p.add_argument("--jobs", type=int, default=1, help="local worker processes")
    p.add_argument("--ray-address", default=None, help="run on Ray: 'local' or a cluster address")
    p.add_argument("--ray-cpus", type=float, default=1.0, help="CPUs per Ray task")
    p.add_argument("--ray-working-dir", default=None, help="ship this directory to the Ray workers")
    p.add_argument("--device", default="cpu")
    p.add_argument("--out-dir", type=Path, default=ROOT / "bench" / "results")
    p.add_argument("--name", default="sweep")
    p.add_argument("--no-chart", action="store_true")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)

    import warp as wp

    from bench.common import machine_info
    from bench.scaling import write_table

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    configs = configurations(args.counts, args.shapes, [m == "on" for m in dict.fromkeys(args.contact)],
                             args.integrators, args.solvers, args.broad_phases, [parse_dt(d) for d in args.dts],
                             args.substeps, args.settle, args.steps)
    meta = machine_info(args.device)
    progress = not args.no_progress
    start = time.perf_counter()
    if args.ray_address:
        meta["runner"] = f"ray ({args.ray_address})"
        rows = run_ray(configs, args.ray_address, args.device, args.ray_cpus, args.ray_working_dir, progress)
    else:
        meta["runner"] = f"local, {args.jobs} job(s)"
        rows = run_local(configs, args.jobs, args.device, progress)
    meta["sweep_wall_s"] = round(time.perf_counter() - start, 2)
    csv_path, _ = write_table(args.out_dir, args.name, rows, meta)
    if not args.no_chart:
        chart(rows, args.out_dir / f"{args.name}.png", f"sweep, {meta['runner']} ({meta['cpu'][:40]})")
    print(f"wrote {csv_path} (+ .json{'' if args.no_chart else ', .png'}): {len(rows)} configurations "
          f"in {meta['sweep_wall_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
