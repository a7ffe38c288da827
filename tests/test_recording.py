"""Run files: streamed in chunks, finished whatever stops the run, read back by load_run;
checkpoints resume bit for bit; provenance in every file; the output path checked first."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

from warp_sim.cli import main
from warp_sim.recording import FRAME_KEYS, RunWriter, chunk_dir, chunk_files, load_run
from warp_sim.run import format_rate, format_summary, run, static_record
from warp_sim.scene import load_scene

MIX = """
name = "mix"
[sim]
dt = 0.01
substeps = 2
sleep_time = 0.05
[terrain]
kind = "fourier"
terms = 3
[[layout]]
type = "grid"
count = [3, 2, 3]
shape = "mix"
random_orientation = true
spacing = 0.9
clearance = 0.05
[[layout]]
type = "stack"
count = 3
position = [3.0, 0.0]
"""

RUN_KEYS = {"time", "position", "orientation", "velocity", "angular_velocity", "kinetic_energy", "max_penetration",
            "contact_count", "shape", "size", "terrain_kind", "terrain_amplitudes", "terrain_phases",
            "terrain_frequency", "terrain_scale", "terrain_offset", "summary", "metadata"}
COMPARED = ("time", "position", "orientation", "velocity", "angular_velocity", "kinetic_energy", "max_penetration",
            "contact_count")


@pytest.fixture
def mix(tmp_path) -> Path:
    path = tmp_path / "mix.toml"
    path.write_text(MIX)
    return path


def test_resume_is_bit_identical(mix, tmp_path):
    """40 steps straight equal 20 steps, a checkpoint, and 20 resumed steps, bit for bit (bodies
    fall asleep before the checkpoint, so sleep timers and pair warm starts are in it)."""
    a, b, c = (tmp_path / f"{n}.npz" for n in "abc")
    assert main(["run", str(mix), "--steps", "40", "--out", str(a), "--quiet"]) == 0
    assert main(["run", str(mix), "--steps", "20", "--checkpoint-every", "10", "--out", str(b), "--quiet"]) == 0
    checkpoint = tmp_path / "b.checkpoint.npz"
    assert checkpoint.is_file()
    with np.load(checkpoint, allow_pickle=False) as data:  # plain arrays, no pickle
        assert json.loads(str(data["info"]))["step_count"] == 20
    assert main(["run", "--resume", str(checkpoint), "--steps", "40", "--out", str(c), "--quiet"]) == 0
    straight, first, resumed = load_run(a), load_run(b), load_run(c)
    assert resumed["summary"]["start_step"] == 20 and resumed["summary"]["stop_step"] == 40
    assert resumed["metadata"]["resumed_from"] == str(checkpoint)
    for key in COMPARED:
        np.testing.assert_array_equal(straight[key][:21], first[key], err_msg=key)
        np.testing.assert_array_equal(straight[key][20:], resumed[key], err_msg=key)
    # a resumed run with a record interval records the same steps as a straight one
    d = tmp_path / "d.npz"
    assert main(["run", "--resume", str(checkpoint), "--steps", "40", "--record-every", "7", "--out", str(d),
                 "--quiet"]) == 0
    np.testing.assert_allclose(load_run(d)["time"], [0.2, 0.21, 0.28, 0.35, 0.4])
    np.testing.assert_array_equal(load_run(d)["position"], straight["position"][[20, 21, 28, 35, 40]])


def test_resume_refuses_another_scene(mix, tmp_path, capsys):
    assert main(["run", str(mix), "--steps", "4", "--checkpoint-every", "2", "--out", str(tmp_path / "b.npz"),
                 "--quiet"]) == 0
    other = tmp_path / "other.toml"
    other.write_text(MIX.replace("count = 3\n", "count = 4\n"))
    code = main(["run", str(other), "--resume", str(tmp_path / "b.checkpoint.npz"), "--steps", "8",
                 "--out", str(tmp_path / "c.npz"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.splitlines()) == 1 and "another scene" in err
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    assert main(["run", "--resume", str(tmp_path / "junk.npz"), "--out", str(tmp_path / "c.npz")]) == 2
    assert "not a readable checkpoint file" in capsys.readouterr().err


def test_load_run_keys_and_provenance(mix, tmp_path):
    out = tmp_path / "run.npz"
    assert main(["run", str(mix), "--steps", "3", "--out", str(out), "--quiet"]) == 0
    r = load_run(out)
    assert set(r) == RUN_KEYS
    assert r["terrain_kind"] == "fourier" and isinstance(r["terrain_frequency"], float)
    assert r["position"].shape == (4, 21, 3) and r["position"].dtype == np.float32
    assert r["summary"]["stop_reason"] == "completed" and r["summary"]["steps"] == 3
    meta = r["metadata"]
    assert meta["scene_text"] == MIX and meta["seed"] == 0
    assert meta["settings"]["dt"] == 0.01 and meta["settings"]["substeps"] == 2
    assert meta["warp_version"] and meta["warp_sim_version"] and meta["device"] == "cpu"
    assert meta["machine"]["platform"] and meta["machine"]["cpu"]
    with np.load(out, allow_pickle=False) as data:  # the summary is also a JSON string in the file
        assert json.loads(str(data["summary"])) == r["summary"]
    # the in-memory API returns the same keys but the metadata
    mem = run(load_scene(mix).build("cpu"), 3, progress=False)
    assert set(mem) == RUN_KEYS - {"metadata"}
    for key in COMPARED:
        np.testing.assert_array_equal(mem[key], r[key], err_msg=key)


def test_load_run_reads_the_format_before_streaming(tmp_path):
    """A file as the runner wrote it before (savez_compressed, summary JSON, no metadata)."""
    path = tmp_path / "old.npz"
    f, n = 3, 2
    np.savez_compressed(path, summary=json.dumps({"steps": 2}), time=np.arange(f, dtype=np.float64),
                        position=np.ones((f, n, 3), np.float32), orientation=np.zeros((f, n, 4), np.float32),
                        velocity=np.zeros((f, n, 3), np.float32), angular_velocity=np.zeros((f, n, 3), np.float32),
                        kinetic_energy=np.zeros(f), max_penetration=np.zeros(f), contact_count=np.zeros(f, np.int32),
                        shape=np.zeros(n, np.int32), size=np.ones((n, 3), np.float32), terrain_kind="none")
    r = load_run(path)
    assert r["summary"] == {"steps": 2} and r["metadata"] == {} and r["terrain_kind"] == "none"
    assert r["position"].shape == (f, n, 3)


def _writer(sim, path, chunk_frames):
    return RunWriter(path, sim.model.body_count, static_record(sim), {"note": "test"}, chunk_frames=chunk_frames)


def test_interrupt_keeps_every_frame(mix, tmp_path):
    """Ctrl-C at step 7 of 20: the finished file holds frames 0..7, written in chunks of 3."""
    sim = load_scene(mix).build("cpu")
    out = tmp_path / "run.npz"
    writer = _writer(sim, out, 3)

    def interrupt(s):
        if s.step_count == 7:
            assert len(list(chunk_dir(out).glob("chunk_*.npz"))) == 2  # frames 0..5 already on disk
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(sim, 20, progress=False, writer=writer, checkpoint_every=1, on_checkpoint=interrupt)
    r = load_run(out)
    assert not chunk_dir(out).exists()
    assert r["summary"]["stop_reason"] == "interrupted" and r["summary"]["stop_step"] == 7
    np.testing.assert_allclose(r["time"], np.arange(8) * 0.01)
    assert r["metadata"] == {"note": "test"}


def test_a_killed_run_is_still_readable(mix, tmp_path):
    """A process killed mid-run leaves whole chunks; load_run reads them and says "incomplete"."""
    sim = load_scene(mix).build("cpu")
    out = tmp_path / "run.npz"
    writer = _writer(sim, out, 2)
    for _ in range(5):
        frame = {key: 0.0 for key in FRAME_KEYS}
        for key in ("position", "velocity", "angular_velocity"):
            frame[key] = sim.state.body_pos.numpy().copy()
        frame["orientation"] = sim.state.body_quat.numpy().copy()
        writer.add(frame)
    (chunk_dir(out) / "chunk_000002.npz.tmp.npz").write_bytes(b"half written")  # the kill hit mid-write
    r = load_run(out)  # no out file yet: read from the chunks
    assert r["summary"]["stop_reason"] == "incomplete" and r["position"].shape == (4, 21, 3)
    assert r["metadata"] == {"note": "test"} and r["terrain_kind"] == "fourier"


OUT_ERRORS = {
    "suffix": ("x.txt", "--out must be an .npz file, got"),
    "directory": (".", "is a directory"),
    "missing directory": ("no/such/dir/run.npz", "directory 'no/such/dir' does not exist"),
    # numpy appended .npz and left '/dev/null.npz' behind
    "device": ("/dev/null", "--out '/dev/null' is not a regular file (a device or a pipe)"),
}


@pytest.mark.parametrize("out, message", OUT_ERRORS.values(), ids=OUT_ERRORS.keys())
def test_output_path_checked_before_simulating(mix, tmp_path, capsys, monkeypatch, out, message):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("warp_sim.scene.Scene.build", lambda *a, **k: pytest.fail("simulated before the check"))
    assert main(["run", str(mix), "--out", out, "--steps", "2", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("error: ") and message in err


@pytest.mark.skipif(not os.path.isdir("/sys"), reason="needs a read-only /sys")
def test_unwritable_output_is_refused_first(mix, capsys, monkeypatch):
    monkeypatch.setattr("warp_sim.scene.Scene.build", lambda *a, **k: pytest.fail("simulated before the check"))
    assert main(["run", str(mix), "--out", "/sys/rain.npz", "--steps", "2", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --out: cannot write '/sys/rain.npz'") and len(err.splitlines()) == 1


def test_rates_have_three_significant_figures():
    assert format_rate(0.41234) == "0.412" and format_rate(12.345) == "12.3" and format_rate(2345.4) == "2,345"
    assert format_rate(0.0001234) == "0.000123"
    line = format_summary({"steps": 3, "steps_per_s": 0.412, "body_steps_per_s": 4.12, "final_kinetic_energy": 1.0,
                           "max_penetration": 0.0, "stop_reason": "interrupted", "stop_step": 3})
    assert "0.412 steps/s" in line and "4.12 body-steps/s" in line and "stopped: interrupted at step 3" in line


def test_ctrl_c_on_the_command_line_keeps_the_frames(mix, tmp_path, capsys, monkeypatch):
    """Ctrl-C during step 6: exit 130, one line saying where the frames are, and the file has them."""
    from warp_sim.simulator import Simulator

    step = Simulator.step

    def interrupted_step(self, count=1, check=True):
        if self.step_count >= 5:
            raise KeyboardInterrupt
        step(self, count, check)

    monkeypatch.setattr(Simulator, "step", interrupted_step)
    out = tmp_path / "run.npz"
    assert main(["run", str(mix), "--steps", "50", "--out", str(out), "--quiet"]) == 130
    err = capsys.readouterr().err
    assert err == f"error: interrupted; frames up to step 5 are in '{out}'\n"
    r = load_run(out)
    assert r["summary"]["stop_reason"] == "interrupted" and len(r["time"]) == 6


def test_simulator_refuses_a_contact_capacity_it_cannot_allocate():
    from warp_sim import ModelBuilder, SimConfig, Simulator

    b = ModelBuilder()
    b.add_sphere(0.1)
    b.add_sphere(0.1, position=(1, 0, 0))
    with pytest.raises(ValueError, match=r"^SimConfig contact_max = 1000000000000: the simulator needs about"):
        Simulator(b.finalize("cpu"), SimConfig(contact_max=10**12))


def _default_sigint():
    """In the child: SIGINT back to its default action.  A test run started in the background of a
    non-interactive shell (nohup ... &) inherits SIGINT ignored, Python then leaves it ignored, and
    the Ctrl-C below would never arrive."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start_long_run(scene: Path, out: Path):
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root)}
    return subprocess.Popen([sys.executable, "-m", "warp_sim", "run", str(scene), "--steps", "1000000", "--out",
                             str(out), "--quiet"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_default_sigint)


def _wait_for_chunks(out: Path, proc, count: int = 1):
    import time

    deadline = time.monotonic() + 120
    # whole chunks only: a kill while only a chunk being written existed left nothing to read
    while len(chunk_files(chunk_dir(out))) < count:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no chunk was written"
        time.sleep(0.05)


@pytest.mark.parametrize("sig", ["SIGINT", "SIGKILL"])
def test_a_real_signal_keeps_the_frames(tmp_path, sig):
    """A real Ctrl-C finishes the file (exit 130); kill -9 leaves whole chunks that load_run reads."""
    import signal

    scene = tmp_path / "ball.toml"
    scene.write_text('[sim]\nsleep = false\n[terrain]\nkind = "plane"\n[[body]]\nshape = "sphere"\n'
                     'radius = 0.1\nposition = [0.0, 1.0, 0.0]\n')
    out = tmp_path / "run.npz"
    proc = _start_long_run(scene, out)
    try:
        _wait_for_chunks(out, proc)
        proc.send_signal(getattr(signal, sig))
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    r = load_run(out)
    frames = len(r["time"])
    assert frames >= 256
    np.testing.assert_allclose(r["time"], np.arange(frames) / 60.0, rtol=1e-12)
    if sig == "SIGINT":
        assert proc.returncode == 130 and err.splitlines()[-1].startswith("error: interrupted; frames up to step")
        assert r["summary"]["stop_reason"] == "interrupted" and r["summary"]["stop_step"] == frames - 1
        assert not chunk_dir(out).exists()
    else:
        assert r["summary"]["stop_reason"] == "incomplete" and r["metadata"]["scene_text"] == scene.read_text()


def test_resume_with_another_thread_count_says_so(mix, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("WARP_SIM_CPU_THREADS", "1")
    assert main(["run", str(mix), "--steps", "2", "--checkpoint-every", "2", "--out", str(tmp_path / "b.npz"),
                 "--quiet"]) == 0
    monkeypatch.setenv("WARP_SIM_CPU_THREADS", "2")
    assert main(["run", "--resume", str(tmp_path / "b.checkpoint.npz"), "--steps", "4", "--out",
                 str(tmp_path / "c.npz"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "written with WARP_SIM_CPU_THREADS=1, resuming with 2: the run goes on validly but not bit-identically" in err
