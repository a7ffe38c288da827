"""Runs on one device are bit-identical: run to run, and after restoring a snapshot (time travel)."""

import hashlib

import numpy as np
import pytest

from warp_sim import FourierTerrain, cases


def state_digest(sim) -> str:
    h = hashlib.sha256()
    for a in sim.state.fields():
        h.update(np.ascontiguousarray(a.numpy()).tobytes())
    return h.hexdigest()


def mixed_drop(device="cpu"):
    return cases.terrain_drop(50, "mix", terrain=FourierTerrain(amplitude=0.4), rolling_resistance=0.1,
                              device=device)


def test_two_runs_are_bit_identical(device):
    digests = []
    for _ in range(2):
        sim = mixed_drop(device)
        sim.step(120)
        digests.append(state_digest(sim))
    assert digests[0] == digests[1]


def test_restoring_a_snapshot_replays_bit_for_bit(device):
    sim = mixed_drop(device)
    sim.step(60)
    snap = sim.snapshot()
    sim.step(60)
    first = state_digest(sim)
    sim.restore(snap)
    assert sim.step_count == 60
    sim.step(60)
    assert state_digest(sim) == first


def test_the_colour_schedule_gives_the_same_state_on_any_cpu_thread_count(monkeypatch):
    """The colour sweeps split a colour across the CPU threads once it holds launch.PAIR_CHUNK pairs
    (a colour's pairs share no body, so the split must not change any result): a rain dense enough
    that its colours pass that size gives one state on 1, 2 and 3 threads, with and without
    restitution (its impact sweeps and joint phase split the same way)."""
    import pytest

    from warp_sim.launch import PAIR_CHUNK

    for e in (0.0, 0.5):
        digests = []
        for threads in (1, 2, 3):
            monkeypatch.setenv("WARP_SIM_CPU_THREADS", str(threads))
            sim = cases.terrain_drop(2500, "mix", body_contact=True, spacing=0.7, seed=5, restitution=e,
                                     pair_schedule="colors", sleep=False)
            sim.step(20)
            starts = sim.contacts.color_start.numpy()
            if threads == 1:  # the colours are large enough to split, else this proves nothing
                if int(np.diff(starts).max()) <= PAIR_CHUNK:
                    pytest.fail(f"largest colour {int(np.diff(starts).max())} pairs, not over {PAIR_CHUNK}")
            digests.append(state_digest(sim))
        assert digests[0] == digests[1] == digests[2], e


@pytest.mark.parametrize("substeps, graph", [(1, False), (3, False), (1, True)])
def test_a_terrain_only_step_run_in_place_equals_the_double_buffered_one(substeps, graph, monkeypatch):
    """Without pairs the first of an odd number of substeps writes the buffer it reads
    (solvers/solver.py fused_in_place) instead of copying the result back after the step: the
    same bytes as the double-buffered step, and the state stays in the buffer it started in (a
    caller holding ``sim.state`` sees every step, captured or not)."""
    def run(in_place: bool):
        sim = cases.terrain_drop(40, "mix", terrain=FourierTerrain(amplitude=0.4), rolling_resistance=0.1, dt=1 / 60,
                                 substeps=substeps, graph=graph)
        assert sim.substeps == substeps
        monkeypatch.setattr(sim.solver, "fused_in_place", in_place)
        held = sim.state
        sim.step(1)
        for _ in range(8):
            sim.step(10)
            assert sim.state is held
        return state_digest(sim)

    assert run(True) == run(False)
