"""bench/audit.py end to end on one cheap case: the table is printed and the CSV and JSON are
written with the documented columns.  Whether the physics passes is the audit's report, not
this test's business."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
COLUMNS = ["group", "item", "case", "variant", "expectation", "expected", "measured", "tolerance", "unit", "kind",
           "verdict", "note", "group_wall_s"]


def run_audit(*args):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, str(ROOT / "bench" / "audit.py"), *args], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=300)


def test_quick_case_writes_csv_and_json(tmp_path):
    out = run_audit("--quick", "--case", "impact_friction", "--out-dir", str(tmp_path))
    assert out.returncode == 0, out.stderr
    with (tmp_path / "audit.csv").open(newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    assert reader.fieldnames == COLUMNS
    assert rows and {r["group"] for r in rows} == {"impact_friction"}
    for r in rows:
        assert r["verdict"] in ("PASS", "FAIL")
        float(r["measured"]), float(r["expected"]), float(r["tolerance"])
        assert r["item"] == "3"
    data = json.loads((tmp_path / "audit.json").read_text())
    assert len(data["rows"]) == len(rows) and data["machine"]["quick"] is True
    assert "impact_friction_vt" in out.stdout and "checks in" in out.stdout


def test_unknown_case_is_a_one_line_error(tmp_path):
    out = run_audit("--case", "no_such_case", "--out-dir", str(tmp_path))
    assert out.returncode == 2
    assert "error: --case must be one of" in out.stderr and "'no_such_case'" in out.stderr
    assert not (tmp_path / "audit.csv").exists()


def test_set_gives_every_case_a_setting_it_leaves_at_the_default(monkeypatch):
    """--set FIELD=VALUE: the value reaches simulators whose config holds the default, a case's
    own choice is kept, and a bad pair is one error line naming it."""
    sys.path.insert(0, str(ROOT))
    from bench import audit
    from warp_sim import SimConfig, cases, simulator

    assert audit.parse_settings(["iterations=1", "face_friction=points"]) == {"iterations": 1,
                                                                             "face_friction": "points"}
    monkeypatch.setattr(simulator.Simulator, "__init__", simulator.Simulator.__init__)  # undone after the test
    audit.apply_settings({"iterations": 1})
    assert cases.terrain_drop(2, "sphere").config.iterations == 1
    assert cases.terrain_drop(2, "sphere", iterations=3).config.iterations == 3
    assert SimConfig().iterations == 2
    for bad in ("iterations", "no_field=1", "iterations=0"):
        out = run_audit("--set", bad)
        assert out.returncode == 2 and out.stderr.startswith("error:") and len(out.stderr.strip().splitlines()) == 1
