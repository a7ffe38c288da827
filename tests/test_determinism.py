"""Runs on one device are bit-identical: run to run, and after restoring a snapshot (time travel)."""

import hashlib

import numpy as np

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
