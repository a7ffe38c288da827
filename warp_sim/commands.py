"""The ``validate``, ``info`` and ``export`` subcommands and ``--version``/``--verbose``.

    python -m warp_sim validate SCENE.toml      # one line: "SCENE.toml: OK, 1000 bodies" or the error
    python -m warp_sim info SCENE.toml          # bodies by shape, memory, expected cost per step
    python -m warp_sim export run.npz --usd run.usd --csv run.csv

``info``'s memory figure is measured, not modelled: the scene is built on the CPU and the bytes of
every Warp array the Simulator holds (model, both states, contact buffers, solver scratch) are
added up; CUDA allocates the same arrays.  Its cost per step is a model, ``expected_step_seconds``:
bodies times the per-body cost measured by the benchmarks on the 2-core CI CPU, scaled by the
substep count (the benches' own settings are in ``STEP_COST``).  It says how a scene compares
with the benchmarked ones; it does not know about sleeping, piles or a GPU.
"""

from __future__ import annotations

import argparse
import sys
from importlib import metadata
from pathlib import Path

import numpy as np

# Seconds per body-substep on the 2-core CI CPU, from bench/results (warp 1.19):
#   terrain only: terrain_drop_cpu.json at 100k bodies, 1 substep: spheres 2.77 M body-steps/s,
#                 boxes (26 checkpoints) 0.690 M;
#   body contact: rain_cpu.json at 10k mixed bodies, grid broad phase, contacts once per step,
#                 slab schedule, 4 substeps: 33.8 steps/s = 338 k body-steps/s, 1.35 M body-substeps/s.
STEP_COST = {
    ("terrain", "sphere"): 1 / 2.77e6,
    ("terrain", "box"): 1 / 0.690e6,
    ("contact", "sphere"): 1 / 1.35e6,
    ("contact", "box"): 1 / 1.35e6,  # the rain mixes both shapes half and half: one average
}


def package_version() -> str:
    try:
        return metadata.version("warp-sim")
    except metadata.PackageNotFoundError:  # a checkout on PYTHONPATH, never installed
        return "0+unknown"


def version_text() -> str:
    import warp

    return f"warp_sim {package_version()} (warp {warp.config.version}, numpy {np.__version__}, " \
           f"Python {sys.version.split()[0]})"


def add_commands(parser: argparse.ArgumentParser, commands) -> None:
    """Add validate, info and export to the ``python -m warp_sim`` parser, and the global options."""
    parser.add_argument("--version", action="version", version=version_text())
    p = commands.add_parser("validate", help="check a scene file: one line, OK or the error",
                            description="Check a scene file; prints one line, OK or the error (status 2).")
    p.add_argument("scene", metavar="SCENE.toml")
    p.set_defaults(func=validate_command)

    p = commands.add_parser("info", help="bodies, memory and expected cost per step of a scene",
                            description="Bodies by shape, memory of the built simulator and expected "
                                        "cost per step of a scene file (see warp_sim/commands.py).")
    p.add_argument("scene", metavar="SCENE.toml")
    p.set_defaults(func=info_command)

    p = commands.add_parser("export", help="write a recorded .npz as USD (usdview, Blender) or CSV",
                            description="Write a run recorded by 'python -m warp_sim run' as a USD stage "
                                        "(time-sampled body transforms and the terrain mesh; needs usd-core: "
                                        "pip install 'warp-sim[usd]') and/or a CSV of per-body tracks.")
    p.add_argument("run", metavar="RUN.npz")
    p.add_argument("--usd", metavar="OUT.usd", help="USD stage (.usd, .usda or .usdc)")
    p.add_argument("--csv", metavar="OUT.csv", help="one row per frame and body: frame,time,body,x,y,z,qx,qy,qz,qw")
    p.add_argument("--terrain-extent", type=float, default=None, metavar="M",
                   help="half width of the exported terrain mesh [m] (default: the bodies' range plus 5 m)")
    p.add_argument("--terrain-resolution", type=int, default=128, metavar="N",
                   help="terrain mesh cells per side (default: 128)")
    p.set_defaults(func=export_command)

    # every subcommand takes --verbose (Warp's banner, module loads and driver warnings)
    for sub in commands.choices.values():
        sub.add_argument("--verbose", action="store_true", help="show Warp's own start-up and compile output")


def validate_command(args) -> int:
    from .scene import load_scene

    scene = load_scene(args.scene)  # SceneError: main prints "error: ..." and returns 2
    count = scene.body_count
    print(f"{args.scene}: OK, {count:,} bod{'y' if count == 1 else 'ies'}")
    return 0


def array_bytes(root) -> int:
    """Bytes of every distinct Warp array reachable from ``root`` through this package's objects."""
    import warp as wp

    seen, total, stack = set(), 0, [(root, 0)]
    while stack:
        obj, depth = stack.pop()
        if id(obj) in seen or depth > 6:
            continue
        seen.add(id(obj))
        if isinstance(obj, wp.array):
            total += int(getattr(obj, "capacity", 0) or obj.size * wp.types.type_size_in_bytes(obj.dtype))
        elif isinstance(obj, dict):
            stack.extend((v, depth + 1) for v in obj.values())
        elif isinstance(obj, (list, tuple)):
            stack.extend((v, depth + 1) for v in obj)
        elif type(obj).__module__.startswith("warp_sim") and hasattr(obj, "__dict__"):
            stack.extend((v, depth + 1) for v in vars(obj).values())
    return total


def expected_step_seconds(spheres: int, boxes: int, substeps: int, body_contact: bool) -> float:
    """The STEP_COST model: per-body costs of the benchmarks times bodies and substeps."""
    kind = "contact" if body_contact else "terrain"
    return substeps * (spheres * STEP_COST[(kind, "sphere")] + boxes * STEP_COST[(kind, "box")])


def info_command(args) -> int:
    from .scene import load_scene
    from .types import SHAPE_SPHERE

    from .limits import expected_steps

    scene = load_scene(args.scene)
    cfg = scene.config
    sim = scene.build("cpu")
    memory = array_bytes(sim)
    shapes = sim.model.host["body_shape"]
    static = sim.model.host["body_inv_mass"] == 0.0
    spheres = int(np.count_nonzero(shapes == SHAPE_SPHERE))
    boxes = len(shapes) - spheres
    moving_spheres = int(np.count_nonzero((shapes == SHAPE_SPHERE) & ~static))
    moving_boxes = int(np.count_nonzero((shapes != SHAPE_SPHERE) & ~static))
    cost = expected_step_seconds(moving_spheres, moving_boxes, sim.substeps, cfg.body_contact)
    contacts = sim.contacts
    lines = [
        f"scene       {scene.name} ({args.scene})",
        f"bodies      {len(shapes):,}: {spheres:,} spheres, {boxes:,} boxes ({int(static.sum()):,} static)",
        f"terrain     {scene.terrain.kind}; {sim.model.checkpoint_count:,} terrain checkpoints "
        f"({sim.model.host['checkpoints_per_edge']} per box edge)",
        f"contacts    capacity {contacts.slot_count:,} terrain slots, {contacts.pair_max:,} body pairs"
        + ("" if cfg.body_contact else " (body contact off)"),
        f"settings    dt {cfg.dt:.6g} s, {cfg.substeps} substeps, {cfg.integrator}, {cfg.solver}, "
        f"{cfg.duration:g} s = {expected_steps(cfg.duration, cfg.dt):,} steps",
        f"substeps    {sim.substep_plan.describe()}",
        *([f"order       bodies stored in {sim.model.body_order} order (body_order.py); recordings, exports and "
           f"errors use the scene's"] if sim.model.body_order != "scene" else []),
        f"memory      {memory / 2**20:,.1f} MiB of Warp arrays (built on the CPU; CUDA holds the same)",
        f"cost        ~{cost * 1e3:,.3g} ms a step, all bodies awake, on the 2-core CI CPU "
        f"({'body contact' if cfg.body_contact else 'terrain only'} model of warp_sim/commands.py)",
    ]
    print("\n".join(lines))
    return 0


EXPORT_RESOLUTION_MAX = 4096
EXPORT_EXTENT_MAX = 1.0e6  # [m] float32 positions are metre-coarse past a few thousand km


def export_command(args) -> int:
    from .cli import CommandError
    from .export import export_csv, export_usd
    from .replay import load_recording

    if not args.usd and not args.csv:
        raise CommandError("export needs --usd OUT.usd and/or --csv OUT.csv")
    # a grid of N x N terrain points: 4096 is 16.8 M points (1.2 GB of USD text), 100000 asked for
    # 37 GB and failed in numpy; an infinite extent wrote NaN points
    if not 1 <= args.terrain_resolution <= EXPORT_RESOLUTION_MAX:
        raise CommandError(f"--terrain-resolution must be an integer in [1, {EXPORT_RESOLUTION_MAX}], "
                           f"got {args.terrain_resolution}")
    if args.terrain_extent is not None and not 0 < args.terrain_extent <= EXPORT_EXTENT_MAX:
        raise CommandError(f"--terrain-extent must be a number of metres in (0, {EXPORT_EXTENT_MAX:g}], "
                           f"got {args.terrain_extent}")
    if args.usd and Path(args.usd).suffix not in (".usd", ".usda", ".usdc"):
        raise CommandError(f"--usd must name a .usd, .usda or .usdc file, got '{args.usd}'")
    for option, path in (("--usd", args.usd), ("--csv", args.csv)):
        if path and not Path(path).resolve().parent.is_dir():
            raise CommandError(f"{option}: directory '{Path(path).parent}' does not exist")
    try:
        record = load_recording(args.run)
        if args.csv:
            rows = export_csv(record, args.csv)
            print(f"wrote {args.csv} ({rows:,} rows)", file=sys.stderr)
        if args.usd:
            export_usd(record, args.usd, extent=args.terrain_extent, resolution=args.terrain_resolution)
            print(f"wrote {args.usd}", file=sys.stderr)
    except OSError as e:
        raise CommandError(f"cannot write export: {e.strerror or e}: '{e.filename}'") from None
    except ValueError as e:  # RecordingError, or no USD modules
        raise CommandError(str(e)) from None
    except Exception as e:  # noqa: BLE001  USD's own errors (pxr.Tf.ErrorException), e.g. an unwritable path
        if type(e).__module__.startswith("pxr"):
            reason = str(e).strip().splitlines()[-1].rsplit(" : ", 1)[-1].strip("' ")
            raise CommandError(f"--usd: USD could not write '{args.usd}': {reason}") from None
        raise
    return 0
