"""Run files: frames streamed to disk in chunks, read back with one call, and checkpoints.

    from warp_sim.recording import load_run
    run = load_run("run.npz")
    run["position"]          # (F, N, 3) float32
    run["summary"]           # dict: steps, rates, stop_reason, ...
    run["metadata"]          # dict: scene text, settings, seed, versions, device, machine

``load_run(path) -> dict`` (a stable signature, other tools build on it) returns

    time (F) float64, position (F, N, 3), orientation (F, N, 4; x y z w), velocity (F, N, 3),
    angular_velocity (F, N, 3; world frame) float32, kinetic_energy (F), max_penetration (F)
    float64, contact_count (F) int32, shape (N) int32, size (N, 3) float32, the terrain_* keys
    (0-d entries as Python str / float), summary (dict) and metadata (dict; {} for files
    written before metadata existed).

It reads the finished ``.npz`` (today's format and the older one written before streaming), and
also a run that never finished: when ``path`` is missing but its chunk directory
``<path>.chunks/`` exists (the process was killed or crashed), the chunks written so far are
read and ``summary["stop_reason"]`` is ``"incomplete"``.

Streaming: ``RunWriter`` writes every ``chunk_frames`` frames as one small .npz into
``<out>.chunks/`` (each written to a temporary name, then renamed: a chunk is whole or absent).
``finish`` joins the chunks into ``<out>`` (one array per key, streamed entry by entry, so
joining never holds more than one chunk in memory), adds ``summary`` and ``metadata`` as JSON
strings, and removes the chunk directory.  The run code calls ``finish`` whatever ended the run
(completed, Ctrl-C, non-finite state, contact overflow, another exception), so every simulated
frame is kept and ``summary`` says where (``stop_step``) and why (``stop_reason``) it stopped.

Checkpoints: ``save_checkpoint`` writes what ``Simulator.snapshot()`` holds (every persistent
array, plus the second state buffer) as plain arrays in an .npz (no pickle), with the run's
settings as JSON; ``restore_checkpoint`` puts them back into a Simulator built from the same
scene, after which stepping continues bit-identically on the CPU.  They hold the arrays in the
Model's internal body order (``[sim] body_order``, body_order.py) with that order itself
(``body_scene_index``), and resume only into a Model that stores its bodies in the same order.
"""

from __future__ import annotations

import json
import os
import shutil
import zipfile
from pathlib import Path

import numpy as np

FRAME_KEYS = ("time", "position", "orientation", "velocity", "angular_velocity", "kinetic_energy",
              "max_penetration", "contact_count")
FRAME_DTYPES = {"time": np.float64, "position": np.float32, "orientation": np.float32, "velocity": np.float32,
                "angular_velocity": np.float32, "kinetic_energy": np.float64, "max_penetration": np.float64,
                "contact_count": np.int32}
FRAME_WIDTH = {"position": 3, "orientation": 4, "velocity": 3, "angular_velocity": 3}
CHUNK_FRAMES = 256
FORMAT_VERSION = 2
CHECKPOINT_FORMAT = 2  # 2: the solver's support shares (staged.support_share) saved


def chunk_dir(path) -> Path:
    path = Path(path)
    return path.with_name(path.name + ".chunks")


def frame_bytes(bodies: int) -> int:
    """Bytes one recorded frame takes in memory (and, uncompressed, on disk)."""
    per_body = sum(FRAME_WIDTH.values()) * 4
    return bodies * per_body + 8 * 3 + 4


def check_output_path(path) -> Path:
    """The run file ``path`` as given, checked before anything is simulated.

    No suffix: ``.npz`` is appended (numpy's own habit, kept for old command lines); any other
    suffix than ``.npz`` is an error, and so are a directory, a device or pipe (``/dev/null``), a
    missing parent directory and a place that cannot be written (checked by creating and removing
    a probe file).
    """
    out = Path(path)
    if out.is_dir():
        raise ValueError(f"--out '{path}' is a directory; give a file name such as '{out / 'run.npz'}'")
    if out.exists() and not out.is_file():
        # /dev/null or a pipe: numpy would append .npz and leave a stray '/dev/null.npz' behind
        raise ValueError(f"--out '{path}' is not a regular file (a device or a pipe); give an .npz file name, "
                         f"such as 'run.npz'")
    if out.suffix == "":
        out = out.with_name(out.name + ".npz")
    elif out.suffix != ".npz":
        raise ValueError(f"--out must be an .npz file, got '{path}' (suffix '{out.suffix}')")
    if out.is_dir():
        raise ValueError(f"--out '{out}' is a directory; give a file name such as '{out / 'run.npz'}'")
    if not out.parent.is_dir():
        raise ValueError(f"--out: directory '{out.parent}' does not exist")
    probe = out.with_name(f".{out.name}.probe-{os.getpid()}")
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise ValueError(f"--out: cannot write '{out}': {e.strerror or e}") from None
    return out


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (tuple, set)):
        return list(value)
    return str(value)


def to_json(value) -> str:
    return json.dumps(value, default=_json_default)


class RunWriter:
    """Collects frames and writes them in chunks; ``finish`` makes the final .npz.

    ``static`` holds the per-body and terrain arrays (shape, size, terrain_*), written once.
    """

    def __init__(self, path, bodies: int, static: dict, metadata: dict, chunk_frames: int = CHUNK_FRAMES):
        self.path = Path(path)
        self.bodies = int(bodies)
        self.static = static
        self.metadata = metadata
        self.chunk_frames = max(1, int(chunk_frames))
        self.dir = chunk_dir(self.path)
        if self.dir.exists():
            shutil.rmtree(self.dir)
        self.dir.mkdir()
        np.savez(self.dir / "static.npz", **static)
        (self.dir / "metadata.json").write_text(to_json(metadata))
        self.chunks = 0
        self.frames = 0
        self._buffer = {key: [] for key in FRAME_KEYS}

    def add(self, frame: dict):
        for key in FRAME_KEYS:
            self._buffer[key].append(frame[key])
        if len(self._buffer["time"]) >= self.chunk_frames:
            self.flush()

    def flush(self):
        count = len(self._buffer["time"])
        if count == 0:
            return
        arrays = {key: np.asarray(self._buffer[key], dtype=FRAME_DTYPES[key]) for key in FRAME_KEYS}
        for key, width in FRAME_WIDTH.items():
            arrays[key] = arrays[key].reshape(count, self.bodies, width)
        name = self.dir / f"chunk_{self.chunks:06d}.npz"
        tmp = name.with_name(name.name + ".tmp.npz")
        np.savez(tmp, **arrays)
        os.replace(tmp, name)  # a chunk is whole or absent
        self.chunks += 1
        self.frames += count
        self._buffer = {key: [] for key in FRAME_KEYS}

    def finish(self, summary: dict) -> Path:
        """Join the chunks into the final file (atomically replacing it) and drop the chunk directory."""
        self.flush()
        tmp = self.path.with_name(f".{self.path.name}.tmp-{os.getpid()}")
        _join(self.dir, tmp, self.static, summary, self.metadata, self.bodies)
        os.replace(tmp, self.path)
        shutil.rmtree(self.dir, ignore_errors=True)
        return self.path

    def discard(self):
        shutil.rmtree(self.dir, ignore_errors=True)


def chunk_files(directory: Path) -> list[Path]:
    """The whole chunks in ``directory``, in order (a chunk being written has a .tmp.npz name)."""
    return sorted(p for p in directory.glob("chunk_*.npz") if not p.name.endswith(".tmp.npz"))


def _write_npy_entry(zf: zipfile.ZipFile, name: str, shape: tuple, dtype, pieces):
    """One .npy entry of ``shape`` written piece by piece (C order, so pieces along axis 0 concatenate)."""
    header = {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False, "shape": shape}
    with zf.open(name + ".npy", "w", force_zip64=True) as f:
        np.lib.format.write_array_header_2_0(f, header)
        for piece in pieces:
            f.write(np.ascontiguousarray(piece, dtype=dtype).tobytes())


def _join(directory: Path, out: Path, static: dict, summary: dict, metadata: dict, bodies: int):
    files = chunk_files(directory)
    counts = []
    for path in files:
        with np.load(path) as data:
            counts.append(len(data["time"]))
    total = sum(counts)
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
        for key in FRAME_KEYS:
            shape = (total, bodies, FRAME_WIDTH[key]) if key in FRAME_WIDTH else (total,)

            def pieces(key=key):
                for path in files:
                    with np.load(path) as data:
                        yield data[key]

            _write_npy_entry(zf, key, shape, FRAME_DTYPES[key], pieces())
        for key, value in static.items():
            arr = np.asarray(value)
            _write_npy_entry(zf, key, arr.shape, arr.dtype, [arr])
        for key, text in (("summary", to_json(summary)), ("metadata", to_json(metadata))):
            arr = np.asarray(text)
            _write_npy_entry(zf, key, arr.shape, arr.dtype, [arr])
        arr = np.asarray(FORMAT_VERSION, np.int32)
        _write_npy_entry(zf, "format_version", arr.shape, arr.dtype, [arr])


def _plain(value):
    """0-d arrays as Python scalars (terrain_kind as str, terrain_frequency as float)."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return value.item()
    return value


def load_run(path) -> dict:
    """Read a run file (see the module docstring for the keys); works on unfinished runs too."""
    path = Path(path)
    if path.is_file():
        with np.load(path, allow_pickle=False) as data:
            out = {key: _plain(data[key]) for key in data.files}
        out["summary"] = json.loads(out["summary"]) if "summary" in out else {}
        out["metadata"] = json.loads(out["metadata"]) if "metadata" in out else {}
        out.pop("format_version", None)
        return out
    directory = chunk_dir(path)
    if not directory.is_dir():
        raise FileNotFoundError(f"no run file '{path}' (and no unfinished run '{directory}')")
    with np.load(directory / "static.npz", allow_pickle=False) as data:
        out = {key: _plain(data[key]) for key in data.files}
    metadata = json.loads((directory / "metadata.json").read_text())
    parts = {key: [] for key in FRAME_KEYS}
    for file in chunk_files(directory):
        with np.load(file, allow_pickle=False) as data:
            for key in FRAME_KEYS:
                parts[key].append(data[key])
    bodies = len(np.atleast_1d(out.get("shape", [])))
    for key in FRAME_KEYS:
        empty = np.zeros((0, bodies, FRAME_WIDTH[key]) if key in FRAME_WIDTH else (0,), FRAME_DTYPES[key])
        out[key] = np.concatenate(parts[key]) if parts[key] else empty
    frames = len(out["time"])
    out["summary"] = {
        "stop_reason": "incomplete",
        "stop_detail": "the run ended without closing its file (killed or crashed); frames up to the last "
                       "whole chunk are kept",
        "recorded_frames": frames,
        "sim_time_s": float(out["time"][-1]) if frames else 0.0,
    }
    out["metadata"] = metadata
    return out


# ----------------------------------------------------------------------------------------------
# Checkpoints


def save_checkpoint(path, sim, run_info: dict):
    """Write the simulator's whole state (``snapshot()`` and the second state buffer) to ``path``.

    ``run_info`` (JSON-able: scene text, total steps, record_every, ...) is stored alongside so
    that ``--resume`` can continue the same run.  Written to a temporary name, then renamed.
    """
    path = Path(path)
    snap = sim.snapshot()
    arrays = {f"array_{i:03d}": a.numpy() for i, a in enumerate(snap["arrays"])}
    for i, a in enumerate(sim.states[1].fields()):
        arrays[f"state1_{i:03d}"] = a.numpy()
    for i, a in enumerate(_measured_arrays(sim)):
        arrays[f"measured_{i:03d}"] = a.numpy()
    arrays["body_scene_index"] = sim.model.body_scene_index  # the arrays above are in this order
    info = dict(run_info, step_count=int(snap["step_count"]), array_count=len(snap["arrays"]),
                body_order=sim.model.body_order, checkpoint_format=CHECKPOINT_FORMAT)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}.npz")
    np.savez(tmp, info=np.asarray(to_json(info)), **arrays)
    os.replace(tmp, path)


def _measured_arrays(sim) -> list:
    """Not read by the next step, but by contact_count(): kept so a resumed run's first frame matches."""
    c = sim.contacts
    return [c.pair_count, c.pair_point_count] if c.pair_max > 0 else []


# what restoring reads of every checkpoint's info; the command line's run reads RUN_FIELDS too
CHECKPOINT_FIELDS = (("step_count", int, "an integer >= 0"), ("array_count", int, "an integer >= 0"))
RUN_FIELDS = (("scene_text", str, "the scene's text"), ("total_steps", int, "an integer >= 0"),
              ("device", str, "a device name"))


def check_info_fields(info: dict, path, fields):
    """ValueError naming the first of ``fields`` (key, type, what) that ``info`` lacks or holds wrong."""
    for key, kind, what in fields:
        value = info.get(key)
        if not isinstance(value, kind) or isinstance(value, bool) or (kind is int and value < 0):
            raise ValueError(f"--resume: '{path}' field {key} must be {what}, got {value!r}")


def check_snapshot(snap, targets: list):
    """ValueError unless ``snap`` is a Simulator.snapshot() whose arrays fit ``targets`` (another
    scene's snapshot was half copied, one with step_count -3 accepted, {} a KeyError)."""
    if not isinstance(snap, dict) or "arrays" not in snap or "step_count" not in snap:
        raise ValueError("restore: needs a dict from Simulator.snapshot() (keys 'arrays' and 'step_count')")
    step = snap["step_count"]
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 0:
        raise ValueError(f"restore: step_count must be an integer >= 0, got {step!r}")
    if len(snap["arrays"]) != len(targets):
        raise ValueError(f"restore: the snapshot holds {len(snap['arrays'])} arrays, this simulator "
                         f"{len(targets)}: it was taken of another scene or settings")
    for i, (dst, src) in enumerate(zip(targets, snap["arrays"])):
        if tuple(src.shape) != tuple(dst.shape) or src.dtype != dst.dtype:
            raise ValueError(f"restore: snapshot array {i} has shape {tuple(src.shape)}, this simulator's "
                             f"{tuple(dst.shape)}: it was taken of another scene or settings")


def load_checkpoint(path) -> tuple[dict, dict]:
    """(info, arrays) of a checkpoint file; ValueError when it is not one."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            info = json.loads(str(data["info"]))
            arrays = {key: data[key] for key in data.files if key != "info"}
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as e:
        raise ValueError(f"--resume: '{path}' is not a readable checkpoint file ({e})") from None
    if not isinstance(info, dict):
        raise ValueError(f"--resume: '{path}' is not a readable checkpoint file (its info is not a table)")
    if info.get("checkpoint_format") != CHECKPOINT_FORMAT:
        raise ValueError(f"--resume: '{path}' has checkpoint format {info.get('checkpoint_format')!r}, "
                         f"expected {CHECKPOINT_FORMAT}")
    # what resuming reads, checked here so that an edited file is named, not a traceback or a wrong run
    check_info_fields(info, path, CHECKPOINT_FIELDS)
    needed = [f"array_{i:03d}" for i in range(info["array_count"])]
    missing = [key for key in needed if key not in arrays]
    if missing:
        raise ValueError(f"--resume: '{path}' lacks the state array {missing[0]!r} its info announces")
    return info, arrays


def restore_checkpoint(sim, info: dict, arrays: dict):
    """Put a checkpoint's arrays back into ``sim`` (built from the same scene and settings)."""
    import warp as wp

    order = info.get("body_order", "scene")  # checkpoints written before body_order: the scene's
    stored = arrays.get("body_scene_index", np.arange(sim.model.body_count))
    moved = len(stored) == sim.model.body_count and not np.array_equal(stored, sim.model.body_scene_index)
    if order != sim.model.body_order:
        raise ValueError(f"--resume: the checkpoint stores its bodies in body_order {order!r}, this simulator in "
                         f"{sim.model.body_order!r}: build it with [sim] body_order = {order!r}")
    if moved:  # another body count is another scene, refused below
        raise ValueError(f"--resume: the checkpoint's body_order {order!r} put the bodies in another order than this "
                         f"simulator's (written by another version of body_order.py?)")
    targets = sim._persistent_arrays()
    if len(targets) != info["array_count"]:
        raise ValueError(f"--resume: the checkpoint holds {info['array_count']} state arrays but this scene's "
                         f"simulator has {len(targets)}: it was written for another scene or settings")
    for i, dst in enumerate(targets):
        src = arrays[f"array_{i:03d}"]
        if tuple(src.shape[:dst.ndim]) != tuple(dst.shape):
            raise ValueError(f"--resume: state array {i} has shape {src.shape} in the checkpoint, "
                             f"{tuple(dst.shape)} in this scene's simulator: another scene or settings")
        dst.assign(wp.array(src, dtype=dst.dtype, device=dst.device))
    for i, dst in enumerate(sim.states[1].fields()):
        dst.assign(wp.array(arrays[f"state1_{i:03d}"], dtype=dst.dtype, device=dst.device))
    for i, dst in enumerate(_measured_arrays(sim)):
        if f"measured_{i:03d}" in arrays:
            dst.assign(wp.array(arrays[f"measured_{i:03d}"], dtype=dst.dtype, device=dst.device))
    sim.step_count = int(info["step_count"])
