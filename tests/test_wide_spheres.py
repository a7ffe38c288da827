"""Spheres wider than the terrain's curvature radius (collide/terrain_contact.py, module docstring).

Such a ball can touch the ground at several points at once: set in a trough or a pit narrower
than itself, it rests on the walls, and the point under its centre (the bottom) is a stationary
point of the distance, not the nearest point.  The oracle is the NumPy twin of the terrain: the
height at which the nearest surface point of a fine grid lies exactly r from the centre, found by
bisection.  The tolerance, 1 mm, covers the grid (the rest height of a 5 mm grid differs by well
under a millimetre at these slopes) and the soft contact's sag, g / omega^2 = 0.07 mm at the
defaults (60 Hz).
"""

import math

import numpy as np
import pytest

from warp_sim import FourierTerrain, ModelBuilder, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.collide.terrain_contact import WIDE_SPHERE_SLOTS, sphere_terrain_slots

G = 9.81


def wave(table, amplitude=1.0, frequency=1.0) -> FourierTerrain:
    """H = sum over the table's (m, n) entries of amplitude t(m,n) / sqrt(m^2 + n^2) cos(f (m x + n z))."""
    table = np.asarray(table, dtype=float)
    return FourierTerrain(terms=len(table), frequency=frequency, amplitude=amplitude, amplitudes=table,
                          phases=np.zeros_like(table))


TROUGH_X = wave([[0, 0], [1, 0]])  # cos x: troughs along z at x = pi, curvature radius 1 m there
TROUGH_Z = wave([[0, 1], [0, 0]])  # cos z: the same turned a quarter
# cos((x + z) / sqrt 2): the same profile across the diagonal (the (1, 1) term's 1/sqrt 2 undone)
TROUGH_DIAGONAL = wave([[0, 0], [0, 1]], amplitude=math.sqrt(2.0), frequency=1.0 / math.sqrt(2.0))
PIT = wave([[0, 1], [1, 0]])  # cos x + cos z: a pit at (pi, pi), curvature radius 1 m both ways

BOTTOMS = {"x": (math.pi, 0.0), "z": (0.0, math.pi), "diagonal": (math.pi / math.sqrt(2.0),) * 2}
TROUGHS = {"x": TROUGH_X, "z": TROUGH_Z, "diagonal": TROUGH_DIAGONAL}


def rest_height(terrain, x, z, radius, span=4.0, cells=801):
    """The centre height above (x, z) at which the nearest point of the surface is ``radius`` away."""
    g = np.linspace(-span, span, cells)
    gx, gz = np.meshgrid(x + g, z + g)
    height = terrain.height(gx, gz)

    def nearest(y):
        return np.sqrt((gx - x) ** 2 + (height - y) ** 2 + (gz - z) ** 2).min()

    lo, hi = float(height.min()), float(height.max()) + radius + 1.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if nearest(mid) < radius else (lo, mid)
    return hi


def test_only_spheres_past_the_curvature_radius_get_more_slots():
    """curvature_bound bounds every second directional derivative (checked against the exact one on
    random points and directions), and the slot count follows radius * bound >= 1."""
    rng = np.random.default_rng(3)
    terrain = FourierTerrain(terms=4, frequency=0.7, amplitude=0.8, seed=2, scale=(1.5, 0.7, 2.0))
    k = terrain.terms
    a, p = terrain.amplitude_table(), terrain.phase_table()
    m, n = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    angle = rng.uniform(0.0, 2.0 * math.pi, 4000)
    u, w = rng.uniform(-30.0, 30.0, (2, 4000))
    rate = terrain.frequency * (m[None] * (np.cos(angle) / terrain.scale[0])[:, None, None]
                                + n[None] * (np.sin(angle) / terrain.scale[2])[:, None, None])
    phase = terrain.frequency * (m[None] * u[:, None, None] + n[None] * w[:, None, None]) + p[None]
    second = terrain.scale[1] * np.sum(-a[None] * rate**2 * np.cos(phase), axis=(1, 2))
    bound = terrain.curvature_bound()
    assert np.abs(second).max() <= bound
    assert np.abs(second).max() > 0.2 * bound  # and it is not vacuous
    radius = np.array([0.5, 0.99, 1.001, 2.0]) / bound
    np.testing.assert_array_equal(sphere_terrain_slots(terrain, radius), [1, 1, WIDE_SPHERE_SLOTS, WIDE_SPHERE_SLOTS])
    assert sphere_terrain_slots(FourierTerrain(), [0.25]).tolist() == [1]  # the shipped scenes' balls


@pytest.mark.parametrize("radius", [1.2, 1.5, 3.0])
@pytest.mark.parametrize("axis", list(TROUGHS))
def test_a_ball_wider_than_a_trough_rests_on_both_walls(axis, radius, device):
    """A ball of radius 1.2, 1.5 or 3 m set 1 mm above its resting height in a trough of curvature
    radius 1 m, lying along z, along x or across the diagonal: it rests on the two walls.  With one
    contact, Newton started and stopped at the bottom point and the ball settled there, 79 and 652
    mm too low (r 1.5 and 3)."""
    terrain = TROUGHS[axis]
    x, z = BOTTOMS[axis]
    height = rest_height(terrain, x, z, radius)
    b = ModelBuilder()
    b.set_terrain(terrain)
    b.add_sphere(radius, 1.0, position=(x, height + 1e-3, z))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    sim.step(120)
    assert abs(float(sim.state.body_pos.numpy()[0][1]) - height) < 1e-3


@pytest.mark.parametrize("offset", [0.3, 0.8])
@pytest.mark.parametrize("radius", [1.5, 2.5])
@pytest.mark.parametrize("ground", ["trough", "pit"])
def test_a_wide_ball_dropped_off_centre_settles_on_the_walls_without_gaining_energy(ground, radius, offset, device):
    """Dropped 5 cm above the walls, off the bottom by (offset, offset / 2), with rolling resistance
    0.05: the ball rolls down, comes to rest over the bottom at its resting height, and its energy
    E = m v^2 / 2 + L^2 / (2 I) + m g y never exceeds the start's.  Tolerance of the energy: the
    kick-drift free fall's own energy error, m g^2 h^2 at the substep h.  With one contact the
    ball went 34 to 462 mm into the walls and gained up to 2 J."""
    terrain = {"trough": TROUGH_X, "pit": PIT}[ground]
    x, z = math.pi, (math.pi if ground == "pit" else 0.0)
    sx, sz = x + offset, z + 0.5 * offset
    start = rest_height(terrain, sx, sz, radius) + 0.05
    b = ModelBuilder(Material(rolling_resistance=0.05))
    b.set_terrain(terrain)
    b.add_sphere(radius, 1.0, position=(sx, start, sz))
    config = SimConfig(sleep=False, device=device)
    sim = Simulator(b.finalize(device), config)
    inertia = 0.4 * radius**2
    h = config.dt / sim.substeps
    energy = []
    for _ in range(480):
        sim.step(1)
        v, L = sim.state.body_vel.numpy()[0], sim.state.body_angmom.numpy()[0]
        energy.append(0.5 * v @ v + 0.5 * L @ L / inertia + G * float(sim.state.body_pos.numpy()[0][1]))
    assert max(energy) <= G * start + G**2 * h**2
    pos = sim.state.body_pos.numpy()[0]
    centre = (x, sz if ground == "trough" else z)  # a trough leaves the ball where it was along z
    assert np.hypot(pos[0] - centre[0], pos[2] - centre[1]) < 1e-3
    assert abs(float(pos[1]) - rest_height(terrain, pos[0], pos[2], radius)) < 1e-3


def test_wide_spheres_elsewhere_keep_the_one_point_answer(device):
    """Wide balls (5 % past the curvature radius bound) at random places over open ground: the
    deepest active slot is r minus the brute-force distance to the surface (a 5 mm grid: 6 mm
    tolerance, as for one-slot spheres in test_terrain.py), and no two active slots hold surface
    points closer than the duplicate share (5 % of r)."""
    terrain = FourierTerrain(terms=3, frequency=0.4, amplitude=0.6, seed=4)
    radius = 1.05 / terrain.curvature_bound()
    rng = np.random.default_rng(9)
    xz = rng.uniform(-8.0, 8.0, (30, 2))
    b = ModelBuilder()
    b.set_terrain(terrain)
    for x, z in xz:
        b.add_sphere(radius, 1.0, position=(x, float(terrain.height(x, z)) + radius + rng.uniform(-0.05, 0.1), z))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    probe = sim.model.contacts()
    sim.collide(sim.state, probe, 1.0 / 240.0, 0.5)
    active = probe.terrain_contact_active.numpy() != 0
    surface = probe.terrain_contact_surface.numpy()
    depth = probe.terrain_contact_depth.numpy()
    g = np.linspace(-1.5, 1.5, 601)
    for i, (start, count) in enumerate(zip(sim.model.host["body_checkpoint_start"],
                                           sim.model.host["body_checkpoint_count"])):
        slots = np.arange(start, start + count)[active[start:start + count]]
        assert len(slots) >= 1
        points = surface[slots]
        apart = np.linalg.norm(points[:, None] - points[None], axis=2) + np.eye(len(slots)) * 1e9
        assert apart.min() >= 0.05 * radius
        c = sim.model.host["body_pos"][i]
        gx, gz = np.meshgrid(c[0] + g, c[2] + g)
        dist = np.sqrt((gx - c[0]) ** 2 + (terrain.height(gx, gz) - c[1]) ** 2 + (gz - c[2]) ** 2).min()
        assert depth[slots].max() == pytest.approx(radius - dist, abs=6e-3)  # the 5 mm grid's error


@pytest.mark.parametrize("radius", [1.5, 2.5])
def test_a_ball_in_a_pit_holds_its_four_diagonal_contacts(radius, device):
    """A ball at rest over the pit of cos x + cos z touches it at four points on the diagonals
    (the nearest points along t -> (pi + t, pi +- t), by a 0.1 mm search).  The further slots start
    on the axes, between two of them, where the distance has a saddle; each must leave it for its
    own diagonal (1 mm: the search stops below a micrometre, the oracle's step is 0.1 mm)."""
    height = rest_height(PIT, math.pi, math.pi, radius)
    t = np.arange(0.0, radius, 1e-4)
    along = np.hypot(np.sqrt(2.0) * t, PIT.height(math.pi + t, math.pi + t) - height)
    corner = t[np.argmin(along)]
    b = ModelBuilder()
    b.set_terrain(PIT)
    b.add_sphere(radius, 1.0, position=(math.pi, height, math.pi))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    probe = sim.model.contacts()
    sim.collide(sim.state, probe, 1.0 / 240.0, 0.0)
    active = probe.terrain_contact_active.numpy() != 0
    points = probe.terrain_contact_surface.numpy()[active] - math.pi
    expected = np.array([[sx * corner, sz * corner] for sx in (1, -1) for sz in (1, -1)])
    assert len(points) == 4
    distance = np.linalg.norm(points[:, None] - expected[None], axis=2)
    assert np.all(distance.min(axis=0) < 1e-3)  # every diagonal held, by one slot each


@pytest.mark.parametrize("ground", ["trough", "pit"])
@pytest.mark.parametrize("radius", [1.5, 2.5])
def test_a_wide_ball_bouncing_on_both_walls_keeps_its_energy(ground, radius, device):
    """e = 1, no friction: dropped 0.3 m straight into a trough (two walls) or a pit (four), the
    ball strikes every wall at once and leaves as fast as it came, without spin.  In free flight
    the ball follows the parabola (integrate.free_drift) and keeps E = m v^2 / 2 + m g y; a substep
    in which a contact touches it drifts by symplectic Euler (v += g h, then y += h v), lowering E
    by m g^2 h^2 / 2.  Contacts act only inside the speculative window, margin + h |v| + h^2 |g|, so
    at most 2 (margin / (h v) + 3) substeps of the bounce (v its speed) lose that; and float32
    round-off of E (1e-6 of m g y).  With its one contact at the bottom point the ball sank into
    the walls instead."""
    terrain = {"trough": TROUGH_X, "pit": PIT}[ground]
    x, z = math.pi, (math.pi if ground == "pit" else 0.0)
    start = rest_height(terrain, x, z, radius) + 0.3
    b = ModelBuilder(Material(restitution=1.0, friction=0.0))
    b.set_terrain(terrain)
    b.add_sphere(radius, 1.0, position=(x, start, z))
    config = SimConfig(sleep=False, device=device)
    sim = Simulator(b.finalize(device), config)
    h = config.dt / sim.substeps
    error, rising, spin, lowest = [], [], [], start
    for step in range(1, 46):
        sim.step(1)
        v, L = sim.state.body_vel.numpy()[0], sim.state.body_angmom.numpy()[0]
        energy = 0.5 * v @ v + 0.5 * L @ L / (0.4 * radius**2) + G * float(sim.state.body_pos.numpy()[0][1])
        error.append(G * start - energy)
        rising.append(v[1] > 0.0)
        spin.append(np.linalg.norm(L))
        lowest = min(lowest, float(sim.state.body_pos.numpy()[0][1]))
    assert lowest > start - 0.3 - 1e-3  # it turned on the walls (the soft contact gives g / omega^2)
    assert any(rising)  # it bounced within the 0.75 s (the fall takes 0.25 s)
    roundoff = 1e-6 * G * (abs(start) + 1.0)
    touched = 2.0 * (config.speculative_margin / (h * math.sqrt(2.0 * G * 0.3)) + 3.0)
    assert min(error) > -roundoff, min(error)  # never gains
    assert max(error) < touched * 0.5 * G**2 * h**2 + roundoff, (max(error), touched * 0.5 * G**2 * h**2)
    assert max(spin) < 1e-3
