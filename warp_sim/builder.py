"""ModelBuilder: collects bodies on the host, then uploads one static Model.

Every value is checked with the rules of the scene files (validation.py): ``add_sphere(-1.0)``
raises ``ValueError: radius must be a positive finite number, got -1.0``.  Beyond the per-key
rules, a body whose mass, inertia or their inverses are not finite, non-zero float32 numbers is
refused (a sphere of radius 1e-30 has an inertia that rounds to 0 in float32, and every energy
would turn into NaN).

``add_bodies`` adds many bodies from NumPy arrays, checked column by column, and gives bit for
bit the bodies that the same ``add_sphere`` / ``add_box`` calls give.  Bodies are stored as
columns (``columns()``); ``bodies`` is a list-like view of one dict per body.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .model import Model
from .collide.covered_faces import covered_faces
from .collide.terrain_contact import sphere_terrain_slots
from .terrain import FourierTerrain, NoTerrain, PlaneTerrain, Terrain
from .types import FRICTION_MODELS, FRICTION_SLIPPERINESS, SHAPE_BOX, SHAPE_SPHERE
from .validation import (BODY_ORDERS, BODY_SCHEMA, MATERIAL_SCHEMA, Boolean, Choice, ValidationError, check,
                         check_array, check_fields, unit_rows)

FLOAT32_TINY = float(np.finfo(np.float32).tiny)
COLUMNS = ("shape", "size", "mass", "position", "orientation", "velocity", "angular_velocity", "restitution",
           "friction", "static")
_WIDTH = {"size": 3, "position": 3, "orientation": 4, "velocity": 3, "angular_velocity": 3}


@dataclass
class Material:
    """Contact material. ``friction`` is Coulomb mu; under ``friction_model = "slipperiness"``
    the thesis's gamma in [0, 1] is used instead: the friction impulse is clamped to (1 - gamma)
    times the normal impulse (SEED.md 3), which is Coulomb friction with mu = 1 - gamma."""

    restitution: float = 0.0
    friction: float = 0.5
    friction_model: str = "coulomb"
    slipperiness: float = 0.5
    rolling_resistance: float = 0.0

    def __post_init__(self):
        check_fields(self, MATERIAL_SCHEMA, "Material")

    def effective_friction(self) -> float:
        if FRICTION_MODELS[self.friction_model] == FRICTION_SLIPPERINESS:
            return 1.0 - self.slipperiness
        return self.friction


def quat_to_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions -> (n, 3, 3), the same arithmetic as quat_to_matrix."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


def box_checkpoints(half_extents, per_edge: int) -> np.ndarray:
    """Points on the box surface: an even per_edge^3 lattice, keeping those on a face.

    per_edge = 2 gives the 8 corners (exact against a plane, where the deepest point of a box
    is always a corner); 3 adds edge midpoints and face centres (26 points), and so on.  The
    spacing must stay below the terrain's feature size for the thesis's method to be accurate.
    """
    return unit_box_checkpoints(per_edge) * np.asarray(half_extents, dtype=np.float64)


def unit_box_checkpoints(per_edge: int) -> np.ndarray:
    t = np.linspace(-1.0, 1.0, per_edge)
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    return g[np.any(np.abs(g) == 1.0, axis=1)]


def inertia_box(mass: float, half_extents) -> np.ndarray:
    w, hgt, l = 2.0 * np.asarray(half_extents, dtype=np.float64)
    return mass / 12.0 * np.array([hgt * hgt + l * l, w * w + l * l, w * w + hgt * hgt])


def body_inertia(shape: np.ndarray, size: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """(n, 3) principal inertia: sphere 2/5 m r^2, box m/12 (h^2 + l^2, ...) (full extents)."""
    full = 2.0 * size
    sq = full * full
    box = (mass / 12.0)[:, None] * np.stack([sq[:, 1] + sq[:, 2], sq[:, 0] + sq[:, 2], sq[:, 0] + sq[:, 1]], axis=1)
    r = size[:, 0]
    sphere = np.repeat((0.4 * mass * r * r)[:, None], 3, axis=1)
    return np.where((shape == SHAPE_SPHERE)[:, None], sphere, box)


def check_derived(shape, size, mass, where: str = "", index_base: int | None = None):
    """Refuse bodies whose mass, inertia or inverses are not finite, non-zero float32 numbers.

    x and 1/x are both normal float32 numbers exactly when tiny <= x <= 1/tiny (1/tiny < max).
    """
    with np.errstate(over="ignore", divide="ignore", invalid="ignore", under="ignore"):
        inertia = body_inertia(shape, size, mass)
        low, high = FLOAT32_TINY, 1.0 / FLOAT32_TINY
        if len(mass) == 0 or (min(inertia.min(), mass.min()) >= low and max(inertia.max(), mass.max()) <= high):
            return  # NaN compares false, so it falls through to the per-body test
        values = np.concatenate([mass[:, None], inertia], axis=1)
        good = np.all((values >= low) & (values <= high), axis=1)
    i = int(np.argmin(good))
    what = f"radius {size[i, 0]:g}" if shape[i] == SHAPE_SPHERE else f"half_extents {list(map(float, size[i]))}"
    label = f"body {i} " if index_base is not None else ""
    prefix = f"{where} " if where else ""
    raise ValidationError(
        f"{prefix}{label}{what} with mass {mass[i]:g} gives inertia {list(map(float, inertia[i]))} and mass "
        f"{mass[i]:g}, not all finite non-zero float32 numbers (their inverses must be too); use a size and mass "
        f"nearer 1 (SI units)")


class _BodyView:
    """``builder.bodies``: one dict per body, made on demand from the columns."""

    def __init__(self, builder: "ModelBuilder"):
        self._builder = builder

    def __len__(self):
        return self._builder.body_count

    def _row(self, i: int) -> dict:
        c = self._builder.columns()
        return {key: (c[key][i].copy() if key in _WIDTH else c[key][i].item()) for key in COLUMNS}

    def __getitem__(self, index):
        n = len(self)
        if isinstance(index, slice):
            return [self._row(i) for i in range(*index.indices(n))]
        if index < 0:
            index += n
        if not 0 <= index < n:
            raise IndexError("body index out of range")
        return self._row(index)

    def __iter__(self):
        return (self._row(i) for i in range(len(self)))


class ModelBuilder:
    """Adds spheres and boxes, sets the terrain, then ``finalize`` uploads a Model."""

    def __init__(self, material: Material | None = None):
        if material is not None and not isinstance(material, Material):
            raise ValidationError(f"material must be a Material, got {material!r}")
        self.material = material or Material()
        self.terrain: Terrain = NoTerrain()
        self._blocks: list[dict] = []  # column blocks, one per add_bodies (or per run of single adds)
        self._rows: list[tuple] = []  # single adds not yet in a block
        self._count = 0

    def set_terrain(self, terrain: Terrain):
        if not isinstance(terrain, (FourierTerrain, PlaneTerrain, NoTerrain)):
            raise ValidationError(f"terrain must be a FourierTerrain, PlaneTerrain or NoTerrain, got {terrain!r}")
        self.terrain = terrain

    @property
    def body_count(self) -> int:
        return self._count

    @property
    def bodies(self) -> _BodyView:
        return _BodyView(self)

    @bodies.setter
    def bodies(self, items):
        """Replace every body by a list of dicts with the keys of ``COLUMNS`` (as ``bodies`` gives)."""
        items = list(items)
        self._blocks, self._rows, self._count = [], [], 0
        if items:
            block = {key: np.asarray([b[key] for b in items]) for key in COLUMNS}
            self._push_block(block)

    def _push_block(self, block: dict):
        self._flush_rows()
        self._blocks.append({
            "shape": np.asarray(block["shape"], np.int32),
            **{key: np.asarray(block[key], np.float64).reshape(-1, w) for key, w in _WIDTH.items()},
            "mass": np.asarray(block["mass"], np.float64),
            "restitution": np.asarray(block["restitution"], np.float64),
            "friction": np.asarray(block["friction"], np.float64),
            "static": np.asarray(block["static"], bool),
        })
        self._count += len(self._blocks[-1]["shape"])

    def _flush_rows(self):
        if not self._rows:
            return
        rows, self._rows = self._rows, []
        cols = list(zip(*rows))
        self._blocks.append({key: np.asarray(col, dtype=(np.int32 if key == "shape" else bool if key == "static"
                                                         else np.float64))
                             for key, col in zip(COLUMNS, cols)})

    def columns(self) -> dict:
        """All bodies as arrays: shape (n) int32, size / position / velocity / angular_velocity (n, 3),
        orientation (n, 4; as given), mass / restitution / friction (n) float64, static (n) bool."""
        self._flush_rows()
        if len(self._blocks) != 1:
            if not self._blocks:
                return {key: np.zeros((0, _WIDTH[key]) if key in _WIDTH else 0,
                                      np.int32 if key == "shape" else bool if key == "static" else np.float64)
                        for key in COLUMNS}
            self._blocks = [{key: np.concatenate([b[key] for b in self._blocks]) for key in COLUMNS}]
        return self._blocks[0]

    def _add(self, shape, size, mass, position, orientation, velocity, angular_velocity,
             restitution, friction, static):
        spec = BODY_SCHEMA
        mass = check(spec["mass"], mass, "mass")
        position = check(spec["position"], position, "position")
        orientation = check(spec["orientation"], orientation, "orientation")
        velocity = check(spec["velocity"], velocity, "velocity")
        angular_velocity = check(spec["angular_velocity"], angular_velocity, "angular_velocity")
        restitution = self.material.restitution if restitution is None else check(
            spec["restitution"], restitution, "restitution")
        friction = self.material.effective_friction() if friction is None else check(
            spec["friction"], friction, "friction")
        static = check(Boolean(), static, "static")
        size = np.asarray(size, dtype=np.float64)
        check_derived(np.array([shape]), size[None], np.array([mass]))
        self._rows.append((shape, size, mass, position, orientation, velocity, angular_velocity,
                           float(restitution), float(friction), static))
        self._count += 1
        return self._count - 1

    def add_sphere(self, radius, mass=1.0, position=(0, 0, 0), orientation=(0, 0, 0, 1),
                   velocity=(0, 0, 0), angular_velocity=(0, 0, 0), restitution=None, friction=None,
                   static=False) -> int:
        radius = check(BODY_SCHEMA["radius"], radius, "radius")
        return self._add(SHAPE_SPHERE, (radius, 0.0, 0.0), mass, position, orientation, velocity,
                         angular_velocity, restitution, friction, static)

    def add_box(self, half_extents, mass=1.0, position=(0, 0, 0), orientation=(0, 0, 0, 1),
                velocity=(0, 0, 0), angular_velocity=(0, 0, 0), restitution=None, friction=None,
                static=False) -> int:
        half_extents = check(BODY_SCHEMA["half_extents"], half_extents, "half_extents")
        return self._add(SHAPE_BOX, half_extents, mass, position, orientation, velocity,
                         angular_velocity, restitution, friction, static)

    def add_bodies(self, shape, size, mass=1.0, position=(0.0, 0.0, 0.0), orientation=None, velocity=None,
                   angular_velocity=None, restitution=None, friction=None, static=False) -> np.ndarray:
        """Add n bodies at once; returns their indices.

        shape: "sphere", "box", or an (n) array of those names or of 0 (sphere) / 1 (box).
        size: a scalar, an (n) or (n, 1) array (a sphere's radius, a cube's half extent), or
        (3) or (n, 3) rows of half extents (a sphere's row is (r, 0, 0) or (r, r, r); other
        rows are an error).  A 3-array is always one row; give the radii of exactly 3 bodies as
        (3, 1).
        mass, restitution, friction, static: a scalar or an (n) array.  position, velocity,
        angular_velocity: (3) or (n, 3); orientation: (4) or (n, 4) quaternions (x y z w), not
        all 0.  Every entry is checked with the rules of add_sphere / add_box; the first bad one
        is named by index, e.g. ``mass[17] must be a positive finite number, got 0.0``.
        """
        n = self._bulk_count(shape, size, mass, position, orientation, velocity)
        codes = {"sphere": SHAPE_SPHERE, "box": SHAPE_BOX}
        if isinstance(shape, str):
            if shape not in codes:
                raise ValidationError(f"shape must be one of sphere, box, got {shape!r}")
            shapes = np.full(n, codes[shape], np.int32)
        else:
            raw = np.asarray(shape)
            if raw.dtype == bool:
                raise ValidationError("shape must be names (sphere, box) or codes 0 and 1, got booleans")
            if raw.dtype.kind in "US":
                bad = ~np.isin(raw, list(codes))
                if bad.any():
                    i = int(np.argmax(bad))
                    raise ValidationError(f"shape[{i}] must be one of sphere, box, got {str(raw[i])!r}")
                shapes = np.where(raw == "sphere", SHAPE_SPHERE, SHAPE_BOX).astype(np.int32)
            else:
                bad = ~np.isin(raw, [SHAPE_SPHERE, SHAPE_BOX])
                if bad.any():
                    i = int(np.argmax(bad))
                    raise ValidationError(f"shape[{i}] must be 0 (sphere) or 1 (box), got {raw[i]!r}")
                shapes = raw.astype(np.int32)
            if shapes.ndim > 1 or (shapes.ndim == 1 and len(shapes) != n):
                raise ValidationError(f"shape must be one shape or {n} (one a body), got shape {shapes.shape}")
            shapes = np.broadcast_to(shapes, (n,)).copy()
        is_sphere = shapes == SHAPE_SPHERE

        raw_size = self._numbers(size, "size")
        if raw_size.ndim == 2 and raw_size.shape[1] == 1:
            raw_size = raw_size[:, 0]
        if raw_size.ndim == 0 or (raw_size.ndim == 1 and len(raw_size) != 3):
            sizes = np.repeat(self._column(raw_size, n, "size")[:, None], 3, axis=1)  # boxes: cubes
        else:
            sizes = self._rows_of(raw_size, n, 3, "size").copy()
            # a sphere's row is (r, 0, 0) or (r, r, r); anything else in it was meant as something
            # else (three radii read as one row of half extents), not silently dropped
            odd = is_sphere & ~np.all((sizes[:, 1:] == 0.0) | (sizes[:, 1:] == sizes[:, :1]), axis=1)
            if odd.any():
                i = int(np.argmax(odd))
                raise ValidationError(
                    f"size[{i}] of a sphere must be its radius, (r, 0, 0) or (r, r, r), got "
                    f"{[float(x) for x in sizes[i]]}; a 3-array is one row of half extents: give the radii of "
                    f"3 bodies as a (3, 1) array")
        sizes[is_sphere, 1:] = 0.0
        spec = BODY_SCHEMA
        check_array(spec["radius"], sizes[is_sphere, 0], "size (radius)")
        check_array(spec["half_extents"], sizes[~is_sphere], "size (half_extents)", rows=True)
        masses = check_array(spec["mass"], self._column(mass, n, "mass"), "mass")
        positions = check_array(spec["position"], self._rows_of(position, n, 3, "position"), "position", rows=True)
        orientations = check_array(spec["orientation"], self._rows_of((0, 0, 0, 1) if orientation is None
                                                                      else orientation, n, 4, "orientation"),
                                   "orientation", rows=True)
        velocities = check_array(spec["velocity"], self._rows_of((0, 0, 0) if velocity is None else velocity,
                                                                 n, 3, "velocity"), "velocity", rows=True)
        omegas = check_array(spec["angular_velocity"],
                             self._rows_of((0, 0, 0) if angular_velocity is None else angular_velocity, n, 3,
                                           "angular_velocity"), "angular_velocity", rows=True)
        rest = self._column(self.material.restitution if restitution is None else restitution, n, "restitution")
        check_array(spec["restitution"], rest, "restitution")
        fric = self._column(self.material.effective_friction() if friction is None else friction, n, "friction")
        check_array(spec["friction"], fric, "friction")
        statics = np.asarray(static)
        if statics.dtype != bool:
            raise ValidationError(f"static must be true or false (a bool or a bool array), got {statics.dtype}")
        if statics.ndim > 1 or (statics.ndim == 1 and len(statics) != n):
            raise ValidationError(f"static must be one bool or {n} (one a body), got shape {statics.shape}")
        check_derived(shapes, sizes, masses, index_base=0)
        first = self._count
        self._push_block({"shape": shapes, "size": sizes, "mass": masses, "position": positions,
                          "orientation": orientations, "velocity": velocities, "angular_velocity": omegas,
                          "restitution": rest.copy(), "friction": fric.copy(),
                          "static": np.broadcast_to(statics, (n,)).copy()})
        return np.arange(first, first + n)

    @staticmethod
    def _bulk_count(shape, size, mass, position, orientation=None, velocity=None) -> int:
        for value, width in ((shape, 0), (mass, 0), (position, 3), (size, 3)):
            a = np.asarray(value)
            if (width == 0 and a.ndim == 1) or a.ndim == 2:
                return len(a)
        a = np.asarray(size)
        if a.ndim == 1 and len(a) != 3:
            return len(a)
        for value in (orientation, velocity):
            if value is not None and np.ndim(value) == 2:
                return len(value)
        raise ValidationError("add_bodies needs at least one per-body array (shape, mass, position or size) "
                              "to give the body count")

    @staticmethod
    def _numbers(value, key: str) -> np.ndarray:
        """``value`` as float64, or ValidationError naming ``key`` (strings and ints past float
        range gave numpy's and Python's own errors, naming nothing)."""
        try:
            raw = np.asarray(value)
            a = raw.astype(np.float64)
        except (TypeError, ValueError, OverflowError) as e:
            raise ValidationError(f"{key} must be numbers, got {str(value)[:80]} ({e})") from None
        if raw.dtype == bool:  # add_sphere refuses True for a mass too
            raise ValidationError(f"{key} must be numbers, got booleans")
        return a

    @classmethod
    def _column(cls, value, n: int, key: str) -> np.ndarray:
        """A scalar or an (n) array of numbers, as (n) float64; ValidationError naming ``key``."""
        a = cls._numbers(value, key)
        if a.ndim > 1 or (a.ndim == 1 and len(a) != n):
            raise ValidationError(f"{key} must be a number or {n} numbers (one a body), got shape {a.shape}")
        return np.broadcast_to(a, (n,))

    @classmethod
    def _rows_of(cls, value, n: int, width: int, key: str) -> np.ndarray:
        a = cls._numbers(value, key)
        if a.shape == (width,):
            return np.broadcast_to(a, (n, width))
        if a.shape != (n, width):
            raise ValidationError(f"{key} must have shape ({width},) or ({n}, {width}), got {a.shape}")
        return a

    def default_checkpoints_per_edge(self) -> int:
        # On a plane the corners are exact; curved terrain needs points between them.
        return 2 if isinstance(self.terrain, PlaneTerrain) else 3

    def finalize(self, device="cpu", checkpoints_per_edge: int | None = None, body_order: str = "scene") -> Model:
        """Upload the bodies as a Model.  ``body_order`` (body_order.py): ``"scene"`` keeps the
        order they were added in; ``"morton"`` and ``"shape_morton"`` store them sorted for memory
        locality, and the Model maps back (``body_scene_index``, ``to_scene_order``)."""
        from .body_order import body_order as order_of
        from .validation import SIM_SCHEMA

        if device is not None:  # None: Warp's default device
            name = check(SIM_SCHEMA["device"], str(device), "device")
            if name.startswith("cuda"):
                import warp as wp

                available = wp.get_cuda_device_count()
                if int(name.partition(":")[2] or 0) >= available:
                    raise ValidationError(f"device {name!r} is not available ({available} CUDA devices found)")
        per_edge = checkpoints_per_edge or self.default_checkpoints_per_edge()
        mode = check(Choice(BODY_ORDERS), body_order, "body_order")
        if mode == "scene":  # nothing permuted: the arrays are exactly the added order's
            return Model(self.host_arrays(per_edge), self.terrain, device)
        c = self.columns()
        order = order_of(c["shape"], c["position"], mode, static=c["static"])
        return Model(self.host_arrays(per_edge, order), self.terrain, device, body_scene_index=order, body_order=mode)

    def host_arrays(self, per_edge: int, order: np.ndarray | None = None) -> dict:
        """The Model's host arrays (float32 / int32), computed column-wise; with ``order`` (a
        permutation, body_order.py) internal body i is added body ``order[i]``."""
        from .limits import check_terrain_resolution

        c = self.columns()
        if order is not None:
            c = {key: column[order] for key, column in c.items()}
        n = len(c["shape"])
        shape, size, mass = c["shape"], c["size"], c["mass"]
        is_sphere = shape == SHAPE_SPHERE
        check_terrain_resolution(self.terrain, c, per_edge)
        inertia = body_inertia(shape, size, mass)
        bound = np.where(is_sphere, size[:, 0], np.linalg.norm(size, axis=1))
        q = unit_rows(c["orientation"], axis=1)
        rot = quats_to_matrices(q)
        dynamic = ~c["static"]
        h = {
            "body_shape": shape.astype(np.int32),
            "body_size": size.astype(np.float32),
            "body_bound_radius": bound.astype(np.float32),
            "body_covered_faces": covered_faces(shape, size, c["position"], rot, c["static"], SHAPE_BOX,
                                                self.terrain if isinstance(self.terrain, PlaneTerrain) else None),
            "body_inv_mass": np.where(dynamic, 1.0 / mass, 0.0).astype(np.float32),
            "body_inertia": inertia.astype(np.float32),
            "body_inv_inertia": np.where(dynamic[:, None], 1.0 / inertia, 0.0).astype(np.float32),
            "body_restitution": c["restitution"].astype(np.float32),
            "body_friction": c["friction"].astype(np.float32),
            "body_rolling_resistance": np.full(n, self.material.rolling_resistance, np.float32),
            "body_pos": c["position"].astype(np.float32),
            "body_quat": q.astype(np.float32),
            "body_rot": rot.astype(np.float32),
        }
        # L = R I_body R^T omega; static bodies keep no velocity
        local = np.einsum("nji,nj->ni", rot, c["angular_velocity"])
        angmom = np.einsum("nij,nj->ni", rot, inertia * local)
        h["body_angmom"] = np.where(dynamic[:, None], angmom, 0.0).astype(np.float32)
        h["body_vel"] = np.where(dynamic[:, None], c["velocity"], 0.0).astype(np.float32)

        unit = unit_box_checkpoints(per_edge)
        counts = np.where(is_sphere, sphere_terrain_slots(self.terrain, size[:, 0]), len(unit)).astype(np.int32)
        starts = np.zeros(n, np.int64)
        if n:
            starts[1:] = np.cumsum(counts[:-1], dtype=np.int64)
        total = int(counts.sum(dtype=np.int64))
        local_points = np.zeros((total, 3), np.float32)
        boxes = np.flatnonzero(~is_sphere)
        for chunk in np.array_split(boxes, max(1, len(boxes) // 65536)) if len(boxes) else []:
            rows = (starts[chunk][:, None] + np.arange(len(unit))[None]).ravel()
            local_points[rows] = (unit[None] * size[chunk][:, None, :]).reshape(-1, 3).astype(np.float32)
        h["body_checkpoint_start"] = starts.astype(np.int32)
        h["body_checkpoint_count"] = counts
        h["checkpoint_body"] = np.repeat(np.arange(n, dtype=np.int32), counts)
        h["checkpoint_local"] = local_points
        h["checkpoints_per_edge"] = per_edge
        return h


def random_quaternions(rng: np.random.Generator, count: int) -> np.ndarray:
    """Uniform random rotations (Shoemake), (x, y, z, w)."""
    u1, u2, u3 = rng.random((3, count))
    a, b = np.sqrt(1 - u1), np.sqrt(u1)
    return np.stack(
        [a * np.sin(2 * math.pi * u2), a * np.cos(2 * math.pi * u2), b * np.sin(2 * math.pi * u3),
         b * np.cos(2 * math.pi * u3)], axis=1)
