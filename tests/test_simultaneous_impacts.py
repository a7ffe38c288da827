"""One body struck on two pairs at the same instant (solvers/impact.py: between manifolds the impacts
are taken in sequence, in pair order).

A ball dropped exactly onto the seam of two touching balls, or into a V-groove of two static
boxes, meets both at once.  Whatever the model of a simultaneous impact, a symmetric blow must
give a symmetric outcome, and momentum, and for e = 1 kinetic energy, must be kept.  The laws
hold; the symmetry does not: the first pair in order takes the whole blow and the second is
then separating (README, design notes: impacts in sequence).  Physically any offset between the
two contact times gives that sequential answer, which side depending on which is touched first;
only the exactly simultaneous case, which a user's symmetric scene is, differs.
"""

import math

import numpy as np
import pytest

from warp_sim import ModelBuilder, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.terrain import NoTerrain

SEQUENTIAL = pytest.mark.xfail(strict=True, reason=(
    "known limitation (README, design notes: impacts in sequence): two pairs struck at the same "
    "instant are taken one after the other in pair order, so the first takes the whole blow"))


def seam_drop(restitution, left_first, device, mass_below=1.0):
    """Zero gravity: a ball (r 0.25, 3 m/s down) meets two touching balls below at once, their
    centres 60 degrees off its line of fall on either side.  Returns (velocities, sim) with the
    bodies as (left, right, striker) whatever order they were added in."""
    r = 0.25
    b = ModelBuilder(Material(restitution=restitution, friction=0.0))
    b.set_terrain(NoTerrain())
    for x in ((-r, r) if left_first else (r, -r)):
        b.add_sphere(r, mass_below, position=(x, 0.0, 0.0))
    b.add_sphere(r, 1.0, position=(0.0, math.sqrt(3.0) * r + 0.05, 0.0), velocity=(0.0, -3.0, 0.0))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, gravity=(0.0, 0.0, 0.0), device=device))
    sim.step(10)
    v = sim.state.body_vel.numpy().astype(np.float64)
    if not left_first:
        v = v[[1, 0, 2]]
    return v, sim


@pytest.mark.parametrize("left_first", [True, False], ids=["left_first", "right_first"])
@pytest.mark.parametrize("restitution, mass_below", [(1.0, 1.0), (0.5, 1.0), (1.0, 3.0), (0.8, 0.5)])
def test_a_ball_striking_two_at_once_keeps_momentum_and_energy(restitution, mass_below, left_first, device):
    """Momentum to float32 round-off (1e-5 of m v); kinetic energy kept for e = 1 (to the impact
    stage's convergence, 1e-3 of it) and never gained for e < 1."""
    v, sim = seam_drop(restitution, left_first, device, mass_below)
    mass = np.array([mass_below, mass_below, 1.0])
    momentum = (mass[:, None] * v).sum(axis=0)
    np.testing.assert_allclose(momentum, [0.0, -3.0, 0.0], atol=3e-5)
    energy = 0.5 * float((mass * (v**2).sum(axis=1)).sum())
    if restitution == 1.0:
        assert energy == pytest.approx(4.5, rel=1e-3)
    else:
        assert energy <= 4.5 * (1 + 1e-6)


@SEQUENTIAL
@pytest.mark.parametrize("left_first", [True, False], ids=["left_first", "right_first"])
@pytest.mark.parametrize("restitution", [1.0, 0.5])
def test_a_ball_striking_two_at_once_gives_a_symmetric_outcome(restitution, left_first, device):
    """The striker leaves along its line of fall and the two struck balls mirror each other (1e-3
    of the 3 m/s: the impact stage's convergence).  Measured: the striker leaves 0.65 m/s sideways
    (e = 1) and one lower ball takes twice the other's speed."""
    v, _ = seam_drop(restitution, left_first, device)
    assert abs(v[2, 0]) < 3e-3
    np.testing.assert_allclose(v[0] * [-1.0, 1.0, 1.0], v[1], atol=3e-3)


@SEQUENTIAL
@pytest.mark.parametrize("half_angle", [20.0, 40.0])
def test_a_ball_dropped_into_a_v_groove_bounces_straight_up(half_angle, device):
    """Two static boxes whose faces lean ``half_angle`` off horizontal form a V; a ball (r 0.25)
    falling 0.3 m into it (e = 1, mu = 0) meets both faces at once and must leave straight up
    as fast as it came.  Measured: it leaves off one face only, 1.55 m/s sideways at 20 degrees."""
    r, drop, theta = 0.25, 0.3, math.radians(half_angle)
    b = ModelBuilder(Material(restitution=1.0, friction=0.0))
    b.set_terrain(NoTerrain())
    half = (1.0, 0.1, 0.5)
    rest = np.array([0.0, 1.0, 0.0])  # where the ball touches both faces
    for side in (1, -1):
        normal = np.array([side * math.sin(theta), math.cos(theta), 0.0])
        touch = rest - r * normal
        along = np.array([math.cos(theta), -side * math.sin(theta), 0.0])
        along = along if along[0] * touch[0] > 0 else -along  # away from the groove's middle
        inner = 0.9 * r * math.tan(theta)  # the face stops just short of the middle
        centre = touch - half[1] * normal + along * (half[0] - inner)
        b.add_box(half, 1.0, position=tuple(centre), static=True,
                  orientation=(0.0, 0.0, math.sin(-side * theta / 2), math.cos(-side * theta / 2)))
    b.add_sphere(r, 1.0, position=tuple(rest + [0.0, drop, 0.0]))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    speed_in = math.sqrt(2 * 9.81 * drop)
    for _ in range(40):
        sim.step(1)
        v = sim.state.body_vel.numpy()[-1]
        if v[1] > 0.0:
            break
    assert v[1] > 0.0
    assert abs(v[0]) < 1e-2 * speed_in
