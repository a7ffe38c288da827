"""Closed-form physics cases shared by the tests and the accuracy benchmarks.

Each builder returns a ready Simulator; the matching exact answer is a small function next to
it, so a test and a work-precision chart measure exactly the same thing.
"""

from __future__ import annotations

import math

import numpy as np

from .builder import Material, ModelBuilder
from .simulator import SimConfig, Simulator
from .terrain import FourierTerrain, NoTerrain, PlaneTerrain

GRAVITY = 9.81


def _sim(builder: ModelBuilder, device="cpu", body_order="scene", checkpoints_per_edge=None, **config) -> Simulator:
    # sleeping off: these cases measure the solver itself, not how soon it may stop
    config.setdefault("sleep", False)
    cfg = SimConfig(device=device, **config)
    return Simulator(builder.finalize(device, checkpoints_per_edge, body_order=body_order), cfg)


# Free flight ----------------------------------------------------------------------------------

def projectile(integrator: str, dt: float, velocity=(3.0, 4.0, 0.0), height=10.0, device="cpu") -> Simulator:
    """A sphere thrown from (0, height, 0) with no terrain: x(t) = x0 + v0 t + g t^2 / 2."""
    b = ModelBuilder()
    b.set_terrain(NoTerrain())
    b.add_sphere(0.1, 1.0, position=(0.0, height, 0.0), velocity=velocity)
    return _sim(b, device, dt=dt, substeps=1, integrator=integrator, gravity=(0.0, -GRAVITY, 0.0))


def projectile_exact(t: float, velocity=(3.0, 4.0, 0.0), height=10.0) -> np.ndarray:
    v = np.asarray(velocity, dtype=np.float64)
    return np.array([0.0, height, 0.0]) + v * t + 0.5 * np.array([0.0, -GRAVITY, 0.0]) * t * t


TUMBLING_HALF_EXTENTS = (0.1, 0.4, 0.2)  # principal moments I_y < I_z < I_x: z is the intermediate axis


def tumbling_box(integrator: str, rotation: str, dt: float, omega=(0.3, 0.4, 5.0), device="cpu") -> Simulator:
    """A free box spinning in zero gravity (default: near the intermediate axis, so it flips)."""
    b = ModelBuilder()
    b.set_terrain(NoTerrain())
    b.add_box(TUMBLING_HALF_EXTENTS, 1.0, angular_velocity=omega)
    return _sim(b, device, dt=dt, substeps=1, integrator=integrator, rotation=rotation, gravity=(0.0, 0.0, 0.0))


def tumbling_reference(omega0, t_end: float, samples: int, half_extents=TUMBLING_HALF_EXTENTS, mass=1.0):
    """Float64 reference orientation R(t) of a torque-free box (RK4 on quaternions, tiny step).

    Returns (times, rotations) at ``samples`` evenly spaced times in [0, t_end].
    """
    from .builder import inertia_box

    inertia = inertia_box(mass, half_extents)
    angmom = inertia * np.asarray(omega0, dtype=np.float64)  # R(0) = I, so L = I_body omega

    def deriv(q):
        qn = q / np.linalg.norm(q)
        rot = quat_matrix(qn)
        w = rot @ ((rot.T @ angmom) / inertia)
        x, y, z, s = qn
        wx, wy, wz = w
        # 1/2 [w, 0] (x) q, Hamilton product with (x, y, z, w) storage
        return 0.5 * np.array([
            wx * s + wy * z - wz * y,
            wy * s + wz * x - wx * z,
            wz * s + wx * y - wy * x,
            -(wx * x + wy * y + wz * z),
        ])

    times = np.linspace(0.0, t_end, samples)
    out = [np.eye(3)]
    q = np.array([0.0, 0.0, 0.0, 1.0])
    sub = 2000
    for i in range(1, samples):
        h = (times[i] - times[i - 1]) / sub
        for _ in range(sub):
            k1 = deriv(q)
            k2 = deriv(q + 0.5 * h * k1)
            k3 = deriv(q + 0.5 * h * k2)
            k4 = deriv(q + h * k3)
            q = q + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
            q /= np.linalg.norm(q)
        out.append(quat_matrix(q))
    return times, np.array(out)


def quat_matrix(q) -> np.ndarray:
    from .builder import quat_to_matrix

    return quat_to_matrix(q)


# Contact --------------------------------------------------------------------------------------

def bounce(restitution: float, drop_height=1.0, radius=0.1, dt=1.0 / 60.0, substeps=8,
           integrator="semi_implicit", device="cpu") -> Simulator:
    """A sphere whose lowest point starts ``drop_height`` above the plane y = 0."""
    b = ModelBuilder(Material(restitution=restitution, friction=0.0))
    b.set_terrain(PlaneTerrain())
    b.add_sphere(radius, 1.0, position=(0.0, drop_height + radius, 0.0))
    return _sim(b, device, dt=dt, substeps=substeps, integrator=integrator)


def slope_plane(angle_deg: float) -> PlaneTerrain:
    """Plane through the origin rising along +x; down-slope is -x."""
    return PlaneTerrain.from_slope(angle_deg)


def slope_frame(angle_deg: float):
    """(down-slope unit vector, plane normal) for ``slope_plane``."""
    a = math.radians(angle_deg)
    down = np.array([-math.cos(a), -math.sin(a), 0.0])
    normal = np.array([-math.sin(a), math.cos(a), 0.0])
    return down, normal


def rolling_sphere(angle_deg=20.0, friction=0.5, radius=0.25, dt=1.0 / 60.0, substeps=4,
                   integrator="semi_implicit", device="cpu") -> Simulator:
    """A sphere released at rest touching a slope: a = 5/7 g sin(theta) if mu >= 2/7 tan(theta)."""
    b = ModelBuilder(Material(restitution=0.0, friction=friction))
    b.set_terrain(slope_plane(angle_deg))
    _, normal = slope_frame(angle_deg)
    b.add_sphere(radius, 1.0, position=tuple(normal * radius))
    return _sim(b, device, dt=dt, substeps=substeps, integrator=integrator)


def rolling_acceleration(angle_deg: float) -> float:
    return 5.0 / 7.0 * GRAVITY * math.sin(math.radians(angle_deg))


def sliding_box(angle_deg=30.0, friction=0.3, half=0.25, dt=1.0 / 60.0, substeps=4,
                integrator="semi_implicit", device="cpu") -> Simulator:
    """A cube released at rest flat on a slope: a = g (sin - mu cos) when tan(theta) > mu, else 0."""
    b = ModelBuilder(Material(restitution=0.0, friction=friction))
    b.set_terrain(slope_plane(angle_deg))
    a = math.radians(angle_deg)
    _, normal = slope_frame(angle_deg)
    # rotate the cube about z by the slope angle so its bottom face lies on the plane
    q = (0.0, 0.0, math.sin(a / 2.0), math.cos(a / 2.0))
    b.add_box((half, half, half), 1.0, position=tuple(normal * half), orientation=q)
    return _sim(b, device, dt=dt, substeps=substeps, integrator=integrator)


def sliding_acceleration(angle_deg: float, friction: float) -> float:
    a = math.radians(angle_deg)
    return max(GRAVITY * (math.sin(a) - friction * math.cos(a)), 0.0)


def spinning_box(half, mass=1.0, friction=0.5, spin=10.0, floor="plane", velocity=(0.0, 0.0, 0.0), device="cpu",
                 **config) -> Simulator:
    """A box (half extents ``half``) set down on its x-z face, spinning about the vertical at
    ``spin`` (and sliding at ``velocity``), on the plane, a wide static box or a free slab lying on
    the plane (collide/contact_patch.py): the spin falls at mu g r_e(a, b) 3 / (a^2 + b^2) while it
    slides in place (spin_down_rate)."""
    b = ModelBuilder(Material(friction=friction))
    base = 0.0
    if floor == "plane":
        b.set_terrain(PlaneTerrain())
    elif floor == "static box":
        b.set_terrain(NoTerrain())
        b.add_box((3.0, 0.2, 3.0), 1.0, position=(0.0, -0.2, 0.0), static=True)
    elif floor == "box on the plane":
        # a free 20 kg slab on the plane: its ground friction holds the top box's torque many times
        b.set_terrain(PlaneTerrain())
        b.add_box((0.8, 0.2, 0.8), 20.0, position=(0.0, 0.2, 0.0))
        base = 0.4
    else:
        raise ValueError(f"floor must be 'plane', 'static box' or 'box on the plane', got {floor!r}")
    b.add_box(half, mass, position=(0.0, base + half[1], 0.0), velocity=velocity, angular_velocity=(0.0, spin, 0.0))
    return _sim(b, device, **config)


def spin_down_rate(half, friction: float) -> float:
    """mu g r_e 3 / (a^2 + b^2) [rad/s^2] for spinning_box, r_e the mean distance over the a x b
    face from its centre in closed form (float64; contact_patch.py derives it)."""
    a, b = half[0], half[2]
    d = math.hypot(a, b)
    r_e = (2 * a * b * d + a**3 * math.log((b + d) / a) + b**3 * math.log((a + d) / b)) / (6 * a * b)
    return friction * GRAVITY * r_e * 3.0 / (a * a + b * b)


DEFAULT_TERRAIN = FourierTerrain()


def squeezed_column(below: float, above: float, light: float = 1.0, half: float = 0.5, offset: float = 0.0,
                    friction: float = 0.0, device="cpu", **config) -> Simulator:
    """A light cube (``light`` kg, half extent ``half``) set down at rest between two unit-half cubes of
    ``below`` and ``above`` kg on the plane, ``offset`` off their axis along x, restitution 0: the
    column the substep plan raises substeps for, and without friction the squeeze
    (collide/box_box.py: near-parallel faces).  Bodies (below, light, above); sleeping off."""
    b = ModelBuilder(Material(restitution=0.0, friction=friction))
    b.set_terrain(PlaneTerrain())
    b.add_box((0.5, 0.5, 0.5), below, position=(0.0, 0.5, 0.0))
    b.add_box((half, half, half), light, position=(offset, 1.0 + half, 0.0))
    b.add_box((0.5, 0.5, 0.5), above, position=(0.0, 1.5 + 2.0 * half, 0.0))
    return _sim(b, device, **config)


def terrain_drop(count: int, shape="sphere", terrain: FourierTerrain | None = None, spacing=1.2, clearance=0.5,
                 radius=0.25, half_extents=(0.25, 0.25, 0.25), rolling_resistance=0.1, friction=0.6,
                 restitution=0.0, dt=1.0 / 60.0, substeps=4, seed=0, body_contact=False,
                 device="cpu", body_order="scene", checkpoints_per_edge=None, **config) -> Simulator:
    """``count`` bodies on a square grid above the Fourier terrain; ``shape`` sphere, box or mix.

    This is the benchmark scene too: the same bodies, the same terrain, the same drop heights.
    ``body_contact`` adds body-body collision (off: terrain contact only, the fused fast path);
    ``body_order`` is how the Model stores them (body_order.py); ``checkpoints_per_edge`` the
    boxes' terrain points (None: the builder's default); other keyword arguments are SimConfig
    fields (broad_phase, solver, sleep, ...).
    """
    b = terrain_drop_builder(count, shape, terrain, spacing, clearance, radius, half_extents, rolling_resistance,
                             friction, restitution, seed)
    return _sim(b, device, body_order, checkpoints_per_edge, dt=dt, substeps=substeps, seed=seed,
                body_contact=body_contact, **config)


def terrain_drop_builder(count: int, shape="sphere", terrain: FourierTerrain | None = None, spacing=1.2,
                         clearance=0.5, radius=0.25, half_extents=(0.25, 0.25, 0.25), rolling_resistance=0.1,
                         friction=0.6, restitution=0.0, seed=0) -> ModelBuilder:
    """The ModelBuilder of ``terrain_drop`` (its bodies row by row, spheres and boxes alternating)."""
    from .builder import random_quaternions

    terrain = terrain or DEFAULT_TERRAIN
    rng = np.random.default_rng(seed)
    side = int(math.ceil(math.sqrt(count)))
    idx = np.arange(count)
    gx = (idx % side - (side - 1) / 2.0) * spacing
    gz = (idx // side - (side - 1) / 2.0) * spacing
    ground = terrain.height(gx, gz)
    reach = max(radius, float(np.linalg.norm(half_extents)))
    gy = ground + clearance + reach
    quats = random_quaternions(rng, count)
    b = ModelBuilder(Material(restitution=restitution, friction=friction, rolling_resistance=rolling_resistance))
    b.set_terrain(terrain)
    for i in range(count):
        is_sphere = shape == "sphere" or (shape == "mix" and i % 2 == 0)
        pos = (float(gx[i]), float(gy[i]), float(gz[i]))
        if is_sphere:
            b.add_sphere(radius, 1.0, position=pos)
        else:
            b.add_box(half_extents, 1.0, position=pos, orientation=tuple(quats[i]))
    return b


def pileup_builder(seed: int, count: int = 12) -> ModelBuilder:
    """Spheres and boxes of random size (0.1 to 0.4), mass (0.5 to 5 kg), orientation and spin (up
    to 3 rad/s an axis) on a lattice, all flying at the centre at 2 to 4 m/s, each with its own e
    and mu in [0, 1]; no terrain (run it without gravity).  The physics audit's random impacts and
    the tests' pile-ups."""
    from .builder import random_quaternions

    rng = np.random.default_rng(seed)
    b = ModelBuilder()
    b.set_terrain(NoTerrain())
    side = math.ceil(count ** (1 / 3))
    quats = random_quaternions(rng, count)
    for k in range(count):
        cell = np.array([k % side, (k // side) % side, k // (side * side)], dtype=float)
        pos = (cell - (side - 1) / 2.0) * 1.6 + rng.uniform(-0.1, 0.1, 3)
        vel = -pos / max(np.linalg.norm(pos), 1e-6) * rng.uniform(2.0, 4.0) + rng.uniform(-0.5, 0.5, 3)
        args = dict(mass=float(rng.uniform(0.5, 5.0)), position=tuple(pos), velocity=tuple(vel),
                    angular_velocity=tuple(rng.uniform(-3, 3, 3)), restitution=float(rng.uniform(0, 1)),
                    friction=float(rng.uniform(0, 1)))
        if rng.random() < 0.5:
            b.add_sphere(float(rng.uniform(0.15, 0.4)), **args)
        else:
            b.add_box(tuple(rng.uniform(0.1, 0.4, 3)), orientation=tuple(quats[k]), **args)
    return b


def seam_drop(restitution: float, left_first: bool = True, mass_below: float = 1.0, device="cpu", **config):
    """Zero gravity: a ball (r 0.25, 1 kg, 3 m/s down) meets two touching balls (``mass_below``
    each) at once, their centres 30 degrees off its line of fall on either side, friction 0: the
    symmetric simultaneous impact (solvers/impact_joint.py).  ``left_first``: which lower ball is
    added first (the sequential impacts' pair order).  The bodies are (left, right, striker) or
    (right, left, striker)."""
    r = 0.25
    b = ModelBuilder(Material(restitution=restitution, friction=0.0))
    b.set_terrain(NoTerrain())
    for x in ((-r, r) if left_first else (r, -r)):
        b.add_sphere(r, mass_below, position=(x, 0.0, 0.0))
    b.add_sphere(r, 1.0, position=(0.0, math.sqrt(3.0) * r + 0.05, 0.0), velocity=(0.0, -3.0, 0.0))
    return _sim(b, device, sleep=False, gravity=(0.0, 0.0, 0.0), **config)
