"""The rules every entry point checks values against: scene files, ModelBuilder, SimConfig,
the terrain classes and Simulator.step.  One copy, so the messages agree everywhere:

    scene.toml: [[body]] #3 mass must be a positive finite number, got 0     (scene file)
    mass must be a positive finite number, got 0                            (builder.add_sphere)
    SimConfig dt must be a number in [1e-06, 1], got -1                   (SimConfig(dt=-1))

Each spec turns a raw value into a clean Python value or raises ``Bad``; ``check`` turns that
into a ValidationError (a ValueError) naming the field and the value.  "Finite" means
representable as a 32-bit float (|x| <= 3.4e38), the precision the simulator runs in.  The
``check_array`` form applies a spec to a whole NumPy column at once (ModelBuilder.add_bodies)
and names the first bad entry by index.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from .types import FRICTION_MODELS, INTEGRATORS, ROTATIONS, SHAPES

FLOAT32_MAX = float(np.finfo(np.float32).max)
# Starting speeds: nothing faster than light is a rigid body, and past that a body's swept reach
# (speed x dt) and squared speeds leave float32 arithmetic behind: a ball given 1e38 m/s made its
# candidate pairs' contact solve return NaN to a box 5 m the other way in its first step.
SPEED_LIMIT = 299_792_458.0
SPIN_LIMIT = 1.0e12  # rad/s: its square, times an inertia, stays far inside float32's 3.4e38

SOLVERS = ("soft_step", "pushout")
CONTACT_UPDATES = ("step", "substep")
PAIR_SCHEDULES = ("auto", "domains", "colors")
OVERFLOW_PAIRS = ("auto", "split", "in_order")
IMPACT_STAGES = ("auto", "always")
FACE_FRICTIONS = ("patch", "points")  # collide/contact_patch.py
SIMULTANEOUS_IMPACTS = ("sequential", "joint")  # solvers/impact_joint.py
BODY_ORDERS = ("scene", "morton", "shape_morton")  # body_order.py


class ValidationError(ValueError):
    """A value outside its rule; the message is one line naming the field and the value."""


class Bad(Exception):
    """Raised by a spec's ``convert``; carries nothing, the caller words the message."""


def show(value) -> str:
    """A value as it would be written in TOML, cut to one short line."""
    if isinstance(value, (bool, np.bool_)):
        text = "true" if value else "false"
    elif isinstance(value, (list, tuple)):
        text = "[" + ", ".join(show(v) for v in value) + "]"
    elif isinstance(value, dict):
        text = "a table {" + ", ".join(str(k) for k in value) + "}"
    elif isinstance(value, np.ndarray):
        text = show(value.tolist())
    elif isinstance(value, np.generic):
        text = repr(value.item())
    else:
        text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def is_number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def is_finite(value) -> bool:
    try:
        return math.isfinite(value) and abs(value) <= FLOAT32_MAX
    except OverflowError:  # an int too large for a float
        return False


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _range_text(ge, gt, le) -> str:
    parts = []
    if gt is not None:
        parts.append(f"> {gt:g}")
    if ge is not None:
        parts.append(f">= {ge:g}")
    if le is not None:
        parts.append(f"<= {le:g}")
    return " and ".join(parts)


@dataclass(frozen=True)
class Number:
    """A finite number (int or float, never bool) -> float, with optional bounds."""

    default: float | None = None
    gt: float | None = None
    ge: float | None = None
    le: float | None = None
    required: bool = False

    def describe(self) -> str:
        if self.ge is not None and self.le is not None:
            return f"a number in [{self.ge:g}, {self.le:g}]"
        if self.gt == 0 and self.le is None:
            return "a positive finite number"
        bounds = _range_text(self.ge, self.gt, self.le)
        return f"a finite number {bounds}" if bounds else "a finite number"

    def ok(self, v):
        """Elementwise test (floats or float arrays) of finiteness and the bounds."""
        v = np.asarray(v, dtype=np.float64)
        good = np.isfinite(v) & (np.abs(v) <= FLOAT32_MAX)
        with np.errstate(invalid="ignore"):
            if self.gt is not None:
                good &= v > self.gt
            if self.ge is not None:
                good &= v >= self.ge
            if self.le is not None:
                good &= v <= self.le
        return good

    def convert(self, value):
        if not is_number(value) or not is_finite(value):
            raise Bad
        v = float(value)
        if not self.ok(v):
            raise Bad
        return v


@dataclass(frozen=True)
class Integer:
    """An integer (never bool, never a float) with optional bounds."""

    default: int | None = None
    ge: int | None = None
    le: int | None = None
    required: bool = False

    def describe(self) -> str:
        if self.ge is not None and self.le is not None:
            return f"an integer in [{self.ge}, {self.le}]"
        bounds = _range_text(self.ge, None, self.le)
        return f"an integer {bounds}" if bounds else "an integer"

    def convert(self, value):
        if not _is_int(value):
            raise Bad
        if (self.ge is not None and value < self.ge) or (self.le is not None and value > self.le):
            raise Bad
        return int(value)


@dataclass(frozen=True)
class Vector:
    """``n`` finite numbers -> tuple of floats; ``positive``: every entry > 0; ``nonzero``: not all 0;
    ``longest``: the vector's length at most this (``longest_why`` says why, in the message)."""

    n: int
    default: tuple | None = None
    positive: bool = False
    nonzero: bool = False
    required: bool = False
    longest: float | None = None
    longest_why: str = ""

    def describe(self) -> str:
        if self.positive:
            return f"{self.n} positive finite numbers"
        if self.nonzero:
            return f"a non-zero vector of {self.n} finite numbers"
        if self.longest is not None:
            return f"{self.n} finite numbers of length at most {self.longest:.4g} ({self.longest_why})"
        return f"{self.n} finite numbers"

    def ok(self, rows):
        """Row-wise test of an (m, n) float array."""
        rows = np.asarray(rows, dtype=np.float64)
        good = np.all(np.isfinite(rows) & (np.abs(rows) <= FLOAT32_MAX), axis=-1)
        if self.positive:
            good &= np.all(rows > 0, axis=-1)
        if self.nonzero:
            good &= np.any(rows != 0, axis=-1)
        if self.longest is not None:
            with np.errstate(over="ignore", invalid="ignore"):
                good &= np.linalg.norm(np.where(np.isfinite(rows), rows, 0.0), axis=-1) <= self.longest
        return good

    def convert(self, value):
        if isinstance(value, np.ndarray):
            if value.ndim != 1:
                raise Bad
            value = value.tolist()
        if not isinstance(value, (list, tuple)) or len(value) != self.n:
            raise Bad
        if not all(is_number(v) and is_finite(v) for v in value):
            raise Bad
        out = tuple(float(v) for v in value)
        if not self.ok(out):
            raise Bad
        return out


def unit_rows(v, axis: int = -1) -> np.ndarray:
    """``v`` scaled to unit length along ``axis``, in float64, first divided by its largest entry:
    a tiny but non-zero vector has a direction too (1e-300 squared underflows to 0, and the plain
    v / |v| gave inf and NaN)."""
    v = np.asarray(v, dtype=np.float64)
    largest = np.max(np.abs(v), axis=axis, keepdims=True)
    v = v / np.where(largest > 0.0, largest, 1.0)
    return v / np.linalg.norm(v, axis=axis, keepdims=True)


@dataclass(frozen=True)
class Point:
    """[x, y, z], or [x, z] for "rest on the terrain" -> (x, y or None, z)."""

    default: tuple | None = None
    required: bool = False

    def describe(self) -> str:
        return "2 finite numbers [x, z] or 3 finite numbers [x, y, z]"

    def convert(self, value):
        if not isinstance(value, (list, tuple)) or len(value) not in (2, 3):
            raise Bad
        v = Vector(len(value)).convert(value)
        return (v[0], None, v[1]) if len(v) == 2 else v


@dataclass(frozen=True)
class Choice:
    options: tuple[str, ...]
    default: str | None = None
    required: bool = False

    def describe(self) -> str:
        return "one of " + ", ".join(self.options)

    def convert(self, value):
        if not isinstance(value, str) or value not in self.options:
            raise Bad
        return value


@dataclass(frozen=True)
class Boolean:
    default: bool | None = None
    required: bool = False

    def describe(self) -> str:
        return "true or false"

    def convert(self, value):
        if not isinstance(value, (bool, np.bool_)):
            raise Bad
        return bool(value)


@dataclass(frozen=True)
class String:
    default: str | None = None
    required: bool = False

    def describe(self) -> str:
        return "a string"

    def convert(self, value):
        if not isinstance(value, str):
            raise Bad
        return value


@dataclass(frozen=True)
class Pattern:
    """A string matching ``regex`` (full match); ``text`` describes it."""

    regex: str
    text: str
    default: str | None = None
    required: bool = False

    def describe(self) -> str:
        return self.text

    def convert(self, value):
        if not isinstance(value, str) or not re.fullmatch(self.regex, value):
            raise Bad
        return value


@dataclass(frozen=True)
class Matrix:
    """A rectangular 2-D array of finite numbers -> float64 ndarray (its shape is checked by the caller)."""

    default: None = None
    required: bool = False

    def describe(self) -> str:
        return "a 2-D array (a list of equal-length lists) of finite numbers"

    def convert(self, value):
        if isinstance(value, np.ndarray):
            value = value.tolist()
        if not isinstance(value, (list, tuple)) or not value:
            raise Bad
        if not all(isinstance(row, (list, tuple)) and len(row) == len(value[0]) and row for row in value):
            raise Bad
        if not all(is_number(v) and is_finite(v) for row in value for v in row):
            raise Bad
        return np.asarray(value, dtype=np.float64)


@dataclass(frozen=True)
class Count:
    """A total count (int >= 1) or per-axis counts [nx, ny, nz] (ints >= 1)."""

    default: int | None = None
    required: bool = False

    def describe(self) -> str:
        return "an integer >= 1 or 3 integers [nx, ny, nz] >= 1"

    def convert(self, value):
        if isinstance(value, (list, tuple)):
            if len(value) != 3:
                raise Bad
            return tuple(Integer(ge=1).convert(v) for v in value)
        return Integer(ge=1).convert(value)


def where_key(where: str, key: str) -> str:
    return f"{where} {key}" if where else key


def check(spec, value, key: str, where: str = "", error=ValidationError):
    """``value`` converted by ``spec``, or ``error`` "<where> <key> must be <rule>, got <value>"."""
    try:
        return spec.convert(value)
    except Bad:
        raise error(f"{where_key(where, key)} must be {spec.describe()}, got {show(value)}") from None


def check_fields(obj, schema: dict, where: str):
    """Check (and normalise in place) the attributes of a dataclass instance against ``schema``."""
    for key, spec in schema.items():
        if hasattr(obj, key):
            value = getattr(obj, key)
            if value is None and not spec.required:
                continue
            setattr(obj, key, check(spec, value, key, where))


def check_array(spec, values, key: str, where: str = "", rows: bool = False) -> np.ndarray:
    """A whole column checked at once; the first bad entry is named by index.

    ``rows``: ``values`` is (m, n) and ``spec`` a Vector checked row by row.
    """
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim >= 1 and len(arr) > 1 and arr.strides[0] == 0:
        probe = arr[:1]  # one value broadcast to every body: check it once
    else:
        probe = arr
    good = spec.ok(probe)
    if not np.all(good):
        i = int(np.argmin(good))
        raise ValidationError(f"{where_key(where, f'{key}[{i}]')} must be {spec.describe()}, got {show(arr[i])}")
    return arr


# ----------------------------------------------------------------------------------------------
# Schemas.  Defaults of [sim], [terrain] and [material] stay in SimConfig, FourierTerrain,
# PlaneTerrain and Material: a key that is not given is not passed on.  [sim] holds every
# SimConfig field (a test keeps the two in step).


def _broad_phases():
    from .collide.broad_phase import BROAD_PHASES

    return tuple(BROAD_PHASES)


# Bounds past which a value would be accepted and then break something far from where it was
# written: a step under 1 us (dt = 1e-300 overflowed the contact frequency 1 / (4 h) when squared)
# or over 1 s (contacts softer than a quarter hertz); counts of sweeps or substeps in the billions
# (a run "of 5 days" that never ends); a contact frequency of 1e-300 Hz (its square is 0).
SIM_SCHEMA = {
    "dt": Number(ge=1e-6, le=1.0),
    "substeps": Integer(ge=1, le=4096),
    "gravity": Vector(3),
    "duration": Number(gt=0),
    "integrator": Choice(tuple(INTEGRATORS)),
    "rotation": Choice(tuple(ROTATIONS)),
    "device": Pattern(r"cpu|cuda(:\d+)?", "'cpu', 'cuda' or 'cuda:N'"),
    "seed": Integer(ge=0),
    "iterations": Integer(ge=1, le=1000),
    "relax_iterations": Integer(ge=0, le=1000),
    "relax_passes": Integer(ge=1, le=1000),
    "contact_hertz": Number(ge=1e-3),
    "auto_substeps": Boolean(),
    "column_sag": Number(gt=0),
    "landing_depth": Number(gt=0),
    "damping_ratio": Number(ge=0),
    "max_push_velocity": Number(gt=0),
    "restitution_threshold": Number(ge=0),
    "impacts": Choice(IMPACT_STAGES),
    "face_friction": Choice(FACE_FRICTIONS),
    "simultaneous_impacts": Choice(SIMULTANEOUS_IMPACTS),
    "convergence_tolerance": Number(ge=0),
    "convergence_gravity_share": Number(ge=0, le=1),
    "speculative_margin": Number(ge=0),
    "face_search": Boolean(),
    "prune_face_points": Boolean(),
    "still_contacts": Boolean(),
    "solver": Choice(SOLVERS),
    "sleep": Boolean(),
    "sleep_velocity": Number(gt=0),
    "sleep_time": Number(gt=0),
    "body_contact": Boolean(),
    "broad_phase": Choice(_broad_phases()),
    "contact_max": Integer(ge=0),
    "contact_update": Choice(CONTACT_UPDATES),
    "recollide_outrun": Boolean(),
    "turn_refresh": Number(ge=0),
    "pair_schedule": Choice(PAIR_SCHEDULES),
    "overflow_pairs": Choice(OVERFLOW_PAIRS),
    "allow_initial_overlap": Boolean(),
    "graph": Boolean(),
}

# [sim] keys that are not SimConfig fields: they shape the Model a scene builds
# (ModelBuilder.finalize), not the stepping, so they cannot change between steps (update_settings)
# and a checkpoint resumes only into a model built the same way (recording.restore_checkpoint).
SIM_BUILD_SCHEMA = {
    "body_order": Choice(BODY_ORDERS),
}

TERRAIN_KIND = Choice(("fourier", "plane", "none"), default="none")

FOURIER_SCHEMA = {
    "kind": TERRAIN_KIND,
    "terms": Integer(ge=1, le=32),  # terrain.MAX_TERMS: the Warp evaluation keeps that many powers
    "frequency": Number(gt=0),
    "amplitude": Number(ge=0),
    "phase": Number(),
    "seed": Integer(ge=0),
    "scale": Vector(3, positive=True),
    "offset": Vector(3),
    "amplitudes": Matrix(),
    "phases": Matrix(),
    "checkpoints_per_edge": Integer(ge=2),
}

PLANE_SCHEMA = {
    "kind": TERRAIN_KIND,
    "normal": Vector(3, nonzero=True),
    "offset": Number(),
    "checkpoints_per_edge": Integer(ge=2),
}

NONE_SCHEMA = {"kind": TERRAIN_KIND}

MATERIAL_SCHEMA = {
    "restitution": Number(ge=0, le=1),
    "friction": Number(ge=0),
    "friction_model": Choice(tuple(FRICTION_MODELS)),
    "slipperiness": Number(ge=0, le=1),
    "rolling_resistance": Number(ge=0),
}

BODY_SCHEMA = {
    "shape": Choice(tuple(SHAPES), required=True),
    "radius": Number(gt=0),
    "half_extents": Vector(3, positive=True),
    "mass": Number(default=1.0, gt=0),
    "position": Vector(3, default=(0.0, 0.0, 0.0)),
    "orientation": Vector(4, default=(0.0, 0.0, 0.0, 1.0), nonzero=True),
    "velocity": Vector(3, default=(0.0, 0.0, 0.0), longest=SPEED_LIMIT, longest_why="the speed of light, m/s"),
    "angular_velocity": Vector(3, default=(0.0, 0.0, 0.0), longest=SPIN_LIMIT,
                               longest_why="float32 squares of faster spins near overflow, rad/s"),
    "restitution": Number(ge=0, le=1),
    "friction": Number(ge=0),
    "static": Boolean(default=False),
}

STEP_COUNT = Integer(ge=0)


def check_terrain_tables(terrain, where: str):
    """Explicit amplitude / phase tables must be terms x terms."""
    k = terrain.terms
    for key in ("amplitudes", "phases"):
        table = getattr(terrain, key)
        if table is not None and np.shape(table) != (k, k):
            rows, cols = np.shape(table)
            raise ValidationError(
                f"{where_key(where, key)} must be a terms x terms ({k} x {k}) array, got a {rows} x {cols} array "
                f"{show(np.asarray(table))}"
            )
