"""Resting under gravity far past Earth's: the soft contact's hold speed and the sag it implies
(warp_sim/solvers/soft_step.py: push_cap, resting_sag).

At rest a contact must push out at the hold speed g h / a2 (a2 = h omega (2 zeta + h omega),
33.9 at the defaults).  The push cap (max_push_velocity, 3 m/s) used to stop it short above
g = 3 a2 / h = 2.4e4 m/s^2 at 4 substeps of 1/60 s, and bodies sank for ever without a word (a
0.25 m ball 8.8 mm a step at 2.9e4).  Now the cap never falls below twice the hold speed, and
where the sag that speed implies, g h^2 / a2, passes half the smallest body's size, the
Simulator says so and names the substeps that hold.
"""

import re
import warnings

import numpy as np
import pytest

from warp_sim import ModelBuilder, PlaneTerrain, SimConfig, Simulator
from warp_sim.solvers.soft_step import resting_sag

DT = 1.0 / 60.0
SUBSTEPS = 4
H = DT / SUBSTEPS
A2 = (H * 2.0 * np.pi * (1.0 / H) / 4.0) * (2.0 * 10.0 + H * 2.0 * np.pi * (1.0 / H) / 4.0)  # omega = rate / 4
G_CAP = 3.0 * A2 / H  # where the 3 m/s cap used to stop the hold (2.4e4 m/s^2)


def resting(shape: str, size: float, g: float, device, substeps: int = SUBSTEPS) -> Simulator:
    b = ModelBuilder()
    b.set_terrain(PlaneTerrain())
    if shape == "sphere":
        b.add_sphere(size, 1.0, position=(0.3, size, 0.2))
    else:
        b.add_box((size, size, size), 1.0, position=(0.3, size, 0.2))
    return Simulator(b.finalize(device), SimConfig(dt=DT, substeps=substeps, gravity=(0.0, -g, 0.0), device=device))


def settle(sim, size: float):
    """Deepest depth over steps 40 to 120, and the depth's trend a step over them (a fit: a box
    rocks on its corners by about a millimetre, which a difference of two samples would read as
    sinking)."""
    sim.step(40)
    depths = []
    for _ in range(17):
        depths.append(size - float(sim.state.body_pos.numpy()[0, 1]))
        sim.step(5)
    slope = np.polyfit(5.0 * np.arange(len(depths)), depths, 1)[0]
    return max(depths), slope


@pytest.mark.parametrize("factor", [1.5, 3.0, 6.0])
@pytest.mark.parametrize("size", [0.25, 0.5])
@pytest.mark.parametrize("shape", ["sphere", "box"])
def test_a_resting_body_holds_past_the_old_push_cap(device, shape, size, factor):
    g = factor * G_CAP
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # below half its size: no warning is due
        sim = resting(shape, size, g, device)
    depth, trend = settle(sim, size)
    # holding means no steady sinking: the old cap let it go (hold - cap) x dt a step, 9 mm a step
    # and more here; 2e-5 m a step (1.6 mm over the 80 steps fitted) is the rocking's leftover
    assert abs(trend) < 2e-5, (depth, trend)
    assert depth < 0.5 * size
    assert abs(resting_sag((0.0, -g, 0.0), H, None, 10.0) - g * H * H / A2) < 1e-9 * g * H * H


def test_gravity_too_heavy_for_the_substeps_warns_and_the_substeps_it_names_hold(device):
    size, g = 0.25, 1.0e6
    with pytest.warns(RuntimeWarning, match=r"presses resting bodies about 0\.5\d* m .* use \[sim\] substeps >= (\d+)") \
            as record:
        resting("sphere", size, g, device)
    need = int(re.search(r"substeps >= (\d+)", str(record[0].message)).group(1))
    assert need > SUBSTEPS
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sim = resting("sphere", size, g, device, substeps=need)
    depth, trend = settle(sim, size)
    assert abs(trend) < 2e-5 and depth < 0.5 * size


def test_earth_gravity_keeps_the_push_cap_it_is_given():
    from warp_sim.solvers.soft_step import push_cap, soft_coefficients

    soft = soft_coefficients(H, None, 10.0, 0.0)
    assert push_cap(3.0, (0.0, -9.81, 0.0), H, soft) == 3.0  # the default scenes are bit for bit as before
    assert push_cap(3.0, (0.0, -1.0e5, 0.0), H, soft) == pytest.approx(2.0 * 1.0e5 * H / A2, rel=1e-5)


def test_gravity_no_substeps_can_hold_says_so_instead_of_naming_too_many():
    with pytest.warns(RuntimeWarning, match=r"even 4096 substeps \(the most allowed\) would not hold them"):
        resting("sphere", 0.25, 1.0e12, "cpu")
