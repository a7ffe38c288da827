"""Shared benchmark plumbing: machine description, the invalid-state gate, result files."""

from __future__ import annotations

import csv
import json
import os
import platform
from pathlib import Path

import numpy as np
import warp as wp

RESULTS = Path(__file__).resolve().parent / "results"


def machine_info(device: str) -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    dev = wp.get_device(device)
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "device": device,
        "device_name": dev.name if dev.is_cuda else "cpu",
        "warp": wp.__version__,
        "python": platform.python_version(),
    }


def run_child(command: list[str]) -> dict:
    """Run a benchmark's child process and return the JSON object on its last ``{`` line, or a
    ``status`` naming the failure (the child's last stderr line): each timed run in a fresh process."""
    import subprocess

    out = subprocess.run(command, capture_output=True, text=True)
    lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
    if out.returncode != 0 or not lines:
        return {"status": f"failed: {(out.stderr.strip().splitlines() or ['no output'])[-1]}"}
    return json.loads(lines[-1])


def finish_report(summary_lines: list[str], csv_path: Path, rows: list[dict]) -> int:
    """The end of a back-to-back benchmark: its medians, where it wrote, and the exit status (1 when
    any run failed)."""
    print("medians over the repeats:")
    for line in summary_lines:
        print(line)
    print(f"wrote {csv_path} (.json, .png)")
    return 0 if all(r["status"] == "ok" for r in rows) else 1


def state_gate(sim, depth_slop: float = 0.01, speed_bound: float = 100.0) -> str:
    """'' when the state is valid, else the reason (Newton-style invalid-state check).

    Finite values, unit quaternions, orthonormal matrices (unless the scene asked for the raw
    ``matrix`` mode), no body deeper than ``depth_slop`` in the terrain, no speed above the bound.
    """
    s = sim.state
    pos, quat, rot, vel = (a.numpy() for a in (s.body_pos, s.body_quat, s.body_rot, s.body_vel))
    if not all(np.isfinite(a).all() for a in (pos, quat, rot, vel)):
        return "non-finite state"
    if np.abs(np.linalg.norm(quat, axis=1) - 1.0).max() > 1e-4:
        return "quaternion not unit"
    if sim.config.rotation != "matrix":
        err = np.abs(np.einsum("nji,njk->nik", rot, rot) - np.eye(3)).max()
        if err > 1e-4:
            return f"rotation not orthonormal ({err:.2g})"
    depth = sim.max_penetration()
    if depth > depth_slop:
        return f"penetration {depth:.3g} m > {depth_slop} m"
    speed = np.linalg.norm(vel, axis=1).max() if len(vel) else 0.0
    if speed > speed_bound:
        return f"speed {speed:.3g} m/s > {speed_bound} m/s"
    return ""


def write_rows(name: str, rows: list[dict], meta: dict, out_dir: Path | None = None) -> tuple[Path, Path]:
    out_dir = Path(out_dir) if out_dir is not None else RESULTS
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path = out_dir / f"{name}.csv"
    with csv_path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        writer.writeheader()
        writer.writerows(rows)
    json_path = out_dir / f"{name}.json"
    json_path.write_text(json.dumps({"machine": meta, "rows": rows}, indent=2))
    return csv_path, json_path


QUICK_LABEL = "QUICK smoke run: tiny sizes, not comparable with bench/results"


def output_dir(out_dir, quick: bool, bench: str) -> Path:
    """Where a run writes: ``--out-dir``, else bench/results; a ``--quick`` run never writes there.

    Quick runs without ``--out-dir`` go to a new temporary folder (printed), so a smoke run cannot
    overwrite the committed results, and every chart they save says it was quick.
    """
    if not quick:
        return Path(out_dir) if out_dir is not None else RESULTS
    if out_dir is None:
        import tempfile

        folder = Path(tempfile.mkdtemp(prefix=f"warp_sim_{bench}_quick_"))
        print(f"--quick: writing to {folder} (bench/results keeps the committed full runs)")
        out_dir = folder
    elif Path(out_dir).resolve() == RESULTS.resolve():
        raise SystemExit(f"error: --quick results may not go to {RESULTS} (it holds the committed full runs); "
                         "give another --out-dir or none")
    label_quick_charts()
    return Path(out_dir)


def label_quick_charts():
    """Every figure saved from now on carries QUICK_LABEL across its top."""
    from matplotlib.figure import Figure

    if getattr(Figure.savefig, "_quick_label", False):
        return
    original = Figure.savefig

    def savefig(self, *args, **kwargs):
        if not getattr(self, "_quick_labelled", False):
            self.text(0.5, 0.999, QUICK_LABEL, ha="center", va="top", fontsize=9, color="#c0392b",
                      fontweight="bold")
            self._quick_labelled = True
        return original(self, *args, **kwargs)

    savefig._quick_label = True
    Figure.savefig = savefig
