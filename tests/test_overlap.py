"""Initial overlaps are reported naming the bodies; touching bodies and the shipped scenes pass."""

import math
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from warp_sim import FourierTerrain, ModelBuilder, PlaneTerrain
from warp_sim.overlap import TOLERANCE, find_overlaps
from warp_sim.scene import SceneError, load_scene, parse_scene

ROOT = Path(__file__).resolve().parents[1]
BALL = {"shape": "sphere", "radius": 0.25, "position": [0.0, 1.0, 0.0]}


def test_two_bodies_in_the_same_place():
    with pytest.raises(SceneError) as e:
        parse_scene({"body": [BALL, BALL]}, "s.toml")
    assert str(e.value) == ("s.toml: bodies 0 ([[body]] #1) and 1 ([[body]] #2) overlap by 500 mm at the start "
                            "(set [sim] allow_initial_overlap = true to run anyway)")


def test_a_body_inside_a_stack():
    box = {"shape": "box", "half_extents": [0.2, 0.2, 0.2], "position": [0.0, 0.65, 0.0]}
    with pytest.raises(SceneError, match=r"bodies 0 \(\[\[body\]\] #1\) and 2 \(\[\[layout\]\] #1 \(stack\), its body "
                                         r"2 of 3\) overlap by 350 mm"):
        parse_scene({"body": [box], "layout": [{"type": "stack", "count": 3}]}, "s.toml")


def test_a_body_under_the_terrain():
    data = {"terrain": {"kind": "fourier"}, "body": [dict(BALL, position=[2.0, -5.0, 1.0])]}
    with pytest.raises(SceneError, match=r"body 0 \(\[\[body\]\] #1\) starts 4.98 m inside the terrain"):
        parse_scene(data, "s.toml")
    box = {"shape": "box", "half_extents": [0.3, 0.3, 0.3], "position": [0.0, 0.2, 0.0]}
    with pytest.raises(SceneError, match=r"starts 100 mm inside the terrain"):
        parse_scene({"terrain": {"kind": "plane"}, "body": [box]}, "s.toml")


def test_allowed_overlap_is_a_warning():
    with pytest.warns(UserWarning, match=r"bodies 0 .* and 1 .* overlap by 500 mm"):
        scene = parse_scene({"sim": {"allow_initial_overlap": True}, "body": [BALL, BALL]}, "s.toml")
    assert scene.body_count == 2


def _pair_depth(builder):
    found = find_overlaps(builder)
    return found["pairs"][0][2] if found.get("pairs") else None


def test_touching_is_not_overlapping():
    """Bodies that just touch (within the 1 mm tolerance) pass; 2 mm of overlap does not."""
    for gap, flagged in ((0.0, False), (-0.5 * TOLERANCE, False), (-2 * TOLERANCE, True)):
        b = ModelBuilder()
        b.add_sphere(0.25, position=(0, 1, 0))
        b.add_sphere(0.1, position=(0.35 + gap, 1, 0))
        assert (_pair_depth(b) is not None) == flagged
        b = ModelBuilder()
        b.add_box((0.2, 0.3, 0.4), position=(0, 1, 0))
        b.add_box((0.2, 0.3, 0.4), position=(0, 1.6 + gap, 0))
        assert (_pair_depth(b) is not None) == flagged
        b = ModelBuilder()
        b.add_box((0.2, 0.3, 0.4), position=(0, 1, 0))
        b.add_sphere(0.1, position=(0.3 + gap, 1, 0))
        assert (_pair_depth(b) is not None) == flagged
    b = ModelBuilder()  # a sphere resting on a plane, and a box on it
    b.set_terrain(PlaneTerrain())
    b.add_sphere(0.25, position=(0, 0.25, 0))
    b.add_box((0.2, 0.2, 0.2), position=(2, 0.2, 0))
    assert find_overlaps(b) == {}


def test_rotated_boxes_apart_pass_the_separating_axes():
    """Two boxes whose bounding spheres overlap but which are apart (a 45-degree diamond next to a
    cube): the separating axes tell them apart; moved closer they overlap by the expected depth."""
    s = math.sin(math.pi / 8)
    q = (0.0, 0.0, s, math.cos(math.pi / 8))  # 45 degrees about z
    reach = 0.2 * math.sqrt(2)  # the diamond's half width along x
    for x, expected in ((0.2 + reach + 0.01, None), (0.2 + reach - 0.05, 0.05)):
        b = ModelBuilder()
        b.add_box((0.2, 0.2, 0.2), position=(0, 1, 0))
        b.add_box((0.2, 0.2, 0.2), position=(x, 1, 0), orientation=q)
        depth = _pair_depth(b)
        assert (depth is None) if expected is None else depth == pytest.approx(expected, abs=1e-9)


def test_static_bodies_may_overlap_each_other_and_the_ground():
    b = ModelBuilder()
    b.set_terrain(PlaneTerrain())
    b.add_box((1, 1, 1), position=(0, 0, 0), static=True)
    b.add_box((1, 1, 1), position=(0.5, 0, 0), static=True)
    assert find_overlaps(b) == {}
    b.add_sphere(0.3, position=(0, 1.2, 0))  # a moving body in a static one is still reported
    assert find_overlaps(b)["pairs"][0][:2] == (0, 2)


@pytest.mark.parametrize("path", sorted((ROOT / "examples" / "scenes").glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_scenes_have_no_overlaps(path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = load_scene(path)
    assert find_overlaps(scene.builder) == {}


def test_many_bodies_are_checked_quickly_and_found():
    """1e5 bodies on a lattice (a grid hash in NumPy, no pair loop); one planted overlap is found."""
    n = 100_000
    side = 317
    i = np.arange(n)
    pos = np.stack([(i % side) * 0.6, np.full(n, 2.0), (i // side) * 0.6], axis=1)
    pos[12345] = pos[12346] + (0.1, 0.0, 0.0)
    b = ModelBuilder()
    b.set_terrain(FourierTerrain())
    b.add_bodies(np.where(i % 2 == 0, "sphere", "box"), 0.2 * np.ones((n, 1)), position=pos)
    started = time.perf_counter()
    found = find_overlaps(b)
    elapsed = time.perf_counter() - started
    assert found["pair_count"] == 1 and found["pairs"][0][:2] == (12345, 12346)
    assert elapsed < 20.0  # seconds even on a loaded 2-core machine (about 0.5 s alone)
