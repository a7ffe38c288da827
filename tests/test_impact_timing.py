"""Impacts timed to close exactly at a substep's end, and far from the origin.

A contact that the impact stage judged open (its predicted end gap, gap + h vn, at or a rounding
above 0) but that the integration then closed by a hair was held by the relax as a resting
contact: stopped dead, its bounce lost.  Two equal balls, e = 1, meeting after exactly four
substeps' travel left together at v / 2; a ball hitting a wall or the plane that way stuck to it;
900 m from the origin, 15 of 300 timed cases lost their bounce.  The laws checked here hold
whatever the timing: the 1-D impact of two spheres (or of a sphere and a wall) along one normal,
which the impact stage solves in closed form: v_a' = v_a - (1 + e) m_b / (m_a + m_b) (v_a - v_b),
v_b' = v_b + (1 + e) m_a / (m_a + m_b) (v_a - v_b).  Tolerance 1e-4 of the approach speed: the
velocities are float32 (6e-8 relative) and the impact is exact on one normal; a lost bounce misses
by a quarter of the approach speed or more.
"""

import numpy as np
import pytest

from warp_sim import ModelBuilder, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.terrain import PlaneTerrain

H = 1.0 / 240.0  # the default substep
RADIUS = 0.25


def after_head_on(x0: float, speed: float, gap: float, restitution: float, mass_a: float, mass_b: float, device):
    b = ModelBuilder(Material(restitution=restitution, friction=0.0))
    b.add_sphere(RADIUS, mass_a, position=(x0 - 2 * RADIUS - gap, 0.3, 0.1), velocity=(speed, 0.0, 0.0))
    b.add_sphere(RADIUS, mass_b, position=(x0, 0.3, 0.1))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, device=device))
    sim.step(int(gap / speed * 60.0) + 2)
    return sim.state.body_vel.numpy()[:, 0].astype(float)


@pytest.mark.parametrize("x0", [0.0, 37.0, 900.0])
@pytest.mark.parametrize("speed, substeps_of_travel, rounding", [
    (30.0, 4, 0.0), (60.0, 2, 0.0), (12.0, 5, 1e-7), (7.0, 3, -1e-7), (3.0, 2, 3e-6), (3.0, 6, 0.0)])
@pytest.mark.parametrize("restitution, mass_a, mass_b", [(1.0, 1.0, 1.0), (1.0, 3.0, 1.0), (0.5, 1.0, 2.5)])
def test_head_on_impact_timed_to_a_substep_end_follows_the_1d_law(x0, speed, substeps_of_travel, rounding,
                                                                   restitution, mass_a, mass_b, device):
    gap = substeps_of_travel * speed * H * (1.0 + rounding)
    va, vb = after_head_on(x0, speed, gap, restitution, mass_a, mass_b, device)
    share = (1.0 + restitution) * speed / (mass_a + mass_b)
    assert va == pytest.approx(speed - share * mass_b, abs=1e-4 * speed)
    assert vb == pytest.approx(share * mass_a, abs=1e-4 * speed)


@pytest.mark.parametrize("wall", ["static box", "plane"])
@pytest.mark.parametrize("speed, substeps_of_travel", [(30.0, 4), (8.0, 3), (45.0, 1)])
@pytest.mark.parametrize("restitution", [1.0, 0.6])
def test_ball_into_a_wall_timed_to_a_substep_end_leaves_at_e_v(wall, speed, substeps_of_travel, restitution,
                                                                device):
    gap = substeps_of_travel * speed * H
    b = ModelBuilder(Material(restitution=restitution, friction=0.0))
    if wall == "static box":
        b.add_box((0.02, 1.0, 1.0), 1.0, position=(gap + RADIUS + 0.02, 0.0, 0.0), static=True)
    else:
        b.set_terrain(PlaneTerrain(normal=(-1.0, 0.0, 0.0), offset=-(gap + RADIUS)))
    ball = b.add_sphere(RADIUS, 1.0, position=(0.0, 0.0, 0.0), velocity=(speed, 0.0, 0.0))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, device=device))
    sim.step(int(gap / speed * 60.0) + 2)
    assert sim.state.body_vel.numpy()[ball, 0] == pytest.approx(-restitution * speed, abs=1e-4 * speed)


@pytest.mark.parametrize("seed", range(4))
def test_tumbling_box_bouncing_elastically_keeps_its_kinetic_energy(seed, device):
    """A spinning box (5 to 20 rad/s) thrown at the plane, e = 1, mu = 0, no gravity: its corner
    closes along a curve the impact stage predicts linearly.  Kinetic energy is kept (impacts with
    e = 1 and no friction are elastic; the free flight's integrator keeps it to 1e-5 over these
    steps, issue: free rotation), so 1e-3 of it."""
    rng = np.random.default_rng(seed)
    b = ModelBuilder(Material(restitution=1.0, friction=0.0))
    b.set_terrain(PlaneTerrain())
    b.add_box(tuple(rng.uniform(0.1, 0.5, 3)), float(rng.uniform(0.5, 3.0)), position=(0.0, rng.uniform(0.9, 1.2), 0.0),
              velocity=(rng.uniform(-1, 1), -rng.uniform(3, 6), rng.uniform(-1, 1)),
              angular_velocity=tuple(rng.uniform(-1, 1, 3) * rng.uniform(5, 20)))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, device=device))
    before = sim.kinetic_energy()
    sim.step(40)
    assert sim.state.body_vel.numpy()[0, 1] > 0.0  # it did hit the plane
    assert sim.kinetic_energy() == pytest.approx(before, rel=1e-3)


def yaw_pitch(rng, pitch: float):
    """A random turn about the vertical, then ``pitch`` about the body's x axis (quaternion x y z w)."""
    yaw = rng.uniform(0.0, 2.0 * np.pi)
    qy = np.array([0.0, np.sin(yaw / 2), 0.0, np.cos(yaw / 2)])
    qx = np.array([np.sin(pitch / 2), 0.0, 0.0, np.cos(pitch / 2)])
    x1, y1, z1, w1 = qy
    x2, y2, z2, w2 = qx
    return (w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2)


def elastic_floor(floor: str) -> ModelBuilder:
    """e = 1, mu = 0, the floor's top at y = 0: the plane, or a static box."""
    b = ModelBuilder(Material(restitution=1.0, friction=0.0))
    if floor == "plane":
        b.set_terrain(PlaneTerrain())
    else:
        b.add_box((3.0, 0.25, 3.0), 1.0, position=(0.0, -0.25, 0.0), static=True)
    return b


@pytest.mark.parametrize("floor", ["plane", "static box"])
@pytest.mark.parametrize("seed", [3, 7, 12, 25, 1002, 1013, 1025])
def test_tumbling_box_struck_corner_after_corner_keeps_its_energy(floor, seed, device):
    """A tumbling box (2 to 6 m/s, up to 20 rad/s) whose first corner's bounce swings the next one
    down within the same substep: that second contact is an impact of its own (impact.py: rounds,
    and the shift of the first impact counted as motion).  Met by the soft solve's speculative row
    or the relax instead it was plastic: seeds 1025, 1002, 1013 lost 31, 14 and 6 % of their
    energy on the plane, 1013 also on the static box.  e = 1, mu = 0, no gravity: the energy is kept
    to the compression's convergence (updates under 1e-5 m/s, a remaining error of that over one
    minus the sweeps' rate) and the free flight's 1e-5: 1e-3 of it."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    speed = rng.uniform(2.0, 6.0)
    direction = np.array([rng.uniform(-0.3, 0.3), -1.0, rng.uniform(-0.3, 0.3)])
    spin = rng.normal(size=3)
    spin *= rng.uniform(0.0, 20.0) / np.linalg.norm(spin)
    b = elastic_floor(floor)
    b.add_box((0.2, 0.14, 0.26), 1.0, position=(0.0, 0.6, 0.0), orientation=tuple(q),
              velocity=tuple(speed * direction / np.linalg.norm(direction)), angular_velocity=tuple(spin))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, device=device))
    before = sim.kinetic_energy()
    sim.step(30)
    assert sim.state.body_vel.numpy()[-1, 1] > 0.0  # it did hit the floor
    assert sim.kinetic_energy() == pytest.approx(before, rel=1e-3)


LATE_TURN = pytest.mark.xfail(strict=True, reason="known limitation (README, design notes: impacts timed to "
                              "the substep): an impact late in a substep moves the centre from t* but turns the "
                              "body from the substep's start; this plate's far corner swung 19 mm into the plane "
                              "and the push-out gave it 0.3 % energy (1 of 60 layouts tried)")


@pytest.mark.parametrize("floor, seed", [pytest.param("plane", 0, marks=LATE_TURN)]
                         + [(floor, seed) for floor in ("plane", "static box") for seed in range(1, 6)])
def test_thin_plate_landing_edge_first_keeps_its_energy(floor, seed, device):
    """A plate (half thickness 5 to 20 mm) landing edge first at 5 to 20 m/s, e = 1, mu = 0, no
    gravity.  Its edge gives contact points in pairs 2t apart, nearly one row twice, on which the
    compression's Gauss-Seidel converges slowly: at a fixed 16 sweeps a 1 cm plate at 10 m/s left
    with 1 to 2 % more energy than it came with.  The bound is the previous test's."""
    rng = np.random.default_rng(seed)
    thickness = rng.uniform(0.005, 0.02)
    speed = rng.uniform(5.0, 20.0)
    b = elastic_floor(floor)
    b.add_box((0.3, thickness, 0.2), 1.0, position=(0.0, 0.5, 0.0),
              orientation=yaw_pitch(rng, 0.5 * np.pi + rng.uniform(-0.3, 0.3)),
              velocity=(rng.uniform(-1.0, 1.0), -speed, rng.uniform(-1.0, 1.0)),
              angular_velocity=tuple(rng.uniform(-2.0, 2.0, 3)))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, device=device))
    before = sim.kinetic_energy()
    sim.step(int(0.5 / speed * 60) + 6)
    assert sim.state.body_vel.numpy()[-1, 1] > 0.0
    assert sim.kinetic_energy() == pytest.approx(before, rel=1e-3)
