"""Pairs found again mid-step where their bodies have turned (solvers/pair_refresh.py).

The refreshed manifold is stored in the solver's reference representation; what must hold is
that the solver then reads exactly the contact a fresh narrow phase finds at the current pose:
pair_point_now's gap is minus the fresh depth, and both arms end at the anchor the fresh point
stands for.  The poses
here are random (plates, cubes, and balls on boxes, turned by up to 0.4 rad and moved by up to 5 cm since the
reference pose), built by hand, so each kernel is checked alone.
"""

import math

import numpy as np
import pytest
import warp as wp

from test_internal_edges import yaw
from test_primitives import rotation
from warp_sim import ModelBuilder, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.collide.primitives import collide_pair
from warp_sim.kernel_args import BodyModel
from warp_sim.solvers.pair_geometry import pair_point_now
from warp_sim.solvers.pair_refresh import refresh_turned_pairs
from warp_sim.solvers.soft_step import drift_rotation
from warp_sim.terrain import PlaneTerrain
from warp_sim.types import SHAPE_BOX, SHAPE_SPHERE

G = 9.81

POINTS = 4
MARGIN = 0.05


@wp.kernel
def fresh_and_read(shape: wp.array(dtype=wp.int32), pos: wp.array(dtype=wp.vec3), rot: wp.array(dtype=wp.mat33),
                   half: wp.array(dtype=wp.vec3), model: BodyModel, ref_pos: wp.array(dtype=wp.vec3),
                   ref_rot: wp.array(dtype=wp.mat33), pair_normal: wp.array(dtype=wp.vec3),
                   pair_point: wp.array(dtype=wp.vec3), pair_depth: wp.array(dtype=float),
                   pair_feature: wp.array(dtype=wp.int32), pair_point_count: wp.array(dtype=wp.int32), margin: float,
                   fresh_depth: wp.array(dtype=float), fresh_point: wp.array(dtype=wp.vec3),
                   read_gap: wp.array(dtype=float), read_end_i: wp.array(dtype=wp.vec3),
                   read_end_j: wp.array(dtype=wp.vec3), fresh_count: wp.array(dtype=wp.int32)):
    """The fresh manifold at the current pose, and what the solver reads from the stored one."""
    m = collide_pair(shape[0], pos[0], rot[0], half[0], 0, shape[1], pos[1], rot[1], half[1], 0, margin, 0)
    fresh_count[0] = m.count
    for k in range(m.count):
        fresh_depth[k] = m.depth[k]
        fresh_point[k] = wp.vec3(m.point[k, 0], m.point[k, 1], m.point[k, 2])
    dpi = pos[0] - ref_pos[0]
    dpj = pos[1] - ref_pos[1]
    # the drift as the solver takes it (a sphere's support point does not turn with the ball)
    dri = drift_rotation(shape[0], rot[0], ref_rot[0])
    drj = drift_rotation(shape[1], rot[1], ref_rot[1])
    for k in range(pair_point_count[0]):
        now = pair_point_now(pair_normal[0], pair_point[k], pair_depth[k], pair_feature[k], ref_pos[0], ref_pos[1],
                             dpi, dpj, dri, drj, ref_rot, 0, 1, model)
        read_gap[k] = now.separation
        read_end_i[k] = pos[0] + now.arm_i
        read_end_j[k] = pos[1] + now.arm_j


def arrays(values, dtype, device="cpu"):
    return wp.array(np.asarray(values, dtype=np.int32 if dtype == wp.int32 else np.float32), dtype=dtype,
                    device=device)


def refresh(case, tolerance=0.0, device="cpu"):
    """Stores the reference pose's manifold as the pass would, moves the bodies, runs the kernel;
    returns the stored arrays after it and the fresh contact at the current pose."""
    shape = arrays(case["shape"], wp.int32, device)
    half = arrays(case["half"], wp.vec3, device)
    radius = arrays([h[0] if k == SHAPE_SPHERE else 0.0 for k, h in zip(case["shape"], case["half"])], float,
                    device)
    inv_mass = arrays(case["inv_mass"], float, device)
    ref_pos, ref_rot = arrays(case["ref_pos"], wp.vec3, device), arrays(case["ref_rot"], wp.mat33, device)
    pos, rot = arrays(case["pos"], wp.vec3, device), arrays(case["rot"], wp.mat33, device)
    bound = arrays([h[0] if k == SHAPE_SPHERE else np.linalg.norm(h) for k, h in zip(case["shape"], case["half"])],
                   float, device)
    n = wp.zeros(1, dtype=wp.vec3, device=device)
    count = wp.zeros(1, dtype=wp.int32, device=device)
    points = wp.zeros(POINTS, dtype=wp.vec3, device=device)
    depths = wp.zeros(POINTS, dtype=float, device=device)
    scratch = [wp.zeros(POINTS, dtype=t, device=device) for t in (float, wp.vec3, float, wp.vec3, wp.vec3)]
    fresh_count = wp.zeros(1, dtype=wp.int32, device=device)
    # the pass at the reference pose: its manifold is stored as is (drift zero there)
    features = wp.zeros(POINTS, dtype=wp.int32, device=device)
    wp.launch(store_pass, 1, device=device, inputs=[shape, ref_pos, ref_rot, half, MARGIN, n, points, depths, features,
                                                   count])
    impulses = wp.array(np.arange(1, POINTS + 1, dtype=np.float32), dtype=float, device=device)
    tangents = wp.array(np.tile(np.float32([0.1, 0.0, 0.0]), (POINTS, 1)), dtype=wp.vec3, device=device)
    before = {"count": count.numpy().copy(), "normal": n.numpy().copy(), "point": points.numpy().copy(),
              "depth": depths.numpy().copy(), "feature": features.numpy().copy(), "impulse": impulses.numpy().copy()}
    refreshed = wp.zeros(1, dtype=wp.int32, device=device)
    wp.launch(refresh_turned_pairs, 1, device=device, inputs=[
        0, shape, half, bound, arrays([0, 0], wp.int32, device), inv_mass, MARGIN, tolerance, pos, rot, ref_pos,
        ref_rot,
        bound, arrays([1], wp.int32, device), wp.array([wp.vec2i(0, 1)], dtype=wp.vec2i, device=device),
        count, n, points, depths, features, impulses, tangents, refreshed, 1,
        wp.zeros(1, dtype=wp.vec4, device=device)])
    model = BodyModel()  # the fields pair_point_now reads
    model.body_sphere_radius, model.body_inv_mass, model.body_size = radius, inv_mass, half
    model.body_covered_faces = arrays([0, 0], wp.int32, device)
    wp.launch(fresh_and_read, 1, device=device, inputs=[shape, pos, rot, half, model, ref_pos, ref_rot, n,
                                                       points, depths, features, count, MARGIN, *scratch, fresh_count])
    after = {"count": count.numpy(), "normal": n.numpy(), "point": points.numpy(), "depth": depths.numpy(),
             "feature": features.numpy(), "impulse": impulses.numpy(), "refreshed": int(refreshed.numpy()[0])}
    fresh = {"count": int(fresh_count.numpy()[0]), "depth": scratch[0].numpy(), "point": scratch[1].numpy(),
             "gap": scratch[2].numpy(), "end_i": scratch[3].numpy(), "end_j": scratch[4].numpy()}
    return before, after, fresh


@wp.kernel
def store_pass(shape: wp.array(dtype=wp.int32), pos: wp.array(dtype=wp.vec3), rot: wp.array(dtype=wp.mat33),
               half: wp.array(dtype=wp.vec3), margin: float, normal: wp.array(dtype=wp.vec3), point: wp.array(dtype=wp.vec3),
               depth: wp.array(dtype=float), feature: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    m = collide_pair(shape[0], pos[0], rot[0], half[0], 0, shape[1], pos[1], rot[1], half[1], 0, margin, 0)
    count[0] = m.count
    normal[0] = m.normal
    for k in range(4):
        point[k] = wp.vec3(m.point[k, 0], m.point[k, 1], m.point[k, 2])
        depth[k] = m.depth[k]
        feature[k] = m.feature[k]


def random_case(rng, half_a, half_b, turn):
    """B below, A resting on it with a tilt (A a sphere of radius half_a[0] when half_a has one
    entry); then both move and turn since the reference pose."""
    height_a = half_a[0] if len(half_a) == 1 else half_a[1]
    ref_rot_b = rotation(rng.normal(size=3), rng.uniform(0, 0.2))
    ref_rot_a = rotation(rng.normal(size=3), rng.uniform(0, 0.3)) @ ref_rot_b
    ref_pos_b = rng.normal(size=3) * 0.1
    ref_pos_a = ref_pos_b + ref_rot_b @ np.array([rng.uniform(-0.2, 0.2), half_b[1] + height_a + 0.02,
                                                  rng.uniform(-0.2, 0.2)])
    rot_a = rotation(rng.normal(size=3), turn) @ ref_rot_a
    rot_b = rotation(rng.normal(size=3), 0.25 * turn) @ ref_rot_b
    pos_a = ref_pos_a + rng.uniform(-0.05, 0.05, size=3) - np.array([0.0, 0.03, 0.0])
    pos_b = ref_pos_b + rng.uniform(-0.02, 0.02, size=3)
    shape = [SHAPE_SPHERE if len(half_a) == 1 else SHAPE_BOX, SHAPE_BOX]
    if len(half_a) == 1:  # a sphere of that radius resting on B
        half_a = (half_a[0], 0.0, 0.0)
    return {"shape": shape, "half": [half_a, half_b], "inv_mass": [1.0 / rng.uniform(1, 100), 1.0 / rng.uniform(1, 100)],
            "ref_pos": [ref_pos_a, ref_pos_b], "ref_rot": [ref_rot_a, ref_rot_b],
            "pos": [pos_a, pos_b], "rot": [rot_a, rot_b]}


@pytest.mark.parametrize("half_a, half_b", [((0.3, 0.1, 0.3), (0.3, 0.1, 0.3)), ((0.5, 0.5, 0.5), (0.6, 0.1, 0.4)),
                                            ((0.2,), (0.25, 0.15, 0.1))])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_refreshed_pair_reads_as_the_fresh_contact_at_the_current_pose(half_a, half_b, seed, device):
    """For each refreshed point the solver's gap is minus the fresh depth and both arms end at
    the anchor the fresh point stands for: the point lies midway across the gap found, the anchor
    w of the way to i's surface (pair_geometry.anchor_weight; a sphere's support point), so at
    p + (w - 1/2) (-depth) n (float32 rounding on metre-sized bodies: 2e-5 m); the point count and
    order are the fresh manifold's; a point whose feature id survives keeps its accumulated
    impulse.  Plates, cubes on plates, and a ball on a turning thin box (its one point follows the
    ball)."""
    rng = np.random.default_rng(seed)
    checked = kept = 0
    for _ in range(8):
        case = random_case(rng, half_a, half_b, rng.uniform(0.1, 0.4))
        before, after, fresh = refresh(case, device=device)
        assert after["refreshed"] == 1
        n = int(after["count"][0])
        assert n == fresh["count"]
        inv_i, inv_j = case["inv_mass"]
        w = 1.0 if case["shape"][0] == SHAPE_SPHERE else inv_i / (inv_i + inv_j)
        anchor = fresh["point"][:n] + (w - 0.5) * -fresh["depth"][:n, None] * after["normal"][0]
        np.testing.assert_allclose(fresh["gap"][:n], -fresh["depth"][:n], atol=2e-5)
        np.testing.assert_allclose(fresh["end_i"][:n], anchor, atol=2e-5)
        np.testing.assert_allclose(fresh["end_j"][:n], anchor, atol=2e-5)
        old = {int(f): float(j) for f, j in zip(before["feature"][: int(before["count"][0])], before["impulse"])}
        for f, j in zip(after["feature"][:n], after["impulse"][:n]):
            if int(f) in old:
                assert j == old[int(f)]
                kept += 1
        checked += n
    assert checked >= 8 and kept >= 4


def test_pairs_turned_less_than_the_tolerance_are_left_alone(device):
    """Below the tolerance (turn times bounding radius, summed, plus the two boxes' slide along the
    pass's contact plane) nothing is written, bit for bit; above it the pair is refreshed."""
    rng = np.random.default_rng(5)
    case = random_case(rng, (0.3, 0.1, 0.3), (0.3, 0.1, 0.3), 0.02)
    swing = 0.0
    for k in range(2):
        r = case["rot"][k] @ case["ref_rot"][k].T
        swing += np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)) * np.linalg.norm(case["half"][k])
    n = refresh(case, tolerance=1e9, device=device)[0]["normal"][0].astype(float)
    moved = (case["pos"][0] - case["ref_pos"][0]) - (case["pos"][1] - case["ref_pos"][1])
    slide = float(np.linalg.norm(moved - np.dot(moved, n) * n))
    assert slide > 0.1 * swing  # the case does slide: the test sees that term too
    swing += slide
    before, after, _ = refresh(case, tolerance=1.01 * swing, device=device)
    assert after["refreshed"] == 0
    for key in ("count", "normal", "point", "depth", "feature", "impulse"):
        np.testing.assert_array_equal(before[key], after[key])
    _, after, _ = refresh(case, tolerance=0.99 * swing, device=device)
    assert after["refreshed"] == 1


@pytest.mark.parametrize("speed, radius, turn, crate", [
    (2.0, 0.1, 0.0, 0.0), (3.0, 0.25, 0.0, 0.0), (2.5, 0.2, 0.6, 0.0), (1.5, 0.15, 0.0, 0.0), (8.0, 0.25, 0.0, 0.0),
    (12.0, 0.2, -0.4, 0.0), (5.0, 0.1, 1.1, 0.0), (2.0, 0.1, 0.0, 100.0), (4.0, 0.2, 0.5, 30.0), (6.0, 0.15, 0.0, 1e3)])
def test_ball_rolling_off_a_table_leaves_it_at_the_edge(speed, radius, turn, crate, device):
    """A ball rolling at v with v^2 > g r cannot follow the edge round: it leaves the table as its
    centre passes the edge and falls on the parabola from there, within a substep of it with
    contacts found every substep: off the parabola by at most g tau h (falling one substep late,
    tau after the edge) plus g h^2 for the substep's own kick.  The step's manifold held it at the
    table's height for the rest of the step (a whole step at 2 m/s, 59 mm off the parabola) until
    a pair with a static body counted the slide along it toward the refresh; fast balls (8 and
    12 m/s) were then thrown up as they left, by the ball's own spin taken as a turn of its
    support point (12 and 45 mm).  Tables turned about the vertical, and the ball sent along the
    turned axis; the table static, or a crate of ``crate`` kg resting on the ground plane (a
    sphere's slide along any body counts: off a 100 kg crate at 2 m/s the ball was 39 mm above
    the parabola while only static bodies' did)."""
    assert speed ** 2 > G * radius
    along = np.array([math.cos(turn), 0.0, -math.sin(turn)])
    axis = np.cross([0.0, 1.0, 0.0], along)
    b = ModelBuilder(Material(friction=0.5))
    if crate:
        b.set_terrain(PlaneTerrain())
    b.add_box((1.0, 0.5, 1.0), crate or 1.0, position=(0.0, 0.5, 0.0), orientation=yaw(turn), static=not crate)
    ball = b.add_sphere(radius, 1.0, position=tuple(0.5 * along + [0.0, 1.0 + radius, 0.0]),
                        velocity=tuple(speed * along), angular_velocity=tuple(speed / radius * axis))
    config = SimConfig(sleep=False, device=device)
    sim = Simulator(b.finalize(device), config)
    h = config.dt / config.substeps
    t_edge = 0.5 / speed
    worst = -1.0
    for k in range(1, int((t_edge + 0.3) * 60)):
        sim.step()
        at = sim.state.body_pos.numpy()[ball].astype(float)
        tau = k * config.dt - t_edge
        if tau > 0.0 and at[1] > radius:
            want = 1.0 + radius - 0.5 * G * ((float(np.dot(at, along)) - 1.0) / speed) ** 2
            worst = max(worst, abs(at[1] - want) - (G * tau * h + G * h * h))
    assert -1.0 < worst <= 0.0


@pytest.mark.parametrize("speed, radius, yaw_rate", [(8.0, 0.25, 0.5), (4.0, 0.2, 1.0), (6.0, 0.1, -0.8),
                                                     (3.0, 0.3, 0.6)])
def test_ball_rolling_on_a_turning_plank_stays_on_its_face(speed, radius, yaw_rate, device):
    """A ball rolling along a heavy plank that spins about the vertical: the plank's turn refreshes
    the pair mid-step, and the refresh must take the ball's anchor as the solver does, its support
    point, which the ball's own spin does not move (soft_step.drift_rotation).  Turned with the
    ball it lifts the ball by r (1 - cos theta), theta its spin since the step's pass: 17 mm at
    8 m/s.  On the face the ball stays at its rest height within the soft contact's sag (g /
    omega^2, 0.07 mm at the defaults) and float rounding at metres (1e-6 m): 0.5 mm bounds it."""
    b = ModelBuilder(Material(friction=0.5))
    plank = b.add_box((3.0, 0.1, 1.0), 200.0, position=(0.0, 0.1, 0.0), angular_velocity=(0.0, yaw_rate, 0.0))
    ball = b.add_sphere(radius, 1.0, position=(-2.0, 0.2 + radius, 0.0), velocity=(speed, 0.0, 0.0),
                        angular_velocity=(0.0, 0.0, -speed / radius))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    rise = -1.0
    refreshed = 0
    for _ in range(int(3.0 / speed * 60)):
        sim.step()
        refreshed += sim.refreshed_pair_count()
        pos = sim.state.body_pos.numpy()
        local = sim.state.body_rot.numpy()[plank].T @ (pos[ball] - pos[plank])
        assert abs(local[0]) < 3.0 and abs(local[2]) < 1.0  # still over the face
        rise = max(rise, float(local[1]) - 0.1 - radius)
    assert refreshed > 0  # the plank's turn did refresh the pair
    assert -1e-3 < rise < 5e-4


@pytest.mark.parametrize("box_mass", [0.5, 2.0])
@pytest.mark.parametrize("speed, angle", [(20.0, 30.0), (80.0, 15.0), (80.0, 60.0)])
def test_box_shot_slantwise_at_a_free_plate_never_passes_through_it(box_mass, speed, angle, device):
    """A 4 cm cube shot at a free 1 kg plate 1 cm thick, no gravity, 15 to 60 degrees off its normal,
    at eight start phases across a step.  The pass's manifold anchors each point partly on each body
    (pair_geometry.anchor_weight), so a box sliding along a free body leaves its points behind by
    its share of the slide; that slide was counted toward the refresh only against static bodies and
    spheres, and a cube reaching the plate after sliding 12 cm along it since the pass was pushed at
    points outside its own face: struck on one edge, it spun at 380 rad/s and went through (2 to 6
    of 16 phases at 20 to 80 m/s, 30 degrees).  The slide along the contact plane now counts for two
    boxes as well.  What must hold: the cube's centre never crosses the plate's mid-plane within
    the plate (measured in the plate's frame between consecutive steps)."""
    a = math.radians(angle)
    direction = np.array([math.sin(a), -math.cos(a), 0.0])
    crossed = []
    for phase in range(8):
        b = ModelBuilder(Material(restitution=0.0, friction=0.5))
        plate = b.add_box((0.5, 0.005, 0.5), 1.0, position=(0.0, 0.0, 0.0))
        start = -direction * (1.0 + phase * speed / 60.0 / 8.0)
        box = b.add_box((0.02, 0.02, 0.02), box_mass, position=tuple(start), velocity=tuple(speed * direction))
        sim = Simulator(b.finalize(device), SimConfig(gravity=(0.0, 0.0, 0.0), sleep=False, device=device))
        before = None
        for step in range(int(2.0 / speed * 60) + 4):
            sim.step()
            pos, rot = sim.state.body_pos.numpy().astype(float), sim.state.body_rot.numpy().astype(float)
            local = rot[plate].T @ (pos[box] - pos[plate])
            if before is not None and before[1] > 0.0 >= local[1]:
                at = before + before[1] / (before[1] - local[1]) * (local - before)
                if abs(at[0]) < 0.5 and abs(at[2]) < 0.5:
                    crossed.append((phase, step))
            before = local
    assert not crossed, f"the cube passed through the plate (phase, step): {crossed}"
