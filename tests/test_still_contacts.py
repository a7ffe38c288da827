"""A still body's terrain contacts are carried, not searched again (collide/still_contacts.py).

The carried slots are checked against a full search at the same pose, in piles of spheres, cubes
and plates on terrains of two heights and several seeds: no contact the search finds is missing,
and every carried depth lies within the error the module derives for it.  Then what must make a
still body searched again: a terrain edited under it, a settings change, a body moved by hand.
"""

import numpy as np
import pytest
import warp as wp

from warp_sim import FourierTerrain, ModelBuilder, SimConfig, Simulator, cases
from warp_sim.collide.still_contacts import STILL_TRAVEL
from warp_sim.types import SHAPE_BOX

from test_bounded_points import FACE_SEARCH_GAIN, support_face
from test_face_search import grid_error, oracle_depth

TERRAIN_ARRAYS = ("terrain_contact_active", "terrain_contact_point", "terrain_contact_normal", "terrain_contact_depth",
                  "terrain_contact_normal_impulse", "terrain_contact_tangent_impulse", "terrain_contact_surface",
                  "terrain_contact_count", "terrain_contact_anchor_pos", "terrain_contact_anchor_quat")


def copy_of(sim: Simulator, contacts):
    out = sim.model.contacts(contacts.pair_max)
    for name in TERRAIN_ARRAYS:
        wp.copy(getattr(out, name), getattr(contacts, name))
    return out


def carried_against_searched(sim: Simulator):
    """The step's pass run twice from the live slots at the pose of now: carrying, and searching
    every body.  Returns (carried, searched) Contacts and which bodies were carried after moving."""
    h, margin = sim.config.dt, sim.config.speculative_margin
    carried, searched = copy_of(sim, sim.contacts), copy_of(sim, sim.contacts)
    sim.collide(sim.state, carried, h, margin)
    sim.collide(sim.state, searched, h, margin, carry_still=False)
    pos = sim.state.body_pos.numpy()
    moved_and_carried = np.any(carried.terrain_contact_anchor_pos.numpy() != pos, axis=1)
    return carried, searched, moved_and_carried


def prunable(sim: Simulator, body: int, slot: int) -> bool:
    """Whether the slot is an edge midpoint or the centre of the body's support face: a row the
    face's corners may bound (collide/bounded_points.py)."""
    local = sim.model.host["checkpoint_local"][slot]
    half = sim.model.body_size.numpy()[body]
    axis, sign = support_face(sim.model.terrain, sim.state.body_pos.numpy()[body], sim.state.body_rot.numpy()[body])
    return bool(local[axis] == sign * half[axis] and not np.all(np.abs(local) == half))


def pile(shape: str, seed: int, amplitude: float, device) -> Simulator:
    half = (0.3, 0.05, 0.3) if shape == "plate" else (0.25, 0.25, 0.25)
    return cases.terrain_drop(36, "box" if shape == "plate" else shape, terrain=FourierTerrain(amplitude=amplitude),
                              half_extents=half, body_contact=True, spacing=0.8, seed=seed, sleep=False,
                              device=device)


@pytest.mark.parametrize("shape", ["sphere", "box", "plate", "mix"])
@pytest.mark.parametrize("seed,amplitude", [(0, 0.5), (1, 0.3), (2, 0.8)])
def test_carried_contacts_are_the_searched_ones(shape, seed, amplitude, device):
    """After the pile has settled, at several later steps, the pass carrying still bodies against
    one searching every body, from the same slots at the same pose:

    - every slot the search opens is open carried (a closed slot is kept closed only where the
      module proves that it stays closed), but for a row the face's corners bound, closed at the
      anchor (collide/bounded_points.py), which may lie deeper than they by what the climb
      resolves;
    - a sphere's carried depth is the searched one to the search's resolution (a few float32 ulps
      of the coordinates) plus the curvature's k STILL_TRAVEL^2 / 2;
    - a box's deepest carried contact is its deepest point by the float64 oracle over its faces
      (tests/test_face_search.py) to what the face search is held to there (the oracle grid's
      interpolation error + 0.1 mm), plus STILL_TRAVEL / 2: the climb's result moves by up to
      0.05 mm when the box moves 3 micrometres (it stops on its gain and iteration limits), so
      carried and searched depths are each compared with the truth, not with each other."""
    sim = pile(shape, seed, amplitude, device)
    terrain = sim.model.terrain
    sim.step(150)
    carried_bodies = 0
    starts, counts = sim.model.host["body_checkpoint_start"], sim.model.host["body_checkpoint_count"]
    is_box = sim.model.host["body_shape"] == SHAPE_BOX
    margin = sim.config.speculative_margin
    for _ in range(4):
        sim.step(5)
        carried, searched, moved_and_carried = carried_against_searched(sim)
        carried_bodies += int(moved_and_carried.sum())
        open_searched = searched.terrain_contact_active.numpy() != 0
        open_carried = carried.terrain_contact_active.numpy() != 0
        for slot in np.flatnonzero(open_searched & ~open_carried):
            # only a row the corners bound may stay closed carried (collide/bounded_points.py): one
            # pruned at the anchor, which the search now keeps.  Pruned, it lay no deeper than the
            # blend of its face's corners, each taken at least at minus its window, so now no
            # deeper than the body's deepest carried row or the margin's width out (a corner out of
            # reach), plus the slack, what the climb resolves (0.1 mm, the face search's own
            # bound) and half the travel allowed
            body = int(np.searchsorted(starts, slot, side="right") - 1)
            assert prunable(sim, body, slot), slot
            rows = np.arange(starts[body], starts[body] + counts[body])
            held = max([carried.terrain_contact_depth.numpy()[r] for r in rows if open_carried[r]] + [-margin])
            excess = searched.terrain_contact_depth.numpy()[slot] - held
            assert excess <= FACE_SEARCH_GAIN + 1.0e-4 + STILL_TRAVEL / 2, (slot, excess)
        depth_carried = carried.terrain_contact_depth.numpy()
        depth_searched = searched.terrain_contact_depth.numpy()
        point = searched.terrain_contact_point.numpy()
        pos, rot, size = sim.state.body_pos.numpy(), sim.state.body_rot.numpy(), sim.model.body_size.numpy()
        for body in range(len(pos)):
            slots = np.arange(starts[body], starts[body] + counts[body])
            both = slots[open_searched[slots] & open_carried[slots]]
            if is_box[body]:
                if not open_carried[slots].any():
                    continue
                truth = oracle_depth(terrain, pos[body].astype(float), rot[body].astype(float), size[body])
                tolerance = grid_error(terrain, size[body]) + 1.0e-4 + STILL_TRAVEL / 2
                assert abs(depth_carried[slots][open_carried[slots]].max() - truth) <= tolerance, (body, truth)
            else:
                p = point[both]
                resolution = (1.0e-6 + 2.0e-7 * (np.abs(p[:, 0]) + np.abs(p[:, 2]))
                              + 4 * 1.2e-7 * np.linalg.norm(p, axis=1))
                tolerance = resolution + terrain.curvature_bound() * STILL_TRAVEL**2 / 2
                assert np.all(np.abs(depth_carried[both] - depth_searched[both]) <= tolerance), body
    # the pile is still, so bodies that moved a little were carried: the checks above had work
    assert carried_bodies >= 4 * 36 // 4, carried_bodies


def settled_mix(device, **config) -> Simulator:
    sim = cases.terrain_drop(16, "mix", terrain=FourierTerrain(amplitude=0.3), body_contact=True, spacing=0.9,
                             sleep=False, device=device, **config)
    sim.step(150)
    return sim


def test_a_terrain_edited_under_still_bodies_is_seen(device):
    """The terrain raised by 1 cm under a resting pile: carried slots would keep the old surface
    and leave every body 1 cm in; the edit forgets the anchors, so the pile is pushed out and
    rests on the new surface as a pile set down there does (within the same resting depth)."""
    sim = settled_mix(device)
    rest_depth = sim.max_penetration()
    sim.set_terrain(FourierTerrain(amplitude=0.3, offset=(0.0, 0.01, 0.0)))
    sim.step(60)
    assert sim.max_penetration() <= rest_depth + 1.0e-3


def test_a_settings_change_searches_every_body_again(device):
    """update_settings forgets the anchors: the next pass searches all, as with carrying off."""
    sim = settled_mix(device)
    sim.update_settings(speculative_margin=0.03)
    h, margin = sim.config.dt, sim.config.speculative_margin
    anchors = sim.contacts.terrain_contact_anchor_pos.numpy()
    assert np.all(anchors > 1.0e29)
    sim.collide(sim.state, sim.contacts, h, margin)
    dynamic = sim.model.host["body_inv_mass"] > 0
    internal = sim.state.body_pos.numpy()
    assert np.array_equal(sim.contacts.terrain_contact_anchor_pos.numpy()[dynamic], internal[dynamic])


def test_a_still_body_moved_by_hand_is_searched_again(device):
    """A resting body pushed 5 cm down into the terrain by writing its position: its travel from
    the anchor exceeds STILL_TRAVEL, so its slots are searched, see the depth and push it out."""
    sim = settled_mix(device)
    pos = sim.state.body_pos.numpy()
    pos[3, 1] -= 0.05
    sim.state.body_pos.assign(pos)
    carried, searched, _ = carried_against_searched(sim)
    deepest = searched.terrain_contact_depth.numpy()[searched.terrain_contact_active.numpy() != 0].max()
    assert deepest > 0.04
    assert carried.terrain_contact_depth.numpy()[carried.terrain_contact_active.numpy() != 0].max() == deepest


def test_carrying_off_searches_every_body(device):
    sim = settled_mix(device, still_contacts=False)
    sim.step(5)
    dynamic = sim.model.host["body_inv_mass"] > 0
    h, margin = sim.config.dt, sim.config.speculative_margin
    anchors = sim.contacts.terrain_contact_anchor_pos.numpy()
    assert np.all(anchors > 1.0e29)  # never written
    carried, searched, _ = carried_against_searched(sim)
    assert np.array_equal(carried.terrain_contact_depth.numpy(), searched.terrain_contact_depth.numpy())
    assert dynamic.any()


@pytest.mark.parametrize("speed", [0.0009, 0.005])
def test_a_slot_that_would_open_is_open_when_carried(speed, device):
    """Zero gravity: a ball sinking at ``speed`` (under STILL_SPEED) sits just beyond its slot's
    window, margin + h v + 5 micrometres from the surface, when its slots are found; then it moves
    10 micrometres (under STILL_TRAVEL), and the search would open the slot.  Carried, it must be
    open too: the windows found with the floor's approach speed (still_contacts.window_floor)
    opened it at the anchor already.  With the window found at the ball's own speed, the carried
    slot stayed closed while the searched one opened."""
    terrain = FourierTerrain(amplitude=0.5)
    b = ModelBuilder()
    b.set_terrain(terrain)
    b.add_sphere(0.25, 1.0, position=(0.3, float(terrain.height(0.3, 0.2)) + 1.0, 0.2), velocity=(0.0, -speed, 0.0))
    sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, device=device))
    h, margin = sim.config.dt, sim.config.speculative_margin
    probe = sim.model.contacts()
    pos = sim.state.body_pos.numpy()
    for _ in range(4):  # lowered along y: the closest distance closes by n_y a metre
        sim.collide(sim.state, probe, h, 1.0, carry_still=False)
        gap = -float(probe.terrain_contact_depth.numpy()[0])
        pos[0, 1] -= (gap - (margin + h * speed + 5.0e-6)) / float(probe.terrain_contact_normal.numpy()[0][1])
        sim.state.body_pos.assign(pos)
    sim.collide(sim.state, sim.contacts, h, margin)  # the anchor
    pos[0, 1] -= 1.0e-5
    sim.state.body_pos.assign(pos)
    carried, searched, _ = carried_against_searched(sim)
    assert searched.terrain_contact_active.numpy()[0] == 1
    assert carried.terrain_contact_active.numpy()[0] == 1


def test_sleepers_have_no_anchor_and_are_searched_when_woken(device):
    """A sleeper's mass is hidden from the step, so its slots are not found while it sleeps and it
    keeps no anchor; woken, it is searched in full at the next pass (not carried from slots that
    were found, or left closed, while it slept)."""
    sim = cases.terrain_drop(16, "mix", terrain=FourierTerrain(amplitude=0.3), body_contact=True, spacing=0.9,
                             sleep=True, device=device)
    sim.step(240)
    awake = sim.awake_count()
    assert awake < 16  # the pile has fallen asleep
    anchors = sim.contacts.terrain_contact_anchor_pos.numpy()
    asleep = sim.physics_model.body_inv_mass.numpy() == 0.0
    assert asleep.any() and np.all(anchors[asleep] > 1.0e29)
    sim.wake_all()
    carried, _, moved_and_carried = carried_against_searched(sim)
    # the pass after the wake searched every woken body: its anchor is its pose of now
    assert not moved_and_carried[asleep].any()
    np.testing.assert_array_equal(carried.terrain_contact_anchor_pos.numpy()[asleep], sim.state.body_pos.numpy()[asleep])
