"""Push-out: it gains no kinetic energy (issue 12: kinetic energy never rises through a contact),
and a contact deeper than any load could sag it is pushed back within the step.

The soft solve pushes a penetrating body out with a bias velocity, and the relax sweeps without
bias take that velocity back (soft_step.py).  A relax that gives back only part of it leaves the
body moving away from a contact it was merely resting in: a cube started 2 cm into the ground with
no gravity drifted off at 0.077 m/s, and a cube 2 cm into a heavier one at 0.017 m/s.  The relax
now walks each body's terrain rows and each pair's points until a pass changes no point's
velocity by more than ``convergence_tolerance`` (1e-5 m/s); Gauss-Seidel's error after that is
a small multiple of its last change, so what is left is under 10 x 1e-5 m/s.
"""

import math

import numpy as np
import pytest
import warp as wp

from warp_sim import ModelBuilder, NoTerrain, PlaneTerrain, SimConfig, cases
from warp_sim.builder import Material
from warp_sim.simulator import Simulator
from warp_sim.solvers.soft_step import RELAX_PASSES, soft_coefficients, sweep_tolerance

wp.config.quiet = True
LEFT_SPEED = 10 * SimConfig().convergence_tolerance


def overlapping(depth: float, partner: str, ratio: float, half):
    """A 1 kg box ``half`` overlapping its partner by ``depth``: the ground ("terrain"), a free box of
    mass ``ratio`` without terrain ("box"), a static box lying on the plane ("static box"), or a
    dynamic box of mass ``ratio`` resting on the plane ("box on the ground")."""
    b = ModelBuilder(Material(restitution=0.0, friction=0.5))
    if partner == "box":
        b.set_terrain(NoTerrain())
        b.add_box(half, ratio, position=(0.0, 0.0, 0.0))
        b.add_box(half, 1.0, position=(0.0, 2 * half[1] - depth, 0.0))
        return b
    b.set_terrain(PlaneTerrain())
    floor = 0.0
    if partner == "static box":
        b.add_box((2.0, 0.25, 2.0), 1.0, position=(0.0, 0.25, 0.0), static=True)
        floor = 0.5
    elif partner == "box on the ground":
        b.add_box(half, ratio, position=(0.0, half[1], 0.0))
        floor = 2 * half[1]
    b.add_box(half, 1.0, position=(0.0, floor + half[1] - depth, 0.0))
    return b


def gravity_bound(config: SimConfig) -> float:
    """10 tolerances under gravity: Gauss-Seidel's error after the last pass is a small multiple of
    that pass's change, which is under sweep_tolerance (soft_step.py)."""
    h = config.dt / config.substeps
    return 10 * sweep_tolerance(config.convergence_tolerance, config.convergence_gravity_share, config.gravity, h)


def fastest_over(sim: Simulator, steps: int) -> float:
    """The fastest body's speed, the largest over ``steps`` steps."""
    fastest = 0.0
    for _ in range(steps):
        sim.step()
        fastest = max(fastest, float(np.linalg.norm(sim.state.body_vel.numpy(), axis=1).max()))
    return fastest


@pytest.mark.parametrize("pair_schedule", ["domains", "colors"])
@pytest.mark.parametrize("depth", [0.005, 0.012, 0.02])
@pytest.mark.parametrize("partner, ratio, half", [
    ("terrain", 1.0, (0.5, 0.5, 0.5)), ("terrain", 1.0, (0.3, 0.1, 0.3)),
    ("box", 1.0, (0.5, 0.5, 0.5)), ("box", 10.0, (0.5, 0.5, 0.5)), ("box", 3.0, (0.3, 0.1, 0.3))])
def test_push_out_leaves_no_speed_behind(pair_schedule, depth, partner, ratio, half, device):
    """No gravity, a box overlapping the ground or another box by ``depth``: after each of four
    steps every body is back at rest (the push moved it, the relax took the push speed back)."""
    if pair_schedule == "domains" and device != "cpu":
        pytest.skip("the slab schedule runs on the CPU only")
    b = overlapping(depth, partner, ratio, half)
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False,
                                                  allow_initial_overlap=True, pair_schedule=pair_schedule,
                                                  device=device))
    for _ in range(4):
        sim.step()
        speed = np.linalg.norm(sim.state.body_vel.numpy(), axis=1).max()
        assert speed < LEFT_SPEED
    # and the push did move it out
    pos = sim.state.body_pos.numpy()
    gap = pos[-1, 1] - (half[1] if partner == "terrain" else pos[0, 1] + 2 * half[1])
    assert gap > -depth + 1e-3


@pytest.mark.parametrize("relax_passes", [RELAX_PASSES, 1])
@pytest.mark.parametrize("depth", [0.005, 0.012, 0.02])
@pytest.mark.parametrize("floor, half", [("terrain", (0.5, 0.5, 0.5)), ("terrain", (0.3, 0.1, 0.3)),
                                         ("static box", (0.5, 0.5, 0.5)), ("static box", (0.3, 0.1, 0.3))])
def test_push_out_under_gravity_leaves_under_ten_tolerances(relax_passes, depth, floor, half, device):
    """Under gravity the passes stop at sweep_tolerance, the larger of convergence_tolerance and
    convergence_gravity_share |g| h (4.1e-4 m/s at the defaults; soft_step.py says why).  As in the
    zero-gravity test, Gauss-Seidel's error after the last pass is a small multiple of that pass's
    change, so a box pushed out of the ground or out of a static box, then resting there, moves
    under 10 tolerances in every one of eight steps.  A single relax pass (Box2D's) is shown
    failing the same bound."""
    config = SimConfig(sleep=False, allow_initial_overlap=True, relax_passes=relax_passes, device=device)
    bound = gravity_bound(config)
    fastest = fastest_over(Simulator(overlapping(depth, floor, 1.0, half).finalize(device), config), 8)
    if relax_passes == 1:
        assert fastest > bound
    else:
        assert fastest < bound


@pytest.mark.parametrize("pair_schedule", ["domains", "colors"])
@pytest.mark.parametrize("depth, ratio, half", [
    (0.005, 1.0, (0.5, 0.5, 0.5)), (0.02, 1.0, (0.5, 0.5, 0.5)), (0.02, 10.0, (0.5, 0.5, 0.5)),
    (0.02, 100.0, (0.25, 0.25, 0.25)), (0.02, 3.0, (0.3, 0.1, 0.3)), (0.012, 1.0, (0.3, 0.1, 0.3)),
    (0.008, 2.0, (0.2, 0.4, 0.3))])
def test_push_out_of_a_partner_on_the_ground_leaves_under_ten_tolerances(pair_schedule, depth, ratio, half, device):
    """The law of the test above where the partner is not static but rests on the ground (as heavy
    as the pushed box or heavier): kinetic energy must not rise through the push-out, so every body
    moves under 10 tolerances.  Before the relax walked a pair that let go of a push on to its
    bodies' terrain rows (pair_solve.relax_chain_pair), the upper box left at up to 0.5 m/s on the
    slab schedule and both at 0.9 m/s on the colour schedule."""
    if pair_schedule == "domains" and device != "cpu":
        pytest.skip("the slab schedule runs on the CPU only")
    config = SimConfig(sleep=False, allow_initial_overlap=True, pair_schedule=pair_schedule, device=device)
    sim = Simulator(overlapping(depth, "box on the ground", ratio, half).finalize(device), config)
    assert fastest_over(sim, 8) < gravity_bound(config)


def column(count: int, depth: float, pushed: int):
    """``count`` unit cubes of 1 kg stacked on the plane, cube ``pushed`` (1 = the second from the
    ground) started ``depth`` into the one below it."""
    b = ModelBuilder(Material(restitution=0.0, friction=0.5))
    b.set_terrain(PlaneTerrain())
    y = 0.5
    for k in range(count):
        y -= depth if k == pushed else 0.0
        b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, y, 0.0))
        y += 1.0
    return b


CHAIN_LEFT = pytest.mark.xfail(strict=True, reason=(
    "known limitation (README, design notes: push-out across a chain): the walk to the ground covers a pair and its "
    "own bodies' terrain rows, so a partner lighter than the pushed box, or a chain of three bodies or more, is left "
    "to the relax's Gauss-Seidel"))
CHAIN_CASES = [(schedule, scene) for schedule in ("domains", "colors")
               for scene in ("partner 0.1 kg", "partner 0.3 kg", "3 cubes, top pushed", "3 cubes, middle pushed",
                             "4 cubes, top pushed")]


@pytest.mark.parametrize("pair_schedule, scene", [
    pytest.param(*case, marks=()) if case == ("colors", "partner 0.3 kg") else pytest.param(*case, marks=CHAIN_LEFT)
    for case in CHAIN_CASES])
def test_push_out_through_a_longer_chain_leaves_under_ten_tolerances(pair_schedule, scene, device):
    """The same law where the walk does not reach: a lighter partner (the walk's passes hand the push
    down by m / (M + m) of it each, so 15 passes leave most of it) and columns of three and four
    cubes (the pushed pair's partner rests on another body, not on the ground).  Measured: 0.003 to
    1.1 m/s, the middle cube of three pushed out of the bottom one throwing the top cube at 1 m/s.
    The 0.3 kg partner on the colour schedule meets the bound (0.0029 against 0.0041 m/s) since a
    pair whose first solve pass takes a blow sweeps on until converged (pair_solve.solve_pair_points;
    0.020 before); on the slab schedule it reads 0.0043.  Strict, so a fix shows here."""
    if pair_schedule == "domains" and device != "cpu":
        pytest.skip("the slab schedule runs on the CPU only")
    config = SimConfig(sleep=False, allow_initial_overlap=True, pair_schedule=pair_schedule, device=device)
    if scene.startswith("partner"):
        builder = overlapping(0.012 if "0.1" in scene else 0.02, "box on the ground", float(scene.split()[1]),
                              (0.5, 0.5, 0.5))
    else:
        count = int(scene[0])
        builder = column(count, 0.02 if count == 3 else 0.01, 1 if "middle" in scene else count - 1)
    sim = Simulator(builder.finalize(device), config)
    assert fastest_over(sim, 8) < gravity_bound(config)


@pytest.mark.parametrize("partner, ratio, half", [("terrain", 1.0, (0.5, 0.5, 0.5)), ("box", 1.0, (0.5, 0.5, 0.5)),
                                                ("box", 3.0, (0.3, 0.1, 0.3))])
def test_a_single_relax_pass_leaves_push_speed_behind(partner, ratio, half, device):
    """The faster choice, ``relax_passes = 1`` (Box2D's single relax), shown failing the check above:
    a box 2 cm deep keeps part of its push-out speed (the cube on the ground 0.077 m/s when this
    was the only relax), at least 10 times what the default's passes leave."""
    b = overlapping(0.02, partner, ratio, half)
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False,
                                                  allow_initial_overlap=True, relax_passes=1, device=device))
    sim.step()
    assert np.linalg.norm(sim.state.body_vel.numpy(), axis=1).max() > 10 * LEFT_SPEED


@pytest.mark.parametrize("depth", [0.012, 0.02, 0.03])
@pytest.mark.parametrize("partner, ratio", [("terrain", 1.0), ("box", 10.0), ("box", 1.0)])
def test_a_contact_deeper_than_the_column_sag_budget_is_pushed_back_to_it(depth, partner, ratio, device):
    """No gravity, a cube ``depth`` into the ground or into another cube.  No load the substep plan
    allows sags a contact deeper than column_sag d (soft_step.closed_contact_bias), so the excess
    is pushed out at (s + d) / h, capped at max_push_velocity v_p: it is gone after
    ceil((depth - d) / (v_p h)) substeps.  Then only the soft bias acts, taking biasRate s h a
    substep, so after the step's remaining k substeps the overlap lies in
    [d (1 - biasRate h)^k, d] (0.3 mm allows the leak and float32).  The soft law alone would have
    left about depth exp(-biasRate dt), three quarters of it."""
    config = SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, allow_initial_overlap=True, device=device)
    d = config.column_sag
    h = config.dt / config.substeps
    bias_rate = soft_coefficients(h, config.contact_hertz, config.damping_ratio, d)[0]
    b = overlapping(depth, partner, ratio, (0.5, 0.5, 0.5))
    sim = Simulator(b.finalize(device), config)
    sim.step()
    pos = sim.state.body_pos.numpy().astype(float)
    overlap = (0.5 - pos[-1, 1]) if partner == "terrain" else (1.0 - (pos[1, 1] - pos[0, 1]))
    k = config.substeps - math.ceil((depth - d) / (config.max_push_velocity * h))
    assert d * (1.0 - bias_rate * h) ** k - 3e-4 <= overlap <= d + 3e-4, overlap
    assert np.linalg.norm(sim.state.body_vel.numpy(), axis=1).max() < LEFT_SPEED


@pytest.mark.parametrize("ratio", [100.0, 1000.0])
def test_a_column_planned_past_the_budget_keeps_the_soft_law(ratio, device):
    """auto_substeps off: a heavy cube on a light one at exactly 4 substeps is planned to sag past
    column_sag, and its loaded contacts are deeper than the budget.  The push-back depth is then
    the plan's own sag, so the pair sinks by the soft law's estimate instead of being pushed
    apart (with the budget as the depth, the 1 kg cube under 1000 kg was thrown out, 1 m)."""
    b = ModelBuilder(Material(restitution=0.0, friction=0.5))
    b.set_terrain(PlaneTerrain())
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, 0.5, 0.0))
    b.add_box((0.5, 0.5, 0.5), ratio, position=(0.0, 1.5, 0.0))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, auto_substeps=False, device=device))
    plan = sim.substep_plan
    assert plan.sag > sim.config.column_sag
    assert sim.solver.settings.soft_depth == pytest.approx(plan.sag)
    fastest = 0.0
    for _ in range(180):
        sim.step()
        fastest = max(fastest, float(np.linalg.norm(sim.state.body_vel.numpy(), axis=1).max()))
    sink = 1.5 - float(sim.state.body_pos.numpy()[1, 1])
    # the soft spring's sag, as planned (column_sag.py: within 5 % of what the columns measure)
    assert sink == pytest.approx(plan.sag, rel=0.05)
    assert fastest < 1.0


SQUEEZED_WITHOUT_FRICTION = pytest.mark.xfail(strict=True, reason=(
    "known limitation (README, found and not fixed): without friction, a column of 3e4 kg cubes, of unequal heavy "
    "cubes, with a 0.5 kg cube of half 0.3, or with the light cube off the axis still creeps sideways at 1.5 to 19 mm/s "
    "in its second and third seconds, and an offset of 0.1 m between cubes of 1e3 kg is squeezed out at 11 m/s: off the "
    "axis the heavy cubes tilt on their soft supports past the face tie (box_box.collide_box_box)"))
# (below, above, light, half extent of the light cube, its offset along x): aligned columns stand
# without friction once the light cube's faces are its contacts' references (box_box.collide_box_box)
FRICTIONLESS = [(1e2, 1e2, 1.0, 0.5, 0.0), (1e3, 1e3, 1.0, 0.5, 0.0), (3e3, 3e3, 1.0, 0.5, 0.0),
                (1e4, 1e4, 1.0, 0.5, 0.0), (1e4, 1e4, 2.0, 0.4, 0.0), (1e4, 3e3, 1.0, 0.5, 0.0)]
FRICTIONLESS_FAILING = [(3e4, 3e4, 1.0, 0.5, 0.0), (1e4, 1e4, 0.5, 0.3, 0.0), (3e3, 3e4, 1.0, 0.5, 0.0),
                        (3e4, 3e3, 0.5, 0.5, 0.0), (1e4, 1e4, 1.0, 0.5, 0.05), (1e3, 1e3, 1.0, 0.5, 0.1)]


@pytest.mark.parametrize("below, above, friction, light, half, offset", [
    pytest.param(below, above, mu, 1.0, 0.5, 0.0) for below in (3e3, 1e4, 3e4) for above in (3e3, 1e4)
    for mu in (0.3, 0.5, 1.0)
] + [pytest.param(below, above, 0.0, light, half, offset) for below, above, light, half, offset in FRICTIONLESS]
  + [pytest.param(below, above, 0.0, light, half, offset, marks=SQUEEZED_WITHOUT_FRICTION)
     for below, above, light, half, offset in FRICTIONLESS_FAILING])
def test_a_light_cube_between_two_heavy_ones_stands(below, above, friction, light, half, offset, device):
    """A light cube (0.5 to 2 kg, half 0.3 to 0.5) set down at rest between two cubes of 1e2 to
    3e4 kg (the column the substep plan raises to 30 to 64 substeps for, its sag planned just under
    column_sag).  Its loaded contacts are not pushed back past the budget
    (contact_rows.loaded_soft): the load settling overshot the plan's sag by a fraction of a
    millimetre, and the push through the light cube, which two sweeps cannot converge against a
    body 1e4 times heavier, rang until the light cube was thrown out at 5 to 11 m/s (9 of the 18
    cases with friction).  Without friction every column was squeezed out (6 to 65 m/s within 3 s)
    while the heavy cubes' faces, tilted on their soft supports, were the references of the light
    cube's contacts.  After the first second, as a resting stack: no point faster than
    sleep_velocity, the speed below which the sleep rule takes a body for still, and no body
    moving by a tenth of column_sag in two seconds."""
    sim = cases.squeezed_column(below, above, light, half, offset, friction, device)
    sim.step(60)
    start = sim.state.body_pos.numpy().copy()
    fastest = 0.0
    for _ in range(120):
        sim.step()
        fastest = max(fastest, float(np.linalg.norm(sim.state.body_vel.numpy(), axis=1).max()))
    moved = float(np.linalg.norm(sim.state.body_pos.numpy() - start, axis=1).max())
    assert fastest < sim.config.sleep_velocity, fastest
    assert moved < 0.1 * sim.config.column_sag, moved
