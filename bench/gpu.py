"""GPU benchmark in one prepared run (at most ~8 minutes on one H200), results after each part.

    python bench/gpu.py --out OUT [--device cuda:0] [--budget 450] [--quick]
    python bench/gpu.py --compile-only --out OUT [--device cuda:0]   # fill the kernel cache, stop
    python bench/gpu.py --out OUT --parts spheres_terrain,mixed_1000000,capture   # some parts only

Parts, in the order they run (the figures that matter most first), each appended to
OUT/gpu.json, OUT/gpu.csv (one row per measurement) and OUT/gpu.png as soon as it finishes
(a run cut short keeps what it measured):

1. compile: every kernel module loaded for the device on parallel threads (Warp compiles modules
   one at a time on first use; a cold cache would otherwise cost minutes of the run);
2. environment: Warp, device, memory, driver;
3. spheres on the terrain (terrain contact only, dt 1/240, 1 substep), 1M;
4. mixed bodies with body contact (dt 1/60, 4 substeps), 100k and 1M; per-kernel times (CUDA
   kernel timing, or the simulator's stage times on the CPU) and the achieved GB/s against the
   byte model (bench/byte_model.py);
5. capture: a 100k mixed rain stepped with ``graph`` off and on;
6. determinism: two runs with sleeping on, state digests;
7. CPU against the device on a small scene (largest position difference);
8. device memory per body (every array the Simulator holds, and the device's own count);
9. 10M mixed bodies when memory allows (the 1M part's bytes per body, times 1.2, must be free);
10. body order: the 1M mixed rain with its bodies listed in a random order, stored as listed and
    sorted at build (``body_order = "shape_morton"``, warp_sim/body_order.py);
11. Newton's SolverXPBD on the same rain, when ``import newton`` works.

``--quick`` shrinks every count (the CPU test runs it: ``--quick --device cpu``).  Scenes are
built with a vectorised copy of cases.terrain_drop (``rain_model``, checked against it in the
test), since the per-body ModelBuilder takes ~0.3 ms a body.  Each part checks the time left
in ``--budget`` against an estimate from the parts before and is skipped, with the reason
recorded, when it would not fit; every stepping loop stops at a share of the time left
(``Report.cap``), so a device slower than planned shortens the timings instead of the run.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.byte_model import per_body_step  # noqa: E402
from bench.common import machine_info  # noqa: E402
from warp_sim import FourierTerrain, SimConfig, Simulator  # noqa: E402
from warp_sim.body_order import body_order  # noqa: E402
from warp_sim.builder import box_checkpoints, inertia_box, random_quaternions  # noqa: E402
from warp_sim.collide.terrain_contact import sphere_terrain_slots  # noqa: E402
from warp_sim.model import Model  # noqa: E402
from warp_sim.types import SHAPE_BOX, SHAPE_SPHERE  # noqa: E402

TERRAIN = FourierTerrain(amplitude=0.5)
FULL = {"capture": 100_000, "spheres": 1_000_000, "mixed": [100_000, 1_000_000, 10_000_000], "determinism": 100_000,
        "compare": 2_000, "order": 1_000_000, "newton": 10_000, "steps": 60, "settle": 30}
QUICK = {"capture": 300, "spheres": 2_000, "mixed": [500, 2_000], "determinism": 300, "compare": 100, "order": 500,
         "newton": 100, "steps": 5, "settle": 2}


def rain_positions(count: int, spacing: float = 1.2, radius: float = 0.25, half: float = 0.25,
                   clearance: float = 0.5, terrain=TERRAIN) -> np.ndarray:
    """(count, 3) starting positions of cases.terrain_drop's grid."""
    side = int(math.ceil(math.sqrt(count)))
    idx = np.arange(count)
    gx = (idx % side - (side - 1) / 2.0) * spacing
    gz = (idx // side - (side - 1) / 2.0) * spacing
    reach = max(radius, float(np.linalg.norm((half,) * 3)))
    return np.stack([gx, terrain.height(gx, gz) + clearance + reach, gz], axis=1)


def rain_model(count: int, shape: str, device, spacing: float = 1.2, radius: float = 0.25, half: float = 0.25,
               clearance: float = 0.5, friction: float = 0.6, rolling_resistance: float = 0.1, seed: int = 0,
               terrain=TERRAIN, order=None, body_scene_index=None, body_order: str = "scene") -> Model:
    """cases.terrain_drop's bodies (same grid, heights, shapes, orientations), built with NumPy.

    ``order``: the grid index of each stored body (default: the grid's order); ``body_scene_index``
    and ``body_order`` go to the Model (the scene order a sorted model maps back to)."""
    rng = np.random.default_rng(seed)
    idx = np.arange(count)
    gx, gy, gz = rain_positions(count, spacing, radius, half, clearance, terrain).T
    quats = random_quaternions(rng, count)
    sphere = np.full(count, shape == "sphere") | ((shape == "mix") & (idx % 2 == 0))
    if order is not None:
        gx, gy, gz, quats, sphere = gx[order], gy[order], gz[order], quats[order], sphere[order]
    q = np.where(sphere[:, None], np.array([0.0, 0.0, 0.0, 1.0]), quats)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    rot = _qm(q)
    box_inertia = inertia_box(1.0, (half,) * 3)
    inertia = np.where(sphere[:, None], 0.4 * radius * radius, box_inertia[None, :])
    points = box_checkpoints((half,) * 3, 3)
    per_body = np.where(sphere, sphere_terrain_slots(terrain, np.full(count, radius)), len(points)).astype(np.int32)
    start = np.concatenate([[0], np.cumsum(per_body)[:-1]]).astype(np.int32)
    local = np.zeros((int(per_body.sum()), 3))
    boxes = np.flatnonzero(~sphere)
    if boxes.size:
        local[(start[boxes][:, None] + np.arange(len(points))[None, :]).ravel()] = np.tile(points, (boxes.size, 1))
    size = np.where(sphere[:, None], np.array([radius, 0.0, 0.0]), np.array([half] * 3))
    h = {
        "body_shape": np.where(sphere, SHAPE_SPHERE, SHAPE_BOX).astype(np.int32),
        "body_size": size.astype(np.float32),
        "body_bound_radius": np.where(sphere, radius, float(np.linalg.norm((half,) * 3))).astype(np.float32),
        "body_covered_faces": np.zeros(count, np.int32),  # every body dynamic: no static face is covered
        "body_inv_mass": np.ones(count, np.float32),
        "body_inertia": inertia.astype(np.float32),
        "body_inv_inertia": (1.0 / inertia).astype(np.float32),
        "body_restitution": np.zeros(count, np.float32),
        "body_friction": np.full(count, friction, np.float32),
        "body_rolling_resistance": np.full(count, rolling_resistance, np.float32),
        "body_checkpoint_start": start,
        "body_checkpoint_count": per_body,
        "body_pos": np.stack([gx, gy, gz], axis=1).astype(np.float32),
        "body_quat": q.astype(np.float32),
        "body_rot": rot.astype(np.float32),
        "body_vel": np.zeros((count, 3), np.float32),
        "body_angmom": np.zeros((count, 3), np.float32),
        "checkpoint_body": np.repeat(idx, per_body).astype(np.int32),
        "checkpoint_local": local.astype(np.float32),
        "checkpoints_per_edge": 3,
    }
    return Model(h, terrain, device, body_scene_index=body_scene_index, body_order=body_order)


def _qm(q):
    """builder.quat_to_matrix for many quaternions at once (x, y, z, w)."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1)], axis=1)


def kernel_modules() -> list[str]:
    root = Path(__file__).resolve().parents[1]
    return [".".join(p.relative_to(root).with_suffix("").parts)
            for p in sorted((root / "warp_sim").rglob("*.py")) if "@wp.kernel" in p.read_text()]


def precompile(device: str) -> dict:
    """Import every kernel module and load them for ``device`` on parallel threads."""
    import importlib
    import os

    names = kernel_modules()
    for name in names:
        importlib.import_module(name)
    start = time.perf_counter()
    wp.load_module("warp_sim", device=device, recursive=True, max_workers=os.cpu_count() or 1)
    return {"modules": names, "load_seconds": round(time.perf_counter() - start, 1)}


GRAPH = {"default": None}  # None: the Simulator's own default (on for CUDA); the graph probe may turn it off


def rain(count, shape, device, body_contact, **config) -> Simulator:
    config.setdefault("sleep", False)
    config.setdefault("graph", GRAPH["default"])
    spacing = 0.9 if body_contact else 1.2
    return Simulator(rain_model(count, shape, device, spacing=spacing),
                     SimConfig(device=str(device), body_contact=body_contact, **config))


def shuffled_rain(count: int, device, mode: str, seed: int = 1) -> Simulator:
    """The mixed rain with body contact, its bodies listed in a random order (a scene assembled
    from an unordered source) and stored in ``mode`` (warp_sim/body_order.py)."""
    shuffle = np.random.default_rng(seed).permutation(count)
    order, scene_index = shuffle, None
    if mode != "scene":
        shapes = np.where(shuffle % 2 == 0, SHAPE_SPHERE, SHAPE_BOX)
        scene_index = body_order(shapes, rain_positions(count, spacing=0.9)[shuffle], mode)
        order = shuffle[scene_index]
    model = rain_model(count, "mix", device, spacing=0.9, order=order, body_scene_index=scene_index, body_order=mode)
    return Simulator(model, SimConfig(device=str(device), body_contact=True, sleep=False))


def digest(sim) -> str:
    h = hashlib.sha256()
    for a in sim.state.fields():
        h.update(np.ascontiguousarray(a.numpy()).tobytes())
    return h.hexdigest()[:16]


def timed_steps(sim, steps: int) -> float:
    """Seconds per step over ``steps`` steps (one call, one read of the overflow flag)."""
    wp.synchronize_device(sim.device)
    start = time.perf_counter()
    sim.step(steps, check=False)
    wp.synchronize_device(sim.device)
    return (time.perf_counter() - start) / steps


def step_for(sim, steps: int, cap: float) -> int:
    """Run up to ``steps`` steps, stopping once ``cap`` seconds have passed; the steps run.  A step
    that costs far more than planned (an untried device) then cannot eat the rest of the run."""
    start, done = time.perf_counter(), 0
    while done < steps:
        chunk = max(1, min(steps - done, done))  # 1, 1, 2, 4, ...: few host syncs, quick stop
        sim.step(chunk, check=False)
        wp.synchronize_device(sim.device)
        done += chunk
        if time.perf_counter() - start > cap:
            break
    return done


def measure(sim, steps: int, cap: float) -> tuple[float, int]:
    """Seconds a step and the steps timed: one warm-up step (it captures the graph where one is
    used), one step timed alone, then as many of ``steps`` as fit in ``cap`` seconds."""
    sim.step(1, check=False)
    one = timed_steps(sim, 1)
    count = int(max(1, min(steps, cap / max(one, 1e-9))))
    return timed_steps(sim, count), count


def sim_bytes(sim) -> int:
    """Bytes of every distinct Warp array reachable from the Simulator's attributes."""
    seen, total, stack = set(), 0, [sim]
    visited = set()
    while stack:
        obj = stack.pop()
        if id(obj) in visited:
            continue
        visited.add(id(obj))
        if isinstance(obj, wp.array):
            if obj.ptr and obj.ptr not in seen:
                seen.add(obj.ptr)
                total += obj.capacity if obj.capacity else obj.size * wp.types.type_size_in_bytes(obj.dtype)
            continue
        if isinstance(obj, (list, tuple)):
            stack.extend(obj)
        elif isinstance(obj, dict):
            stack.extend(obj.values())
        elif hasattr(obj, "__dict__") and type(obj).__module__.startswith("warp_sim"):
            stack.extend(vars(obj).values())
    return total


def kernel_times(sim, steps: int) -> dict[str, float]:
    """Milliseconds a step per kernel (CUDA kernel timing, of direct launches: a graph replay is
    not timed per kernel) or per stage (CPU)."""
    if sim.device.is_cuda:
        graph, sim.use_graph = sim.use_graph, False
        wp.timing_begin(cuda_filter=wp.TIMING_KERNEL)
        sim.step(steps, check=False)
        results = wp.timing_end()
        sim.use_graph = graph
        out: dict[str, float] = {}
        for r in results:
            name = r.name.split("(")[0].removeprefix("forward kernel ")
            out[name] = out.get(name, 0.0) + r.elapsed / steps
        return dict(sorted(out.items(), key=lambda kv: -kv[1]))
    sim.profile, sim.stage_times = True, {}
    sim.step(steps, check=False)
    sim.profile = False
    return {k: 1000.0 * v / steps for k, v in sim.stage_times.items()}


class Report:
    def __init__(self, out: Path, budget: float, only: set[str] | None = None):
        self.out = out
        self.budget = budget
        self.only = only  # part names to run (None: all)
        self.start = time.perf_counter()
        self.parts: dict[str, dict] = {}
        self.rows: list[dict] = []
        out.mkdir(parents=True, exist_ok=True)

    def left(self) -> float:
        return self.budget - (time.perf_counter() - self.start)

    def cap(self, share: float = 0.08, most: float = 20.0) -> float:
        """Seconds one timed loop may take: a share of what is left, at most ``most``."""
        return max(0.5, min(most, share * self.left()))

    def part(self, name: str, fn, estimate: float = 0.0):
        if self.only is not None and name not in self.only:
            self.parts[name] = {"status": "skipped: not in --parts"}
        elif self.left() < estimate:
            self.parts[name] = {"status": f"skipped: {self.left():.0f} s left, needs ~{estimate:.0f} s"}
        else:
            t = time.perf_counter()
            try:
                self.parts[name] = {"status": "ok", **fn()}
            except Exception as e:  # a failed part is recorded; the rest still run
                self.parts[name] = {"status": f"failed: {type(e).__name__}: {e}",
                                    "traceback": traceback.format_exc(limit=4)}
            self.parts[name]["seconds"] = round(time.perf_counter() - t, 2)
        print(f"[gpu.py] {name}: {self.parts[name]['status']} ({self.parts[name].get('seconds', 0)} s)", flush=True)
        self.write()

    def row(self, **values):
        self.rows.append(values)

    def write(self):
        (self.out / "gpu.json").write_text(json.dumps({"parts": self.parts, "rows": self.rows}, indent=2,
                                                      default=str))
        keys = list(dict.fromkeys(k for r in self.rows for k in r))
        with (self.out / "gpu.csv").open("w") as f:
            f.write(",".join(keys) + "\n")
            for r in self.rows:
                f.write(",".join(str(r.get(k, "")) for k in keys) + "\n")
        self.chart()

    def chart(self):
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        timed = [r for r in self.rows if r.get("steps_per_s")]
        fig, ax = plt.subplots(figsize=(9, 4))
        if timed:
            labels = [f"{r['part']}\n{r.get('bodies', '')} {r.get('variant', '')}" for r in timed]
            ax.bar(range(len(timed)), [r["steps_per_s"] for r in timed], color="tab:blue")
            ax.set_xticks(range(len(timed)), labels, fontsize=6)
            ax.set_yscale("log")
        ax.set_ylabel("steps / s")
        ax.set_title(f"bench/gpu.py on {self.parts.get('environment', {}).get('device_name', '?')}", fontsize=9)
        fig.tight_layout()
        fig.savefig(self.out / "gpu.png", dpi=110)
        plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--budget", type=float, default=450.0, help="seconds for the whole run")
    p.add_argument("--quick", action="store_true", help="small counts (CPU test)")
    p.add_argument("--parts", default="", help="comma-separated part names to run (default: all); compile and "
                   "environment always run")
    p.add_argument("--compile-only", action="store_true",
                   help="load every kernel module for --device and the CPU (fills the kernel cache) and stop")
    args = p.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    if args.device.startswith("cuda") and not wp.is_cuda_available():
        print(f"error: --device {args.device} but no CUDA device is available", file=sys.stderr)
        return 2
    if args.compile_only:
        start = time.perf_counter()
        for d in dict.fromkeys([args.device, "cpu"]):
            print(f"[gpu.py] {d}: {precompile(d)['load_seconds']} s", flush=True)
        print(f"[gpu.py] kernel cache filled in {time.perf_counter() - start:.0f} s")
        return 0
    device = wp.get_device(args.device)
    size = QUICK if args.quick else FULL
    steps = size["steps"]
    only = {"compile", "environment", *args.parts.split(",")} if args.parts else None
    report = Report(args.out, args.budget, only)
    report.part("compile", lambda: precompile(args.device))
    per_body_s = {"mixed": 3e-6, "spheres": 1e-6}  # host build + upload per body, updated as parts run

    def environment():
        info = machine_info(args.device)
        if device.is_cuda:
            info.update(total_memory_gb=round(device.total_memory / 2**30, 1), arch=device.arch,
                        driver=wp.get_cuda_driver_version(), free_memory_gb=round(device.free_memory / 2**30, 1))
        return info

    report.part("environment", environment)

    def graph_probe():
        """A small mixed rain with sleeping, stepped directly and replayed from a captured graph:
        equal bit for bit is the capture contract; a capture that fails turns graphs off for the
        parts after this one (so one broken capture does not void every figure), and says so."""
        states = {}
        for graph in (False, True):
            sim = rain(size["determinism"] // 10 or 30, "mix", device, True, sleep=True, graph=graph)
            try:
                sim.step(20, check=False)
            except Exception as e:
                if not graph:
                    raise
                GRAPH["default"] = False
                return {"capture": f"failed: {type(e).__name__}: {e}", "graph_for_later_parts": False}
            states[graph] = digest(sim)
        return {"direct": states[False], "replayed": states[True], "identical": states[False] == states[True],
                "graph_for_later_parts": GRAPH["default"] is not False}

    report.part("graph_probe", graph_probe)

    def spheres():
        n = size["spheres"]
        t = time.perf_counter()
        sim = rain(n, "sphere", device, False, dt=1 / 240, substeps=1)
        per_body_s["spheres"] = (time.perf_counter() - t) / n
        sec, timed = measure(sim, 4 * steps, report.cap())
        model = per_body_step(sim)
        gbs = model["total"] * n / sec / 1e9
        report.row(part="spheres_terrain", bodies=n, variant="dt 1/240", ms_per_step=round(1000 * sec, 4),
                   steps_per_s=round(1 / sec, 1), bytes_per_body_step=round(model["total"]), achieved_gb_s=round(gbs, 1))
        return {"bodies": n, "steps_timed": timed, "steps_per_s": round(1 / sec, 1), "byte_model": model,
                "achieved_gb_s": round(gbs, 1), "kernels_ms": kernel_times(sim, 2)}

    report.part("spheres_terrain", spheres, estimate=size["spheres"] * 1e-5)

    mixed_results = {}

    def mixed(n):
        def run():
            t = time.perf_counter()
            sim = rain(n, "mix", device, True)
            per_body_s["mixed"] = (time.perf_counter() - t) / n
            settled = step_for(sim, size["settle"], report.cap())  # landed: pairs to solve
            sec, timed = measure(sim, steps, report.cap())
            model = per_body_step(sim)
            gbs = model["total"] * n / sec / 1e9
            mem = sim_bytes(sim)
            report.row(part="mixed_body_contact", bodies=n, variant="dt 1/60 x4", ms_per_step=round(1000 * sec, 3),
                       steps_per_s=round(1 / sec, 2), bytes_per_body_step=round(model["total"]),
                       achieved_gb_s=round(gbs, 1), bytes_per_body=round(mem / n))
            mixed_results[n] = mem / n
            out = {"bodies": n, "settle_steps": settled, "steps_timed": timed, "steps_per_s": round(1 / sec, 2),
                   "byte_model": model, "achieved_gb_s": round(gbs, 1),
                   "pairs": int(sim.contacts.pair_count.numpy()[0]), "capacity": sim.pairs.capacity,
                   "bytes_per_body": round(mem / n), "kernels_ms": kernel_times(sim, 1)}
            if device.is_cuda:
                out["device_free_gb_after"] = round(device.free_memory / 2**30, 1)
            return out
        return run

    def mixed_part(n):
        if mixed_results and device.is_cuda:
            need = max(mixed_results.values()) * n * 1.2
            if need > device.free_memory:
                report.parts[f"mixed_{n}"] = {
                    "status": f"skipped: needs ~{need / 2**30:.0f} GiB, {device.free_memory / 2**30:.0f} GiB free"}
                report.write()
                return
        # build, settle and time, each capped: about 3 builds' worth
        report.part(f"mixed_{n}", mixed(n), estimate=n * per_body_s["mixed"] * 3)

    def capture():
        out = {}
        for graph in (False, True):
            sim = rain(size["capture"], "mix", device, True, graph=graph)
            sec, timed = measure(sim, steps, report.cap(most=10))
            out[f"graph_{str(graph).lower()}_ms"] = round(1000 * sec, 3)
            report.row(part="capture", bodies=size["capture"], variant=f"graph={graph}", ms_per_step=round(1000 * sec, 3),
                       steps_per_s=round(1 / sec, 2))
        return out

    def determinism():
        digests, counts = [], []
        for _ in range(2):
            sim = rain(size["determinism"], "mix", device, True, sleep=True)
            if counts:  # the second run takes exactly the first run's steps
                sim.step(counts[0], check=False)
            else:
                counts.append(step_for(sim, 3 * steps, report.cap()))
            digests.append(digest(sim))
            awake = sim.awake_count()
        return {"steps": counts[0], "digests": digests, "identical": digests[0] == digests[1], "awake_at_end": awake,
                "bodies": size["determinism"]}

    def memory():
        n = size["capture"]
        free_before = device.free_memory if device.is_cuda else 0
        sim = rain(n, "mix", device, True)
        sim.step(1, check=False)
        out = {"bodies": n, "simulator_bytes_per_body": round(sim_bytes(sim) / n)}
        if device.is_cuda:
            out["device_bytes_per_body"] = round((free_before - device.free_memory) / n)
        out["mixed_bytes_per_body"] = {str(k): round(v) for k, v in mixed_results.items()}
        return out

    def compare():
        n = size["compare"]
        pos = {}
        for d in ("cpu", str(device)):
            sim = rain(n, "mix", d, True, pair_schedule="colors")
            sim.step(steps, check=False)
            pos[d] = sim.state.body_pos.numpy()
        diff = float(np.abs(pos["cpu"] - pos[str(device)]).max())
        return {"bodies": n, "steps": steps, "max_position_difference_m": diff}

    def orders():
        n = size["order"]
        out = {"bodies": n}
        for mode in ("scene", "shape_morton"):
            variant = "random order" + (", shape_morton" if mode != "scene" else "")
            sim = shuffled_rain(n, device, mode)
            step_for(sim, size["settle"], report.cap(most=10))
            sec, timed = measure(sim, steps, report.cap(most=10))
            report.row(part="body_order", bodies=n, variant=variant, ms_per_step=round(1000 * sec, 3),
                       steps_per_s=round(1 / sec, 2))
            out[f"{mode}_ms"] = round(1000 * sec, 3)
            del sim  # free the first rain's device memory before the second is built
        return out

    def newton_rain():
        try:
            import newton  # noqa: F401
        except Exception as e:  # the wheel is optional
            return {"available": False, "reason": f"{type(e).__name__}: {e}"}
        from bench.peer_engines import NewtonEngine, rain_spec

        spec = rain_spec(size["newton"], "mix", True, 0.0, steps, 1)
        engine = NewtonEngine(spec, 0.25, 1.0, device=str(device))
        engine.step(2)
        wp.synchronize_device(device)
        t = time.perf_counter()
        engine.step(steps)
        wp.synchronize_device(device)
        sec = (time.perf_counter() - t) / steps
        report.row(part="newton_xpbd", bodies=size["newton"], variant="dt 1/240", ms_per_step=round(1000 * sec, 3),
                   steps_per_s=round(1 / sec, 1))
        return {"available": True, "bodies": size["newton"], "steps_per_s": round(1 / sec, 1), "settings": engine.settings}

    # most wanted first: a run cut short by its budget keeps the figures that matter most
    *smaller, largest = size["mixed"]
    for n in smaller:
        mixed_part(n)
    report.part("capture", capture, estimate=10)
    report.part("determinism", determinism, estimate=size["determinism"] * per_body_s["mixed"] * 4)
    report.part("cpu_vs_device", compare, estimate=20)
    report.part("memory", memory, estimate=5)
    mixed_part(largest)
    # two builds and settles of the mixed rain at this size, as the mixed parts measured them
    report.part("body_order", orders, estimate=2 * size["order"] * per_body_s["mixed"] * 3)
    report.part("newton", newton_rain, estimate=30)
    print(f"[gpu.py] wrote {args.out}/gpu.json, gpu.csv, gpu.png in {time.perf_counter() - report.start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
