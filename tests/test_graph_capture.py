"""The CUDA contract proven on the CPU: the whole step (terrain, pairs, colours, substeps,
restitution, sleeping) captured as one graph replays bit for bit like direct stepping; pair
buffers that run out grow and redo the step instead of losing contacts."""

import hashlib
import warnings

import numpy as np
import pytest

import warp_sim.simulator as simulator
from warp_sim import ModelBuilder, PlaneTerrain, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.schedule.coloring import COLOR_COUNT


def digest(sim) -> str:
    h = hashlib.sha256()
    for a in sim.state.fields():
        h.update(np.ascontiguousarray(a.numpy()).tobytes())
    return h.hexdigest()


def sleeping_stack(device="cpu", **config) -> Simulator:
    """Three boxes that settle and sleep, then a ball that lands on them at ~0.9 s and wakes them."""
    b = ModelBuilder(Material(friction=0.6, restitution=0.3))
    b.set_terrain(PlaneTerrain())
    for k in range(3):
        b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, 0.5 + k, 0.0))
    b.add_sphere(0.25, 1.0, position=(0.1, 7.0, 0.0))
    return Simulator(b.finalize(device), SimConfig(dt=1 / 60, substeps=4, sleep_time=0.2,
                                                  pair_schedule="colors", device=device, **config))


def test_captured_step_replays_bit_for_bit_with_body_contact_and_sleeping(device):
    direct = sleeping_stack(device, graph=False)
    captured = sleeping_stack(device, graph=True)
    assert captured.use_graph and not direct.use_graph
    awake = []
    for k in range(80):
        direct.step()
        captured.step()
        assert digest(direct) == digest(captured), f"step {k + 1}"
        awake.append(captured.awake_count())
    assert captured.graph is not None  # the replay, not direct stepping, made those steps
    assert min(awake[:45]) < 3 <= max(awake[45:])  # the stack slept, then the ball woke it


def test_graph_is_refused_with_the_slab_schedule():
    with pytest.raises(ValueError, match="graph = true"):
        Simulator(
            sleeping_stack().model, SimConfig(graph=True, pair_schedule="domains"))


def lattice(n: int, device="cpu", **config) -> Simulator:
    b = ModelBuilder(Material(friction=0.6))
    b.set_terrain(PlaneTerrain())
    for x in range(n):
        for y in range(n):
            for z in range(n):
                b.add_box((0.5, 0.5, 0.5), 1.0, position=(float(x), 0.5 + y, float(z)))
    return Simulator(b.finalize(device), SimConfig(dt=1 / 60, substeps=4, sleep=False, pair_schedule="colors",
                                                  device=device, **config))


def test_default_capacity_holds_a_10x10x10_lattice_of_touching_cubes_and_colours_it_all(device):
    sim = lattice(10, device)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a growth would warn
        sim.step()
    demand = int(sim.contacts.pair_demand.numpy()[0])
    assert demand > 10 * 1000  # 10.5 candidate pairs a body: more than the old 8 a body
    assert demand <= sim.pairs.capacity
    starts = sim.contacts.color_start.numpy()
    assert starts[COLOR_COUNT + 1] - starts[COLOR_COUNT] == 0  # no pair left to the one-thread overflow set
    assert starts[COLOR_COUNT] > 0.99 * demand  # (pairs without points take no colour)


@pytest.mark.parametrize("n", [2, 4])
def test_a_captured_step_colours_in_the_rounds_it_needs_and_no_more(device, n):
    """The colouring's rounds run in a device-side loop (``wp.capture_while``) that stops once no
    pair is pending; a captured step used to run all ROUND_CAP rounds, idle ones returning at
    once (on an H200 that cost most of the colouring's 40 ms a step at 1M bodies).  Replayed,
    it must stop where direct stepping stops and colour alike."""
    from warp_sim.schedule.coloring import ROUND_CAP

    direct = lattice(n, device, graph=False)
    captured = lattice(n, device, graph=True)
    for _ in range(3):  # the first step runs directly, the second captures, the third replays
        direct.step()
        captured.step()
    used = int(direct.pairs.coloring.round_index.numpy()[0])
    assert 2 <= used < ROUND_CAP
    assert int(captured.pairs.coloring.round_index.numpy()[0]) == used
    np.testing.assert_array_equal(captured.contacts.color_start.numpy(), direct.contacts.color_start.numpy())
    assert digest(captured) == digest(direct)


@pytest.mark.parametrize("graph", [False, True])
def test_pair_overflow_grows_the_buffers_and_redoes_the_step(monkeypatch, graph, device):
    """Direct stepping grows within the step; a captured call is rerun from its saved start."""
    reference = lattice(3, device)
    monkeypatch.setattr(simulator, "default_pair_capacity", lambda n: 16)
    small = lattice(3, device, graph=graph)
    assert small.pairs.capacity == 16
    with pytest.warns(RuntimeWarning, match=r"grown to \d+ pairs") as record:
        small.step(1)
        small.step(2)
    assert len(record) == 1
    reference.step(3)
    assert small.pairs.capacity >= int(small.contacts.pair_demand.numpy()[0]) > 16
    assert digest(small) == digest(reference)  # no contact was lost on the way


def test_no_array_is_allocated_inside_a_conditional_graph_body(monkeypatch):
    """CUDA refuses an allocation inside a conditional body (``wp.capture_if``: the mid-step pair
    pass, the pass after a wake, the overflow colour's stage): "Conditional body graph contains
    an unsupported operation (memory allocation)".  On the CPU that is not an error, so every
    allocation made while a body is being captured is recorded here: a sleeping stack struck by
    a bouncing ball, and a restitution rain (impacts, mid-step passes), captured on the CPU.
    Native temporaries (``wp.utils.array_scan``'s) are kept out by test_architecture."""
    import warp as wp
    from warp._src import context

    inside, made, entered = [0], [], [0]
    allocate = context.CpuDefaultAllocator.allocate

    def recording_allocate(self, size):
        if inside[0]:
            made.append(size)
        return allocate(self, size)

    capture_if = wp.capture_if

    def watched_capture_if(condition, on_true=None, on_false=None, **kwargs):
        def watch(body):
            if not callable(body):
                return body

            def run(**args):
                inside[0] += 1
                entered[0] += 1
                try:
                    return body(**args)
                finally:
                    inside[0] -= 1
            return run
        return capture_if(condition, on_true=watch(on_true), on_false=watch(on_false), **kwargs)

    monkeypatch.setattr(context.CpuDefaultAllocator, "allocate", recording_allocate)
    monkeypatch.setattr(wp, "capture_if", watched_capture_if)
    from warp_sim import cases

    for sim in (sleeping_stack(graph=True),
                cases.terrain_drop(60, "mix", spacing=0.9, body_contact=True, sleep=True, graph=True,
                                   restitution=0.6, pair_schedule="colors")):
        before = len(made)
        sim.step(70, check=False)
        assert len(made) == before, f"{len(made) - before} arrays allocated inside a conditional body"
    assert entered[0] > 0  # bodies were captured: the check saw something
