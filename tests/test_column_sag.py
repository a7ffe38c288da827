"""Soft-contact sag of columns and the substeps auto_substeps picks against it (column_sag.py).

A soft contact of frequency omega holding a weight W sags W / (m_pair omega^2); down a column the
sags add.  These tests check the estimate against that series in closed form, check that the
column search finds a column wherever the grid falls, and check the simulated columns against the
estimate: the sag is the spring's equilibrium, so the measured sink must equal it (to the 5 % the
other stack tests allow for the first second's transient), and with the chosen substeps stay under
the 1 cm of a standing stack.
"""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from warp_sim import ModelBuilder, PlaneTerrain, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.column_sag import (CALIBRATION_THICKNESS, LANDING_RESIDUAL, MAX_AUTO_SUBSTEPS, contact_omega,
                                 plan_substeps)

G = 9.81


def column(masses, half=0.5, x=0.0, device="cpu", **config):
    b = ModelBuilder(Material(friction=0.5))
    b.set_terrain(PlaneTerrain())
    for k, m in enumerate(masses):
        b.add_box((half, half, half), float(m), position=(x, half + 2 * half * k, 0.0))
    config.setdefault("sleep", False)
    return Simulator(b.finalize(device), SimConfig(device=device, **config))


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
def test_column_at_the_defaults_sinks_by_the_estimate_and_stands(masses, device):
    """At 4 substeps these sag 27.6 and ~16 mm; the defaults run the substeps that keep the sag
    under 7.5 mm, and the column then stands: the top sinks by the estimate and moves sideways
    under 1 cm."""
    sim = column(masses, device=device)
    assert sim.substep_plan.sag_requested > 0.01 and sim.substep_plan.sag <= sim.config.column_sag
    top0 = sim.state.body_pos.numpy()[-1].copy()
    sim.step(60)
    settled = sim.state.body_pos.numpy()[-1].copy()
    assert top0[1] - settled[1] == pytest.approx(sim.substep_plan.sag, rel=0.05)
    sim.step(180)
    top = sim.state.body_pos.numpy()[-1]
    assert top0[1] - top[1] < 0.01
    assert math.hypot(*(top - settled)[[0, 2]]) < 0.01


def box_column(halves, masses, yaw_step=0.0, on_side=False, device="cpu", **config):
    """Boxes of half extents ``halves`` stacked face on face, each turned ``yaw_step`` further
    about the vertical than the one below; ``on_side`` lays each on a side face (turned a
    quarter about x, so its local z is vertical)."""
    b = ModelBuilder(Material(friction=0.5))
    b.set_terrain(PlaneTerrain())
    y = 0.0
    for k, (half, m) in enumerate(zip(halves, masses)):
        if on_side:
            up_half, q = half[2], (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4))
        else:
            up_half, q = half[1], (0.0, math.sin(yaw_step * k / 2), 0.0, math.cos(yaw_step * k / 2))
        b.add_box(half, float(m), position=(0.0, y + up_half, 0.0), orientation=q)
        y += 2.0 * up_half
    config.setdefault("sleep", False)
    return Simulator(b.finalize(device), SimConfig(device=device, **config))


def sink_after_a_second(sim) -> float:
    top0 = sim.state.body_pos.numpy()[-1].copy()
    sim.step(60)
    return float(top0[1] - sim.state.body_pos.numpy()[-1][1])


RNG = np.random.default_rng(11)
BOX_COLUMNS = {
    "plates 0.6 x 0.2 x 0.6": ([(0.3, 0.1, 0.3)] * 15, np.ones(15)),
    "flat boxes, random masses": ([(0.5, 0.25, 0.5)] * 12, np.exp(RNG.uniform(-1.0, 1.0, 12))),
    "tall boxes": ([(0.25, 0.5, 0.25)] * 12, np.ones(12)),
    "faces shrinking upwards": ([(0.6 - 0.03 * k, 0.2, 0.6 - 0.03 * k) for k in range(12)], np.ones(12)),
    "oblong plates": ([(0.3, 0.1, 0.5)] * 15, np.exp(RNG.uniform(-0.5, 0.5, 15))),
}


@pytest.mark.parametrize("name", list(BOX_COLUMNS))
@pytest.mark.parametrize("on_side", [False, True], ids=["flat", "on a side face"])
def test_box_columns_sink_by_the_estimate_of_their_corners(name, on_side):
    """A box's face pushes back with the effective masses of its four corners, which a flat box
    turns more easily than a cube (column_sag.contact_masses): the column sinks by that estimate,
    whatever the boxes' proportions, masses and the face they lie on.  Fixed substeps (8, or 4 for
    the stiff tall boxes) keep the sag large enough to measure; 5 % as in the tests above."""
    halves, masses = BOX_COLUMNS[name]
    if on_side:  # the same proportions lying on a side face: swap the vertical extent into z
        halves = [(hx, hz, hy) for hx, hy, hz in halves]
    substeps = 4 if name == "tall boxes" and not on_side else 8
    sim = box_column(halves, masses, on_side=on_side, auto_substeps=False, substeps=substeps)
    assert sim.substep_plan.column_bodies == len(halves)
    assert sink_after_a_second(sim) == pytest.approx(sim.substep_plan.sag, rel=0.05)


@pytest.mark.parametrize("yaw_step", [0.5, math.pi / 4, math.pi / 2])
def test_boxes_turned_on_each_other_sink_no_further_than_estimated(yaw_step):
    """Turned boxes touch over less than the smaller face the estimate assumes, with corners
    nearer the centres: stiffer, so the estimate is an upper bound (measured 0.6 to 0.9 of it)."""
    sim = box_column([(0.3, 0.1, 0.5)] * 15, np.ones(15), yaw_step, auto_substeps=False, substeps=8)
    assert 0.0 < sink_after_a_second(sim) <= sim.substep_plan.sag


def test_a_column_of_plates_stands_at_the_defaults(device):
    """25 plates of 0.6 x 0.2 x 0.6 m: taken for cubes the plan ran 10 substeps and the column
    sank 11 mm.  Now the plan sees their corners and the top sinks by the estimate, under the
    7.5 mm column_sag budget and the 1 cm of a standing stack, and stays put sideways."""
    sim = box_column([(0.3, 0.1, 0.3)] * 25, np.ones(25), device=device)
    assert sim.substep_plan.sag <= sim.config.column_sag
    top0 = sim.state.body_pos.numpy()[-1].copy()
    sim.step(240)
    top = sim.state.body_pos.numpy()[-1]
    assert top0[1] - top[1] == pytest.approx(sim.substep_plan.sag, rel=0.05)
    assert top0[1] - top[1] < 0.01 and math.hypot(*(top - top0)[[0, 2]]) < 0.01


@pytest.mark.parametrize("side, count, masses", [(0.01, 10, "equal"), (0.02, 10, "equal"), (0.05, 10, "equal"),
                                                (0.01, 7, "random"), (0.03, 8, "random")])
def test_a_column_of_small_cubes_stands_at_the_defaults(side, count, masses, device):
    """Cubes of 1 to 5 cm stacked on the plane, masses equal or random (0.2 to 5 kg), sleeping off.
    A column's sag is a length fixed by g / omega^2 whatever its bodies' size, so the 7.5 mm
    budget alone let ten 1 cm cubes sag 69 % of a cube at the 4 substeps it planned, and the
    column fell over (5 cm cubes sank 13 % of a cube).  The plan scales the budget by the median
    body's thickness over the 0.2 m it holds for (column_sag.plan_budgets): the top sinks by the
    estimate, at most 3.75 % of a cube, and moves sideways under 1 % of a cube (float32 positions
    of a 1 cm column round at 1e-9 m)."""
    rng = np.random.default_rng(count)
    weights = np.ones(count) if masses == "equal" else rng.uniform(0.2, 5.0, count)
    sim = box_column([(side / 2,) * 3] * count, weights, device=device)
    plan = sim.substep_plan
    assert plan.budget == pytest.approx(sim.config.column_sag * side / CALIBRATION_THICKNESS)
    assert plan.sag <= plan.budget
    top0 = sim.state.body_pos.numpy()[-1].astype(float)
    sim.step(180)
    top = sim.state.body_pos.numpy()[-1].astype(float)
    assert top0[1] - top[1] == pytest.approx(plan.sag, rel=0.05)
    assert math.hypot(*(top - top0)[[0, 2]]) < 0.01 * side


# Landing on a pile ---------------------------------------------------------------------------

def layered_column(count: int, gap: float, shape: str = "plate", seed: int = 0, tilt: float = 0.0,
                   device="cpu", **config):
    """``count`` bodies one above the other, ``gap`` apart between their volume-equivalent
    spheres (column_sag.volume_radius), the lowest resting on a plane; ``tilt`` turns each by a
    random angle up to that many radians about a random horizontal axis."""
    rng = np.random.default_rng(seed)
    b = ModelBuilder(Material(friction=0.6, restitution=0.1))
    b.set_terrain(PlaneTerrain())
    half = {"plate": (0.3, 0.1, 0.3), "sheet": (0.3, 0.06, 0.3), "cube": (0.25, 0.25, 0.25)}
    y = 0.0
    for k in range(count):
        kind = shape if shape != "mixed" else ("sphere" if k % 2 else "plate")
        if kind == "sphere":
            r = 0.2
        else:
            h = half[kind]
            r = float(np.cbrt(np.prod(h)))
        y += r if k == 0 else gap + r
        axis = rng.normal(size=3)
        axis[1] = 0.0
        axis /= np.linalg.norm(axis)
        angle = rng.uniform(-tilt, tilt)
        q = (*(math.sin(angle / 2) * axis), math.cos(angle / 2))
        if kind == "sphere":
            b.add_sphere(0.2, 1.0, position=(0.0, y, 0.0))
        else:
            b.add_box(h, 1.0, position=(0.0, y, 0.0), orientation=q)
        y += r
    config.setdefault("sleep", False)
    return Simulator(b.finalize(device), SimConfig(device=device, **config))


@pytest.mark.parametrize("count, gap, shape", [(3, 0.5, "plate"), (5, 0.3, "cube"), (10, 0.45, "plate"),
                                               (7, 0.8, "mixed")])
def test_landing_speed_is_the_gaps_summed_up_a_column_and_sets_the_substeps(count, gap, shape):
    """The top body lands on the pile at sqrt(2 g (count - 1) gap) (the bottom body's own drop is
    the terrain's, not a landing on the pile), and auto_substeps runs the fewest substeps, at
    least the 4 asked, that keep LANDING_RESIDUAL v dt / n under landing_depth."""
    sim = layered_column(count, gap, shape)
    plan = sim.substep_plan
    v = math.sqrt(2 * G * (count - 1) * gap)
    assert plan.landing_speed == pytest.approx(v, rel=1e-5)
    need = lambda n: LANDING_RESIDUAL * v * sim.config.dt / n  # noqa: E731
    n = plan.substeps
    assert need(n) <= sim.config.landing_depth and (n == 4 or need(n - 1) > sim.config.landing_depth)
    assert n == max(4, math.ceil(LANDING_RESIDUAL * v * sim.config.dt / sim.config.landing_depth - 1e-9))
    if n > 4:
        assert "landing" in plan.describe()


def test_no_landing_without_a_pile_to_land_on():
    # touching: nothing falls (the float32 positions leave gaps of ~1e-7 m: no landing worth a
    # substep); two bodies: a two-body impact, which the impact sweeps solve exactly
    assert column(np.ones(6), auto_substeps=False).substep_plan.landing_transient() < 1e-6
    assert layered_column(2, 3.0).substep_plan.landing_speed == 0.0
    assert layered_column(3, 3.0).substep_plan.landing_speed > 0.0
    # no gravity, no body contact: nothing lands
    assert layered_column(6, 1.0, gravity=(0.0, 0.0, 0.0)).substep_plan.substeps == 4
    assert layered_column(6, 1.0, body_contact=False).substep_plan.substeps == 4
    # off: exactly as asked, and said to be over the budget
    plan = layered_column(10, 0.45, auto_substeps=False).substep_plan
    assert plan.substeps == 4 and "still over the budget" in plan.describe()


def test_a_jittered_layer_missing_from_its_column_is_not_a_long_fall():
    """A layer's body shifted out of its column leaves a gap of two layers there; counted as it is
    the column would fall further than any real one (the rain of mixed_rain.toml: 7.4 m for 4.9).
    A gap over twice the scene's median counts as two median gaps."""
    b = ModelBuilder(Material(friction=0.6))
    b.set_terrain(PlaneTerrain())
    for cx in range(3):
        for layer in range(6):
            shift = 0.45 if (cx == 1 and layer in (2, 3)) else 0.0
            b.add_box((0.25, 0.25, 0.25), 1.0, position=(3.0 * cx + shift, 0.25 + 1.0 * layer, 0.0))
    sim = Simulator(b.finalize(), SimConfig(sleep=False))
    # full columns: 5 gaps of 0.5 m
    assert sim.substep_plan.landing_speed == pytest.approx(math.sqrt(2 * G * 2.5), rel=1e-5)


@pytest.mark.parametrize("count, gap, shape, seed", [(10, 0.5, "plate", 0), (10, 0.5, "plate", 2),
                                                     (10, 0.6, "sheet", 3), (10, 0.5, "mixed", 4)])
def test_a_layered_column_lands_within_the_landing_depth(count, gap, shape, seed, device):
    """The physical check of the plan: columns of ten plates, sheets, or plates and balls at
    random orientations rained on themselves at the planned substeps; the deepest body-body
    penetration, found after every step, stays under landing_depth.  (At the 4 substeps asked,
    the second and third went 13.0 and 12.2 mm deep; planned, all four stay under 7.5 mm.)"""
    sim = layered_column(count, gap, shape, seed, tilt=math.pi, device=device)
    assert sim.substeps > 4
    deepest = 0.0
    for _ in range(100):
        sim.step(1)
        deepest = max(deepest, sim.pairs.probe_depth(sim.state, sim.probe_contacts()))
    assert deepest < sim.config.landing_depth, f"{deepest * 1000:.1f} mm ({sim.substep_plan.describe()})"


def test_the_plan_says_which_budget_raised_the_substeps():
    assert column(np.ones(20)).substep_plan.reason().startswith("a column would sag")
    assert layered_column(10, 0.5).substep_plan.reason().startswith("a landing on a pile would sink")
    assert column(np.ones(3)).substep_plan.reason() == ""
    # the GUI's switch reaches the plan
    sim = layered_column(10, 0.5)
    sim.update_settings(auto_substeps=False)
    assert sim.substeps == 4 and sim.substep_plan.reason() == ""


def test_the_full_size_plate_rain_lands_within_the_landing_depth_at_the_defaults(device):
    """The layout of the plate rain (360 plates in 10 layers, bench/audit_stacks.thin_box_rains)
    that went deepest at the 7 substeps the former landing constant planned, 13.8 mm: at the
    substeps planned now (LANDING_RESIDUAL, the worst measured over 15 layouts) its deepest
    body-body pair, found after every step over 5 s, stays under landing_depth."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    from bench.audit_stacks import rain_depth, thin_box_rains

    _, plates = thin_box_rains()
    deepest, _ = rain_depth({**plates, "sim": {**plates["sim"], "seed": 9}}, 5.0, 1, device=device)
    assert deepest < SimConfig().landing_depth, deepest  # the scene leaves landing_depth at its default
