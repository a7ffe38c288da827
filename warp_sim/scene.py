"""Scene files: a TOML description of one simulation, validated key by key.

    scene = load_scene("examples/scenes/balls_on_terrain.toml")
    sim = scene.build()                 # a Simulator on the scene's [sim] device

A scene file has the top-level key ``name`` and the tables ``[sim]`` (SimConfig, and
``body_order``, which shapes the build: body_order.py), ``[terrain]``,
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

import sys
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .builder import Material, ModelBuilder
from .simulator import SimConfig, Simulator
from .terrain import FourierTerrain, NoTerrain, PlaneTerrain
from .validation import (  # noqa: F401  (the specs and schemas are re-exported for layouts.py and tests)
    BODY_SCHEMA, FLOAT32_MAX, FOURIER_SCHEMA, MATERIAL_SCHEMA, NONE_SCHEMA, PLANE_SCHEMA, SIM_BUILD_SCHEMA, SIM_SCHEMA,
    TERRAIN_KIND, Bad, Boolean, Choice, Count, Integer, Matrix, Number, Pattern, Point, String, ValidationError, Vector,
    check, is_finite, is_number, show, unit_rows, where_key,
)



class SceneError(ValidationError):
    """An invalid scene; the message is one line naming the file, the key and the value."""


def read_key(table: dict, key: str, spec, where: str):
    """One key of ``table`` checked against ``spec``; its default (maybe None) when absent."""
    if key not in table:
        if spec.required:
            raise SceneError(f"{where_key(where, key)} is required ({spec.describe()})")
        return spec.default
    return check(spec, table[key], key, where, error=SceneError)


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
# Schemas: validation.py holds them (one copy for scene files and the Python API).

TOP_KEYS = ("name", "sim", "terrain", "material", "body", "layout")


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
    body_order: str = "scene"  # [sim] body_order: how the Model stores the bodies (body_order.py)

    @property
    def terrain(self):
        return self.builder.terrain

    @property
    def body_count(self) -> int:
        return self.builder.body_count

    def body_origin(self, index: int) -> str:
        """Which table made body ``index`` (0-based, the scene's numbering: what recordings, exports
        and errors use whatever ``body_order`` the Model stores the bodies in)."""
        for start, end, origin in self.origins:
            if start <= index < end:
                if end - start == 1:
                    return origin
                return f"{origin}, its body {index - start + 1} of {end - start}"
        return "unknown"

    def build(self, device=None) -> Simulator:
        """Upload the model to ``device`` (default: the scene's [sim] device) and make a Simulator."""
        from .limits import check_scene_memory

        config = replace(self.config)
        if device is not None:
            config.device = str(device)
        check_scene_memory(self)  # refuse before allocating what the machine does not have
        model = self.builder.finalize(config.device, self.checkpoints_per_edge, self.body_order)
        return Simulator(model, config)


def load_scene(path) -> Scene:
    """Read and validate a scene file; every problem is a one-line SceneError."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise SceneError(f"cannot read scene file '{path}': {e.strerror or e}") from None
    try:
        data = tomllib.loads(raw.decode("utf-8-sig"))  # a byte-order mark (some editors write one) is no TOML
    except UnicodeDecodeError as e:
        raise SceneError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: TOML syntax error: {e}") from None
    return parse_scene(data, source=str(path))


def parse_scene_text(text: str, source: str = "<scene>") -> Scene:
    """A scene from TOML text (e.g. the copy a run file or checkpoint keeps)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{source}: TOML syntax error: {e}") from None
    return parse_scene(data, source=source)


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

    sim = read_table(data.get("sim", {}), {**SIM_SCHEMA, **SIM_BUILD_SCHEMA}, "[sim]")
    build = {key: sim.pop(key) for key in SIM_BUILD_SCHEMA if key in sim}
    config = SimConfig(**sim)
    terrain, checkpoints_per_edge = _parse_terrain(data.get("terrain", {}))
    builder = ModelBuilder(Material(**read_table(data.get("material", {}), MATERIAL_SCHEMA, "[material]")))
    builder.set_terrain(terrain)
    scene = Scene(name, config, builder, checkpoints_per_edge, source, **build)

    for i, table in enumerate(_array_of_tables(data, "body"), start=1):
        start = scene.body_count
        _add_body(builder, table, f"[[body]] #{i}")
        scene.origins.append((start, scene.body_count, f"[[body]] #{i}"))

    rng = np.random.default_rng(config.seed)
    layout_tables = _array_of_tables(data, "layout")
    # a bar on a terminal, and only once building has taken a second (a million-body grid)
    bar = tqdm(total=len(layout_tables) + 1, desc="building scene", unit="step", file=sys.stderr, delay=1.0,
               disable=not sys.stderr.isatty(), leave=False)
    with bar:
        for i, table in enumerate(layout_tables, start=1):
            start = scene.body_count
            where = _add_layout(builder, table, i, rng)
            scene.origins.append((start, scene.body_count, where))
            bar.update(1)
        bar.set_postfix_str("overlap check")
        _finish_checks(scene, terrain, checkpoints_per_edge)
        bar.update(1)
    return scene


def _finish_checks(scene: Scene, terrain, checkpoints_per_edge):
    """What needs every body: at least one, a terrain float32 can evaluate there, no overlaps."""
    from .limits import check_terrain_resolution

    builder = scene.builder
    if scene.body_count == 0:
        raise SceneError("the scene has no bodies: add [[body]] or [[layout]] tables")
    per_edge = checkpoints_per_edge or builder.default_checkpoints_per_edge()
    try:  # the build warns about what the contacts cannot resolve; here only what cannot work
        check_terrain_resolution(terrain, builder.columns(), per_edge, "[terrain]", warn=False)
    except ValueError as e:
        raise SceneError(str(e)) from None
    _check_overlaps(scene)


def _check_overlaps(scene: Scene):
    """Bodies overlapping each other or inside the terrain: an error unless [sim] allow_initial_overlap."""
    from .overlap import describe_overlaps, find_overlaps

    found = find_overlaps(scene.builder)
    if not found:
        return
    text = describe_overlaps(found, scene.body_origin)
    if not scene.config.allow_initial_overlap:
        raise SceneError(f"{text} (set [sim] allow_initial_overlap = true to run anyway)")
    import warnings

    warnings.warn(f"{scene.source}: {text}", stacklevel=3)


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
    k = values.get("terms", FourierTerrain.terms)
    for key in ("amplitudes", "phases"):
        if key in values and values[key].shape != (k, k):
            rows, cols = values[key].shape
            raise SceneError(
                f"[terrain] {key} must be a terms x terms ({k} x {k}) array, got a {rows} x {cols} array "
                f"{show(table[key])}"
            )
    return FourierTerrain(**values), per_edge


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
        "mass": b["mass"], "position": b["position"], "orientation": unit_rows(q),
        "velocity": b["velocity"], "angular_velocity": b["angular_velocity"],
        "restitution": b.get("restitution"), "friction": b.get("friction"), "static": b["static"],
    }
    try:
        if shape == "sphere":
            builder.add_sphere(b["radius"], **common)
        else:
            builder.add_box(b["half_extents"], **common)
    except ValueError as e:  # the builder's derived checks (float32 mass and inertia)
        raise SceneError(f"{where} {e}") from None


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
    except ValueError as e:  # SceneError, the builder's checks and the memory estimate
        raise SceneError(f"{where} {e}") from None
    return where
