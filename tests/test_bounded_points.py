"""A support-face checkpoint the corners already hold holds no row (collide/bounded_points.py).

The same collision pass is run with ``prune_face_points`` on and off on boxes at random poses set
into curved ground, and the rule is checked from the full pass's depths in NumPy: the pruned pass
differs from the full one exactly by the non-corner support-face rows no deeper than the bilinear
blend of the face's corner depths (plus the slack), and its deepest contact is the same.  Then
what the rule is for: on ground flat under the face the four corners alone hold a resting box,
over a crest between them the midpoint's row stays, and boxes dropped on curved ground settle as
deep with the rule as without it.
"""

import math

import numpy as np
import pytest

from warp_sim import FourierTerrain, ModelBuilder, SimConfig, Simulator, cases
from warp_sim.builder import quats_to_matrices

# the rule's slack (bounded_points.py): FACE_SEARCH_GAIN plus 1e-7 per metre from the origin
FACE_SEARCH_GAIN = 1.0e-5
SLACK_RATE = 1.0e-7

TERRAINS = {
    "wave": FourierTerrain(terms=2, frequency=1.0, amplitude=0.3, amplitudes=np.array([[0.0, 0.0], [1.0, 0.0]]),
                           phases=np.zeros((2, 2))),
    "default": cases.DEFAULT_TERRAIN,
    "rough": FourierTerrain(terms=3, frequency=0.5, amplitude=0.5, seed=7),
}
SIZES = [(0.25, 0.25, 0.25), (0.5, 0.5, 0.5), (0.6, 0.1, 0.4)]


def random_boxes(terrain, half, seed: int, count: int = 24):
    """Boxes at random headings, tilted up to 6 degrees, their centres 0 to 40 mm lower than where
    the lowest face point would touch the surface below it (a coarse NumPy search)."""
    rng = np.random.default_rng(seed)
    b = ModelBuilder()
    b.set_terrain(terrain)
    g = np.linspace(-1.0, 1.0, 9)
    grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3) * np.asarray(half)
    for _ in range(count):
        yaw = rng.uniform(0.0, 2.0 * math.pi)
        axis = rng.normal(size=3)
        axis[1] = 0.0
        axis /= np.linalg.norm(axis)
        tilt = rng.uniform(0.0, math.radians(6.0))
        q_yaw = np.array([0.0, math.sin(yaw / 2), 0.0, math.cos(yaw / 2)])
        q_tilt = np.append(axis * math.sin(tilt / 2), math.cos(tilt / 2))
        v1, w1, v2, w2 = q_tilt[:3], q_tilt[3], q_yaw[:3], q_yaw[3]
        q = np.append(w1 * v2 + w2 * v1 + np.cross(v1, v2), w1 * w2 - v1 @ v2)
        rot = quats_to_matrices(q[None])[0]
        x, z = rng.uniform(-20.0, 20.0, 2)
        p = grid @ rot.T + np.array([x, 0.0, z])
        y = float(np.max(terrain.height(p[:, 0], p[:, 2]) - p[:, 1])) - rng.uniform(0.0, 0.04)
        b.add_box(half, 1.0, position=(x, y, z), orientation=tuple(q))
    return b


def collide(builder, device, prune: bool, margin: float = 0.02):
    """One collision pass; the default speculative margin keeps rows within 2 cm of the surface
    open, so a face's middle rows are open beside its corners.  A margin of metres opens (and
    samples) every checkpoint: the cull skips none and no window closes one."""
    sim = Simulator(builder.finalize(device), SimConfig(sleep=False, device=device, prune_face_points=prune))
    probe = sim.model.contacts()
    sim.collide(sim.state, probe, 1.0 / 240.0, margin)
    return sim, probe.terrain_contact_active.numpy() != 0, probe.terrain_contact_depth.numpy()


def support_face(terrain, pos, rot):
    """(axis, sign) of the face whose outward normal points most down the surface normal under the
    centre (face_search.support_face)."""
    gx, gz = terrain.gradient(np.array([pos[0]]), np.array([pos[2]]))
    down = -np.array([-gx[0], 1.0, -gz[0]])
    c = rot.T @ down  # the world direction in body axes
    axis = int(np.argmax(np.abs(c)))
    return axis, 1 if c[axis] > 0.0 else -1


def corner_blend(local, half, axis: int, sign: int, depth, j: int):
    """The bilinear blend of the support face's corner depths at checkpoint j (bounded_points.py);
    None where j is not a non-corner point of that face."""
    h = np.asarray(half, dtype=np.float32)
    on_face = local[:, axis] == sign * h[axis]
    corner = np.all(np.abs(local) == h, axis=1)
    if not on_face[j] or corner[j]:
        return None
    a, b = (axis + 1) % 3, (axis + 2) % 3
    ta, tb = 0.5 * (local[j, a] / h[a] + 1.0), 0.5 * (local[j, b] / h[b] + 1.0)
    blend = 0.0
    for c in np.flatnonzero(on_face & corner):
        blend += (ta if local[c, a] > 0 else 1 - ta) * (tb if local[c, b] > 0 else 1 - tb) * depth[c]
    return blend


@pytest.mark.parametrize("terrain_name", list(TERRAINS))
@pytest.mark.parametrize("half", SIZES)
def test_only_rows_the_corners_bound_are_pruned(terrain_name, half, device):
    """The rule, exactly, where every checkpoint is sampled (a margin of metres): the pruned pass
    keeps every row of the full pass but the non-corner support-face rows no deeper than the blend
    of the corners plus the slack.  At the default margin: a subset of the full pass's rows, with
    the same depths and the same deepest contact to the slack."""
    terrain = TERRAINS[terrain_name]
    builder = random_boxes(terrain, half, seed=len(terrain_name) + int(100 * half[1]))
    sim, every, depth = collide(builder, device, prune=False, margin=10.0)
    _, kept, _ = collide(builder, device, prune=True, margin=10.0)
    _, full, depth_full = collide(builder, device, prune=False)
    _, pruned, depth_pruned = collide(builder, device, prune=True)
    local = sim.model.host["checkpoint_local"]
    starts, counts = sim.model.host["body_checkpoint_start"], sim.model.host["body_checkpoint_count"]
    pos, rot = sim.state.body_pos.numpy(), sim.state.body_rot.numpy()
    h = np.asarray(half, dtype=np.float32)
    closed = 0
    for k in range(len(starts)):
        s = slice(starts[k], starts[k] + counts[k])
        loc, d = local[s], depth[s]
        assert every[s].all(), k
        axis, sign = support_face(terrain, pos[k], rot[k])
        assert np.sum((loc[:, axis] == sign * h[axis]) & np.all(np.abs(loc) == h, axis=1)) == 4
        slack = FACE_SEARCH_GAIN + SLACK_RATE * (abs(pos[k][0]) + abs(pos[k][2]))
        for j in range(len(loc)):
            blend = corner_blend(loc, half, axis, sign, d, j)
            expect_kept = blend is None or d[j] > blend + slack
            assert kept[s][j] == expect_kept, (k, j, d[j], blend)
            closed += int(not expect_kept)
        # the default margin: a subset with the same depths and the same deepest contact
        assert full[s].any() and not (pruned[s] & ~full[s]).any(), k
        np.testing.assert_array_equal(depth_pruned[s][pruned[s]], depth_full[s][pruned[s]])
        assert depth_full[s][pruned[s]].max() >= depth_full[s][full[s]].max() - slack, k
    assert closed > 0  # the rule was exercised


def resting_rows(terrain, half, x: float, device, prune: bool = True):
    """Active terrain rows of a level cube set 1 mm into the ground under its centre at x."""
    b = ModelBuilder()
    b.set_terrain(terrain)
    y = float(terrain.height(np.array([x]), np.array([0.0]))[0]) + half - 0.001
    b.add_box((half,) * 3, 1.0, position=(x, y, 0.0))
    _, active, depth = collide(b, device, prune)
    return int(active.sum()), depth[active]


@pytest.mark.parametrize("half", [0.1, 0.25])
def test_a_box_on_a_trough_rests_on_its_corners_and_on_a_crest_keeps_its_middle(half, device):
    """H = 0.3 cos x: a level cube centred over the trough (x = pi) touches at its corners only,
    whatever the middle rows would say; centred over the crest (x = 0) its bottom face's centre is
    the deepest point, and its row stays."""
    terrain = TERRAINS["wave"]
    trough_rows, _ = resting_rows(terrain, half, math.pi, device)
    trough_full, _ = resting_rows(terrain, half, math.pi, device, prune=False)
    assert trough_rows == 4 < trough_full
    crest_rows, crest_depth = resting_rows(terrain, half, 0.0, device)
    assert crest_rows > 0
    assert crest_depth.max() == pytest.approx(0.001, abs=1.0e-4)  # the centre's depth, by construction


@pytest.mark.parametrize("terrain_name", ["default", "rough"])
def test_pruned_boxes_settle_as_deep_as_boxes_with_every_row(terrain_name, device):
    """60 cubes dropped on curved ground, 4 s: the deepest of them, with and without the rule, within
    one resting sag's 1/7 (FACE_SEARCH_GAIN's 0.01 mm, the slack) plus 0.1 mm (float32 and the
    climb's stop, as in test_face_search.py), and as many at rest."""
    figures = []
    for prune in (True, False):
        sim = cases.terrain_drop(60, "box", terrain=TERRAINS[terrain_name], half_extents=(0.25,) * 3, spacing=0.8,
                                 sleep=False, seed=5, device=device, prune_face_points=prune)
        sim.step(240, check=False)
        before = sim.state.body_pos.numpy().copy()
        sim.step(60)
        moved = np.linalg.norm(sim.state.body_pos.numpy() - before, axis=1)
        figures.append((sim.max_penetration(), int((moved < 1.0e-3).sum())))
    (deep_pruned, still_pruned), (deep_full, still_full) = figures
    assert deep_pruned <= deep_full + FACE_SEARCH_GAIN + 1.0e-4, figures
    assert still_pruned >= still_full - 1, figures
