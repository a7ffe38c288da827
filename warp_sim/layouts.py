"""Layout generators: the ``[[layout]]`` tables of a scene file.

Each generator takes the validated table (a dict: the keys of its schema below, defaults
filled in, keys without a default present only when given), the ModelBuilder, the terrain and a
numpy Generator, and adds its bodies with one ``builder.add_bodies`` call (so a million-body grid
builds in seconds).  The body count is checked against the machine's memory before anything is
allocated (limits.py): ``count = 1000000000000`` is one line, not a 21.8 TiB allocation error.  Problems
that involve several keys raise SceneError with a message that starts with the key.  Lengths
are in m, masses in kg, velocities in m/s; y is up.

"Ground" below means the highest terrain point under a footprint (sampled densely; a plane's
height is exact), or y = 0 when the scene has no terrain.  A ``position``/``start`` given as
[x, z] rests the bodies on the ground; [x, y, z] places them exactly.

grid -- bodies on a regular lattice, dropped from above the ground.
    count               int N (one layer, about sqrt(N) x sqrt(N)) or [nx, ny, nz] (ny layers).
                        Required.
    spacing             centre-to-centre distance of neighbours (default 3 x the largest
                        bounding radius); at least 2 x the largest bounding radius.
    center              [x, z] of the grid's centre (default [0, 0]).
    clearance           gap between the lowest body's lowest point and the ground under the
                        whole grid footprint (>= 0, default 0.5).
    shape               "sphere" (default), "box" or "mix".
    sphere_fraction     share of spheres for "mix", in [0, 1] (default 0.5); the shapes are
                        shuffled with the scene seed.
    radius              sphere radius (default 0.25); not for shape "box".
    half_extents        box half extents (default [0.25, 0.25, 0.25]); not for shape "sphere".
    mass                mass of each body (default 1).
    random_orientation  uniformly random orientations (default false).
    velocity            initial velocity of every body (default [0, 0, 0]).
    jitter              random horizontal offset in [0, 1] (default 0), as a fraction of the free
                        gap between neighbours, so bodies never overlap.

stack -- a column of ``count`` boxes.
    count               number of boxes (int >= 1). Required.
    half_extents        box half extents (default [0.25, 0.25, 0.25]).
    position            centre of the stack's base, i.e. the bottom face of the lowest box
                        (default [0, 0]: on the ground at the origin).
    gap                 vertical gap between boxes (>= 0, default 0).
    mass                mass of each box (default 1).

pyramid -- a 2-D pyramid in the x-y plane: rows of base, base - 1, ..., 1 boxes.
    base                boxes in the bottom row (int >= 1). Required.
    half_extents        box half extents (default [0.25, 0.25, 0.25]).
    position            centre of the bottom face of the bottom row (default [0, 0]).
    gap                 gap between neighbouring boxes, in a row and between rows (default 0).
    mass                mass of each box (default 1).

chain -- a row of bodies along a direction, e.g. a Newton's cradle.
    count               number of bodies (int >= 1). Required.
    shape               "sphere" (default) or "box".
    radius              sphere radius (default 0.25); not for shape "box".
    half_extents        box half extents (default [0.25, 0.25, 0.25]); not for shape "sphere".
    spacing             centre-to-centre distance (default: touching, twice the body's extent
                        along ``direction``); no less than that.
    start               centre of the first body (default [0, 0]: resting on the ground; with
                        [x, z] the whole row is lifted until no body is below the ground).
    direction           direction of the row, normalised (default [1, 0, 0]).
    velocity            initial velocity of the first body (default [0, 0, 0]); the rest are at rest.
    mass                mass of each body (default 1).
"""

from __future__ import annotations

import math

import numpy as np

from .builder import ModelBuilder, quat_to_matrix, quats_to_matrices, random_quaternions
from .limits import check_body_count
from .scene import Boolean, Choice, Count, Integer, Number, Point, SceneError, Vector, show, unit_rows
from .terrain import FourierTerrain, PlaneTerrain

DEFAULT_RADIUS = 0.25
DEFAULT_HALF_EXTENTS = (0.25, 0.25, 0.25)
IDENTITY = (0.0, 0.0, 0.0, 1.0)

# Ground sampling: at most this spacing [m] and this many samples per axis.  The sampled maximum
# is off by a second-order term only (the gradient vanishes at an interior maximum).
GROUND_STEP = 0.05
GROUND_SAMPLES_MAX = 257


def ground_height(terrain, x0: float, x1: float, z0: float, z1: float) -> float:
    """Highest terrain point over the rectangle [x0, x1] x [z0, z1]; 0 without terrain."""
    if isinstance(terrain, PlaneTerrain):
        if abs(terrain.normal[1]) < 1e-6:
            raise SceneError(
                f"needs a ground height, but the terrain plane is vertical (normal {show(terrain.normal)})"
            )
        # A plane's maximum over a rectangle is at a corner.
        return float(np.max(terrain.height(np.array([x0, x0, x1, x1]), np.array([z0, z1, z0, z1]))))
    if isinstance(terrain, FourierTerrain):
        nx = min(GROUND_SAMPLES_MAX, max(2, math.ceil((x1 - x0) / GROUND_STEP) + 1))
        nz = min(GROUND_SAMPLES_MAX, max(2, math.ceil((z1 - z0) / GROUND_STEP) + 1))
        x, z = np.meshgrid(np.linspace(x0, x1, nx), np.linspace(z0, z1, nz), indexing="ij")
        return float(terrain.height(x, z).max())
    return 0.0


def bound_radius(shape: str, size) -> float:
    return float(size[0]) if shape == "sphere" else float(np.linalg.norm(size))


def down_extent(shape: str, size, orientation) -> float:
    """Distance from the centre down to the body's lowest point."""
    if shape == "sphere":
        return float(size[0])
    return float(np.abs(quat_to_matrix(orientation)[1]) @ np.asarray(size, dtype=np.float64))


def _shape_size(p: dict, shape: str):
    """Builder size of ``shape`` from the table's ``radius`` / ``half_extents`` or their defaults."""
    if shape == "sphere":
        return (p.get("radius", DEFAULT_RADIUS), 0.0, 0.0)
    return p.get("half_extents", DEFAULT_HALF_EXTENTS)


def _check_shape_keys(p: dict, shape: str):
    if shape == "sphere" and "half_extents" in p:
        raise SceneError("half_extents is not valid for shape 'sphere' (use radius)")
    if shape == "box" and "radius" in p:
        raise SceneError("radius is not valid for shape 'box' (use half_extents)")


def _add(builder: ModelBuilder, shape: str, size, **kwargs) -> int:
    if shape == "sphere":
        return builder.add_sphere(size[0], **kwargs)
    return builder.add_box(size, **kwargs)


# ----------------------------------------------------------------------------------------------


def grid(p: dict, builder: ModelBuilder, terrain, rng: np.random.Generator):
    shape = p["shape"]
    _check_shape_keys(p, shape)
    if "sphere_fraction" in p and shape != "mix":
        raise SceneError(f"sphere_fraction is only valid for shape 'mix', got shape {shape!r}")

    count = p["count"]
    if isinstance(count, tuple):
        nx, ny, nz = count
        n = nx * ny * nz
    else:
        n, ny = count, 1
        nx = math.ceil(math.sqrt(n))
        nz = math.ceil(n / nx)
    check_body_count(n, f"count = {show(count)}", boxes=n if shape != "sphere" else 0)

    if shape == "mix":
        spheres = round(p.get("sphere_fraction", 0.5) * n)
        kinds = rng.permutation(np.array(["sphere"] * spheres + ["box"] * (n - spheres)))
    else:
        kinds = np.full(n, shape)
    sizes = {k: _shape_size(p, k) for k in set(kinds.tolist())}
    bound = max(bound_radius(k, sizes[k]) for k in sizes)

    spacing = p.get("spacing", 3.0 * bound)
    if spacing < 2.0 * bound:
        raise SceneError(
            f"spacing must be at least {2.0 * bound:.6g} (twice the largest bounding radius) so bodies do "
            f"not overlap, got {show(spacing)}"
        )
    orientations = random_quaternions(rng, n) if p["random_orientation"] else np.tile(IDENTITY, (n, 1))
    max_offset = 0.5 * p["jitter"] * (spacing - 2.0 * bound)
    offsets = rng.uniform(-1.0, 1.0, (n, 2)) * max_offset

    # Fill layer by layer, row by row (a partial last row with an int count).
    iy, rest = np.divmod(np.arange(n), nx * nz)
    iz, ix = np.divmod(rest, nx)
    cx, cz = p["center"]
    x = cx + (ix - 0.5 * (nx - 1)) * spacing + offsets[:, 0]
    z = cz + (iz - 0.5 * (nz - 1)) * spacing + offsets[:, 1]

    half_x = 0.5 * (nx - 1) * spacing + max_offset + bound
    half_z = 0.5 * (nz - 1) * spacing + max_offset + bound
    ground = ground_height(terrain, cx - half_x, cx + half_x, cz - half_z, cz + half_z)
    is_sphere = kinds == "sphere"
    size_rows = np.array([sizes[k] for k in ("sphere", "box") if k in sizes])
    size_of = {k: size_rows[i] for i, k in enumerate(k for k in ("sphere", "box") if k in sizes)}
    down = 0.0
    if is_sphere.any():
        down = float(size_of["sphere"][0])
    if (~is_sphere).any():
        rows = quats_to_matrices(orientations[~is_sphere])[:, 1, :]
        down = max(down, float(np.max(np.abs(rows) @ np.asarray(size_of["box"], dtype=np.float64))))
    y = ground + p["clearance"] + down + iy * spacing

    body_size = np.empty((n, 3))
    for k, row in size_of.items():
        body_size[kinds == k] = row
    builder.add_bodies(np.where(is_sphere, "sphere", "box"), body_size, mass=p["mass"],
                       position=np.stack([x, y, z], axis=1), orientation=orientations, velocity=p["velocity"])


def stack(p: dict, builder: ModelBuilder, terrain, rng: np.random.Generator):
    h = np.asarray(p["half_extents"])
    count = p["count"]
    check_body_count(count, f"count = {count}", boxes=count)
    x, y, z = p["position"]
    if y is None:
        y = ground_height(terrain, x - h[0], x + h[0], z - h[2], z + h[2])
    ys = y + h[1] + np.arange(count) * (2.0 * h[1] + p["gap"])
    builder.add_bodies("box", h, mass=p["mass"], position=np.stack([np.full(count, x), ys, np.full(count, z)], axis=1))


def pyramid(p: dict, builder: ModelBuilder, terrain, rng: np.random.Generator):
    h = np.asarray(p["half_extents"])
    base, gap = p["base"], p["gap"]
    count = base * (base + 1) // 2
    check_body_count(count, f"base = {base}", boxes=count)
    pitch_x, pitch_y = 2.0 * h[0] + gap, 2.0 * h[1] + gap
    x, y, z = p["position"]
    if y is None:
        half_width = 0.5 * base * pitch_x
        y = ground_height(terrain, x - half_width, x + half_width, z - h[2], z + h[2])
    rows = np.repeat(np.arange(base), np.arange(base, 0, -1))
    boxes = base - rows
    first = np.concatenate([[0], np.cumsum(np.arange(base, 1, -1))]) if base > 1 else np.zeros(1, np.int64)
    i = np.arange(count) - first[rows]
    px = x + (i - 0.5 * (boxes - 1)) * pitch_x
    py = y + h[1] + rows * pitch_y
    builder.add_bodies("box", h, mass=p["mass"], position=np.stack([px, py, np.full(count, z)], axis=1))


def chain(p: dict, builder: ModelBuilder, terrain, rng: np.random.Generator):
    shape = p["shape"]
    _check_shape_keys(p, shape)
    size = _shape_size(p, shape)
    d = unit_rows(p["direction"])
    reach = size[0] if shape == "sphere" else float(np.abs(d) @ np.asarray(size))
    spacing = p.get("spacing", 2.0 * reach)
    if spacing < 2.0 * reach * (1.0 - 1e-9):
        raise SceneError(
            f"spacing must be at least {2.0 * reach:.6g} (the body's size along direction) so bodies do "
            f"not overlap, got {show(spacing)}"
        )
    count = p["count"]
    check_body_count(count, f"count = {count}", boxes=count if shape == "box" else 0)
    offsets = np.arange(count)[:, None] * spacing * d
    x, y, z = p["start"]
    if y is None:
        down = down_extent(shape, size, IDENTITY)
        r = bound_radius(shape, size)
        y = max(
            ground_height(terrain, x + o[0] - r, x + o[0] + r, z + o[2] - r, z + o[2] + r) + down - o[1]
            for o in offsets
        )
    velocity = np.zeros((count, 3))
    velocity[0] = p["velocity"]
    builder.add_bodies(shape, np.asarray(size, dtype=np.float64), mass=p["mass"],
                       position=np.array([x, y, z]) + offsets, velocity=velocity)


# ----------------------------------------------------------------------------------------------
# Schemas: key -> spec (see scene.py).  Keys with no default are absent unless given.

_SIZE = {"radius": Number(gt=0), "half_extents": Vector(3, positive=True)}
_MASS = Number(default=1.0, gt=0)
_ZERO3 = (0.0, 0.0, 0.0)

LAYOUTS = {
    "grid": (grid, {
        "count": Count(required=True),
        "spacing": Number(gt=0),
        "center": Vector(2, default=(0.0, 0.0)),
        "clearance": Number(default=0.5, ge=0),
        "shape": Choice(("sphere", "box", "mix"), default="sphere"),
        "sphere_fraction": Number(ge=0, le=1),
        **_SIZE,
        "mass": _MASS,
        "random_orientation": Boolean(default=False),
        "velocity": Vector(3, default=_ZERO3),
        "jitter": Number(default=0.0, ge=0, le=1),
    }),
    "stack": (stack, {
        "count": Integer(ge=1, required=True),
        "half_extents": Vector(3, default=DEFAULT_HALF_EXTENTS, positive=True),
        "position": Point(default=(0.0, None, 0.0)),
        "gap": Number(default=0.0, ge=0),
        "mass": _MASS,
    }),
    "pyramid": (pyramid, {
        "base": Integer(ge=1, required=True),
        "half_extents": Vector(3, default=DEFAULT_HALF_EXTENTS, positive=True),
        "position": Point(default=(0.0, None, 0.0)),
        "gap": Number(default=0.0, ge=0),
        "mass": _MASS,
    }),
    "chain": (chain, {
        "count": Integer(ge=1, required=True),
        "shape": Choice(("sphere", "box"), default="sphere"),
        **_SIZE,
        "spacing": Number(gt=0),
        "start": Point(default=(0.0, None, 0.0)),
        "direction": Vector(3, default=(1.0, 0.0, 0.0), nonzero=True),
        "velocity": Vector(3, default=_ZERO3),
        "mass": _MASS,
    }),
}
