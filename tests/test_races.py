"""Every per-step kernel launched through warp_sim.launch run in reversed and shuffled chunk
orders and thread by thread (race_check.py): the same bytes, and no element written by two
threads.  Tiny scenes, since the check launches each thread on its own."""

import pytest

from warp_sim import FourierTerrain, ModelBuilder, PlaneTerrain, SimConfig, Simulator, cases
from warp_sim.builder import Material
from warp_sim.race_check import RaceCheck, RaceError


def pile(top_mass=1.0, overlap=0.0, **config) -> Simulator:
    """Two boxes stacked, a ball resting against them and one falling onto them: pairs of both
    kinds, restitution, friction and terrain contact in the first steps.  A ``top_mass`` 10 times
    the bottom box's or more makes its pair walk the bottom box's terrain contacts too
    (pair_solve.CHAIN_MASS_RATIO), writes the pair's thread must own; so does an ``overlap`` of the
    top box into the bottom one, whose push-out the relax walks down to the ground
    (pair_solve.relax_chain_pair)."""
    b = ModelBuilder(Material(friction=0.6, restitution=0.3))
    b.set_terrain(PlaneTerrain())
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, 0.5, 0.0))
    b.add_box((0.5, 0.5, 0.5), top_mass, position=(0.1, 1.5 - overlap, 0.0))
    b.add_sphere(0.3, 1.0, position=(0.8, 0.3, 0.0))
    b.add_sphere(0.25, 1.0, position=(0.0, 2.3, 0.1), velocity=(0.0, -2.0, 0.0))
    return Simulator(b.finalize(), SimConfig(dt=1 / 60, substeps=2, sleep_time=0.05, allow_initial_overlap=overlap > 0,
                                             **config))


@pytest.mark.parametrize("schedule,capturable,top_mass,overlap", [
    ("colors", False, 1.0, 0.0), ("colors", True, 1.0, 0.0), ("domains", False, 1.0, 0.0), ("colors", False, 50.0, 0.0),
    ("domains", False, 50.0, 0.0), ("colors", False, 1.0, 0.02), ("domains", False, 1.0, 0.02)])
def test_pair_contact_steps_have_no_races(schedule, capturable, top_mass, overlap):
    """``capturable``: launches sized by capacities and bounds, as a captured step sizes them."""
    sim = pile(top_mass, overlap, pair_schedule=schedule)
    sim.pairs.capturable = capturable
    if overlap > 0.0:
        # the push-out and its walk happen in the first step: checked too, after loading the modules
        pile(top_mass, overlap, pair_schedule=schedule).step()
    else:
        sim.step()  # loads the modules outside the check
    walked = 0
    with RaceCheck() as check:
        for _ in range(3):
            sim.step()
            walked += int(sim.contacts.pair_relax_chain.numpy().sum())
    if overlap > 0.0 and schedule == "colors":
        # the walk to the ground, a launch of its own, for a pair its relax flagged
        assert walked > 0 and check.checked.get("chain_pass", 0) > 0
    assert check.isolated.get("pair_pass_solve" if schedule == "colors" else "domain_sweep_solve", 0) > 0
    # the neighbour-timer gather and the wake marks use atomics, so they run as one launch, never
    # split (launch.py); the slab schedule colours no pairs
    kernels = ["collide_terrain", "collide_pairs", "carry_pair_impulses", "store_pairs", "update_sleep", "wake_marked"]
    # and the joint phase of the impacts (solvers/impact_joint.py): its parallel sweeps on colours, one
    # thread on slabs
    kernels += ["terrain_members", "terrain_joint_impact", "pair_joint_pass"] if schedule == "colors" else [
        "joint_phase_in_order"]
    if schedule == "colors":
        kernels += ["color_pick", "color_bounds"]
        if top_mass >= 10.0:
            kernels.append("chain_pass")  # the heavy-on-light passes, a launch of their own
    for kernel in kernels:
        assert check.checked.get(kernel, 0) > 0, kernel
    # the sweeps are one kernel per mode (solvers/domains.py, pair_solve.py); this restitution runs its impacts and
    # relaxes closed contacts only
    sweeps = [("pair_pass_" if schedule == "colors" else "domain_sweep_") + mode
              for mode in ("impact", "solve", "relax_closed")]
    for kernel in sweeps:
        assert check.checked.get(kernel, 0) > 0, kernel


@pytest.mark.parametrize("substeps", [4, 1, 3])
def test_terrain_only_fused_step_has_no_races(substeps):
    """With an odd substep count the first fused substep reads and writes one state buffer
    (Simulator, solvers/solver.py fused_in_place): no thread may read another body's state."""
    sim = cases.terrain_drop(4, "mix", terrain=FourierTerrain(amplitude=0.3), spacing=0.6, dt=1 / 60,
                             substeps=substeps)
    assert sim.substeps == substeps
    sim.step()
    with RaceCheck() as check:
        sim.step(2)
    assert check.checked.get("solve_and_integrate", 0) > 0


def test_the_check_catches_a_race():
    """Two threads adding into one element (what two pairs of one body in one colour would do)."""
    import warp as wp

    from warp_sim.launch import launch

    @wp.kernel
    def scatter(tid_offset: int, target: wp.array(dtype=int), out: wp.array(dtype=float)):
        t = wp.tid() + tid_offset
        out[target[t]] = out[target[t]] + 1.0

    target = wp.array([0, 1, 1, 2], dtype=int, device="cpu")
    out = wp.zeros(3, dtype=float, device="cpu")
    launch(scatter, 4, [target, out], "cpu")  # outside the check: loads the module
    with pytest.raises(RaceError, match="written by threads 1 and 2"):
        with RaceCheck():
            launch(scatter, 4, [target, out], "cpu")


def test_the_check_sees_writes_through_struct_fields(monkeypatch):
    """Kernels take most arrays inside structs (kernel_args.py): a race on a struct's field is
    caught like one on an array argument, and SHARED_WRITES exempts a field by its
    ``parameter.field`` name only."""
    import warp as wp

    import warp_sim.race_check as race_check
    from warp_sim.kernel_args import BadSteps
    from warp_sim.launch import launch

    @wp.struct
    class Scatter:
        target: wp.array(dtype=int)
        out: wp.array(dtype=float)

    @wp.kernel
    def scatter_fields(tid_offset: int, args: Scatter):
        t = wp.tid() + tid_offset
        args.out[args.target[t]] = args.out[args.target[t]] + 1.0

    @wp.kernel
    def flag_every_thread(tid_offset: int, bad_steps: BadSteps):
        t = wp.tid() + tid_offset
        bad_steps.body_bad_step[t] = t
        bad_steps.bad_count[0] = 1

    args = Scatter()
    args.target = wp.array([0, 1, 1, 2], dtype=int, device="cpu")
    args.out = wp.zeros(3, dtype=float, device="cpu")
    launch(scatter_fields, 4, [args], "cpu")  # outside the check: loads the module
    with pytest.raises(RaceError, match="of 'args.out' written by threads 1 and 2"):
        with RaceCheck():
            launch(scatter_fields, 4, [args], "cpu")

    flags = BadSteps()
    flags.sim_step = wp.zeros(1, dtype=wp.int32, device="cpu")
    flags.body_bad_step = wp.zeros(4, dtype=wp.int32, device="cpu")
    flags.bad_count = wp.zeros(1, dtype=wp.int32, device="cpu")
    launch(flag_every_thread, 4, [flags], "cpu")
    flags.bad_count.zero_()  # a thread that stores the value already there is invisible to the check
    with pytest.raises(RaceError, match="of 'bad_steps.bad_count' written by threads 0 and 1"):
        with RaceCheck():
            launch(flag_every_thread, 4, [flags], "cpu")
    monkeypatch.setitem(race_check.SHARED_WRITES, flag_every_thread.key, {"bad_steps.bad_count"})
    flags.bad_count.zero_()
    with RaceCheck() as check:
        launch(flag_every_thread, 4, [flags], "cpu")
    assert check.isolated[flag_every_thread.key] == 1
