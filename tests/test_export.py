"""Recorded runs read back: terrain rebuilt from the .npz, replay clock, CSV and USD exports."""

import csv

import numpy as np
import pytest

from warp_sim.cli import main
from warp_sim.replay import Playback, RecordingError, load_recording, terrain_from_record
from warp_sim.scene import load_scene

SCENE = """
name = "export test"
[sim]
dt = 0.02
substeps = 2
[terrain]
kind = "fourier"
terms = 4
amplitude = 0.6
phase = 0.3
seed = 7
scale = [1.5, 0.8, 1.2]
offset = [0.5, -0.2, 0.1]
[[body]]
shape = "sphere"
radius = 0.2
position = [0.0, 2.0, 0.0]
velocity = [1.0, 0.0, 0.5]
[[body]]
shape = "box"
half_extents = [0.3, 0.2, 0.1]
position = [1.5, 2.5, 0.0]
orientation = [0.2, 0.1, 0.0, 0.97]
angular_velocity = [0.0, 3.0, 1.0]
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("export")
    scene = folder / "scene.toml"
    scene.write_text(SCENE)
    out = folder / "run.npz"
    assert main(["run", str(scene), "--out", str(out), "--steps", "12", "--record-every", "3", "--quiet"]) == 0
    return scene, out


def test_terrain_rebuilt_from_record(recorded):
    """The rebuilt terrain has the scene's height everywhere (not just the same table shapes)."""
    scene, out = recorded
    original = load_scene(scene).terrain
    rebuilt = terrain_from_record(load_recording(out))
    x, z = np.meshgrid(np.linspace(-20, 20, 41), np.linspace(-15, 25, 41))
    np.testing.assert_allclose(rebuilt.height(x, z), original.height(x, z), rtol=0, atol=1e-12)


def test_plane_and_no_terrain_rebuilt():
    plane = terrain_from_record({"terrain_kind": np.array("plane"), "terrain_normal": np.array([0.0, 2.0, 1.0]),
                                 "terrain_plane_offset": np.array(0.25)})
    assert plane.kind == "plane" and plane.offset == 0.25
    np.testing.assert_allclose(plane.normal, np.array([0.0, 2.0, 1.0]) / np.sqrt(5.0))
    assert terrain_from_record({"terrain_kind": np.array("none")}).kind == "none"


def test_not_a_run_is_one_line_error(tmp_path):
    bad = tmp_path / "bad.npz"
    np.savez(bad, something=np.zeros(3))
    with pytest.raises(RecordingError, match=r"bad.npz: not a recorded run \(missing time"):
        load_recording(bad)
    with pytest.raises(RecordingError, match="no such file"):
        load_recording(tmp_path / "absent.npz")
    with pytest.raises(RecordingError, match="it is a directory"):  # was "no such file"
        load_recording(tmp_path)


def test_playback_clock():
    p = Playback([0.0, 0.5, 1.0, 1.5], playing=True, loop=False)
    p.advance(0.6)
    assert p.frame == 1 and p.time == pytest.approx(0.6)
    p.speed = 2.0
    p.advance(0.3)  # 0.6 + 0.6 s of run time
    assert p.frame == 2
    p.advance(10.0)  # stops at the end without looping
    assert p.time == 1.5 and not p.playing and p.frame == 3
    p.toggle()  # play again from the start
    assert p.playing and p.time == 0.0
    p.toggle()
    p.advance(1.0)  # paused: no motion
    assert p.time == 0.0
    p.seek_frame(2)
    assert p.frame == 2 and p.time == 1.0
    p.seek_time(-3.0)
    assert p.frame == 0
    looping = Playback([0.0, 1.0, 2.0], playing=True, loop=True)
    looping.advance(2.5)
    assert looping.time == pytest.approx(0.5) and looping.playing


def test_csv_tracks(recorded, tmp_path):
    _, out = recorded
    record = load_recording(out)
    path = tmp_path / "tracks.csv"
    assert main(["export", str(out), "--csv", str(path)]) == 0
    with open(path) as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["frame", "time", "body", "x", "y", "z", "qx", "qy", "qz", "qw"]
    data = np.array(rows[1:], dtype=np.float64)
    frames, bodies = record["position"].shape[:2]
    assert data.shape == (frames * bodies, 10)
    frame, body = data[:, 0].astype(int), data[:, 2].astype(int)
    np.testing.assert_array_equal(data[:, 1], record["time"][frame])
    # %.9g round-trips float32 exactly
    np.testing.assert_array_equal(data[:, 3:6].astype(np.float32), record["position"][frame, body])
    np.testing.assert_array_equal(data[:, 6:10].astype(np.float32), record["orientation"][frame, body])


def test_usd_read_back(recorded, tmp_path):
    pytest.importorskip("pxr", reason="USD export needs usd-core (pip install 'warp-sim[usd]')")
    from pxr import Usd, UsdGeom

    scene, out = recorded
    record = load_recording(out)
    path = tmp_path / "run.usda"
    assert main(["export", str(out), "--usd", str(path), "--terrain-resolution", "16"]) == 0
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    frames = len(record["time"])
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == frames - 1
    # time codes per second = recorded frames per simulated second (12 steps of 0.02 s, every 3rd)
    assert stage.GetTimeCodesPerSecond() == pytest.approx((frames - 1) / record["time"][-1])

    if record.get("metadata"):  # provenance travels with the export
        import json

        meta = json.loads(stage.GetPrimAtPath("/World").GetCustomDataByKey("warp_sim:metadata"))
        assert meta["scene_text"] == scene.read_text()
    sphere = stage.GetPrimAtPath("/World/Bodies/body_000000")
    box = stage.GetPrimAtPath("/World/Bodies/body_000001")
    assert sphere.GetTypeName() == "Sphere" and box.GetTypeName() == "Cube"
    assert UsdGeom.Sphere(sphere).GetRadiusAttr().Get() == pytest.approx(0.2)
    for i in range(frames):
        for b, prim in enumerate((sphere, box)):
            xf = UsdGeom.Xformable(prim)
            m = np.array(xf.ComputeLocalToWorldTransform(i), dtype=np.float64)  # row-vector convention
            np.testing.assert_allclose(m[3, :3], record["position"][i, b], atol=1e-5)
            ops = {op.GetOpName(): op.Get(i) for op in xf.GetOrderedXformOps()}
            q = ops["xformOp:orient"]
            got = np.array([*q.GetImaginary(), q.GetReal()])
            np.testing.assert_allclose(got, record["orientation"][i, b], atol=1e-6)
    # the box's rotation and half extents: its local x axis is R e_x scaled by 0.3 (last frame)
    x, y, z, w = record["orientation"][-1, 1].astype(np.float64)
    r_ex = np.array([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])
    m = np.array(UsdGeom.Xformable(box).ComputeLocalToWorldTransform(frames - 1))
    np.testing.assert_allclose(m[0, :3], 0.3 * r_ex, atol=1e-5)

    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Terrain"))
    points = np.array(mesh.GetPointsAttr().Get(), dtype=np.float64)
    assert len(points) == 17 * 17 and len(mesh.GetFaceVertexCountsAttr().Get()) == 16 * 16
    terrain = load_scene(scene).terrain
    np.testing.assert_allclose(points[:, 1], terrain.height(points[:, 0], points[:, 2]), atol=1e-5)
    # the mesh covers every body position of the run
    lo, hi = points[:, [0, 2]].min(axis=0), points[:, [0, 2]].max(axis=0)
    xz = record["position"][..., [0, 2]].reshape(-1, 2)
    assert np.all(xz >= lo) and np.all(xz <= hi)


def test_export_errors(recorded, tmp_path, capsys):
    _, out = recorded
    assert main(["export", str(out)]) == 2
    assert capsys.readouterr().err.strip() == "error: export needs --usd OUT.usd and/or --csv OUT.csv"
    assert main(["export", str(tmp_path / "none.npz"), "--csv", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "none.npz" in err and "no such file" in err
    assert main(["export", str(out), "--csv", str(tmp_path / "no" / "x.csv")]) == 2
    assert "--csv: directory" in capsys.readouterr().err


@pytest.mark.parametrize("flags, message", [
    (["--terrain-extent", "inf"], "--terrain-extent must be a number of metres in (0, 1e+06], got inf"),
    (["--terrain-resolution", "100000"], "--terrain-resolution must be an integer in [1, 4096], got 100000"),
    (["--usd", "OUT/e.txt"], "--usd must name a .usd, .usda or .usdc file"),
])
def test_export_bounds_are_named(recorded, tmp_path, capsys, flags, message):
    """An infinite extent wrote 49,671 NaN terrain points and exited 0; a 100000-point grid died in
    numpy asking for 37 GB; a .txt path died in USD's own exception."""
    _, out = recorded
    flags = [f.replace("OUT", str(tmp_path)) for f in flags]
    if "--usd" not in flags:
        flags = ["--usd", str(tmp_path / "e.usda"), *flags]
    assert main(["export", str(out), *flags]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and message in err, err
