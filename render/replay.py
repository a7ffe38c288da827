"""ReplayController: the demo showing a run recorded by ``python -m warp_sim run`` (no OpenGL here).

    python -m warp_sim.demo --replay run.npz

The recorded bodies and the terrain rebuilt from the run's ``terrain_*`` keys make an ordinary
Model, so the viewer's renderers draw a replay exactly as they draw a live run; nothing is ever
simulated.  Each frame writes the recorded position, rotation and velocity of the frame that the
``Playback`` clock (warp_sim/replay.py) points at into the simulator's state.  Play, pause, the
arrow keys, the timeline and R move that clock instead of the physics; physics, material and
terrain parameters are the recording's and cannot be changed (a note says so).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from warp_sim.builder import Material, ModelBuilder
from warp_sim.replay import Playback, load_recording, terrain_from_record
from warp_sim.simulator import SimConfig
from warp_sim.types import SHAPE_SPHERE

from .controller import DemoController, DemoScene

MAX_WALL_DT = 0.1  # [s] a stalled frame (window drag, first upload) does not skip the run ahead


def quat_matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of unit quaternions (N, 4) in x y z w order."""
    x, y, z, w = (q[:, i].astype(np.float64) for i in range(4))
    m = np.empty((len(q), 3, 3))
    m[:, 0] = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1)
    m[:, 1] = np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1)
    m[:, 2] = np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1)
    return m.astype(np.float32)


def replay_scene(record: dict, name: str) -> DemoScene:
    """A DemoScene with the recorded bodies at their first frame, on the recorded terrain."""
    builder = ModelBuilder(Material())
    builder.set_terrain(terrain_from_record(record))
    pos = np.asarray(record["position"][0], np.float64)
    quat = np.array(record["orientation"][0], np.float64)
    bad = ~np.all(np.isfinite(quat), axis=1) | ~np.any(quat, axis=1)
    quat[bad] = (0.0, 0.0, 0.0, 1.0)  # a frame-0 NaN (a body that blew up at once) draws unrotated
    pos[~np.all(np.isfinite(pos), axis=1)] = 0.0
    shapes, sizes = np.asarray(record["shape"]), np.asarray(record["size"], np.float64)
    if hasattr(builder, "add_bodies"):  # one call instead of a Python loop per body
        builder.add_bodies(shapes, sizes, position=pos, orientation=quat)
    else:
        for b, (shape, size) in enumerate(zip(shapes, sizes, strict=True)):
            if shape == SHAPE_SPHERE:
                builder.add_sphere(float(size[0]), position=pos[b], orientation=quat[b])
            else:
                builder.add_box(tuple(float(v) for v in size), position=pos[b], orientation=quat[b])
    summary = record.get("summary") or {}
    dt = float(summary.get("dt", SimConfig.dt)) if isinstance(summary, dict) else SimConfig.dt
    return DemoScene(name, SimConfig(dt=dt, sleep=False), builder, None, source=name)


class ReplayController(DemoController):
    replay_mode = True

    def __init__(self, path, device: str | None = None, playing: bool = True, frame_dt: float | None = None):
        """``frame_dt``: fixed run seconds per frame at speed 1 (headless renders); None: the wall clock."""
        self.path = Path(path)
        self.record = load_recording(self.path)
        summary = self.record.get("summary") or {}
        name = summary.get("scene") if isinstance(summary, dict) and summary.get("scene") else self.path.stem
        self.playback = Playback(self.record["time"], playing=playing)
        self.frame_dt = frame_dt
        self._clock = None
        super().__init__(replay_scene(self.record, str(name)), device=device, history_budget_mb=1.0,
                         paused=not playing)
        self.frame_count = len(self.record["time"])
        self._shown = None
        self.show(0)

    # DemoController sets and reads ``paused``; in a replay it is the playback clock's state.
    @property
    def paused(self) -> bool:
        return not self.playback.playing

    @paused.setter
    def paused(self, value: bool):
        self.playback.playing = not value
        self._clock = None

    @property
    def frame(self) -> int:
        return self.playback.frame

    def show(self, frame: int):
        """Write recorded frame ``frame`` into the simulator's state (what the renderers read)."""
        if frame == self._shown:
            return
        r, s = self.record, self.sim.state
        s.body_pos.assign(np.ascontiguousarray(r["position"][frame], np.float32))
        s.body_quat.assign(np.ascontiguousarray(r["orientation"][frame], np.float32))
        s.body_rot.assign(quat_matrices(r["orientation"][frame]))
        if "velocity" in r:  # speed colouring
            s.body_vel.assign(np.ascontiguousarray(r["velocity"][frame], np.float32))
        self._shown = frame

    # Time: the clock, not the physics ---------------------------------------------------------

    def toggle_pause(self):
        self.playback.toggle()
        self._clock = None

    def step_forward(self, count: int = 1):
        self.playback.seek_frame(self.playback.frame + count)
        self.show(self.playback.frame)

    def step_backward(self, count: int = 1):
        self.playback.seek_frame(self.playback.frame - count)
        self.show(self.playback.frame)

    def seek(self, frame: int):
        self.playback.seek_frame(frame)
        self.show(self.playback.frame)

    def seek_time(self, t: float):
        self.playback.seek_time(t)
        self.show(self.playback.frame)

    def reset(self):
        self.seek(0)
        self._emit("reset")

    def replay(self):
        self.reset()
        self.playback.playing = True

    def rebuild(self):
        self.note("replay: the bodies and settings are the recording's")

    def update(self) -> bool:
        self.last_physics_ms = 0.0
        now = time.perf_counter()
        if self.playback.playing:
            if self.frame_dt is not None:
                self.playback.advance(self.frame_dt)
            elif self._clock is not None:
                self.playback.advance(min(now - self._clock, MAX_WALL_DT))
        self._clock = now
        before = self._shown
        self.show(self.playback.frame)
        return self._shown != before

    def set_param(self, name: str, value):
        spec = self._spec(name)
        if spec.group in ("sim", "material", "terrain"):
            self.note(f"{name}: a replay shows the recorded run; its settings cannot change")
            return self.get_param(name)
        return super().set_param(name, value)

    def measure(self, render_ms: float, with_energy: bool = True):
        r, f = self.record, self.playback.frame
        contacts = int(r["contact_count"][f]) if "contact_count" in r else 0
        energy = float(r["kinetic_energy"][f]) if "kinetic_energy" in r else float("nan")
        self.stats.add(0.0, render_ms, contacts, energy, len(r["shape"]))
