"""Work-precision charts: error against wall-clock cost for every integrator on closed-form cases.

    python bench/work_precision.py                         # all cases, the committed results (~2 min, 2 cores)
    python bench/work_precision.py --cases tumbling --repeats 5
    python bench/work_precision.py --quick --out-dir /tmp/wp   # tiny sizes (the tests use this)
    python bench/work_precision.py --replot                    # redraw the PNGs from the JSON only

Cases (each the builder in ``warp_sim.cases`` the tests use, so a chart and a test measure the
same thing), one line per method, one point per dt:

    projectile   |x(1 s) - projectile_exact| [m]; one substep per step
    tumbling     torque-free box spun near its intermediate axis (it flips), every integrator x every
                 rotation representation, against the float64 ``tumbling_reference``:
                 orientation error max|R - R_ref| at --orient-time (the charted error) and at the
                 end (--tumble-time, 20 s), energy drift max|E/E0 - 1| and |L_body| drift
                 max| |R^T L| / |L| - 1 | over the whole run (sampled every --orient-time)
    rolling      sphere rolling down a 20 deg slope: |a / (5/7 g sin) - 1|, a = v(1 s) . down / 1 s
    sliding      cube sliding down a 30 deg slope, mu 0.3: |a / (g (sin - mu cos)) - 1|, same a
    bounce       ball dropped 1 m, e = 0.8: |apex / (e^2 H) - 1|, apex of the first rebound (vertex
                 of the parabola through the three highest per-step samples, so the once-per-step
                 sampling does not add g dt^2 / 2 of its own)

Cost of a row = the median over --repeats runs of the wall time of the simulated run
(``sim.step`` bracketed by device synchronisation; the first step of each run is run but not
timed, because it compiles and records the launches; reads for the error are made outside the
timed region).  The repeats are round-robin passes over all rows, so a burst of load from other
work on the machine lands on one repeat of many rows, not on every repeat of one.  One body per
scene makes every run launch-bound (a step costs about the same whatever the integrator), so
each row also gives ``steps``, ``us_per_step`` and ``cost_per_sim_s`` = wall seconds per
simulated second, and every chart has a second panel against substeps per simulated second.
For the tumbling box a third cost is estimated where the scene is compute-bound:
``compute_us_per_sim_s`` = the marginal cost of one body-step (t(N boxes) - t(1 box), measured
with --compute-bodies copies of the box) x steps per simulated second, in microseconds per body
per simulated second.

On every chart a grey band marks the cheapest measured point reaching each error (the lower
envelope of all methods), and a table beside the charts names the cheapest method and dt per
decade of error (costs within 10% count as a tie, won by the smaller error).  The tumbling
JSON's ``summary`` holds the equal-cost comparison against explicit Euler (quaternion rotation):
each method's log error is interpolated linearly in log cost, and the ratio
err_euler / err_method is sampled over the cost range both methods cover (no extrapolation);
``beats_euler_10x`` says whether the ratio stays above 10 over that whole range, and
``rk4_or_verlet_beats_explicit_euler_10x`` whether RK4 or Verlet does so at the measured cost.

A row whose run raised NonFiniteStateError or whose final state fails the invalid-state gate
(bench.common.state_gate) keeps its status and is left out of the lines, never charted as a
cheap error.  Writes <out-dir>/work_precision_<case>.{csv,json,png} (default bench/results/).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench import common  # noqa: E402
from bench.common import machine_info, state_gate  # noqa: E402
from warp_sim import ModelBuilder, NonFiniteStateError, NoTerrain, SimConfig, Simulator, cases  # noqa: E402

INTEGRATORS = ["explicit_euler", "semi_implicit", "verlet", "rk4"]
ROTATIONS = ["quaternion", "matrix", "matrix_cross", "matrix_gram_schmidt"]
CASES = ["projectile", "tumbling", "rolling", "sliding", "bounce"]
COLORS = {"explicit_euler": "tab:red", "semi_implicit": "tab:orange", "verlet": "tab:green", "rk4": "tab:blue"}
MARKERS = {"quaternion": "o", "matrix": "x", "matrix_cross": "s", "matrix_gram_schmidt": "^"}
LINESTYLES = {"quaternion": "-", "matrix": ":", "matrix_cross": "--", "matrix_gram_schmidt": "-."}
TUMBLE_OMEGA = (0.3, 0.4, 5.0)
ROLL_ANGLE, SLIDE_ANGLE, SLIDE_MU, BOUNCE_E = 20.0, 30.0, 0.3, 0.8
NOTES = {  # what each simple chart shows, printed under its title
    "projectile": "explicit and symplectic Euler err by -/+ g t h / 2 (same size: lines coincide); "
                  "Verlet and RK4 are exact for constant g, so only float32 round-off is left, growing with the steps",
    "rolling": "the end-of-step velocity carries (1 - alpha) of an unconstrained gravity kick: error = (1 - alpha) "
               "(g sin / a - 1) h; semi_implicit (alpha 1) solves the contact on the velocity it ends with: round-off",
    "sliding": "as rolling: error = (1 - alpha) (g sin / a - 1) h, so semi_implicit is exact to round-off; "
               "Verlet and RK4 (alpha 1/2) coincide at half explicit Euler's error",
    "bounce": "the apex error comes from the contact (restitution on the approach speed, lagging by up to g h), "
              "not from the integrator: every method is first order in h",
}
ERROR_FLOOR = 1e-9  # errors below this (exact to round-off) are charted at the floor

FULL = {"free_dts": [1 / 25, 1 / 50, 1 / 100, 1 / 200, 1 / 400, 1 / 800],
        "contact_dts": [1 / 15, 1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480],
        "tumble_time": 20.0, "repeats": 3, "compute_bodies": 8192}
QUICK = {"free_dts": [1 / 25, 1 / 50], "contact_dts": [1 / 30, 1 / 60],
         "tumble_time": 2.0, "repeats": 1, "compute_bodies": 64}


# Result files ---------------------------------------------------------------------------------

def _plain(value):
    """JSON/CSV-friendly value: NaN and inf become None (an empty CSV cell)."""
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_results(out_dir: Path, name: str, rows: list[dict], meta: dict, extra: dict | None = None):
    """bench.common.write_rows into ``out_dir`` (every row gets every column), plus ``extra`` keys
    in the JSON.  Returns (csv, json) paths."""
    keys = list(dict.fromkeys(k for r in rows for k in r))
    rows = [{k: _plain(r.get(k, "")) for k in keys} for r in rows]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    saved = common.RESULTS
    common.RESULTS = out_dir
    try:
        csv_path, json_path = common.write_rows(name, rows, meta)
    finally:
        common.RESULTS = saved
    if extra:
        data = json.loads(json_path.read_text())
        data.update(json.loads(json.dumps(extra, default=_plain)))
        json_path.write_text(json.dumps(data, indent=2))
    return csv_path, json_path


# Timing ---------------------------------------------------------------------------------------

def timed_run(sim: Simulator, chunks: list[int], repeats: int, probe=None) -> dict:
    """Run ``sum(chunks)`` steps ``repeats`` times from the initial state; time all but the first step.

    ``chunks`` splits the run (the first chunk includes the untimed first step); ``probe(k)`` is
    called after chunk k of the last repeat, outside the timed region.  Returns wall times and
    the failure ('' when finite and through the gate)."""
    walls = []
    for rep in range(repeats):
        sim.reset()
        sim.step(1, check=False)  # compiles kernels / records launches: not timed
        wall = 0.0
        for k, n in enumerate(chunks):
            n = n - 1 if k == 0 else n
            wp.synchronize_device(sim.device)
            start = time.perf_counter()
            if n > 0:
                sim.step(n, check=False)
            wp.synchronize_device(sim.device)
            wall += time.perf_counter() - start
            try:
                sim.check_finite()
            except NonFiniteStateError as exc:
                return {"walls": walls or [wall], "status": f"non-finite at step {exc.step}"}
            if probe is not None and rep == repeats - 1:
                probe(k)
        walls.append(wall)
    return {"walls": walls, "status": state_gate(sim) or "ok"}


def cost_columns(timing: dict, steps: int, dt: float, substeps: int) -> dict:
    timed_time = (steps - 1) * dt
    wall = statistics.median(timing["walls"])
    return {
        "steps": steps,
        "sim_time_s": round(steps * dt, 6),
        "wall_s": round(wall, 6),
        "wall_s_min": round(min(timing["walls"]), 6),
        "wall_s_max": round(max(timing["walls"]), 6),
        "cost_per_sim_s": wall / timed_time,
        "substeps_per_sim_s": round(substeps / dt, 3),
        "us_per_step": round(wall / (steps - 1) * 1e6, 2),
    }


# Cases ----------------------------------------------------------------------------------------
# Each prepare_* builds the simulator once and returns a Prepared run: the driver times every
# run once per pass and makes --repeats passes over all of them (round robin, so a burst of
# load from other work on the machine spreads over many points instead of ruining one), then
# ``finish`` turns the wall times and the last pass's measurements into the row.


class Prepared:
    def __init__(self, sim: Simulator, chunks: list[int], finish, probe=None):
        self.sim, self.chunks, self.finish_fn, self.probe = sim, chunks, finish, probe
        self.walls: list[float] = []
        self.status = "ok"

    def time_once(self, last: bool):
        if self.status != "ok":
            return  # a run that failed is not timed again
        timing = timed_run(self.sim, self.chunks, 1, self.probe if last else None)
        self.walls += timing["walls"]
        self.status = timing["status"]

    def finish(self) -> dict:
        return self.finish_fn({"walls": self.walls, "status": self.status})


def prepare_projectile(integrator: str, dt: float) -> Prepared:
    t_end = 1.0
    steps = int(round(t_end / dt))
    sim = cases.projectile(integrator, dt)

    def finish(timing):
        pos = sim.state.body_pos.numpy()[0].astype(np.float64)
        err = float(np.linalg.norm(pos - cases.projectile_exact(steps * dt)))
        return {"case": "projectile", "method": integrator, "integrator": integrator, "rotation": "quaternion",
                "dt": dt, "substeps": 1, **cost_columns(timing, steps, dt, 1),
                "error": err if timing["status"] == "ok" else None, "error_kind": "|x - x_exact| at 1 s [m]",
                "status": timing["status"]}

    return Prepared(sim, [steps], finish)


@functools.lru_cache(maxsize=8)
def tumbling_reference(t_end: float, every: float):
    """float64 reference rotations at 0, every, 2 every, ..., t_end (cached: ~0.1 s per second)."""
    samples = int(round(t_end / every)) + 1
    return cases.tumbling_reference(TUMBLE_OMEGA, t_end, samples)[1]


def prepare_tumbling(integrator: str, rotation: str, dt: float, t_end: float, every: float) -> Prepared:
    ref = tumbling_reference(t_end, every)
    per_chunk = int(round(every / dt))
    chunk_count = int(round(t_end / every))
    steps = per_chunk * chunk_count
    sim = cases.tumbling_box(integrator, rotation, dt, omega=TUMBLE_OMEGA)
    angmom0 = sim.state.body_angmom.numpy()[0].astype(np.float64)
    e0 = sim.kinetic_energy()
    orient, energy, lbody = [], [], []

    def probe(k):
        rot = sim.state.body_rot.numpy()[0].astype(np.float64)
        orient.append(float(np.abs(rot - ref[k + 1]).max()))
        energy.append(abs(sim.kinetic_energy() / e0 - 1.0))
        lb = np.linalg.norm(rot.T @ sim.state.body_angmom.numpy()[0].astype(np.float64))
        lbody.append(abs(lb / np.linalg.norm(angmom0) - 1.0))

    def finish(timing):
        ok = timing["status"] == "ok" and len(orient) == chunk_count
        return {"case": "tumbling", "method": f"{integrator}/{rotation}", "integrator": integrator,
                "rotation": rotation, "dt": dt, "substeps": 1, **cost_columns(timing, steps, dt, 1),
                "error": orient[0] if ok else None,
                "error_kind": f"max|R - R_ref| at {every:g} s",
                "orient_err_end": orient[-1] if ok else None,
                "energy_drift": max(energy) if ok else None,
                "lbody_drift": max(lbody) if ok else None,
                "status": timing["status"]}

    return Prepared(sim, [per_chunk] * chunk_count, finish, probe)


def tumbling_body_step_cost(integrator: str, rotation: str, bodies: int, repeats: int, steps: int = 20) -> float:
    """Marginal wall time of one body-step [s]: (t(N bodies) - t(1 body)) / ((N - 1) steps)."""
    def make(n):
        b = ModelBuilder()
        b.set_terrain(NoTerrain())
        for i in range(n):
            b.add_box(cases.TUMBLING_HALF_EXTENTS, 1.0, position=(2.0 * i, 0.0, 0.0), angular_velocity=TUMBLE_OMEGA)
        cfg = SimConfig(dt=0.01, substeps=1, integrator=integrator, rotation=rotation, gravity=(0.0, 0.0, 0.0),
                        sleep=False, body_contact=False)
        return Simulator(b.finalize("cpu"), cfg)

    walls = {}
    for n in (1, bodies):
        timing = timed_run(make(n), [steps + 1], max(repeats, 5))
        walls[n] = statistics.median(timing["walls"])
    return max(walls[bodies] - walls[1], 0.0) / ((bodies - 1) * steps)


def slope_acceleration(sim: Simulator, angle: float, t: float) -> float:
    down, _ = cases.slope_frame(angle)
    return float(sim.state.body_vel.numpy()[0].astype(np.float64) @ down / t)


def prepare_slope(case: str, integrator: str, dt: float) -> Prepared:
    steps = int(round(1.0 / dt))
    if case == "rolling":
        sim = cases.rolling_sphere(angle_deg=ROLL_ANGLE, friction=0.5, dt=dt, integrator=integrator)
        angle, exact, kind = ROLL_ANGLE, cases.rolling_acceleration(ROLL_ANGLE), "|a / (5/7 g sin) - 1| at 1 s"
    else:
        sim = cases.sliding_box(angle_deg=SLIDE_ANGLE, friction=SLIDE_MU, dt=dt, integrator=integrator)
        angle, exact = SLIDE_ANGLE, cases.sliding_acceleration(SLIDE_ANGLE, SLIDE_MU)
        kind = "|a / (g (sin - mu cos)) - 1| at 1 s"

    def finish(timing):
        err = abs(slope_acceleration(sim, angle, steps * dt) / exact - 1.0)
        return {"case": case, "method": integrator, "integrator": integrator, "rotation": "quaternion", "dt": dt,
                "substeps": sim.substeps, **cost_columns(timing, steps, dt, sim.substeps),
                "error": err if timing["status"] == "ok" else None, "error_kind": kind, "status": timing["status"]}

    return Prepared(sim, [steps], finish)


def parabola_apex(heights: np.ndarray) -> float:
    """Apex of the first rebound: vertex of the parabola through the highest sample and its neighbours."""
    rise = int(np.argmax(np.diff(heights) > 0))
    k = rise + int(np.argmax(heights[rise:]))
    if k + 1 >= len(heights) or k - 1 < rise:
        return float(heights[k])
    y0, y1, y2 = heights[k - 1], heights[k], heights[k + 1]
    curvature = y0 + y2 - 2.0 * y1
    if curvature >= 0.0:
        return float(y1)
    return float(y1 - (y2 - y0) ** 2 / (8.0 * curvature))


def prepare_bounce(integrator: str, dt: float) -> Prepared:
    drop, radius, t_end = 1.0, 0.1, 1.1  # apex of the first rebound at ~0.81 s, next impact at ~1.17 s
    steps = int(round(t_end / dt))
    sim = cases.bounce(BOUNCE_E, drop_height=drop, radius=radius, dt=dt, integrator=integrator)

    def finish(timing):
        err = None
        if timing["status"] == "ok":
            sim.reset()  # measurement pass (untimed, bit-identical on CPU): the height after every step
            heights = []
            for _ in range(steps):
                sim.step(check=False)
                heights.append(float(sim.state.body_pos.numpy()[0][1]) - radius)
            apex = parabola_apex(np.array(heights, dtype=np.float64))
            err = abs(apex / (BOUNCE_E**2 * drop) - 1.0)
        return {"case": "bounce", "method": integrator, "integrator": integrator, "rotation": "quaternion", "dt": dt,
                "substeps": sim.substeps, **cost_columns(timing, steps, dt, sim.substeps),
                "error": err, "error_kind": f"|apex / (e^2 H) - 1|, e = {BOUNCE_E}", "status": timing["status"]}

    return Prepared(sim, [steps], finish)


# Analysis -------------------------------------------------------------------------------------

def method_curve(rows: list[dict], method: str, cost_key: str, err_key: str = "error"):
    """(log cost, log error) of a method's good rows, sorted by cost."""
    pts = sorted((r[cost_key], max(r[err_key], ERROR_FLOOR)) for r in rows
                 if r["method"] == method and r["status"] == "ok" and r.get(err_key) is not None
                 and r.get(cost_key) not in (None, "") and float(r[cost_key]) > 0.0)  # 0: under the clock's tick
    if not pts:
        return None
    c, e = np.log10(np.array(pts)).T
    return c, e


def equal_cost_ratio(rows: list[dict], method: str, baseline: str, cost_key: str, err_key: str = "error",
                     samples: int = 12) -> dict:
    """err_baseline / err_method at equal cost, log-log interpolated over the common cost range."""
    a, b = method_curve(rows, baseline, cost_key, err_key), method_curve(rows, method, cost_key, err_key)
    if a is None or b is None:
        return {"comparable": False, "reason": "no valid rows"}
    lo, hi = max(a[0].min(), b[0].min()), min(a[0].max(), b[0].max())
    if lo > hi:
        return {"comparable": False, "reason": "cost ranges do not overlap",
                "cost_range_baseline": [10 ** a[0].min(), 10 ** a[0].max()],
                "cost_range_method": [10 ** b[0].min(), 10 ** b[0].max()]}
    grid = np.linspace(lo, hi, samples) if hi > lo else np.array([lo])
    ratio = 10 ** (np.interp(grid, *a) - np.interp(grid, *b))
    return {
        "comparable": True,
        "cost_range": [10**lo, 10**hi],
        "ratio_min": float(ratio.min()),
        "ratio_max": float(ratio.max()),
        "ratio_geomean": float(10 ** np.log10(ratio).mean()),
        "beats_euler_10x": bool(ratio.min() > 10.0),
        "beats_euler_10x_somewhere": bool(ratio.max() > 10.0),
        "samples": [[float(10**g), float(r)] for g, r in zip(grid, ratio)],
    }


def cheapest_per_decade(rows: list[dict], cost_key: str, err_key: str = "error") -> list[dict]:
    """For each decade of error reached, the cheapest measured point with error at or below it
    (points within 10% of the cheapest cost count as ties, won by the smaller error)."""
    good = [r for r in rows if r["status"] == "ok" and r.get(err_key) is not None]
    if not good:
        return []
    errs = [max(r[err_key], ERROR_FLOOR) for r in good]
    top, bottom = math.ceil(math.log10(max(errs))), math.ceil(math.log10(min(errs)))
    out = []
    for d in range(top, bottom - 1, -1):
        target = 10.0**d
        hits = [r for r in good if max(r[err_key], ERROR_FLOOR) <= target]
        if hits:
            cheapest = min(r[cost_key] for r in hits)
            # costs within 10% are a tie on a shared machine: the more accurate point wins it
            best = min((r for r in hits if r[cost_key] <= 1.1 * cheapest), key=lambda r: r[err_key])
            out.append({"error_at_most": target, "method": best["method"], "dt": best["dt"],
                        cost_key: best[cost_key], "error": best[err_key]})
    return out


def pareto_front(rows: list[dict], cost_key: str, err_key: str = "error"):
    pts = sorted((r[cost_key], max(r[err_key], ERROR_FLOOR)) for r in rows
                 if r["status"] == "ok" and r.get(err_key) is not None)
    front, best = [], math.inf
    for c, e in pts:
        if e < best:
            front.append((c, e))
            best = e
    return front


# Charts ---------------------------------------------------------------------------------------

def _dt_label(dt: float) -> str:
    inv = 1.0 / dt
    return f"1/{inv:.0f}" if abs(inv - round(inv)) < 1e-6 else f"{dt:.3g}"


def _panel(ax, rows, cost_key, err_key, xlabel, ylabel, title, label_dts=False):
    from matplotlib.ticker import NullFormatter

    methods = list(dict.fromkeys(r["method"] for r in rows))
    front = pareto_front(rows, cost_key, err_key)
    if len(front) > 1:
        ax.step(*zip(*front), where="post", color="grey", lw=7, alpha=0.25, zorder=0, label="cheapest for an error")
    many_rot = len({r["rotation"] for r in rows}) > 1
    for m in methods:
        mr = sorted((r for r in rows if r["method"] == m and r["status"] == "ok" and r.get(err_key) is not None),
                    key=lambda r: r[cost_key])
        if not mr:
            continue
        integ, rot = mr[0]["integrator"], mr[0]["rotation"]
        ax.loglog([r[cost_key] for r in mr], [max(r[err_key], ERROR_FLOOR) for r in mr],
                  color=COLORS[integ], marker=MARKERS[rot] if many_rot else "o",
                  ls=LINESTYLES[rot] if many_rot else "-", ms=5 if rot == "quaternion" else 4,
                  lw=1.8 if rot == "quaternion" else 0.9, label=m if many_rot else integ)
        if label_dts:
            for r in mr:
                ax.annotate(_dt_label(r["dt"]), (r[cost_key], max(r[err_key], ERROR_FLOOR)), fontsize=6,
                            color=COLORS[integ], xytext=(3, 3), textcoords="offset points")
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        ax.text(0.01, 0.01, f"{len(failed)} failed runs not drawn (see CSV status)", transform=ax.transAxes,
                fontsize=7, color="black", va="bottom")
    if cost_key == "substeps_per_sim_s":  # tick the swept step rates themselves
        ticks = sorted({r[cost_key] for r in rows})
        ax.set_xticks(ticks, [f"{t:g}" for t in ticks], fontsize=8)
        ax.xaxis.set_minor_formatter(NullFormatter())
    else:
        from matplotlib.ticker import FuncFormatter, LogLocator

        ax.xaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))  # 1-2-5 ticks, plainly labelled
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)


def _table(ax, blocks):
    """Text column: per (heading, rows, cost key, error key) the cheapest method per error decade."""
    ax.axis("off")
    lines = []
    for heading, rows, cost_key, err_key in blocks:
        lines.append(heading)
        for t in cheapest_per_decade(rows, cost_key, err_key):
            lines.append(f" <={t['error_at_most']:.0e}: {t['method']:<22s} {_dt_label(t['dt']):>6s}")
        lines.append("")
    ax.text(0.0, 1.0, "\n".join(lines), transform=ax.transAxes, va="top", ha="left", family="monospace",
            fontsize=7.5)


def chart_simple(rows: list[dict], path: Path, title: str, ylabel: str, note: str = ""):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8), gridspec_kw={"width_ratios": [1, 1, 0.4]})
    _panel(axes[0], rows, "cost_per_sim_s", "error", "measured wall time per simulated second [s/s]", ylabel,
           "error vs measured cost (1 body: launch-bound)", label_dts=True)
    _panel(axes[1], rows, "substeps_per_sim_s", "error", "substeps per simulated second", ylabel,
           "error vs steps (the cost where every step costs the same)")
    handles, labels = axes[0].get_legend_handles_labels()
    _table(axes[2], [("cheapest at measured cost\n(error <= x: method, dt)", rows, "cost_per_sim_s", "error")])
    axes[2].legend(handles, labels, fontsize=8, loc="lower left")
    fig.suptitle(title + (f"\n{note}" if note else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def chart_tumbling(rows: list[dict], path: Path, title: str, every: float, t_end: float):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(22, 10), gridspec_kw={"width_ratios": [1, 1, 1, 0.62]})
    x_wall = "measured wall time per simulated second [s/s]"
    _panel(axes[0, 0], rows, "cost_per_sim_s", "error", x_wall, f"max|R - R_ref| at {every:g} s",
           f"orientation error at {every:g} s vs measured cost (1 body)")
    has_compute = any(r.get("compute_us_per_sim_s") not in (None, "") for r in rows)
    if has_compute:
        _panel(axes[0, 1], rows, "compute_us_per_sim_s", "error",
               "compute-bound cost [us per body per simulated s]", f"max|R - R_ref| at {every:g} s",
               "same, cost where the scene is compute-bound (many bodies)")
    else:
        axes[0, 1].axis("off")
    _panel(axes[0, 2], rows, "substeps_per_sim_s", "error", "steps per simulated second",
           f"max|R - R_ref| at {every:g} s", "same, vs steps")
    _panel(axes[1, 0], rows, "cost_per_sim_s", "orient_err_end", x_wall, f"max|R - R_ref| at {t_end:g} s",
           f"orientation error at {t_end:g} s (after the flips)")
    _panel(axes[1, 1], rows, "cost_per_sim_s", "energy_drift", x_wall, "max |E/E0 - 1|",
           f"energy drift over {t_end:g} s")
    _panel(axes[1, 2], rows, "cost_per_sim_s", "lbody_drift", x_wall, "max | |R^T L| / |L| - 1 |",
           f"|L_body| drift over {t_end:g} s (only the unrepaired matrix drifts)")
    blocks = [(f"orientation at {every:g} s, measured cost", rows, "cost_per_sim_s", "error")]
    if has_compute:
        blocks.append((f"orientation at {every:g} s, compute-bound", rows, "compute_us_per_sim_s", "error"))
    _table(axes[0, 3], [("cheapest (error <= x: method, dt)\n", [], "cost_per_sim_s", "error")] + blocks)
    _table(axes[1, 3], [(f"orientation at {t_end:g} s, measured cost", rows, "cost_per_sim_s", "orient_err_end"),
                        ("energy drift, measured cost", rows, "cost_per_sim_s", "energy_drift")])
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=6, fontsize=8)
    fig.suptitle(title + "\nsemi_implicit's rotation is the implicit midpoint rule (order 2, energy kept to round-off); "
                 "RK4 reaches float32 round-off (~1e-6) by 100 steps/s", fontsize=11)
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    fig.savefig(path, dpi=90)
    plt.close(fig)


TITLES = {
    "projectile": ("projectile, |x - exact| at 1 s", "position error [m]"),
    "rolling": (f"sphere rolling down {ROLL_ANGLE:g} deg (4 substeps)", "|a / (5/7 g sin) - 1|"),
    "sliding": (f"box sliding down {SLIDE_ANGLE:g} deg, mu {SLIDE_MU} (4 substeps)", "|a / (g(sin - mu cos)) - 1|"),
    "bounce": (f"bounce apex ratio, e = {BOUNCE_E} (8 substeps)", "|apex / (e^2 H) - 1|"),
}


def draw(case: str, rows: list[dict], png: Path, meta: dict, every: float, t_end: float):
    cpu = meta["cpu"][:40]
    if case == "tumbling":
        chart_tumbling(rows, png, f"torque-free box near its intermediate axis, omega0 = {TUMBLE_OMEGA} rad/s,"
                       f" {t_end:g} s, float64 reference ({cpu})", every, t_end)
    else:
        title, ylabel = TITLES[case]
        chart_simple(rows, png, f"{title} ({cpu})", ylabel, NOTES[case])


def replot(out_dir: Path, case_names: list[str]) -> int:
    """Redraw the charts from the JSON files already in ``out_dir`` (no simulation)."""
    for case in case_names:
        path = out_dir / f"work_precision_{case}.json"
        if not path.exists():
            continue
        data = json.loads(path.read_text())
        cfg = data.get("config", {})
        draw(case, data["rows"], out_dir / f"work_precision_{case}.png", data["machine"],
             cfg.get("orient_time", 1.0), cfg.get("tumble_time", FULL["tumble_time"]))
        print(f"redrew {out_dir / f'work_precision_{case}.png'}")
    return 0


# Driver ---------------------------------------------------------------------------------------

def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cases", nargs="+", default=CASES, choices=CASES)
    p.add_argument("--integrators", nargs="+", default=INTEGRATORS, choices=INTEGRATORS)
    p.add_argument("--rotations", nargs="+", default=ROTATIONS, choices=ROTATIONS,
                   help="rotation representations for the tumbling box")
    p.add_argument("--repeats", type=int, default=None, help="timed runs per point; the median is kept")
    p.add_argument("--tumble-time", type=float, default=None, help="tumbling run length [s] (drift window)")
    p.add_argument("--orient-time", type=float, default=1.0, help="time of the charted orientation error [s]")
    p.add_argument("--compute-bodies", type=int, default=None,
                   help="boxes used to measure the compute-bound cost per body-step (0: skip)")
    p.add_argument("--quick", action="store_true", help="tiny sizes (two dt per method, short runs)")
    p.add_argument("--out-dir", type=Path, default=None, help="default bench/results; --quick: a temporary folder")
    p.add_argument("--device", default="cpu")
    p.add_argument("--replot", action="store_true", help="only redraw the PNGs from the JSON in --out-dir")
    args = p.parse_args(argv)
    args.out_dir = common.output_dir(args.out_dir, args.quick, "work_precision")
    if args.replot:
        return replot(args.out_dir, args.cases)
    size = QUICK if args.quick else FULL
    repeats = args.repeats or size["repeats"]
    t_end = args.tumble_time or size["tumble_time"]
    every = args.orient_time
    if abs(t_end / every - round(t_end / every)) > 1e-9:
        p.error("--tumble-time must be a multiple of --orient-time")
    bodies = size["compute_bodies"] if args.compute_bodies is None else args.compute_bodies
    wp.config.quiet = True
    wp.init()
    if args.device != "cpu":
        p.error("the cases are built on the CPU device only")
    meta = machine_info(args.device)
    meta["command"] = "python bench/work_precision.py " + " ".join(argv if argv is not None else sys.argv[1:])

    from tqdm import tqdm

    jobs = []
    for case in args.cases:
        dts = size["contact_dts"] if case in ("rolling", "sliding", "bounce") else size["free_dts"]
        if case == "tumbling":
            jobs += [(case, i, r, dt) for i in args.integrators for r in args.rotations for dt in dts]
        else:
            jobs += [(case, i, None, dt) for i in args.integrators for dt in dts]
    rows: dict[str, list[dict]] = {c: [] for c in args.cases}
    body_cost = {}
    if "tumbling" in args.cases and bodies > 1:
        for i in tqdm([(i, r) for i in args.integrators for r in args.rotations], desc="body-step cost",
                      unit="method"):
            body_cost[i] = tumbling_body_step_cost(*i, bodies, repeats)
    if "tumbling" in args.cases:
        tumbling_reference(t_end, every)  # computed once up front, outside every timed region
    prepared = []
    for case, integ, rot, dt in jobs:
        if case == "projectile":
            prepared.append(prepare_projectile(integ, dt))
        elif case == "tumbling":
            prepared.append(prepare_tumbling(integ, rot, dt, t_end, every))
        elif case in ("rolling", "sliding"):
            prepared.append(prepare_slope(case, integ, dt))
        else:
            prepared.append(prepare_bounce(integ, dt))
    with tqdm(total=repeats * len(prepared), desc="work-precision", unit="run") as bar:
        for rep in range(repeats):
            for run in prepared:
                run.time_once(last=rep == repeats - 1)
                bar.update()
    for (case, integ, rot, dt), run in zip(jobs, prepared):
        row = run.finish()
        if case == "tumbling":
            c = body_cost.get((integ, rot))
            row["compute_us_per_sim_s"] = c * 1e6 / dt if c is not None else None
        rows[case].append(row)

    written = []
    for case, case_rows in rows.items():
        name = f"work_precision_{case}"
        summary = {"cheapest_per_decade": cheapest_per_decade(case_rows, "cost_per_sim_s")}
        if case == "tumbling":
            summary = tumbling_summary(case_rows, every, t_end, bodies)
        extra = {"config": {"repeats": repeats, "quick": args.quick, "tumble_time": t_end, "orient_time": every,
                            "compute_bodies": bodies},
                 "summary": summary}
        csv_path, _ = write_results(args.out_dir, name, case_rows, meta, extra)
        draw(case, case_rows, args.out_dir / f"{name}.png", meta, every, t_end)
        written.append(csv_path)
        if case == "tumbling":
            for key, label in (("measured", "measured cost"), ("compute_bound", "compute-bound cost")):
                for m in ("verlet", "rk4"):
                    cmp = summary["equal_cost"].get(key, {}).get(m)
                    if cmp and cmp.get("comparable"):
                        tqdm.write(f"{m} vs explicit_euler at equal {label}: error ratio "
                                   f"{cmp['ratio_min']:.3g}x .. {cmp['ratio_max']:.3g}x "
                                   f"(beats 10x everywhere: {cmp['beats_euler_10x']})")
    for path in written:
        print(f"wrote {path} (+ .json, .png)")
    return 0


def tumbling_summary(rows: list[dict], every: float, t_end: float, bodies: int) -> dict:
    """Equal-cost comparison against explicit Euler (quaternion rotation), per cost model."""
    quat = [r for r in rows if r["rotation"] == "quaternion"]
    out = {"metric": f"orientation error max|R - R_ref| at {every:g} s, quaternion rotation",
           "ratio": "err(explicit_euler) / err(method) at equal cost, log-log interpolation, no extrapolation",
           "equal_cost": {}}
    cost_models = {"measured": "cost_per_sim_s"}
    if bodies > 1:
        cost_models["compute_bound"] = "compute_us_per_sim_s"
    baseline = "explicit_euler/quaternion"
    for name, key in cost_models.items():
        out["equal_cost"][name] = {}
        for m in ("semi_implicit", "verlet", "rk4"):
            out["equal_cost"][name][m] = equal_cost_ratio(quat, f"{m}/quaternion", baseline, key)
        out["equal_cost"][name]["energy_drift"] = {
            m: equal_cost_ratio(quat, f"{m}/quaternion", baseline, key, "energy_drift") for m in ("verlet", "rk4")}
        out["equal_cost"][name]["orientation_end"] = {
            m: equal_cost_ratio(quat, f"{m}/quaternion", baseline, key, "orient_err_end") for m in ("verlet", "rk4")}
    measured = out["equal_cost"]["measured"]
    out["rk4_or_verlet_beats_explicit_euler_10x"] = bool(
        any(measured[m].get("beats_euler_10x", False) for m in ("verlet", "rk4")))
    out["cheapest_per_decade"] = {
        f"orientation at {every:g} s": cheapest_per_decade(rows, "cost_per_sim_s"),
        f"orientation at {t_end:g} s": cheapest_per_decade(rows, "cost_per_sim_s", "orient_err_end"),
        "energy drift": cheapest_per_decade(rows, "cost_per_sim_s", "energy_drift"),
    }
    return out


if __name__ == "__main__":
    sys.exit(main())
