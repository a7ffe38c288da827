"""Impacts, checked against textbook results and conservation laws (solvers/impact.py).

Each case is a family (restitution, friction, masses, sizes, body order, seeds), run through the
default pipeline (terrain-only fused kernel, or the staged solver with body contact).
"""

import math

import numpy as np
import pytest

from warp_sim import ModelBuilder, SimConfig, Simulator, cases
from warp_sim.builder import Material
from warp_sim.terrain import NoTerrain, PlaneTerrain

G = 9.81
H = 1.0 / 240.0  # the default substep: dt 1/60, 4 substeps


def simulator(builder, device="cpu", **config):
    config.setdefault("sleep", False)
    return Simulator(builder.finalize(device), SimConfig(device=device, **config))


def momentum(sim):
    return (sim.model.body_mass[:, None] * sim.state.body_vel.numpy().astype(np.float64)).sum(0)


def angular_momentum_about_origin(sim):
    x = sim.state.body_pos.numpy().astype(np.float64)
    p = sim.model.body_mass[:, None] * sim.state.body_vel.numpy().astype(np.float64)
    return (np.cross(x, p) + sim.state.body_angmom.numpy().astype(np.float64)).sum(0)


@pytest.mark.parametrize("restitution, half", [(0.3, 0.25), (0.5, 0.25), (0.8, 0.4), (0.5, 0.1)])
def test_flat_dropped_cube_bounces_straight_to_e_squared_height(restitution, half, device):
    """A cube dropped flat from H0 = 2 m rises to e^2 H0 without turning.  Tolerance: the impact
    is taken at its time within the substep (impact.py), so what is left is semi-implicit Euler's
    lag, e (1 + e) v0 h / 2 (the fall arrives g h / 2 slow, the rise at e v0 peaks e v0 h / 2
    low; v0 = sqrt(2 g H0)), the apex sampled once per step of dt (g dt^2 / 2) and the soft
    contact's deflection g / omega^2.  The spin left is the projected Gauss-Seidel residual on
    four redundant points: under 1e-3 of the bounce speed per half extent."""
    drop = 2.0
    b = ModelBuilder(Material(restitution=restitution, friction=0.5))
    b.set_terrain(PlaneTerrain())
    b.add_box((half, half, half), 1.0, position=(0.0, drop + half, 0.0))
    sim = simulator(b, device)
    v0 = math.sqrt(2 * G * drop)
    apex, spin, rising = 0.0, 0.0, False
    for _ in range(300):
        sim.step()
        vy = float(sim.state.body_vel.numpy()[0][1])
        if vy > 0:
            rising = True
        if rising:
            apex = max(apex, float(sim.state.body_pos.numpy()[0][1]) - half)
            spin = max(spin, float(np.linalg.norm(sim.angular_velocity()[0])))
            if vy < 0:
                break
    assert SimConfig().contact_hertz is None  # a quarter of the substep rate
    omega = 2 * math.pi * 0.25 / H
    tolerance = restitution * (1 + restitution) * v0 * H / 2 + 0.5 * G * (1 / 60) ** 2 + G / omega**2
    assert rising
    assert abs(apex - restitution**2 * drop) < tolerance
    assert spin * half < 1e-3 * restitution * v0


@pytest.mark.parametrize("floor", ["plane", "plane, body contact on", "static box"])
@pytest.mark.parametrize("half, drop, friction", [(0.2, 1.0, 0.6), (0.2, 1.0, 0.45), (0.1, 2.0, 0.8),
                                                  (0.4, 0.5, 0.3), (0.25, 2.0, 1.0)])
def test_flat_dropped_cube_without_restitution_lands_without_turning(floor, half, drop, friction, device):
    """e = 0: a cube dropped flat stops on its face, and by symmetry it neither turns nor slides.
    An inelastic scene runs no impact stage, so the solve's rows take the landing; a cube whose
    landing impulse the relax had taken in the substep before its face reached the plane met it
    again warm with two sweeps and left spinning at 0.17 rad/s, sliding at 3.5 cm/s (half 0.2,
    1 m, mu 0.6; soft_step.solve_sweeps).  The same bound as the elastic test above: the projected
    Gauss-Seidel residual on four redundant points, under 1e-3 of the landing speed per half
    extent, and as much sideways.  "body contact on": a ball far away makes the step the staged
    one (solvers/staged.py) instead of the fused terrain-only kernel."""
    b = ModelBuilder(Material(restitution=0.0, friction=friction))
    if floor == "static box":
        b.set_terrain(NoTerrain())
        b.add_box((3.0, 0.5, 3.0), 1.0, position=(0.0, -0.5, 0.0), static=True)
    else:
        b.set_terrain(PlaneTerrain())
    b.add_box((half, half, half), 1.0, position=(0.0, drop + half + 0.0123, 0.0))
    if floor == "plane, body contact on":
        b.add_sphere(0.2, 1.0, position=(5.0, 0.2, 0.0))
    sim = simulator(b, device)
    cube = 1 if floor == "static box" else 0
    v0 = math.sqrt(2 * G * drop)
    spin = side = 0.0
    for _ in range(int(1.5 * 60)):
        sim.step()
        v = sim.state.body_vel.numpy()[cube]
        spin = max(spin, float(np.linalg.norm(sim.angular_velocity()[cube])))
        side = max(side, float(np.hypot(v[0], v[2])))
    assert abs(float(sim.state.body_pos.numpy()[cube][1]) - half) < 1e-3  # it landed and rests
    assert spin * half < 1e-3 * v0
    assert side < 1e-3 * v0


def discrete_bounce_apex(restitution, drop, dt, substeps, threshold):
    """Float64 twin of what the solver is meant to compute for a body dropped on a plane: semi-
    implicit Euler per substep, and an impact taken at its time t* within the substep (impact.py:
    Poisson's e on the speed gravity has grown by t*, the position shifted to the piecewise
    motion); a substep without one leaves the body untouched, so it drifts on the parabola
    (integrate.free_drift).  Returns the first rebound's apex sampled at the steps, as the
    simulation is."""
    h, g = dt / substeps, -G
    y, v, apex, rising = drop, 0.0, 0.0, False
    for _ in range(100_000):
        for _ in range(substeps):
            if (y <= 0.0 or y + h * (v + g * h) < 0.0) and v < -threshold:  # the kick's end gap
                t = min(max(y, 0.0) / -v, h)
                v_touch = v + g * t
                v_out = -restitution * v_touch
                shift = t * (v_touch - v_out)
                v = v_out - g * t + g * h
                y = y + h * v + shift
            else:
                v = v + g * h
                y = y + h * v - 0.5 * g * h * h
        rising = rising or v > 0.0
        if rising:
            apex = max(apex, y)
            if v < 0.0:
                return apex
    raise AssertionError("no rebound")


# drops whose last substep before contact closes the gap only through its gravity kick (a band
# g h^2 wide around 1 + phase sqrt(2 g) h: impact.py, engagement on the kicked speed)
KICK_BAND = [1.0 + phase * math.sqrt(2.0 * G) / 240.0 for phase in (0.124, 0.128, 0.132)]


@pytest.mark.parametrize("restitution, half, drop, substeps", [
    (0.3, 0.25, 2.0, 4), (0.5, 0.1, 1.3, 4), (0.8, 0.4, 2.7, 4), (0.65, 0.3, 0.9, 2), (0.45, 0.2, 1.7, 8),
    (0.8, 0.25, KICK_BAND[0], 4), (0.5, 0.25, KICK_BAND[1], 4), (0.8, 0.25, KICK_BAND[2], 4)])
def test_dropped_cube_bounce_equals_its_discrete_twin(restitution, half, drop, substeps, device):
    """The apex of a flat-dropped cube equals the float64 twin of the scheme (semi-implicit Euler
    with impacts at their time of impact), not only e^2 H within the method's error: this pins the
    time-of-impact shift and its gravity term (left out, the apex moved by up to (1 + e) v h and
    (1 + e) g h of speed).  Tolerance: float32 rounding of a height of order H, half an ulp per
    substep over the ~N = 2 sqrt(2 H / g) / h substeps of the fall and rise."""
    b = ModelBuilder(Material(restitution=restitution, friction=0.5))
    b.set_terrain(PlaneTerrain())
    b.add_box((half, half, half), 1.0, position=(0.0, drop + half, 0.0))
    sim = simulator(b, device, substeps=substeps)
    apex, rising = 0.0, False
    for _ in range(600):
        sim.step()
        vy = float(sim.state.body_vel.numpy()[0][1])
        rising = rising or vy > 0
        if rising:
            apex = max(apex, float(sim.state.body_pos.numpy()[0][1]) - half)
            if vy < 0:
                break
    h = sim.config.dt / substeps
    want = discrete_bounce_apex(restitution, drop, sim.config.dt, substeps, sim.config.restitution_threshold)
    substeps_run = 2 * math.sqrt(2 * drop / G) / h
    assert rising
    assert abs(apex - want) < substeps_run * 0.5 * np.spacing(np.float32(drop + half))


@pytest.mark.parametrize("restitution", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("friction", [0.05, 0.1, 0.3])
@pytest.mark.parametrize("speed_x", [3.0, -1.5])
def test_sphere_oblique_impact_follows_coulomb_with_poisson_restitution(restitution, friction, speed_x,
                                                                        device):
    """Zero gravity, a solid sphere hits a plane at (v_t, -5): the normal velocity becomes e * 5, the
    tangential impulse is mu (1 + e) m v_n unless that would reverse the slip, where the sphere
    rolls away (v_t' = 5/7 v_t).  Exact per impact: the tolerance is float32 rounding."""
    vn = 5.0
    b = ModelBuilder(Material(restitution=restitution, friction=friction))
    b.set_terrain(PlaneTerrain())
    b.add_sphere(0.25, 1.0, position=(0.0, 0.26, 0.0), velocity=(speed_x, -vn, 0.0))
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0))
    sim.step(6)
    v = sim.state.body_vel.numpy()[0]
    slip_change = min(friction * (1 + restitution) * vn, 2.0 / 7.0 * abs(speed_x))
    assert v[1] == pytest.approx(restitution * vn, abs=1e-4)
    assert v[0] == pytest.approx(speed_x - math.copysign(slip_change, speed_x), abs=1e-4)


def add_floor(builder, floor):
    """The plane, a static box or a dynamic box 1e6 times heavier than anything dropped on it,
    its top face at y = 0."""
    if floor == "plane":
        builder.set_terrain(PlaneTerrain())
    else:
        builder.add_box((5.0, 0.5, 5.0), 1e6, position=(0.0, -0.5, 0.0), static=floor == "static box")


@pytest.mark.parametrize("floor", ["static box", "heavy box"])
@pytest.mark.parametrize("restitution, friction", [(0.0, 0.1), (0.5, 1.0), (1.0, 0.05), (0.8, 0.3)])
@pytest.mark.parametrize("gap", [0.01, 0.1])
def test_sphere_oblique_impact_on_a_body_follows_coulomb(floor, restitution, friction, gap, device):
    """The same Coulomb-Poisson impact on a box floor, the contact found with the gap still open
    (up to a step's fall).  Friction acts at the sphere's support point: taken midway across the
    found gap, the arm was r + gap / 2 and a sticking ball left 3 to 5 % fast.  Without
    restitution the soft solve takes the impact (the impact stage runs only where e > 0); a
    1e6-times heavier floor moves by m / M of it, under the tolerance.  Tolerance: float32 rounding
    of a converged impact, 1e-4 m/s, and the rolling condition w r = -v_x where the ball sticks."""
    vn, vt, radius = 5.0, 3.0, 0.25
    b = ModelBuilder(Material(restitution=restitution, friction=friction))
    add_floor(b, floor)
    b.add_sphere(radius, 1.0, position=(0.0, radius + gap, 0.0), velocity=(vt, -vn, 0.0))
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0))
    sim.step(6)
    v = sim.state.body_vel.numpy()[-1]
    stick = 2.0 / 7.0 * vt
    slip_change = min(friction * (1 + restitution) * vn, stick)
    assert v[1] == pytest.approx(restitution * vn, abs=1e-4)
    assert v[0] == pytest.approx(vt - slip_change, abs=1e-4)
    if slip_change == stick:
        spin = sim.state.body_angmom.numpy()[-1][2] / (0.4 * radius * radius)
        assert spin * radius == pytest.approx(-v[0], abs=1e-4)


@pytest.mark.parametrize("floor", ["plane", "static box"])
@pytest.mark.parametrize("restitution, friction", [(0.5, 0.1), (0.5, 1.0), (1.0, 0.05)])
@pytest.mark.parametrize("half, mass, gap", [(0.25, 1.0, 0.05), (0.1, 5.0, 0.02)])
def test_cube_landing_flat_while_sliding_turns_only_about_the_slide(floor, restitution, friction, half, mass,
                                                                      gap, device):
    """Zero gravity, a cube (half a, mass m) lands flat at (3, -5) m/s.  By symmetry the friction of
    the four corners is one force F against the slide, applied a below the centre: v_x = 3 - F / m,
    L_z = -a F, no sideways velocity and no spin about any other axis; F = mu (1 + e) m v_n unless
    the bottom face sticks, F = 0.4 m v_t (k_t = 1/m + a^2 / (2/3 m a^2) = 2.5 / m).  The corners'
    Coulomb discs are taken in turn, so this holds only once the friction sweeps have converged
    (two left a sideways drift of 0.3 % of the slide), and on a box floor only with the arms on the
    cube's face (the found point lies midway across the gap: 10 % too much spin).  Tolerance
    1e-4 of the approach speed: float32 rounding of a converged impact."""
    vn, vt = 5.0, 3.0
    b = ModelBuilder(Material(restitution=restitution, friction=friction))
    add_floor(b, floor)
    b.add_box((half, half, half), mass, position=(0.0, half + gap, 0.0), velocity=(vt, -vn, 0.0))
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0))
    sim.step(6)
    v = sim.state.body_vel.numpy()[-1]
    spin = sim.state.body_angmom.numpy()[-1] / (mass * half)  # angular momentum as a speed at the arm
    force = min(friction * (1 + restitution) * vn, 0.4 * vt) * mass
    tolerance = 1e-4 * vn
    assert v[1] == pytest.approx(restitution * vn, abs=tolerance)
    assert v[0] == pytest.approx(vt - force / mass, abs=tolerance)
    assert abs(v[2]) < tolerance
    assert spin[2] == pytest.approx(-force / mass, abs=tolerance)
    assert abs(spin[0]) < tolerance and abs(spin[1]) < tolerance


@pytest.mark.parametrize("count", [2, 3, 5])
@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize("speed", [1.5, 3.0])
def test_row_of_touching_balls_passes_the_strike_down_the_row(count, reverse, speed, device):
    """Newton's cradle in zero gravity, e = 1, mu = 0: impacts propagate as a sequence of two-body
    impacts (impact.py), so the last ball leaves at the striker's speed and the others stop;
    momentum and kinetic energy are kept to float32 rounding.  ``reverse`` numbers the bodies from
    the far end, so the propagation runs against the pair order."""
    b = ModelBuilder(Material(restitution=1.0, friction=0.0))
    order = range(count - 1, -1, -1) if reverse else range(count)
    for k in order:
        b.add_sphere(0.5, 1.0, position=(float(k), 0.0, 0.0), velocity=(speed if k == 0 else 0.0, 0.0, 0.0))
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0))
    ke0 = sim.kinetic_energy()
    sim.step(30)
    x = sim.state.body_pos.numpy()[:, 0]
    vx = sim.state.body_vel.numpy()[:, 0]
    last = int(np.argmax(x))
    assert vx[last] == pytest.approx(speed, rel=1e-4)
    assert np.abs(np.delete(vx, last)).max() < 1e-4 * speed
    assert sim.kinetic_energy() == pytest.approx(ke0, rel=1e-5)


@pytest.mark.parametrize("striker_mass", [0.5, 2.0, 3.0, 10.0])
@pytest.mark.parametrize("speed", [0.3, 3.0])
@pytest.mark.parametrize("count", [3, 5])
def test_row_struck_by_another_mass_keeps_energy_whatever_the_speeds_it_passes_on(striker_mass, speed, count,
                                                                                  device):
    """The cradle above with a striker of another mass, e = 1, mu = 0, zero gravity: the sequence
    of two-body impacts now leaves several balls moving, and the later impacts close slower than
    the strike (a 3 kg striker at 3 m/s: 0.45 m/s).  Each is elastic whatever its speed: with the
    former default restitution_threshold of 1 m/s they were plastic and the row lost 2.5 % (3 kg)
    to 6.7 % (2 kg) of its kinetic energy.  Laws: momentum and kinetic energy kept (float32,
    1e-5), and no ball still closing on the next one (velocities non-decreasing along the row)."""
    b = ModelBuilder(Material(restitution=1.0, friction=0.0))
    b.add_sphere(0.25, striker_mass, position=(-1.0, 0.0, 0.0), velocity=(speed, 0.0, 0.0))
    for k in range(count):
        b.add_sphere(0.25, 1.0, position=(0.5 * k, 0.0, 0.0))
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0))
    ke0, p0 = sim.kinetic_energy(), momentum(sim)
    sim.step(int(60 * (1.0 / speed)) + 60)
    order = np.argsort(sim.state.body_pos.numpy()[:, 0])
    vx = sim.state.body_vel.numpy()[order, 0].astype(float)
    assert sim.kinetic_energy() == pytest.approx(ke0, rel=1e-5)
    assert momentum(sim) == pytest.approx(p0, abs=1e-5 * striker_mass * speed)
    assert np.all(np.diff(vx) >= -1e-4 * speed), vx


def row_of_masses(masses, schedule, device):
    """A ball of masses[0] at 2 m/s striking, 0.1 m off, a row of touching balls of masses[1:]
    (all r 0.2) along x, e = 1, mu = 0, zero gravity, stepped 1 s; returns (v along x in row
    order, the kinetic energy and momentum before, the simulator)."""
    b = ModelBuilder(Material(restitution=1.0, friction=0.0))
    b.set_terrain(NoTerrain())
    b.add_sphere(0.2, float(masses[0]), position=(-0.5, 0.0, 0.0), velocity=(2.0, 0.0, 0.0))
    for k, mass in enumerate(masses[1:]):
        b.add_sphere(0.2, float(mass), position=(0.4 * k, 0.0, 0.0))
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0), pair_schedule=schedule)
    ke0, p0 = sim.kinetic_energy(), momentum(sim)
    sim.step(60)
    order = np.argsort(sim.state.body_pos.numpy()[:, 0])
    return sim.state.body_vel.numpy()[order, 0].astype(float), ke0, p0, sim


# a row an outside check found losing 0.34 % (masses in kg, the striker first)
FOUND_ROW = [0.134431, 0.678272, 4.950031, 0.297532, 2.17909, 0.64657, 0.339086]


@pytest.mark.parametrize("schedule", ["domains", "colors"])
@pytest.mark.parametrize("masses", [
    "heavy, 0.1 light, heavy", "heavy, 0.01 light, heavy", "heavy, 0.003 light, heavy", "found row",
    "random 5", "random 6", "random 7"])
def test_blows_taken_back_and_forth_keep_energy(masses, schedule, device):
    """Rows whose impacts go back and forth: a light ball between heavy ones (mass ratios 10 to
    333) rattles between them, and rows of random masses (log-uniform, 0.1 to 10 kg) pass blows
    both ways.  Each two-body impact keeps energy at e = 1, so the sequence does, however many
    there are (impact.py: the stage's rounds run on while a blow travels).  With a fixed 16 sweeps
    (slab schedule) the light ball at 1/100 lost 30 % of the energy and random rows of 5 to 7 up to 6 %.  Laws as
    above: momentum and energy kept (float32, 1e-5), no ball still closing on the next."""
    if schedule == "domains" and device != "cpu":
        pytest.skip("the slab schedule runs on the CPU only")
    if masses.startswith("heavy"):
        weights = [1.0, 1.0, float(masses.split()[1]), 1.0]
    elif masses == "found row":
        weights = FOUND_ROW
    else:
        count = int(masses.split()[1])
        weights = 10.0 ** np.random.default_rng(count).uniform(-1.0, 1.0, count)
    vx, ke0, p0, sim = row_of_masses(weights, schedule, device)
    assert sim.kinetic_energy() == pytest.approx(ke0, rel=1e-5)
    assert momentum(sim) == pytest.approx(p0, abs=1e-5 * 2.0 * float(weights[0]))
    assert np.all(np.diff(vx) >= -1e-4 * 2.0), vx


@pytest.mark.parametrize("offset", [0.0, 0.1, 0.2])
@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_cube_cube_impact_in_free_space_keeps_momenta_and_energy(offset, friction, device):
    """Two cubes meet face-on (offset 0: the impact is symmetric, so no spin) or off-centre, e = 1.
    Linear and angular momentum about the origin are kept in free space whatever the friction
    (every pair impulse acts at one point for both bodies, pair_geometry.py; float32 rounding of
    positions and velocities is the tolerance).  Without friction the kinetic energy is kept
    (Poisson at convergence, impact.py), with friction it can only drop."""
    b = ModelBuilder(Material(restitution=1.0, friction=friction))
    b.add_box((0.25, 0.25, 0.25), 1.0, position=(-0.5, offset, 0.0), velocity=(2.0, 0.0, 0.0))
    b.add_box((0.25, 0.25, 0.25), 2.0, position=(0.5, 0.0, 0.0), velocity=(-2.0, 0.0, 0.0))
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0))
    p0, l0, ke0 = momentum(sim), angular_momentum_about_origin(sim), sim.kinetic_energy()
    sim.step(30)
    scale = 2.0 * 3.0  # |p| of the bodies
    np.testing.assert_allclose(momentum(sim), p0, atol=1e-5 * scale)
    np.testing.assert_allclose(angular_momentum_about_origin(sim), l0, atol=1e-5 * scale)
    if friction == 0.0:
        assert sim.kinetic_energy() == pytest.approx(ke0, rel=1e-5)
    assert sim.kinetic_energy() <= ke0 * (1 + 1e-5)
    if offset == 0.0:
        assert np.abs(sim.angular_velocity()).max() < 1e-4
    assert sim.state.body_vel.numpy()[0][0] < 0.0  # they did bounce


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("contact_update", ["step", "substep"])
def test_random_impacts_keep_momentum_and_never_gain_energy(seed, contact_update, device):
    """Random spheres and boxes, masses, restitutions and frictions colliding in free space:
    total momentum and angular momentum are kept (to float32 rounding, scaled by the bodies'
    |m v| and positions of order 1 m), and kinetic energy never rises (e <= 1).  Both contact
    update modes."""
    rng = np.random.default_rng(seed)
    b = ModelBuilder(Material(restitution=float(rng.uniform(0, 1)), friction=float(rng.uniform(0, 0.8))))
    for k in range(4):
        pos = (1.1 * k - 1.6, float(rng.uniform(-0.2, 0.2)), float(rng.uniform(-0.2, 0.2)))
        vel = tuple(float(v) for v in rng.uniform(-3, 3, 3))
        mass = float(rng.uniform(0.2, 5.0))
        e = float(rng.uniform(0, 1))
        if k % 2:
            b.add_sphere(float(rng.uniform(0.2, 0.45)), mass, position=pos, velocity=vel, restitution=e)
        else:
            b.add_box(tuple(float(v) for v in rng.uniform(0.15, 0.35, 3)), mass, position=pos, velocity=vel,
                      restitution=e)
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0), contact_update=contact_update)
    p0, l0 = momentum(sim), angular_momentum_about_origin(sim)
    ke = sim.kinetic_energy()
    scale = float(np.abs(sim.model.body_mass[:, None] * sim.state.body_vel.numpy()).sum())
    for _ in range(40):
        sim.step()
        now = sim.kinetic_energy()
        # float32 rounding of the velocities: a few ulp of the energy per step
        assert now <= ke * (1 + 1e-5) + 1e-7
        ke = now
    np.testing.assert_allclose(momentum(sim), p0, atol=1e-4 * scale)
    np.testing.assert_allclose(angular_momentum_about_origin(sim), l0, atol=1e-4 * scale)


@pytest.mark.parametrize("seeds", [range(0, 20), range(20, 40)])
def test_random_pileups_never_gain_energy(seeds, device):
    """Twelve bodies thrown together (cases.pileup_builder): kinetic energy never rises in a step, whatever the
    seed.  An impact's friction, swept against the slip v - (v . n) n, removes energy only with a
    unit normal; a ball's contact with a box turned on to t* by a first-order rotation had a face
    normal up to 4e-4 over unit length, and the friction pushed the pair apart through the normal
    speed it read as slip (seed 4: +2.2 % of the energy in one step; seeds 25 and 36: +0.09 and
    +0.07 %).  Tolerance: float32 rounding of the energy, 1e-5 of it a step (the glancing and
    random-impact tests above)."""
    for seed in seeds:
        sim = simulator(cases.pileup_builder(seed), device, gravity=(0.0, 0.0, 0.0))
        start = previous = sim.kinetic_energy()
        for step in range(60):
            sim.step()
            now = sim.kinetic_energy()
            assert now - previous <= 1e-5 * start, f"seed {seed}, step {step}: {(now - previous) / start:+.2e}"
            previous = now


@pytest.mark.parametrize("shapes", ["sphere-sphere", "sphere-box", "box-box"])
@pytest.mark.parametrize("restitution, friction", [(0.0, 0.5), (0.5, 0.5), (0.5, 0.0), (1.0, 0.9)])
@pytest.mark.parametrize("seed", range(3))
def test_glancing_pair_keeps_angular_momentum(shapes, restitution, friction, seed, device):
    """Two bodies of random size, mass, spin and orientation hit off-centre in free space: the
    angular momentum about the origin is kept whatever the pair, the friction and the gap the
    contact is solved at (each impulse acts at one point for both bodies, pair_geometry.py; with
    the sphere-sphere arms a gap apart, friction turned L by 3e-3 of it).  Tolerance as in
    test_random_impacts_keep_momentum_and_never_gain_energy: float32 rounding, 1e-4 of sum |L_i|."""
    from warp_sim.builder import random_quaternions
    from warp_sim.terrain import NoTerrain

    rng = np.random.default_rng(seed)
    b = ModelBuilder(Material(restitution=restitution, friction=friction))
    b.set_terrain(NoTerrain())
    quats = random_quaternions(rng, 2)
    for k, shape in enumerate(shapes.split("-")):
        args = dict(mass=float(rng.uniform(0.5, 5.0)), position=(1.2 * k - 0.6, *rng.uniform(-0.2, 0.2, 2)),
                    velocity=(3.0 - 6.0 * k, *rng.uniform(-0.5, 0.5, 2)), angular_velocity=tuple(rng.uniform(-3, 3, 3)))
        if shape == "sphere":
            b.add_sphere(float(rng.uniform(0.15, 0.4)), **args)
        else:
            b.add_box(tuple(rng.uniform(0.1, 0.4, 3)), orientation=tuple(quats[k]), **args)
    sim = simulator(b, device, gravity=(0.0, 0.0, 0.0))
    x = sim.state.body_pos.numpy().astype(np.float64)
    p = sim.model.body_mass[:, None] * sim.state.body_vel.numpy().astype(np.float64)
    scale = float(np.abs(np.cross(x, p)).sum() + np.abs(sim.state.body_angmom.numpy()).sum())
    l0 = angular_momentum_about_origin(sim)
    sim.step(60)
    np.testing.assert_allclose(angular_momentum_about_origin(sim), l0, atol=1e-4 * scale)


def step_trip(half: float, step_height: float, step_depth: float, friction: float, gap: float, device,
              impacts: str = "auto"):
    """No gravity, no floor: a cube (half ``half``, 1 kg) sliding at 3 m/s into a static step of
    height ``step_height`` (half depth ``step_depth``), e = 0.  Returns the cube's angular momentum
    about the step's top edge after the impact, over the value before."""
    b = ModelBuilder(Material(friction=friction, restitution=0.0))
    b.set_terrain(NoTerrain())
    b.add_box((step_depth, step_height / 2, 2.0), 1.0, position=(0.3 + step_depth, step_height / 2, 0.0), static=True)
    b.add_box((half, half, half), 1.0, position=(0.3 - half - gap, half, 0.0), velocity=(3.0, 0.0, 0.0))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, impacts=impacts,
                                                  device=device))
    edge = np.array([0.3, step_height, 0.0])
    sim.step(int(gap / 3.0 * 60) + 3)
    pos = sim.state.body_pos.numpy()[-1].astype(float)
    vel = sim.state.body_vel.numpy()[-1].astype(float)
    spin = sim.state.body_angmom.numpy()[-1].astype(float)
    about_edge = spin[2] + np.cross(pos - edge, vel)[2]
    return about_edge / -(3.0 * (half - step_height))


TRIPS = [(0.25, 0.1, 2.0, 1.0, 0.037), (0.25, 0.1, 2.0, 0.0, 0.02), (0.5, 0.2, 2.0, 0.5, 0.03), (0.4, 0.15, 1.0, 1.0, 0.037),
         (0.4, 0.15, 2.0, 1.0, 0.037), (0.4, 0.15, 2.0, 0.0, 0.02), (0.4, 0.1, 4.0, 0.5, 0.015), (0.4, 0.15, 0.5, 0.0, 0.02),
         (0.3, 0.05, 3.0, 0.0, 0.011), (0.3, 0.05, 3.0, 1.0, 0.011), (0.3, 0.03, 3.0, 0.5, 0.011),
         (0.3, 0.05, 3.0, 1.0, 0.02)]
# the inelastic scene's default, where the soft solve meets the impact (SimConfig.impacts): with
# friction on a low step it leaves the face's lower points an impulse (SOFT_SOLVE_TRIP)
SOFT_SOLVE_TRIPS = {(0.3, 0.03, 3.0, 0.5, 0.011)}
# the same coupling leaves this one at the tolerance's edge: 1.07 % too much before friction rows
# acted at the patch's arms (collide/contact_patch.py), 0.99 % since; which side of 1 % it lands on follows
# the sweeps' rounding, so it is expected to fail without being required to
EDGE_TRIPS = {(0.3, 0.05, 3.0, 1.0, 0.011)}


SOFT_SOLVE_TRIP = pytest.mark.xfail(strict=True, reason=(
    "known limitation (README, design notes: impacts), impacts = 'auto' only: an inelastic scene runs no impact stage, "
    "and the soft solve's few sweeps leave the edge's friction and the face's normal impulses coupled through the "
    "cube's turn: the face's lower points keep an impulse, 1.1 to 1.5 % too much angular momentum about the edge; "
    "impacts = 'always' converges them (0.2 %)"))
EDGE_TRIP = pytest.mark.xfail(strict=False, reason=(
    "known limitation (README, design notes: impacts), impacts = 'auto' only: as SOFT_SOLVE_TRIP, at the "
    "tolerance's edge (0.99 % too much angular momentum about the edge)"))


@pytest.mark.parametrize("half, step_height, step_depth, friction, gap, impacts", [
    pytest.param(*trip, impacts, marks=(SOFT_SOLVE_TRIP if trip in SOFT_SOLVE_TRIPS
                                        else EDGE_TRIP if trip in EDGE_TRIPS else ()) if impacts == "auto" else ())
    for trip in TRIPS for impacts in ("auto", "always")])
def test_cube_tripping_on_a_static_step_keeps_angular_momentum_about_the_edge(half, step_height, step_depth, friction,
                                                                           gap, impacts, device):
    """Every impulse of the impact acts on the cube's face at the step (its points at the top edge
    and below it); after it, the cube turns about the top edge and the points below separate, so
    only the edge's impulse remains and the angular momentum about the edge is kept (the textbook
    trip, with or without friction).  No gravity: nothing but rounding acts besides the impact,
    so 1 %.  While the boxes were apart the nearest pair of features, as deep as the face's clip
    to rounding, could take a clip point's slot (box_box.with_nearest): for some step sizes the
    step's top corner on one side gave way to a copy of a bottom corner, 13 to 19 % too much
    angular momentum about the edge.  The scene is inelastic, so at the default the soft solve
    meets the impact; ``impacts = "always"`` runs the impact stage (impact.py) on it."""
    assert step_trip(half, step_height, step_depth, friction, gap, device, impacts) == pytest.approx(1.0, abs=0.01)
