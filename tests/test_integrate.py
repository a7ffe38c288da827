"""Free flight against closed forms; tolerances follow from each integrator's error term."""

import math

import numpy as np
import pytest

from warp_sim import cases

EPS32 = 2.0**-24
INTEGRATORS = ["explicit_euler", "semi_implicit", "verlet", "rk4"]
ROTATIONS = ["quaternion", "matrix", "matrix_cross", "matrix_gram_schmidt"]


def run_projectile(integrator, dt, t_end=1.0, device="cpu"):
    sim = cases.projectile(integrator, dt, device=device)
    steps = int(round(t_end / dt))
    sim.step(steps)
    return sim.state.body_pos.numpy()[0].astype(np.float64), steps


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_projectile_error_and_order(integrator, device):
    """Kick-drift-kick with pre-kick alpha drifts with v_k* = v0 + g h (k + alpha), so
    y_n = y0 + v0 t + g h^2 (n (n - 1) / 2 + alpha n) = exact + (alpha - 1/2) g t h exactly:
    explicit Euler (alpha 0) stays high by |g| t h / 2; Verlet and RK4 (alpha 1/2) are exact for
    constant g; and so is semi_implicit (alpha 1), whose drift of a body no contact touched is the
    parabola's (integrate.free_drift; symplectic Euler's own would land low by |g| t h / 2).
    Horizontal motion is exact for all.  Measured at h and h/2 the first-order error halves
    (order 1); the exact ones must stay under float32 round-off, n steps * a few ulps of |x|
    (bound: 8 n eps |x|max)."""
    t = 1.0
    g = -cases.GRAVITY
    alpha = {"explicit_euler": 0.0, "semi_implicit": 0.5, "verlet": 0.5, "rk4": 0.5}[integrator]  # as drifted
    errors = []
    for dt in (0.02, 0.01):
        pos, steps = run_projectile(integrator, dt, device=device)
        exact = cases.projectile_exact(t)
        roundoff = 8 * steps * EPS32 * np.abs(exact).max()
        predicted = (alpha - 0.5) * g * t * dt
        assert pos[1] - exact[1] == pytest.approx(predicted, abs=roundoff)
        assert abs(pos[0] - exact[0]) <= roundoff
        errors.append(abs(pos[1] - exact[1]))
    if alpha != 0.5:
        assert math.log2(errors[0] / errors[1]) == pytest.approx(1.0, abs=0.01)


def bouncing_ball(floor: str, radius: float, drop: float, substeps: int, device):
    """A ball (1 kg, e = 1, mu 0, sleeping off) dropped ``drop`` onto a plane, the shipped
    Fourier terrain (off a crest's flank, so it bounces sideways) or a static box."""
    from warp_sim import FourierTerrain, ModelBuilder, SimConfig, Simulator
    from warp_sim.builder import Material
    from warp_sim.terrain import NoTerrain, PlaneTerrain

    b = ModelBuilder(Material(restitution=1.0, friction=0.0))
    x, z, ground = 0.3, -0.7, 0.0
    if floor == "plane":
        b.set_terrain(PlaneTerrain())
    elif floor == "terrain":
        terrain = FourierTerrain()
        b.set_terrain(terrain)
        ground = float(terrain.height(x, z))
    else:
        b.set_terrain(NoTerrain())
        b.add_box((20.0, 0.5, 20.0), 1.0, position=(0.0, -0.5, 0.0), static=True)
    b.add_sphere(radius, 1.0, position=(x, ground + radius + drop, z))
    return Simulator(b.finalize(device), SimConfig(substeps=substeps, sleep=False, device=device))


def mechanical_energy(sim) -> float:
    g = -float(sim.config.gravity[1])
    y = sim.state.body_pos.numpy()[:, 1].astype(np.float64)
    dynamic = sim.model.host["body_inv_mass"] > 0
    mass = 1.0 / sim.model.host["body_inv_mass"][dynamic]
    return sim.kinetic_energy() + float((mass * g * y[dynamic]).sum())


@pytest.mark.parametrize("floor", ["plane", "terrain", "static box"])
@pytest.mark.parametrize("radius, drop, substeps", [(0.2, 2.0, 4), (0.1, 0.5, 4), (0.25, 1.0, 1)])
def test_a_ball_bouncing_with_restitution_one_keeps_its_energy(floor, radius, drop, substeps, device):
    """e = 1, mu 0: what the ball loses is only the drift of the substeps in which a contact
    touches it (integrate.free_drift: the others follow the parabola exactly), m g^2 h^2 / 2 each
    (symplectic Euler's drift runs g h^2 / 2 ahead of the parabola).  A contact is active while
    its gap is inside the speculative window, margin + h |v| + h^2 |g|, so per bounce at most
    2 (margin / (h v) + 3) substeps, v the impact speed sqrt(2 g drop).  Without the free drift
    every substep lost that, m g^2 h / 2 a second: 12 % of the 2 m drop's energy in 10 s."""
    sim = bouncing_ball(floor, radius, drop, substeps, device)
    h = sim.substep_dt
    g = -float(sim.config.gravity[1])
    speed = math.sqrt(2.0 * g * drop)
    seconds = 6.0
    bounces = math.ceil(seconds / (2.0 * speed / g))
    per_bounce = 2.0 * (sim.config.speculative_margin / (h * speed) + 3.0) * g * g * h * h / 2.0
    e0 = mechanical_energy(sim)
    low, high = e0, e0
    for _ in range(round(seconds / sim.config.dt)):
        sim.step()
        e = mechanical_energy(sim)
        low, high = min(low, e), max(high, e)
    roundoff = 1e-5 * e0  # float32 positions and speeds of a few m and m/s, summed over the run
    assert e0 - low <= bounces * per_bounce + roundoff, (e0 - low, bounces * per_bounce)
    assert high - e0 <= roundoff, high - e0


ORDER_CASES = [  # (integrator, order, step sizes): larger steps for higher orders keep the error
    ("explicit_euler", 1, (0.01, 0.005)),  # far above float32 round-off (~1e-6) at T = 1 s
    ("semi_implicit", 2, (0.02, 0.01)),  # implicit midpoint of Euler's equations (integrate.py)
    ("verlet", 2, (0.02, 0.01)),
    ("rk4", 4, (0.05, 0.025)),
]


@pytest.mark.parametrize("integrator,order,steps", ORDER_CASES)
def test_rotation_error_order_against_float64_reference(integrator, order, steps, device):
    """Orientation error after 1 s of torque-free tumbling versus a float64 RK4 reference with a
    2000x finer step.  Error = C h^p (1 + O(h |omega|)); with h |omega| <= 0.25 the correction
    moves log2(e(h)/e(h/2)) by at most ~0.3, the tolerance used."""
    t_end = 1.0
    _, ref = cases.tumbling_reference((0.3, 0.4, 5.0), t_end, 2)
    errors = []
    for h in steps:
        sim = cases.tumbling_box(integrator, "quaternion", h, device=device)
        sim.step(int(round(t_end / h)))
        errors.append(np.abs(sim.state.body_rot.numpy()[0] - ref[-1]).max())
    assert math.log2(errors[0] / errors[1]) == pytest.approx(order, abs=0.3)


GROWTH = {  # per-step factor of |column|^2 for R' = R + h f(R) at constant omega, x = h |omega|
    "explicit_euler": lambda x: 1.0 + x * x,  # |1 + i x|^2
    "verlet": lambda x: 1.0 + x**4 / 4.0,  # |1 + i x - x^2/2|^2
    "rk4": lambda x: 1.0 - x**6 / 72.0,  # |sum_{k<=4} (i x)^k / k!|^2
}


@pytest.mark.parametrize("integrator", list(GROWTH))
def test_unrepaired_matrix_drifts_exactly_as_predicted(integrator, device):
    """Spin about a principal axis keeps omega constant even for a scaled R, so the raw matrix
    update multiplies the two columns normal to omega by GROWTH(x) per step: R^T R's largest
    eigenvalue is GROWTH^n.  Checked to 1% of its distance from 1 (where that is above round-off);
    the repaired modes stay orthonormal to float32 round-off (16 ulps, no accumulation)."""
    h, n, omega = 0.01, 300, 5.0
    predicted = GROWTH[integrator](h * omega) ** n - 1.0
    for rotation in ROTATIONS:
        sim = cases.tumbling_box(integrator, rotation, h, omega=(0.0, 0.0, omega), device=device)
        sim.step(n)
        rot = sim.state.body_rot.numpy()[0].astype(np.float64)
        eig = np.linalg.eigvalsh(rot.T @ rot)
        deviation = eig.max() - 1.0 if eig.max() - 1.0 > 1.0 - eig.min() else eig.min() - 1.0
        if rotation == "matrix" and abs(predicted) > 1e-4:
            assert deviation == pytest.approx(predicted, rel=0.01), rotation
        else:
            # repaired each step (or, for raw RK4, |predicted| ~ 7e-8): round-off of one
            # normalisation, a few ulps per entry of R^T R; 16 ulps bound it
            assert abs(deviation) < 16 * EPS32 + abs(predicted), rotation


@pytest.mark.parametrize("rotation", ROTATIONS)
@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_torque_free_drift_per_method(integrator, rotation, device):
    """Over 3 s at h = 0.01 (h|omega| = 0.05): world L is the stored variable and must not move
    (round-off only); the energy error of an order-p method is O((h omega)^p omega T), so it falls
    by orders of magnitude from Euler to RK4.  Bounds: Euler < 0.5 (it gains energy, sign
    checked), Verlet < 2 (h omega)^2 = 5e-3, RK4 < 2 (h omega)^4 + round-off = 1e-5.
    semi_implicit's midpoint rule keeps the energy exactly, so only float32 round-off is left:
    a few roundings per step (normalisation, R^T L), bounded by 4 n eps (measured: 0.03 n eps
    with the quaternion, 0.8 n eps with the raw matrix, whose own round-off grows ~7 eps a step)."""
    h, n = 0.01, 300
    if integrator == "explicit_euler" and rotation == "matrix":
        n = 100  # the raw matrix under Euler grows ~e^(n x^2); keep it finite for the energy check
    sim = cases.tumbling_box(integrator, rotation, h, device=device)
    angmom0 = sim.state.body_angmom.numpy()[0].astype(np.float64)
    e0 = 0.5 * sim.angular_velocity()[0] @ angmom0
    sim.step(n)
    angmom = sim.state.body_angmom.numpy()[0].astype(np.float64)
    e = 0.5 * sim.angular_velocity()[0] @ angmom
    assert np.linalg.norm(angmom - angmom0) <= 4 * EPS32 * np.linalg.norm(angmom0)
    drift = e / e0 - 1.0
    x = h * 5.0
    if integrator == "explicit_euler":
        assert 0.0 < drift < 0.5
    elif integrator == "semi_implicit":
        assert abs(drift) < 4 * n * EPS32
    elif integrator == "verlet":
        assert abs(drift) < 2 * x**2
    else:
        assert abs(drift) < 2 * x**4 + 1e-6


def test_intermediate_axis_flips_and_major_axis_does_not(device):
    """Dzhanibekov: a spin near the intermediate axis (z here) reverses that axis within a few
    seconds; the same perturbation about the major axis (x) stays within its small cone."""
    h, n = 0.01, 600
    flip = cases.tumbling_box("rk4", "quaternion", h, omega=(0.3, 0.4, 5.0), device=device)
    stable = cases.tumbling_box("rk4", "quaternion", h, omega=(5.0, 0.3, 0.4), device=device)
    min_flip, min_stable = 1.0, 1.0
    for _ in range(n):
        flip.step()
        stable.step()
        min_flip = min(min_flip, flip.state.body_rot.numpy()[0][2, 2])
        min_stable = min(min_stable, stable.state.body_rot.numpy()[0][0, 0])
    assert min_flip < -0.9
    assert min_stable > 0.9


# The box: 1 x 2 x 3, mass 1, spun about its middle axis (y) with a small perturbation.
MIDDLE_AXIS_HALF = (0.5, 1.0, 1.5)
MIDDLE_AXIS_OMEGA = (0.01, 5.0, 0.01)


def euler_equations_reference(inertia, angmom_body, t_end, every, sub=8):
    """Float64 RK4 of Lb' = Lb x (I^-1 Lb) (body-frame momentum), sampled every ``every``;
    sub = 8 substeps of 1/480 s give a per-sample error ~ (h omega)^4 ~ 1e-10, far below the
    float32 round-off the simulator works with."""
    inertia = np.asarray(inertia, dtype=np.float64)
    angmom = np.asarray(angmom_body, dtype=np.float64)
    h = every / sub

    def f(lb):
        return np.cross(lb, lb / inertia)

    out = [angmom.copy()]
    for _ in range(int(round(t_end / every))):
        for _s in range(sub):
            k1 = f(angmom)
            k2 = f(angmom + 0.5 * h * k1)
            k3 = f(angmom + 0.5 * h * k2)
            k4 = f(angmom + h * k3)
            angmom = angmom + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(angmom.copy())
    return np.array(out)


def sign_changes(values):
    s = np.sign(values)
    return np.nonzero(s[1:] != s[:-1])[0] + 1  # sample index just after each change


def test_default_integrator_keeps_free_rotation_energy_and_flips(device):
    """What a user gets without choosing (SimConfig defaults: dt 1/60, 4 substeps, the default
    integrator): over 20 s the tumbling box's kinetic energy stays within 1 % (the issue's goal);
    the midpoint rule conserves it exactly, so the bound actually checked is float32 round-off,
    4 eps per substep over n = 4800 substeps (1.1e-3).  The middle axis must flip as often as in
    a float64 reference of Euler's equations, the first flip within one sample (1/60 s; the
    method's own phase error, (h omega)^2 t / 12 ~ 1e-4 s, is far smaller).  Later flip times are
    not compared: this start is within 4e-6 (relative energy) of the separatrix, where float32
    round-off alone shifts them by tenths of a second (rk4 too), while the count has about 2 s of
    margin on either side in the reference."""
    from warp_sim import ModelBuilder, SimConfig, Simulator
    from warp_sim.builder import inertia_box
    from warp_sim.terrain import NoTerrain

    b = ModelBuilder()
    b.set_terrain(NoTerrain())
    b.add_box(MIDDLE_AXIS_HALF, 1.0, angular_velocity=MIDDLE_AXIS_OMEGA)
    cfg = SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, device=device)
    sim = Simulator(b.finalize(device), cfg)
    t_end = 20.0
    steps = int(round(t_end / cfg.dt))
    angmom = sim.state.body_angmom.numpy()[0].astype(np.float64)
    e0 = sim.kinetic_energy()
    middle, worst = [angmom[1]], 0.0
    for _ in range(steps):
        sim.step(check=False)
        worst = max(worst, abs(sim.kinetic_energy() / e0 - 1.0))
        middle.append((sim.state.body_rot.numpy()[0].astype(np.float64).T @ angmom)[1])
    substeps = steps * cfg.substeps
    assert worst < min(0.01, 4 * substeps * EPS32)

    inertia = inertia_box(1.0, MIDDLE_AXIS_HALF)
    ref = euler_equations_reference(inertia, inertia * np.asarray(MIDDLE_AXIS_OMEGA), t_end, cfg.dt)
    flips_ref = sign_changes(ref[:, 1])
    flips_sim = sign_changes(np.array(middle))
    assert len(flips_ref) == 3  # the physics: 3 flips in 20 s
    assert len(flips_sim) == len(flips_ref)
    assert abs(int(flips_sim[0]) - int(flips_ref[0])) <= 1


@pytest.mark.parametrize("spin", [20.0, 60.0])
def test_semi_implicit_energy_at_coarse_steps(spin, device):
    """One substep of 1/60 s with h omega = 1/3 and 1: the Newton solve of the midpoint rule
    (error squared each iteration from (h omega)^2, 4 iterations) still converges, so the energy
    is kept to round-off, 4 n eps for n = 600 steps; explicit Euler would gain a factor
    (1 + (h omega)^2)^n."""
    from warp_sim import ModelBuilder, SimConfig, Simulator
    from warp_sim.terrain import NoTerrain

    b = ModelBuilder()
    b.set_terrain(NoTerrain())
    b.add_box(MIDDLE_AXIS_HALF, 1.0, angular_velocity=(0.01, spin, 0.01))
    sim = Simulator(b.finalize(device), SimConfig(dt=1 / 60, substeps=1, integrator="semi_implicit",
                                                  gravity=(0.0, 0.0, 0.0), sleep=False, device=device))
    e0 = sim.kinetic_energy()
    n = 600
    sim.step(n)
    assert abs(sim.kinetic_energy() / e0 - 1.0) < 4 * n * EPS32
