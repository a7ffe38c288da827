"""Spin-down of boxes on a face: friction over the patch against friction at the corners.

A box set spinning about the vertical on one of its faces slows at the constant rate Coulomb
friction under even pressure gives, mu g r_e 3 / (a^2 + b^2) (collide/contact_patch.py).  For
each box (a cube, a plate on its wide face, a bar) on the plane and on a static box, this runs
``face_friction = "patch"`` (the default) and ``"points"`` (friction at the manifold's points)
for 0.5 s at the defaults and records the spin every step, and the steps per second of a
rain of 10k mixed bodies under each choice is in ``bench/versions.py``'s results.  Writes
``face_friction.csv``/``.json`` (one row a run: the rate it slows at from 2 steps on, over 0.1 s,
against even pressure's) and ``face_friction.png`` (spin against time, the even-pressure line
drawn).

    python bench/face_friction.py            # about 20 s on 2 cores
    python bench/face_friction.py --quick    # the cube only, 0.2 s (a smoke run)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import common  # noqa: E402

BOXES = {"cube 0.5 m": (0.25, 0.25, 0.25), "plate 0.8 x 0.2 x 0.4 m": (0.4, 0.1, 0.2),
         "bar 1.0 x 0.5 x 0.2 m": (0.5, 0.25, 0.1)}
MU, SPIN = 0.5, 10.0


def spin_down(half, floor: str, choice: str, seconds: float) -> list[float]:
    import warp as wp

    from warp_sim import cases

    wp.config.quiet = True
    sim = cases.spinning_box(half, friction=MU, spin=SPIN, floor=floor, face_friction=choice)
    spins = [SPIN]
    for _ in range(int(round(seconds / sim.config.dt))):
        sim.step()
        spins.append(float(sim.angular_velocity()[-1, 1]))
    return spins


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="the cube only, 0.2 s (a smoke run)")
    p.add_argument("--out-dir", type=Path, default=None)
    args = p.parse_args(argv)
    from warp_sim import cases

    out_dir = common.output_dir(args.out_dir, args.quick, "face_friction")
    seconds = 0.2 if args.quick else 0.5
    boxes = {k: BOXES[k] for k in list(BOXES)[:1]} if args.quick else BOXES
    rows, runs = [], []
    for name, half in boxes.items():
        for floor in ("plane", "static box"):
            for choice in ("patch", "points"):
                spins = spin_down(half, floor, choice, seconds)
                runs.append((name, floor, choice, spins))
                rate = cases.spin_down_rate(half, MU)
                # from 2 steps on (the soft contact takes the load first), over 0.1 s
                slowed = (spins[2] - spins[8]) / 0.1
                rows.append({"box": name, "floor": floor, "face_friction": choice,
                             "slows_rad_s2": round(slowed, 4), "even_pressure_rad_s2": round(rate, 4),
                             "ratio": round(slowed / rate, 4), "spin_at_end_rad_s": round(spins[-1], 4),
                             "seconds": seconds})
                print(f"{name:24s} {floor:10s} {choice:6s} slows at {slowed:7.2f} rad/s^2, even pressure "
                      f"{rate:7.2f} ({slowed / rate:.3f}x)")
    common.write_rows("face_friction", rows, common.machine_info("cpu"), out_dir)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(boxes), figsize=(4.2 * len(boxes), 3.6), squeeze=False)
    for ax, (name, half) in zip(axes[0], boxes.items()):
        rate = cases.spin_down_rate(half, MU)
        t = [k / 60.0 for k in range(int(round(seconds * 60)) + 1)]
        ax.plot(t, [max(SPIN - rate * x, 0.0) for x in t], color="k", lw=2.5, alpha=0.35,
                label="even pressure (Coulomb over the face)")
        for run_name, floor, choice, spins in runs:
            if run_name == name:
                # the plane's runs wide and pale underneath: where the floors agree both show
                ax.plot(t, spins, lw=4.0 if floor == "plane" else 1.2, alpha=0.45 if floor == "plane" else 1.0,
                        ls="-" if choice == "patch" else "--", color="#1f77b4" if floor == "plane" else "#d62728",
                        label=f"{choice}, {floor}")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("spin about the vertical [rad/s]")
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"Spin-down on a face, mu {MU}: face_friction = patch (solid) and points (dashed)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out_dir / "face_friction.png", dpi=120)
    print(f"wrote {out_dir / 'face_friction.csv'} (.json, .png)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
