"""The scaling, peers, sweep and report scripts run end to end at tiny sizes and write well-formed files."""

import csv
import json
import math
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench import peer_engines, peers, rain, report, scaling, sweep  # noqa: E402

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def read_csv(path: Path) -> list[dict]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def assert_png(path: Path):
    assert path.is_file(), path
    assert path.read_bytes()[:8] == PNG_SIGNATURE, f"{path} is not a PNG"


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """Every script once, into one directory (the report test reads them all)."""
    out = tmp_path_factory.mktemp("bench_results")
    scaling.main(["--counts", "40", "--shapes", "sphere", "mix", "--contact", "off", "on", "--broad-phases", "grid",
                  "--settle", "0.05", "--budget", "0.02", "--min-steps", "2", "--max-steps", "4",
                  "--profile-steps", "2", "--out-dir", str(out), "--no-progress"])
    peers.main(["--engines", "warp_sim", "--quick", "--scenes", "rain", "bounce", "roll", "--out-dir", str(out)])
    sweep.main(["--counts", "20", "--integrators", "semi_implicit", "--dts", "1/60", "--settle", "0.05",
                "--steps", "2", "--out-dir", str(out), "--no-progress"])
    return out


def test_scaling_writes_numeric_rows_and_charts(results):
    rows = read_csv(results / "scaling.csv")
    assert {(r["shape"], r["body_contact"], r["broad_phase"]) for r in rows} == {
        ("sphere", "False", ""), ("sphere", "True", "grid"), ("mix", "False", ""), ("mix", "True", "grid")}
    numeric = ["bodies", "dt", "substeps", "steps", "steps_per_s", "body_steps_per_s", "ms_per_step", "terrain_ms",
               "pairs_ms", "solve_ms", "sleep_ms", "other_ms", "bytes_per_body", "model_bytes", "states_bytes",
               "contacts_bytes", "solver_bytes", "max_penetration_m"]
    for r in rows:
        assert r["status"] == "ok", r
        for key in numeric:
            assert is_number(r[key]), (key, r[key])
        assert float(r["steps_per_s"]) > 0 and float(r["bytes_per_body"]) > 0
        # the stage split is visible: terrain-only runs spend nothing in the pair pipeline
        if r["body_contact"] == "False":
            assert float(r["pairs_ms"]) == 0.0 and float(r["terrain_ms"]) > 0.0
        else:
            assert float(r["pairs_ms"]) > 0.0
    meta = json.loads((results / "scaling.json").read_text())
    assert meta["machine"]["device"] == "cpu" and len(meta["rows"]) == len(rows)
    assert_png(results / "scaling_throughput.png")
    assert_png(results / "scaling_stages.png")


def test_memory_walker_counts_every_state_array_once():
    import warp as wp

    from warp_sim import cases

    sim = cases.terrain_drop(10, "sphere")
    state_bytes = sum(a.size * wp.types.type_size_in_bytes(a.dtype) for a in sim.state.fields())
    assert scaling.array_nbytes(sim.state) == state_bytes
    parts = scaling.memory_breakdown(sim)
    assert parts["states"] == 2 * state_bytes
    assert parts["model"] > 0 and parts["contacts"] > 0 and parts["solver"] > 0
    # shared arrays are counted once: the states hold nothing already counted in the model
    assert scaling.array_nbytes([sim.model, sim.model]) == parts["model"]


def test_scaling_skips_unusable_broad_phase_and_says_why():
    todo = scaling.plan([20000], ["sphere"], [True], ["grid", "bounding_sphere"], bounding_sphere_max=10000)
    reasons = {bp: why for _, _, _, bp, why in todo}
    assert reasons["grid"] == "" and "bounding_sphere" in reasons["bounding_sphere"]


def test_peers_writes_rows_for_installed_engines(results):
    rows = read_csv(results / "peers.csv")
    assert {r["scene"] for r in rows} == {"rain", "bounce", "roll"}
    assert {r["engine"] for r in rows} == {"warp_sim"}
    rain = next(r for r in rows if r["scene"] == "rain")
    for key in ("bodies", "steps_per_s", "body_steps_per_s", "max_penetration_m", "ke_end_j", "speed_vs_warp_sim"):
        assert is_number(rain[key]), (key, rain[key])
    assert float(rain["speed_vs_warp_sim"]) == 1.0
    assert float(rain["max_penetration_m"]) < 0.01  # the same probe the peers are measured with
    for r in rows:
        assert r["status"] == "ok", r
        if r["scene"] != "rain":
            assert is_number(r["value"]) and is_number(r["exact"]) and is_number(r["error"])
    bounce = next(r for r in rows if r["scene"] == "bounce")
    assert float(bounce["value"]) == pytest.approx(0.25, rel=0.1)  # e^2 = 0.25
    roll = next(r for r in rows if r["scene"] == "roll")
    assert float(roll["error"]) < 0.05
    assert_png(results / "peers.png")


def test_peers_skip_an_engine_that_is_not_installed(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(peer_engines.MODULE, "newton", "no_such_module_for_this_test")
    assert "not installed" in peer_engines.available("newton")
    peers.main(["--engines", "warp_sim", "newton", "--quick", "--scenes", "roll", "--out-dir", str(tmp_path),
                "--no-chart"])
    assert "newton: skipped, not installed" in capsys.readouterr().out
    rows = read_csv(tmp_path / "peers.csv")
    assert [r["engine"] for r in rows] == ["warp_sim"]
    meta = json.loads((tmp_path / "peers.json").read_text())["machine"]
    assert "not installed" in meta["newton_status"]


def test_peers_frame_mapping_round_trips():
    import numpy as np

    rng = np.random.default_rng(1)
    v = rng.normal(size=(5, 3))
    assert np.allclose(peer_engines.from_peer(peer_engines.to_peer(v)), v)
    assert np.allclose(peer_engines.to_peer(np.array([[0.0, 1.0, 0.0]])), [[0.0, 0.0, 1.0]])  # y up -> z up
    q = rng.normal(size=(5, 4))
    r = peer_engines.quat_matrices(q)
    assert np.allclose(peer_engines.quat_matrices(peer_engines.matrix_quats(r)), r, atol=1e-12)
    assert np.allclose(peer_engines.rot_from_peer(peer_engines.rot_to_peer(r)), r)
    assert np.allclose(np.linalg.det(peer_engines.rot_to_peer(r)), 1.0)


def _without_timing(rows):
    return [{k: v for k, v in r.items() if k not in sweep.TIMING_COLUMNS} for r in rows]


def test_sweep_local_runner_matches_direct_calls():
    configs = sweep.configurations([24], ["mix"], [True, False], ["semi_implicit", "verlet"], ["soft_step"],
                                   ["grid"], [1 / 60], [2], settle=0.1, steps=3)
    assert len(configs) == 4
    direct = [sweep.run_config(c) for c in configs]
    local = sweep.run_local(configs, jobs=1, progress=False)
    assert _without_timing(local) == _without_timing(direct)
    assert all(r["status"] == "ok" for r in direct)
    # the integrators really differ (body contact does not matter yet: the bodies are still falling)
    assert {r["integrator"]: r["state_hash"] for r in direct if r["body_contact"]}["semi_implicit"] != \
        {r["integrator"]: r["state_hash"] for r in direct if r["body_contact"]}["verlet"]


def test_sweep_process_pool_matches_direct_calls():
    configs = sweep.configurations([24], ["mix"], [True], ["semi_implicit"], ["soft_step", "pushout"], ["grid"],
                                   [1 / 60], [2], settle=0.1, steps=3)
    direct = [sweep.run_config(c) for c in configs]
    pooled = sweep.run_local(configs, jobs=2, progress=False)
    assert _without_timing(pooled) == _without_timing(direct)


@pytest.mark.skipif(os.environ.get("WARP_SIM_TEST_RAY") != "1", reason="set WARP_SIM_TEST_RAY=1 (needs ray, ~30 s)")
def test_sweep_on_local_ray_matches_direct_calls():
    pytest.importorskip("ray")
    configs = sweep.configurations([24], ["mix"], [True], ["semi_implicit", "verlet"], ["soft_step"], ["grid"],
                                   [1 / 60], [2], settle=0.1, steps=3)
    direct = [sweep.run_config(c) for c in configs]
    remote = sweep.run_ray(configs, "local", progress=False)
    assert _without_timing(remote) == _without_timing(direct)


def test_sweep_csv(results):
    rows = read_csv(results / "sweep.csv")
    assert len(rows) == 1 and rows[0]["status"] == "ok"  # one configuration: 20 mixed bodies, semi-implicit, 1/60
    for key in ("bodies", "dt", "substeps", "steps_per_s", "body_steps_per_s", "max_penetration_m",
                "kinetic_energy_j"):
        assert all(is_number(r[key]) for r in rows), key
    assert_png(results / "sweep.png")


def test_report_has_a_table_per_results_file(results, tmp_path):
    out = tmp_path / "REPORT.md"
    report.main(["--results-dir", str(results), "--out", str(out)])
    text = out.read_text()
    assert text.startswith("# Benchmark report")
    assert "## Goals" in text and "| Goal | Verdict | Measured |" in text
    names = sorted(p.stem for p in results.glob("*.json"))
    assert names == ["peers", "scaling", "sweep"]
    sections = text.split('<a id="')[1:]
    assert sorted(s.split('"')[0] for s in sections) == names
    for s in sections:
        assert "\n|---" in s, s[:200]  # a markdown table
        assert "Machine: cpu:" in s
    for png in ("scaling_throughput.png", "scaling_stages.png", "peers.png", "sweep.png"):
        assert f"{png})" in text, png
    # goals are judged from the data: the tiny peers run has no peer engine
    assert "NOT MEASURED" in text


def test_rain_compares_both_contact_update_modes(tmp_path):
    """bench/rain.py at a tiny size: one row per mode and impact-stage choice, each timed and with
    its landing depth."""
    assert rain.main(["--counts", "60", "--broad-phases", "grid", "--settle", "0.6", "--steps", "3",
                      "--impacts", "auto", "always", "--out-dir", str(tmp_path)]) == 0
    rows = read_csv(tmp_path / "rain_cpu.csv")
    assert [(r["contact_update"], r["impacts"]) for r in rows] == [("step", "auto"), ("step", "always"),
                                                                   ("substep", "auto"), ("substep", "always")]
    for r in rows:
        assert r["status"] == "ok"
        for key in ("steps_per_s", "peak_penetration_m", "max_penetration_m"):
            assert is_number(r[key]), (key, r[key])
        assert float(r["peak_penetration_m"]) > 0.0  # bodies landed: some contact was probed
    assert_png(tmp_path / "rain_cpu.png")


def test_report_takes_a_result_whose_machine_is_words(tmp_path):
    """A result file naming its machine in a sentence (the GPU runs' test summary) gets a section
    like any other instead of stopping the whole report (it raised AttributeError)."""
    (tmp_path / "gpu_tests.json").write_text(json.dumps({"machine": "one H200, 16 cores", "rows": [{"a": 1}]}))
    out = tmp_path / "REPORT.md"
    report.main(["--results-dir", str(tmp_path), "--out", str(out)])
    assert "Machine: one H200, 16 cores" in out.read_text()
