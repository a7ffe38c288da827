"""Resting contacts, sleeping bodies, rolling resistance and speculative windows, each as a family
checked against its physical expectation (see solvers/impact.py, sleep.py, collide/narrow_phase.py).
"""

import math

import numpy as np
import pytest

from warp_sim import ModelBuilder, SimConfig, Simulator, cases
from warp_sim.builder import Material
from warp_sim.column_sag import contact_omega
from warp_sim.terrain import FourierTerrain, NoTerrain, PlaneTerrain

G = 9.81


def simulator(builder, device="cpu", **config):
    return Simulator(builder.finalize(device), SimConfig(device=device, **config))


@pytest.mark.parametrize("mass_a, mass_b", [(1.0, 1.0), (100.0, 1.0), (1.0, 100.0), (2.0, 3.0)])
@pytest.mark.parametrize("restitution", [1.0, 0.5])
def test_a_sleeping_body_takes_part_in_the_step_it_is_hit(mass_a, mass_b, restitution, device):
    """On a frictionless plane (mu 0: no spin, the balls slide), ball A strikes ball B, which has
    fallen asleep resting there.  The outcome is the two-body impact's, v_A' = (m_A - e m_B) v /
    (m_A + m_B), v_B' = (1 + e) m_A v / (m_A + m_B), momentum along x exact: a sleeping body is
    no wall.  B sleeps from t = 0.5 s, A arrives at 2/3 s; the velocities are read at 1 s, before
    a slow B (under sleep_velocity) could fall asleep again.  (Without gravity nothing sleeps,
    sleep.py, so the plane and gravity hold B for its sleep.)"""
    speed = 3.0
    b = ModelBuilder(Material(restitution=restitution, friction=0.0))
    b.set_terrain(PlaneTerrain())
    b.add_sphere(0.5, mass_a, position=(-3.0, 0.5, 0.0), velocity=(speed, 0.0, 0.0))
    b.add_sphere(0.5, mass_b, position=(0.0, 0.5, 0.0))
    sim = simulator(b, device, sleep=True)
    slept = False
    for _ in range(60):
        sim.step()
        slept = slept or sim.awake_count() < 2
    assert slept
    v = sim.state.body_vel.numpy()[:, 0].astype(np.float64)
    total = mass_a + mass_b
    assert v[0] == pytest.approx((mass_a - restitution * mass_b) * speed / total, abs=1e-4 * speed)
    assert v[1] == pytest.approx((1 + restitution) * mass_a * speed / total, abs=1e-4 * speed)
    assert mass_a * v[0] + mass_b * v[1] == pytest.approx(mass_a * speed, rel=1e-5)



def struck_row(count, restitution, masses, sleep, device):
    """A ball at 3 m/s striking a row of ``count`` touching balls resting on a frictionless plane
    (asleep by the hit with sleeping on); returns the velocities along x at 1.2 s (the hit is at
    about 0.83 s, so nothing slowed has slept again) and whether any body slept."""
    b = ModelBuilder(Material(restitution=restitution, friction=0.0))
    b.set_terrain(PlaneTerrain())
    b.add_sphere(0.5, 1.0, position=(-3.5, 0.5, 0.0), velocity=(3.0, 0.0, 0.0))
    for k in range(count):
        b.add_sphere(0.5, float(masses[k]), position=(float(k), 0.5, 0.0))
    sim = simulator(b, device, sleep=sleep)
    slept = False
    for _ in range(72):
        sim.step()
        slept = slept or sim.awake_count() < count + 1
    return sim.state.body_vel.numpy()[:, 0].astype(np.float64), slept


@pytest.mark.parametrize("count", [2, 4, 6])
@pytest.mark.parametrize("restitution", [1.0, 0.8, 0.5])
@pytest.mark.parametrize("masses", ["equal", "random"])
def test_a_sleeping_row_struck_at_one_end_moves_as_an_awake_one(count, restitution, masses, device):
    """The law above through a chain: every sleeper the blow reaches takes part in the step it is
    struck (sleep.py), so the outcome is the awake row's, to the float32 rounding of a converged
    impact (1e-4 of the strike), with momentum exact.  When only the struck ball woke, the rest
    of the row held still for that step: a ball striking four sleeping balls at 3 m/s with e = 1
    bounced back at 3 m/s."""
    weights = np.ones(count) if masses == "equal" else np.random.default_rng(count).uniform(0.5, 2.0, count)
    asleep, slept = struck_row(count, restitution, weights, True, device)
    awake, _ = struck_row(count, restitution, weights, False, device)
    assert slept
    assert np.abs(asleep - awake).max() < 1e-4 * 3.0
    assert float(np.dot(np.concatenate([[1.0], weights]), asleep)) == pytest.approx(3.0, rel=1e-5)

@pytest.mark.parametrize("restitution", [0.5, 0.9])
@pytest.mark.parametrize("count", [5, 10])
def test_resting_stack_with_restitution_stands(restitution, count, device):
    """A resting contact approaches at ~0 m/s, under the restitution threshold, so it never bounces
    however much load it holds: a stack with e > 0 stands like one with e = 0.  Bound: the soft
    contacts' static sag, count^2 g / omega^2 (omega = 2 pi 60 Hz; test_body_contact derives it),
    5 % and 1 mm over, and 1 cm sideways."""
    b = ModelBuilder(Material(restitution=restitution, friction=0.5))
    b.set_terrain(PlaneTerrain())
    for k in range(count):
        b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, 0.5 + k, 0.0))
    sim = simulator(b, device, sleep=False)
    sim.step(180)
    top = sim.state.body_pos.numpy()[-1]
    omega = 2 * np.pi * 60.0
    assert abs(top[1] - (count - 0.5)) < 1.05 * count**2 * G / omega**2 + 1e-3
    assert np.hypot(top[0], top[2]) < 0.01
    assert np.abs(sim.state.body_vel.numpy()).max() < 0.05


@pytest.mark.parametrize("ratio", [10.0, 1e4])
def test_heavy_body_on_light_one_does_not_launch_it(ratio, device):
    """e = 0.5, a heavy cube at rest on a light one: no contact approaches, nothing bounces; the
    light cube must not be ejected (it was thrown at 118 m/s when the load's impulse decided)."""
    b = ModelBuilder(Material(restitution=0.5, friction=0.5))
    b.set_terrain(PlaneTerrain())
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, 0.5, 0.0))
    b.add_box((0.5, 0.5, 0.5), ratio, position=(0.0, 1.5, 0.0))
    sim = simulator(b, device, sleep=False)
    sim.step(60)
    assert np.abs(sim.state.body_vel.numpy()).max() < 1.0


@pytest.mark.parametrize("schedule", ["domains", "colors"])
@pytest.mark.parametrize("ratio, half_height, restitution", [(30.0, 0.5, 0.0), (1e3, 0.25, 0.5), (1e4, 0.5, 0.5),
                                                            (1e4, 0.1, 0.0)])
def test_heavy_body_settles_on_light_one_without_swinging(ratio, half_height, restitution, schedule, device):
    """A heavy cube set down on a light box (a cube, a slab, a plate) on the plane settles into its
    soft-contact sag without swinging.  The light box's contacts are springs of its own small mass;
    undamped for the heavy body, the pair rode down to twice the sag and up again for a second
    (0.23 m/s at 1e4:1), and Gauss-Seidel handed the load down by m / M a sweep.  Checks:
    - at rest under load a body moves by at most one step of gravity between solves: |v| <= g dt;
    - critically damped, the sag approaches its rest value from above without overshoot: the
      deepest sag is the final one, 5 % and 0.2 mm (float32 and the step's last fraction) over;
    - the stiffness is the soft law's (unchanged by the damping): each point a spring of
      omega^2 / k_n, four of them under each face, the two faces in series, so the sag is
      g (M + m) k_n,ground / (4 omega^2) + g M k_n,pair / (4 omega^2); within 5 % (the faces'
      points share the load equally only while nothing tilts)."""
    if schedule == "domains" and device != "cpu":
        pytest.skip("the slab schedule runs on the CPU only")
    b = ModelBuilder(Material(restitution=restitution, friction=0.5))
    b.set_terrain(PlaneTerrain())
    b.add_box((0.5, half_height, 0.5), 1.0, position=(0.0, half_height, 0.0))
    b.add_box((0.5, 0.5, 0.5), ratio, position=(0.0, 2 * half_height + 0.5, 0.0))
    sim = simulator(b, device, sleep=False, pair_schedule=schedule)
    top0 = 2 * half_height + 0.5
    speed, deepest, sag = 0.0, 0.0, 0.0
    for _ in range(90):
        sim.step()
        speed = max(speed, float(np.linalg.norm(sim.state.body_vel.numpy()[0])))
        sag = top0 - float(sim.state.body_pos.numpy()[1][1])
        deepest = max(deepest, sag)
    assert speed <= G * sim.config.dt
    assert deepest <= 1.05 * sag + 2e-4
    omega = contact_omega(sim.config.dt / sim.substep_plan.substeps, sim.config.contact_hertz)

    def corner_term(mass, half):
        # (r x n) . I^-1 (r x n) at a corner of a horizontal face of a box, n vertical
        a, b, c = half
        return c * c / (mass * (b * b + c * c) / 3) + a * a / (mass * (a * a + b * b) / 3)

    light, heavy = (0.5, half_height, 0.5), (0.5, 0.5, 0.5)
    k_ground = 1.0 + corner_term(1.0, light)
    k_pair = 1.0 + corner_term(1.0, light) + 1.0 / ratio + corner_term(ratio, heavy)
    expected = G * ((ratio + 1.0) * k_ground + ratio * k_pair) / (4.0 * omega**2)
    assert sag == pytest.approx(expected, rel=0.05)


@pytest.mark.parametrize("gravity, dt, substeps", [(100.0, 1 / 30, 1), (9.81, 1 / 30, 1), (50.0, 1 / 60, 2)])
def test_cube_on_plane_under_coarse_steps_settles_without_rising(gravity, dt, substeps, device):
    """A cube resting on a plane with restitution never rises above its resting height (it rose
    49 mm at g = 100, dt = 1/30, 1 substep) and comes to rest within 2 s."""
    b = ModelBuilder(Material(restitution=0.5, friction=0.5))
    b.set_terrain(PlaneTerrain())
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, 0.5, 0.0))
    sim = simulator(b, device, gravity=(0.0, -gravity, 0.0), dt=dt, substeps=substeps, sleep=False)
    heights = []
    for _ in range(int(2.0 / dt)):
        sim.step()
        heights.append(float(sim.state.body_pos.numpy()[0][1]))
    assert max(heights) < 0.5 + 1e-3
    assert abs(float(sim.state.body_vel.numpy()[0][1])) < 0.05


@pytest.mark.parametrize("gravity", [30.0, 100.0, 300.0])
@pytest.mark.parametrize("half, turn", [((0.25, 0.25, 0.25), 0.0), ((0.5, 0.2, 0.3), 0.4), ((0.1, 0.1, 0.1), 1.1)])
@pytest.mark.parametrize("pair_schedule", ["none", "domains", "colors"])
def test_box_set_on_a_level_plane_under_coarse_steps_does_not_move_sideways(gravity, half, turn, pair_schedule,
                                                                             device):
    """By symmetry a box set on a level plane moves only down into its sag.  Its rows start cold
    (no impulse held), and two Gauss-Seidel sweeps in row order shared the load unevenly between
    its corners: at dt 1/30, 1 substep it moved 13 mm sideways in its first step under g = 100
    and 29 mm under g = 300.  Swept to convergence (soft_step.solve_sweeps), what is left is the
    stopping rule's: a pass stops changing velocity by under share g h, and the geometric tail
    after it is at most as large again, so the step moves it under 2 share g h^2 sideways.
    ``none``: the terrain-only kernel; the others carry a far sphere so the staged solver runs."""
    if pair_schedule == "domains" and device != "cpu":
        pytest.skip("the slab schedule runs on the CPU only")
    b = ModelBuilder(Material(restitution=0.5, friction=0.5))
    b.set_terrain(PlaneTerrain())
    b.add_box(half, 1.0, position=(0.0, half[1], 0.0), orientation=(0.0, np.sin(turn / 2), 0.0, np.cos(turn / 2)))
    config = {}
    if pair_schedule != "none":
        b.add_sphere(0.2, 1.0, position=(5.0, 0.2, 0.0))
        config["pair_schedule"] = pair_schedule
    dt = 1.0 / 30.0
    sim = simulator(b, device, gravity=(0.0, -gravity, 0.0), dt=dt, substeps=1, sleep=False, **config)
    start = sim.state.body_pos.numpy()[0].astype(float)
    sideways = 0.0
    for _ in range(30):
        sim.step()
        moved = sim.state.body_pos.numpy()[0].astype(float) - start
        sideways = max(sideways, float(np.hypot(moved[0], moved[2])))
    bound = 2.0 * sim.config.convergence_gravity_share * gravity * dt ** 2
    assert sideways < bound, (sideways, bound)


@pytest.mark.parametrize("rolling_resistance", [0.02, 0.05])
@pytest.mark.parametrize("radius", [0.1, 0.25])
def test_rolling_resistance_on_a_box_floor_matches_the_plane(rolling_resistance, radius, device):
    """A solid ball rolling on a static box, or on a 1000 kg box lying on the plane, decelerates at
    5/7 c_r g, as on the terrain plane (on the dynamic box, whose pair with the ball is solved
    across two slabs, the resistance's accumulator was kept from substep to substep, so it acted
    once a step: 1 / substeps of it).  Tolerance: the resistance is clamped per substep, exact for
    a steady roll; 2 %."""
    decelerations = []
    for floor in ("box", "dynamic box", "plane"):
        b = ModelBuilder(Material(friction=0.5, rolling_resistance=rolling_resistance))
        top = 0.0
        if floor == "box":
            b.add_box((20.0, 0.5, 20.0), 1.0, position=(0.0, -0.5, 0.0), static=True)
        elif floor == "dynamic box":
            b.set_terrain(PlaneTerrain())
            b.add_box((20.0, 0.5, 20.0), 1000.0, position=(0.0, 0.5, 0.0))
            top = 1.0
        else:
            b.set_terrain(PlaneTerrain())
        b.add_sphere(radius, 1.0, position=(-5.0, top + radius, 0.0), velocity=(2.0, 0.0, 0.0),
                     angular_velocity=(0.0, 0.0, -2.0 / radius))
        sim = simulator(b, device, sleep=False)
        sim.step(30)
        v0 = float(sim.state.body_vel.numpy()[-1][0])
        sim.step(60)
        decelerations.append(v0 - float(sim.state.body_vel.numpy()[-1][0]))
    expected = 5.0 / 7.0 * rolling_resistance * G
    for a in decelerations:
        assert a == pytest.approx(expected, rel=0.02)


def tilted_floor(builder, path, theta, radius):
    """A floor through the origin tilted theta about z (the terrain plane, or a static box whose
    top face is that plane: the pair's rows, rolling.hold_ball_on_static), a ball of ``radius``
    resting on it at the origin; returns the ball's index and the floor's downhill direction."""
    normal = np.array([math.sin(theta), math.cos(theta), 0.0])
    if path == "static box floor":
        half = 0.5
        builder.add_box((6.0, half, 6.0), 1.0, position=tuple(-normal * half),
                        orientation=(0.0, 0.0, math.sin(-theta / 2), math.cos(-theta / 2)), static=True)
    else:
        builder.set_terrain(PlaneTerrain(normal=tuple(normal)))
    ball = builder.add_sphere(radius, 1.0, position=tuple(normal * radius))
    if path == "body contact on":
        builder.add_sphere(0.1, 1.0, position=(30.0, 40.0, 0.0))  # far above: the staged solver runs
    return ball, np.array([math.cos(theta), -math.sin(theta), 0.0])


@pytest.mark.parametrize("path", ["terrain only", "body contact on", "static box floor"])
@pytest.mark.parametrize("rolling_resistance, under_deg, radius", [
    (0.1, 1.0, 0.25), (0.1, 3.0, 0.1), (0.3, 5.0, 0.25), (0.05, 0.5, 0.5), (0.2, 1.0, 0.1)])
def test_rolling_resistance_holds_a_ball_on_a_gentler_slope(path, rolling_resistance, under_deg, radius, device):
    """A ball set on a plane tilted under atan(c_r) (mu 0.8, sleeping off) stays where it is:
    friction m g sin(theta) at the contact and its torque r m g sin(theta) are within mu N and
    c_r r N.  Taken as two rows in turn the friction and the resistance undid each other, and the
    ball crept down at about 0.6 g sin(theta) h for ever (2.7 mm/s for c_r 0.1 at 1 degree under;
    rolling.hold_ball).  Bound over 5 s: the contact spring's sag along the slope,
    g / omega^2 at omega = 2 pi 60 Hz (0.07 mm), twice."""
    b = ModelBuilder(Material(friction=0.8, rolling_resistance=rolling_resistance))
    ball, down = tilted_floor(b, path, math.atan(rolling_resistance) - math.radians(under_deg), radius)
    sim = simulator(b, device, sleep=False)
    start = sim.state.body_pos.numpy()[ball].astype(np.float64)
    sim.step(300)
    moved = float(np.dot(sim.state.body_pos.numpy()[ball] - start, down))
    assert abs(moved) < 2.0 * G / (2.0 * math.pi * 60.0) ** 2


@pytest.mark.parametrize("path", ["terrain only", "static box floor"])
@pytest.mark.parametrize("rolling_resistance, over_deg, radius", [(0.1, 2.0, 0.25), (0.2, 4.0, 0.1), (0.05, 3.0, 0.5)])
def test_rolling_resistance_lets_a_ball_roll_down_a_steeper_slope(path, rolling_resistance, over_deg, radius, device):
    """The hold must not hold what cannot be held: past atan(c_r) (friction mu 0.8 still grips) a
    ball rolls down at (5/7) g (sin(theta) - c_r cos(theta)) (the resistance's torque c_r r N
    against the roll, the ball's I = 2/5 m r^2).  Measured as the velocity gained between 0.5 s
    and 1.5 s (the first half second lets the contact settle); semi-implicit Euler gains exactly
    a h per substep at a constant force, so 2 % covers the contact spring's ripple."""
    theta = math.atan(rolling_resistance) + math.radians(over_deg)
    b = ModelBuilder(Material(friction=0.8, rolling_resistance=rolling_resistance))
    ball, down = tilted_floor(b, path, theta, radius)
    sim = simulator(b, device, sleep=False)
    sim.step(30)
    v0 = float(np.dot(sim.state.body_vel.numpy()[ball], down))
    sim.step(60)
    gained = float(np.dot(sim.state.body_vel.numpy()[ball], down)) - v0
    expected = 5.0 / 7.0 * G * (math.sin(theta) - rolling_resistance * math.cos(theta))
    assert gained == pytest.approx(expected, rel=0.02)


@pytest.mark.parametrize("gravity, dt", [(100.0, 1 / 30), (40.0, 1 / 20)])
def test_body_floor_window_covers_gravity_like_the_terrain(gravity, dt, device):
    """A sphere falling on a static box sinks no deeper than on the terrain plane: the pair's swept
    reach includes the T^2 |g| a body falls within the step, as the terrain window does (it sank
    16.7 cm into the box and 2.9 cm into the plane).  Tolerance 5 mm."""
    deepest = []
    for floor in ("box", "plane"):
        b = ModelBuilder(Material(friction=0.5))
        if floor == "box":
            b.add_box((5.0, 0.5, 5.0), 1.0, position=(0.0, -0.5, 0.0), static=True)
        else:
            b.set_terrain(PlaneTerrain())
        b.add_sphere(0.25, 1.0, position=(0.0, 3.0, 0.0))
        sim = simulator(b, device, gravity=(0.0, -gravity, 0.0), dt=dt, substeps=1, sleep=False)
        low = np.inf
        for _ in range(int(1.5 / dt)):
            sim.step()
            low = min(low, float(sim.state.body_pos.numpy()[-1][1]))
        deepest.append(0.25 - low)
    assert deepest[0] < deepest[1] + 5e-3


@pytest.mark.parametrize("start_offset", [0.6, 1.0])
@pytest.mark.parametrize("friction", [0.5, 0.9])
def test_ball_rolling_in_a_valley_keeps_its_energy_with_other_bodies_present(start_offset, friction, device):
    """A ball rolling without slipping in the valley of a one-term terrain (A cos(f x), f = 0.5)
    keeps its mechanical energy, also when the scene holds a second body (so body contact and
    contacts found once per step are on): it gained 16 % of its oscillation energy in 20 s when
    its terrain contact's tangent-plane gap was carried through the substeps (k d^2 / 2 per step).
    Bound over 10 s: the 1 mm it drops onto the surface (m g 1e-3) plus 1 % of the oscillation
    energy (without the per-substep sphere contacts, Simulator.refresh_sphere_contacts = False, the
    ball started 1 m up the slope fails it)."""
    terrain = FourierTerrain(terms=2, frequency=0.5, amplitudes=np.array([[0.0, 0.0], [1.0, 0.0]]),
                             phases=np.zeros((2, 2)))
    valley = np.pi / 0.5
    x0 = valley - start_offset
    b = ModelBuilder(Material(friction=friction))
    b.set_terrain(terrain)
    ground = float(terrain.height(np.array([x0]), np.array([0.0]))[0])
    b.add_sphere(0.25, 1.0, position=(x0, ground + 0.251, 0.0))
    b.add_sphere(0.25, 1.0, position=(valley + 30.0, 5.0, 30.0))  # far away, but body contact is on
    sim = simulator(b, device, sleep=False)
    assert sim.pairs is not None and sim.config.contact_update == "step"
    oscillation = G * (ground - float(terrain.height(np.array([valley]), np.array([0.0]))[0]))

    def energy():
        return float(sim.kinetic_energy(per_body=True)[0]) + G * float(sim.state.body_pos.numpy()[0][1])

    e0 = energy()
    drift = []
    for _ in range(10):
        sim.step(60)
        drift.append(energy() - e0)
    assert max(abs(d) for d in drift) < G * 1e-3 + 0.01 * oscillation


@pytest.mark.parametrize("drop", [1.0, 3.0])
@pytest.mark.parametrize("contact_update", ["step", "substep"])
def test_balls_dropped_on_the_terrain_with_body_contact_stop_at_the_surface(drop, contact_update, device):
    """Balls falling 1 and 3 m onto the Fourier terrain with body contact on (so the staged solver,
    and with contacts once per step the per-substep sphere refresh): the speculative contact stops
    each one at the surface.  What is left is the soft contact's static sag g / omega^2 (0.07 mm)
    and the tangent-plane gap error over one substep of sliding, kappa (v h)^2 / 2 (under 0.1 mm
    here); bound 1 mm.  A refresh that dropped a slot the step's pass had opened let them sink
    32 mm on landing."""
    terrain = FourierTerrain(amplitude=0.5)
    b = ModelBuilder(Material(friction=0.6, rolling_resistance=0.1))
    b.set_terrain(terrain)
    for k in range(4):
        x = 1.3 * k
        b.add_sphere(0.25, 1.0, position=(x, float(terrain.height(np.array([x]), np.array([0.0]))[0]) + 0.25 + drop,
                                          0.0))
    sim = simulator(b, device, sleep=False, contact_update=contact_update)
    deepest = 0.0
    for _ in range(90):
        sim.step()
        deepest = max(deepest, sim.max_penetration())
    assert deepest < 1e-3


@pytest.mark.parametrize("theta_deg", [10.0, 20.0, 30.0])
@pytest.mark.parametrize("shape, friction", [("box", 0.2), ("box", 0.8), ("sphere", 0.5), ("sphere", 0.05)])
def test_body_on_a_tilted_box_accelerates_as_on_an_incline(theta_deg, shape, friction, device):
    """A cube or a ball on a static box tilted by theta (body-body contact, not the terrain): the
    textbook incline.  A sliding cube accelerates at g (sin theta - mu cos theta), or stays put
    where mu >= tan theta; a solid ball rolls at 5/7 g sin theta while mu >= 2/7 tan theta, and
    slides at g (sin theta - mu cos theta) below that.  Constant acceleration is integrated exactly
    by the semi-implicit step, so what is left is float32 rounding of speeds near 1 m/s over 120
    substeps (about 1e-5 m/s, 2e-5 m/s^2 over the 0.5 s measured): tolerance 1e-3 m/s^2."""
    theta = np.radians(theta_deg)
    down = np.array([np.cos(theta), -np.sin(theta), 0.0])  # along the slope, descending
    normal = np.array([np.sin(theta), np.cos(theta), 0.0])
    tilt = (0.0, 0.0, -np.sin(theta / 2), np.cos(theta / 2))
    b = ModelBuilder(Material(friction=friction))
    b.add_box((10.0, 0.5, 3.0), 1.0, position=tuple(-0.5 * normal), orientation=tilt, static=True)
    start = tuple(0.2 * normal - 2.0 * down)
    if shape == "box":
        b.add_box((0.2, 0.2, 0.2), 1.0, position=start, orientation=tilt)
        want = max(0.0, G * (np.sin(theta) - friction * np.cos(theta)))
    else:
        b.add_sphere(0.2, 1.0, position=start)
        rolls = friction >= 2.0 / 7.0 * np.tan(theta)
        want = 5.0 / 7.0 * G * np.sin(theta) if rolls else G * (np.sin(theta) - friction * np.cos(theta))
    sim = simulator(b, device, sleep=False)
    sim.step(30)  # settled onto the slope, the motion under way
    v0 = sim.state.body_vel.numpy()[-1].astype(np.float64)
    sim.step(30)
    v1 = sim.state.body_vel.numpy()[-1].astype(np.float64)
    assert (v1 - v0) @ down / 0.5 == pytest.approx(want, abs=1e-3)
    assert abs((v1 - v0) @ normal) < 1e-3 * 0.5  # it stays on the slope


def slow_start(shape: str, accel: float, size: float, mass: float, sleep: bool, device, seconds: float = 3.0):
    """A ball released at rest on a plane tilted so that it rolls at ``accel`` = 5/7 g sin theta, or
    a cube on a plane steeper than its friction angle by what makes it slide at ``accel`` =
    g (sin theta - mu cos theta): distance travelled down the slope after ``seconds`` (the sag into
    the soft contact, normal to it, is left out), and the expected a t^2 / 2."""
    mu = 0.5
    if shape == "sphere":
        theta = math.asin(accel / (5.0 / 7.0 * G))
    else:  # g (sin theta - mu cos theta) = g sqrt(1 + mu^2) sin(theta - atan mu)
        theta = math.atan(mu) + math.asin(accel / (G * math.sqrt(1.0 + mu * mu)))
    b = ModelBuilder(Material(friction=mu))
    b.set_terrain(PlaneTerrain.from_slope(math.degrees(theta)))
    n = np.array([-math.sin(theta), math.cos(theta), 0.0])
    if shape == "sphere":
        b.add_sphere(size, mass, position=tuple(size * n))
    else:
        b.add_box((size, size, size), mass, position=tuple(size * n), orientation=(0.0, 0.0, math.sin(theta / 2),
                                                                                   math.cos(theta / 2)))
    sim = simulator(b, device, sleep=sleep)
    start = sim.state.body_pos.numpy()[0].astype(float)
    sim.step(round(seconds * 60))
    down = np.array([-math.cos(theta), -math.sin(theta), 0.0])  # the plane rises along +x
    travelled = float((sim.state.body_pos.numpy()[0] - start) @ down)
    return travelled, 0.5 * accel * seconds ** 2, sim


@pytest.mark.parametrize("shape", ["sphere", "box"])
def test_bodies_starting_slowly_from_rest_roll_or_slide_as_the_incline_says(shape, device):
    """Sleeping off: the textbook distance within 3 % (constant acceleration is integrated exactly
    but for the first step's soft-contact transient, a few mm)."""
    travelled, want, _ = slow_start(shape, 0.037 if shape == "sphere" else 0.077, 0.25, 1.0, False, device)
    assert travelled == pytest.approx(want, rel=0.03)


@pytest.mark.parametrize("shape", ["sphere", "box"])
@pytest.mark.parametrize("accel, size, mass", [(0.015, 0.25, 1.0), (0.037, 0.25, 1.0), (0.037, 0.1, 50.0),
                                               (0.06, 0.5, 0.2), (0.09, 0.25, 5.0)])
def test_bodies_starting_slowly_from_rest_are_not_put_to_sleep(shape, accel, size, mass, device):
    """The same at the defaults, sleeping on, for accelerations between the rise floor (sleep.py:
    SLEEP_RISE_FRACTION sleep_velocity / sleep_time, 0.01 m/s^2) and sleep_velocity / sleep_time
    (0.1 m/s^2), below which the speed alone put them to sleep: the ball at 0.037 m/s^2 rolled 4.6
    mm and the cube at 0.077 m/s^2 slid 10 mm before they slept for good.  Sleeping must not
    change the motion at all: the distance equals the sleep-off run's to float32 (the kernels are
    the same, so it is bit for bit).  The sleep-off run is checked against the textbook above (a
    cube released touching the slope also slides an extra 1e-3 m/s before its friction is loaded,
    3 mm over the 3 s, which at these small accelerations is more than 3 % of the distance)."""
    travelled, _, sim = slow_start(shape, accel, size, mass, True, device)
    assert sim.sleep.awake_count() == 1
    free, _, _ = slow_start(shape, accel, size, mass, False, device)
    assert travelled == pytest.approx(free, rel=1e-6)


@pytest.mark.parametrize("shape", ["sphere", "box"])
def test_a_body_accelerating_under_the_rise_floor_still_falls_asleep(shape, device):
    """The blind spot that is left, shown: at half the rise floor (0.005 m/s^2) a body's speed grows
    by less than the floor asks each step, and it sleeps after sleep_time as before, having moved
    a t^2 / 2 = 0.6 mm or so, far short of the 22 mm the incline gives in 3 s."""
    travelled, want, sim = slow_start(shape, 0.005, 0.25, 1.0, True, device)
    assert sim.sleep.awake_count() == 0
    assert travelled < 0.1 * want


@pytest.mark.parametrize("shape, mass, size", [("sphere", 1.0, 0.25), ("box", 1.0, 0.25), ("box", 20.0, 0.5),
                                               ("box", 0.1, 0.1)])
@pytest.mark.parametrize("tilt", [0.0, 10.0, 20.0])
def test_bodies_at_rest_still_fall_asleep_in_sleep_time(shape, mass, size, tilt, device):
    """The rise rule must not keep resting bodies awake.  A body released just above the ground on
    a plane tilted ``tilt`` degrees, mu 0.5 (a cube held by friction, under atan 0.5 = 26.6 degrees;
    a ball only on the level) lands, settles within a few steps and must sleep within sleep_time
    of it: by 1 s."""
    if shape == "sphere" and tilt > 0.0:
        pytest.skip("a ball rolls down any tilt")
    theta = math.radians(tilt)
    n = np.array([-math.sin(theta), math.cos(theta), 0.0])
    b = ModelBuilder(Material(friction=0.5))
    b.set_terrain(PlaneTerrain.from_slope(tilt))
    if shape == "sphere":
        b.add_sphere(size, mass, position=tuple((size + 0.01) * n))
    else:
        b.add_box((size, size, size), mass, position=tuple((size + 0.01) * n),
                  orientation=(0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)))
    sim = simulator(b, device)
    sim.step(60)
    assert sim.sleep.awake_count() == 0


@pytest.mark.parametrize("shape", ["sphere", "box", "two boxes"])
@pytest.mark.parametrize("speed", [0.01, 0.03, 0.049])
@pytest.mark.parametrize("gravity", [0.0, 0.005])
def test_bodies_drifting_without_gravity_stay_awake_and_keep_their_momentum(shape, speed, gravity, device):
    """Zero gravity (and gravity weaker than the rise rule's a_rise = 0.01 m/s^2), sleeping on: a
    body, or two touching cubes, drifting slower than sleep_velocity is free, not at rest, and
    travels v t.  A slow free body is told from a resting one by nothing the sleep timers read
    without gravity, so none sleeps there (sleep.py); before, a box at 0.049 m/s fell asleep after
    sleep_time and stopped, its momentum zeroed.  Tolerance: free flight is exact but for float32
    rounding of positions of order 1 m (1e-6), plus the weak gravity's g t^2 / 2 along y."""
    b = ModelBuilder(Material(restitution=0.0, friction=0.5))
    b.set_terrain(NoTerrain())
    if shape == "sphere":
        b.add_sphere(0.25, 1.0, position=(0.0, 0.0, 0.0), velocity=(speed, 0.0, 0.0))
    else:
        b.add_box((0.25, 0.25, 0.25), 1.0, position=(0.0, 0.0, 0.0), velocity=(speed, 0.0, 0.0))
        if shape == "two boxes":
            b.add_box((0.25, 0.25, 0.25), 2.0, position=(0.5, 0.0, 0.0), velocity=(speed, 0.0, 0.0))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, -gravity, 0.0), device=device))
    seconds = 2.0
    sim.step(int(round(seconds / sim.config.dt)))
    x = sim.state.body_pos.numpy()[0].astype(float)
    assert x[0] == pytest.approx(speed * seconds, abs=1e-5)
    assert sim.awake_count() == sim.model.body_count


def test_resting_bodies_still_sleep_under_gravity_as_weak_as_the_rise_floor(device):
    """The guard of the rule above: a cube at rest on the plane under g = 0.02 m/s^2 (twice a_rise)
    sleeps within sleep_time and a step."""
    b = ModelBuilder(Material(restitution=0.0, friction=0.5))
    b.set_terrain(PlaneTerrain())
    b.add_box((0.25, 0.25, 0.25), 1.0, position=(0.0, 0.25, 0.0))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, -0.02, 0.0), device=device))
    sim.step(int(math.ceil(sim.config.sleep_time / sim.config.dt)) + 2)
    assert sim.awake_count() == 0


@pytest.mark.parametrize("integrator", ["explicit_euler", "semi_implicit", "verlet", "rk4"])
@pytest.mark.parametrize("dt, substeps", [(1.0 / 60.0, 1), (1.0 / 30.0, 1), (1.0 / 60.0, 4)])
@pytest.mark.parametrize("shape", ["sphere", "box"])
def test_resting_bodies_sleep_under_every_integrator(integrator, dt, substeps, shape, device):
    """A ball and a cube at rest on the plane sleep within sleep_time and 0.2 s, whatever the
    integrator and step.  Each substep adds (1 - alpha) g h after its solve (integrate.py), which
    the contacts take back only at the next; counted as motion, a resting body under verlet or
    rk4 moved at g h / 2 (0.082 m/s at dt 1/60 with one substep, over sleep_velocity) and under
    explicit_euler at g h, and never slept."""
    b = ModelBuilder(Material(restitution=0.0, friction=0.5))
    b.set_terrain(PlaneTerrain())
    if shape == "sphere":
        b.add_sphere(0.25, 1.0, position=(0.0, 0.25, 0.0))
    else:
        b.add_box((0.25, 0.25, 0.25), 1.0, position=(0.0, 0.25, 0.0))
    config = SimConfig(dt=dt, substeps=substeps, integrator=integrator, auto_substeps=False, device=device)
    sim = Simulator(b.finalize(device), config)
    sim.step(int(math.ceil((config.sleep_time + 0.2) / dt)))
    assert sim.awake_count() == 0


@pytest.mark.parametrize("floor", ["plane", "static box"])
@pytest.mark.parametrize("mu, spin", [(0.5, 10.0), (0.3, 6.0)])
def test_a_cube_spinning_on_its_face_slows_as_even_pressure_says(floor, mu, spin, device):
    """A cube (half a = 0.25) spinning about the vertical on a face: Coulomb friction under even
    pressure over the square gives the torque mu m g a (sqrt 2 + ln(1 + sqrt 2)) / 3 and a
    constant deceleration of that over I = 2 m a^2 / 3.  Measured over the first 0.1 s (the spin
    does not stop within it); the integration of a constant torque is exact, so 2 % covers the
    first substep's soft-contact transient.  With friction at the corners (before contact_patch.py) it
    slowed 1.85 times as fast."""
    a, m = 0.25, 1.0
    sim = cases.spinning_box((a, a, a), m, mu, spin, floor, device=device)
    sim.step(6)
    slowed = (spin - sim.angular_velocity()[-1, 1]) / 0.1
    even = mu * m * G * a * (math.sqrt(2.0) + math.log(1.0 + math.sqrt(2.0))) / 3.0 / (2.0 * m * a * a / 3.0)
    assert slowed == pytest.approx(even, rel=0.02)
