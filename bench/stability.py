"""Stability maps: sweep dt (and solver iterations / substeps) and name where each method fails.

    python bench/stability.py                              # every study, the committed results (~2 min, 2 cores)
    python bench/stability.py --studies stack pyramid
    python bench/stability.py --quick --out-dir /tmp/st    # tiny sweeps (the tests use this)

One row = one simulated run: the study, the method (integrator, rotation mode or solver
variant), the swept parameters, the measured quantity, ``failed`` (true/false) and
``failure``, the failure's name ('' when the run passed).  A run that raises NonFiniteStateError
fails as "non-finite (step k)"; every run's final state also goes through the invalid-state gate
(bench.common.state_gate) and a gate rejection is a failure named by the gate's reason
("penetration 0.013 m > 0.01 m", "rotation not orthonormal", ...).  Studies:

    energy    a free box spun at ``spin`` rad/s about (0.3, 0.4, 5)/|.| (near its intermediate
              axis) in zero gravity for 10 s, every integrator (quaternion rotation) plus the
              thesis's explicit Euler on the unrepaired matrix, x dt x spin.  Row value: E_max/E0
              over the run (sampled every 0.5 s).  Failure "energy x2 (t = ..)" once E/E0 > 2.
              With |L| conserved and R orthonormal, E/E0 is bounded by |L|^2 / (2 I_min E0) = 3.4
              (all the energy in a spin about the box's long axis): the quaternion runs saturate
              there; only the unrepaired matrix can grow without bound (to non-finite).
    rotation  the same box at omega0 = (0.3, 0.4, 5) rad/s for 5 s, every rotation
              mode x integrator x dt.  Row value: max|R^T R - I| at the end.  Failure "stretched"
              when it exceeds 1e-3 (the box visibly stretches); only ``matrix`` (no repair) can.
    tunnel    a 0.1 m ball thrown from 3 m above the Fourier terrain at ``speed`` m/s, ``angle``
              below the horizontal, one substep per step, the speculative margin as shipped, 1.5 s.
              Failure "tunnelled" when the centre ends below the surface, "dipped below" when it
              passed below the surface at some step but came back, "deep contact" when the
              penetration measured after some step exceeded the gate's 1 cm (the gate applied
              during the run, not only at the end).  Row values: lowest clearance of the centre
              above the surface, deepest measured penetration.
    stack     a column of ``height`` unit boxes on a plane (friction 0.6, dt 1/60, sleeping off)
              for --stack-time s, per solver variant.  Failure "fell" when the top box sinks more
              than half a box below where it was at 1 s, "drifted" when it moved more than 1 cm
              from there at some later sample (every 0.5 s; the run goes on to the end, and the
              name says how far, how much of it sideways, and that it still stood).  A variant
              that fails at two heights in a row is not run higher ("not run").
    pyramid   a 2-D pyramid of base ``base`` (bases 2..10), same criterion applied to every box,
              --pyramid-time s (1 s to settle, then the rest is watched).
    jitter    three stacked unit boxes, dt swept at 4 substeps: RMS speed of the boxes over 2 s
              after a 1 s settle.  Failure "jitter" when it exceeds g h (h = dt / substeps), one
              gravity kick per substep; the value is also given as a fraction of g h.

Solver variants: soft_step (4 iterations, the default), soft_step with 2 and 1 iterations,
soft_step with 1 substep (dt 1/60, h = 1/60), and the thesis's push-out (4 iterations).
Writes <out-dir>/stability_<study>.{csv,json,png} (default bench/results/); each JSON has a
``summary`` (largest passing dt, highest stack, ...).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench import common  # noqa: E402
from bench.common import machine_info, state_gate  # noqa: E402
from bench.work_precision import write_results  # noqa: E402
from warp_sim import (  # noqa: E402
    FourierTerrain,
    ModelBuilder,
    NonFiniteStateError,
    PlaneTerrain,
    SimConfig,
    Simulator,
    cases,
)
from warp_sim.builder import Material  # noqa: E402

G = cases.GRAVITY
INTEGRATORS = ["explicit_euler", "semi_implicit", "verlet", "rk4"]
ROTATIONS = ["quaternion", "matrix", "matrix_cross", "matrix_gram_schmidt"]
STUDIES = ["energy", "rotation", "tunnel", "stack", "pyramid", "jitter"]
COLORS = {"explicit_euler": "tab:red", "semi_implicit": "tab:orange", "verlet": "tab:green", "rk4": "tab:blue"}
SPIN_DIR = np.array([0.3, 0.4, 5.0]) / np.linalg.norm([0.3, 0.4, 5.0])
STRETCH_LIMIT = 1e-3
DRIFT_LIMIT = 0.01
DEPTH_SLOP = 0.01  # the gate's default: no body deeper than 1 cm in the terrain
# name -> SimConfig overrides (dt 1/60 throughout)
# (the fixed variants run exactly their substeps; "defaults" is what a scene gets without
# choosing: 2 + 1 sweeps and auto_substeps, warp_sim/column_sag.py)
VARIANTS = {
    "soft_step": {"solver": "soft_step", "iterations": 4, "substeps": 4},
    "soft_step it2": {"solver": "soft_step", "iterations": 2, "substeps": 4},
    "soft_step it1": {"solver": "soft_step", "iterations": 1, "substeps": 4},
    "soft_step 1 substep": {"solver": "soft_step", "iterations": 4, "substeps": 1},
    "pushout": {"solver": "pushout", "iterations": 4, "substeps": 4},
    "defaults": {"solver": "soft_step", "iterations": 2, "substeps": 4, "auto_substeps": True},
}
VARIANT_COLORS = {"soft_step": "tab:blue", "soft_step it2": "tab:cyan", "soft_step it1": "tab:purple",
                  "soft_step 1 substep": "tab:olive", "pushout": "tab:red", "defaults": "tab:green"}

FULL = {
    "energy_dts": [1 / 240, 1 / 120, 1 / 60, 1 / 30, 1 / 15], "spins": [1.0, 2.0, 5.0, 10.0, 20.0, 40.0],
    "energy_time": 10.0,
    "rotation_dts": [1 / 480, 1 / 240, 1 / 120, 1 / 60, 1 / 30, 1 / 15], "rotation_time": 5.0,
    "tunnel_dts": [1 / 240, 1 / 120, 1 / 60, 1 / 30, 1 / 15], "speeds": [5.0, 10.0, 20.0, 40.0, 80.0],
    "angles": [90.0, 45.0, 15.0],
    "heights": [2, 4, 8, 12, 16, 20, 24, 32, 40], "stack_time": 10.0,
    "bases": [2, 3, 4, 5, 6, 7, 8, 9, 10], "pyramid_time": 5.0,
    "jitter_dts": [1 / 30, 1 / 60, 1 / 120, 1 / 240], "jitter_time": 2.0,
    "variants": list(VARIANTS),
}
QUICK = {
    "energy_dts": [1 / 60, 1 / 15], "spins": [5.0, 40.0], "energy_time": 2.0,
    "rotation_dts": [1 / 60, 1 / 15], "rotation_time": 1.0,
    "tunnel_dts": [1 / 60], "speeds": [20.0, 80.0], "angles": [90.0],
    "heights": [2, 4], "stack_time": 2.0,
    "bases": [2, 3], "pyramid_time": 2.0,
    "jitter_dts": [1 / 60], "jitter_time": 0.5,
    "variants": ["soft_step", "pushout"],
}


def dt_label(dt: float) -> str:
    inv = 1.0 / dt
    return f"1/{inv:.0f}" if abs(inv - round(inv)) < 1e-6 else f"{dt:.3g}"


def gate(sim, **kw) -> str:
    reason = state_gate(sim, **kw)
    return f"gate: {reason}" if reason else ""


def step_or_fail(sim, n: int) -> str:
    """Step ``n`` steps; '' or the non-finite failure name."""
    try:
        sim.step(n)
    except NonFiniteStateError as exc:
        return f"non-finite (step {exc.step})"
    return ""


# Studies --------------------------------------------------------------------------------------

ENERGY_METHODS = [(i, "quaternion") for i in INTEGRATORS] + [("explicit_euler", "matrix")]


def run_energy(integrator: str, rotation: str, dt: float, spin: float, t_end: float) -> dict:
    sim = cases.tumbling_box(integrator, rotation, dt, omega=tuple(SPIN_DIR * spin))
    e0 = sim.kinetic_energy()
    chunk = max(1, int(round(0.5 / dt)))
    steps = int(round(t_end / dt))
    worst, failure, done = 1.0, "", 0
    while done < steps and not failure:
        n = min(chunk, steps - done)
        failure = step_or_fail(sim, n)
        done += n
        if not failure:
            ratio = sim.kinetic_energy() / e0
            worst = max(worst, ratio)
            if ratio > 2.0:
                failure = f"energy x2 (t = {done * dt:.2g} s)"
    if not failure:
        failure = gate(sim)
    method = integrator if rotation == "quaternion" else f"{integrator}/{rotation}"
    return {"study": "energy", "method": method, "integrator": integrator, "rotation": rotation, "dt": dt,
            "spin_rad_s": spin, "h_omega": round(dt * spin, 5), "sim_time_s": round(done * dt, 4),
            "energy_ratio_max": worst if "non-finite" not in failure else None,
            "failed": bool(failure), "failure": failure}


def orthonormality_error(sim) -> float:
    rot = sim.state.body_rot.numpy()[0].astype(np.float64)
    return float(np.abs(rot.T @ rot - np.eye(3)).max())


def run_rotation(integrator: str, rotation: str, dt: float, t_end: float) -> dict:
    sim = cases.tumbling_box(integrator, rotation, dt)
    steps = int(round(t_end / dt))
    failure = step_or_fail(sim, steps)
    err = None
    if not failure:
        err = orthonormality_error(sim)
        if not math.isfinite(err):
            failure = "non-finite"
        elif err > STRETCH_LIMIT:
            failure = f"stretched (|R^T R - I| {err:.2g} > {STRETCH_LIMIT:g})"
        else:
            failure = gate(sim)
    return {"study": "rotation", "method": f"{integrator}/{rotation}", "integrator": integrator, "rotation": rotation,
            "dt": dt, "h_omega": round(dt * float(np.linalg.norm([0.3, 0.4, 5.0])), 5), "sim_time_s": t_end,
            "orthonormality_error": err, "failed": bool(failure), "failure": failure}


TUNNEL_TERRAIN = FourierTerrain()


def run_tunnel(speed: float, angle: float, dt: float, t_end: float = 1.5) -> dict:
    terrain = TUNNEL_TERRAIN
    a = math.radians(angle)
    b = ModelBuilder(Material(restitution=0.3))
    b.set_terrain(terrain)
    b.add_sphere(0.1, 1.0, position=(0.0, float(terrain.height(0.0, 0.0)) + 3.0, 0.0),
                 velocity=(speed * math.cos(a), -speed * math.sin(a), 0.0))
    sim = Simulator(b.finalize(), SimConfig(dt=dt, substeps=1, sleep=False))
    clearance, deepest, failure = math.inf, 0.0, ""
    below_at = None
    for k in range(int(round(t_end / dt))):
        failure = step_or_fail(sim, 1)
        if failure:
            break
        p = sim.state.body_pos.numpy()[0].astype(np.float64)
        c = p[1] - float(terrain.height(p[0], p[2]))
        clearance = min(clearance, c)
        if c < 0.0 and below_at is None:
            below_at = (k + 1) * dt
        deepest = max(deepest, sim.max_penetration())
    if not failure:
        p = sim.state.body_pos.numpy()[0].astype(np.float64)
        end = p[1] - float(terrain.height(p[0], p[2]))
        if end < 0.0:
            failure = f"tunnelled (centre {-end:.2g} m below, first at t = {below_at:.3g} s)"
        elif below_at is not None:
            failure = f"dipped below (t = {below_at:.3g} s)"
        elif deepest > DEPTH_SLOP:
            failure = f"deep contact ({1000 * deepest:.0f} mm during the run)"
        else:
            failure = gate(sim, depth_slop=DEPTH_SLOP, speed_bound=max(100.0, 2.0 * speed))
    return {"study": "tunnel", "method": "soft_step", "speed_m_s": speed, "angle_deg": angle, "dt": dt, "substeps": 1,
            "travel_per_step_m": round(speed * dt, 4),
            "min_clearance_m": clearance if math.isfinite(clearance) else None,
            "max_penetration_m": deepest, "failed": bool(failure), "failure": failure}


def box_scene(positions, variant: str) -> Simulator:
    b = ModelBuilder(Material(friction=0.6))
    b.set_terrain(PlaneTerrain())
    for p in positions:
        b.add_box((0.5, 0.5, 0.5), 1.0, position=p)
    v = VARIANTS[variant]
    return Simulator(b.finalize(), SimConfig(dt=1 / 60, substeps=v["substeps"], solver=v["solver"],
                                              iterations=v["iterations"], sleep=False,
                                              auto_substeps=v.get("auto_substeps", False)))


def watch(sim: Simulator, t_end: float, watched: slice) -> dict:
    """Settle 1 s, then watch ``watched`` bodies every 0.5 s to the end (a run that drifts is
    followed on, so a bounded sway and a fall are told apart)."""
    failure = step_or_fail(sim, 60)
    if failure:
        return {"max_drift_m": None, "sideways_m": None, "failure": failure, "watched_s": 0.0}
    settled = sim.state.body_pos.numpy()[watched].astype(np.float64)
    drift, sideways, t, first_drift, fell_at = 0.0, 0.0, 1.0, None, None
    while t < t_end - 1e-9:
        failure = step_or_fail(sim, 30)
        if failure:
            break
        t += 0.5
        pos = sim.state.body_pos.numpy()[watched].astype(np.float64)
        moved = pos - settled
        drift = max(drift, float(np.linalg.norm(moved, axis=1).max()))
        sideways = max(sideways, float(np.hypot(moved[:, 0], moved[:, 2]).max()))
        if drift > DRIFT_LIMIT and first_drift is None:
            first_drift = t
        if float(-moved[:, 1].min()) > 0.5:
            fell_at = t
            break  # fallen: nothing more to learn
    if not failure:
        if fell_at is not None:
            failure = f"fell (t = {fell_at:.3g} s)"
        elif first_drift is not None:
            failure = (f"drifted (from t = {first_drift:.3g} s, max {100 * drift:.2g} cm, "
                       f"{100 * sideways:.2g} cm sideways; standing at the end)")
        else:
            failure = gate(sim)
    return {"max_drift_m": drift, "sideways_m": sideways, "failure": failure, "watched_s": round(t - 1.0, 3)}


def run_stack(variant: str, height: int, t_end: float) -> dict:
    sim = box_scene([(0.0, 0.5 + k, 0.0) for k in range(height)], variant)
    out = watch(sim, t_end, slice(height - 1, height))
    return {"study": "stack", "method": variant, **VARIANTS[variant], "dt": 1 / 60, "height": height,
            "sim_time_s": t_end, "watched_s": out["watched_s"], "max_drift_m": out["max_drift_m"],
            "sideways_m": out["sideways_m"], "failed": bool(out["failure"]), "failure": out["failure"]}


def run_pyramid(variant: str, base: int, t_end: float) -> dict:
    pos = [(k - (base - 1 - row) / 2.0, 0.5 + row, 0.0) for row in range(base) for k in range(base - row)]
    sim = box_scene(pos, variant)
    out = watch(sim, t_end, slice(0, len(pos)))
    return {"study": "pyramid", "method": variant, **VARIANTS[variant], "dt": 1 / 60, "base": base,
            "boxes": len(pos), "sim_time_s": t_end, "watched_s": out["watched_s"],
            "max_drift_m": out["max_drift_m"], "sideways_m": out["sideways_m"], "failed": bool(out["failure"]),
            "failure": out["failure"]}


def run_jitter(solver: str, dt: float, t_watch: float, substeps: int = 4) -> dict:
    b = ModelBuilder(Material(friction=0.6))
    b.set_terrain(PlaneTerrain())
    for k in range(3):
        b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, 0.5 + k, 0.0))
    sim = Simulator(b.finalize(), SimConfig(dt=dt, substeps=substeps, solver=solver, sleep=False))
    failure = step_or_fail(sim, int(round(1.0 / dt)))
    speeds = []
    for _ in range(int(round(t_watch / dt))):
        if failure:
            break
        failure = step_or_fail(sim, 1)
        speeds.append(np.linalg.norm(sim.state.body_vel.numpy().astype(np.float64), axis=1))
    gh = G * dt / substeps
    rms = float(np.sqrt(np.mean(np.square(speeds)))) if speeds and not failure else None
    if not failure:
        failure = f"jitter (RMS {rms:.2g} m/s > g h)" if rms > gh else gate(sim)
    return {"study": "jitter", "method": solver, "solver": solver, "dt": dt, "substeps": substeps,
            "g_h_m_s": gh, "rms_speed_m_s": rms, "rms_over_g_h": rms / gh if rms is not None else None,
            "failed": bool(failure), "failure": failure}


# Summaries ------------------------------------------------------------------------------------

def largest_passing_dt(rows, key_fields):
    """Per method (and key fields), the largest dt at which every smaller dt passed too."""
    out = {}
    groups = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in key_fields), []).append(r)
    for key, rs in groups.items():
        best = None
        for r in sorted(rs, key=lambda r: r["dt"]):
            if r["failed"]:
                break
            best = r["dt"]
        out[" ".join(str(k) for k in key)] = dt_label(best) if best else "none"
    return out


def highest_standing(rows, size_key):
    out = {}
    for variant in dict.fromkeys(r["method"] for r in rows):
        best = 0
        for r in sorted((r for r in rows if r["method"] == variant), key=lambda r: r[size_key]):
            if r["failed"]:
                break
            best = r[size_key]
        first_fail = next((r for r in sorted(rows, key=lambda r: r[size_key])
                           if r["method"] == variant and r["failed"] and not r["failure"].startswith("not run")), None)
        out[variant] = {"highest": best,
                        "first_failure": f"{size_key} {first_fail[size_key]}: {first_fail['failure']}"
                        if first_fail else ""}
    return out


# Charts ---------------------------------------------------------------------------------------

def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def dt_axis(ax, dts):
    """Log dt axis ticked at the swept values, labelled 1/N."""
    from matplotlib.ticker import NullFormatter

    ax.set_xticks(dts, [dt_label(d) for d in dts])
    ax.xaxis.set_minor_formatter(NullFormatter())


def short_failure(f: str) -> str:
    if not f:
        return ""
    for key, label in (("non-finite", "NaN"), ("energy", "E x2"), ("stretched", "str"), ("tunnelled", "TUN"),
                       ("dipped", "dip"), ("deep", "deep"), ("fell", "fell"), ("drifted", "drift"), ("jitter", "jit"),
                       ("gate: penetration", "pen"), ("gate", "gate"), ("not run", "-")):
        if f.startswith(key):
            return label
    return f[:5]


def chart_energy(rows, path: Path, t_end: float):
    plt = _plt()
    from matplotlib.colors import LogNorm

    methods = list(dict.fromkeys(r["method"] for r in rows))
    dts = sorted({r["dt"] for r in rows})
    spins = sorted({r["spin_rad_s"] for r in rows})
    fig, axes = plt.subplots(1, len(methods), figsize=(3.6 * len(methods) + 1.5, 4.4), squeeze=False, sharey=True)
    im = None
    norm = LogNorm(vmin=1.0, vmax=10.0)
    for ax, method in zip(axes[0], methods):
        grid = np.full((len(spins), len(dts)), np.nan)
        for r in rows:
            if r["method"] != method:
                continue
            i, j = spins.index(r["spin_rad_s"]), dts.index(r["dt"])
            v = r["energy_ratio_max"]
            grid[i, j] = min(max(v, 1.0), 10.0) if v is not None else 10.0
            value = (f"{v:.3g}" if v < 1000 else f"{v:.0e}") if v is not None else ""
            text = f"{short_failure(r['failure'])}\n{value}" if r["failed"] else value
            ax.text(j, i, text, ha="center", va="center", fontsize=7,
                    color="white" if r["failed"] and (v is None or v > 3) else "black",
                    fontweight="bold" if r["failed"] else None)
        im = ax.imshow(grid, origin="lower", cmap="magma_r", norm=norm, aspect="auto")
        for r in rows:
            if r["method"] == method and r["failed"]:
                i, j = spins.index(r["spin_rad_s"]), dts.index(r["dt"])
                ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="red", lw=2))
        ax.set_xticks(range(len(dts)), [dt_label(d) for d in dts], fontsize=8)
        ax.set_yticks(range(len(spins)), [f"{s:g}" for s in spins])
        ax.set_xlabel("dt [s] (1 substep)")
        ax.set_title(method + (" (thesis)" if method == "explicit_euler/matrix" else ""),
                     color=COLORS.get(method.split("/")[0], "black"))
    axes[0, 0].set_ylabel("spin |omega| [rad/s]")
    fig.colorbar(im, ax=axes[0].tolist(), label="max E/E0 over the run (red box: failed)", shrink=0.85)
    fig.suptitle(f"energy blow-up of a spinning box, {t_end:g} s (quaternion unless named): cell = max E/E0; "
                 "E x2 = energy doubled, NaN = non-finite.\nWith |L| fixed and R orthonormal E/E0 cannot pass "
                 "|L|^2 / (2 I_min E0) = 3.4 (all the energy in a spin about the long axis)", fontsize=9, y=1.06)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def chart_rotation(rows, path: Path, t_end: float):
    plt = _plt()
    rots = list(dict.fromkeys(r["rotation"] for r in rows))
    fig, axes = plt.subplots(1, len(rots), figsize=(4.2 * len(rots), 4.2), squeeze=False, sharey=True)
    for ax, rot in zip(axes[0], rots):
        for integ in dict.fromkeys(r["integrator"] for r in rows):
            rs = sorted((r for r in rows if r["rotation"] == rot and r["integrator"] == integ), key=lambda r: r["dt"])
            pts = [(r["dt"], max(r["orthonormality_error"], 1e-9)) for r in rs if r["orthonormality_error"] is not None]
            if pts:
                ax.loglog(*zip(*pts), marker="o", ms=4, color=COLORS[integ], label=integ,
                          ls="--" if integ == "semi_implicit" else "-")
            for r in rs:
                if r["failed"]:
                    y = r["orthonormality_error"] if r["orthonormality_error"] is not None else 1e3
                    ax.plot(r["dt"], min(max(y, 1e-9), 1e3), marker="X", ms=10, color=COLORS[integ], mec="black")
                    if r["orthonormality_error"] is None:
                        ax.annotate("NaN", (r["dt"], 1e3), fontsize=7, xytext=(2, -9), textcoords="offset points")
        ax.axhline(STRETCH_LIMIT, color="black", ls=":", lw=1)
        ax.text(min(r["dt"] for r in rows), STRETCH_LIMIT * 1.5, "1e-3: box visibly stretches", fontsize=7)
        dt_axis(ax, sorted({r["dt"] for r in rows}))
        ax.set_xlabel("dt [s] (1 substep)")
        ax.set_title(rot)
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].set_ylabel(f"max|R^T R - I| after {t_end:g} s (floor 1e-9)")
    handles, labels = axes[0, 1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8)
    fig.suptitle(f"orthonormality drift, box spun at |omega| = 5 rad/s for {t_end:g} s; X = failed "
                 "(stretched or non-finite)", fontsize=10)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


STATUS_COLOR = {"": 0, "deep": 1, "dip": 1, "pen": 2, "gate": 2, "TUN": 3, "NaN": 3}


def chart_tunnel(rows, path: Path):
    plt = _plt()
    from matplotlib.colors import ListedColormap

    angles = list(dict.fromkeys(r["angle_deg"] for r in rows))
    dts = sorted({r["dt"] for r in rows})
    speeds = sorted({r["speed_m_s"] for r in rows})
    tunnelled = sum(short_failure(r["failure"]) == "TUN" for r in rows)
    fig, axes = plt.subplots(1, len(angles), figsize=(4.6 * len(angles), 4.4), squeeze=False)
    cmap = ListedColormap(["#9be39b", "#ffd27f", "#c9a0ff", "#ff6f6f"])
    for ax, angle in zip(axes[0], angles):
        grid = np.zeros((len(speeds), len(dts)))
        for r in rows:
            if r["angle_deg"] != angle:
                continue
            i, j = speeds.index(r["speed_m_s"]), dts.index(r["dt"])
            label = short_failure(r["failure"])
            grid[i, j] = STATUS_COLOR.get(label, 2)
            pen = r["max_penetration_m"]
            depth = f"{1000 * pen:.1f} mm" if pen is not None else ""
            text = f"{label}\n{depth}" if label else depth
            ax.text(j, i, text, ha="center", va="center", fontsize=7)
        ax.imshow(grid, origin="lower", cmap=cmap, vmin=-0.5, vmax=3.5, aspect="auto")
        ax.set_xticks(range(len(dts)), [dt_label(d) for d in dts])
        ax.set_yticks(range(len(speeds)), [f"{s:g}" for s in speeds])
        ax.set_xlabel("dt [s] (1 substep)")
        ax.set_ylabel("launch speed [m/s]")
        ax.set_title(f"thrown {angle:g} deg below horizontal")
    fig.suptitle("fast 0.1 m spheres vs the Fourier terrain, 1.5 s; cell: deepest penetration during the run.\n"
                 "green = held; orange deep = over 1 cm at some step, dip = centre went below the surface; "
                 f"purple pen = final state fails the gate; red TUN = tunnelled ({tunnelled} runs)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def chart_sizes(rows, path: Path, size_key: str, title: str, xlabel: str):
    """Marked scatter: one row per solver variant, one column per size; failures named."""
    plt = _plt()
    variants = list(dict.fromkeys(r["method"] for r in rows))
    sizes = sorted({r[size_key] for r in rows})
    fig, ax = plt.subplots(figsize=(1.25 * len(sizes) + 3.5, 0.65 * len(variants) + 1.6))
    for i, v in enumerate(variants):
        for r in rows:
            if r["method"] != v:
                continue
            j = sizes.index(r[size_key])
            if r["failure"].startswith("not run"):
                ax.plot(j, i, marker=".", color="lightgrey")
                continue
            ok = not r["failed"]
            ax.plot(j, i, marker="o" if ok else "X", ms=11, color="tab:green" if ok else "tab:red", mec="black")
            drift = r["max_drift_m"]
            text = short_failure(r["failure"])
            if drift is not None and (ok or text == "drift"):
                text = f"{text} {100 * drift:.2g} cm".strip()
            ax.annotate(text, (j, i), xytext=(0, 9), textcoords="offset points", ha="center", fontsize=7)
    ax.set_yticks(range(len(variants)), variants)
    ax.set_xticks(range(len(sizes)), [str(s) for s in sizes])
    ax.set_xlim(-0.6, len(sizes) - 0.4)
    ax.set_ylim(-0.6, len(variants) - 0.3)
    ax.set_xlabel(xlabel)
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def chart_jitter(rows, path: Path):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for solver in dict.fromkeys(r["solver"] for r in rows):
        rs = sorted((r for r in rows if r["solver"] == solver and r["rms_speed_m_s"] is not None),
                    key=lambda r: r["dt"])
        ax.loglog([r["dt"] for r in rs], [max(r["rms_speed_m_s"], 1e-9) for r in rs], marker="o",
                  color=VARIANT_COLORS.get(solver, "black"), label=solver)
        for r in rs:
            if r["failed"]:
                ax.plot(r["dt"], max(r["rms_speed_m_s"], 1e-9), marker="X", ms=11, color="tab:red", mec="black")
    dts = sorted({r["dt"] for r in rows})
    subs = rows[0]["substeps"]
    ax.loglog(dts, [G * d / subs for d in dts], color="grey", ls="--", label="g h (failure above)")
    ax.loglog(dts, [0.1 * G * d / subs for d in dts], color="grey", ls=":", label="0.1 g h")
    dt_axis(ax, dts)
    ax.set_xlabel(f"dt [s] ({subs} substeps)")
    ax.set_ylabel("RMS body speed at rest [m/s]")
    ax.set_title("jitter of a 3-box stack at rest (X = RMS above g h)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="center right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# Driver ---------------------------------------------------------------------------------------

def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--studies", nargs="+", default=STUDIES, choices=STUDIES)
    p.add_argument("--quick", action="store_true", help="tiny sweeps")
    p.add_argument("--out-dir", type=Path, default=None, help="default bench/results; --quick: a temporary folder")
    p.add_argument("--stack-time", type=float, default=None, help="[s], default 10 (quick 2)")
    p.add_argument("--pyramid-time", type=float, default=None, help="[s], default 5 (quick 2)")
    args = p.parse_args(argv)
    args.out_dir = common.output_dir(args.out_dir, args.quick, "stability")
    size = dict(QUICK if args.quick else FULL)
    if args.stack_time:
        size["stack_time"] = args.stack_time
    if args.pyramid_time:
        size["pyramid_time"] = args.pyramid_time
    wp.config.quiet = True
    wp.init()
    meta = machine_info("cpu")
    meta["command"] = "python bench/stability.py " + " ".join(argv if argv is not None else sys.argv[1:])
    from tqdm import tqdm

    jobs = []
    if "energy" in args.studies:
        jobs += [("energy", (i, r, dt, s, size["energy_time"])) for i, r in ENERGY_METHODS for s in size["spins"]
                 for dt in size["energy_dts"]]
    if "rotation" in args.studies:
        jobs += [("rotation", (i, r, dt, size["rotation_time"])) for r in ROTATIONS for i in INTEGRATORS
                 for dt in size["rotation_dts"]]
    if "tunnel" in args.studies:
        jobs += [("tunnel", (s, a, dt)) for a in size["angles"] for s in size["speeds"] for dt in size["tunnel_dts"]]
    if "stack" in args.studies:
        jobs += [("stack", (v, h, size["stack_time"])) for v in size["variants"] for h in size["heights"]]
    if "pyramid" in args.studies:
        jobs += [("pyramid", (v, b, size["pyramid_time"])) for v in size["variants"] for b in size["bases"]]
    if "jitter" in args.studies:
        jobs += [("jitter", (s, dt, size["jitter_time"])) for s in ("soft_step", "pushout") for dt in size["jitter_dts"]]
    runners = {"energy": run_energy, "rotation": run_rotation, "tunnel": run_tunnel, "stack": run_stack,
               "pyramid": run_pyramid, "jitter": run_jitter}
    rows: dict[str, list[dict]] = {s: [] for s in args.studies}
    streak: dict[tuple, int] = {}
    for study, params in tqdm(jobs, desc="stability", unit="run"):
        if study in ("stack", "pyramid"):
            variant, n = params[0], params[1]
            if streak.get((study, variant), 0) >= 2:
                key = "height" if study == "stack" else "base"
                rows[study].append({**rows[study][-1], key: n, "max_drift_m": None, "sideways_m": None, "watched_s": 0.0,
                                    **({"boxes": n * (n + 1) // 2} if study == "pyramid" else {}),
                                    "failed": True, "failure": "not run (failed at two smaller sizes)"})
                continue
        row = runners[study](*params)
        rows[study].append(row)
        if study in ("stack", "pyramid"):
            streak[(study, variant)] = streak.get((study, variant), 0) + 1 if row["failed"] else 0
        if row["failed"] and study in ("stack", "pyramid"):
            tqdm.write(f"{study} {params[:2]}: {row['failure']}")

    written = []
    for study, study_rows in rows.items():
        if not study_rows:
            continue
        name = f"stability_{study}"
        png = args.out_dir / f"{name}.png"
        args.out_dir.mkdir(parents=True, exist_ok=True)
        if study == "energy":
            summary = {"largest_passing_dt_per_spin": largest_passing_dt(study_rows, ["method", "spin_rad_s"])}
            chart_energy(study_rows, png, size["energy_time"])
        elif study == "rotation":
            summary = {"largest_passing_dt": largest_passing_dt(study_rows, ["integrator", "rotation"])}
            chart_rotation(study_rows, png, size["rotation_time"])
        elif study == "tunnel":
            summary = {"failures": [f"{r['speed_m_s']:g} m/s at {r['angle_deg']:g} deg, dt {dt_label(r['dt'])}: "
                                    f"{r['failure']}" for r in study_rows if r["failed"]],
                       "runs": len(study_rows)}
            chart_tunnel(study_rows, png)
        elif study == "stack":
            summary = {"highest_stack": highest_standing(study_rows, "height"), "criterion":
                       f"top box moves < 1 cm after the first second of {size['stack_time']:g} s"}
            chart_sizes(study_rows, png, "height",
                        f"box stacks, {size['stack_time']:g} s, dt 1/60, sleep off: green = stood (top-box drift "
                        "after 1 s), X = failed (drift > 1 cm after 1 s, or fell)", "stack height [boxes]")
        elif study == "pyramid":
            summary = {"largest_base": highest_standing(study_rows, "base"), "criterion":
                       f"every box moves < 1 cm after the first second of {size['pyramid_time']:g} s"}
            chart_sizes(study_rows, png, "base",
                        f"2-D pyramids, {size['pyramid_time']:g} s, dt 1/60, sleep off: green = stood (largest "
                        "drift after 1 s), X = failed", "pyramid base [boxes]")
        else:
            summary = {"largest_passing_dt": largest_passing_dt(study_rows, ["solver"]),
                       "rms_over_g_h": {f"{r['solver']} dt {dt_label(r['dt'])}": r["rms_over_g_h"]
                                        for r in study_rows}}
            chart_jitter(study_rows, png)
        csv_path, _ = write_results(args.out_dir, name, study_rows, meta,
                                    {"config": {k: v for k, v in size.items()}, "summary": summary})
        written.append(csv_path)
    for path in written:
        print(f"wrote {path} (+ .json, .png)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
