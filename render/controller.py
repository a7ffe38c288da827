"""DemoController: every change the demo can make, as plain functions (no OpenGL here).

The imgui panel, the keyboard and the tests all go through ``set_param(name, value)``,
``step_forward``/``step_backward``/``seek``, ``toggle_pause``, ``reset``, ``rebuild`` and
``load_scene``.  Values are clamped to the ranges in ``PARAMS``; a clamped or rejected value
leaves a note in ``notes`` (the panel shows them) and never raises.  Unknown names raise ValueError.

One source of truth: a terrain parameter builds a new FourierTerrain, hands it to
``Simulator.set_terrain`` and tells the listeners (the viewer re-uploads its Terrain uniform block
in the same call).  Simulation settings go to ``Simulator.update_settings``.  Material changes
re-finalize the scene's ModelBuilder with the panel's material applied to every body, then reset.
"""

from __future__ import annotations

import copy
import math
import time
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import warp as wp

from warp_sim.builder import Material, ModelBuilder
from warp_sim.simulator import SimConfig, Simulator
from warp_sim.terrain import FourierTerrain
from warp_sim.types import FRICTION_MODELS, INTEGRATORS, ROTATIONS

from .history import History

REPO_ROOT = Path(__file__).resolve().parent.parent
# examples/scenes in a checkout; installed, the same files ship as warp_sim_render/scenes
SCENE_DIR = next((d for d in (Path(__file__).resolve().parent / "scenes", REPO_ROOT / "examples" / "scenes")
                  if d.is_dir()), REPO_ROOT / "examples" / "scenes")
DEFAULT_SCENE = SCENE_DIR / "mixed_rain.toml"
TERRAIN_MAX_TERMS = 32  # what the Terrain uniform block holds


@dataclass(frozen=True)
class Param:
    """One editable value: its group decides what a change does."""

    group: str  # sim | material | terrain | tessellation | view
    kind: str  # float | int | bool | choice | vec3
    lo: float = -math.inf
    hi: float = math.inf
    choices: tuple = ()
    label: str = ""


PARAMS: dict[str, Param] = {
    # Simulator.update_settings
    "dt": Param("sim", "float", 1e-4, 0.1, label="time step [s]"),
    "substeps": Param("sim", "int", 1, 64),
    "auto_substeps": Param("sim", "bool", label="more substeps where columns sag or piles are landed on"),
    "face_search": Param("sim", "bool", label="boxes find crests between their checkpoints"),
    "still_contacts": Param("sim", "bool", label="still bodies keep their terrain contacts"),
    "gravity": Param("sim", "vec3", -100.0, 100.0, label="gravity [m/s^2]"),
    "integrator": Param("sim", "choice", choices=tuple(INTEGRATORS)),
    "rotation": Param("sim", "choice", choices=tuple(ROTATIONS)),
    "iterations": Param("sim", "int", 1, 64, label="solver iterations"),
    "relax_iterations": Param("sim", "int", 0, 64),
    # rebuild
    "restitution": Param("material", "float", 0.0, 1.0),
    "friction": Param("material", "float", 0.0, 2.0, label="friction (Coulomb mu)"),
    "friction_model": Param("material", "choice", choices=tuple(FRICTION_MODELS)),
    "slipperiness": Param("material", "float", 0.0, 1.0, label="slipperiness (gamma)"),
    "rolling_resistance": Param("material", "float", 0.0, 1.0),
    # Simulator.set_terrain + Terrain uniform block
    "amplitude": Param("terrain", "float", 0.0, 20.0),
    "frequency": Param("terrain", "float", 0.01, 5.0),
    "phase": Param("terrain", "float", -100.0, 100.0),
    "terms": Param("terrain", "int", 1, TERRAIN_MAX_TERMS),
    "seed": Param("terrain", "int", 0, 2**31 - 1),
    "scale": Param("terrain", "vec3", 0.05, 100.0),
    # drawing only
    "tess_min_depth": Param("tessellation", "float", 0.0, 5000.0),
    "tess_max_depth": Param("tessellation", "float", 0.1, 5000.0),
    "tess_min_level": Param("tessellation", "float", 1.0, 64.0),
    "tess_max_level": Param("tessellation", "float", 1.0, 64.0),
    "steps_per_frame": Param("view", "int", 1, 100),
    "color_mode": Param("view", "choice", choices=("shape", "speed")),
    "wireframe": Param("view", "bool"),
    "vsync": Param("view", "bool"),
    "show_checkpoints": Param("view", "bool"),
    "show_contacts": Param("view", "bool"),
    "show_normals": Param("view", "bool"),
    "show_velocities": Param("view", "bool"),
    "show_penetration": Param("view", "bool"),
    "debug_on_top": Param("view", "bool"),
}


@dataclass
class ViewSettings:
    """Drawing state edited through set_param (the viewer reads it every frame)."""

    tess_min_depth: float = 4.0
    tess_max_depth: float = 40.0
    tess_min_level: float = 1.0
    tess_max_level: float = 12.0
    steps_per_frame: int = 1
    color_mode: str = "shape"
    wireframe: bool = False
    vsync: bool = True
    show_checkpoints: bool = False
    show_contacts: bool = False
    show_normals: bool = False
    show_velocities: bool = False
    show_penetration: bool = False
    debug_on_top: bool = False  # markers hidden by hills unless asked (they used to show through)


@dataclass
class DemoScene:
    """What the demo needs from a scene (warp_sim.scene.Scene has the same attributes)."""

    name: str
    config: SimConfig
    builder: ModelBuilder
    checkpoints_per_edge: int | None = None
    source: str = "<built-in>"
    body_order: str = "scene"  # how the Model stores the bodies ([sim] body_order, warp_sim/body_order.py)

    @property
    def body_count(self) -> int:
        return len(self.builder.bodies)


def builtin_scene(nx: int = 4, nz: int = 3, layers: int = 1, seed: int = 0) -> DemoScene:
    """A small mixed scene on the default Fourier terrain, independent of the example files."""
    rng = np.random.default_rng(seed)
    terrain = FourierTerrain(amplitude=0.5)
    builder = ModelBuilder(Material(restitution=0.1, friction=0.6, rolling_resistance=0.1))
    builder.set_terrain(terrain)
    top = terrain.offset[1] + terrain.max_height_deviation()
    for layer in range(layers):
        for i in range(nx):
            for k in range(nz):
                x, z = (i - (nx - 1) / 2) * 1.2, (k - (nz - 1) / 2) * 1.2
                y = top + 0.6 + 1.0 * layer
                if (i + k + layer) % 2 == 0:
                    builder.add_sphere(0.3, mass=1.0, position=(x, y, z))
                else:
                    q = rng.normal(size=4)
                    builder.add_box((0.3, 0.2, 0.25), mass=2.0, position=(x, y, z), orientation=q / np.linalg.norm(q))
    return DemoScene("built-in mix", SimConfig(), builder, None)


def load_demo_scene(path=None):
    """A scene file through warp_sim.scene.load_scene, or the built-in one when ``path`` is None."""
    if path is None:
        return builtin_scene()
    from warp_sim.scene import load_scene

    return load_scene(path)


def list_scenes(directory: Path = SCENE_DIR) -> list[Path]:
    return sorted(Path(directory).glob("*.toml"))


class FrameStats:
    """Rolling per-frame measurements for the live plots."""

    def __init__(self, length: int = 300):
        self.frame = deque(maxlen=length)
        self.physics_ms = deque(maxlen=length)
        self.render_ms = deque(maxlen=length)
        self.contacts = deque(maxlen=length)
        self.kinetic_energy = deque(maxlen=length)
        self.awake = deque(maxlen=length)
        self._count = 0

    def add(self, physics_ms: float, render_ms: float, contacts: int, kinetic_energy: float, awake: int = 0):
        self._count += 1
        self.frame.append(self._count)
        self.physics_ms.append(physics_ms)
        self.render_ms.append(render_ms)
        self.contacts.append(contacts)
        self.kinetic_energy.append(kinetic_energy)
        self.awake.append(awake)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.asarray(getattr(self, name), dtype=np.float64)
                for name in ("frame", "physics_ms", "render_ms", "contacts", "kinetic_energy", "awake")}


class DemoController:
    def __init__(self, scene=None, device: str | None = None, history_interval: int = 32,
                 history_budget_mb: float = 256.0, paused: bool = True):
        self.device = device
        self.history_interval = history_interval
        self.history_budget = int(history_budget_mb * (1 << 20))
        self.view = ViewSettings()
        self.paused = paused
        self.notes: list[tuple[float, str]] = []
        self.listeners: list = []
        self.stats = FrameStats()
        self.last_physics_ms = 0.0
        self.scene_path: Path | None = None
        self._install(scene if scene is not None else builtin_scene())

    # Scene and model --------------------------------------------------------------------------

    def _install(self, scene):
        self.scene = scene
        config = copy.deepcopy(scene.config)
        if self.device is not None:
            config.device = str(self.device)
        self.config = config
        self.material = replace(scene.builder.material)
        self.material_edited = False
        self.terrain = scene.builder.terrain
        self._build(event=None)

    def _build(self, event: str | None = "model"):
        """Finalize the scene's bodies with the current terrain (and the panel's material once edited)."""
        builder = self.scene.builder
        if self.material_edited or builder.terrain is not self.terrain:
            builder = ModelBuilder(replace(self.material))
            builder.set_terrain(self.terrain)
            builder.bodies = list(self.scene.builder.bodies)
            if self.material_edited:
                # Bodies store resolved materials, so the panel's material overrides each of them.
                friction = self.material.effective_friction()
                builder.bodies = [dict(b, restitution=self.material.restitution, friction=friction)
                                  for b in builder.bodies]
        per_edge = getattr(self.scene, "checkpoints_per_edge", None) or None
        model = builder.finalize(self.config.device, per_edge, self.scene.body_order)
        self.sim = Simulator(model, copy.deepcopy(self.config))
        self.history = History(self.sim, self.history_interval, self.history_budget)
        self._shown_terrain = self.sim.model.terrain
        if event:
            self._emit(event)

    def load_scene(self, path):
        """Switch to a scene file; on a bad file keep the current scene and leave a note."""
        try:
            scene = load_demo_scene(path)
        except (ValueError, OSError) as exc:  # SceneError is a ValueError: shown in the panel, never fatal
            self.note(f"could not load {path}: {exc}")
            return False
        self.scene_path = Path(path) if path is not None else None
        self._install(scene)
        self._emit("scene")
        return True

    def rebuild(self):
        """Re-finalize the model with the current parameters, then start from the initial layout."""
        self.config = copy.deepcopy(self.sim.config)
        self.terrain = self.sim.model.terrain
        self._build()

    def reset(self):
        """Back to the initial layout keeping every current parameter (R key)."""
        self.sim.reset()
        self.history.clear()
        self._emit("reset")

    def replay(self):
        self.reset()
        self.paused = False

    @property
    def body_count(self) -> int:
        return self.sim.model.body_count

    # Listeners and notes ----------------------------------------------------------------------

    def add_listener(self, callback):
        """``callback(event)`` with event in model, scene, terrain, tessellation, view, reset."""
        self.listeners.append(callback)

    def _emit(self, event: str):
        for callback in self.listeners:
            callback(event)

    def note(self, text: str):
        self.notes.append((time.monotonic(), text))
        del self.notes[:-20]

    def recent_notes(self, seconds: float = 6.0) -> list[str]:
        now = time.monotonic()
        return [text for t, text in self.notes if now - t < seconds]

    # Parameters -------------------------------------------------------------------------------

    def get_param(self, name: str):
        spec = self._spec(name)
        if spec.group == "sim":
            return getattr(self.sim.config, name)
        if spec.group == "material":
            return getattr(self.material, name)
        if spec.group == "terrain":
            t = self.sim.model.terrain
            return getattr(t, name) if isinstance(t, FourierTerrain) else None
        return getattr(self.view, name)

    @staticmethod
    def _spec(name: str) -> Param:
        if name not in PARAMS:
            raise ValueError(f"unknown parameter {name!r} (known: {', '.join(PARAMS)})")
        return PARAMS[name]

    def _coerce(self, name: str, spec: Param, value):
        """Clean value or None; clamping leaves a note."""
        if spec.kind == "bool":
            # bool("false") is True: only real booleans (and 0 / 1) are taken
            if isinstance(value, (bool, np.bool_)) or (isinstance(value, (int, float)) and value in (0, 1)):
                return bool(value)
            self.note(f"{name}: {value!r} is not true or false; unchanged")
            return None
        if spec.kind == "choice":
            if value not in spec.choices:
                self.note(f"{name}: {value!r} is not one of {', '.join(spec.choices)}; unchanged")
                return None
            return value
        if spec.kind == "vec3":
            try:
                vec = [float(v) for v in value]
            except (TypeError, ValueError, OverflowError):
                vec = []
            if len(vec) != 3 or not all(math.isfinite(v) for v in vec):
                self.note(f"{name}: needs three finite numbers, got {value!r}; unchanged")
                return None
            clamped = tuple(min(max(v, spec.lo), spec.hi) for v in vec)
            if clamped != tuple(vec):
                self.note(f"{name}: clamped to [{spec.lo:g}, {spec.hi:g}] per component")
            return clamped
        try:
            number = float(value)
        except (TypeError, ValueError, OverflowError):  # float(10**400) overflows
            number = math.nan
        if not math.isfinite(number):
            self.note(f"{name}: {value!r} is not a finite number; unchanged")
            return None
        clamped = min(max(number, spec.lo), spec.hi)
        if clamped != number:
            self.note(f"{name}: {number:g} is outside [{spec.lo:g}, {spec.hi:g}], clamped to {clamped:g}")
        return round(clamped) if spec.kind == "int" else clamped

    def set_param(self, name: str, value):
        """Apply one parameter change (clamped); returns the value now in force."""
        spec = self._spec(name)
        value = self._coerce(name, spec, value)
        if value is None or value == self.get_param(name):
            return self.get_param(name)
        if spec.group == "sim":
            self.history.fork()
            self.sim.update_settings(**{name: value})
            self.history.record_settings()
        elif spec.group == "material":
            self.material = replace(self.material, **{name: value})
            self.material_edited = True
            self.rebuild()
        elif spec.group == "terrain":
            self._set_terrain_field(name, value)
        elif spec.group == "tessellation":
            self._set_tessellation(name, value)
        else:
            setattr(self.view, name, value)
            self._emit("view")
        return self.get_param(name)

    def _set_terrain_field(self, name: str, value):
        t = self.sim.model.terrain
        if not isinstance(t, FourierTerrain):
            self.note(f"{name}: the scene's terrain is a {t.kind}, not a Fourier series; unchanged")
            return
        changes = {name: value}
        if name == "terms" and (t.amplitudes is not None or t.phases is not None):
            changes.update(amplitudes=None, phases=None)
            self.note("terms: the scene's explicit coefficient tables were replaced by the seeded draw")
        if name == "seed" and t.amplitudes is not None and t.phases is not None:
            self.note("seed: the scene gives explicit coefficient tables, so the seed has no effect")
        self.set_terrain(replace(t, **changes))

    def set_terrain(self, terrain):
        """Swap the terrain for physics and drawing together (a timeline fork)."""
        self.history.fork()
        self.sim.set_terrain(terrain)
        self.history.record_settings()
        self.terrain = terrain
        self._sync_terrain()

    def _sync_terrain(self):
        if self._shown_terrain is not self.sim.model.terrain:
            self._shown_terrain = self.sim.model.terrain
            self._emit("terrain")

    def _set_tessellation(self, name: str, value):
        v = self.view
        setattr(v, name, value)
        if v.tess_min_depth >= v.tess_max_depth:
            if name == "tess_min_depth":
                v.tess_min_depth = max(v.tess_max_depth - 0.1, 0.0)
            else:
                v.tess_max_depth = v.tess_min_depth + 0.1
            self.note("tessellation: min depth must stay below max depth; adjusted")
        if v.tess_min_level > v.tess_max_level:
            if name == "tess_min_level":
                v.tess_min_level = v.tess_max_level
            else:
                v.tess_max_level = v.tess_min_level
            self.note("tessellation: min level must not exceed max level; adjusted")
        self._emit("tessellation")

    # Time -------------------------------------------------------------------------------------

    def toggle_pause(self):
        self.paused = not self.paused

    def _timed(self, action, *args):
        start = time.perf_counter()
        try:
            action(*args)
        except (RuntimeError, ValueError) as exc:  # a non-finite state or overflow must not close the window
            self.paused = True
            self.note(f"simulation stopped: {exc}")
        wp.synchronize_device(self.sim.device)
        self.last_physics_ms = (time.perf_counter() - start) * 1e3
        self._sync_terrain()

    def step_forward(self, count: int = 1):
        self._timed(self.history.step_forward, count)

    def step_backward(self, count: int = 1):
        self._timed(self.history.step_backward, count)

    def seek(self, step: int):
        if isinstance(step, bool) or not isinstance(step, (int, np.integer)):
            self.note(f"seek: {step!r} is not a step number; unchanged")
            return
        self._timed(self.history.seek, int(step))

    def update(self) -> bool:
        """Advance one frame of play (``steps_per_frame`` steps) unless paused; True if stepped."""
        self.last_physics_ms = 0.0
        if self.paused:
            return False
        self.step_forward(self.view.steps_per_frame)
        return True

    def measure(self, render_ms: float, with_energy: bool = True):
        """Record this frame's numbers for the plots."""
        contacts = self.sim.contact_count()
        energy = self.sim.kinetic_energy() if with_energy else math.nan
        self.stats.add(self.last_physics_ms, render_ms, contacts, energy, self.sim.awake_count())
