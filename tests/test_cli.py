"""The command line: a run writes every array, and every failure is one `error:` line with status 2."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from warp_sim.cli import main
from warp_sim.recording import load_run
from warp_sim.run import format_summary, record_steps, run
from warp_sim.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]

TINY = """
name = "tiny"
[sim]
dt = 0.01
substeps = 2
[terrain]
kind = "fourier"
terms = 3
[[body]]
shape = "sphere"
radius = 0.2
position = [0.0, 2.0, 0.0]
[[layout]]
type = "stack"
count = 2
position = [1.0, 0.5]
"""

BODY_ARRAYS = {"position": 3, "orientation": 4, "velocity": 3, "angular_velocity": 3}
FRAME_ARRAYS = ("time", "kinetic_energy", "max_penetration", "contact_count")
TERRAIN_KEYS = ("terrain_kind", "terrain_amplitudes", "terrain_phases", "terrain_frequency", "terrain_scale",
                "terrain_offset")


@pytest.fixture
def tiny(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def write(tmp_path, text: str) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


def test_run_writes_every_array(tiny, tmp_path, capsys):
    """Frames at 0, 2, 4 and the last step 5; per-body and per-frame arrays have matching shapes."""
    out = tmp_path / "run.npz"
    assert main(["run", str(tiny), "--out", str(out), "--steps", "5", "--record-every", "2", "--quiet"]) == 0
    captured = capsys.readouterr()
    lines = captured.out.splitlines()
    assert len(lines) == 1 and lines[0].startswith("steps 5 | ") and "body-steps/s" in lines[0]
    assert captured.err == ""

    with np.load(out) as data:  # no pickled objects: loads with allow_pickle=False
        frames, bodies = 4, 3
        for key, width in BODY_ARRAYS.items():
            assert data[key].shape == (frames, bodies, width), key
            assert np.isfinite(data[key]).all(), key
        for key in FRAME_ARRAYS:
            assert data[key].shape == (frames,), key
        np.testing.assert_allclose(data["time"], [0.0, 0.02, 0.04, 0.05])
        np.testing.assert_array_equal(data["shape"], [0, 1, 1])
        assert data["size"].shape == (bodies, 3)
        np.testing.assert_allclose(data["size"][0], [0.2, 0.0, 0.0])
        for key in TERRAIN_KEYS:
            assert key in data.files, key
        assert str(data["terrain_kind"]) == "fourier"
        np.testing.assert_allclose(np.linalg.norm(data["orientation"], axis=-1), 1.0, atol=1e-5)
        summary = json.loads(str(data["summary"]))
    assert summary["steps"] == 5 and summary["bodies"] == 3 and summary["timed_steps"] == 4
    assert summary["steps_per_s"] > 0
    assert summary["body_steps_per_s"] == pytest.approx(3 * summary["steps_per_s"])
    assert summary["scene"] == "tiny" and summary["integrator"] == "semi_implicit"
    assert lines[0] == format_summary(summary)


def test_progress_and_default_duration(tiny, tmp_path, capsys):
    """Without --steps the scene's duration sets the length; off a terminal a final line replaces the bar."""
    path = write(tmp_path, TINY.replace("substeps = 2", "substeps = 2\nduration = 0.03"))
    out = tmp_path / "out"  # .npz is appended
    assert main(["run", str(path), "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("steps 3 |")
    assert "3 steps" in captured.err and f"wrote {out}.npz" in captured.err
    with np.load(f"{out}.npz") as data:
        assert data["time"].shape == (4,)
    assert main(["run", str(path), "--out", str(out), "--duration", "0.05", "--quiet"]) == 0
    assert capsys.readouterr().out.startswith("steps 5 |")


def test_run_function_records_the_plane_and_no_terrain(tmp_path):
    """run() returns the terrain record of each kind and frames at the requested steps."""
    assert record_steps(7, 3) == [0, 3, 6, 7]
    path = write(tmp_path, '[terrain]\nkind = "plane"\n[[body]]\nshape = "box"\n'
                           'half_extents = [0.1, 0.1, 0.1]\nposition = [0, 0.1, 0]\n')
    result = run(load_scene(path).build("cpu"), 3, progress=False)
    assert result["terrain_kind"] == "plane" and result["position"].shape == (4, 1, 3)
    assert result["contact_count"][-1] > 0
    path = write(tmp_path, '[[body]]\nshape = "sphere"\nradius = 0.1\n')
    result = run(load_scene(path).build("cpu"), 1, progress=False)
    assert result["terrain_kind"] == "none"
    assert result["summary"]["steps_per_s"] is None  # the only step is the untimed warm-up
    assert "n/a steps/s" in format_summary(result["summary"])


def test_format_summary():
    line = format_summary({"steps": 600, "steps_per_s": 2345.4, "body_steps_per_s": 23450000.0,
                           "final_kinetic_energy": 1.2e-05, "max_penetration": 0.00031})
    assert line == ("steps 600 | 2,345 steps/s | 23,450,000 body-steps/s | final KE 1.2e-05 J | "
                    "max penetration 0.31 mm")


BAD_RUNS = {
    "scene error": ('[sim]\ndt = -0.01\n[[body]]\nshape = "sphere"\nradius = 0.1\n', [],
                    "[sim] dt must be a number in [1e-06, 1], got -0.01"),
    "toml syntax": ("[sim\n", [], "TOML syntax error"),
    "missing file": (None, [], "cannot read scene file"),
    "zero steps": (TINY, ["--steps", "0"], "--steps must be an integer >= 1, got 0"),
    "negative duration": (TINY, ["--duration", "-1"], "--duration must be a positive finite number"),
    "nan duration": (TINY, ["--duration", "nan"], "--duration must be a positive finite number"),
    "zero record every": (TINY, ["--record-every", "0"], "--record-every must be an integer >= 1, got 0"),
    "bad device": (TINY, ["--device", "gpu"], "--device must be cpu, cuda or cuda:N, got 'gpu'"),
    "missing out directory": (TINY, ["--out", "no/such/dir/run.npz"],
                              "directory 'no/such/dir' does not exist"),
    "duration past any step count": (TINY, ["--duration", "1e308"], "is inf steps, more than 2,147,483,647"),
    "empty device": (TINY, ["--device", ""], "--device must be cpu, cuda or cuda:N, got ''"),
    "substeps by the billion": ('[sim]\nsubsteps = 2147483648\n[[body]]\nshape = "sphere"\nradius = 0.1\n', [],
                                "[sim] substeps must be an integer in [1, 4096], got 2147483648"),
}


@pytest.mark.parametrize("text, flags, message", BAD_RUNS.values(), ids=BAD_RUNS.keys())
def test_bad_input_is_one_error_line(tmp_path, capsys, text, flags, message):
    """Each failure before the run prints exactly one `error:` line on stderr and returns 2."""
    path = tmp_path / "scene.toml"
    if text is not None:
        path.write_text(text)
    assert main(["run", str(path), "--quiet", "--out", str(tmp_path / "run.npz"), *flags]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("error: ") and "Traceback" not in err
    assert message in err


def test_usage_error_returns_2(tiny, capsys):
    """--steps and --duration exclude each other; argparse reports it with status 2."""
    assert main(["run", str(tiny), "--steps", "2", "--duration", "1"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_non_finite_run_names_body_and_step(tmp_path, capsys):
    """A gravity of 3e38 m/s^2 (a float32, but its products overflow) makes every body non-finite
    in the first step: exit 2, naming the first body, the step and the [[body]] table it came
    from.  (Starting speeds that overflow are refused at build: test_validation.)"""
    second = '[[body]]\nshape = "sphere"\nradius = 0.1\nposition = [3.0, 2.0, 0.0]\n'
    text = TINY.replace("[[layout]]", second + "[[layout]]").replace("substeps = 2", "substeps = 2\n"
                                                                     "gravity = [3.0e38, 0.0, 0.0]")
    path = write(tmp_path, text)
    assert main(["run", str(path), "--steps", "5", "--quiet", "--out", str(tmp_path / "r.npz")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith(f"error: {path}: body 0 (sphere) became non-finite at step 1")
    assert "[[body]] #1" in err and "bodies 1, 2, 3" in err
    # the frames before the failure are kept, and the file says where and why the run stopped
    run = load_run(tmp_path / "r.npz")
    assert run["summary"]["stop_reason"] == "non_finite" and run["summary"]["stop_step"] == 1
    assert "became non-finite at step 1" in run["summary"]["stop_detail"]
    assert run["time"].tolist() == [0.0] and run["position"].shape == (1, 4, 3)


def run_module(*args, cwd):
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "warp_sim", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300, check=False)


def test_module_entry_point(tiny, tmp_path):
    """`python -m warp_sim run` works as a program: summary on stdout, .npz written, status 0;
    a bad scene gives status 2 and a single error line."""
    done = run_module("run", str(tiny), "--steps", "3", "--out", "run.npz", "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("steps 3 | ")
    assert (tmp_path / "run.npz").exists()

    bad = write(tmp_path, '[[body]]\nshape = "sphere"\nradius = 0.1\nmass = true\n')
    done = run_module("run", str(bad), cwd=tmp_path)
    assert done.returncode == 2
    expected = f"error: {bad}: [[body]] #1 mass must be a positive finite number, got true"
    assert done.stderr.splitlines() == [expected]


def test_one_file_for_two_jobs_is_refused(tiny, tmp_path, capsys):
    """The recording overwrote a checkpoint written to the same file (resuming then failed with
    'info is not a file in the archive'), and a run resumed into its own checkpoint destroyed it."""
    out = tmp_path / "run.npz"
    assert main(["run", str(tiny), "--quiet", "--steps", "2", "--checkpoint-every", "1", "--checkpoint", str(out),
                 "--out", str(out)]) == 2
    assert "--checkpoint and --out name the same file" in capsys.readouterr().err
    check = tmp_path / "run.checkpoint.npz"
    assert main(["run", str(tiny), "--quiet", "--steps", "2", "--checkpoint-every", "1", "--out", str(out)]) == 0
    assert main(["run", str(tiny), "--quiet", "--steps", "4", "--resume", str(check), "--out", str(check)]) == 2
    assert "--resume and --out name the same file" in capsys.readouterr().err
    assert check.exists()


@pytest.mark.parametrize("edit, message", [
    (lambda info, arrays: info.update(step_count="abc"), "field step_count must be an integer >= 0, got 'abc'"),
    (lambda info, arrays: info.update(step_count=-7), "field step_count must be an integer >= 0, got -7"),
    (lambda info, arrays: info.pop("scene_text"), "field scene_text must be the scene's text, got None"),
    (lambda info, arrays: arrays.pop("array_000"), "lacks the state array 'array_000'"),
])
def test_an_edited_checkpoint_is_named_not_a_traceback(tiny, tmp_path, capsys, edit, message):
    """Edited checkpoints gave KeyError and AttributeError tracebacks, or resumed from step -7."""
    out = tmp_path / "run.npz"
    assert main(["run", str(tiny), "--quiet", "--steps", "2", "--checkpoint-every", "1", "--out", str(out)]) == 0
    check = tmp_path / "run.checkpoint.npz"
    with np.load(check) as data:
        info = json.loads(str(data["info"]))
        arrays = {key: data[key] for key in data.files if key != "info"}
    edit(info, arrays)
    np.savez(check, info=np.asarray(json.dumps(info)), **arrays)
    capsys.readouterr()
    assert main(["run", "--quiet", "--steps", "4", "--resume", str(check), "--out", str(tmp_path / "r2.npz")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and message in err, err


def test_a_scene_with_a_byte_order_mark_runs(tmp_path, capsys):
    """Some editors start UTF-8 files with a BOM, which TOML does not allow: it was refused as
    'Invalid statement (at line 1, column 1)'."""
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + TINY.encode())
    assert main(["run", str(path), "--quiet", "--steps", "2", "--out", str(tmp_path / "r.npz")]) == 0
