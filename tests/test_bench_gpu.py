"""bench/gpu.py runs end to end on the CPU (``--quick --device cpu``), and its vectorised scene
builder gives the bodies of cases.terrain_drop."""

import json

import numpy as np

from bench import gpu
from warp_sim import cases


def test_rain_model_is_the_terrain_drop_scene():
    for shape in ("sphere", "mix"):
        ours = gpu.rain_model(37, shape, "cpu", spacing=0.9).host
        ref = cases.terrain_drop(37, shape, terrain=gpu.TERRAIN, spacing=0.9).model.host
        assert set(ours) == set(ref)
        for key in ref:
            np.testing.assert_array_equal(ours[key], ref[key], err_msg=key)


def test_quick_run_writes_every_part(tmp_path):
    assert gpu.main(["--quick", "--device", "cpu", "--out", str(tmp_path)]) == 0
    result = json.loads((tmp_path / "gpu.json").read_text())
    parts = result["parts"]
    for name in ("compile", "environment", "capture", "spheres_terrain", "mixed_500", "mixed_2000", "determinism", "memory",
                 "cpu_vs_device", "newton"):
        assert parts[name]["status"] == "ok", (name, parts[name])
    assert parts["determinism"]["identical"]
    assert parts["spheres_terrain"]["byte_model"]["total"] > 0
    assert parts["memory"]["simulator_bytes_per_body"] > 0
    assert (tmp_path / "gpu.csv").read_text().count("\n") >= 5
    assert (tmp_path / "gpu.png").stat().st_size > 0
