"""Soft-contact sag of columns and the substeps auto_substeps picks against it (column_sag.py).

A soft contact of frequency omega holding a weight W sags W / (m_pair omega^2); down a column the
sags add.  These tests check the estimate against that series in closed form, check that the
column search finds a column wherever the grid falls, and check the simulated columns against the
estimate: the sag is the spring's equilibrium, so the measured sink must equal it (to the 5 % the
other stack tests allow for the first second's transient), and with the chosen substeps stay under
the 1 cm of a standing stack.
"""

import math

import numpy as np
import pytest

from warp_sim import ModelBuilder, PlaneTerrain, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.column_sag import MAX_AUTO_SUBSTEPS, contact_omega, plan_substeps

G = 9.81


def column(masses, half=0.5, x=0.0, **config):
    b = ModelBuilder(Material(friction=0.5))
    b.set_terrain(PlaneTerrain())
    for k, m in enumerate(masses):
        b.add_box((half, half, half), float(m), position=(x, half + 2 * half * k, 0.0))
    config.setdefault("sleep", False)
    return Simulator(b.finalize(), SimConfig(**config))


def series(masses) -> float:
    """sum over contacts of W_above / m_pair (the ground contact: the bottom body's own mass)."""
    total = 0.0
    for k, m in enumerate(masses):
        above = float(np.sum(masses[k:]))
        pair = m if k == 0 else m * masses[k - 1] / (m + masses[k - 1])
        total += above / pair
    return total


@pytest.mark.parametrize("count", [2, 7, 40])
def test_unit_cube_column_sags_count_squared_g_over_omega_squared(count):
    sim = column(np.ones(count), auto_substeps=False)
    h = sim.substep_dt
    assert sim.substep_plan.column_bodies == count
    assert sim.substep_plan.sag == pytest.approx(count**2 * G / contact_omega(h, None) ** 2, rel=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_estimate_is_the_series_for_any_masses_and_wherever_the_grid_lines_fall(seed):
    rng = np.random.default_rng(seed)
    masses = np.exp(rng.uniform(np.log(0.1), np.log(10.0), int(rng.integers(3, 15))))
    # on a grid line of either binning, or anywhere: the column must be found whole
    x = float(rng.choice([0.0, 0.5, 1.0, -1.5, rng.uniform(-3, 3)]))
    sim = column(masses, x=x, auto_substeps=False)
    assert sim.substep_plan.column_bodies == len(masses)
    expected = G * series(masses) / contact_omega(sim.substep_dt, None) ** 2
    # the model keeps inverse masses in float32: each mass is off by up to 6e-8 of itself
    assert sim.substep_plan.sag == pytest.approx(expected, rel=1e-6)


def test_auto_picks_the_fewest_substeps_that_meet_the_budget():
    model_sim = column(np.ones(20), auto_substeps=False)
    config = SimConfig(sleep=False)
    plan = plan_substeps(model_sim.model, config)
    dt, budget = config.dt, config.column_sag
    sag = lambda n: 400 * G / contact_omega(dt / n, None) ** 2  # noqa: E731
    assert sag(plan.substeps) <= budget < sag(plan.substeps - 1)
    assert plan.substeps > config.substeps
    # a capped stiffness cannot be substepped away: the cap is reached and said
    capped = plan_substeps(model_sim.model, SimConfig(sleep=False, contact_hertz=30.0))
    assert capped.substeps == MAX_AUTO_SUBSTEPS and capped.sag > budget
    assert "still over the budget" in capped.describe()
    # nothing to hold up: as configured
    assert plan_substeps(model_sim.model, SimConfig(gravity=(0.0, 0.0, 0.0))).substeps == 4
    assert plan_substeps(model_sim.model, SimConfig(body_contact=False)).substeps == 4
    assert plan_substeps(model_sim.model, SimConfig(auto_substeps=False)).substeps == 4


def test_settings_changes_plan_again():
    sim = column(np.ones(20))
    assert sim.substeps == sim.substep_plan.substeps > 4
    sim.update_settings(auto_substeps=False)
    assert sim.substeps == 4 and sim.substep_dt == pytest.approx(sim.config.dt / 4)
    sim.update_settings(auto_substeps=True, column_sag=0.03)
    assert sim.substeps == 4  # 27.6 mm at 4 substeps is within 3 cm
    with pytest.raises(ValueError, match="column_sag"):
        sim.update_settings(column_sag=-1.0)


@pytest.mark.parametrize("masses", [np.ones(20), np.exp(np.random.default_rng(7).uniform(np.log(0.2), np.log(5.0), 12))],
                         ids=["20 unit cubes", "12 random masses"])
def test_column_at_the_defaults_sinks_by_the_estimate_and_stands(masses):
    """At 4 substeps these sag 27.6 and ~16 mm; the defaults run the substeps that keep the sag
    under 7.5 mm, and the column then stands: the top sinks by the estimate and moves sideways
    under 1 cm."""
    sim = column(masses)
    assert sim.substep_plan.sag_requested > 0.01 and sim.substep_plan.sag <= sim.config.column_sag
    top0 = sim.state.body_pos.numpy()[-1].copy()
    sim.step(60)
    settled = sim.state.body_pos.numpy()[-1].copy()
    assert top0[1] - settled[1] == pytest.approx(sim.substep_plan.sag, rel=0.05)
    sim.step(180)
    top = sim.state.body_pos.numpy()[-1]
    assert top0[1] - top[1] < 0.01
    assert math.hypot(*(top - settled)[[0, 2]]) < 0.01
