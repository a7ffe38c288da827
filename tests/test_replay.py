"""The demo's replay of a recorded run and the panel's plot limits (no OpenGL needed)."""

import numpy as np
import pytest

from warp_sim.builder import quat_to_matrix
from warp_sim.cli import main
from warp_sim.render_package import ensure_render_package

ensure_render_package()
from warp_sim_render.plot_limits import axis_limits  # noqa: E402
from warp_sim_render.replay import ReplayController, quat_matrices  # noqa: E402

SCENE = """
[sim]
dt = 0.02
[terrain]
kind = "fourier"
amplitude = 0.4
seed = 3
[[layout]]
type = "grid"
count = 6
shape = "mix"
random_orientation = true
"""


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("replay")
    (folder / "scene.toml").write_text(SCENE)
    out = folder / "run.npz"
    assert main(["run", str(folder / "scene.toml"), "--out", str(out), "--steps", "20", "--record-every", "2",
                 "--quiet"]) == 0
    return out


def test_replay_shows_recorded_frames(run_file):
    c = ReplayController(run_file, playing=False)
    record = c.record
    assert c.frame_count == 11 and c.body_count == 6
    assert c.sim.model.terrain.kind == "fourier"
    c.seek(7)
    np.testing.assert_array_equal(c.sim.state.body_pos.numpy(), record["position"][7])
    np.testing.assert_array_equal(c.sim.state.body_quat.numpy(), record["orientation"][7])
    expected = np.stack([quat_to_matrix(q) for q in record["orientation"][7].astype(np.float64)])
    np.testing.assert_allclose(c.sim.state.body_rot.numpy(), expected, atol=1e-6)
    c.step_backward(3)
    np.testing.assert_array_equal(c.sim.state.body_pos.numpy(), record["position"][4])
    c.reset()
    assert c.frame == 0
    np.testing.assert_array_equal(c.sim.state.body_pos.numpy(), record["position"][0])


def test_replay_clock_drives_the_frames(run_file):
    c = ReplayController(run_file, playing=True, frame_dt=0.04)  # two steps of 0.02 s: one frame each
    for expected in range(1, 4):
        c.update()
        assert c.frame == expected
    c.toggle_pause()
    c.update()
    assert c.frame == 3 and c.paused
    c.paused = False
    c.playback.speed = 2.0
    c.update()
    assert c.frame == 5
    np.testing.assert_array_equal(c.sim.state.body_pos.numpy(), c.record["position"][5])


def test_replay_settings_are_the_recordings(run_file):
    c = ReplayController(run_file, playing=False)
    dt = c.get_param("dt")
    c.set_param("dt", 0.001)
    assert c.get_param("dt") == dt
    assert any("cannot change" in note for note in c.recent_notes())
    c.set_param("wireframe", True)  # view settings still apply
    assert c.view.wireframe


def test_quat_matrices_match_builder():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    np.testing.assert_allclose(quat_matrices(q), np.stack([quat_to_matrix(v) for v in q]), atol=1e-6)


def test_axis_limits_keep_round_off_small():
    # an energy that only carries float32 round-off stays a flat line in the middle of the plot
    lo, hi = axis_limits([0.4533371, 0.4533374, 0.4533372])
    assert hi - lo >= 0.05 * 0.4533374
    assert lo < 0.4533371 and hi > 0.4533374
    # 997 to 1000 awake bodies: a span of at least 5 % of 1000
    lo, hi = axis_limits([1000, 999, 997])
    assert hi - lo >= 50 and lo < 997 and hi > 1000
    # a real change fills the axis, a non-negative series never shows negative values
    lo, hi = axis_limits([0.0, 5.0, 95.0])
    assert lo == pytest.approx(-0.05 * 95) and hi == pytest.approx(95 * 1.05)
    lo, hi = axis_limits([0.1, 0.2])
    assert lo >= -0.05 * (hi - lo) - 1e-12
    assert axis_limits([0, 0, 0]) == (-0.05, 1.05)
    assert axis_limits([np.nan]) == (0.0, 1.0)
