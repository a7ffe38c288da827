"""Scene files: the examples load, every bad key is named in one line, layouts place bodies well."""

import copy
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from warp_sim.builder import quat_to_matrix
from warp_sim.layouts import down_extent
from warp_sim.scene import SIM_SCHEMA, SceneError, load_scene, parse_scene
from warp_sim.simulator import SimConfig
from warp_sim.terrain import FourierTerrain, NoTerrain, PlaneTerrain
from warp_sim.types import SHAPE_SPHERE

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples" / "scenes").glob("*.toml"))

BASE = {
    "name": "base",
    "sim": {"dt": 0.01, "seed": 3},
    "terrain": {"kind": "fourier", "terms": 3},
    "material": {"friction": 0.5},
    "body": [
        {"shape": "sphere", "radius": 0.2, "position": [0, 2, 0]},
        {"shape": "box", "half_extents": [0.1, 0.2, 0.3], "position": [1, 2, 0]},
    ],
}


def scene_with(**changes):
    """BASE with top-level entries replaced (a value of None deletes the entry)."""
    data = copy.deepcopy(BASE)
    for key, value in changes.items():
        if value is None:
            data.pop(key, None)
        else:
            data[key] = value
    return data


def body(**keys):
    return {"body": [{"shape": "sphere", "radius": 0.2, **keys}]}


def box(**keys):
    return {"body": [{"shape": "box", "half_extents": [0.1, 0.2, 0.3], **keys}]}


def grid(**keys):
    return {"body": None, "layout": [{"type": "grid", "count": 4, **keys}]}


def body_corners(b) -> np.ndarray:
    """World points of a body's lowest features: the 8 box corners, or the sphere's bottom point."""
    if b["shape"] == SHAPE_SPHERE:
        return (b["position"] - np.array([0.0, b["size"][0], 0.0]))[None]
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    return b["position"] + (signs * b["size"]) @ quat_to_matrix(b["orientation"]).T


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_scene_loads_and_steps(path):
    """Every example parses, builds on the CPU and takes one finite step."""
    scene = load_scene(path)
    assert scene.body_count > 0
    sim = scene.build("cpu")
    assert sim.model.body_count == scene.body_count
    sim.step(1)
    assert np.isfinite(sim.state.body_pos.numpy()).all()


def test_examples_are_the_documented_set():
    """The scenes the README names are all there."""
    names = {p.stem for p in EXAMPLES}
    assert {"balls_on_terrain", "boxes_on_terrain", "spinning_box", "bounce", "slope", "mixed_rain"} <= names


def test_values_reach_the_model():
    """Keys land in SimConfig, the terrain, the material and the bodies; omitted keys keep defaults."""
    data = scene_with(
        sim={"dt": 0.02, "substeps": 2, "gravity": [0, -1, 0], "integrator": "rk4",
             "rotation": "matrix_cross", "contact_max": 16},
        terrain={"kind": "plane", "normal": [0, 2, 0], "offset": 0.5, "checkpoints_per_edge": 3},
        material={"restitution": 0.3, "friction_model": "slipperiness", "slipperiness": 0.25},
        body=[{"shape": "box", "half_extents": [0.1, 0.2, 0.3], "mass": 2, "orientation": [0, 0, 0, 2],
               "angular_velocity": [0, 1, 0], "static": True, "friction": 0.9}],
    )
    scene = parse_scene(data, "x.toml")
    c = scene.config
    assert (c.dt, c.substeps, c.gravity, c.integrator, c.rotation, c.contact_max) == (
        0.02, 2, (0.0, -1.0, 0.0), "rk4", "matrix_cross", 16)
    assert c.iterations == SimConfig().iterations
    assert isinstance(scene.terrain, PlaneTerrain) and scene.terrain.normal == (0.0, 1.0, 0.0)
    assert scene.checkpoints_per_edge == 3
    assert scene.builder.material.effective_friction() == pytest.approx(0.75)
    b = scene.builder.bodies[0]
    assert b["mass"] == 2.0 and b["static"] and b["friction"] == 0.9
    assert b["restitution"] == pytest.approx(0.3)  # from [material]
    np.testing.assert_allclose(b["orientation"], [0, 0, 0, 1])
    model = scene.build("cpu").model
    assert model.host["checkpoints_per_edge"] == 3


def test_sim_table_covers_every_setting():
    """Each SimConfig field is a [sim] key (or documented as living elsewhere), and only those."""
    fields = {f.name for f in dataclasses.fields(SimConfig)}
    assert fields == set(SIM_SCHEMA)


def test_terrain_defaults_to_none_and_tables_replace_the_draw():
    """No [terrain] table means no terrain; explicit amplitude/phase tables reach FourierTerrain."""
    assert isinstance(parse_scene(scene_with(terrain=None)).terrain, NoTerrain)
    table = [[0.0, 1.0], [0.5, 0.25]]
    terrain = {"kind": "fourier", "terms": 2, "amplitudes": table, "phases": table}
    t = parse_scene(scene_with(terrain=terrain)).terrain
    assert isinstance(t, FourierTerrain)
    np.testing.assert_array_equal(t.base_tables()[0], table)


def test_build_device_override_leaves_the_scene_alone():
    """build(device) uses a copy of the config, so two simulators never share settings."""
    scene = parse_scene(scene_with())
    sim = scene.build("cpu")
    sim.update_settings(dt=0.5)
    assert scene.config.dt == 0.01


# Each case: top-level changes to BASE, then the strings the one-line message must contain.
PLANE = {"kind": "plane"}
FOURIER = {"kind": "fourier"}
BAD = {
    "unknown top-level key": ({"simulation": {}}, ["unknown top-level key 'simulation'", "sim, terrain"]),
    "unknown sim key": ({"sim": {"dtt": 0.01}}, ["unknown key [sim] dtt", "known: dt, substeps"]),
    "unknown body key": (body(colour="red"), ["unknown key [[body]] #1 colour"]),
    "unknown layout key": (grid(size=3), ["unknown key [[layout]] #1 (grid) size"]),
    "name not a string": ({"name": 3}, ["name must be a string, got 3"]),
    "sim not a table": ({"sim": 3}, ["[sim] must be a table, got 3"]),
    "body not an array of tables": ({"body": {"shape": "sphere"}}, ["body must be an array of tables"]),
    "body entry not a table": ({"body": [1]}, ["[[body]] #1 must be a table, got 1"]),
    "negative dt": ({"sim": {"dt": -0.01}}, ["[sim] dt must be a number in [1e-06, 1], got -0.01"]),
    "nan dt": ({"sim": {"dt": math.nan}}, ["[sim] dt", "got nan"]),
    "inf in gravity": ({"sim": {"gravity": [0, -math.inf, 0]}},
                       ["[sim] gravity must be 3 finite numbers, got [0, -inf, 0]"]),
    "beyond float32": (body(position=[1e39, 0, 0]), ["[[body]] #1 position", "1e+39"]),
    "bool as integer": ({"sim": {"substeps": True}}, ["[sim] substeps must be an integer in [1, 4096], got true"]),
    "bool as number": (body(mass=True), ["[[body]] #1 mass", "got true"]),
    "float as integer": ({"sim": {"substeps": 2.5}}, ["[sim] substeps", "got 2.5"]),
    "string as number": ({"sim": {"duration": "5"}}, ["[sim] duration", "got '5'"]),
    "zero substeps": ({"sim": {"substeps": 0}}, ["[sim] substeps", "got 0"]),
    "negative seed": ({"sim": {"seed": -1}}, ["[sim] seed must be an integer >= 0, got -1"]),
    "unknown integrator": (
        {"sim": {"integrator": "rk5"}},
        ["[sim] integrator must be one of explicit_euler, semi_implicit, verlet, rk4, got 'rk5'"]),
    "unknown rotation": ({"sim": {"rotation": "euler"}},
                         ["[sim] rotation must be one of quaternion", "got 'euler'"]),
    "bad device": ({"sim": {"device": "tpu"}}, ["[sim] device", "got 'tpu'"]),
    "unknown body order": ({"sim": {"body_order": "hilbert"}},
                           ["[sim] body_order must be one of scene, morton, shape_morton, got 'hilbert'"]),
    "unknown terrain kind": ({"terrain": {"kind": "mountains"}},
                             ["[terrain] kind must be one of fourier, plane, none, got 'mountains'"]),
    "too many terms": ({"terrain": {**FOURIER, "terms": 33}}, ["[terrain] terms", "[1, 32]", "got 33"]),
    "zero scale": ({"terrain": {**FOURIER, "scale": [1, 0, 1]}}, ["[terrain] scale", "got [1, 0, 1]"]),
    "amplitudes wrong shape": ({"terrain": {**FOURIER, "terms": 3, "amplitudes": [[1, 2], [3, 4]]}},
                               ["[terrain] amplitudes", "3 x 3", "got a 2 x 2 array [[1, 2], [3, 4]]"]),
    "phases ragged": ({"terrain": {**FOURIER, "terms": 2, "phases": [[1, 2], [3]]}},
                      ["[terrain] phases must be a 2-D array", "got [[1, 2], [3]]"]),
    "plane normal zero": ({"terrain": {**PLANE, "normal": [0, 0, 0]}},
                          ["[terrain] normal must be a non-zero vector of 3 finite numbers, got [0, 0, 0]"]),
    "key of the other terrain kind": ({"terrain": {**PLANE, "frequency": 1.0}},
                                      ["unknown key [terrain] frequency for kind 'plane'"]),
    "too few checkpoints": ({"terrain": {**PLANE, "checkpoints_per_edge": 1}},
                            ["[terrain] checkpoints_per_edge", "got 1"]),
    "restitution above 1": ({"material": {"restitution": 1.5}},
                            ["[material] restitution must be a number in [0, 1], got 1.5"]),
    "unknown friction model": ({"material": {"friction_model": "viscous"}},
                               ["[material] friction_model", "'viscous'"]),
    "negative mass": (body(mass=-1), ["[[body]] #1 mass must be a positive finite number, got -1"]),
    "zero mass": (body(mass=0), ["[[body]] #1 mass", "got 0"]),
    "zero radius": (body(radius=0), ["[[body]] #1 radius", "got 0"]),
    "negative half extent": (box(half_extents=[0.1, -0.2, 0.3]),
                             ["[[body]] #1 half_extents", "[0.1, -0.2, 0.3]"]),
    "position not numbers": (body(position=[0, "a", 1]),
                             ["[[body]] #1 position must be 3 finite numbers, got [0, 'a', 1]"]),
    "position too short": (body(position=[0, 1]), ["[[body]] #1 position", "got [0, 1]"]),
    "zero quaternion": (body(orientation=[0, 0, 0, 0]),
                        ["[[body]] #1 orientation", "non-zero", "got [0, 0, 0, 0]"]),
    "static not bool": (body(static=1), ["[[body]] #1 static must be true or false, got 1"]),
    "unknown shape": (body(shape="cone"), ["[[body]] #1 shape must be one of sphere, box, got 'cone'"]),
    "missing shape": ({"body": [{"radius": 1.0}]}, ["[[body]] #1 shape is required"]),
    "sphere without radius": ({"body": [{"shape": "sphere"}]},
                              ["[[body]] #1 radius is required for shape 'sphere'"]),
    "radius on a box": (box(radius=0.2), ["[[body]] #1 radius is not valid for shape 'box'"]),
    "second body named": ({"body": [BASE["body"][0], {"shape": "sphere", "radius": 0.1, "mass": 0}]},
                          ["[[body]] #2 mass", "got 0"]),
    "no bodies": ({"body": None}, ["the scene has no bodies"]),
    "unknown layout type": ({"layout": [{"type": "spiral"}]},
                            ["[[layout]] #1 type must be one of grid, stack, pyramid, chain, got 'spiral'"]),
    "layout without count": ({"layout": [{"type": "stack"}]}, ["[[layout]] #1 (stack) count is required"]),
    "grid count of 2": (grid(count=[2, 2]), ["[[layout]] #1 (grid) count", "got [2, 2]"]),
    "grid spacing too small": (grid(spacing=0.1),
                               ["[[layout]] #1 (grid) spacing must be at least 0.5", "got 0.1"]),
    "grid radius on boxes": (grid(shape="box", radius=0.2),
                             ["[[layout]] #1 (grid) radius is not valid for shape 'box'"]),
    "grid sphere_fraction without mix": (grid(sphere_fraction=0.5),
                                         ["(grid) sphere_fraction", "got shape 'sphere'"]),
    "grid jitter above 1": (grid(jitter=2), ["[[layout]] #1 (grid) jitter", "got 2"]),
    "grid over a vertical plane": ({**grid(), "terrain": {**PLANE, "normal": [1, 0, 0]}},
                                   ["[[layout]] #1 (grid)", "vertical"]),
    "stack position of 4": ({"layout": [{"type": "stack", "count": 2, "position": [0, 1, 2, 3]}]},
                            ["[[layout]] #1 (stack) position", "got [0, 1, 2, 3]"]),
    "pyramid negative gap": ({"layout": [{"type": "pyramid", "base": 3, "gap": -0.1}]},
                             ["[[layout]] #1 (pyramid) gap", "got -0.1"]),
    "chain overlapping": ({"layout": [{"type": "chain", "count": 3, "radius": 0.2, "spacing": 0.3}]},
                          ["[[layout]] #1 (chain) spacing must be at least 0.4", "got 0.3"]),
    "chain zero direction": ({"layout": [{"type": "chain", "count": 3, "direction": [0, 0, 0]}]},
                             ["[[layout]] #1 (chain) direction", "got [0, 0, 0]"]),
}


@pytest.mark.parametrize("changes, expected", BAD.values(), ids=BAD.keys())
def test_bad_scene_names_key_and_value(changes, expected):
    """Every invalid input is a SceneError whose one-line message names the file, key and value."""
    with pytest.raises(SceneError) as info:
        parse_scene(scene_with(**changes), "bad.toml")
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("bad.toml: ")
    for text in expected:
        assert text in message


def test_load_scene_file_errors(tmp_path):
    """Missing files, TOML syntax errors and non-UTF-8 files are one-line SceneErrors."""
    missing = r"^cannot read scene file '.*missing.toml': No such file or directory$"
    with pytest.raises(SceneError, match=missing):
        load_scene(tmp_path / "missing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("[sim]\ndt = = 1\n")
    with pytest.raises(SceneError, match=r"broken.toml: TOML syntax error: .*line 2"):
        load_scene(broken)
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"name = '\xff'\n")
    with pytest.raises(SceneError, match="binary.toml: not UTF-8"):
        load_scene(binary)


def test_load_scene_name_defaults_to_file_stem(tmp_path):
    path = tmp_path / "little.toml"
    path.write_text('[[body]]\nshape = "sphere"\nradius = 0.1\n')
    scene = load_scene(path)
    assert scene.name == "little" and scene.source == str(path)


# Layouts ----------------------------------------------------------------------------------------


def layout_scene(layouts, terrain=None, seed=0, allow_overlap=False):
    data = {"sim": {"seed": seed, "allow_initial_overlap": allow_overlap}, "layout": layouts}
    if terrain is not None:
        data["terrain"] = terrain
    return parse_scene(data, "layout.toml")


def positions(scene) -> np.ndarray:
    return np.array([b["position"] for b in scene.builder.bodies])


@pytest.mark.parametrize("layout, count", [
    ({"type": "grid", "count": 10}, 10),
    ({"type": "grid", "count": [3, 2, 4]}, 24),
    ({"type": "grid", "count": 7, "shape": "mix", "sphere_fraction": 0.5}, 7),
    ({"type": "stack", "count": 5}, 5),
    ({"type": "pyramid", "base": 4}, 10),
    ({"type": "chain", "count": 6, "shape": "box"}, 6),
], ids=["grid-int", "grid-xyz", "grid-mix", "stack", "pyramid", "chain"])
def test_layout_body_counts(layout, count):
    assert layout_scene([layout]).body_count == count


def test_bodies_then_layouts_and_their_origins():
    """[[body]] tables come first, then layouts in order; body_origin maps an index back."""
    data = {"body": [{"shape": "sphere", "radius": 0.1}],
            "layout": [{"type": "stack", "count": 2, "position": [5.0, 0.0]},
                       {"type": "chain", "count": 3, "start": [0.0, 5.0]}]}
    scene = parse_scene(data)
    assert scene.body_count == 6
    assert scene.body_origin(0) == "[[body]] #1"
    assert scene.body_origin(2) == "[[layout]] #1 (stack), its body 2 of 2"
    assert scene.body_origin(5) == "[[layout]] #2 (chain), its body 3 of 3"


def test_grid_mix_has_the_requested_share_of_spheres():
    scene = layout_scene([{"type": "grid", "count": 20, "shape": "mix", "sphere_fraction": 0.25}])
    shapes = [b["shape"] for b in scene.builder.bodies]
    assert shapes.count(SHAPE_SPHERE) == 5


def test_grid_bodies_do_not_overlap():
    """Bounding spheres are disjoint even with full jitter and random orientations."""
    scene = layout_scene([{"type": "grid", "count": [5, 3, 4], "shape": "mix", "radius": 0.3,
                           "half_extents": [0.4, 0.1, 0.2], "random_orientation": True, "jitter": 1.0}])
    p = positions(scene)
    bound = np.array([b["size"][0] if b["shape"] == SHAPE_SPHERE else np.linalg.norm(b["size"])
                      for b in scene.builder.bodies])
    dist = np.linalg.norm(p[:, None] - p[None], axis=-1)
    limit = bound[:, None] + bound[None]
    off_diagonal = ~np.eye(len(p), dtype=bool)
    assert (dist[off_diagonal] >= limit[off_diagonal] - 1e-9).all()


@pytest.mark.parametrize("terrain", [
    {"kind": "fourier", "amplitude": 1.5},
    {"kind": "plane", "normal": [-0.3, 1.0, 0.2], "offset": 0.4},
    {"kind": "none"},
], ids=["fourier", "tilted-plane", "none"])
def test_grid_clearance_puts_every_body_above_the_terrain(terrain):
    """Every body's lowest point is at least `clearance` above the ground, and the lowest one
    sits at that clearance above the highest ground under the grid (not needlessly high)."""
    clearance = 0.3
    scene = layout_scene([{"type": "grid", "count": [6, 2, 5], "shape": "mix", "spacing": 1.1,
                           "center": [2, -1], "clearance": clearance, "random_orientation": True,
                           "jitter": 0.5}], terrain)
    t = scene.terrain
    height = (lambda x, z: np.zeros_like(x)) if isinstance(t, NoTerrain) else t.height
    lowest = []
    for b in scene.builder.bodies:
        corners = body_corners(b)
        gap = corners[:, 1] - height(corners[:, 0], corners[:, 2])
        assert gap.min() >= clearance - 1e-3
        lowest.append(corners[:, 1].min())
    p = positions(scene)
    x, z = np.meshgrid(np.linspace(p[:, 0].min() - 1, p[:, 0].max() + 1, 200),
                       np.linspace(p[:, 2].min() - 1, p[:, 2].max() + 1, 200))
    assert min(lowest) - height(x, z).max() < clearance + 0.05


def test_stack_and_pyramid_rest_on_the_ground():
    """With position [x, z] the bottom boxes rest on the highest ground under them; boxes touch."""
    terrain = {"kind": "fourier", "amplitude": 1.0}
    # the pyramid is placed at y = 0, partly inside this terrain: allowed, with a warning
    with pytest.warns(UserWarning, match=r"body 3 \(\[\[layout\]\] #2 \(pyramid\).* inside the terrain"):
        scene = layout_scene([{"type": "stack", "count": 3, "position": [1.0, 2.0],
                               "half_extents": [0.2, 0.1, 0.3]},
                              {"type": "pyramid", "base": 3, "position": [-2.0, 0.0, 5.0], "gap": 0.05}], terrain,
                             allow_overlap=True)
    t = scene.terrain
    stack = scene.builder.bodies[:3]
    corners = body_corners(stack[0])
    assert (corners[:, 1] - t.height(corners[:, 0], corners[:, 2]) >= -1e-6).all()
    x, z = np.meshgrid(np.linspace(0.8, 1.2, 50), np.linspace(1.7, 2.3, 50))
    assert corners[:, 1].min() == pytest.approx(t.height(x, z).max(), abs=1e-3)
    ys = [b["position"][1] for b in stack]
    np.testing.assert_allclose(np.diff(ys), 0.2)

    pyramid = np.array([b["position"] for b in scene.builder.bodies[3:]])
    np.testing.assert_allclose(sorted(set(np.round(pyramid[:, 1], 9))), [0.25, 0.8, 1.35])
    np.testing.assert_allclose(pyramid[:3, 0], [-2.55, -2.0, -1.45])


def test_chain_defaults_to_touching_bodies_and_moves_only_the_first():
    scene = layout_scene([{"type": "chain", "count": 4, "radius": 0.1, "start": [0, 1, 0],
                           "direction": [0, 0, 2], "velocity": [0, 0, 3]}])
    p = positions(scene)
    np.testing.assert_allclose(p[:, 2], [0.0, 0.2, 0.4, 0.6])
    v = np.array([b["velocity"] for b in scene.builder.bodies])
    np.testing.assert_allclose(v, [[0, 0, 3], [0, 0, 0], [0, 0, 0], [0, 0, 0]])


def test_chain_start_without_height_rests_on_the_ground():
    scene = layout_scene([{"type": "chain", "count": 5, "radius": 0.2, "start": [0, 0]}],
                         {"kind": "plane", "normal": [-0.2, 1.0, 0.0]})
    t = scene.terrain
    p = positions(scene)
    gaps = p[:, 1] - 0.2 - t.height(p[:, 0], p[:, 2])
    assert min(gaps) >= -1e-9 and min(gaps) < 0.1


def test_layouts_are_deterministic_in_the_seed():
    """The same [sim] seed gives identical bodies; another seed gives different ones."""
    layout = [{"type": "grid", "count": 12, "shape": "mix", "random_orientation": True, "jitter": 0.8}]

    def snapshot(seed):
        scene = layout_scene(copy.deepcopy(layout), {"kind": "fourier"}, seed=seed)
        bodies = scene.builder.bodies
        return np.array([np.concatenate([b["position"], b["orientation"], [b["shape"]]]) for b in bodies])

    a, b, c = snapshot(5), snapshot(5), snapshot(6)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_down_extent_of_a_tilted_box():
    """The lowest point of a box turned 90 degrees about z is its x half extent below the centre."""
    q = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
    assert down_extent("box", (0.4, 0.1, 0.2), q) == pytest.approx(0.4)
