"""Speed and accuracy of two (or more) revisions of this repository, timed back to back.

    python bench/versions.py                                   # 96114bb against the working tree
    python bench/versions.py --revs 96114bb HEAD --repeats 3 --count 10000

Speed figures taken months apart on shared machines do not compare (this host's own runs swing
by 20 %), so a speed goal such as "within 10 % of the figure when the issue was filed" is judged
here: each revision is unpacked from git (``git archive``, the working tree for ``WORKTREE``), and
the same rain as ``bench/rain.py`` (``cases.terrain_drop(N, "mix", body_contact=True)``, dt 1/60
with 4 substeps, grid broad phase, contacts once per step, slab schedule, sleeping off) runs in a
fresh process per run, revisions alternating, ``--repeats`` times.  Each run reports the deepest
body penetration probed every 0.1 s while the rain lands (``--settle`` s) and steps/s over the
next ``--steps`` steps, so speed is always charted against the accuracy it bought.

``--scene sphere`` or ``box`` times that shape on the terrain alone instead (bench/terrain_drop.py's
scene: dt 1/240 s, one substep, the fused per-body step), where the stage split shows the
terrain collision against ``solve_and_integrate``.

A revision also runs its named variants (``VARIANTS``: SimConfig fields) when its SimConfig has
those fields; an older revision without them runs its defaults only.  Writes
``bench/results/versions.{csv,json,png}`` (or ``--out-dir``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import RESULTS, finish_report, machine_info, run_child, write_rows  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
WORKTREE = "WORKTREE"

# the default, and what a user may turn off for speed: the mid-step passes (README: contacts found
# once per step; the refresh of turned pairs and the re-collision of outrun bodies) and the relax
# passes that give a push-out speed back in full (relax_passes 1 is Box2D's single relax); and the
# default before the passes' convergence test followed gravity
VARIANTS = {
    "defaults": {},
    # the relax's former convergence test, a fixed 1e-5 m/s (solvers/soft_step.py: sweep_tolerance)
    "fixed tolerance (share 0)": {"convergence_gravity_share": 0.0},
    "no mid-step passes": {"turn_refresh": 0.0, "recollide_outrun": False},
    "fast: that and relax_passes 1": {"turn_refresh": 0.0, "recollide_outrun": False, "relax_passes": 1},
    # the impact stage run on this inelastic rain too (SimConfig.impacts), the accurate choice
    "impacts always": {"impacts": "always"},
    # friction at the manifold's points (the corners) instead of the patch's arms (collide/contact_patch.py)
    "face friction at points": {"face_friction": "points"},
    # boxes tested at their checkpoints alone, blind to crests between them (collide/face_search.py)
    "checkpoints only": {"face_search": False},
    # every support-face checkpoint in reach holds a row, also where the corners bound it (collide/bounded_points.py)
    "every face point": {"prune_face_points": False},
    # every body's terrain contacts searched every pass, still ones too (collide/still_contacts.py)
    "search every pass": {"still_contacts": False},
    # one solve sweep a substep instead of two (Box2D v3's count; its accuracy: audit.py --set iterations=1)
    "iterations 1": {"iterations": 1},
    "iterations 1, relax_passes 1": {"iterations": 1, "relax_passes": 1},
}

# Per-stage split.  This host's speed swings by up to 2x over minutes (other tenants), so one
# profiled run says little about where a difference comes from; each run therefore also records
# its own ms a step per stage (solve sweeps, relax sweeps, each other kernel by name, timed around
# warp_sim.launch) and its process CPU time, and the table gives medians over the repeats.
STAGES = ("solve sweeps", "relax sweeps", "collide_terrain", "solve_and_integrate")
SCENES = {"rain": "mixed bodies raining", "sphere": "spheres on the terrain alone", "box": "boxes on the terrain alone"}

# runs in the child process, with the revision's tree first on sys.path
CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import warp as wp
wp.config.quiet = True
wp.config.log_level = wp.LOG_WARNING
from warp_sim import SimConfig, cases
count, settle, steps = int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
config = json.loads(sys.argv[5])
scene = sys.argv[6]
known = set(SimConfig.__dataclass_fields__)
if not set(config) <= known:
    print(json.dumps({"status": "variant not in this revision"}))
    raise SystemExit
# every launch through warp_sim.launch is timed (STAGES above says why; Simulator.profile's stages
# would not do: its "solve" holds the solve and the relax sweeps together)
import importlib, pkgutil
import warp_sim
import warp_sim.launch as launching
from warp_sim.solvers import pair_solve
MODE_SOLVE = pair_solve.MODE_SOLVE
relax_modes = {pair_solve.MODE_RELAX, getattr(pair_solve, "MODE_RELAX_CLOSED", pair_solve.MODE_RELAX)}
stage_s, timing = {}, [False]
plain_launch = launching.launch
def timed_launch(kernel, dim, inputs, device, *args, **kwargs):
    if not timing[0]:
        return plain_launch(kernel, dim, inputs, device, *args, **kwargs)
    t0 = time.perf_counter()
    plain_launch(kernel, dim, inputs, device, *args, **kwargs)
    name = kernel.key
    mode = None
    if name == "domain_sweep":  # arguments (tid_offset,) first_domain, domain_count, mode, ...
        mode = inputs[2]
    elif name.startswith("domain_sweep_"):  # one kernel per mode since the modes were specialised
        mode = {"solve": MODE_SOLVE, "relax": pair_solve.MODE_RELAX,
                "relax_closed": pair_solve.MODE_RELAX}.get(name[len("domain_sweep_"):], -1)
    if mode is not None:
        name = "solve sweeps" if mode == MODE_SOLVE else "relax sweeps" if mode in relax_modes else "other sweeps"
    stage_s[name] = stage_s.get(name, 0.0) + time.perf_counter() - t0
for info in pkgutil.walk_packages(warp_sim.__path__, "warp_sim."):
    if info.name.endswith("__main__"):
        continue
    try:
        module = importlib.import_module(info.name)
    except Exception:
        continue
    if getattr(module, "launch", None) is plain_launch:
        module.launch = timed_launch
if scene == "rain":
    sim = cases.terrain_drop(count, "mix", body_contact=True, broad_phase="grid", spacing=0.9, sleep=False,
                             rolling_resistance=0.2, contact_update="step", pair_schedule="domains", **config)
else:  # bench/terrain_drop.py's scene: one shape on the terrain alone, dt 1/240 s, 1 substep
    sim = cases.terrain_drop(count, scene, dt=1.0 / 240.0, substeps=1, **config)
sim.step(1)
peak = 0.0
probe_steps = int(round(0.1 / sim.config.dt))
for _ in range(int(round(settle * 10))):
    sim.step(probe_steps, check=False)
    peak = max(peak, sim.max_penetration())
timing[0] = True
cpu_start = time.process_time()
start = time.perf_counter()
sim.step(steps, check=False)
wall = time.perf_counter() - start
cpu = time.process_time() - cpu_start
sim.check_finite()
stage_ms = {k: 1000.0 * v / steps for k, v in stage_s.items()}
print(json.dumps({"status": "ok", "steps_per_s": steps / wall, "peak_penetration_m": peak,
                  "substeps": getattr(sim, "substeps", 4), "cpu_ms_per_step": 1000.0 * cpu / steps,
                  "stage_ms": stage_ms}))
"""


def stage_columns(stage_ms: dict, steps_per_s: float) -> dict:
    """ms a step of the STAGES, and of everything else (wall time less those)."""
    columns = {f"{name.replace(' ', '_')}_ms": round(stage_ms.get(name, 0.0), 2) for name in STAGES}
    if steps_per_s > 0:
        columns["rest_ms"] = round(1000.0 / steps_per_s - sum(stage_ms.get(name, 0.0) for name in STAGES), 2)
    return columns


def summary(rows: list[dict]) -> list[str]:
    """One line per revision and variant: medians over the repeats (steps/s, CPU ms a step, stages)."""
    import statistics

    lines = []
    keys = list(dict.fromkeys((r["rev"], r["variant"]) for r in rows if r["status"] == "ok"))
    for rev, variant in keys:
        ok = [r for r in rows if (r["rev"], r["variant"]) == (rev, variant) and r["status"] == "ok"]

        def median(field):
            return statistics.median(float(r.get(field, 0.0) or 0.0) for r in ok)

        stages = "  ".join(f"{name} {median(name.replace(' ', '_') + '_ms'):.1f}" for name in STAGES)
        lines.append(f"{rev:>10s} {variant:30s} {median('steps_per_s'):6.2f} steps/s  cpu {median('cpu_ms_per_step'):6.1f}"
                     f" ms/step  |  ms a step: {stages}  rest {median('rest_ms'):.1f}")
    return lines


def unpack(rev: str, into: Path) -> Path:
    """The tree of ``rev`` under ``into`` (the working tree itself for WORKTREE)."""
    if rev == WORKTREE:
        return ROOT
    data = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", rev], check=True,
                          capture_output=True).stdout
    target = into / rev.replace("/", "_")
    target.mkdir(parents=True)
    with tarfile.open(fileobj=BytesIO(data)) as tar:
        tar.extractall(target, filter="data")
    return target


def run_once(tree: Path, count: int, settle: float, steps: int, config: dict, scene: str = "rain") -> dict:
    return run_child([sys.executable, "-c", CHILD, str(tree), str(count), str(settle), str(steps), json.dumps(config),
                      scene])


def chart(rows: list[dict], path: Path, title: str, stepping: str = "dt 1/60, 4 substeps"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    palette = plt.get_cmap("tab10").colors
    keys = list(dict.fromkeys((r["rev"], r["variant"]) for r in rows if r["status"] == "ok"))
    for k, (rev, variant) in enumerate(keys):
        ok = [r for r in rows if (r["rev"], r["variant"]) == (rev, variant) and r["status"] == "ok"]
        speeds = [r["steps_per_s"] for r in ok]
        depths = [1000 * r["peak_penetration_m"] for r in ok]
        ax.scatter(speeds, depths, color=palette[k % len(palette)], label=f"{rev}: {variant}", s=28)
        ax.plot([min(speeds), max(speeds)], [sum(depths) / len(depths)] * 2, color=palette[k % len(palette)], lw=1)
    ax.set_xlabel(f"steps / s ({stepping}; each dot one run)")
    ax.set_ylabel("peak penetration while landing [mm]")
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--revs", nargs="+", default=["96114bb", WORKTREE],
                   help=f"git revisions ({WORKTREE}: the working tree as it is)")
    p.add_argument("--count", type=int, default=10000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--settle", type=float, default=1.5, help="simulated seconds while the rain lands")
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    p.add_argument("--scene", default="rain", choices=list(SCENES),
                   help="rain: the mixed rain above; sphere, box: that shape on the terrain alone (bench/terrain_drop.py's "
                        "scene, dt 1/240 s, 1 substep, the fused step), whose --steps should be a few hundred")
    p.add_argument("--out-dir", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if args.count < 1 or args.repeats < 1 or args.steps < 1 or args.settle < 0:
        p.error(f"--count, --repeats and --steps must be >= 1 and --settle >= 0, got {args.count}, "
                f"{args.repeats}, {args.steps}, {args.settle}")
    import warp as wp

    wp.config.quiet = True
    meta = machine_info("cpu")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        trees = {}
        for rev in args.revs:
            try:
                trees[rev] = unpack(rev, Path(tmp))
            except subprocess.CalledProcessError as err:
                p.error(f"--revs: git cannot archive {rev!r}: {err.stderr.decode().strip()}")
        total = args.repeats * len(args.revs) * len(args.variants)
        done = 0
        for repeat in range(args.repeats):
            for rev in args.revs:  # alternating, so a slow spell of the machine hits every revision
                for variant in args.variants:
                    result = run_once(trees[rev], args.count, args.settle, args.steps, VARIANTS[variant], args.scene)
                    done += 1
                    if result["status"] == "variant not in this revision":
                        continue
                    row = {"rev": rev, "variant": variant, "scene": args.scene, "repeat": repeat, "bodies": args.count,
                           "steps_per_s": round(result.get("steps_per_s", 0.0), 3),
                           "peak_penetration_m": round(result.get("peak_penetration_m", 0.0), 6),
                           "substeps": result.get("substeps", ""),
                           "cpu_ms_per_step": round(result.get("cpu_ms_per_step", 0.0), 2),
                           **stage_columns(result.get("stage_ms", {}), result.get("steps_per_s", 0.0)),
                           "status": result["status"]}
                    rows.append(row)
                    print(f"[{done}/{total}] {rev:>10s} {variant:20s} {row['steps_per_s']:7.2f} steps/s  "
                          f"peak {1000 * row['peak_penetration_m']:.1f} mm  [{row['status']}]", flush=True)
    if not rows:
        print("no run produced a row (every variant missing from every revision?)", file=sys.stderr)
        return 1
    csv_path, _ = write_rows("versions", rows, {**meta, "revs": args.revs, "settle_s": args.settle,
                                                "steps": args.steps}, args.out_dir)
    chart(rows, csv_path.with_suffix(".png"),
          f"{args.count} {SCENES[args.scene]}, back to back on {meta['cpu']} ({meta['cores']} cores)",
          "dt 1/60, 4 substeps" if args.scene == "rain" else "dt 1/240, 1 substep")
    return finish_report(summary(rows), csv_path, rows)


if __name__ == "__main__":
    raise SystemExit(main())
