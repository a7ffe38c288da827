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


def test_shuffled_rain_maps_back_to_its_random_order():
    """bench/gpu.py's body-order part: the sorted model holds the shuffled scene's bodies, grouped
    by shape, and maps back to that scene's order."""
    listed = gpu.shuffled_rain(50, "cpu", "scene").model
    sorted_ = gpu.shuffled_rain(50, "cpu", "shape_morton").model
    assert np.all(np.diff(sorted_.host["body_shape"]) >= 0)
    for key in ("body_pos", "body_quat", "body_shape", "body_inertia", "body_checkpoint_count"):
        np.testing.assert_array_equal(sorted_.to_scene_order(sorted_.host[key]), listed.host[key], err_msg=key)


def test_quick_run_writes_every_part(tmp_path):
    assert gpu.main(["--quick", "--device", "cpu", "--out", str(tmp_path)]) == 0
    result = json.loads((tmp_path / "gpu.json").read_text())
    parts = result["parts"]
    for name in ("compile", "environment", "graph_probe", "capture", "spheres_terrain", "mixed_500", "mixed_2000", "determinism", "memory",
                 "cpu_vs_device", "body_order", "newton"):
        assert parts[name]["status"] == "ok", (name, parts[name])
    assert parts["determinism"]["identical"]
    assert parts["graph_probe"]["identical"] and parts["graph_probe"]["graph_for_later_parts"]
    assert parts["spheres_terrain"]["byte_model"]["total"] > 0
    assert parts["memory"]["simulator_bytes_per_body"] > 0
    assert (tmp_path / "gpu.csv").read_text().count("\n") >= 5
    assert (tmp_path / "gpu.png").stat().st_size > 0


def test_byte_model_charges_the_struct_fields_a_kernel_names():
    """Kernels take their arrays in structs (warp_sim/kernel_args.py): the model must still charge
    them (a counter that saw only plain array arguments charged prepare_bodies and terrain_sweep
    nothing), and only the fields the kernel's code names (prepare_bodies never reads the
    checkpoints' body-frame points)."""
    from bench import byte_model
    from warp_sim.kernel_args import BodyModel, bind
    from warp_sim.solvers.staged import prepare_bodies

    sim = cases.terrain_drop(40, "mix", spacing=0.9, body_contact=True, sleep=False, pair_schedule="colors")
    sim.step(30)
    model = byte_model.per_body_step(sim)
    for kernel in ("prepare_bodies", "terrain_sweep", "integrate_positions"):
        assert model.get(kernel, 0.0) > 0.0, kernel
    body_model = bind(BodyModel, sim.model, sim.model)
    charged = {a.ptr for a in byte_model.launch_arrays(prepare_bodies, [0, body_model])}
    assert body_model.body_inv_mass.ptr in charged
    assert body_model.checkpoint_local.ptr not in charged


def test_the_device_session_dry_run_lists_the_device_tests_and_runs_the_benchmark(tmp_path):
    """bench/gpu_session.sh, the one command a GPU machine runs, dry-run on the CPU: it finds the
    test files whose tests take ``device`` (their cuda:0 instances are what it runs there), and
    bench/gpu.py writes its results under OUT within the call's budget."""
    import os
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, OUT=str(tmp_path), DEVICE="cpu", GPU_ARGS="--quick", TEST_BUDGET="60",
               CALL_BUDGET="240")
    out = subprocess.run(["bash", str(root / "bench" / "gpu_session.sh")], env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    listed = next(line for line in out.stdout.splitlines() if "tests on cpu" in line)
    for name in ("test_impacts.py", "test_contact_laws.py", "test_body_contact.py", "test_push_out.py"):
        assert name in listed
    assert "test_races.py" not in listed  # CPU thread chunking: no device parameter
    assert json.loads((tmp_path / "gpu.json").read_text())["parts"]["capture"]["status"] == "ok"
    files = [p.name for p in tmp_path.iterdir()]
    assert len(files) <= 8  # what a device call brings back from $OUT


def test_byte_model_charges_a_captured_step_what_a_direct_one_moves():
    """A captured step runs all 96 colouring rounds, the idle ones returning at once; the model
    must charge them nothing (the H200 runs' figures had charged their whole pair arrays, about
    45 kB a body-step).  The same rain stepped directly stops at the last busy round: with the
    two states equal bit for bit, the colouring must cost the same bytes either way."""
    from bench import byte_model

    charged = {}
    for graph in (False, True):
        sim = cases.terrain_drop(60, "mix", spacing=0.9, body_contact=True, sleep=False, pair_schedule="colors",
                                 graph=graph)
        sim.step(40)
        charged[graph] = byte_model.per_body_step(sim)
    assert charged[False]["color_pick"] > 0.0
    assert charged[True]["color_pick"] == charged[False]["color_pick"]


def test_cuda_cache_packs_each_modules_cubin_and_meta_in_its_cache_folder(tmp_path):
    """bench/cuda_cache.py (sm_90 cubins built here, unpacked on a GPU machine so that it skips
    NVRTC): one small module, compiled for real; the archive holds <module dir>/<cubin> and the
    meta file Warp reads beside it, as Warp's kernel cache lays them out."""
    import tarfile

    from bench import cuda_cache

    out = tmp_path / "cache.tar.xz"
    assert cuda_cache.main(["--out", str(out), "--workers", "1"], modules=["warp_sim.prefix_sum"]) == 0
    names = tarfile.open(out).getnames()
    folders = {n.split("/")[0] for n in names}
    assert len(folders) == 1 and next(iter(folders)).startswith("wp_warp_sim.prefix_sum_")
    assert any(n.endswith(".sm90.cubin") for n in names) and any(n.endswith(".meta") for n in names)


def test_the_device_session_unpacks_a_cuda_cache_into_warps_kernel_cache(tmp_path):
    """CUDA_CACHE (bench/cuda_cache.py's archive) lands in Warp's kernel-cache folder: a dry run
    once read Warp's start-up banner as that folder's path and unpacked 34 files into a stray
    folder of the checkout."""
    import os
    import subprocess
    import tarfile
    from pathlib import Path

    import warp as wp

    wp.init()  # sets wp.config.kernel_cache_dir
    root = Path(__file__).resolve().parents[1]
    before = set(os.listdir(root))
    archive = tmp_path / "cache.tar.xz"
    marker = tmp_path / "wp_probe_0000000"
    marker.mkdir()
    (marker / "wp_probe_0000000.meta").write_text("{}")
    with tarfile.open(archive, "w:xz") as tar:
        tar.add(marker / "wp_probe_0000000.meta", arcname="wp_probe_0000000/wp_probe_0000000.meta")
    out = tmp_path / "out"
    env = dict(os.environ, OUT=str(out), DEVICE="cpu", GPU_ARGS="--quick --parts graph_probe", TEST_BUDGET="5",
               CALL_BUDGET="60", CUDA_CACHE=str(archive))
    done = subprocess.run(["bash", str(root / "bench" / "gpu_session.sh")], env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    unpacked = Path(wp.config.kernel_cache_dir) / "wp_probe_0000000" / "wp_probe_0000000.meta"
    try:
        assert f"into {wp.config.kernel_cache_dir}" in done.stdout and unpacked.exists()
    finally:
        if unpacked.exists():
            unpacked.unlink()
            unpacked.parent.rmdir()
    assert set(os.listdir(root)) <= before | {".pytest_cache"}  # nothing new beside the sources
