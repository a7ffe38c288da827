"""Recorded runs as plain data: load an .npz, rebuild its terrain, pick the frame for a time.

``load_recording(path)`` returns the dict of ``warp_sim.recording.load_run`` (arrays, plus
``summary`` and ``metadata`` as dicts) and falls back to reading the .npz directly where that
module is absent.  ``terrain_from_record`` turns the ``terrain_*`` keys (``Simulator.
terrain_record()``) back into the terrain the run used, so a replay or an export shows the
ground the bodies rested on.  ``Playback`` is the clock of a replay: play, pause, speed, scrub.
No OpenGL here; the demo's replay view (render/replay.py) and ``export`` build on it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .terrain import FourierTerrain, NoTerrain, PlaneTerrain

REQUIRED = ("time", "position", "orientation", "shape", "size")


class RecordingError(ValueError):
    """An .npz that is not a recorded run (one-line message naming the file and what is wrong)."""


def _read_npz(path: Path) -> dict:
    with np.load(path, allow_pickle=False) as data:
        record = {k: data[k] for k in data.files}
    for key in ("summary", "metadata"):
        value = record.get(key)
        if value is not None and not isinstance(value, dict):
            try:
                record[key] = json.loads(str(value[()] if isinstance(value, np.ndarray) else value))
            except (TypeError, ValueError):
                record[key] = {}
    return record


def load_recording(path) -> dict:
    """Read a run written by ``python -m warp_sim run`` and check the keys a replay needs."""
    path = Path(path)
    try:
        from .recording import load_run
    except ImportError:  # older checkouts: the plain .npz layout
        load_run = _read_npz
        if not path.is_file():
            raise RecordingError(f"cannot read run file '{path}': no such file") from None
    try:
        record = dict(load_run(path))
    except FileNotFoundError:  # neither the file nor an unfinished run's chunk folder
        if path.is_dir():
            raise RecordingError(f"cannot read run file '{path}': it is a directory; give the .npz that "
                                 f"'python -m warp_sim run --out' wrote") from None
        raise RecordingError(f"cannot read run file '{path}': no such file") from None
    except (OSError, ValueError, KeyError) as e:
        raise RecordingError(f"{path}: not a recorded run ({e})") from None
    missing = [k for k in REQUIRED if k not in record]
    if missing:
        raise RecordingError(f"{path}: not a recorded run (missing {', '.join(missing)})")
    f, n = record["position"].shape[:2] if record["position"].ndim == 3 else (0, 0)
    if record["position"].ndim != 3 or record["orientation"].shape != (f, n, 4) or len(record["time"]) != f \
            or len(record["shape"]) != n or f == 0:
        raise RecordingError(f"{path}: inconsistent arrays (position {record['position'].shape}, "
                             f"orientation {record['orientation'].shape}, time {record['time'].shape}, "
                             f"shape {record['shape'].shape})")
    return record


def terrain_from_record(record: dict):
    """The terrain of a run, from its ``terrain_*`` keys (no keys: no terrain)."""
    kind = str(np.asarray(record.get("terrain_kind", "none")))
    if kind == "fourier":
        a = np.asarray(record["terrain_amplitudes"], np.float64)
        k = a.shape[0]
        # The tables are final A(m, n); FourierTerrain divides its base table by sqrt(m^2 + n^2),
        # so hand it A times that radius with a unit amplitude factor.
        m, n = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
        return FourierTerrain(terms=k, frequency=float(record["terrain_frequency"]), amplitude=1.0, phase=0.0,
                              scale=tuple(float(v) for v in record["terrain_scale"]),
                              offset=tuple(float(v) for v in record["terrain_offset"]),
                              amplitudes=a * np.sqrt(m * m + n * n),
                              phases=np.asarray(record["terrain_phases"], np.float64))
    if kind == "plane":
        return PlaneTerrain(normal=tuple(float(v) for v in record["terrain_normal"]),
                            offset=float(record["terrain_plane_offset"]))
    return NoTerrain()


class Playback:
    """Replay clock over a run's frame times: ``advance(wall_dt)`` moves ``time`` when playing."""

    SPEEDS = (0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)

    def __init__(self, times, playing: bool = True, speed: float = 1.0, loop: bool = True):
        self.times = np.asarray(times, np.float64)
        self.playing = playing
        self.speed = speed
        self.loop = loop
        self.time = float(self.times[0])

    @property
    def start(self) -> float:
        return float(self.times[0])

    @property
    def end(self) -> float:
        return float(self.times[-1])

    @property
    def frame(self) -> int:
        """The last recorded frame at or before ``time``."""
        return int(np.clip(np.searchsorted(self.times, self.time + 1e-12, side="right") - 1,
                           0, len(self.times) - 1))

    def seek_frame(self, frame: int):
        self.time = float(self.times[int(np.clip(frame, 0, len(self.times) - 1))])

    def seek_time(self, t: float):
        self.time = float(np.clip(t, self.start, self.end))

    def toggle(self):
        if not self.playing and self.time >= self.end:  # play again from the start
            self.time = self.start
        self.playing = not self.playing

    def advance(self, wall_dt: float):
        if not self.playing:
            return
        self.time += wall_dt * self.speed
        if self.time > self.end:
            if self.loop and self.end > self.start:
                self.time = self.start + (self.time - self.start) % (self.end - self.start)
            else:
                self.time, self.playing = self.end, False
