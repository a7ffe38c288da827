"""A floor of static boxes laid flush: crossing the seam between two of them (collide/covered_faces.py).

Each box is collided on its own, so at a seam the far box's top edge and side face were features
to the narrow phase, though the near box's top covers them; with the step's motion in the
speculative margin the edge's contact was a ramp.  On the parent of the covered-face masks a ball
rolling across the seam at 2, 4 and 8 m/s rose 9 mm, 85 mm and 0.87 m, and a cube sliding at
5 m/s with mu 0.2 stopped at the seam, 4.8 m short.  The laws: crossing a seam changes nothing
(the same height and the same sliding distance as on one box), and a real step, which covers
nothing, still stops what slides into it.
"""

import math

import numpy as np
import pytest

from warp_sim import ModelBuilder, SimConfig, Simulator
from warp_sim.builder import Material
from warp_sim.terrain import PlaneTerrain
from warp_sim.collide.covered_faces import face_bit

G = 9.81


def yaw(angle: float):
    return (0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2))


def tiled_floor(friction: float, tiles: int = 2, turn: float = 0.0, tile: float = 4.0) -> ModelBuilder:
    """``tiles`` static slabs (tile x 1 x 10 m, tops at y = 0) side by side along the direction
    ``turn`` (radians about y from +x), the first seam at the origin."""
    b = ModelBuilder(Material(friction=friction))
    along = np.array([math.cos(turn), 0.0, -math.sin(turn)])
    for k in range(tiles):
        centre = (k - tiles / 2 + 0.5) * tile * along + np.array([0.0, -0.5, 0.0])
        if tiles % 2:
            centre += 0.5 * tile * along  # an odd count: still a seam at the origin
        b.add_box((tile / 2, 0.5, 5.0), 1.0, position=tuple(centre), orientation=yaw(turn), static=True)
    return b


@pytest.mark.parametrize("speed, radius, turn, tiles", [
    (2.0, 0.25, 0.0, 2), (4.0, 0.25, 0.0, 2), (8.0, 0.25, 0.0, 2), (8.0, 0.1, 0.0, 3), (6.0, 0.5, 0.7, 2),
    (12.0, 0.2, 0.3, 4)])
def test_ball_rolling_across_seams_of_static_boxes_stays_on_the_floor(speed, radius, turn, tiles, device):
    """A ball rolling at ``speed`` across one or more seams.  On one box it stays at its rest
    height within the soft contact's sag (g / omega^2, 0.07 mm at the defaults); a seam adds
    nothing, so it may not rise by more than 1 mm, nor change speed by more than rolling friction's
    zero (it rolls without slipping: 2e-3 of its speed)."""
    b = tiled_floor(0.5, tiles, turn)
    along = np.array([math.cos(turn), 0.0, -math.sin(turn)])
    axis = np.cross([0.0, 1.0, 0.0], along)  # rolling along `along` spins about up x along, at v / r
    start = -1.0 * along + np.array([0.0, radius, 0.0])
    ball = b.add_sphere(radius, 1.0, position=tuple(start), velocity=tuple(speed * along),
                        angular_velocity=tuple(speed / radius * axis))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    rise = 0.0
    for _ in range(int((1.0 + 4.0 * (tiles - 1)) / speed * 60) + 10):
        sim.step()
        rise = max(rise, float(sim.state.body_pos.numpy()[ball, 1]) - radius)
    assert rise < 1e-3
    assert float(np.dot(sim.state.body_vel.numpy()[ball], along)) == pytest.approx(speed, rel=2e-3)


@pytest.mark.parametrize("speed, half, turn", [(2.0, 0.25, 0.0), (5.0, 0.25, 0.0), (5.0, 0.1, 0.4),
                                               (4.0, 0.4, -0.9)])
def test_box_sliding_across_a_seam_of_static_boxes_slides_as_on_one_box(speed, half, turn, device):
    """A cube sliding at ``speed`` with mu 0.2 stops after v^2 / (2 mu g) whether or not it crosses
    a seam (5 m/s: 6.4 m, past the seam at the origin).  Tolerance: 1 % of the distance
    (semi-implicit Euler under constant deceleration is exact but for the step the stop falls
    in, v dt / 2 = 2 to 4 cm, and the soft contact's transient).  It stays on the floor (1 mm)."""
    b = tiled_floor(0.2, 3, turn)
    along = np.array([math.cos(turn), 0.0, -math.sin(turn)])
    start = -1.0 * along + np.array([0.0, half, 0.0])
    cube = b.add_box((half, half, half), 1.0, position=tuple(start), orientation=yaw(turn),
                     velocity=tuple(speed * along))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    sim.step(int(speed / (0.2 * G) * 60) + 30)
    travelled = float(np.dot(sim.state.body_pos.numpy()[cube] - start, along))
    assert travelled == pytest.approx(speed ** 2 / (2 * 0.2 * G), rel=0.01)
    assert abs(float(sim.state.body_pos.numpy()[cube, 1]) - half) < 1e-3


@pytest.mark.parametrize("shape, speed", [("sphere", 0.5), ("sphere", 2.0), ("sphere", 5.0), ("box", 3.0)])
def test_crossing_from_the_ground_plane_onto_a_static_box_set_flush_into_it(shape, speed, device):
    """A static box set into the ground plane with its top flush: its sides lie in the ground
    (covered by it, covered_faces._under_ground), so a body crossing from the plane onto it and
    off again meets a flat floor.  A ball rolling at 2 m/s hopped 19 mm (5 m/s: 0.37 m) at the
    box's edge, and a sliding cube lost speed there.  Laws as above: no rise over 1 mm, a ball keeps
    its rolling speed (2e-3), a cube slides mu g to rest wherever it crosses (1 %)."""
    b = ModelBuilder(Material(friction=0.5 if shape == "sphere" else 0.2))
    b.set_terrain(PlaneTerrain())
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(1.0, -0.5, 0.0), static=True)
    if shape == "sphere":
        body = b.add_sphere(0.1, 1.0, position=(0.0, 0.1, 0.0), velocity=(speed, 0.0, 0.0),
                            angular_velocity=(0.0, 0.0, -speed / 0.1))
        rest = 0.1
    else:
        body = b.add_box((0.1, 0.1, 0.1), 1.0, position=(0.0, 0.1, 0.0), velocity=(speed, 0.0, 0.0))
        rest = 0.1
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    steps = int(2.5 / speed * 60) if shape == "sphere" else int(speed / (0.2 * G) * 60) + 30
    rise = 0.0
    for _ in range(steps):
        sim.step()
        rise = max(rise, float(sim.state.body_pos.numpy()[body, 1]) - rest)
    assert rise < 1e-3
    if shape == "sphere":
        assert float(sim.state.body_vel.numpy()[body, 0]) == pytest.approx(speed, rel=2e-3)
    else:
        assert float(sim.state.body_pos.numpy()[body, 0]) == pytest.approx(speed ** 2 / (2 * 0.2 * G), rel=0.01)


def test_a_real_step_still_stops_a_sliding_box(device):
    """The far slab 5 cm higher: its side face is not covered (the near slab's face is smaller; the
    near slab's face is, by it), so a cube sliding into it at 3 m/s stops against it (it would
    otherwise slide 2.3 m)."""
    b = ModelBuilder(Material(friction=0.2))
    b.add_box((2.0, 0.5, 5.0), 1.0, position=(-2.0, -0.5, 0.0), static=True)
    b.add_box((2.0, 0.525, 5.0), 1.0, position=(2.0, -0.475, 0.0), static=True)
    cube = b.add_box((0.25, 0.25, 0.25), 1.0, position=(-1.0, 0.25, 0.0), velocity=(3.0, 0.0, 0.0))
    model = b.finalize(device)
    assert model.host["body_covered_faces"][0] == face_bit(0, 1.0) and model.host["body_covered_faces"][1] == 0
    sim = Simulator(model, SimConfig(sleep=False, device=device))
    sim.step(90)
    assert float(sim.state.body_pos.numpy()[cube, 0]) < -0.25 + 1e-3


def test_covered_faces_are_the_faces_another_static_box_lies_on_and_contains():
    b = ModelBuilder(Material())
    b.add_box((1.0, 0.5, 1.0), 1.0, position=(-1.0, 0.0, 0.0), static=True)   # 0: its +x face on 1's -x face
    b.add_box((1.0, 0.5, 1.0), 1.0, position=(1.0, 0.0, 0.0), static=True)    # 1
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(1.0, 0.0, 1.5), static=True)    # 2: narrower, on 1's +z face
    b.add_box((1.0, 0.5, 1.0), 1.0, position=(1.0, 0.0, -2.001), static=True)  # 3: 1 mm from 1: no
    b.add_box((1.0, 0.5, 1.0), 1.0, position=(-1.0, 1.0, 0.0))                # 4: dynamic on 0: no mask
    turned = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))          # 5, 6: turned 90 deg about z
    b.add_box((0.5, 1.0, 1.0), 1.0, position=(10.0, 0.0, 0.0), orientation=turned, static=True)
    b.add_box((0.5, 1.0, 1.0), 1.0, position=(10.0, 1.0, 0.0), orientation=turned, static=True)
    mask = b.finalize("cpu").host["body_covered_faces"]
    assert mask[0] == face_bit(0, 1.0)
    # 2 covers only part of 1's +z face, but 1 covers all of 2's -z face
    assert mask[1] == face_bit(0, -1.0)
    assert mask[2] == face_bit(2, -1.0)
    assert mask[3] == 0 and mask[4] == 0
    # stacked along world y, which is each box's local +x (a quarter turn about z): 5's top is 6's bottom
    assert mask[5] == face_bit(0, 1.0) and mask[6] == face_bit(0, -1.0)


def test_faces_under_the_ground_plane_are_covered_by_it():
    """A box set flush into the plane has every face in the ground's half-space (its top lies on
    the surface, which supports the same bodies); 1 mm proud, its top and the upper edges of its
    sides are above the ground and nothing is covered; sunk 0.3 m into a plane tilted 10 degrees,
    with its top 5 cm under the plane's height at its centre, its bottom and the side wholly below
    the surface are."""
    b = ModelBuilder(Material())
    b.set_terrain(PlaneTerrain())
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, -0.5, 0.0), static=True)
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(3.0, -0.499, 0.0), static=True)
    mask = b.finalize("cpu").host["body_covered_faces"]
    assert mask[0] == 0b111111 and mask[1] == face_bit(1, -1.0)
    tilt = math.radians(10.0)
    b = ModelBuilder(Material())
    b.set_terrain(PlaneTerrain(normal=(-math.sin(tilt), math.cos(tilt), 0.0)))
    b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, -0.55, 0.0), static=True)
    mask = b.finalize("cpu").host["body_covered_faces"]
    # the surface is y = x tan(10): at x = 0.5 it is 0.088 above the top (y -0.05), at x = -0.5
    # 0.038 below it, so the +x side and the bottom are under it, the top and the other sides not
    assert mask[0] == face_bit(1, -1.0) | face_bit(0, 1.0)
