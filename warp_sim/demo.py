"""Interactive desktop demo: bodies on the Fourier terrain, with a parameter panel and time travel.

    python -m warp_sim.demo [SCENE.toml] [--device cpu|cuda]
    python -m warp_sim.demo SCENE.toml --screenshot out.png --frames 120      # hidden window
    python -m warp_sim.demo SCENE.toml --record frames/ --frames 300 --headless

Without a scene file the demo opens examples/scenes/mixed_rain.toml (or a small built-in scene
when that file is missing).  Headless machines need a display server, e.g.
``xvfb-run -a -s "-screen 0 1280x720x24" python -m warp_sim.demo ...``.

OpenGL, GLFW and imgui are imported here only inside ``main``: the physics package never
imports them.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

HISTORY_MB_MAX = 1.0e9  # a petabyte of keyframes: past any machine, short of float overflow


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 1280x720, got {text!r}") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"size must be between 16x16 and 8192x8192, got {text!r}")
    return w, h


def create_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m warp_sim.demo", description=__doc__.split("\n\n")[0])
    p.add_argument("scene", nargs="?", help="scene file (.toml); default examples/scenes/mixed_rain.toml")
    p.add_argument("--replay", metavar="RUN.npz", help="play a run recorded by 'python -m warp_sim run' "
                                                       "(play, pause, scrub, speed) on the terrain it ran on")
    p.add_argument("--device", default=None, help="Warp device for the physics: cpu or cuda (default: the scene's)")
    p.add_argument("--screenshot", metavar="PNG", help="render --frames frames in a hidden window, save the last")
    p.add_argument("--frames", type=int, default=None, help="stop after this many frames")
    p.add_argument("--record", metavar="DIR", help="write every frame to DIR/frame_00000.png ...")
    p.add_argument("--headless", action="store_true", help="hidden window (implied by --screenshot)")
    p.add_argument("--size", type=parse_size, default=(1280, 720), help="window size, e.g. 1280x720")
    p.add_argument("--no-gui", action="store_true", help="no imgui panel")
    p.add_argument("--play", action="store_true", help="start running (interactive runs start paused)")
    p.add_argument("--no-vsync", action="store_true")
    p.add_argument("--samples", type=int, default=4, help="multisampling (0 = off)")
    p.add_argument("--verbose", action="store_true", help="show Warp's own start-up and compile output")
    p.add_argument("--history-mb", type=float, default=256.0, help="memory budget for time-travel keyframes")
    return p


def _writable_dir(directory: Path, flag: str, target: Path):
    probe = directory / f".warp_sim_probe_{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise ValueError(f"{flag}: cannot write '{target}': {e.strerror or e}") from None


def check_arguments(args):
    """Every path and device flag, before a window opens or a frame is rendered (ValueError, one line)."""
    from warp_sim.cli import check_device
    from warp_sim.launch import cpu_threads

    cpu_threads()  # WARP_SIM_CPU_THREADS
    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames must be an integer >= 1, got {args.frames}")
    if args.samples < 0:
        raise ValueError(f"--samples must be an integer >= 0, got {args.samples}")
    if not (args.history_mb > 0 and args.history_mb <= HISTORY_MB_MAX):  # 1e308 MB overflowed the byte count
        raise ValueError(f"--history-mb must be a number in (0, {HISTORY_MB_MAX:g}], got {args.history_mb}")
    if args.device is not None:
        check_device(args.device)
    if args.screenshot is not None:
        shot = Path(args.screenshot)
        if shot.is_dir():
            raise ValueError(f"--screenshot '{shot}' is a directory; give a file name such as '{shot / 'out.png'}'")
        if shot.suffix.lower() != ".png":
            raise ValueError(f"--screenshot must be a .png file, got '{shot}'")
        if not shot.parent.is_dir():
            raise ValueError(f"--screenshot: directory '{shot.parent}' does not exist")
        _writable_dir(shot.parent, "--screenshot", shot)
    if args.record is not None:
        record = Path(args.record)
        if record.exists() and not record.is_dir():
            raise ValueError(f"--record must be a directory, got the file '{record}'")
        existing = record
        while not existing.exists():  # the viewer creates the missing folders
            existing = existing.parent
        if not existing.is_dir():
            raise ValueError(f"--record: '{existing}' is a file, so '{record}' cannot be made")
        _writable_dir(existing, "--record", record)


def main(argv=None) -> int:
    args = create_parser().parse_args(argv)
    headless = args.headless or args.screenshot is not None
    if args.screenshot and args.frames is None:
        args.frames = 1

    from warp_sim.quiet import announce_compiles, init_warp

    init_warp(verbose=args.verbose)
    announce_compiles()
    try:
        check_arguments(args)
    except ValueError as exc:  # CommandError and the thread count's error are ValueErrors
        print(f"error: {exc}", file=sys.stderr)
        return 2
    from warp_sim.render_package import ensure_render_package

    ensure_render_package()
    from warp_sim_render.controller import DEFAULT_SCENE, DemoController, load_demo_scene

    if args.replay:
        if args.scene:
            print("error: give a scene file or --replay RUN.npz, not both", file=sys.stderr)
            return 2
        from warp_sim_render.replay import ReplayController

        try:
            # headless renders advance a fixed 1/60 s of the run per frame, so they do not
            # depend on how fast this machine draws
            controller = ReplayController(args.replay, device=args.device, playing=True,
                                          frame_dt=1.0 / 60.0 if headless else None)
        except (ValueError, OSError) as exc:  # RecordingError is a ValueError
            print(f"error: {exc}", file=sys.stderr)
            return 2
    else:
        scene_path = args.scene or (DEFAULT_SCENE if DEFAULT_SCENE.is_file() else None)
        try:
            scene = load_demo_scene(scene_path)
        except (ValueError, OSError) as exc:  # SceneError is a ValueError: one clear line
            print(f"error: {exc}", file=sys.stderr)
            return 2
        controller = DemoController(scene, device=args.device, history_budget_mb=args.history_mb,
                                    paused=not (args.play or headless))
        controller.scene_path = Path(scene_path) if scene_path else None

    from warp_sim_render.viewer import Viewer
    from warp_sim_render.window import ContextError

    try:
        viewer = Viewer(controller, *args.size, visible=not headless, vsync=not args.no_vsync,
                        gui=not args.no_gui, samples=args.samples)
    except ContextError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    try:
        written = viewer.run(frames=args.frames, record_dir=args.record, screenshot=args.screenshot)
    finally:
        viewer.close()
    if args.record:
        print(f"wrote {written} frames to {Path(args.record).resolve() / 'frame_00000.png'} ...")
    if args.screenshot:
        print(f"wrote {args.screenshot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
