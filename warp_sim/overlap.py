"""Initial overlaps: bodies inside each other or inside the terrain when a scene starts.

``find_overlaps(builder)`` runs in NumPy at build time and scales to millions of bodies:

* Candidate pairs come from a uniform grid of cell size 2 x the largest bounding radius (bodies
  sorted by cell, the cell and 13 neighbours looked up with searchsorted), then the bounding
  spheres.
* Sphere-sphere is exact; sphere-box uses the box's closest point to the centre; box-box uses
  the 15 separating axes, whose smallest overlap is the penetration depth of two boxes.
* Terrain: a sphere overlaps when the surface point straight below (or above) its centre is
  closer than its radius (the centre's distance to the surface is at most that vertical gap, so
  this never flags a sphere that is clear); a box when one of its corners is under the surface by
  more than the tolerance along the normal (the vertical depth times the slope factor); planes
  use the exact signed distance.

Static bodies are never reported inside the terrain or each other (they do not move, so
nothing is pushed apart), only overlapping a moving body.  Only overlaps deeper than
``TOLERANCE`` (1 mm) count, so bodies that just touch (stacks and
pyramids with gap 0, a cradle of touching balls, boxes resting on the ground) are not reported.
"""

from __future__ import annotations

import numpy as np

from .builder import quats_to_matrices
from .types import SHAPE_BOX, SHAPE_SPHERE

TOLERANCE = 1e-3  # m
_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64)


def _expand(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (p[k], q) for q in [lo[k], hi[k])."""
    counts = np.maximum(hi - lo, 0)
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    step = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    return np.repeat(p, counts), np.repeat(lo, counts) + step


def _candidate_pairs(pos: np.ndarray, bound: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs whose bounding spheres overlap by more than TOLERANCE, each once.

    Cells of 2 x the largest bounding radius get a linear index (the grid padded by one cell, so
    a neighbour's index is the body's plus a constant); bodies are sorted by it, and the same cell
    plus 13 of the 26 neighbours (one of each opposite pair: the next cell in z and four rows of
    three cells adjacent in z, so five key ranges) are looked up with searchsorted.
    """
    n = len(pos)
    empty = np.zeros(0, np.int64), np.zeros(0, np.int64)
    if n < 2:
        return empty
    cell = max(2.0 * float(bound.max()), 1e-9)
    coords = np.floor(pos / cell).astype(np.int64)
    coords -= coords.min(axis=0) - 1
    dims = coords.max(axis=0) + 2
    if float(dims[0]) * float(dims[1]) * float(dims[2]) >= 2.0 ** 62:
        raise ValueError(f"the bodies spread over {dims.tolist()} cells of {cell:g} m, too many to check for overlaps")
    stride = np.array([dims[1] * dims[2], dims[2], 1], np.int64)
    keys = coords @ stride
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    positions = np.arange(n)
    firsts, seconds = [], []
    run_end = np.searchsorted(sorted_keys, sorted_keys, "right")
    i, j = _expand(positions, positions + 1, run_end)  # same cell, later in the run
    firsts.append(i)
    seconds.append(j)
    # the next cell in z, then 4 rows of 3 cells (dz = -1, 0, 1 are adjacent keys: one range each)
    for delta, width in ((1, 0), (stride[1], 1), (stride[0] - stride[1], 1), (stride[0], 1),
                         (stride[0] + stride[1], 1)):
        lo = np.searchsorted(sorted_keys, sorted_keys + (delta - width), "left")
        hi = np.searchsorted(sorted_keys, sorted_keys + (delta + width), "right")
        i, j = _expand(positions, lo, hi)
        firsts.append(i)
        seconds.append(j)
    i, j = order[np.concatenate(firsts)], order[np.concatenate(seconds)]
    i, j = np.minimum(i, j), np.maximum(i, j)
    d = np.linalg.norm(pos[i] - pos[j], axis=1)
    near = d < bound[i] + bound[j] - TOLERANCE
    return i[near], j[near]


def _sphere_box_depth(center, radius, box_pos, box_rot, half):
    local = np.einsum("nji,nj->ni", box_rot, center - box_pos)
    closest = np.clip(local, -half, half)
    dist = np.linalg.norm(local - closest, axis=1)
    inside = np.all(np.abs(local) <= half, axis=1)
    return np.where(inside, radius + np.min(half - np.abs(local), axis=1), radius - dist)


def _box_box_depth(pa, ra, ha, pb, rb, hb):
    """Smallest overlap over the 15 separating axes (negative: separated)."""
    axes = [ra[:, :, k] for k in range(3)] + [rb[:, :, k] for k in range(3)]
    for a in range(3):
        for b in range(3):
            axes.append(np.cross(ra[:, :, a], rb[:, :, b]))
    d = pb - pa
    depth = np.full(len(pa), np.inf)
    for axis in axes:
        length = np.linalg.norm(axis, axis=1)
        valid = length > 1e-9  # parallel edges: the face axes already cover them
        u = axis / np.where(valid, length, 1.0)[:, None]
        extent_a = np.sum(ha * np.abs(np.einsum("nij,ni->nj", ra, u)), axis=1)
        extent_b = np.sum(hb * np.abs(np.einsum("nij,ni->nj", rb, u)), axis=1)
        overlap = extent_a + extent_b - np.abs(np.sum(d * u, axis=1))
        depth = np.where(valid, np.minimum(depth, overlap), depth)
    return depth


def _terrain_depths(terrain, shape, size, pos, rot) -> np.ndarray:
    """Depth of each body into the terrain (see the module docstring); <= 0 when clear."""
    from .terrain import FourierTerrain, PlaneTerrain

    n = len(shape)
    depth = np.full(n, -np.inf)
    if not isinstance(terrain, (FourierTerrain, PlaneTerrain)) or n == 0:
        return depth
    spheres = np.flatnonzero(shape == SHAPE_SPHERE)
    boxes = np.flatnonzero(shape == SHAPE_BOX)
    corner_pts = pos[boxes][:, None, :] + np.einsum("nij,nkj->nki", rot[boxes], _CORNERS[None] * size[boxes][:, None])
    if isinstance(terrain, PlaneTerrain):
        nrm = np.asarray(terrain.normal)
        depth[spheres] = size[spheres, 0] - (pos[spheres] @ nrm - terrain.offset)
        if len(boxes):
            depth[boxes] = np.max(terrain.offset - corner_pts @ nrm, axis=1)
        return depth
    # bodies whose lowest point is above the highest the surface can reach need no evaluation
    top = terrain.offset[1] + terrain.max_height_deviation()
    spheres = spheres[pos[spheres, 1] - size[spheres, 0] <= top]
    if len(boxes):
        low = corner_pts[:, :, 1].min(axis=1) <= top
        boxes, corner_pts = boxes[low], corner_pts[low]
    r = size[spheres, 0]
    p = pos[spheres]
    depth[spheres] = r - (p[:, 1] - terrain.height(p[:, 0], p[:, 2]))
    if len(boxes):
        flat = corner_pts.reshape(-1, 3)
        vertical = terrain.height(flat[:, 0], flat[:, 2]) - flat[:, 1]
        slope = np.sqrt(1.0 + terrain.slope_bound() ** 2)
        depth[boxes] = np.max(vertical.reshape(len(boxes), 8), axis=1) / slope
    return depth


def find_overlaps(builder, limit: int = 5) -> dict:
    """{"pairs": [(i, j, depth), ...], "terrain": [(i, depth), ...], "pair_count", "terrain_count"}
    for overlaps deeper than TOLERANCE (the deepest ``limit`` of each kind); {} when there are none."""
    c = builder.columns()
    shape, size, pos = c["shape"], c["size"], c["position"]
    n = len(shape)
    if n == 0:
        return {}
    rot = np.zeros((n, 3, 3))
    box = np.flatnonzero(shape == SHAPE_BOX)  # spheres need no rotation
    q = c["orientation"][box]
    rot[box] = quats_to_matrices(q / np.linalg.norm(q, axis=1, keepdims=True))
    bound = np.where(shape == SHAPE_SPHERE, size[:, 0], np.linalg.norm(size, axis=1))
    i, j = _candidate_pairs(pos, bound)
    depth = np.full(len(i), -np.inf)
    si, sj = shape[i] == SHAPE_SPHERE, shape[j] == SHAPE_SPHERE
    both = si & sj
    depth[both] = size[i[both], 0] + size[j[both], 0] - np.linalg.norm(pos[i[both]] - pos[j[both]], axis=1)
    for sphere_first in (True, False):
        sel = (si & ~sj) if sphere_first else (~si & sj)
        s, b = (i[sel], j[sel]) if sphere_first else (j[sel], i[sel])
        if len(s):
            depth[sel] = _sphere_box_depth(pos[s], size[s, 0], pos[b], rot[b], size[b])
    boxes = ~si & ~sj
    if boxes.any():
        a, b = i[boxes], j[boxes]
        depth[boxes] = _box_box_depth(pos[a], rot[a], size[a], pos[b], rot[b], size[b])
    static = c["static"]
    hit = (depth > TOLERANCE) & ~(static[i] & static[j])
    ground = np.where(static, -np.inf, _terrain_depths(builder.terrain, shape, size, pos, rot))
    under = np.flatnonzero(ground > TOLERANCE)
    if not hit.any() and len(under) == 0:
        return {}
    worst = np.argsort(-depth[hit])[:limit]
    hi, hj, hd = i[hit][worst], j[hit][worst], depth[hit][worst]
    worst_under = under[np.argsort(-ground[under])[:limit]]
    return {"pairs": [(int(a), int(b), float(d)) for a, b, d in zip(hi, hj, hd)],
            "terrain": [(int(a), float(ground[a])) for a in worst_under],
            "pair_count": int(hit.sum()), "terrain_count": int(len(under))}


def _length(d: float) -> str:
    return f"{d:.3g} m" if d >= 1.0 else f"{d * 1000:.3g} mm"


def describe_overlaps(found: dict, origin=lambda i: f"body {i}") -> str:
    """One line naming the bodies (``origin(i)`` says where body i came from)."""
    parts = []
    if found.get("pairs"):
        a, b, d = found["pairs"][0]
        more = found["pair_count"] - 1
        parts.append(f"bodies {a} ({origin(a)}) and {b} ({origin(b)}) overlap by {_length(d)} at the start"
                     + (f", and {more} more pairs overlap" if more else ""))
    if found.get("terrain"):
        a, d = found["terrain"][0]
        more = found["terrain_count"] - 1
        parts.append(f"body {a} ({origin(a)}) starts {_length(d)} inside the terrain"
                     + (f", and {more} more bodies do" if more else ""))
    return "; ".join(parts)
