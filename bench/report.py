"""Generate bench/REPORT.md from whatever result files exist in bench/results/.

    python bench/report.py                                 # bench/results -> bench/REPORT.md
    python bench/report.py --results-dir /tmp/r --out /tmp/r/REPORT.md

Every ``<name>.json`` ({"machine": ..., "rows": [...], optional "summary"}) or, failing that,
``<name>.csv`` in the results directory becomes one section: its machine description, a
markdown table of its rows (columns empty in every row are dropped; long text columns are listed
under the table instead), its ``summary`` if it has one, and links to the PNGs whose names start
with ``<name>``.  Known files come first in a fixed order, then the rest alphabetically.

At the top, the project's goals are checked against the data that exists, each MET, NOT MET or
NOT MEASURED, with the measured figure and the file it came from.  Nothing is assumed: a goal
whose file is missing, or whose rows all failed the invalid-state gate, is NOT MEASURED.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results"

ORDER = ["terrain_drop_cpu", "rain_cpu", "scaling", "peers", "broad_phase_cpu", "render_cpu", "sweep"]
PREFIX_ORDER = ["work_precision_", "stability_"]
TITLES = {
    "terrain_drop_cpu": "Terrain contact throughput (bench/terrain_drop.py)",
    "rain_cpu": "Rain of mixed bodies with body-body contact, per broad phase (bench/rain.py)",
    "broad_phase_cpu": "Broad phase cost per call (bench/broad_phase.py)",
    "render_cpu": "Rendering cost per frame (bench/render_bench.py)",
    "scaling": "Body-count scaling, per-stage time and memory (bench/scaling.py)",
    "peers": "Peers: the same scenes on MuJoCo, PyBullet and Newton (bench/peers.py)",
    "sweep": "Configuration sweep (bench/sweep.py)",
}
LONG_TEXT = 60  # characters: longer text columns go under the table


# Loading ---------------------------------------------------------------------------------------

def _number(text: str):
    if text in ("", None):
        return ""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        value = float(text)
    except ValueError:
        return text
    return int(value) if value.is_integer() and "." not in text and "e" not in low else value


def load_results(results_dir: Path) -> dict[str, dict]:
    """name -> {"machine": dict, "rows": list, "summary": ..., "source": file name}."""
    results_dir = Path(results_dir)
    out = {}
    if not results_dir.is_dir():
        return out
    for path in sorted(results_dir.glob("*.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            out[path.stem] = {"machine": {}, "rows": [], "error": f"unreadable: {exc}", "source": path.name}
            continue
        if not isinstance(data, dict):
            continue
        rows = data.get("rows") if isinstance(data.get("rows"), list) else []
        extra = {k: v for k, v in data.items() if k not in ("machine", "rows")}
        out[path.stem] = {"machine": data.get("machine") or {}, "rows": rows, "extra": extra, "source": path.name}
    for path in sorted(results_dir.glob("*.csv")):
        if path.stem in out:
            continue
        with path.open(newline="") as f:
            rows = [{k: _number(v) for k, v in r.items()} for r in csv.DictReader(f)]
        out[path.stem] = {"machine": {}, "rows": rows, "extra": {}, "source": path.name}
    return out


def ordered_names(results: dict) -> list[str]:
    names = [n for n in ORDER if n in results]
    for prefix in PREFIX_ORDER:
        names += sorted(n for n in results if n.startswith(prefix) and n not in names)
    names += sorted(n for n in results if n not in names)
    return names


# Formatting ------------------------------------------------------------------------------------

def fmt(value) -> str:
    if value is None or value == "":
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if value == 0:
            return "0"
        if abs(value) >= 1e5:
            return f"{value:,.0f}"
        return f"{value:.4g}"
    if isinstance(value, int):
        return f"{value:,}" if abs(value) >= 10000 else str(value)
    if isinstance(value, (list, dict)):
        text = json.dumps(value)
        return text if len(text) <= LONG_TEXT else text[:LONG_TEXT - 3] + "..."
    return str(value).replace("|", "\\|").replace("\n", " ")


def markdown_table(rows: list[dict], columns: list[str] | None = None) -> str:
    if not rows:
        return "_no rows_\n"
    columns = columns or list(dict.fromkeys(k for r in rows for k in r))
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        lines.append("| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |")
    return "\n".join(lines) + "\n"


def split_columns(rows: list[dict]) -> tuple[list[str], list[str]]:
    """(table columns, long-text columns); columns empty in every row are dropped."""
    columns = list(dict.fromkeys(k for r in rows for k in r))
    columns = [c for c in columns if any(r.get(c) not in ("", None) for r in rows)]
    long_cols = [c for c in columns
                 if any(isinstance(r.get(c), str) and len(r.get(c)) > LONG_TEXT for r in rows)
                 and c not in ("case", "config", "status")]
    return [c for c in columns if c not in long_cols], long_cols


def _strip(obj, drop=("samples",)):
    if isinstance(obj, dict):
        return {k: _strip(v, drop) for k, v in obj.items() if k not in drop}
    if isinstance(obj, list):
        return [_strip(v, drop) for v in obj]
    if isinstance(obj, float):
        return float(f"{obj:.4g}")
    return obj


def machine_line(machine: dict | str) -> str:
    if not machine:
        return "_machine not recorded_"
    if isinstance(machine, str):  # a result that names its machine in words (gpu_h200_tests.json)
        return f"Machine: {machine}"
    keys = ["cpu", "cores", "device", "device_name", "warp", "python", "gl_renderer", "runner"]
    parts = [f"{k}: {machine[k]}" for k in keys if k in machine]
    parts += [f"{k}: {fmt(v)}" for k, v in machine.items() if k not in keys and not isinstance(v, (dict, list))]
    parts += [f"{k}: {json.dumps(v)}" for k, v in machine.items() if isinstance(v, dict)]
    return "Machine: " + "; ".join(parts)


def pngs_for(name: str, results_dir: Path, names: list[str]) -> list[Path]:
    """PNGs named <name>.png or <name>_*.png, unless a longer result name claims them."""
    longer = [n for n in names if n != name and n.startswith(name)]
    out = []
    for png in sorted(Path(results_dir).glob(f"{name}*.png")):
        stem = png.stem
        if stem != name and not stem.startswith(name + "_"):
            continue
        if any(stem == n or stem.startswith(n + "_") for n in longer):
            continue
        out.append(png)
    return out


# Goals -----------------------------------------------------------------------------------------

def _ok(r) -> bool:
    return str(r.get("status", "ok")) == "ok"


def _f(value, default=None):
    try:
        return float(value)
    except (TypeError, ValueError):
        return default


def _close(a, b, rel=1e-3) -> bool:
    a, b = _f(a), _f(b)
    return a is not None and b is not None and abs(a - b) <= rel * abs(b)


def _verdict(values: list[float], target: float) -> str:
    if not values:
        return "NOT MEASURED"
    hits = sum(v >= target for v in values)
    if hits == len(values):
        return "MET"
    if hits == 0:
        return "NOT MET"
    return f"MET in {hits} of {len(values)} runs"


def goal_throughput(results, label, target, sources) -> dict:
    measured = []
    for name, select in sources:
        data = results.get(name)
        if not data:
            continue
        for r in data["rows"]:
            if select(r):
                if _ok(r) and _f(r.get("steps_per_s")) is not None:
                    measured.append((name, _f(r["steps_per_s"]), ""))
                else:
                    measured.append((name, None, str(r.get("status"))))
    values = [v for _, v, _ in measured if v is not None]
    text = "; ".join(f"{v:.1f} steps/s ({n})" if v is not None else f"failed: {why} ({n})"
                     for n, v, why in measured) or "no matching rows"
    return {"goal": label, "verdict": _verdict(values, target), "measured": text}


def goal_peers(results) -> dict:
    label = "Faster than the fastest peer at 1k and 4k spheres, with smaller max penetration (bench/peers.py)"
    data = results.get("peers")
    if not data:
        return {"goal": label, "verdict": "NOT MEASURED", "measured": "no peers results"}
    rows = [r for r in data["rows"] if r.get("scene") == "rain" and r.get("shape") == "sphere"]
    peers = sorted({r["engine"] for r in rows if not str(r["engine"]).startswith("warp_sim")})
    if not peers:
        return {"goal": label, "verdict": "NOT MEASURED", "measured": "no peer engine ran"}
    parts, verdicts = [], []
    for count in (1000, 4000):
        for contact in (True, False):
            sel = [r for r in rows if _f(r.get("bodies")) == count and str(r.get("body_contact")) in (str(contact), str(contact).lower())]
            ours = next((r for r in sel if r["engine"] == "warp_sim" and _ok(r)), None)
            others = [r for r in sel if not str(r["engine"]).startswith("warp_sim") and _ok(r)]
            if not sel:
                continue
            if ours is None or not others:
                parts.append(f"N={count} {'contact' if contact else 'terrain only'}: not comparable "
                             f"({'warp_sim' if ours is None else 'no peer'} missing or failed)")
                continue
            fastest = max(others, key=lambda r: _f(r["steps_per_s"], 0.0))
            speed = _f(ours["steps_per_s"]) / _f(fastest["steps_per_s"])
            pen_ours = _f(ours["max_penetration_m"])
            pen_best = min(_f(r["max_penetration_m"], math.inf) for r in others)
            fast_ok, pen_ok = speed >= 1.0, pen_ours < pen_best
            verdicts.append(fast_ok and pen_ok)
            parts.append(f"N={count} {'with body contact' if contact else 'terrain only'}: warp_sim "
                         f"{_f(ours['steps_per_s']):.1f} steps/s vs fastest peer {fastest['engine']} "
                         f"{_f(fastest['steps_per_s']):.1f} ({speed:.2f}x); max penetration "
                         f"{1e3 * pen_ours:.2f} mm vs best peer {1e3 * pen_best:.2f} mm")
    if not verdicts:
        return {"goal": label, "verdict": "NOT MEASURED", "measured": "; ".join(parts) or "no 1k/4k sphere rows"}
    counts_seen = {p.split()[0] for p in parts if "not comparable" not in p}
    verdict = "MET" if all(verdicts) else ("NOT MET" if not any(verdicts) else
                                           f"MET in {sum(verdicts)} of {len(verdicts)} cases")
    if verdict == "MET" and counts_seen != {"N=1000", "N=4000"}:
        verdict = "MET where measured (" + ", ".join(sorted(counts_seen)) + ")"
    return {"goal": label, "verdict": verdict, "measured": "; ".join(parts)}


def goal_tumbling(results) -> dict:
    label = "RK4 or Verlet more than 10x better than explicit Euler at equal cost on the tumbling box"
    data = results.get("work_precision_tumbling")
    if not data:
        return {"goal": label, "verdict": "NOT MEASURED", "measured": "no work_precision_tumbling results"}
    summary = data.get("extra", {}).get("summary") or {}
    equal = (summary.get("equal_cost") or {}) if isinstance(summary, dict) else {}
    if equal:
        parts, verdict = [], None
        for model, methods in equal.items():
            for m in ("verlet", "rk4"):
                e = methods.get(m) or {}
                if e.get("comparable"):
                    parts.append(f"{m} ({model} cost): err ratio {e['ratio_min']:.3g}..{e['ratio_max']:.3g}, "
                                 f"geomean {e['ratio_geomean']:.3g}")
                elif e:
                    parts.append(f"{m} ({model} cost): not comparable ({e.get('reason', '')})")
        beats = summary.get("rk4_or_verlet_beats_explicit_euler_10x")
        if beats is None:
            measured = equal.get("measured", {})
            beats = any((measured.get(m) or {}).get("beats_euler_10x") for m in ("verlet", "rk4"))
        verdict = "MET" if beats else "NOT MET"
        if not parts:
            verdict = "NOT MEASURED"
        return {"goal": label, "verdict": verdict,
                "measured": "; ".join(parts) + " (ratio = err(explicit Euler) / err(method) at equal measured cost; "
                                               "MET needs it > 10 over the whole common cost range)"}
    return {"goal": label, "verdict": "NOT MEASURED", "measured": "work_precision_tumbling has no equal-cost summary"}


def goal_stack(results) -> dict:
    label = "A stack of at least 20 unit boxes standing 10 s with the default solver"
    data = results.get("stability_stack")
    if not data:
        return {"goal": label, "verdict": "NOT MEASURED", "measured": "no stability_stack results"}
    rows = [r for r in data["rows"] if r.get("method") == "soft_step"]
    if not rows:
        return {"goal": label, "verdict": "NOT MEASURED", "measured": "no default-solver (soft_step) rows"}
    standing = [r for r in rows if str(r.get("failed")).lower() in ("false", "0", "") and
                _f(r.get("sim_time_s"), 0.0) >= 10.0 - 1e-9]
    highest = max((int(_f(r.get("height"), 0)) for r in standing), default=0)
    failures = [f"{r.get('height')}: {r.get('failure')}" for r in rows if str(r.get("failed")).lower() in ("true", "1")
                and not str(r.get("failure", "")).startswith("not run")]
    upright = [int(_f(r.get("height"), 0)) for r in rows if "standing at the end" in str(r.get("failure", ""))]
    measured = (f"highest stack meeting the rule (top box moves < 1 cm after the first second, 10 s): "
                f"{highest} boxes")
    if upright:
        measured += f"; still standing after 10 s but swaying more than 1 cm: up to {max(upright)} boxes"
    if failures:
        measured += "; first failure at height " + failures[0]
    if not any(_f(r.get("sim_time_s"), 0.0) >= 10.0 - 1e-9 for r in rows):
        return {"goal": label, "verdict": "NOT MEASURED", "measured": measured + " (no run of 10 s)"}
    return {"goal": label, "verdict": "MET" if highest >= 20 else "NOT MET", "measured": measured}


def goals(results) -> list[dict]:
    def sphere_terrain_10k(r):
        return (r.get("shape") == "sphere" and _f(r.get("bodies")) == 10000 and _close(r.get("dt"), 1 / 240)
                and int(_f(r.get("substeps"), 1)) == 1
                and str(r.get("body_contact", False)).lower() in ("false", ""))

    def mixed_contact_10k(r):
        return (_f(r.get("bodies")) == 10000 and _close(r.get("dt"), 1 / 60) and int(_f(r.get("substeps"), 0)) == 4
                and r.get("broad_phase") in ("grid", "grid_sorted")
                and r.get("shape", "mix") == "mix" and str(r.get("body_contact", True)).lower() in ("true", "")
                and str(r.get("sleep", False)).lower() in ("false", ""))

    return [
        goal_throughput(results, "10k spheres on the terrain at >= 100 steps/s of 1/240 s (terrain contact)", 100.0,
                        [("terrain_drop_cpu", sphere_terrain_10k), ("scaling", sphere_terrain_10k)]),
        # the GPU-first step's CPU target: no regression of the fused terrain-only step
        goal_throughput(results, "10k spheres on the terrain at >= 250 steps/s of 1/240 s (the GPU-first step's CPU "
                        "target)", 250.0, [("terrain_drop_cpu", sphere_terrain_10k)]),
        goal_throughput(results, "10k mixed bodies in contact at >= 30 steps/s (dt 1/60 s, 4 substeps, grid, "
                        "sleeping off)", 30.0, [("rain_cpu", mixed_contact_10k), ("scaling", mixed_contact_10k)]),
        goal_peers(results),
        goal_tumbling(results),
        goal_stack(results),
    ]


# Sections --------------------------------------------------------------------------------------

def peers_glance(rows: list[dict]) -> str:
    cols = ["case", "engine", "steps_per_s", "speed_vs_warp_sim", "max_penetration_m", "final_penetration_m",
            "penetration_vs_warp_sim", "hfield_error_m", "ke_end_j", "metric", "value", "exact", "error", "status"]
    present = [c for c in cols if any(r.get(c) not in ("", None) for r in rows)]
    return ("At a glance (ratios: engine / warp_sim on the same scene; speed > 1 means the engine is faster, "
            "penetration < 1 means it penetrates less):\n\n" + markdown_table(rows, present))


def section(name: str, data: dict, results_dir: Path, out_dir: Path, names: list[str]) -> str:
    title = TITLES.get(name)
    if title is None:
        if name.startswith("work_precision_"):
            title = f"Work-precision: {name[len('work_precision_'):]} (bench/work_precision.py)"
        elif name.startswith("stability_"):
            title = f"Stability: {name[len('stability_'):]} (bench/stability.py)"
        else:
            title = name
    source = Path(results_dir, data["source"]).resolve()
    shown = source.relative_to(ROOT) if source.is_relative_to(ROOT) else source
    parts = [f"## {title}\n", f"Source: `{shown}`  ", machine_line(data["machine"]) + "\n"]
    if data.get("error"):
        parts.append(f"_{data['error']}_\n")
    rows = data["rows"]
    failed = [r for r in rows if "status" in r and not str(r["status"]).startswith(("ok", "skipped")) and r["status"] != ""]
    if failed:
        parts.append(f"{len(failed)} of {len(rows)} rows did not pass (status column); they are not charted.\n")
    if name == "peers" and rows:
        parts.append(peers_glance(rows))
        parts.append("Full table:\n")
    columns, long_cols = split_columns(rows)
    parts.append(markdown_table(rows, columns))
    for c in long_cols:
        values = list(dict.fromkeys(str(r.get(c)) for r in rows if r.get(c) not in ("", None)))
        keyed = []
        for v in values:
            who = sorted({str(r.get("engine", r.get("method", r.get("config", "")))) for r in rows if str(r.get(c)) == v})
            keyed.append(f"- `{c}`{' (' + ', '.join(w for w in who if w) + ')' if any(who) else ''}: {v}")
        parts.append("\n".join(keyed) + "\n")
    summary = data.get("extra", {}).get("summary")
    if summary:
        text = json.dumps(_strip(summary), indent=1)
        if len(text) > 4000:
            text = text[:4000] + "\n... (truncated; see the JSON file)"
        parts.append("Summary from the file:\n\n```json\n" + text + "\n```\n")
    for png in pngs_for(name, results_dir, names):
        rel = os.path.relpath(png, out_dir)
        parts.append(f"![{png.stem}]({rel})\n")
    return "\n".join(parts)


def render(results_dir: Path, out: Path) -> str:
    results = load_results(results_dir)
    names = ordered_names(results)
    out_dir = Path(out).parent
    lines = ["# Benchmark report", "",
             ("Generated by `python bench/report.py` from the files in "
              f"`{os.path.relpath(results_dir, out_dir)}/`; rerun it after any benchmark.  Every figure below "
              "is what the files hold: a run whose final state failed the invalid-state gate "
              "(bench/common.py: finite values, unit quaternions, orthonormal rotations, penetration "
              "<= 1 cm, speed <= 100 m/s) is marked in its status column and never counted as fast."), "",
             "## Goals", "",
             "| Goal | Verdict | Measured |", "|---|---|---|"]
    for g in goals(results):
        lines.append(f"| {fmt(g['goal'])} | **{g['verdict']}** | {fmt(g['measured'])} |")
    lines += ["", "Files: " + (", ".join(f"[{n}](#{n})" for n in names) if names else "none found"), ""]
    for name in names:
        lines.append(f'<a id="{name}"></a>\n')
        lines.append(section(name, results[name], Path(results_dir), out_dir, names))
    text = "\n".join(lines).rstrip() + "\n"
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(text)
    return text


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--results-dir", type=Path, default=RESULTS)
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "REPORT.md")
    args = p.parse_args(argv)
    text = render(args.results_dir.resolve(), args.out.resolve())
    sections = text.count("\n## ") - 1
    print(f"wrote {args.out} ({sections} result sections)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
