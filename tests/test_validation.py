"""One set of rules for every entry point: the builder, SimConfig, the terrain classes and
Simulator.step raise ValueError naming the field and the value, with the scene files' words."""

import dataclasses

import numpy as np
import pytest

from warp_sim import FourierTerrain, ModelBuilder, PlaneTerrain, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.scene import SceneError, load_scene, parse_scene

API_ERRORS = {
    "negative radius": (lambda: ModelBuilder().add_sphere(-1.0), "radius must be a positive finite number, got -1.0"),
    "zero mass": (lambda: ModelBuilder().add_sphere(0.1, mass=0), "mass must be a positive finite number, got 0"),
    "nan mass": (lambda: ModelBuilder().add_box((1, 1, 1), mass=float("nan")),
                 "mass must be a positive finite number, got nan"),
    "two half extents": (lambda: ModelBuilder().add_box([1, 1]),
                         "half_extents must be 3 positive finite numbers, got [1, 1]"),
    "zero quaternion": (lambda: ModelBuilder().add_sphere(0.1, orientation=(0, 0, 0, 0)),
                        "orientation must be a non-zero vector of 4 finite numbers, got [0, 0, 0, 0]"),
    "restitution": (lambda: ModelBuilder().add_sphere(0.1, restitution=2),
                    "restitution must be a number in [0, 1], got 2"),
    "position": (lambda: ModelBuilder().add_sphere(0.1, position=(0, 1e39, 0)),
                 "position must be 3 finite numbers, got [0, 1e+39, 0]"),
    "static": (lambda: ModelBuilder().add_sphere(0.1, static="yes"), "static must be true or false, got 'yes'"),
    "negative dt": (lambda: SimConfig(dt=-1), "SimConfig dt must be a number in [1e-06, 1], got -1"),
    "zero substeps": (lambda: SimConfig(substeps=0), "SimConfig substeps must be an integer in [1, 4096], got 0"),
    "float substeps": (lambda: SimConfig(substeps=2.0), "SimConfig substeps must be an integer in [1, 4096], got 2.0"),
    "bogus integrator": (lambda: SimConfig(integrator="bogus"),
                         "SimConfig integrator must be one of explicit_euler, semi_implicit, verlet, rk4, got 'bogus'"),
    "gravity": (lambda: SimConfig(gravity=(0, -9.81)), "SimConfig gravity must be 3 finite numbers, got [0, -9.81]"),
    "terms": (lambda: FourierTerrain(terms=100), "FourierTerrain terms must be an integer in [1, 32], got 100"),
    "amplitude": (lambda: FourierTerrain(amplitude=-1),
                  "FourierTerrain amplitude must be a finite number >= 0, got -1"),
    "table shape": (lambda: FourierTerrain(terms=2, amplitudes=np.ones((3, 3))),
                    "FourierTerrain amplitudes must be a terms x terms (2 x 2) array, got a 3 x 3 array"),
    "plane normal": (lambda: PlaneTerrain(normal=(0, 0, 0)),
                     "PlaneTerrain normal must be a non-zero vector of 3 finite numbers, got [0, 0, 0]"),
    "material": (lambda: Material(friction=-1), "Material friction must be a finite number >= 0, got -1"),
}


@pytest.mark.parametrize("make, message", API_ERRORS.values(), ids=API_ERRORS.keys())
def test_api_rejects_bad_values_with_one_line(make, message):
    with pytest.raises(ValueError) as info:
        make()
    text = str(info.value)
    assert message in text and "\n" not in text


def test_scene_and_api_share_the_words():
    """The same bad mass gives the same sentence from a scene file and from the builder."""
    with pytest.raises(SceneError) as scene_error:
        parse_scene({"body": [{"shape": "sphere", "radius": 0.1, "mass": 0}]}, "s.toml")
    with pytest.raises(ValueError) as api_error:
        ModelBuilder().add_sphere(0.1, mass=0)
    assert str(scene_error.value) == f"s.toml: [[body]] #1 {api_error.value}"
    with pytest.raises(SceneError) as scene_error:
        parse_scene({"sim": {"dt": -1}, "body": [{"shape": "sphere", "radius": 0.1}]}, "s.toml")
    with pytest.raises(ValueError) as api_error:
        SimConfig(dt=-1)
    assert str(scene_error.value).replace("s.toml: [sim]", "SimConfig") == str(api_error.value)


def test_step_count_is_checked(device):
    b = ModelBuilder()
    b.add_sphere(0.1)
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    for bad, shown in ((-5, "-5"), (1.5, "1.5"), (True, "true")):
        with pytest.raises(ValueError, match=f"Simulator.step count must be an integer >= 0, got {shown}"):
            sim.step(bad)
    sim.step(0)
    assert sim.step_count == 0
    with pytest.raises(ValueError, match=r"SimConfig substeps must be an integer in \[1, 4096\], got 0"):
        sim.update_settings(substeps=0)
    assert sim.config.substeps == 4  # a refused change leaves the settings as they were


def test_config_changed_after_construction_is_checked_by_the_simulator():
    b = ModelBuilder()
    b.add_sphere(0.1)
    config = SimConfig()
    message = "SimConfig solver must be one of soft_step, pushout, got 'nope'"
    with pytest.raises(ValueError, match=message):
        config.solver = "nope"  # refused at once now (SimConfig.__setattr__)
    object.__setattr__(config, "solver", "nope")  # and past that, by the simulator
    with pytest.raises(ValueError, match=message):
        Simulator(b.finalize("cpu"), config)


def test_tiny_and_huge_bodies_are_refused_by_their_float32_inertia():
    """A sphere of radius 1e-30 passes the per-key rules but its inertia is 0 in float32."""
    with pytest.raises(ValueError, match=r"radius 1e-30 with mass 1 gives inertia .* not all finite non-zero float32"):
        ModelBuilder().add_sphere(1e-30)
    with pytest.raises(ValueError, match="half_extents"):
        ModelBuilder().add_box((1e20, 1e20, 1e20), mass=1e30)
    with pytest.raises(SceneError, match=r"^s.toml: \[\[body\]\] #1 radius 1e-30"):
        parse_scene({"body": [{"shape": "sphere", "radius": 1e-30}]}, "s.toml")
    ModelBuilder().add_sphere(1e-6, mass=1e-3)  # small but representable


def test_the_sim_schema_and_simconfig_stay_in_step():
    from warp_sim.validation import SIM_SCHEMA

    assert set(SIM_SCHEMA) == {f.name for f in dataclasses.fields(SimConfig)}


# ----------------------------------------------------------------------------------------------
# add_bodies


def _random_bodies(rng, n):
    shapes = rng.integers(0, 2, n)
    size = rng.uniform(0.05, 0.5, (n, 3))
    size[shapes == 0, 1:] = 0.0
    q = rng.normal(size=(n, 4))
    return dict(shape=shapes, size=size, mass=rng.uniform(0.5, 3, n), position=rng.uniform(-10, 10, (n, 3)),
                orientation=q, velocity=rng.normal(size=(n, 3)), angular_velocity=rng.normal(size=(n, 3)),
                restitution=rng.uniform(0, 1, n), friction=rng.uniform(0, 1, n), static=rng.random(n) < 0.2)


def test_bulk_add_equals_single_adds_bit_for_bit():
    rng = np.random.default_rng(4)
    n = 300
    arrays = _random_bodies(rng, n)
    bulk, single = ModelBuilder(), ModelBuilder()
    single.add_sphere(0.3)  # mixing single and bulk adds keeps the order
    bulk.add_sphere(0.3)
    assert list(bulk.add_bodies(**arrays)) == list(range(1, n + 1))
    for i in range(n):
        common = {key: arrays[key][i] for key in ("mass", "position", "orientation", "velocity", "angular_velocity",
                                                  "restitution", "friction", "static")}
        if arrays["shape"][i] == 0:
            single.add_sphere(arrays["size"][i, 0], **common)
        else:
            single.add_box(arrays["size"][i], **common)
    a, b = bulk.host_arrays(3), single.host_arrays(3)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert bulk.bodies[5].keys() == single.bodies[5].keys()


def test_bulk_add_names_the_first_bad_entry():
    b = ModelBuilder()
    mass = np.ones(10)
    mass[7] = 0.0
    with pytest.raises(ValueError, match=r"^mass\[7\] must be a positive finite number, got 0.0$"):
        b.add_bodies("sphere", 0.1, mass=mass)
    pos = np.zeros((4, 3))
    pos[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"position\[2\] must be 3 finite numbers, got \[0.0, nan, 0.0\]"):
        b.add_bodies("box", (0.1, 0.2, 0.3), position=pos)
    with pytest.raises(ValueError, match=r"shape\[1\] must be one of sphere, box, got 'cone'"):
        b.add_bodies(np.array(["sphere", "cone"]), 0.1)
    with pytest.raises(ValueError, match=r"orientation\[0\] must be a non-zero vector"):
        b.add_bodies("sphere", 0.1, position=np.zeros((2, 3)), orientation=np.zeros((2, 4)))
    # three radii for three spheres, given as one 3-array, read as one row: named, not dropped
    with pytest.raises(ValueError, match=r"^size\[0\] of a sphere must be its radius, \(r, 0, 0\) or \(r, r, r\), "
                       r"got \[0.2, -0.1, 0.3\]; .*\(3, 1\) array$"):
        b.add_bodies("sphere", np.array([0.2, -0.1, 0.3]), position=np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"^size\[1\] of a sphere"):
        b.add_bodies(np.array(["box", "sphere"]), np.array([[0.1, 0.2, 0.3], [0.1, 0.2, 0.1]]))
    assert b.body_count == 0  # nothing half-added
    b.add_bodies("sphere", np.array([0.2, 0.2, 0.2]), position=np.zeros((3, 3)))  # (r, r, r) is one radius
    b.add_bodies(np.array(["box", "sphere"]), np.array([[0.1, 0.2, 0.3], [0.1, 0.0, 0.0]]))
    assert b.body_count == 5 and float(b.columns()["size"][4][0]) == 0.1


def test_finalize_names_a_bad_device():
    """An unknown device, or a CUDA device this machine lacks, is named: not Warp's own error."""
    import warp as wp

    b = ModelBuilder()
    b.add_sphere(0.1, 1.0)
    with pytest.raises(ValueError, match=r"^device must be 'cpu', 'cuda' or 'cuda:N', got 'tpu'$"):
        b.finalize("tpu")
    missing = f"cuda:{wp.get_cuda_device_count()}"
    with pytest.raises(ValueError, match=rf"^device '{missing}' is not available \(\d+ CUDA devices found\)$"):
        b.finalize(missing)
    assert b.finalize(wp.get_device("cpu")).body_count == 1


def test_simulator_names_a_device_other_than_the_models(device):
    """SimConfig's device must be the model's: one this machine lacks, or another than the model
    was finalized on, is named with both, before anything is allocated (Warp would say only
    'Invalid device identifier', or fail at the first launch)."""
    import warp as wp

    b = ModelBuilder()
    b.add_sphere(0.1, 1.0)
    model = b.finalize(device)
    alias = wp.get_device(device).alias
    missing = f"cuda:{wp.get_cuda_device_count()}"
    with pytest.raises(ValueError, match=rf"^SimConfig device '{missing}' is not available \(\d+ CUDA devices "
                                         rf"found\); the model is on '{alias}'$"):
        Simulator(model, SimConfig(device=missing))
    if wp.get_cuda_device_count() > 0:
        other = "cpu" if alias != "cpu" else "cuda:0"
        with pytest.raises(ValueError, match=rf"^SimConfig device '{other}' is not the model's device '{alias}'"):
            Simulator(model, SimConfig(device=other))
    assert Simulator(model, SimConfig(device=device)).device == wp.get_device(device)


def test_bodies_view_round_trips():
    """builder.bodies gives one dict per body and can be assigned back (the demo does)."""
    b = ModelBuilder()
    b.add_bodies("sphere", np.array([0.1, 0.2, 0.3, 0.4]).reshape(4, 1), position=np.arange(12.0).reshape(4, 3))
    copy = ModelBuilder()
    copy.bodies = [dict(body, friction=0.9) for body in b.bodies]
    assert copy.body_count == 4 and copy.bodies[-1]["size"][0] == 0.4
    assert np.all(copy.columns()["friction"] == 0.9)
    np.testing.assert_array_equal(copy.columns()["position"], b.columns()["position"])


@pytest.mark.parametrize("key, value", [("dt", 1e-300), ("dt", 2.0), ("substeps", 2**31), ("iterations", 10**20),
                                        ("relax_iterations", 10**9), ("relax_passes", 5000),
                                        ("contact_hertz", 1e-300)])
def test_settings_that_would_break_far_away_are_refused_by_name(key, value):
    """A positive dt of 1e-300 passed "> 0" and overflowed the contact frequency's square in the
    substep plan; a contact frequency of 1e-300 Hz divided by zero there; billions of substeps or
    sweeps were accepted and the run never ended.  Each is now a one-line error naming the field
    and the value, from SimConfig, a scene file and update_settings alike."""
    with pytest.raises(ValueError, match=rf"{key} must be .*got {value:g}" if isinstance(value, float)
                       else rf"{key} must be .*got {value}"):
        SimConfig(**{key: value})
    with pytest.raises(SceneError, match=rf"\[sim\] {key} must be"):
        parse_scene({"sim": {key: value}, "body": [{"shape": "sphere", "radius": 0.1}]}, "s.toml")
    b = ModelBuilder()
    b.add_sphere(0.1, position=(0.0, 1.0, 0.0))
    sim = Simulator(b.finalize("cpu"), SimConfig())
    with pytest.raises(ValueError, match=rf"{key} must be"):
        sim.update_settings(**{key: value})


def test_a_run_too_long_to_count_is_refused_by_name():
    from warp_sim.limits import expected_steps

    with pytest.raises(ValueError, match=r"duration = 1e\+308 s at dt = 0.0166667 s is inf steps"):
        expected_steps(1e308, 1.0 / 60.0)
    assert expected_steps(1.0, 1.0 / 60.0) == 60


@pytest.mark.parametrize("tiny", [1e-300, 1e-200, 1e-40])
def test_tiny_vectors_keep_their_direction(tiny):
    """A normal or orientation of 1e-300 has a direction; v / |v| squared it to 0 and gave inf and
    NaN (a plane that no ball touched, a box with a NaN quaternion)."""
    assert PlaneTerrain(normal=(tiny, 0.0, 0.0)).normal == (1.0, 0.0, 0.0)
    assert PlaneTerrain(normal=(0.0, tiny, -tiny)).normal == pytest.approx((0.0, 2**-0.5, -(2**-0.5)))
    b = ModelBuilder()
    b.add_box((0.1, 0.1, 0.1), orientation=(tiny, 0.0, 0.0, 0.0))
    np.testing.assert_array_equal(b.host_arrays(2)["body_quat"], [[1.0, 0.0, 0.0, 0.0]])


@pytest.mark.parametrize("key, value", [("body_contact", False), ("device", "cuda:7"), ("contact_max", 1),
                                        ("sleep", False), ("broad_phase", "all_pairs"), ("pair_schedule", "colors"),
                                        ("graph", True)])
def test_update_settings_refuses_what_the_simulator_is_built_around(key, value):
    """These were stored and never applied (bodies kept colliding after body_contact = False)."""
    b = ModelBuilder()
    b.add_sphere(0.1, position=(0.0, 1.0, 0.0))
    b.add_sphere(0.1, position=(0.0, 1.3, 0.0))
    sim = Simulator(b.finalize("cpu"), SimConfig())
    with pytest.raises(ValueError, match=rf"SimConfig.{key} is fixed when the Simulator is built"):
        sim.update_settings(**{key: value})
    if getattr(sim.config, key) is not None:  # graph = None: chosen by the device at build
        sim.update_settings(**{key: getattr(sim.config, key)})  # the value it was built with is no change
    with pytest.raises(ValueError, match="unknown simulation setting 'validate'"):
        sim.update_settings(validate=1)


@pytest.mark.parametrize("kwargs, message", [
    (dict(shape="sphere", size=[0.1, 0.1], mass=[1.0, 2.0, 3.0]), "size must be a number or 3 numbers"),
    (dict(shape="sphere", size=[0.1, 0.1], friction=[0.1, 0.2, 0.3]), "friction must be a number or 2 numbers"),
    (dict(shape="sphere", size=[0.1, 0.1], restitution=[0.1, 0.2, 0.3]), "restitution must be a number or 2"),
    (dict(shape="sphere", size=[0.1, 0.1], static=[True, False, True]), "static must be one bool or 2"),
    (dict(shape=["sphere", "box", "box"], size=[0.1, 0.1]), "size must be a number or 3 numbers"),
    (dict(shape="sphere", size=[0.1, 0.1], position=[["a", 0, 0], [0, 0, 0]]), "position must be numbers"),
    (dict(shape="box", size=[10**400, 1.0]), "size must be numbers"),
    (dict(shape="sphere", size=[0.1, 0.1], mass=[True, True]), "mass must be numbers, got booleans"),
    (dict(shape=np.array([True, False]), size=[0.1, 0.1]), "shape must be names (sphere, box) or codes"),
])
def test_add_bodies_names_the_column_at_fault(kwargs, message):
    """Wrong lengths gave numpy's 'operands could not be broadcast together', strings and huge
    integers numpy's and Python's own errors, naming no column; booleans were taken for masses
    and shapes, which add_sphere refuses."""
    with pytest.raises(ValueError) as e:
        ModelBuilder().add_bodies(**kwargs)
    assert message in str(e.value)
    assert "broadcast" not in str(e.value)


def test_wrong_objects_and_foreign_snapshots_are_named():
    """set_terrain('flat') and ModelBuilder(material='ice') failed later with AttributeError,
    from_slope('a') with a TypeError; a snapshot of another scene was half copied, one with
    step_count -3 accepted, and restore({}) raised KeyError."""
    with pytest.raises(ValueError, match="terrain must be a FourierTerrain, PlaneTerrain or NoTerrain, got 'flat'"):
        ModelBuilder().set_terrain("flat")
    with pytest.raises(ValueError, match="material must be a Material, got 'ice'"):
        ModelBuilder(material="ice")
    with pytest.raises(ValueError, match="angle_deg must be a finite number, got 'a'"):
        PlaneTerrain.from_slope("a")
    one, two = ModelBuilder(), ModelBuilder()
    one.add_sphere(0.1, position=(0.0, 1.0, 0.0))
    for x in (0.0, 1.0):
        two.add_sphere(0.1, position=(x, 1.0, 0.0))
    sim, other = Simulator(one.finalize("cpu"), SimConfig()), Simulator(two.finalize("cpu"), SimConfig())
    with pytest.raises(ValueError, match="taken of another scene or settings"):
        sim.restore(other.snapshot())
    with pytest.raises(ValueError, match="step_count must be an integer >= 0, got -3"):
        sim.restore(dict(sim.snapshot(), step_count=-3))
    with pytest.raises(ValueError, match="needs a dict from Simulator.snapshot"):
        sim.restore({})
    sim.step(3)
    snap = sim.snapshot()
    sim.step(2)
    sim.restore(snap)
    assert sim.step_count == 3


def test_a_non_finite_step_names_every_body_it_reached():
    """Two bodies at 1e38 and 3e38 m/s beside a healthy ball: both go non-finite in the first step,
    and the error names the lower index and lists the other.  Every body of that step is named
    because NaN can travel in it: in a scene of the input probe's, with a chain of two, a healthy
    1 m/s ball of lower index went non-finite in the same step and was named alone."""
    from warp_sim import NonFiniteStateError
    from warp_sim.terrain import NoTerrain

    b = ModelBuilder()
    b.set_terrain(NoTerrain())
    b.add_sphere(0.1, position=(0.0, 0.0, 0.0), velocity=(1.0, 0.0, 0.0))
    b.add_box((0.1, 0.1, 0.1), position=(0.0, 5.0, 0.0))
    b.add_sphere(0.1, position=(0.0, 10.0, 0.0))
    sim = Simulator(b.finalize("cpu"), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False))
    # speeds no builder accepts (past light), written into the state as an API user may
    vel = sim.state.body_vel.numpy()
    vel[1], vel[2] = (1e38, 0.0, 0.0), (3e38, 0.0, 0.0)
    sim.state.body_vel.assign(vel)
    with pytest.raises(NonFiniteStateError) as e:
        sim.step(3)
    assert (e.value.body, *e.value.others) == (1, 2)
    assert "body 1 (box) became non-finite at step 1" in str(e.value)
    assert "with 1 other in that step (bodies 2)" in str(e.value)


def test_config_fields_assigned_later_meet_the_same_rules():
    """sim.config.dt = -1 ran time backwards and a NaN gravity set this way was ignored."""
    b = ModelBuilder()
    b.add_sphere(0.1, position=(0.0, 1.0, 0.0))
    sim = Simulator(b.finalize("cpu"), SimConfig())
    with pytest.raises(ValueError, match=r"SimConfig dt must be a number in \[1e-06, 1\], got -1"):
        sim.config.dt = -1
    with pytest.raises(ValueError, match="SimConfig gravity must be 3 finite numbers"):
        sim.config.gravity = (0.0, float("nan"), 0.0)
    assert sim.config.dt == pytest.approx(1.0 / 60.0)


SPEED_OF_LIGHT = 299_792_458.0


@pytest.mark.parametrize("speed, accepted", [(0.5 * SPEED_OF_LIGHT, True), (0.999 * SPEED_OF_LIGHT, True),
                                             (1.001 * SPEED_OF_LIGHT, False), (1e20, False), (1e38, False)])
@pytest.mark.parametrize("direction", [(1.0, 0.0, 0.0), (0.0, -0.6, 0.8)])
def test_starting_speeds_beyond_light_are_refused_everywhere_a_body_is_made(tmp_path, speed, accepted, direction):
    """A ball given 1e38 m/s used to hand NaN to a box 5 m the other way in its first step; speeds
    up to light are kept (and stay finite: the next test), faster ones refused by name."""
    velocity = tuple(speed * d for d in direction)
    makers = {
        "add_sphere": lambda b: b.add_sphere(0.25, 1.0, velocity=velocity),
        "add_box": lambda b: b.add_box((0.25, 0.25, 0.25), 1.0, velocity=velocity),
        "add_bodies": lambda b: b.add_bodies("sphere", 0.25, position=[[0, 0, 0], [2, 0, 0]],
                                             velocity=[[0, 0, 0], list(velocity)]),
    }
    for name, make in makers.items():
        if accepted:
            make(ModelBuilder())
        else:
            with pytest.raises(ValueError, match=r"velocity(\[1\])? must be 3 finite numbers of length at most "
                                                 r"2\.998e\+08 \(the speed of light"):
                make(ModelBuilder())
    scene = tmp_path / "fast.toml"
    scene.write_text(f'[[body]]\nshape = "sphere"\nradius = 0.5\nvelocity = [{velocity[0]!r}, {velocity[1]!r}, '
                     f'{velocity[2]!r}]\n')
    if accepted:
        load_scene(scene)
    else:
        with pytest.raises(SceneError, match=r"\[\[body\]\] #1 velocity must be .* at most 2\.998e\+08"):
            load_scene(scene)


@pytest.mark.parametrize("spin, accepted", [(0.9e12, True), (1.1e12, False), (1e30, False)])
def test_starting_spins_past_float32_safety_are_refused(spin, accepted):
    make = lambda: ModelBuilder().add_box((0.1, 0.2, 0.3), 1.0, angular_velocity=(0.0, spin, 0.0))  # noqa: E731
    if accepted:
        make()
    else:
        with pytest.raises(ValueError, match=r"angular_velocity must be .* at most 1e\+12"):
            make()


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_ball_at_nearly_light_speed_leaves_bodies_out_of_its_path_alone(device, sign):
    """The fastest start allowed, 0.999 c along x, among balls on that line and a box on the
    other side: everything stays finite, and what lies behind the ball is not touched."""
    b = ModelBuilder()
    b.set_terrain(PlaneTerrain())
    b.add_sphere(0.25, 1.0, position=(0.0, 0.25, 0.0), velocity=(sign * 0.999 * SPEED_OF_LIGHT, 0.0, 0.0))
    ahead = [b.add_sphere(0.25, 1.0, position=(sign * 5.0 * k, 0.25, 0.0)) for k in range(1, 4)]
    behind = b.add_box((0.25, 0.25, 0.25), 1.0, position=(-sign * 5.0, 0.25, 0.0))
    sim = Simulator(b.finalize(device), SimConfig(body_contact=True, device=device))
    sim.step(1)  # raises NonFiniteStateError on any NaN or inf
    pos = sim.state.body_pos.numpy()
    assert np.isfinite(pos).all() and np.isfinite(sim.state.body_vel.numpy()).all()
    # the box behind only settles on the plane: a step of gravity, g dt^2 ~ 3 mm at most
    assert abs(pos[behind][0] - (-sign * 5.0)) < 1e-3 and abs(pos[behind][1] - 0.25) < 5e-3
    assert len(ahead) == 3
