"""The CPU pair schedule (schedule/slabs.py cuts, solvers/domains.py sweeps): slabs that cover every body and pair exactly once."""

import itertools

import numpy as np
import pytest

from warp_sim import ModelBuilder, PlaneTerrain, SimConfig, Simulator, cases
from warp_sim.builder import Material
from warp_sim.schedule.slabs import BINS, CUT_SLACK

DOMAINS = 3  # more slabs than this machine may have cores: the schedule must not depend on them


@pytest.fixture
def rain(monkeypatch):
    monkeypatch.setenv("WARP_SIM_CPU_THREADS", str(DOMAINS))
    sim = cases.terrain_drop(400, "mix", body_contact=True, spacing=0.9, sleep=False, rolling_resistance=0.2)
    sim.step(40)  # landed and piled: pairs and terrain contacts in every slab
    return sim


def partition(sim):
    p = sim.pairs
    return (p.domain_body_start.numpy(), p.domain_body.numpy(), p.domain_pair_start.numpy(),
            p.domain_pair.numpy(), p.body_domain.numpy())


def test_every_dynamic_body_is_in_exactly_one_slab(rain):
    body_start, body_list, _, _, body_domain = partition(rain)
    # all bodies are dynamic here: the static list after the slabs is empty
    assert body_start[0] == 0 and body_start[DOMAINS] == body_start[-1] == rain.model.body_count
    listed = body_list[: body_start[DOMAINS]]
    assert np.array_equal(np.sort(listed), np.arange(rain.model.body_count))
    for d in range(DOMAINS):
        members = body_list[body_start[d]:body_start[d + 1]]
        assert np.all(np.diff(members) > 0), "a slab walks its bodies in body order"
        assert np.all(body_domain[members] == d)


def test_slabs_are_ordered_along_the_cut_axis_and_balanced(rain):
    body_start, body_list, _, _, body_domain = partition(rain)
    pos = rain.state.body_pos.numpy()
    extent = pos.max(axis=0) - pos.min(axis=0)
    axis = 2 if extent[2] > extent[0] else 0
    slabs = [pos[body_list[body_start[d]:body_start[d + 1]], axis] for d in range(DOMAINS)]
    assert all(len(s) for s in slabs)
    # bins are 1/1024 of the extent wide: neighbouring slabs may share at most one bin's width
    bin_width = extent[axis] / 1024
    for a, b in itertools.pairwise(slabs):
        assert a.max() <= b.min() + bin_width
    # work per slab: 1 + active terrain slots per body, plus each pair's points on both bodies
    c = rain.contacts
    active = c.terrain_contact_active.numpy()
    start = rain.model.host["body_checkpoint_start"]
    count = rain.model.host["body_checkpoint_count"]
    weight = np.array([1.0 + active[s:s + k].sum() for s, k in zip(start, count)])
    pairs = int(c.pair_count.numpy()[0])
    points = c.pair_point_count.numpy()[:pairs]
    for (i, j), k in zip(c.pair_body.numpy()[:pairs], points):
        weight[i] += k
        weight[j] += k
    share = np.array([weight[body_domain == d].sum() for d in range(DOMAINS)])
    # each of a slab's two cuts lies within CUT_SLACK of a share of its balanced place (it may move to
    # where no pair crosses it), at bin granularity: one bin's work more, a few bodies' worth here
    # (bound: 2 % of a share, ~10 bodies of ~5 units each)
    assert np.abs(share - weight.sum() / DOMAINS).max() <= (2 * CUT_SLACK + 0.02) * weight.sum() / DOMAINS + weight.max()


def test_every_touching_pair_is_solved_in_exactly_one_place(rain):
    _, _, pair_start, pair_list, body_domain = partition(rain)
    c = rain.contacts
    pairs = int(c.pair_count.numpy()[0])
    touching = np.nonzero(c.pair_point_count.numpy()[:pairs] > 0)[0]
    listed = pair_list[: pair_start[-1]]
    # each pair once; every pair with points now is listed (a pair refreshed mid-step, see
    # solvers/pair_refresh.py, may have lost its points since the pass listed it, never gained)
    assert len(np.unique(listed)) == len(listed)
    assert np.all(np.isin(touching, listed))
    assert len(listed) - len(touching) <= 0.05 * len(listed)
    bodies = c.pair_body.numpy()
    for d in range(DOMAINS):
        for p in pair_list[pair_start[d]:pair_start[d + 1]]:
            assert body_domain[bodies[p][0]] == d and body_domain[bodies[p][1]] == d
    boundary = pair_list[pair_start[DOMAINS]:pair_start[DOMAINS + 1]]
    for p in boundary:
        assert body_domain[bodies[p][0]] != body_domain[bodies[p][1]]
    # the cuts are planes through a pile: few pairs cross them
    assert len(boundary) < 0.2 * len(touching)


def test_slab_schedule_is_deterministic(monkeypatch):
    monkeypatch.setenv("WARP_SIM_CPU_THREADS", str(DOMAINS))
    runs = []
    for _ in range(2):
        sim = cases.terrain_drop(200, "mix", body_contact=True, spacing=0.9, sleep=False)
        sim.step(30)
        runs.append(sim.state.body_pos.numpy().tobytes() + sim.state.body_vel.numpy().tobytes())
    assert runs[0] == runs[1]


def test_boundary_bodies_are_listed_once_each(rain):
    """The dynamic bodies of boundary pairs are integrated and finalized by the boundary thread
    (solvers/domains.py), so the list must hold each of them exactly once, and no other body."""
    _, _, pair_start, pair_list, body_domain = partition(rain)
    p = rain.pairs
    bodies = rain.contacts.pair_body.numpy()
    boundary = pair_list[pair_start[DOMAINS]:pair_start[DOMAINS + 1]]
    assert len(boundary) > 0  # the scene must exercise the boundary
    expected = {int(b) for pair in boundary for b in bodies[pair] if body_domain[b] >= 0}
    listed = p.boundary_body.numpy()[: int(p.boundary_body_count.numpy()[0])]
    assert len(listed) == len(set(listed.tolist())) and set(listed.tolist()) == expected
    assert set(np.nonzero(p.body_on_boundary.numpy())[0].tolist()) == expected


def test_static_bodies_are_listed_after_the_slabs_and_stay_put(monkeypatch):
    """Static bodies belong to no slab; one thread copies them each substep.  Balls and boxes
    dropped into a pit of static walls stay inside, and the walls do not move at all."""
    monkeypatch.setenv("WARP_SIM_CPU_THREADS", str(DOMAINS))
    b = ModelBuilder(Material(friction=0.5, rolling_resistance=0.2))
    b.set_terrain(PlaneTerrain())
    for x, z, hx, hz in ((-2.6, 0, 0.1, 1.0), (2.6, 0, 0.1, 1.0), (0, -1.1, 2.7, 0.1), (0, 1.1, 2.7, 0.1)):
        b.add_box((hx, 0.5, hz), 1.0, position=(x, 0.5, z), static=True)
    for k in range(12):
        position = (-2.2 + 0.4 * k, 1.0 + 0.3 * k, 0.3 * (-1) ** k)
        if k % 2:
            b.add_box((0.15, 0.15, 0.15), 1.0, position=position)
        else:
            b.add_sphere(0.2, 1.0, position=position)
    sim = Simulator(b.finalize(), SimConfig(dt=1 / 60, substeps=4, sleep=False))
    walls = np.nonzero(sim.model.host["body_inv_mass"] == 0)[0]
    start_pos = sim.state.body_pos.numpy()[walls].copy()
    sim.step(120)
    body_start, body_list, _, _, body_domain = partition(sim)
    assert np.array_equal(np.sort(body_list[body_start[DOMAINS]:body_start[DOMAINS + 1]]), walls)
    assert np.all(body_domain[walls] == -1)
    for state in sim.states:  # both buffers: the copies are made every substep
        assert np.array_equal(state.body_pos.numpy()[walls], start_pos)
        assert not state.body_vel.numpy()[walls].any()
    pos = sim.state.body_pos.numpy()[len(walls):]
    assert np.all(np.abs(pos[:, 0]) < 2.5) and np.all(np.abs(pos[:, 2]) < 1.0)


def test_a_cut_moves_to_a_gap_within_reach(monkeypatch):
    """Two rows of touching balls, 52 and 48, with a gap between: the balanced cut (half the work)
    falls inside the longer row, the gap lies 4 % of a slab's work away, within CUT_SLACK, so the
    cut goes there and no pair crosses it (no boundary launch at all)."""
    monkeypatch.setenv("WARP_SIM_CPU_THREADS", "2")
    b = ModelBuilder(Material(friction=0.5))
    b.set_terrain(PlaneTerrain())
    xs = [0.49 * k for k in range(52)] + [0.49 * 51 + 2.0 + 0.49 * k for k in range(48)]
    for x in xs:
        b.add_sphere(0.25, 1.0, position=(x, 0.25, 0.0))
    sim = Simulator(b.finalize(), SimConfig(dt=1 / 60, substeps=4, sleep=False))
    sim.step(1)
    p = sim.pairs
    work_before, crossing = p.bin_work_before.numpy(), p.bin_crossing.numpy()
    share = work_before[BINS] / 2
    balanced = int(np.argmin(np.abs(work_before - share)))
    assert crossing[balanced] > 0  # the balanced cut would cut the long row
    body_domain = p.body_domain.numpy()
    assert p.schedule.boundary_pairs == 0
    assert np.all(body_domain[:52] == 0) and np.all(body_domain[52:] == 1)
