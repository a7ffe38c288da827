"""The same scenes on the engines users would pick instead: MuJoCo, PyBullet, Newton.

    pip install -e ".[peers]"                  # mujoco, pybullet, newton (optional extras)
    python bench/peers.py                      # 1k and 4k spheres, 1k boxes, the analytic scenes
    python bench/peers.py --contact on off     # the committed results: also terrain contact only
    python bench/peers.py --engines warp_sim mujoco --counts 1000 --scenes rain bounce
    python bench/peers.py --quick              # tiny sizes, a smoke run (to a temporary folder)

An engine that is not installed is skipped with a line saying so; the core package never
imports any of them.

Scenes (identical across engines; built in warp_sim's y-up frame and rotated into the peers'
z-up frame by (x, y, z) -> (x, -z, y), a proper rotation, and back for every measurement):

* ``rain``: ``warp_sim.cases.terrain_drop(N, shape)``, N spheres (r = 0.25 m) or cubes (half
  0.25 m), 1 kg, on a 1.2 m grid 0.5 m above the Fourier terrain; friction 0.6, restitution 0,
  rolling resistance (spheres) 0.1 x r = 0.025 m as a torque/normal-force ratio, which is what
  MuJoCo's and Bullet's rolling/torsional friction coefficients mean.  The peers get the terrain
  as a heightfield sampled from ``FourierTerrain.height`` every <= ``--hfield-spacing`` m over
  the drop area plus ``--hfield-margin`` m (their only way to represent it); warp_sim collides
  with the analytic surface.  ``--contact on`` (default) lets bodies collide with each other in
  every engine, ``off`` filters body-body pairs out (MuJoCo contype/conaffinity, Bullet
  collision masks, Newton negative collision groups).  Simulated ``--settle`` s, then
  ``--steps`` steps are timed (the stepping calls only).
* ``stack``: 10 unit cubes (1 kg, mu 0.6) on a plane; top-box drift between t = 1 s and 5 s.
* ``bounce``: a sphere (r = 0.1 m, mu 0) dropped from 1 m onto a plane with restitution 0.5;
  first rebound apex / drop height, exact e^2 = 0.25.
* ``roll``: a sphere (r = 0.25 m, mu 0.5) released on a 20 degree plane; acceleration along the
  slope from the displacement after 1 s, exact 5/7 g sin(20 deg) = 2.397 m/s^2.
* ``slide``: a cube (half 0.25 m, mu 0.3) released on a 30 degree plane, exact
  g (sin 30 - 0.3 cos 30) = 2.356 m/s^2.

Every engine runs at dt = 1/240 s, one step per 1/240 s (warp_sim with 1 substep), with its
recommended settings otherwise:

* warp_sim: soft-step solver (4 iterations + 2 relax), semi-implicit Euler, grid broad phase,
  sleeping off (as in every benchmark scene), CPU launches split over all cores.  A second row,
  ``warp_sim-1t``, runs with WARP_SIM_CPU_THREADS=1 for a per-core comparison (the peers run
  one thread).
* MuJoCo: ``implicitfast`` integrator (the documented recommendation), default Newton solver,
  pyramidal cone, default solref/solimp, ``mj_step(nstep=k)``; condim 6 (rolling and torsional
  friction) for spheres with rolling resistance, else condim 3 (1 for frictionless).  MuJoCo has
  no restitution coefficient: the bounce uses solref = (0.02, zeta) with the damping ratio of a
  linear spring-damper whose coefficient of restitution is e, e = exp(-pi zeta / sqrt(1 -
  zeta^2)), i.e. zeta = -ln e / sqrt(pi^2 + ln^2 e) = 0.2155 for e = 0.5 (an approximation:
  MuJoCo's impedance solimp makes the contact only roughly a linear spring).
* PyBullet: defaults (sequential impulse, 50 iterations, ERP/split impulse as shipped, sleeping
  as shipped) and ``setTimeStep(1/240)``; Bullet multiplies the two bodies' friction and
  restitution, so the ground gets 1.0 and each body the scene's value, and combines rolling and
  spinning friction as r_a mu_b + r_b mu_a, so the ground gets 0 (body-body contacts in the rain
  therefore see friction 0.36 and rolling friction 1.2 r: Bullet's rules, not ours).
* Newton: ``SolverXPBD`` with its defaults (2 iterations), the default ``CollisionPipeline``
  run once per step, ``enable_restitution`` only in the bounce; material values on both shapes
  (Newton averages them); density chosen so every body weighs 1 kg.  Warp CPU launches run on one
  thread and Newton targets CUDA, so its CPU figure is not its best case.

Accuracy is measured the same way for every engine, warp_sim included: the bodies' positions
and orientations (read back from the engine and rotated into warp_sim's frame) are loaded into
a warp_sim model of the same bodies with terrain contact only, and its exact closest-point query
(spheres) / checkpoints (boxes, 26 per cube) gives the deepest penetration into the *analytic*
terrain (``max_penetration_m``: the maximum over frames sampled through the timed window).
A heightfield's own deviation from the analytic surface therefore shows up as penetration; the
``hfield_error_m`` column gives that deviation (ray casts against the engine's heightfield at
2,000 random points; blank where the engine has no ray query we use).  Bodies that left the
heightfield's area are not probed and are counted in ``off_field``.  ``ke_end_j`` is the total
kinetic energy at the end of the run, ``sim_time_s`` after the drop: on this terrain many balls
are still rolling down long slopes then, so it compares how fast each engine dissipates the
fall, not a residual jitter at rest (the analytic scenes' ``ke_end_j`` is that, for the stack).

Writes ``<out-dir>/peers.{csv,json,png}``; each row has ``speed_vs_warp_sim`` (engine steps/s
over warp_sim's, same scene) and ``penetration_vs_warp_sim``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import machine_info, output_dir  # noqa: E402
from bench.scaling import write_table  # noqa: E402
from warp_sim import cases  # noqa: E402

from bench.peer_engines import (  # noqa: E402
    DT,
    ENGINES,
    Engine,
    RESTITUTION,
    SCENES,
    Spec,
    available,
    bounce_spec,
    make_engine,
    matrix_quats,
    quat_matrices,
    rain_spec,
    roll_spec,
    slide_spec,
    stack_spec,
)


def probe_depth(spec: Spec, pos, rot, field_half: float) -> tuple[float, int]:
    """Deepest penetration into the analytic ground of the bodies inside the field, and how many
    bodies are outside it (off a heightfield's edge)."""
    probe = spec.probe()
    inside = (np.abs(pos[:, 0]) < field_half - spec.size) & (np.abs(pos[:, 2]) < field_half - spec.size)
    p = np.where(inside[:, None], pos, spec.pos)  # bodies off the field are probed at their start point
    r = np.where(inside[:, None, None], rot, quat_matrices(spec.quat))
    probe.state.body_pos.assign(p.astype(np.float32))
    probe.state.body_rot.assign(r.astype(np.float32))
    probe.state.body_quat.assign(matrix_quats(r).astype(np.float32))
    probe.state.body_vel.zero_()
    probe.contacts.terrain_contact_active.zero_()
    return probe.max_penetration(), int(np.count_nonzero(~inside))


def kinetic_energy(spec: Spec, rot, vel, omega) -> float:
    w_body = np.einsum("nji,nj->ni", rot, omega)
    return float(0.5 * (spec.mass * np.einsum("ni,ni->n", vel, vel)).sum()
                 + 0.5 * np.einsum("ni,ni,ni->", spec.inertia, w_body, w_body))


def timed(engine: Engine, k: int) -> float:
    start = time.perf_counter()
    engine.step(k)
    return time.perf_counter() - start


def run_rain(engine: Engine, spec: Spec, case_budget: float) -> dict:
    engine.step(1)  # compile / warm-up, not timed
    probe_steps = 3
    estimate = timed(engine, probe_steps) / probe_steps * (spec.settle_steps + spec.steps)
    if estimate > case_budget:
        return {"status": f"skipped: projected {estimate:.0f} s > --case-budget {case_budget:.0f} s"}
    engine.step(max(spec.settle_steps - 1 - probe_steps, 0))
    wall, done, deepest, off_field = 0.0, 0, 0.0, 0
    while done < spec.steps:
        k = min(spec.sample_every, spec.steps - done)
        wall += timed(engine, k)
        done += k
        pos, rot, vel, omega = engine.read()
        depth, off = probe_depth(spec, pos, rot, engine.field_half)
        deepest, off_field = max(deepest, depth), max(off_field, off)
    pos, rot, vel, omega = engine.read()
    final_depth, _ = probe_depth(spec, pos, rot, engine.field_half)
    finite = all(np.isfinite(a).all() for a in (pos, rot, vel, omega))
    return {
        "steps": spec.steps,
        "wall_s": round(wall, 4),
        "steps_per_s": round(spec.steps / wall, 3),
        "body_steps_per_s": round(spec.count * spec.steps / wall),
        "max_penetration_m": round(deepest, 6),
        "final_penetration_m": round(final_depth, 6),
        "ke_end_j": round(kinetic_energy(spec, rot, vel, omega), 6),
        "sim_time_s": round((spec.settle_steps + spec.steps) * DT, 4),
        "contacts": engine.contact_count(),
        "off_field": off_field,
        "status": "ok" if finite else "non-finite state",
    }


def run_analytic(engine: Engine, spec: Spec) -> dict:
    pos0, _, _, _ = engine.read()
    engine.step(1)  # warm-up step (kernel compile for Warp engines) counts as simulated time
    wall, done = 0.0, 1
    trace = [(DT, engine.read()[0])]
    stride = 1 if spec.scene == "bounce" else max(1, spec.steps // 20)
    while done < spec.steps:
        k = min(stride, spec.steps - done)
        wall += timed(engine, k)
        done += k
        trace.append((done * DT, engine.read()[0]))
    pos, rot, vel, omega = engine.read()
    depth, _ = probe_depth(spec, pos, rot, math.inf)
    row = {"steps": spec.steps, "wall_s": round(wall, 4),
           "steps_per_s": round((spec.steps - 1) / wall, 3) if wall > 0 else "",
           "body_steps_per_s": round(spec.count * (spec.steps - 1) / wall) if wall > 0 else "",
           "final_penetration_m": round(depth, 6), "ke_end_j": round(kinetic_energy(spec, rot, vel, omega), 6)}
    times = np.array([t for t, _ in trace])
    positions = np.array([p for _, p in trace])
    if spec.scene == "stack":
        top0 = pos0[-1]
        settled = positions[np.argmin(np.abs(times - 1.0)), -1]
        row.update({"metric": "top drift 1-5 s [m]", "value": round(float(np.linalg.norm(pos[-1] - settled)), 6),
                    "exact": 0.0, "sag_m": round(float(top0[1] - settled[1]), 6),
                    "standing": bool(pos[-1, 1] > top0[1] - 0.5 and abs(pos[-1, 0] - top0[0]) < 0.5)})
        row["error"] = row["value"]
    elif spec.scene == "bounce":
        low = positions[:, 0, 1] - spec.size[0]
        drop = float(pos0[0, 1] - spec.size[0])
        j = int(np.argmax(low < 0.02))  # first frame within 2 cm of the floor, then down to the turning point
        while j + 1 < len(low) and low[j + 1] <= low[j]:
            j += 1
        apex = float(low[j:].max()) if j + 1 < len(low) else 0.0  # later apices are lower: the max is the first
        exact = RESTITUTION ** 2
        row.update({"metric": "apex ratio", "value": round(apex / drop, 5), "exact": exact,
                    "error": round(abs(apex / drop - exact) / exact, 5)})
    else:
        angle = 20.0 if spec.scene == "roll" else 30.0
        down, _ = cases.slope_frame(angle)
        s = float((pos[0] - pos0[0]) @ down)
        t = done * DT
        accel = 2.0 * s / (t * t)
        exact = cases.rolling_acceleration(angle) if spec.scene == "roll" else cases.sliding_acceleration(angle, 0.3)
        row.update({"metric": "acceleration [m/s^2]", "value": round(accel, 5), "exact": round(exact, 5),
                    "error": round(abs(accel - exact) / exact, 5)})
    row["status"] = "ok" if np.isfinite(positions).all() else "non-finite state"
    return row


# Driver ----------------------------------------------------------------------------------------

def build_specs(args) -> list[Spec]:
    specs = []
    if "rain" in args.scenes:
        for count in args.counts:
            for shape in args.shapes:
                if shape == "box" and count > args.box_max:
                    continue
                for mode in args.contact:
                    specs.append(rain_spec(count, shape, mode == "on", args.settle, args.steps, args.samples))
    makers = {"stack": stack_spec, "bounce": bounce_spec, "roll": roll_spec, "slide": slide_spec}
    specs += [makers[s]() for s in args.scenes if s in makers]
    return specs


def add_ratios(rows: list[dict]):
    ours = {r["case"]: r for r in rows if r["engine"] == "warp_sim" and r["status"] == "ok"}
    for r in rows:
        ref = ours.get(r["case"])
        ok = ref is not None and r["status"] == "ok"
        try:
            r["speed_vs_warp_sim"] = round(float(r["steps_per_s"]) / float(ref["steps_per_s"]), 4) if ok else ""
        except (TypeError, ValueError, ZeroDivisionError):
            r["speed_vs_warp_sim"] = ""
        key = "max_penetration_m" if r.get("scene") == "rain" else "final_penetration_m"
        try:
            ratio = float(r[key]) / float(ref[key]) if ok and float(ref[key]) > 0 else ""
            r["penetration_vs_warp_sim"] = round(ratio, 3) if ratio != "" else ""
        except (TypeError, ValueError, KeyError):
            r["penetration_vs_warp_sim"] = ""


def chart(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    engines = list(dict.fromkeys(r["engine"] for r in rows))
    colours = dict(zip(ENGINES, ["#2a9d8f", "#8ab17d", "#e76f51", "#f4a261", "#6a4c93"]))
    rain = [r for r in rows if r["scene"] == "rain"]
    analytic = [r for r in rows if r["scene"] != "rain"]
    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    for ax, key, ylabel in ((axes[0], "steps_per_s", "steps / s (dt 1/240 s)"),
                            (axes[1], "max_penetration_m", "max penetration into the analytic terrain [m]")):
        cases_ = list(dict.fromkeys(r["case"] for r in rain))
        width = 0.8 / max(len(engines), 1)
        for k, eng in enumerate(engines):
            xs, ys = [], []
            for j, c in enumerate(cases_):
                r = next((r for r in rain if r["case"] == c and r["engine"] == eng and r["status"] == "ok"), None)
                if r is not None and r.get(key) not in ("", None):
                    xs.append(j + (k - (len(engines) - 1) / 2) * width)
                    ys.append(max(float(r[key]), 1e-6))
            ax.bar(xs, ys, width, label=eng, color=colours.get(eng))
        ax.set_yscale("log")
        ax.set_xticks(range(len(cases_)), [c.removeprefix("rain ").replace(" (", "\n(") for c in cases_],
                      fontsize=7, rotation=30)
        ax.set_ylabel(ylabel)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    axes[0].set_title("rain on the Fourier terrain: speed")
    axes[1].set_title("rain: deepest penetration (sampled frames)")
    axes[0].legend(fontsize=8)
    ax = axes[2]
    scenes = list(dict.fromkeys(r["scene"] for r in analytic))
    width = 0.8 / max(len(engines), 1)
    for k, eng in enumerate(engines):
        xs, ys = [], []
        for j, sc in enumerate(scenes):
            r = next((r for r in analytic if r["scene"] == sc and r["engine"] == eng and r["status"] == "ok"), None)
            if r is not None and r.get("error") not in ("", None):
                xs.append(j + (k - (len(engines) - 1) / 2) * width)
                ys.append(max(float(r["error"]), 1e-6))
        ax.bar(xs, ys, width, label=eng, color=colours.get(eng))
    ax.set_yscale("log")
    ax.set_xticks(range(len(scenes)), [{"stack": "stack\ntop drift [m]", "bounce": "bounce\napex rel. err",
                                        "roll": "roll\naccel rel. err", "slide": "slide\naccel rel. err"}.get(s, s)
                                       for s in scenes], fontsize=8)
    ax.set_title("analytic scenes: error (lower is better; 0 drawn at 1e-6)")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _dist_version(dist: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return "?"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--engines", nargs="+", default=list(ENGINES), choices=ENGINES)
    p.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES)
    p.add_argument("--counts", type=int, nargs="+", default=[1000, 4000])
    p.add_argument("--shapes", nargs="+", default=["sphere", "box"], choices=["sphere", "box"])
    p.add_argument("--box-max", type=int, default=1000, help="largest box count (box terrain contact is costly)")
    p.add_argument("--contact", nargs="+", default=["on"], choices=["on", "off"],
                   help="body-body contact in the rain scene")
    p.add_argument("--settle", type=float, default=2.0, help="simulated seconds before timing (rain)")
    p.add_argument("--steps", type=int, default=100, help="timed steps (rain)")
    p.add_argument("--samples", type=int, default=4, help="frames probed for penetration in the timed window")
    p.add_argument("--hfield-spacing", type=float, default=0.25)
    p.add_argument("--hfield-margin", type=float, default=6.0)
    p.add_argument("--case-budget", type=float, default=400.0,
                   help="skip (and say so) a rain case whose projected wall time is longer [s]")
    p.add_argument("--quick", action="store_true", help="N = 64 spheres, short runs")
    p.add_argument("--out-dir", type=Path, default=None, help="default bench/results; --quick: a temporary folder")
    p.add_argument("--name", default="peers")
    p.add_argument("--no-chart", action="store_true")
    args = p.parse_args(argv)
    args.out_dir = output_dir(args.out_dir, args.quick, "peers")
    if args.quick:
        args.counts, args.shapes, args.settle, args.steps, args.samples = [64], ["sphere"], 0.1, 10, 2
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    meta = machine_info("cpu")
    engines = []
    for name in args.engines:
        why = available(name)
        if why:
            print(f"{name}: skipped, {why}")
            meta[f"{name}_status"] = why
        else:
            engines.append(name)
    versions = {}
    for name in engines:
        if name.startswith("warp_sim"):
            versions[name] = f"warp_sim {_dist_version('warp-sim')}, warp {wp.__version__}"
        elif name == "pybullet":
            versions[name] = f"pybullet {_dist_version('pybullet')} (API {sys.modules['pybullet'].getAPIVersion()})"
        else:
            versions[name] = _dist_version(name)
    meta["engine_versions"] = versions
    meta.update({"dt": DT, "hfield_spacing": args.hfield_spacing, "hfield_margin": args.hfield_margin,
                 "settle_s": args.settle})
    from tqdm import tqdm

    specs = build_specs(args)
    rows = []
    bar = tqdm([(s, e) for s in specs for e in engines], desc="peers", unit="run")
    for spec, name in bar:
        bar.set_postfix_str(f"{spec.label} / {name}")
        row = {"case": spec.label, "scene": spec.scene, "engine": name, "bodies": spec.count,
               "shape": "/".join(sorted(set(spec.shape))), "body_contact": spec.body_contact}
        try:
            engine = make_engine(name, spec, args.hfield_spacing, args.hfield_margin)
            row["settings"] = engine.settings
            try:
                result = run_rain(engine, spec, args.case_budget) if spec.scene == "rain" else run_analytic(engine, spec)
            finally:
                engine.close()
            row.update(result)
            row["hfield_error_m"] = "" if engine.hfield_error is None else round(engine.hfield_error, 6)
        except Exception as exc:  # one engine failing a scene is a result, not a crash
            row["status"] = f"error: {type(exc).__name__}: {exc}"[:300]
        rows.append(row)
        tqdm.write(f"{spec.label:34s} {name:12s} {row.get('steps_per_s', '-')!s:>9} steps/s  "
                   f"pen {row.get('max_penetration_m', row.get('final_penetration_m', '-'))!s:>9}  "
                   f"{row.get('metric', '')} {row.get('value', '')}  [{row.get('status')}]")
    add_ratios(rows)
    fields = ["case", "scene", "engine", "bodies", "shape", "body_contact", "steps", "wall_s", "steps_per_s",
              "body_steps_per_s", "speed_vs_warp_sim", "max_penetration_m", "final_penetration_m",
              "penetration_vs_warp_sim", "hfield_error_m", "ke_end_j", "sim_time_s", "contacts", "off_field", "metric", "value",
              "exact", "error", "sag_m", "standing", "status", "settings"]
    rows = [{k: r.get(k, "") for k in fields} for r in rows]
    csv_path, _ = write_table(args.out_dir, args.name, rows, meta)
    if not args.no_chart:
        chart(rows, args.out_dir / f"{args.name}.png", f"peers on {meta['cpu'][:40]} ({meta['cores']} cores), dt 1/240 s")
    print(f"wrote {csv_path} (+ .json{'' if args.no_chart else ', .png'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
