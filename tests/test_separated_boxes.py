"""Speculative box-box contacts: boxes apart by less than the margin must get a point, and no
point may claim a gap smaller than the boxes' true distance.

The true distance is a float64 brute force over the features that can hold the closest points
of two boxes: every vertex clamped into the other box (vertex against face, edge or vertex) and
every pair of edges (closest points of two segments).
"""

import itertools
import math

import numpy as np
import pytest

from test_primitives import box, collide, rotation

MARGIN = 0.05


def box_vertices(b):
    return [b["pos"] + b["rot"] @ (np.array(s) * b["size"]) for s in itertools.product((-1.0, 1.0), repeat=3)]


def box_edges(b):
    corners = list(itertools.product((-1.0, 1.0), repeat=3))
    edges = []
    for s, t in itertools.combinations(corners, 2):
        if sum(u != v for u, v in zip(s, t)) == 1:
            edges.append((b["pos"] + b["rot"] @ (np.array(s) * b["size"]), b["pos"] + b["rot"] @ (np.array(t) * b["size"])))
    return edges


def point_box_distance(p, b):
    local = b["rot"].T @ (p - b["pos"])
    return np.linalg.norm(local - np.clip(local, -b["size"], b["size"]))


def segment_distance(p0, p1, q0, q1):
    """Closest distance of segments p0p1 and q0q1 (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c, b = d1 @ r, d1 @ d2
    denom = a * e - b * b
    s = np.clip((b * f - c * e) / denom, 0.0, 1.0) if denom > 1e-15 else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, np.clip(-c / a, 0.0, 1.0)
    elif t > 1.0:
        t, s = 1.0, np.clip((b - c) / a, 0.0, 1.0)
    return np.linalg.norm(p0 + s * d1 - (q0 + t * d2))


def box_distance(a, b):
    vertex = min(min(point_box_distance(v, b) for v in box_vertices(a)),
                 min(point_box_distance(v, a) for v in box_vertices(b)))
    edge = min(segment_distance(*ea, *eb) for ea in box_edges(a) for eb in box_edges(b))
    return min(vertex, edge)


def separated_family(half_a, half_b, seed, count=150):
    """Random orientations; A moved along a random direction to just touching (bisection on the
    separating-axis test), then a random 2 mm to 0.9 margin further; pairs whose true gap ends
    below 2 mm are dropped."""
    rng = np.random.default_rng(seed)
    pairs, gaps = [], []
    while len(pairs) < count:
        rot_a = rotation(rng.normal(size=3), rng.uniform(0, math.pi))
        b = box((0, 0, 0), half_b, rotation(rng.normal(size=3), rng.uniform(0, math.pi)))
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        lo, hi = 0.0, 2.0 * (np.linalg.norm(half_a) + np.linalg.norm(half_b))
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if sat_overlaps(box(mid * direction, half_a, rot_a), b) else (lo, mid)
        a = box((hi + rng.uniform(0.002, 0.9 * MARGIN)) * direction, half_a, rot_a)
        gap = box_distance(a, b)
        if 0.002 <= gap < MARGIN:
            pairs.append((a, b))
            gaps.append(gap)
    return pairs, np.array(gaps)


def sat_overlaps(a, b):
    axes = [a["rot"][:, i] for i in range(3)] + [b["rot"][:, j] for j in range(3)]
    axes += [np.cross(a["rot"][:, i], b["rot"][:, j]) for i in range(3) for j in range(3)]
    d = a["pos"] - b["pos"]
    for axis in axes:
        n = np.linalg.norm(axis)
        if n < 1e-9:
            continue
        axis = axis / n
        if abs(d @ axis) > np.abs(a["rot"].T @ axis) @ a["size"] + np.abs(b["rot"].T @ axis) @ b["size"]:
            return False
    return True


@pytest.mark.parametrize("half_a, half_b, seed", [((0.3, 0.1, 0.3), (0.3, 0.1, 0.3), 1),
                                                  ((0.5, 0.5, 0.5), (0.3, 0.05, 0.4), 2),
                                                  ((0.6, 0.1, 0.2), (0.5, 0.5, 0.5), 3),
                                                  ((0.3, 0.02, 0.3), (0.2, 0.2, 0.2), 4)])
def test_boxes_closer_than_the_margin_get_their_true_distance_as_the_nearest_gap(half_a, half_b, seed,
                                                                                  device):
    """Plates, cubes, bars and a sheet at random poses, apart by 2 mm to 0.9 of the margin.  Each
    pair has a point: a face clip lying wholly beside its reference face gave none (0, 1 and 3 of
    these 150-pair families before the separated fallback; in a rain a plate falling past
    another's edge met it with no contact for a whole step).  The nearest point's gap is the true
    distance, to float32 rounding on unit-sized boxes (2e-5), both ways:
    - never below it: a contact acting before the bodies can touch stops them apart (the edge
      point's axis separation did that in 0, 2 and 1 pairs);
    - never above it: a clip's or strip's points are the incident face's corners and crossings,
      which can all lie further than the nearest features (27 to 37 of each 150 pairs here, up to
      1.7 times the distance; a plate falling past another's edge, its strip 96 mm off while the edges were 51 mm
      apart, went 29 mm into it), so the nearest vertex or edge pair is added to them
      (box_box.with_nearest)."""
    pairs, gaps = separated_family(half_a, half_b, seed)
    results = collide("box_box", pairs, MARGIN, device)
    for r, gap in zip(results, gaps):
        assert r["count"] >= 1, f"no point for boxes {gap:.4f} m apart"
        nearest = -r["depth"].max()
        assert gap - 2e-5 <= nearest <= gap + 2e-5


@pytest.mark.parametrize("step_depth", [0.5, 1.0, 1.5, 2.0, 3.0, 4.0])
@pytest.mark.parametrize("gap", [0.0125, 0.02, 0.037])
def test_a_face_approaching_a_face_keeps_the_clip_corners(step_depth, gap, device):
    """A cube's face approaching a step's side face, their bottoms flush (a cube sliding into a
    step): the manifold is the four corners of the overlap, 2 at the step's top edge and 2 at the
    bottom, in either body order.  The nearest pair of features is as deep as those to rounding;
    it took a clip point's slot for some step sizes (the step's top corner on one side replaced by
    a copy of a bottom corner), and the cube tripped on one top corner."""
    from test_primitives import box
    a, s = 0.4, 0.15
    cube = box((0.3 - a - gap, a, 0.0), (a, a, a))
    step = box((0.3 + step_depth, s / 2, 0.0), (step_depth, s / 2, 2.0))
    for pair in ((step, cube), (cube, step)):
        r = collide("box_box", [pair], MARGIN, device)[0]
        points = np.round(np.asarray(r["point"])[:, 1:], 4)
        assert sorted(map(tuple, points)) == [(0.0, -a), (0.0, a), (s, -a), (s, a)]
        np.testing.assert_allclose(r["depth"], -gap, atol=2e-5)
