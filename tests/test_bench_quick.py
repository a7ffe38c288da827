"""--quick benchmark runs never write into bench/results, and their charts say they were quick."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import common  # noqa: E402


def test_quick_without_out_dir_uses_a_temporary_folder(capsys):
    folder = common.output_dir(None, True, "scaling")
    assert folder.is_dir() and folder.resolve() != common.RESULTS.resolve()
    assert not folder.is_relative_to(common.RESULTS.resolve())
    assert str(folder) in capsys.readouterr().out
    folder.rmdir()


def test_full_runs_default_to_results(tmp_path):
    assert common.output_dir(None, False, "scaling") == common.RESULTS
    assert common.output_dir(tmp_path, False, "scaling") == tmp_path
    assert common.output_dir(tmp_path, True, "scaling") == tmp_path


@pytest.mark.parametrize("bench", ["scaling", "peers", "stability", "work_precision", "thin_rain", "body_order",
                                   "face_friction", "simultaneous_impacts", "paired"])
def test_quick_into_results_is_refused(bench):
    import importlib

    module = importlib.import_module(f"bench.{bench}")
    with pytest.raises(SystemExit, match="--quick results may not go to"):
        module.main(["--quick", "--out-dir", str(common.RESULTS)])


def test_quick_charts_are_labelled(tmp_path):
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    common.label_quick_charts()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    ax.set_title("a chart")
    fig.savefig(tmp_path / "c.png")
    texts = [t.get_text() for t in fig.texts]
    plt.close(fig)
    assert common.QUICK_LABEL in texts
    assert "quick" in common.QUICK_LABEL.lower()


def test_thin_rain_quick_writes_rows_and_chart(tmp_path):
    """The speed-against-depth bench of the thin-box rains, at smoke size: a row per rain and
    setting, each with a positive speed and a finite, non-negative depth, and the chart."""
    import json
    import math

    from bench import thin_rain

    thin_rain.main(["--quick", "--seconds", "0.3", "--out-dir", str(tmp_path)])
    rows = json.loads((tmp_path / "thin_rain.json").read_text())["rows"]
    assert {(r["rain"], r["variant"]) for r in rows} == {(rain, v) for rain in ("mixed_rain.toml", "plates")
                                                         for v in ("defaults", "4 substeps (auto off)")}
    assert all(r["steps_per_s"] > 0 and math.isfinite(r["deepest_m"]) and r["deepest_m"] >= 0 for r in rows)
    assert (tmp_path / "thin_rain.png").stat().st_size > 0


def test_face_friction_quick_writes_both_choices_and_the_chart(tmp_path):
    """The spin-down bench at smoke size: the cube on both floors under both choices, one row a
    run, the patch at even pressure's rate (1 %, as tests/test_twist_friction.py) and the points
    faster, and the chart."""
    import json

    from bench import face_friction

    face_friction.main(["--quick", "--out-dir", str(tmp_path)])
    rows = json.loads((tmp_path / "face_friction.json").read_text())["rows"]
    runs = {(r["floor"], r["face_friction"]): r for r in rows}
    assert set(runs) == {(floor, choice) for floor in ("plane", "static box") for choice in ("patch", "points")}
    for (floor, choice), row in runs.items():
        assert row["spin_at_end_rad_s"] < face_friction.SPIN
        assert (abs(row["ratio"] - 1.0) < 0.01) == (choice == "patch")
    assert (tmp_path / "face_friction.png").stat().st_size > 0


def test_simultaneous_impacts_quick_measures_both_models_on_both_schedules(tmp_path):
    """The seam drop at smoke size: the joint phase leaves the striker straight (1e-3 of its 3 m/s,
    as tests/test_simultaneous_impacts.py), the sequential one sideways, energy kept by both."""
    import json

    from bench import simultaneous_impacts

    simultaneous_impacts.main(["--quick", "--out-dir", str(tmp_path)])
    rows = json.loads((tmp_path / "simultaneous_impacts.json").read_text())["rows"]
    runs = {(r["simultaneous_impacts"], r["pair_schedule"]): r for r in rows}
    assert set(runs) == {(m, s) for m in ("sequential", "joint") for s in ("domains", "colors")}
    for (model, _), row in runs.items():
        assert (row["seam_striker_sideways_m_s"] < 3e-3) == (model == "joint")
        assert abs(float(row["seam_energy_error"])) < 1e-3
    assert (tmp_path / "simultaneous_impacts.png").stat().st_size > 0


def test_thin_rain_runs_every_setting_on_each_layout(tmp_path):
    """--seeds: one row per rain, setting and layout, the layouts really different scenes."""
    import json

    from bench import thin_rain

    thin_rain.main(["--quick", "--seconds", "0.3", "--seeds", "1", "2", "--out-dir", str(tmp_path)])
    rows = json.loads((tmp_path / "thin_rain.json").read_text())["rows"]
    assert sorted((r["rain"], r["variant"], r["seed"]) for r in rows) == sorted(
        (rain, v, s) for rain in ("mixed_rain.toml", "plates") for v in ("defaults", "4 substeps (auto off)")
        for s in (1, 2))
    # and a seed is another layout: the bodies start elsewhere
    for scene in thin_rain.scenes(quick=True).values():
        first, second = (thin_rain.build(scene, {"seed": s}).state.body_pos.numpy() for s in (1, 2))
        assert first.shape == second.shape and not (first == second).all()


def test_thin_rain_rejects_a_negative_seed(capsys):
    from bench import thin_rain

    with pytest.raises(SystemExit) as exit_info:
        thin_rain.main(["--quick", "--seeds", "-1"])
    assert exit_info.value.code == 2
    assert "--seeds must be integers >= 0, got [-1]" in capsys.readouterr().err


def test_versions_runs_two_revisions_back_to_back(tmp_path):
    """bench/versions.py unpacks a revision with git archive and times it against the working tree
    in fresh processes; every run gives a speed and a depth, and the chart is written."""
    import csv

    from bench import versions

    assert versions.main(["--revs", "HEAD", versions.WORKTREE, "--count", "40", "--repeats", "1", "--settle",
                          "0.1", "--steps", "2", "--variants", "defaults", "--out-dir", str(tmp_path)]) == 0
    rows = list(csv.DictReader((tmp_path / "versions.csv").open()))
    assert [r["rev"] for r in rows] == ["HEAD", versions.WORKTREE]
    assert all(r["status"] == "ok" and float(r["steps_per_s"]) > 0 for r in rows)
    # the per-stage split: every run timed its solve and relax sweeps, and they fit in its step
    for r in rows:
        stages = [float(r[f"{name.replace(' ', '_')}_ms"]) for name in versions.STAGES]
        assert float(r["solve_sweeps_ms"]) > 0 and float(r["relax_sweeps_ms"]) > 0
        assert sum(stages) <= 1000.0 / float(r["steps_per_s"]) and float(r["cpu_ms_per_step"]) > 0
    assert (tmp_path / "versions.png").stat().st_size > 0


def test_versions_times_a_shape_on_the_terrain_alone(tmp_path):
    """--scene sphere: the fused terrain-only step, its split into the terrain collision and
    solve_and_integrate."""
    import csv

    from bench import versions

    assert versions.main(["--revs", versions.WORKTREE, "--count", "40", "--repeats", "1", "--settle", "0.1", "--steps",
                          "5", "--variants", "defaults", "--scene", "sphere", "--out-dir", str(tmp_path)]) == 0
    (row,) = list(csv.DictReader((tmp_path / "versions.csv").open()))
    assert row["status"] == "ok" and row["scene"] == "sphere"
    assert float(row["collide_terrain_ms"]) > 0 and float(row["solve_and_integrate_ms"]) > 0
    assert float(row["solve_sweeps_ms"]) == 0.0


def test_versions_names_a_revision_git_cannot_find(tmp_path, capsys):
    from bench import versions

    with pytest.raises(SystemExit):
        versions.main(["--revs", "no-such-revision-xyz", "--out-dir", str(tmp_path)])
    err = capsys.readouterr().err
    assert "--revs" in err and "no-such-revision-xyz" in err


def test_line_profile_names_the_python_line_of_a_generated_one():
    """bench/line_profile.py shows each generated C++ line with the source comment Warp wrote
    above it (the nearest within a few lines), and nothing where there is none."""
    from bench.line_profile import source_comment

    cpp = ["int a;", "    // v = v + dv                                    <L 42>", "    var_3 = wp::add(var_1, var_2);",
           "    var_4 = wp::mul(var_3, var_3);"]
    assert source_comment(cpp, 3) == "L42: v = v + dv"
    assert source_comment(cpp, 4) == "L42: v = v + dv"
    assert source_comment(cpp, 1) == ""


def test_line_profile_says_which_tool_is_missing(monkeypatch, capsys):
    """Without perf the profile says so and exits 2, instead of a traceback."""
    from bench import line_profile

    monkeypatch.setattr(line_profile.shutil, "which", lambda tool: None if tool == "perf" else "/usr/bin/" + tool)
    assert line_profile.main(["--count", "10", "--steps", "1"]) == 2
    assert "perf" in capsys.readouterr().err


def test_handoff_times_the_same_kernel_whole_and_split(tmp_path, monkeypatch):
    """bench/handoff.py writes one row per kernel size, the split and whole launches timed, and
    refuses to run where there is no second thread to hand a chunk to."""
    import json

    from bench import handoff

    monkeypatch.setenv("WARP_SIM_CPU_THREADS", "2")
    handoff.main(["--works", "10", "200", "--repeats", "3", "--out-dir", str(tmp_path)])
    rows = json.loads((tmp_path / "handoff.json").read_text())["rows"]
    assert [row["work"] for row in rows] == [10, 200]
    assert all(row["whole_us"] > 0.0 and row["split_us"] > 0.0 for row in rows)
    monkeypatch.setenv("WARP_SIM_CPU_THREADS", "1")
    with pytest.raises(SystemExit, match="one CPU thread"):
        handoff.main(["--out-dir", str(tmp_path)])
