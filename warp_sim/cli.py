"""Command line: ``python -m warp_sim run SCENE.toml [options]`` (also installed as ``warp-sim``).

    python -m warp_sim run examples/scenes/bounce.toml --out bounce.npz --duration 2

runs a scene headless with a progress bar on stderr, writes the recorded frames to a
compressed .npz (the arrays of ``warp_sim.run.run``; ``summary`` is a JSON string) and prints
one summary line on stdout.  Invalid scenes, bad option values, unreadable files and a
simulation that fails (non-finite state, contact overflow) print one ``error: ...`` line on
stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import warp as wp

from .commands import add_commands
from .contacts import ContactOverflowError
from .quiet import announce_compiles, init_warp, quiet_warp  # noqa: F401  (quiet_warp: old callers)
from .run import format_summary, run
from .scene import SceneError, load_scene
from .simulator import NonFiniteStateError, expected_steps


class CommandError(ValueError):
    """A failed command (bad option value, unwritable output, failed run): one ``error:`` line."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m warp_sim",
                                     description="Rigid bodies on a procedural terrain.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    p = commands.add_parser("run", help="run a scene file headless and record it to an .npz",
                            description="Run a scene file headless and record it to an .npz.")
    p.add_argument("scene", metavar="SCENE.toml", help="scene file")
    p.add_argument("--out", default="run.npz", help="output .npz file (default: run.npz)")
    p.add_argument("--device", help="cpu, cuda or cuda:N (default: the scene's [sim] device)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--steps", type=int, help="number of steps of [sim] dt")
    length.add_argument("--duration", type=float, help="simulated seconds (default: [sim] duration)")
    p.add_argument("--record-every", type=int, default=1, metavar="K",
                   help="record a frame every K steps (default: 1); the last step is always recorded")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run_command)
    add_commands(parser, commands)
    return parser


def check_device(device: str):
    if not re.fullmatch(r"cpu|cuda(:\d+)?", device):
        raise CommandError(f"--device must be cpu, cuda or cuda:N, got {device!r}")
    if device.startswith("cuda"):
        ordinal = int(device.partition(":")[2] or 0)
        available = wp.get_cuda_device_count()
        if ordinal >= available:
            raise CommandError(
                f"device {device!r} is not available ({available} CUDA devices found); try --device cpu"
            )


def run_command(args) -> int:
    if args.steps is not None and args.steps < 1:
        raise CommandError(f"--steps must be an integer >= 1, got {args.steps}")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise CommandError(f"--duration must be a positive finite number of seconds, got {args.duration}")
    if args.record_every < 1:
        raise CommandError(f"--record-every must be an integer >= 1, got {args.record_every}")
    out = Path(args.out)
    if out.suffix != ".npz":  # numpy would append it anyway
        out = out.with_name(out.name + ".npz")
    if not out.parent.is_dir():
        raise CommandError(f"--out: directory '{out.parent}' does not exist")

    scene = load_scene(args.scene)
    device = args.device or scene.config.device
    check_device(device)
    steps = args.steps or expected_steps(args.duration or scene.config.duration, scene.config.dt)

    sim = scene.build(device)
    try:
        result = run(sim, steps, record_every=args.record_every, progress=not args.quiet)
    except NonFiniteStateError as e:
        raise CommandError(f"{args.scene}: {e}; body {e.body} is {scene.body_origin(e.body)}") from None
    except ContactOverflowError as e:
        raise CommandError(f"{args.scene}: {e}") from None

    summary = result.pop("summary")
    summary.update(scene=scene.name, device=device, dt=scene.config.dt, substeps=scene.config.substeps,
                   integrator=scene.config.integrator)
    try:
        np.savez_compressed(out, summary=json.dumps(summary), **result)
    except OSError as e:
        raise CommandError(f"cannot write '{out}': {e.strerror or e}") from None
    if not args.quiet:
        print(f"wrote {out}", file=sys.stderr)
    print(format_summary(summary))
    return 0


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # usage errors (status 2) and --help (0) return instead of exiting
        return e.code if isinstance(e.code, int) else 2
    init_warp(verbose=getattr(args, "verbose", False))
    if not getattr(args, "quiet", False):
        announce_compiles()
    try:
        return args.func(args)
    except (SceneError, CommandError, NonFiniteStateError, ContactOverflowError) as e:
        print(f"error: {e}", file=sys.stderr)
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    return 2
