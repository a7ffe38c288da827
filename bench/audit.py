"""Physics audit: every case of issue 12 ("What is wrong", items 1-13) as a small family of
scenes, plus property checks on seeded random impacts, against its physical or textbook
expectation.  Prints one table (case, expectation, measured value, tolerance, verdict) and writes
it as CSV and JSON.  It reports and never asserts: a FAIL row is a finding, and the exit status
is 0 whatever the verdicts (2 for bad arguments).

    python bench/audit.py                      # all cases, full families (a few minutes, 2 cores)
    python bench/audit.py --quick              # one or two variants each, shorter runs (< ~60 s warm)
    python bench/audit.py --case impact_friction --quick
    python bench/audit.py --list
    python bench/audit.py --set iterations=1 --out-dir /tmp/a   # the same cases under a faster choice

Output: bench/results/audit.csv and .json, or with --quick a new temporary folder (so a quick
look never overwrites the recorded run); --out-dir chooses.  ``--set FIELD=VALUE`` (repeatable)
gives every simulator the cases build that SimConfig value wherever the case leaves the field at
its default (a case that sets the field itself keeps its own): the accuracy a faster choice costs,
measured on the same families; its verdicts are that choice's, not the defaults'.  Cases (item of the issue):

    sleep_hit (1)              ball hits a sleeping ball (mass ratios, e); ball on a sleeping stack
    multipoint_restitution (2) flat cube bounce (apex e^2 H, no spin); face-on cubes; row of balls
    impact_friction (3)        sphere hits a floor obliquely, cube lands sliding: Coulomb + Poisson
    resting_restitution (4)    stacks with e > 0; resting cube under g 100; heavy on light, e 0.5
    valley_roll (5)            ball rolling in a terrain valley, alone and with a second body
    late_impact_tunnel (6)     a hit sends a ball at a thin wall within the same step (8 phases)
    heavy_gravity_landing (7)  sphere landing on a static box vs the plane at g 100, dt 1/30
    mass_ratio_stack (8)       heavy cube on a light one (10 to 1e4)
    coarse_stack (9)           stacks at dt 1/30 and 1/20 with one substep
    rolling_resistance (10)    deceleration 5/7 c_r g on the plane and on a static box floor
    thin_box_rain (11)         body-body depth in rains of mixed bodies and thin plates
    free_rotation (12)         tumbling 1x2x3 box: energy within 1 % over 20 s, flip count
    tall_stack (13)            20 and 40 unit cubes standing
    impact_properties          random impacts: momentum, angular momentum, no KE rise, no pass-through
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import warp as wp  # noqa: E402

from bench import audit_cases, audit_stacks  # noqa: E402
from bench.common import RESULTS, machine_info, write_rows  # noqa: E402

CASES = {
    "sleep_hit": audit_cases.sleeping_target,
    "multipoint_restitution": audit_cases.multipoint_restitution,
    "impact_friction": audit_cases.impact_friction,
    "resting_restitution": audit_stacks.resting_restitution,
    "valley_roll": audit_stacks.valley_roll,
    "late_impact_tunnel": audit_cases.late_impact_tunnel,
    "heavy_gravity_landing": audit_stacks.heavy_gravity_landing,
    "mass_ratio_stack": audit_stacks.mass_ratio_stack,
    "squeezed_cube": audit_stacks.squeezed_cube,
    "coarse_stack": audit_stacks.coarse_stack,
    "rolling_resistance": audit_stacks.rolling_resistance,
    "thin_box_rain": audit_stacks.thin_box_rain,
    "free_rotation": audit_stacks.free_rotation,
    "tall_stack": audit_stacks.tall_stack,
    "impact_properties": audit_cases.impact_properties,
}

COLUMNS = ["group", "item", "case", "variant", "expectation", "expected", "measured", "tolerance", "unit", "kind",
           "verdict", "note", "group_wall_s"]


def fmt(x: float) -> str:
    return f"{x:.4g}"


def print_table(rows: list[dict]):
    head = ["item", "case", "variant", "expectation", "expected", "measured", "tol", "verdict"]
    cells = [[str(r["item"] or "-"), r["case"], r["variant"], r["expectation"],
              fmt(r["expected"]) + (f" {r['unit']}" if r["unit"] else ""), fmt(r["measured"]),
              ("<= " if r["kind"] == "max" else ">= " if r["kind"] == "min" else "+- ") + fmt(r["tolerance"]),
              r["verdict"]] for r in rows]
    widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(head)]
    line = "  ".join(h.ljust(w) for h, w in zip(head, widths))
    print(line)
    print("-" * len(line))
    for c in cells:
        print("  ".join(x.ljust(w) for x, w in zip(c, widths)))


def parse_settings(pairs: list[str]) -> dict:
    """``FIELD=VALUE`` strings (VALUE as JSON: 1, 0.5, true, "points") as a dict of SimConfig fields;
    ValueError naming the pair that is not one."""
    from warp_sim import SimConfig

    settings = {}
    for pair in pairs:
        field, sep, text = pair.partition("=")
        if not sep or field not in SimConfig.__dataclass_fields__:
            raise ValueError(f"--set takes FIELD=VALUE with FIELD a SimConfig field, got {pair!r}")
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            value = text  # a bare word: a string setting
        setattr(SimConfig(), field, value)  # SimConfig's own check, naming the field and the value
        settings[field] = value
    return settings


def apply_settings(settings: dict) -> None:
    """Every Simulator made from now on takes ``settings`` where its config holds the default."""
    from warp_sim import SimConfig, simulator

    defaults = SimConfig()
    plain_init = simulator.Simulator.__init__

    def init(self, model, config):
        for field, value in settings.items():
            if getattr(config, field) == getattr(defaults, field):
                setattr(config, field, value)
        plain_init(self, model, config)

    simulator.Simulator.__init__ = init


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="one or two variants per case, shorter runs")
    p.add_argument("--case", action="append", metavar="NAME",
                   help="run only this case (repeatable); --list shows the names")
    p.add_argument("--out-dir", type=Path, default=None,
                   help="where audit.csv/.json go (default bench/results; with --quick a temporary folder)")
    p.add_argument("--list", action="store_true", help="list the case names and exit")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="a SimConfig value for every case that leaves the field at its default (repeatable)")
    args = p.parse_args(argv)
    try:
        settings = parse_settings(args.set)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.list:
        print("\n".join(CASES))
        return 0
    names = args.case or list(CASES)
    for name in names:
        if name not in CASES:
            print(f"error: --case must be one of {', '.join(CASES)}, got {name!r}", file=sys.stderr)
            return 2
    out_dir = args.out_dir
    if out_dir is None:
        out_dir = Path(tempfile.mkdtemp(prefix="audit_")) if args.quick else RESULTS

    wp.config.quiet = True
    wp.init()
    if settings:
        apply_settings(settings)
    rows = []
    start = time.perf_counter()
    for name in names:
        t0 = time.perf_counter()
        group = CASES[name](args.quick)
        wall = time.perf_counter() - t0
        for r in group:
            rows.append({"group": name, **r, "group_wall_s": round(wall, 2)})
        print(f"{name}: {sum(r['verdict'] == 'PASS' for r in group)}/{len(group)} pass ({wall:.1f} s)",
              file=sys.stderr, flush=True)
    rows = [{k: r[k] for k in COLUMNS} for r in rows]
    print_table(rows)
    failed = sum(r["verdict"] == "FAIL" for r in rows)
    total = time.perf_counter() - start
    print(f"\n{len(rows) - failed} PASS, {failed} FAIL of {len(rows)} checks in {total:.0f} s"
          + (" (quick)" if args.quick else ""))
    meta = {**machine_info("cpu"), "quick": args.quick, "cases": names, "wall_s": round(total, 1), "settings": settings}
    csv_path, json_path = write_rows("audit", rows, meta, out_dir)
    print(f"wrote {csv_path} and {json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
