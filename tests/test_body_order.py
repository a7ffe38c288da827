"""Bodies stored sorted (body_order.py): the order is a deterministic permutation that groups
shapes and keeps neighbours together, and whatever a user sees (physics read in scene order,
recordings, checkpoints, the body an error names) is the scene's order."""

import json

import numpy as np
import pytest

from warp_sim import ModelBuilder, NonFiniteStateError, SimConfig, Simulator, cases
from warp_sim.body_order import body_order, inverse_order, morton_cells, morton_codes
from warp_sim.cli import main
from warp_sim.recording import load_checkpoint, load_run, restore_checkpoint, save_checkpoint
from warp_sim.scene import SceneError, load_scene, parse_scene_text
from warp_sim.types import SHAPE_BOX, SHAPE_SPHERE
from warp_sim.validation import ValidationError

RAIN = dict(body_contact=True, spacing=0.9, sleep=False, rolling_resistance=0.2, pair_schedule="domains")

SCENE = """
name = "sorted"
[sim]
dt = 0.01
substeps = 2
body_order = "shape_morton"
[terrain]
kind = "fourier"
terms = 3
[[body]]
shape = "box"
half_extents = [0.2, 0.2, 0.2]
position = [4.0, 3.0, 4.0]
[[layout]]
type = "grid"
count = [4, 1, 4]
shape = "mix"
random_orientation = true
spacing = 0.9
"""


def shuffled_grid(side: int, seed: int = 0):
    """A side^3 lattice (1 m apart) of alternating spheres and boxes, listed in a random order."""
    g = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.float64)
    shape = np.where(np.arange(len(g)) % 2 == 0, SHAPE_SPHERE, SHAPE_BOX)
    perm = np.random.default_rng(seed).permutation(len(g))
    return shape[perm], g[perm]


def test_morton_code_interleaves_the_cells():
    """Against a bit-by-bit interleave: bit k of x, y, z goes to bits 3k + 2, 3k + 1, 3k."""
    rng = np.random.default_rng(1)
    p = rng.uniform(-50.0, 50.0, (500, 3))
    cells, codes = morton_cells(p), morton_codes(p)
    assert cells.min() >= 0 and cells.max() <= 1023 and codes.dtype == np.uint32
    expected = np.zeros(len(p), np.uint64)
    for k in range(10):
        for axis, shift in ((0, 2), (1, 1), (2, 0)):
            expected |= ((cells[:, axis].astype(np.uint64) >> k) & 1) << (3 * k + shift)
    np.testing.assert_array_equal(codes, expected)
    # one cube over the largest extent: a flat scene keeps its thin axis in few cells
    flat = np.stack([rng.uniform(0, 100, 200), rng.uniform(0, 1, 200), rng.uniform(0, 100, 200)], axis=1)
    assert morton_cells(flat)[:, 1].max() <= 11
    assert morton_codes(np.zeros((3, 3))).tolist() == [0, 0, 0]  # one point: no extent, one cell


@pytest.mark.parametrize("mode", ["scene", "morton", "shape_morton"])
def test_order_is_a_deterministic_permutation(mode):
    shape, position = shuffled_grid(8)
    order = body_order(shape, position, mode)
    assert order.dtype == np.int64
    np.testing.assert_array_equal(np.sort(order), np.arange(len(shape)))
    np.testing.assert_array_equal(order, body_order(shape.copy(), position.copy(), mode))
    np.testing.assert_array_equal(inverse_order(order)[order], np.arange(len(shape)))
    if mode == "scene":
        np.testing.assert_array_equal(order, np.arange(len(shape)))


def test_shape_morton_groups_shapes_and_puts_static_bodies_last():
    shape, position = shuffled_grid(6)
    static = np.zeros(len(shape), bool)
    static[::7] = True
    order = body_order(shape, position, "shape_morton", static=static)
    groups = np.where(static[order], 2 + shape[order], shape[order])  # 0, 1: dynamic spheres, boxes; 2, 3: static
    assert np.all(np.diff(groups) >= 0)
    assert set(groups) == {0, 1, 2, 3}
    codes = morton_codes(position)[order]
    for g in range(4):  # Morton order within each group
        assert np.all(np.diff(codes[groups == g].astype(np.int64)) >= 0)


def test_morton_neighbours_are_near():
    """Consecutive bodies of a shuffled 16^3 lattice are ~10 m apart on average (a random pair in a
    15 m cube); in Morton order most steps are to a lattice neighbour (1 m), with rarer jumps
    between octants: several-fold closer, per shape group too."""
    shape, position = shuffled_grid(16)

    def mean_step(p):
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).mean())

    before = mean_step(position)
    assert before > 8.0
    assert mean_step(position[body_order(shape, position, "morton")]) < before / 5
    order = body_order(shape, position, "shape_morton")
    spheres = order[shape[order] == SHAPE_SPHERE]
    assert mean_step(position[spheres]) < before / 5


def test_bad_body_order_is_one_clear_error():
    b = ModelBuilder()
    b.add_sphere(0.1)
    message = "body_order must be one of scene, morton, shape_morton, got 'hilbert'"
    with pytest.raises(ValidationError, match=message):
        b.finalize("cpu", body_order="hilbert")
    with pytest.raises(ValidationError, match=message):
        body_order([0], [[0.0, 0.0, 0.0]], "hilbert")
    with pytest.raises(SceneError) as info:
        parse_scene_text(SCENE.replace('"shape_morton"', '"z_order"'), "bad.toml")
    assert str(info.value) == ("bad.toml: [sim] body_order must be one of scene, morton, shape_morton, "
                               "got 'z_order'")
    with pytest.raises(SceneError, match=r"\[sim\] body_order must be one of .*, got 3"):
        parse_scene_text(SCENE.replace('"shape_morton"', "3"), "bad.toml")


def test_scene_order_is_the_builder_as_before_and_a_sorted_model_is_its_permutation():
    """"scene" applies no permutation (every host array as finalize() gives it); a sorted Model's
    per-body arrays are the scene's rows in its order, checkpoints included."""
    b = cases.terrain_drop_builder(30, "mix", spacing=0.9)
    plain, scene, sorted_ = b.finalize("cpu"), b.finalize("cpu", body_order="scene"), \
        b.finalize("cpu", body_order="shape_morton")
    for key, value in plain.host.items():
        np.testing.assert_array_equal(scene.host[key], value, err_msg=key)
    np.testing.assert_array_equal(scene.body_scene_index, np.arange(30))
    order = sorted_.body_scene_index
    assert sorted_.body_order == "shape_morton" and not np.array_equal(order, np.arange(30))
    np.testing.assert_array_equal(sorted_.body_internal_index[order], np.arange(30))
    for key in ("body_shape", "body_size", "body_inv_mass", "body_inertia", "body_pos", "body_quat", "body_rot",
                "body_vel", "body_angmom", "body_checkpoint_count", "body_friction"):
        np.testing.assert_array_equal(sorted_.host[key], plain.host[key][order], err_msg=key)
        np.testing.assert_array_equal(sorted_.to_scene_order(sorted_.host[key]), plain.host[key], err_msg=key)
    for i in range(30):  # each body's terrain checkpoints moved with it
        s, p = sorted_.host, plain.host
        a = slice(s["body_checkpoint_start"][i], s["body_checkpoint_start"][i] + s["body_checkpoint_count"][i])
        j = order[i]
        c = slice(p["body_checkpoint_start"][j], p["body_checkpoint_start"][j] + p["body_checkpoint_count"][j])
        np.testing.assert_array_equal(s["checkpoint_local"][a], p["checkpoint_local"][c])
        assert np.all(s["checkpoint_body"][a] == i)
    np.testing.assert_array_equal(sorted_.from_scene_order(plain.host["body_pos"]), sorted_.host["body_pos"])


def test_sorted_rain_is_the_same_physics_in_scene_order():
    """40 mixed bodies with body contact fall on the terrain, stored in scene and in shape_morton
    order, read back in scene order.

    - Free fall and terrain contacts are per body: the same arithmetic on the same numbers in
      either order, so every step is bit-identical until a body-body pair is found.
    - After that the pair sweeps visit the bodies in another order.  A sweep stops once a pass
      changes velocities by less than the larger of convergence_tolerance (1e-5 m/s) and
      convergence_gravity_share g h (0.01 x 9.81 x h = 4.1e-4 m/s at h = 1/240 s), so the two orders
      may stop on iterates that far apart, each substep, on the bodies in contact.  Over the
      ~0.5 s the bodies spend in contact here that is at most ~4e-4 m/s x 0.5 s x 2 (a pile passes
      differences on) ~ 0.5 mm; the test allows 2 mm (0.8 % of a ball's radius; measured 1e-7 m).
      Total energy KE + m g y then differs by at most sum m (g dy + v dv): 40 x (9.81 x 2e-3 +
      5 x 4.1e-4) = 0.87 J, against ~800 J."""
    a = cases.terrain_drop(40, "mix", **RAIN)
    b = cases.terrain_drop(40, "mix", body_order="shape_morton", **RAIN)
    assert b.model.body_order == "shape_morton" and a.substeps == b.substeps
    shapes = b.model.host["body_shape"]
    assert np.all(np.diff(shapes) >= 0)  # spheres first, then boxes

    def scene_state(sim):
        m = sim.model
        return [m.to_scene_order(x) for x in (sim.state.body_pos, sim.state.body_quat, sim.state.body_vel,
                                              sim.state.body_angmom)]

    def energy(sim):
        pos = sim.model.to_scene_order(sim.state.body_pos).astype(np.float64)
        return sim.kinetic_energy() + float(np.sum(sim.model.body_mass * cases.GRAVITY * pos[:, 1]))

    no_pairs = 0
    for step in range(60):
        a.step(1)
        b.step(1)
        if int(a.contacts.pair_count.numpy()[0]) or int(b.contacts.pair_count.numpy()[0]):
            break
        no_pairs = step + 1
        for x, y in zip(scene_state(a), scene_state(b)):
            np.testing.assert_array_equal(x, y, err_msg=f"step {step + 1}")
    assert no_pairs >= 20, "the bit-identical phase should cover the fall and the landing on the terrain"
    a.step(59 - no_pairs)
    b.step(59 - no_pairs)
    pa, pb = (sim.model.to_scene_order(sim.state.body_pos) for sim in (a, b))
    assert np.abs(pa - pb).max() <= 2e-3
    assert abs(energy(a) - energy(b)) <= 0.87
    assert int(a.contacts.pair_count.numpy()[0]) > 0  # the comparison did include body-body contact


def test_non_finite_error_names_the_scene_index():
    """The spinning box (scene body 0) is stored after the sphere in shape_morton order."""
    b = ModelBuilder()
    b.add_box((0.1, 0.4, 0.2), 1.0, angular_velocity=(0.0, 0.0, 100.0))
    b.add_sphere(0.1, 1.0, position=(10.0, 0.0, 0.0))  # far away: it stays finite
    model = b.finalize("cpu", body_order="shape_morton")
    assert model.body_scene_index.tolist() == [1, 0]
    sim = Simulator(model, SimConfig(dt=0.01, substeps=1, integrator="explicit_euler", rotation="matrix",
                                     gravity=(0, 0, 0)))
    with pytest.raises(NonFiniteStateError, match=r"body 0 \(box\) became non-finite") as info:
        for _ in range(200):
            sim.step()
    assert info.value.body == 0


def test_recording_is_in_scene_order_and_resumes_bit_for_bit(tmp_path, capsys):
    """A run of a sorted scene records frames, shapes and sizes in scene order (its first frame is
    the scene's starting positions); a checkpoint (kept in the internal order, with the order)
    resumes bit for bit, and refuses a simulator that stores the bodies in another order; ``info``
    says which order the bodies are stored in."""
    path = tmp_path / "sorted.toml"
    path.write_text(SCENE)
    scene = load_scene(path)
    columns = scene.builder.columns()
    a, b, c = (tmp_path / f"{n}.npz" for n in "abc")
    assert main(["run", str(path), "--steps", "16", "--out", str(a), "--quiet"]) == 0
    straight = load_run(a)
    np.testing.assert_array_equal(straight["position"][0], columns["position"].astype(np.float32))
    np.testing.assert_array_equal(straight["shape"], columns["shape"])
    assert straight["shape"][0] == SHAPE_BOX  # scene body 0 is the box, stored after the spheres
    assert straight["metadata"]["body_order"] == "shape_morton"
    assert main(["info", str(path)]) == 0
    assert "order       bodies stored in shape_morton order" in capsys.readouterr().out

    assert main(["run", str(path), "--steps", "8", "--checkpoint-every", "8", "--out", str(b), "--quiet"]) == 0
    checkpoint = tmp_path / "b.checkpoint.npz"
    with np.load(checkpoint) as data:
        assert json.loads(str(data["info"]))["body_order"] == "shape_morton"
    assert main(["run", "--resume", str(checkpoint), "--steps", "16", "--out", str(c), "--quiet"]) == 0
    resumed = load_run(c)
    for key in ("position", "orientation", "velocity", "angular_velocity", "kinetic_energy", "contact_count"):
        np.testing.assert_array_equal(straight[key][8:], resumed[key], err_msg=key)

    scene.body_order = "scene"
    info, arrays = load_checkpoint(checkpoint)
    with pytest.raises(ValueError, match="body_order 'shape_morton', this simulator in 'scene'"):
        restore_checkpoint(scene.build("cpu"), info, arrays)


def test_api_checkpoint_round_trip_keeps_the_order(tmp_path):
    """save_checkpoint / restore_checkpoint on a sorted Simulator: the arrays go back as they were."""
    sim = cases.terrain_drop(12, "mix", body_order="morton", **RAIN)
    sim.step(5)
    save_checkpoint(tmp_path / "x.npz", sim, {"note": "test"})
    other = cases.terrain_drop(12, "mix", body_order="morton", **RAIN)
    restore_checkpoint(other, *load_checkpoint(tmp_path / "x.npz"))
    sim.step(5)
    other.step(5)
    np.testing.assert_array_equal(sim.state.body_pos.numpy(), other.state.body_pos.numpy())
