"""Frame time of the interactive viewer, split into physics / upload / draw.

    xvfb-run -a -s "-screen 0 1280x720x24" python bench/render_bench.py           # 1k, 10k, 100k bodies
    xvfb-run -a -s "-screen 0 1280x720x24" python bench/render_bench.py --counts 1000 --frames 50

Each case is a square grid of mixed spheres and boxes dropped on the Fourier terrain (a scene
description through warp_sim.scene.parse_scene, the same path as a scene file), drawn in a hidden
1280x720 window with the camera framing every body.  Per frame:

    physics  one Simulator step (dt = 1/60 s, 4 substeps) with a device sync
    upload   camera/light blocks + the instance kernel + one glBufferSubData per shape kind
    draw     terrain (tessellated), bodies (instanced), with glFinish after each pass

Warm-up frames (kernel compile, first uploads) are excluded.  Writes
bench/results/render_<device>.{csv,json}.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import machine_info, write_rows  # noqa: E402


def grid_scene(count: int):
    """About ``count`` bodies (a side x side grid), half spheres, half boxes."""
    from warp_sim.scene import parse_scene

    side = max(1, round(math.sqrt(count)))
    return parse_scene({
        "name": f"render bench {side * side}",
        "sim": {"dt": 1.0 / 60.0, "substeps": 4, "seed": 1},
        "terrain": {"kind": "fourier", "terms": 5, "frequency": 0.35, "amplitude": 0.5, "seed": 1},
        "material": {"restitution": 0.1, "friction": 0.6, "rolling_resistance": 0.1},
        "layout": [{"type": "grid", "count": [side, 1, side], "spacing": 1.0, "clearance": 0.3, "shape": "mix",
                    "sphere_fraction": 0.5, "radius": 0.25, "half_extents": [0.25, 0.15, 0.2],
                    "random_orientation": True}],
    }, source="render_bench")


def measure(count: int, frames: int, warmup: int, size: tuple[int, int], device: str) -> dict:
    from OpenGL import GL

    from warp_sim.render_package import ensure_render_package

    ensure_render_package()
    from warp_sim_render.controller import DemoController
    from warp_sim_render.viewer import Viewer

    start = time.perf_counter()
    controller = DemoController(grid_scene(count), device=device, paused=True)
    build_s = time.perf_counter() - start
    viewer = Viewer(controller, *size, visible=False, vsync=False, gui=False, samples=0)
    viewer.profile_passes = True
    rows = {k: [] for k in ("physics", "upload", "terrain", "bodies", "frame")}
    try:
        for frame in range(warmup + frames):
            t0 = time.perf_counter()
            controller.step_forward(1)
            t1 = time.perf_counter()
            viewer.upload()
            wp.synchronize_device(controller.sim.device)
            GL.glFinish()
            t2 = time.perf_counter()
            viewer.draw()
            t3 = time.perf_counter()
            if frame >= warmup:
                rows["physics"].append((t1 - t0) * 1e3)
                rows["upload"].append((t2 - t1) * 1e3)
                rows["terrain"].append(viewer.pass_ms["terrain"])
                rows["bodies"].append(viewer.pass_ms["bodies"])
                rows["frame"].append((t3 - t0) * 1e3)
        notes = controller.recent_notes(1e9)
        spheres, boxes = (b.count for b in viewer.bodies.batches)
        renderer = viewer.window.gl_info()["renderer"]
    finally:
        viewer.close()
    med = {k: statistics.median(v) for k, v in rows.items()}
    return {
        "bodies": controller.body_count,
        "spheres": spheres,
        "boxes": boxes,
        "frames": frames,
        "width": size[0],
        "height": size[1],
        "physics_ms": round(med["physics"], 2),
        "upload_ms": round(med["upload"], 2),
        "draw_ms": round(med["terrain"] + med["bodies"], 2),
        "draw_terrain_ms": round(med["terrain"], 2),
        "draw_bodies_ms": round(med["bodies"], 2),
        "frame_ms": round(med["frame"], 2),
        "fps": round(1000.0 / med["frame"], 2),
        "scene_build_s": round(build_s, 2),
        "renderer": renderer,
        "status": notes[-1] if notes else "ok",
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--counts", type=int, nargs="+", default=[1000, 10000, 100000])
    p.add_argument("--frames", type=int, default=20, help="measured frames per case (100k+: at most 5)")
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--size", default="1280x720")
    p.add_argument("--device", default="cpu")
    p.add_argument("--name", default=None, help="result file stem (default render_<device>)")
    args = p.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    rows = []
    for count in args.counts:
        frames = min(args.frames, 5) if count >= 100_000 else args.frames
        row = measure(count, frames, args.warmup, size, args.device)
        rows.append(row)
        print(f"{row['bodies']:>7} bodies: physics {row['physics_ms']:8.2f} ms  upload {row['upload_ms']:7.2f} ms  "
              f"draw {row['draw_ms']:8.2f} ms (terrain {row['draw_terrain_ms']:.1f}, bodies "
              f"{row['draw_bodies_ms']:.1f})  frame {row['frame_ms']:8.2f} ms  {row['fps']:.1f} fps  {row['status']}")
    meta = machine_info(args.device)
    meta["gl_renderer"] = rows[0]["renderer"] if rows else ""
    csv_path, json_path = write_rows(args.name or f"render_{args.device.split(':')[0]}", rows, meta)
    print(f"wrote {json_path} and {csv_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
