"""Command line: ``python -m warp_sim run SCENE.toml [options]`` (also installed as ``warp-sim``).

    python -m warp_sim run examples/scenes/bounce.toml --out bounce.npz --duration 2

runs a scene headless with a progress bar on stderr, streams the recorded frames to a compressed
.npz as it goes (recording.py: read it back with ``recording.load_run``), and prints one summary
line on stdout.  Ctrl-C, a non-finite state or a contact overflow still leave a complete file of
every frame simulated, whose summary says where and why the run stopped.

``--checkpoint-every K`` writes the whole simulator state every K steps to ``--checkpoint FILE``
(default ``<out>.checkpoint.npz``); ``--resume FILE`` continues from one, bit-identically on the
CPU, recording into ``--out`` the frames from the checkpoint's step on.

Invalid scenes, bad option values, unreadable or unwritable files (checked before simulating),
runs too large for the machine's memory, and a simulation that fails print one ``error: ...``
line on stderr and exit with status 2 (130 after Ctrl-C).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path

import warp as wp

from .commands import add_commands
from .contacts import ContactOverflowError
from .quiet import announce_compiles, init_warp, quiet_warp  # noqa: F401  (quiet_warp: old callers)
from .recording import (RUN_FIELDS, RunWriter, check_info_fields, check_output_path, chunk_dir, load_checkpoint,
                        restore_checkpoint, save_checkpoint)
from .run import format_summary, run, static_record
from .scene import SceneError, load_scene, parse_scene_text
from .limits import expected_steps
from .simulator import NonFiniteStateError


class CommandError(ValueError):
    """A failed command (bad option value, unwritable output, failed run): one ``error:`` line."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m warp_sim",
                                     description="Rigid bodies on a procedural terrain.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    p = commands.add_parser("run", help="run a scene file headless and record it to an .npz",
                            description="Run a scene file headless and record it to an .npz.")
    p.add_argument("scene", metavar="SCENE.toml", nargs="?",
                   help="scene file (may be left out with --resume: the checkpoint holds the scene)")
    p.add_argument("--out", default="run.npz",
                   help="output .npz file (default: run.npz; no suffix: .npz is appended; another suffix is an error)")
    p.add_argument("--device", help="cpu, cuda or cuda:N (default: the scene's [sim] device)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--steps", type=int, help="number of steps of [sim] dt (with --resume: the total)")
    length.add_argument("--duration", type=float, help="simulated seconds (default: [sim] duration)")
    p.add_argument("--record-every", type=int, default=1, metavar="K",
                   help="record a frame every K steps (default: 1); the last step is always recorded")
    p.add_argument("--checkpoint-every", type=int, metavar="K", help="save the whole simulator state every K steps")
    p.add_argument("--checkpoint", metavar="FILE", help="checkpoint file (default: <out>.checkpoint.npz)")
    p.add_argument("--resume", metavar="FILE", help="continue the run saved in this checkpoint file")
    p.add_argument("--yes", action="store_true",
                   help="run even when the scene's duration implies a very long run (see --steps)")
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


def _check_options(args):
    if args.steps is not None and args.steps < 1:
        raise CommandError(f"--steps must be an integer >= 1, got {args.steps}")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise CommandError(f"--duration must be a positive finite number of seconds, got {args.duration}")
    if args.record_every < 1:
        raise CommandError(f"--record-every must be an integer >= 1, got {args.record_every}")
    if args.checkpoint_every is not None and args.checkpoint_every < 1:
        raise CommandError(f"--checkpoint-every must be an integer >= 1, got {args.checkpoint_every}")
    if args.scene is None and args.resume is None:
        raise CommandError("a scene file is required (or --resume FILE)")


def _checkpoint_path(args, out: Path) -> Path | None:
    if args.checkpoint_every is None:
        if args.checkpoint is not None:
            raise CommandError("--checkpoint needs --checkpoint-every K")
        return None
    path = Path(args.checkpoint) if args.checkpoint else out.with_name(out.name[:-4] + ".checkpoint.npz")
    if path.suffix != ".npz":
        raise CommandError(f"--checkpoint must be an .npz file, got '{path}'")
    try:
        return check_output_path(path)
    except ValueError as e:
        raise CommandError(str(e).replace("--out", "--checkpoint")) from None


def run_command(args) -> int:
    from .launch import cpu_threads
    from .limits import check_frames_on_disk, check_scene_memory, check_step_count
    from .recording import CHUNK_FRAMES
    from .provenance import provenance

    _check_options(args)
    try:
        cpu_threads()  # a bad WARP_SIM_CPU_THREADS is one line, before anything is built
        out = check_output_path(args.out)
    except ValueError as e:
        raise CommandError(str(e)) from None
    checkpoint = _checkpoint_path(args, out)
    # one file for two jobs: the recording overwrote the checkpoint (or the one being resumed)
    if checkpoint is not None and checkpoint.resolve() == out.resolve():
        raise CommandError(f"--checkpoint and --out name the same file '{out}'")
    if args.resume is not None and Path(args.resume).resolve() == out.resolve():
        raise CommandError(f"--resume and --out name the same file '{out}': the run would overwrite it")

    resume_info = resume_arrays = None
    if args.resume is not None:
        try:
            resume_info, resume_arrays = load_checkpoint(args.resume)
            check_info_fields(resume_info, args.resume, RUN_FIELDS)
        except ValueError as e:
            raise CommandError(str(e)) from None
    if args.scene is not None:
        try:
            scene_text = Path(args.scene).read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError):
            scene_text = None  # load_scene reports it on one line
        scene = load_scene(args.scene)
        source = args.scene
        if resume_info is not None and scene_text != resume_info["scene_text"]:
            raise CommandError(f"--resume: '{args.resume}' was written for another scene text than '{args.scene}'")
    else:
        scene_text = resume_info["scene_text"]
        source = resume_info.get("scene_source", "<checkpoint scene>")
        scene = parse_scene_text(scene_text, source)

    # an empty --device is a bad value, not "not given"
    device = args.device if args.device is not None else (resume_info["device"] if resume_info
                                                          else scene.config.device)
    check_device(device)
    start = int(resume_info["step_count"]) if resume_info else 0
    if args.steps is not None:
        total = args.steps
    elif args.duration is not None:
        total = expected_steps(args.duration, scene.config.dt)
    elif resume_info is not None:
        total = int(resume_info["total_steps"])
    else:
        total = expected_steps(scene.config.duration, scene.config.dt)
        check_step_count(scene, total, confirmed=args.yes)
    if total <= start:
        raise CommandError(f"--resume: the checkpoint is at step {start}, at or past the run's end ({total} steps)")
    record_every = args.record_every
    from .limits import estimate_run_seconds, human_seconds

    seconds = estimate_run_seconds(total - start, scene.config.substeps, scene.body_count)
    if seconds > 60 and not args.quiet:
        print(f"{total - start:,} steps of {scene.config.substeps:,} substeps for {scene.body_count:,} bodies: "
              f"roughly {human_seconds(seconds)} on the CPU", file=sys.stderr)
    frames = (total - start) // record_every + 2
    check_scene_memory(scene, frames_in_memory=min(frames, CHUNK_FRAMES))
    check_frames_on_disk(frames, scene.body_count, out.parent, f"--out '{out}'")

    sim = scene.build(device)
    if not args.quiet and (sim.substeps != scene.config.substeps or sim.substep_plan.sag > sim.substep_plan.budget):
        print(f"{source}: {sim.substep_plan.describe()}", file=sys.stderr)
    if resume_info is not None:
        try:
            restore_checkpoint(sim, resume_info, resume_arrays)
        except ValueError as e:
            raise CommandError(str(e)) from None

    threads = cpu_threads()
    if resume_info is not None and resume_info.get("threads", threads) != threads and device == "cpu":
        # the CPU slab schedule has one slab per thread: another count is another (valid) sweep order
        print(f"warning: '{args.resume}' was written with WARP_SIM_CPU_THREADS={resume_info['threads']}, resuming "
              f"with {threads}: the run goes on validly but not bit-identically", file=sys.stderr)
    run_info = {"scene_text": scene_text, "scene_source": str(source), "device": device, "total_steps": total,
                "record_every": record_every, "threads": threads}
    metadata = provenance(scene_text, sim.config, device,
                          {"scene": scene.name, "scene_source": str(source), "total_steps": total,
                           "record_every": record_every, "resumed_from": args.resume, "start_step": start,
                           "body_order": sim.model.body_order})
    if chunk_dir(out).exists():
        print(f"warning: replacing the chunks of an unfinished run in '{chunk_dir(out)}' (read them first with "
              f"load_run('{out}') to keep them)", file=sys.stderr)
    writer = RunWriter(out, sim.model.body_count, static_record(sim), metadata)
    on_checkpoint = (lambda s: save_checkpoint(checkpoint, s, run_info)) if checkpoint else None
    try:
        result = run(sim, total - start, record_every=record_every, progress=not args.quiet, writer=writer,
                     checkpoint_every=args.checkpoint_every, on_checkpoint=on_checkpoint,
                     summary_extra={"scene": scene.name, "device": device, "dt": sim.config.dt,
                                    "substeps": sim.substeps, "integrator": sim.config.integrator})
    except NonFiniteStateError as e:
        raise CommandError(f"{source}: {e}; body {e.body} is {scene.body_origin(e.body)} "
                           f"(frames up to the last good one are in '{out}')") from None
    except ContactOverflowError as e:
        raise CommandError(f"{source}: {e} (frames so far are in '{out}')") from None
    except KeyboardInterrupt:
        raise KeyboardInterrupt(f"frames up to step {sim.step_count} are in '{out}'") from None

    summary = result["summary"]
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
    except ValueError as e:  # the API's own checks (builder, SimConfig, terrain): one line too
        print(f"error: {e}", file=sys.stderr)
    except KeyboardInterrupt as e:
        print(f"error: interrupted{'; ' + str(e) if str(e) else ''}", file=sys.stderr)
        return 130
    return 2
