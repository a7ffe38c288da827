"""Leaning columns set down cold, and the substeps the plan picks for them (column_lean.py).

A staircase of boxes whose every support carries the centre of mass above it inside its edge
stands by statics at any margin; soft contacts need a margin of about sqrt(e S) (e the load's
offset, S the springs' static shift), and the substep plan picks the substeps that make it
LEAN_SAFETY = 2 times smaller than the margin.  The calibration columns (unit cubes, 3 to 8
high) are in bench/column_lean.py; the columns here are other ones: random masses, plates, bars,
a column turned about the vertical, one over a static table's edge.
"""

import numpy as np
import pytest

from bench.column_lean import largest_move as bench_largest_move
from bench.column_lean import staircase
from warp_sim import SimConfig, Simulator, cases
from warp_sim.column_sag import plan_substeps

FELL = 0.25  # [m] sideways: a box that moved this far has fallen off its support


def largest_move(sim: Simulator, seconds: float) -> float:
    """The largest sideways move of any dynamic box over ``seconds`` [m] (stops once one fell)."""
    return bench_largest_move(sim, seconds, FELL)


COLUMNS = {
    "5 cubes, masses 0.5-2 kg, 30 mm": dict(count=5, margin=0.03, masses=np.random.default_rng(1).uniform(0.5, 2.0, 5)),
    "6 plates 1 x 0.2 x 0.6 m, 10 mm": dict(count=6, margin=0.01, half=(0.5, 0.1, 0.3)),
    "4 bars 0.4 x 0.8 x 0.4 m, 10 mm": dict(count=4, margin=0.01, half=(0.2, 0.4, 0.2)),
    "4 cubes turned 30 degrees, 20 mm": dict(count=4, margin=0.02, yaw_deg=30.0),
    "3 cubes over a table's edge, 10 mm": dict(count=3, margin=0.01, table=True),
    "6 cubes, masses 0.5-2 kg, 45 mm": dict(count=6, margin=0.045, masses=np.random.default_rng(2).uniform(0.5, 2.0, 6)),
}


@pytest.mark.parametrize("name", list(COLUMNS))
def test_a_leaning_column_set_down_cold_stands_at_the_defaults(name):
    """The defaults' plan raises the substeps and the column stands: no box moves sideways by half
    its margin in 2 s (the swing that tips a column comes within the first second).  Half the margin is the plan's own bound: it keeps sqrt(e S), about the
    swing that setting the column down starts (column_lean.py), at margin / LEAN_SAFETY, and the
    static shift S itself is smaller still (S < sqrt(e S) while S < e).  The same column at the
    requested 4 substeps with the plan off tips past twice its margin, so the check can fail."""
    kwargs = COLUMNS[name]
    sim = Simulator(staircase(**kwargs).finalize("cpu"), SimConfig(sleep=False))
    plan = sim.substep_plan
    assert plan.raised_by == "lean" and plan.substeps > 4, plan.describe()
    assert plan.lean_margin == pytest.approx(kwargs["margin"], rel=1e-3)
    assert plan.lean_need <= plan.lean_margin
    assert largest_move(sim, 2.0) < 0.5 * kwargs["margin"]
    cold = Simulator(staircase(**kwargs).finalize("cpu"), SimConfig(sleep=False, auto_substeps=False))
    assert largest_move(cold, 2.0) > 2.0 * kwargs["margin"]


@pytest.mark.parametrize("count, margin", [(3, -0.02), (5, -0.05)])
def test_a_column_leaning_past_its_support_still_falls(count, margin):
    """Statics says it falls, and no plan holds it up: the check skips a centre of mass outside its
    support."""
    sim = Simulator(staircase(count, margin).finalize("cpu"), SimConfig(sleep=False))
    assert sim.substep_plan.lean_margin == 0.0
    assert largest_move(sim, 3.0) > FELL


def pyramid():
    """Rows of 3, 2 and 1 unit cubes, each upper cube bridging two below (two supports)."""
    from warp_sim import ModelBuilder, PlaneTerrain
    from warp_sim.builder import Material

    b = ModelBuilder(Material(friction=0.5))
    b.set_terrain(PlaneTerrain())
    for row, count in enumerate((3, 2, 1)):
        for k in range(count):
            b.add_box((0.5, 0.5, 0.5), 1.0, position=(k * 1.0 + 0.5 * row - 1.0, 0.5 + row, 0.0))
    return b


@pytest.mark.parametrize("scene", ["upright column", "pyramid", "mixed rain", "column of mixed masses",
                                   "brick on the edge"])
def test_the_plan_leaves_scenes_without_a_leaning_column_alone(scene):
    """An upright column loads every support at its centre (e = 0), a pyramid's bridging cubes have
    two supports each (not checked), a rain starts with no body resting on another, and a brick
    placed half over another (its centre on the edge, as a running-bond wall's end bricks) is in
    neutral balance, which no substeps make stand: none of them gets a substep for leaning."""
    if scene == "upright column":
        model = staircase(10, 0.5).finalize("cpu")  # margin = half width: each cube over the one below
    elif scene == "pyramid":
        model = pyramid().finalize("cpu")
    elif scene == "mixed rain":
        model = cases.terrain_drop(300, "mix", body_contact=True, spacing=0.9).model
    elif scene == "brick on the edge":
        model = staircase(2, 2e-6, half=(0.2, 0.05, 0.1)).finalize("cpu")  # 2 micrometres inside
    else:
        model = staircase(6, 0.5, masses=[5.0, 0.2, 3.0, 1.0, 0.5, 2.0]).finalize("cpu")
    config = SimConfig(sleep=False)
    plan = plan_substeps(model, config)
    assert plan.raised_by != "lean"
    assert plan.substeps == plan_substeps(model, config, lean=[]).substeps
    assert plan.lean_need == 0.0


def test_a_setting_changed_later_keeps_the_leaning_columns_substeps():
    """update_settings plans again from the bodies' current poses, and for the leaning columns the
    scene was set down with: a column that needed more substeps keeps them and stands."""
    kwargs = dict(count=4, margin=0.02)
    sim = Simulator(staircase(**kwargs).finalize("cpu"), SimConfig(sleep=False))
    substeps = sim.substeps
    sim.step(30)
    sim.update_settings(iterations=3)
    assert sim.substeps == substeps > 4
    assert largest_move(sim, 2.0) < 0.5 * kwargs["margin"]


def test_the_need_shrinks_as_the_substep_and_the_plan_asks_for_twice_sqrt_e_s():
    """sqrt(e S) falls as the substep h (S as omega^-2, omega = 2 pi / (4 h)): the plan at 8
    requested substeps needs half the margin it needs at 4."""
    model = staircase(5, 0.04).finalize("cpu")
    at4 = plan_substeps(model, SimConfig(substeps=4, auto_substeps=False))
    at8 = plan_substeps(model, SimConfig(substeps=8, auto_substeps=False))
    assert at8.lean_need == pytest.approx(at4.lean_need / 2.0, rel=1e-9)
    assert at4.lean_need > at4.lean_margin  # 4 substeps are not enough for this column
    chosen = plan_substeps(model, SimConfig())
    # the fewest substeps that meet the need: one fewer would not
    assert chosen.lean_need <= chosen.lean_margin < at4.lean_need * 4 / (chosen.substeps - 1)
