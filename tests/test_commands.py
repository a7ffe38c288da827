"""validate, info, --version and --verbose of ``python -m warp_sim``."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from warp_sim.cli import main
from warp_sim.commands import STEP_COST, array_bytes, expected_step_seconds

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "examples" / "scenes").glob("*.toml"))

MIXED = """
[sim]
substeps = 3
[terrain]
kind = "plane"
[[layout]]
type = "grid"
count = 12
shape = "mix"
sphere_fraction = 0.25
[[body]]
shape = "box"
half_extents = [5.0, 0.1, 5.0]
static = true
"""


@pytest.mark.parametrize("scene", SCENES, ids=[s.stem for s in SCENES])
def test_validate_shipped_scenes(scene, capsys):
    assert main(["validate", str(scene)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 1 and out[0].startswith(f"{scene}: OK, ")


def test_validate_bad_scene_is_one_error_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[body]]\nshape = "cone"\n')
    assert main(["validate", str(bad)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert len(captured.err.splitlines()) == 1 and captured.err.startswith(f"error: {bad}: [[body]] #1 shape")
    assert "'cone'" in captured.err


def test_info_counts_and_cost(tmp_path, capsys):
    path = tmp_path / "mixed.toml"
    path.write_text(MIXED)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "13: 3 spheres, 10 boxes (1 static)" in out
    # 9 moving boxes x 8 corner checkpoints (plane: 2 per edge) + 1 static box x 8 + 3 spheres
    assert "83 terrain checkpoints (2 per box edge)" in out
    cost = expected_step_seconds(3, 9, 3, True)
    assert f"~{cost * 1e3:,.3g} ms a step" in out
    assert "MiB of Warp arrays" in out


def test_cost_model_scales_with_bodies_and_substeps():
    one = expected_step_seconds(1000, 0, 1, False)
    assert one == pytest.approx(1000 * STEP_COST[("terrain", "sphere")])
    assert expected_step_seconds(2000, 0, 4, False) == pytest.approx(8 * one)
    # boxes on the terrain cost more than spheres (26 checkpoints against one query)
    assert expected_step_seconds(0, 1000, 1, False) > one


def test_memory_grows_with_bodies():
    from warp_sim.scene import parse_scene

    def memory(count):
        scene = parse_scene({"layout": [{"type": "grid", "count": count}]})
        return array_bytes(scene.build("cpu"))

    small, large = memory(100), memory(400)
    # per-body arrays dominate: four times the bodies, between 2x and 4x the bytes (fixed parts)
    assert 2.0 * small < large <= 4.0 * small


def run_module(*args, cwd):
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "warp_sim", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300, check=False)


def test_version(tmp_path):
    done = run_module("--version", cwd=tmp_path)
    assert done.returncode == 0
    assert done.stdout.startswith("warp_sim ") and "(warp 1." in done.stdout


def test_quiet_unless_verbose(tmp_path):
    """Warp's banner (and, without a CUDA driver, its driver warning) only with --verbose."""
    scene = str(ROOT / "examples" / "scenes" / "bounce.toml")
    quiet = run_module("run", scene, "--steps", "2", "--out", "q.npz", cwd=tmp_path)
    assert quiet.returncode == 0, quiet.stderr
    assert "Warp" not in quiet.stderr + quiet.stdout, quiet.stderr
    assert "wrote q.npz" in quiet.stderr
    loud = run_module("run", scene, "--steps", "2", "--out", "v.npz", "--verbose", cwd=tmp_path)
    assert loud.returncode == 0, loud.stderr
    assert "Warp 1." in loud.stdout + loud.stderr and "initialized" in loud.stdout + loud.stderr


def test_first_compile_is_announced_once(tmp_path):
    """An empty kernel cache: one "compiling kernels" line; the same cache again: none."""
    env = {**os.environ, "WARP_CACHE_PATH": str(tmp_path / "cache"),
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    probe = str(ROOT / "tests" / "compile_probe.py")
    runs = [subprocess.run([sys.executable, probe], env=env, capture_output=True, text=True, timeout=300)
            for _ in range(2)]
    for done in runs:
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == "4.0"
    first = [line for line in runs[0].stderr.splitlines() if line.strip()]
    assert len(first) == 1 and first[0].startswith("compiling kernels (first run, ~") and first[0].endswith(" s)…")
    assert "compiling" not in runs[1].stderr
