"""Scene files: a TOML description of one simulation, validated key by key.

    scene = load_scene("examples/scenes/balls_on_terrain.toml")
    sim = scene.build()                 # a Simulator on the scene's [sim] device

A scene file has the top-level key ``name`` and the tables ``[sim]`` (SimConfig), ``[terrain]``,
``[material]``, ``[[body]]`` (one body each) and ``[[layout]]`` (generated groups of bodies, see
layouts.py).  Bodies are added in this order: every ``[[body]]``, then every ``[[layout]]``.
Keys left out take the defaults of SimConfig, FourierTerrain, PlaneTerrain and Material.

Every key is checked: unknown keys, wrong types, booleans where numbers are expected, NaN and
infinity (TOML allows ``nan`` and ``inf``) and values outside a key's range raise SceneError with
one line naming the file, the key path and the value, e.g.

    scene.toml: [[body]] #3 mass must be a positive finite number, got 0

Tables of an array are numbered from 1 (``[[body]] #1`` is the first ``[[body]]``).  "Finite"
means representable as a 32-bit float (|x| <= 3.4e38), the precision the simulator runs in.
Randomness (layout jitter, orientations, shape mixes) comes from ``np.random.default_rng(seed)``
with the ``[sim] seed``, so a scene file always gives the same bodies.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .builder import Material, ModelBuilder
from .collide.broad_phase import BROAD_PHASES
from .simulator import CONTACT_UPDATES, PAIR_SCHEDULES, SOLVERS, SimConfig, Simulator
from .terrain import FourierTerrain, NoTerrain, PlaneTerrain
from .types import FRICTION_MODELS, INTEGRATORS, ROTATIONS, SHAPES

FLOAT32_MAX = float(np.finfo(np.float32).max)


class SceneError(ValueError):
    """An invalid scene; the message is one line naming the file, the key and the value."""


# ----------------------------------------------------------------------------------------------
# Value checks.  Each spec turns a raw TOML value into a clean Python value or raises _Bad; the
# table reader turns that into "<where> <key> must be <description>, got <value>".


class _Bad(Exception):
    pass


def show(value) -> str:
    """A value as it would be written in TOML, cut to one short line."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, (list, tuple)):
        text = "[" + ", ".join(show(v) for v in value) + "]"
    elif isinstance(value, dict):
        text = "a table {" + ", ".join(str(k) for k in value) + "}"
    elif isinstance(value, np.ndarray):
        text = show(value.tolist())
    else:
        text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def is_finite(value) -> bool:
    try:
        return math.isfinite(value) and abs(value) <= FLOAT32_MAX
    except OverflowError:  # an int too large for a float
        return False


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

    def convert(self, value):
        if not is_number(value) or not is_finite(value):
            raise _Bad
        v = float(value)
        if (self.gt is not None and not v > self.gt) or (self.ge is not None and v < self.ge) or (
            self.le is not None and v > self.le
        ):
            raise _Bad
        return v


@dataclass(frozen=True)
class Integer:
    """A TOML integer (never bool, never a float) with optional bounds."""

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
        if not isinstance(value, int) or isinstance(value, bool):
            raise _Bad
        if (self.ge is not None and value < self.ge) or (self.le is not None and value > self.le):
            raise _Bad
        return int(value)


@dataclass(frozen=True)
class Vector:
    """``n`` finite numbers -> tuple of floats; ``positive``: every entry > 0; ``nonzero``: not all 0."""

    n: int
    default: tuple | None = None
    positive: bool = False
    nonzero: bool = False
    required: bool = False

    def describe(self) -> str:
        if self.positive:
            return f"{self.n} positive finite numbers"
        if self.nonzero:
            return f"a non-zero vector of {self.n} finite numbers"
        return f"{self.n} finite numbers"

    def convert(self, value):
        if not isinstance(value, (list, tuple)) or len(value) != self.n:
            raise _Bad
        if not all(is_number(v) and is_finite(v) for v in value):
            raise _Bad
        out = tuple(float(v) for v in value)
        if self.positive and not all(v > 0 for v in out):
            raise _Bad
        if self.nonzero and not any(v != 0 for v in out):
            raise _Bad
        return out


@dataclass(frozen=True)
class Point:
    """[x, y, z], or [x, z] for "rest on the terrain" -> (x, y or None, z)."""

    default: tuple | None = None
    required: bool = False

    def describe(self) -> str:
        return "2 finite numbers [x, z] or 3 finite numbers [x, y, z]"

    def convert(self, value):
        if not isinstance(value, (list, tuple)) or len(value) not in (2, 3):
            raise _Bad
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
            raise _Bad
        return value


@dataclass(frozen=True)
class Boolean:
    default: bool | None = None
    required: bool = False

    def describe(self) -> str:
        return "true or false"

    def convert(self, value):
        if not isinstance(value, bool):
            raise _Bad
        return value


@dataclass(frozen=True)
class String:
    default: str | None = None
    required: bool = False

    def describe(self) -> str:
        return "a string"

    def convert(self, value):
        if not isinstance(value, str):
            raise _Bad
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
            raise _Bad
        return value


@dataclass(frozen=True)
class Matrix:
    """A rectangular 2-D array of finite numbers -> float64 ndarray (its shape is checked by the caller)."""

    default: None = None
    required: bool = False

    def describe(self) -> str:
        return "a 2-D array (a list of equal-length lists) of finite numbers"

    def convert(self, value):
        if not isinstance(value, (list, tuple)) or not value:
            raise _Bad
        if not all(isinstance(row, (list, tuple)) and len(row) == len(value[0]) and row for row in value):
            raise _Bad
        if not all(is_number(v) and is_finite(v) for row in value for v in row):
            raise _Bad
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
                raise _Bad
            return tuple(Integer(ge=1).convert(v) for v in value)
        return Integer(ge=1).convert(value)


def where_key(where: str, key: str) -> str:
    return f"{where} {key}" if where else key


def read_key(table: dict, key: str, spec, where: str):
    """One key of ``table`` checked against ``spec``; its default (maybe None) when absent."""
    if key not in table:
        if spec.required:
            raise SceneError(f"{where_key(where, key)} is required ({spec.describe()})")
        return spec.default
    value = table[key]
    try:
        return spec.convert(value)
    except _Bad:
        raise SceneError(f"{where_key(where, key)} must be {spec.describe()}, got {show(value)}") from None


def read_table(table, schema: dict, where: str) -> dict:
    """Validate ``table`` against ``schema`` (key -> spec).

    Returns every key that was given, converted, plus the defaults of specs that have one;
    keys without a default that were not given are absent.
    """
    if not isinstance(table, dict):
        raise SceneError(f"{where} must be a table, got {show(table)}")
    for key in table:
        if key not in schema:
            raise SceneError(f"unknown key {where_key(where, key)} (known: {', '.join(schema)})")
    values = {key: read_key(table, key, spec, where) for key, spec in schema.items()}
    return {key: value for key, value in values.items() if value is not None}


# ----------------------------------------------------------------------------------------------
# Schemas.  Defaults of [sim], [terrain] and [material] stay in SimConfig, FourierTerrain,
# PlaneTerrain and Material: a key that is not given is not passed on.  [sim] holds every
# SimConfig field (a test keeps the two in step).

TOP_KEYS = ("name", "sim", "terrain", "material", "body", "layout")

SIM_SCHEMA = {
    "dt": Number(gt=0),
    "substeps": Integer(ge=1),
    "gravity": Vector(3),
    "duration": Number(gt=0),
    "integrator": Choice(tuple(INTEGRATORS)),
    "rotation": Choice(tuple(ROTATIONS)),
    "device": Pattern(r"cpu|cuda(:\d+)?", "'cpu', 'cuda' or 'cuda:N'"),
    "seed": Integer(ge=0),
    "iterations": Integer(ge=1),
    "relax_iterations": Integer(ge=0),
    "contact_hertz": Number(gt=0),
    "damping_ratio": Number(ge=0),
    "max_push_velocity": Number(gt=0),
    "restitution_threshold": Number(ge=0),
    "convergence_tolerance": Number(ge=0),
    "speculative_margin": Number(ge=0),
    "solver": Choice(SOLVERS),
    "sleep": Boolean(),
    "sleep_velocity": Number(gt=0),
    "sleep_time": Number(gt=0),
    "body_contact": Boolean(),
    "broad_phase": Choice(tuple(BROAD_PHASES)),
    "contact_max": Integer(ge=0),
    "contact_update": Choice(CONTACT_UPDATES),
    "pair_schedule": Choice(PAIR_SCHEDULES),
    "graph": Boolean(),
}

TERRAIN_KIND = Choice(("fourier", "plane", "none"), default="none")

FOURIER_SCHEMA = {
    "kind": TERRAIN_KIND,
    "terms": Integer(ge=1, le=32),
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
    "velocity": Vector(3, default=(0.0, 0.0, 0.0)),
    "angular_velocity": Vector(3, default=(0.0, 0.0, 0.0)),
    "restitution": Number(ge=0, le=1),
    "friction": Number(ge=0),
    "static": Boolean(default=False),
}


# ----------------------------------------------------------------------------------------------


@dataclass
class Scene:
    """A parsed scene: settings, a filled ModelBuilder (bodies, terrain, material)."""

    name: str
    config: SimConfig
    builder: ModelBuilder
    checkpoints_per_edge: int | None = None
    source: str = "<scene>"
    # (first body, end, origin) per [[body]] / [[layout]] table, for messages about a body index.
    origins: list = field(default_factory=list)

    @property
    def terrain(self):
        return self.builder.terrain

    @property
    def body_count(self) -> int:
        return len(self.builder.bodies)

    def body_origin(self, index: int) -> str:
        """Which table made body ``index`` (0-based, the simulator's numbering)."""
        for start, end, origin in self.origins:
            if start <= index < end:
                if end - start == 1:
                    return origin
                return f"{origin}, its body {index - start + 1} of {end - start}"
        return "unknown"

    def build(self, device=None) -> Simulator:
        """Upload the model to ``device`` (default: the scene's [sim] device) and make a Simulator."""
        config = replace(self.config)
        if device is not None:
            config.device = str(device)
        model = self.builder.finalize(config.device, self.checkpoints_per_edge)
        return Simulator(model, config)


def load_scene(path) -> Scene:
    """Read and validate a scene file; every problem is a one-line SceneError."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise SceneError(f"cannot read scene file '{path}': {e.strerror or e}") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise SceneError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: TOML syntax error: {e}") from None
    return parse_scene(data, source=str(path))


def parse_scene(data: dict, source: str = "<scene>") -> Scene:
    """Validate a scene given as a dict (the parsed TOML) and fill a ModelBuilder from it."""
    try:
        return _parse(data, source)
    except SceneError as e:
        raise SceneError(f"{source}: {e}") from None


def _parse(data: dict, source: str) -> Scene:
    if not isinstance(data, dict):
        raise SceneError(f"a scene must be a table, got {show(data)}")
    for key in data:
        if key not in TOP_KEYS:
            raise SceneError(f"unknown top-level key {key!r} (known: {', '.join(TOP_KEYS)})")

    name = data.get("name", Path(source).stem if source != "<scene>" else "scene")
    if not isinstance(name, str):
        raise SceneError(f"name must be a string, got {show(name)}")

    config = SimConfig(**read_table(data.get("sim", {}), SIM_SCHEMA, "[sim]"))
    terrain, checkpoints_per_edge = _parse_terrain(data.get("terrain", {}))
    builder = ModelBuilder(Material(**read_table(data.get("material", {}), MATERIAL_SCHEMA, "[material]")))
    builder.set_terrain(terrain)
    scene = Scene(name, config, builder, checkpoints_per_edge, source)

    for i, table in enumerate(_array_of_tables(data, "body"), start=1):
        start = scene.body_count
        _add_body(builder, table, f"[[body]] #{i}")
        scene.origins.append((start, scene.body_count, f"[[body]] #{i}"))

    rng = np.random.default_rng(config.seed)
    for i, table in enumerate(_array_of_tables(data, "layout"), start=1):
        start = scene.body_count
        where = _add_layout(builder, table, i, rng)
        scene.origins.append((start, scene.body_count, where))

    if scene.body_count == 0:
        raise SceneError("the scene has no bodies: add [[body]] or [[layout]] tables")
    return scene


def _array_of_tables(data: dict, key: str) -> list:
    items = data.get(key, [])
    if not isinstance(items, list):
        raise SceneError(f"{key} must be an array of tables ([[{key}]]), got {show(items)}")
    return items


def _parse_terrain(table):
    if not isinstance(table, dict):
        raise SceneError(f"[terrain] must be a table, got {show(table)}")
    kind = read_key(table, "kind", TERRAIN_KIND, "[terrain]")
    schema = {"fourier": FOURIER_SCHEMA, "plane": PLANE_SCHEMA, "none": NONE_SCHEMA}[kind]
    for key in table:
        if key not in schema:
            raise SceneError(f"unknown key [terrain] {key} for kind {kind!r} (known: {', '.join(schema)})")
    values = read_table(table, schema, "[terrain]")
    del values["kind"]
    per_edge = values.pop("checkpoints_per_edge", None)
    if kind == "none":
        return NoTerrain(), per_edge
    if kind == "plane":
        return PlaneTerrain(**values), per_edge
    terrain = FourierTerrain(**values)
    k = terrain.terms
    for key in ("amplitudes", "phases"):
        if key in values and values[key].shape != (k, k):
            rows, cols = values[key].shape
            raise SceneError(
                f"[terrain] {key} must be a terms x terms ({k} x {k}) array, got a {rows} x {cols} array "
                f"{show(table[key])}"
            )
    return terrain, per_edge


def _add_body(builder: ModelBuilder, table, where: str):
    b = read_table(table, BODY_SCHEMA, where)
    shape = b["shape"]
    size_key, other_key = ("radius", "half_extents") if shape == "sphere" else ("half_extents", "radius")
    if other_key in b:
        raise SceneError(f"{where} {other_key} is not valid for shape {shape!r} (use {size_key})")
    if size_key not in b:
        spec = BODY_SCHEMA[size_key]
        raise SceneError(f"{where} {size_key} is required for shape {shape!r} ({spec.describe()})")
    q = np.asarray(b["orientation"])
    common = {
        "mass": b["mass"], "position": b["position"], "orientation": q / np.linalg.norm(q),
        "velocity": b["velocity"], "angular_velocity": b["angular_velocity"],
        "restitution": b.get("restitution"), "friction": b.get("friction"), "static": b["static"],
    }
    if shape == "sphere":
        builder.add_sphere(b["radius"], **common)
    else:
        builder.add_box(b["half_extents"], **common)


def _add_layout(builder: ModelBuilder, table, index: int, rng: np.random.Generator) -> str:
    from . import layouts  # layouts builds its schemas from the specs above

    where = f"[[layout]] #{index}"
    if not isinstance(table, dict):
        raise SceneError(f"{where} must be a table, got {show(table)}")
    type_spec = Choice(tuple(layouts.LAYOUTS), required=True)
    layout_type = read_key(table, "type", type_spec, where)
    where = f"{where} ({layout_type})"
    generator, schema = layouts.LAYOUTS[layout_type]
    params = read_table(table, {"type": type_spec, **schema}, where)
    del params["type"]
    try:
        generator(params, builder, builder.terrain, rng)
    except SceneError as e:
        raise SceneError(f"{where} {e}") from None
    return where
