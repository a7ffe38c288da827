"""Refused before allocating: memory beyond the machine, terrain float32 cannot evaluate, runs
whose length was never asked for, bad environment variables; each one line naming key and value."""

import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from warp_sim import FourierTerrain, ModelBuilder
from warp_sim.cli import main
from warp_sim import limits
from warp_sim.scene import SceneError, parse_scene

ROOT = Path(__file__).resolve().parents[1]
BALL = {"shape": "sphere", "radius": 0.1, "position": [0.0, 1.0, 0.0]}


def one_line(text: str):
    assert len(text.splitlines()) == 1 and "Traceback" not in text, text


def test_huge_layouts_are_refused_before_allocating():
    """count = 1e12 and base = 100000 used to allocate (21.8 TiB) or crash after 36 s."""
    started = time.perf_counter()
    with pytest.raises(SceneError) as e:
        parse_scene({"layout": [{"type": "grid", "count": 1000000000000}]}, "s.toml")
    one_line(str(e.value))
    assert str(e.value).startswith("s.toml: [[layout]] #1 (grid) count = 1000000000000 gives 1,000,000,000,000 "
                                   "bodies, which needs about ")
    assert "PiB of memory, more than this machine has available" in str(e.value)
    with pytest.raises(SceneError, match=r"\[\[layout\]\] #1 \(pyramid\) base = 100000 gives 5,000,050,000 bodies"):
        parse_scene({"layout": [{"type": "pyramid", "base": 100000}]}, "s.toml")
    with pytest.raises(SceneError, match=r"\(stack\) count = 10000000000 gives"):
        parse_scene({"layout": [{"type": "stack", "count": 10**10}]}, "s.toml")
    assert time.perf_counter() - started < 5.0  # nothing was built


def test_contact_capacity_and_checkpoints_are_estimated(tmp_path, capsys, monkeypatch):
    scene = parse_scene({"sim": {"contact_max": 10**12}, "body": [BALL, dict(BALL, position=[1.0, 1.0, 0.0])]})
    with pytest.raises(ValueError, match=r"^\[sim\] contact_max = 1000000000000: the run needs about [\d.]+ [TP]iB"):
        scene.build("cpu")
    box = {"shape": "box", "half_extents": [0.2, 0.2, 0.2], "position": [0.0, 1.0, 0.0]}
    scene = parse_scene({"terrain": {"kind": "plane", "checkpoints_per_edge": 1000}, "body": [box]})
    with pytest.raises(ValueError, match=r"^\[terrain\] checkpoints_per_edge = 1000 \(5,988,008 per box, 1 boxes\)"):
        limits.check_scene_memory(scene, available=1 << 30)
    # through the command line: one error line before anything is built
    path = tmp_path / "s.toml"
    path.write_text('[sim]\ncontact_max = 1000000000000\n[[body]]\nshape = "sphere"\nradius = 0.1\n'
                    '[[body]]\nshape = "sphere"\nradius = 0.1\nposition = [1.0, 0.0, 0.0]\n')
    assert main(["run", str(path), "--steps", "2", "--out", str(tmp_path / "r.npz"), "--quiet"]) == 2
    err = capsys.readouterr().err
    one_line(err)
    assert err.startswith("error: [sim] contact_max = 1000000000000: the run needs about")


def test_estimate_is_not_below_what_a_build_takes():
    """The per-body figures cover a real build (measured on the Model's host arrays alone here)."""
    b = ModelBuilder()
    n = 2000
    b.add_bodies("box", (0.1, 0.2, 0.3), position=np.arange(3 * n, dtype=float).reshape(n, 3))
    host = b.host_arrays(3)
    host_bytes = sum(a.nbytes for a in host.values() if isinstance(a, np.ndarray))
    assert limits.estimate_bytes(n, n, 3)["total"] > 3 * host_bytes


# within the [sim] bounds (dt >= 1e-6 s, substeps <= 4096, under 2^31 steps), still far too long
LONG_RUNS = {
    "tiny dt": ("dt = 1e-6\nduration = 50.0", "[sim] duration = 50 s at dt = 1e-06 s is 50,000,000 steps of 4 substeps"),
    "long duration": ("duration = 1e6", "[sim] duration = 1e+06 s at dt = 0.0166667 s is 60,000,000 steps"),
    "many substeps": ("substeps = 4096\nduration = 100.0", "is 6,000 steps of 4,096 substeps for 1 bodies, roughly"),
}


@pytest.mark.parametrize("line, message", LONG_RUNS.values(), ids=LONG_RUNS.keys())
def test_absurd_runs_need_steps_or_yes(tmp_path, capsys, line, message):
    path = tmp_path / "s.toml"
    path.write_text(f'[sim]\n{line}\n[[body]]\nshape = "sphere"\nradius = 0.1\n')
    assert main(["run", str(path), "--out", str(tmp_path / "r.npz"), "--quiet"]) == 2
    err = capsys.readouterr().err
    one_line(err)
    assert message in err and "pass --steps N to run part of it, or --yes to run it all" in err
    assert not (tmp_path / "r.npz").exists()


def test_confirmed_long_run_still_meets_the_disk_estimate(tmp_path, capsys):
    """--yes on 2e9 steps of dt = 1e-6 lists no 2e9 frames in memory: the disk estimate refuses it."""
    path = tmp_path / "s.toml"
    path.write_text('[sim]\ndt = 1e-6\nduration = 2000.0\n[[body]]\nshape = "sphere"\nradius = 0.1\n')
    assert main(["run", str(path), "--yes", "--out", str(tmp_path / "r.npz"), "--quiet"]) == 2
    err = capsys.readouterr().err
    one_line(err)
    assert "2,000,000,002 frames of 1 bodies take up to" in err and "--record-every" in err


def test_terrain_frequency_float32_cannot_evaluate_is_refused():
    """frequency = 1e30: the ball used to fall through with 0 mm penetration reported."""
    data = {"terrain": {"kind": "fourier", "frequency": 1e30}, "body": [dict(BALL, position=[0.0, 3.0, 0.0])]}
    with pytest.raises(SceneError) as e:
        parse_scene(data, "s.toml")
    one_line(str(e.value))
    assert "s.toml: [terrain] frequency = 1e+30 rad/m with 5 terms cannot be evaluated in float32" in str(e.value)
    assert "use frequency <= " in str(e.value)
    best = float(str(e.value).rsplit("<= ", 1)[1])
    data["terrain"]["frequency"] = best * 0.99
    parse_scene(data, "s.toml")  # just below the bound is accepted
    b = ModelBuilder()  # the Python API meets the same rule at finalize
    b.set_terrain(FourierTerrain(frequency=1e30))
    b.add_sphere(0.1, position=(0, 3, 0))
    with pytest.raises(ValueError, match="terrain frequency = 1e\\+30 rad/m"):
        b.finalize("cpu")


def test_bumps_between_box_checkpoints_are_named():
    b = ModelBuilder()
    b.set_terrain(FourierTerrain(frequency=8.0, amplitude=0.3))
    b.add_box((0.5, 0.5, 0.5), position=(0, 3, 0))
    with pytest.warns(UserWarning, match=r"fit between box checkpoints 0.5 m apart.*checkpoints_per_edge >= \d+"):
        b.host_arrays(3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the shipped terrain resolves a 0.25 m box with 3 per edge
        b = ModelBuilder()
        b.set_terrain(FourierTerrain())
        b.add_box((0.25, 0.25, 0.25), position=(0, 3, 0))
        b.host_arrays(3)


def test_bad_thread_count_is_one_line(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[[body]]\nshape = "sphere"\nradius = 0.1\n')
    env = {**os.environ, "WARP_SIM_CPU_THREADS": "abc", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "warp_sim", "run", str(path), "--steps", "1", "--out",
                           str(tmp_path / "r.npz")], env=env, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1] == "error: WARP_SIM_CPU_THREADS must be a positive integer, got 'abc'"
    assert "Traceback" not in done.stderr


DEMO_ERRORS = {
    "screenshot dir": (["--screenshot", "{tmp}"], "is a directory"),
    "screenshot suffix": (["--screenshot", "{tmp}/x.jpg"], "--screenshot must be a .png file"),
    "screenshot missing dir": (["--screenshot", "{tmp}/no/x.png"], "does not exist"),
    "screenshot unwritable": (["--screenshot", "/sys/x.png"], "--screenshot: cannot write '/sys/x.png'"),
    "record file": (["--record", "{tmp}/file"], "--record must be a directory, got the file"),
    "record unwritable": (["--record", "/sys/frames"], "--record: cannot write '/sys/frames'"),
    "device": (["--device", "gpu"], "--device must be cpu, cuda or cuda:N, got 'gpu'"),
    "frames": (["--frames", "0"], "--frames must be an integer >= 1, got 0"),
}


@pytest.mark.parametrize("flags, message", DEMO_ERRORS.values(), ids=DEMO_ERRORS.keys())
def test_demo_flags_are_checked_before_rendering(tmp_path, capsys, monkeypatch, flags, message):
    from warp_sim import demo

    if any(f.startswith("/sys") for f in flags) and not os.path.isdir("/sys"):
        pytest.skip("needs a read-only /sys")
    (tmp_path / "file").write_text("x")
    monkeypatch.setitem(sys.modules, "render.viewer", None)  # rendering would fail loudly: never reached
    assert demo.main([f.format(tmp=tmp_path) for f in flags]) == 2
    err = capsys.readouterr().err
    one_line(err)
    assert err.startswith("error: ") and message in err


def test_demo_without_a_gpu_says_so(capsys, monkeypatch):
    from warp_sim import demo

    monkeypatch.setattr("warp.get_cuda_device_count", lambda: 0)
    monkeypatch.setitem(sys.modules, "render.viewer", None)
    assert demo.main(["--device", "cuda"]) == 2
    err = capsys.readouterr().err
    one_line(err)
    assert "device 'cuda' is not available (0 CUDA devices found); try --device cpu" in err


def test_demo_bad_thread_count_is_one_line(capsys, monkeypatch):
    from warp_sim import demo

    monkeypatch.setenv("WARP_SIM_CPU_THREADS", "0")
    monkeypatch.setitem(sys.modules, "render.viewer", None)
    assert demo.main([]) == 2
    assert capsys.readouterr().err == "error: WARP_SIM_CPU_THREADS must be a positive integer, got '0'\n"


def test_in_memory_run_refuses_frames_it_cannot_hold():
    from warp_sim import SimConfig, Simulator
    from warp_sim.run import run

    b = ModelBuilder()
    b.add_sphere(0.1)
    sim = Simulator(b.finalize("cpu"), SimConfig())
    with pytest.raises(ValueError, match=r"^steps = 5000000000000 with record_every = 1 \(5,000,000,000,002 frames"):
        run(sim, 5 * 10**12, progress=False)
    assert sim.step_count == 0
