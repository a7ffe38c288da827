"""Warm starting across collision passes (collide/narrow_phase.carry_pair_impulses).

A resting contact's accumulated impulse is the load it carries; a pass that hands a point zero
instead drops that load for a substep, and a column of boxes jolts.  Feature ids identify points
across passes, but where two equal faces meet the same place can come back under another id
(a corner one pass, a clipped edge crossing the next), so a point with a new id takes the
impulses of the old point at its place.  These tests build the two passes by hand.
"""

import numpy as np
import pytest
import warp as wp

from warp_sim.collide.narrow_phase import carry_pair_impulses

POINTS = 4


def carry(prev_points, prev_features, prev_normal, new_points, new_features, same_pair=True,
          turn=0.0, device="cpu"):
    """Run the kernel on one pair (bodies 0, 1) per pass, its normal turned by ``turn`` radians
    between them; returns the carried normal and tangent impulses of the new points."""
    def slots(values, dtype, fill):
        out = np.full((POINTS,) + np.shape(fill), fill, dtype=np.float32 if dtype != wp.int32 else np.int32)
        out[: len(values)] = values
        return wp.array(out, dtype=dtype, device=device)

    tangent = np.stack([np.asarray(prev_normal) * 0.1, np.zeros(len(prev_normal)), np.zeros(len(prev_normal))], 1)
    normal = wp.zeros(POINTS, dtype=float, device=device)
    tangent_out = wp.zeros(POINTS, dtype=wp.vec3, device=device)
    one = wp.array([1], dtype=wp.int32, device=device)
    wp.launch(carry_pair_impulses, dim=1, device=device, inputs=[
        0,
        one, wp.array([wp.vec2i(0, 1 if same_pair else 2)], dtype=wp.vec2i, device=device),
        wp.array([len(prev_points)], dtype=wp.int32, device=device),
        slots(prev_features, wp.int32, 0), wp.array([wp.vec3(0.0, 1.0, 0.0)], dtype=wp.vec3, device=device),
        slots(prev_points, wp.vec3, np.zeros(3)),
        slots(prev_normal, float, 0.0), slots(tangent, wp.vec3, np.zeros(3)),
        one, wp.array([wp.vec2i(0, 1)], dtype=wp.vec2i, device=device),
        wp.array([len(new_points)], dtype=wp.int32, device=device),
        slots(new_features, wp.int32, 0),
        wp.array([wp.vec3(np.sin(turn), np.cos(turn), 0.0)], dtype=wp.vec3, device=device),
        slots(new_points, wp.vec3, np.zeros(3)), slots([], float, 0.0), 1,
        normal, tangent_out, wp.zeros(1, dtype=wp.vec4, device=device)])
    return normal.numpy()[: len(new_points)], tangent_out.numpy()[: len(new_points)]


def square(rng, half):
    corners = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], dtype=float) * half
    return corners + rng.uniform(-5, 5, 3)


@pytest.mark.parametrize("seed", range(12))
def test_a_point_whose_id_changed_keeps_the_impulse_of_the_point_at_its_place(seed, device):
    """A face manifold comes back moved by less than a tenth of its spacing, in another order,
    with some ids changed: every point takes the impulse of the old point at its place, so the
    pair's load is carried whole (old kernel: the points with new ids got zero)."""
    rng = np.random.default_rng(seed)
    half = rng.uniform(0.02, 2.0)
    prev_points = square(rng, half)
    prev_features = rng.choice(1000, POINTS, replace=False)
    prev_normal = rng.uniform(0.1, 10.0, POINTS)
    order = rng.permutation(POINTS)
    new_points = prev_points[order] + rng.uniform(-0.1, 0.1, (POINTS, 3)) * half
    renamed = rng.random(POINTS) < 0.6
    renamed[rng.integers(POINTS)] = True  # at least one id changes
    new_features = np.where(renamed, prev_features[order] + 1000, prev_features[order])
    normal, tangent = carry(prev_points, prev_features, prev_normal, new_points, new_features,
                            device=device)
    np.testing.assert_allclose(normal, prev_normal[order], rtol=1e-6)
    np.testing.assert_allclose(tangent[:, 0], 0.1 * prev_normal[order], rtol=1e-6)
    assert normal.sum() == pytest.approx(prev_normal.sum(), rel=1e-6)


@pytest.mark.parametrize("seed", range(6))
def test_no_old_point_is_handed_out_twice_and_far_points_start_from_zero(seed, device):
    """Two new points near one old point: one takes its impulse, the other starts from zero (the
    load is not doubled); a point farther than half the old spacing from every old point is new."""
    rng = np.random.default_rng(100 + seed)
    half = rng.uniform(0.05, 1.0)
    prev_points = square(rng, half)
    prev_normal = rng.uniform(0.1, 10.0, POINTS)
    near = prev_points[0] + rng.uniform(-0.05, 0.05, (2, 3)) * half
    far = prev_points.mean(0) + np.array([0.0, 0.0, 0.0])  # the face centre: half a side from the corners
    far = far + np.array([0.0, 1.2 * half, 0.0])  # and off the face
    normal, _ = carry(prev_points, np.arange(POINTS), prev_normal, np.vstack([near, far]), [50, 51, 52],
                      device=device)
    assert sorted(normal[:2].tolist()) == pytest.approx([0.0, prev_normal[0]], rel=1e-6)
    assert normal[2] == 0.0


def test_a_feature_match_wins_over_a_nearer_point_and_a_new_pair_starts_cold(device):
    prev_points = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], dtype=float)
    prev_normal = np.array([1.0, 2.0, 3.0, 4.0])
    # new point 0 keeps the id of old point 2 although it sits on old point 0
    normal, _ = carry(prev_points, [10, 11, 12, 13], prev_normal, prev_points[[0, 1]], [12, 99],
                      device=device)
    assert normal.tolist() == pytest.approx([3.0, 2.0])
    normal, _ = carry(prev_points, [10, 11, 12, 13], prev_normal, prev_points, [10, 11, 12, 13],
                      same_pair=False, device=device)
    assert normal.tolist() == [0.0, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("turn_degrees,carried", [(2.0, True), (4.5, True), (6.0, False), (30.0, False)])
def test_points_are_matched_by_place_only_while_the_same_faces_meet(turn_degrees, carried, device):
    """A normal that turned by more than 5 degrees between passes is another contact (a box
    tipping onto its edge): a load carried along the old normal would push the wrong way, so
    points with new ids start from zero there, as before."""
    prev_points = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], dtype=float)
    prev_normal = np.array([1.0, 2.0, 3.0, 4.0])
    normal, _ = carry(prev_points, [10, 11, 12, 13], prev_normal, prev_points, [20, 21, 22, 23],
                      turn=np.radians(turn_degrees), device=device)
    assert normal.tolist() == pytest.approx(prev_normal.tolist() if carried else [0.0] * 4)
