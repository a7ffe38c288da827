"""Refuse what cannot work before allocating it: memory, float32 terrain evaluation, run length.

Memory (``estimate_bytes``) is a sum of per-item costs read off the arrays the builder, the Model,
the two States, the two contact buffers (the live one, and the penetration probe that a run
recording frames makes on its first frame) and the pair pipeline allocate, plus the recorded
frames a run keeps in memory.  It is compared with ``available_memory()`` (MemAvailable of
/proc/meminfo, else os.sysconf), or on CUDA with the device's free memory, and a run that would
not fit stops with one line naming the key and the estimate.

Terrain resolution (``check_terrain_resolution``).  The Warp kernel evaluates the series from
e^{i f u} by repeated complex multiplication in float32, so a term (m, n) carries a phase error
of about (m |f u| + n |f w|) 2^-24 rad; the height is only meaningful while that stays small.
Over the region where the bodies start, widened by ``REACH`` metres, the largest phase error must
stay under ``PHASE_TOLERANCE`` rad (then every term's height error is below 1 % of its
amplitude); otherwise the terrain is noise to float32 (``frequency = 1e30``: the ball falls
through and no contact is ever found) and the build is refused, naming the highest usable
frequency.  What the contact method resolves is then a warning, not an error: box checkpoints
sample the surface every d = 2 h_max / (checkpoints_per_edge - 1), so by Nyquist a term whose
world wavelength 2 pi / (f |(m / s.x, n / s.z)|) is shorter than 2 d fits between them (the
checkpoints of the face turned to the ground climb to a crest within their cell, which they find
from where the surface is concave: within a quarter wavelength of the crest, which this rule
gives; collide/face_search.py).  A
sphere under the terrain's curvature radius touches it at one point; a wider one searches for up
to five (collide/terrain_contact.py), which stand for the whole sphere while its diameter stays
below the shortest wavelength (about a crest and a trough each way under it).  Terms of world
amplitude under ``SIGNIFICANT_AMPLITUDE`` (1 mm) are ignored there: missing them costs less than
the solver's own slop.

Run length (``check_step_count``): a run's time is estimated as steps x substeps x (bodies x
``BODY_SUBSTEP_S`` + ``SUBSTEP_OVERHEAD_S``), the CPU figures of bench/rain.py rounded up; a run
of more than ``LONG_RUN_STEPS`` steps or ``LONG_RUN_S`` seconds that was asked for only through
the scene's duration needs ``--steps`` or ``--yes``.
"""

from __future__ import annotations

import math
import os
import warnings

import numpy as np

from .validation import SIM_SCHEMA, ValidationError

# Bytes per item (see the module docstring), rounded up.
BYTES_PER_BODY = 1600  # builder columns, float64 work arrays, Model host + device, 2 States, per-body pipeline
BYTES_PER_CHECKPOINT = 160  # model slot (host + device) and two contact buffers' terrain slots
BYTES_PER_PAIR = 640  # pair and previous-pair rows with 4 points each, in two buffers, plus schedule rows
SAFETY = 0.8  # use at most this share of the available memory

PHASE_TOLERANCE = 0.01  # rad
REACH = 10.0  # m around the bodies' starting region where the terrain must evaluate accurately
FLOAT32_EPS = 2.0 ** -24
SIGNIFICANT_AMPLITUDE = 1e-3  # m

BODY_SUBSTEP_S = 1.0e-6
SUBSTEP_OVERHEAD_S = 2.0e-4
LONG_RUN_STEPS = 10_000_000
LONG_RUN_S = 3600.0


def available_memory() -> int:
    """Bytes the system can give without swapping (MemAvailable), or free physical pages."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 1 << 62  # unknown: do not refuse


def human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.3g} EiB"


def human_seconds(s: float) -> str:
    for unit, size in (("years", 365 * 86400), ("days", 86400), ("hours", 3600), ("minutes", 60)):
        if s >= size:
            return f"{s / size:.3g} {unit}"
    return f"{s:.3g} s"


def box_checkpoint_count(per_edge: int) -> int:
    return per_edge ** 3 - max(per_edge - 2, 0) ** 3


def estimate_bytes(bodies: int, boxes: int = 0, per_edge: int = 3, pair_capacity: int | None = None,
                   frames_in_memory: int = 0, sphere_slots: int | None = None) -> dict:
    """Bytes by part: bodies, checkpoints, contact pairs, frames; and the total.  ``sphere_slots``:
    the spheres' terrain slots, one each unless given (wider spheres take more: terrain_contact.py)."""
    from .recording import frame_bytes

    if pair_capacity is None:
        pair_capacity = 8 * bodies + 64 if bodies >= 2 else 0
    parts = {
        "bodies": bodies * BYTES_PER_BODY,
        "checkpoints": ((bodies - boxes if sphere_slots is None else sphere_slots)
                        + boxes * box_checkpoint_count(per_edge)) * BYTES_PER_CHECKPOINT,
        "contact pairs": pair_capacity * BYTES_PER_PAIR,
        "frames": frames_in_memory * frame_bytes(bodies),
    }
    parts["total"] = sum(parts.values())
    return parts


def check_memory(need: int, what: str, available: int | None = None, where: str = "this machine"):
    """ValueError naming ``what`` (the key and its value) when ``need`` bytes will not fit."""
    have = available_memory() if available is None else available
    if need > SAFETY * have:
        raise ValidationError(f"{what} needs about {human_bytes(need)} of memory, more than {where} has "
                              f"available ({human_bytes(have)})")


def check_body_count(count: int, what: str, boxes: int = 0, per_edge: int = 3):
    """Before a layout allocates ``count`` bodies."""
    parts = estimate_bytes(count, boxes, per_edge)
    check_memory(parts["total"], f"{what} gives {count:,} bodies, which")


def _pair_capacity(config, bodies: int) -> int:
    if not config.body_contact or bodies < 2:
        return 0
    return config.contact_max or 8 * bodies + 64


def check_scene_memory(scene, frames_in_memory: int = 0, available: int | None = None):
    """The whole simulation of ``scene``: one line naming the part that dominates and its key."""
    c = scene.builder.columns()
    n = len(c["shape"])
    boxes = int(np.count_nonzero(c["shape"] == 1))
    per_edge = scene.checkpoints_per_edge or scene.builder.default_checkpoints_per_edge()
    capacity = _pair_capacity(scene.config, n)
    from .collide.terrain_contact import sphere_terrain_slots

    sphere_slots = int(sphere_terrain_slots(scene.terrain, c["size"][c["shape"] != 1, 0]).sum())
    parts = estimate_bytes(n, boxes, per_edge, capacity, frames_in_memory, sphere_slots)
    keys = {
        "bodies": f"{n:,} bodies",
        "checkpoints": f"[terrain] checkpoints_per_edge = {per_edge} ({box_checkpoint_count(per_edge):,} per box, "
                       f"{boxes:,} boxes)",
        "contact pairs": f"[sim] contact_max = {scene.config.contact_max}" if scene.config.contact_max
                         else f"the default pair capacity of {n:,} bodies",
        "frames": f"recording {frames_in_memory:,} frames in memory",
    }
    main = max((k for k in keys), key=lambda k: parts[k])
    check_memory(parts["total"], f"{keys[main]}: the run", available)


def check_simulator_memory(model, config):
    """Simulator(model, config): the contact buffers and per-body arrays it is about to allocate."""
    n = model.body_count
    boxes = int(np.count_nonzero(model.host["body_shape"] == 1))
    capacity = _pair_capacity(config, n)
    parts = estimate_bytes(n, boxes, model.host.get("checkpoints_per_edge", 3), capacity)
    what = (f"SimConfig contact_max = {config.contact_max}: the simulator" if config.contact_max and
            parts["contact pairs"] >= parts["bodies"] else f"a simulator of {n:,} bodies")
    import warp as wp

    device = wp.get_device(config.device)
    # on a GPU the contact buffers and per-body arrays live in the device's memory: that is the
    # limit (the estimate's host share makes it err on the safe side)
    if device.is_cuda:
        check_memory(parts["total"], what, device.free_memory, f"{device.alias} ({device.name})")
    else:
        check_memory(parts["total"], what)


def estimate_run_seconds(steps: int, substeps: int, bodies: int) -> float:
    return float(steps) * substeps * (bodies * BODY_SUBSTEP_S + SUBSTEP_OVERHEAD_S)


def check_step_count(scene, steps: int, confirmed: bool = False):
    """A run asked for through [sim] duration alone that is very long needs --steps or --yes."""
    cfg = scene.config
    seconds = estimate_run_seconds(steps, cfg.substeps, scene.body_count)
    if confirmed or (steps <= LONG_RUN_STEPS and seconds <= LONG_RUN_S):
        return
    raise ValidationError(
        f"[sim] duration = {cfg.duration:g} s at dt = {cfg.dt:g} s is {steps:,} steps of {cfg.substeps:,} substeps "
        f"for {scene.body_count:,} bodies, roughly {human_seconds(seconds)} on the CPU; pass --steps N to run "
        f"part of it, or --yes to run it all")


def check_frames_on_disk(frames: int, bodies: int, directory, what: str):
    """The uncompressed size of the recorded frames against the free space where they go."""
    import shutil

    from .recording import frame_bytes

    need = frames * frame_bytes(bodies)
    try:
        free = shutil.disk_usage(directory).free
    except OSError:
        return
    if need > free:
        raise ValidationError(f"{what}: {frames:,} frames of {bodies:,} bodies take up to {human_bytes(need)}, more "
                              f"than the {human_bytes(free)} free in '{directory}'; record fewer frames "
                              f"(--record-every) or run fewer steps")


def check_terrain_resolution(terrain, columns: dict, per_edge: int, where: str = "terrain", warn: bool = True):
    """Refuse a Fourier terrain float32 cannot evaluate where the bodies are; warn about bumps the
    contact method cannot resolve (see the module docstring)."""
    from .terrain import FourierTerrain

    if not isinstance(terrain, FourierTerrain) or terrain.terms < 2 or len(columns["shape"]) == 0:
        return
    pos = columns["position"]
    sx, sy, sz = terrain.scale
    ox, _, oz = terrain.offset
    reach_u = (float(np.max(np.abs(pos[:, 0] - ox))) + REACH) / sx
    reach_w = (float(np.max(np.abs(pos[:, 2] - oz))) + REACH) / sz
    k = terrain.terms - 1
    f = terrain.frequency
    phase_error = k * f * (reach_u + reach_w) * FLOAT32_EPS
    if phase_error > PHASE_TOLERANCE:
        best = PHASE_TOLERANCE / (k * (reach_u + reach_w) * FLOAT32_EPS)
        raise ValidationError(
            f"{where} frequency = {f:g} rad/m with {terrain.terms} terms cannot be evaluated in float32 where the "
            f"bodies are (within {REACH:g} m of them the phase is off by up to {phase_error:.3g} rad, more than "
            f"{PHASE_TOLERANCE:g}); use frequency <= {best:.3g}")

    if not warn:
        return
    amp = np.abs(terrain.amplitude_table()) * abs(sy)
    m, n = np.meshgrid(np.arange(terrain.terms), np.arange(terrain.terms), indexing="ij")
    wavenumber = f * np.sqrt((m / sx) ** 2 + (n / sz) ** 2)
    significant = (amp >= SIGNIFICANT_AMPLITUDE) & (wavenumber > 0)
    if not significant.any():
        return
    shortest = float(2.0 * math.pi / wavenumber[significant].max())
    shape, size = columns["shape"], columns["size"]
    boxes = shape == 1
    if boxes.any() and per_edge >= 2:
        spacing = float(2.0 * size[boxes].max() / (per_edge - 1))
        if spacing > 0.5 * shortest:
            need = math.ceil(4.0 * size[boxes].max() / shortest) + 1
            warnings.warn(
                f"{where}: bumps of wavelength {shortest:.3g} m fit between box checkpoints {spacing:.3g} m apart, "
                f"so boxes can sink into them; use checkpoints_per_edge >= {need} or a lower frequency", stacklevel=3)
    # spheres under the curvature radius touch once: only wide ones that span a wavelength can miss
    from .collide.terrain_contact import WIDE_SPHERE_SLOTS, sphere_terrain_slots

    wide = ~boxes & (sphere_terrain_slots(terrain, size[:, 0]) > 1)
    if wide.any():
        r = float(size[wide, 0].max())
        if 2.0 * r > shortest:
            warnings.warn(
                f"{where}: spheres of radius {r:.3g} m span more than the shortest terrain wavelength "
                f"({shortest:.3g} m); their {WIDE_SPHERE_SLOTS} contact searches can miss further bumps", stacklevel=3)


def warn_heavy_gravity(model, config, substeps: int):
    """Says when gravity presses resting bodies deeper than half the smallest radius or half extent
    (solvers/soft_step.resting_sag), with the substeps that would hold them: silent before, a
    ball under 1e6 m/s^2 sat 0.5 m deep in the ground."""
    from .solvers.soft_step import resting_sag
    from .types import SHAPE_SPHERE

    h = model.host
    dynamic = h["body_inv_mass"] > 0
    if not dynamic.any():
        return
    half = np.where(h["body_shape"] == SHAPE_SPHERE, h["body_size"][:, 0], h["body_size"].min(axis=1))
    smallest = float(half[dynamic].min())
    step = config.dt / substeps
    sag = resting_sag(config.gravity, step, config.contact_hertz, config.damping_ratio)
    if sag <= 0.5 * smallest:
        return
    # the sag goes with h^2 (a2 is fixed while the contact frequency follows the substep rate)
    need = math.ceil(substeps * math.sqrt(sag / (0.5 * smallest)))
    most = SIM_SCHEMA["substeps"].le
    advice = (f"use [sim] substeps >= {need}" if need <= most else
              f"even {most} substeps (the most allowed) would not hold them: lower dt or the gravity")
    warnings.warn(f"gravity of {float(np.linalg.norm(config.gravity)):.3g} m/s^2 at substeps of {step:.3g} s "
                  f"presses resting bodies about {sag:.3g} m into what holds them, more than half the smallest "
                  f"radius or half extent ({smallest:.3g} m); {advice}", RuntimeWarning, stacklevel=3)


STEP_COUNT_MAX = 2**31 - 1  # the step counter is an int32 on the device


def expected_steps(duration: float, dt: float) -> int:
    """Steps of ``dt`` that cover ``duration``; ValueError naming both where that is no count a run
    can hold (``duration = 1e308`` overflowed int())."""
    steps = duration / dt
    if not math.isfinite(steps) or steps > STEP_COUNT_MAX:
        raise ValueError(f"duration = {duration:g} s at dt = {dt:g} s is {steps:.3g} steps, more than "
                         f"{STEP_COUNT_MAX:,} a run can count")
    return max(1, int(math.ceil(steps - 1e-9)))
