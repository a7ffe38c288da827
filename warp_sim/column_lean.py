"""How far a scene's soft contacts let a leaning column tip, and the substeps that keep it up.

A column whose load rests off the centre of its supports (books stacked to overhang a table's
edge, a staircase of boxes) stands while each support carries the centre of mass of all that rests
on it inside the area the two share.  Rigid bodies stand at any margin inside; soft contacts
(solvers/soft_step.py) need some.  A contact point of effective mass m_p is a spring of stiffness
m_p omega^2 (column_sag.py), so an interface loaded off its centre turns: load W whose centre of
mass lies at horizontal offset e from the points' stiffness centre z tilts it by

    theta = W e / K,    K = omega^2 sum_p m_p ((p - z) . l)^2

(l the direction of e), and each interface tilting below the centre of mass of a load carries it
sideways by theta_i (h_c - h_i) (h_c its height, h_i the interface's).  S, the sum down the column,
is the static shift, and it is not what tips a column: 8 unit cubes, each 80 mm inside its
support's edge, shift by S = 32 to 36 mm at 4 substeps, and with gravity ramped in over a second
they stand.  What tips a column is setting it down cold: every contact starts unloaded, the column
sinks into its springs within a few substeps, and the turn that sinking starts has the speed
theta Omega, Omega = sqrt(K / I) the turning mode's frequency, I the load's moment of inertia about
the edge.  Once the inner side lifts, only the margin d holds it, against a rise of the centre of
mass of about d^2 / (2 H) (H its height over the edge); the kinetic energy I (theta Omega)^2 / 2
clears that when d < theta sqrt(K H / W) = sqrt(e S) (with S ~ theta H).  So a column set down cold
needs a margin of about sqrt(e S): the geometric mean of the load's offset and the static shift.
Measured on staircases of 3 to 8 unit cubes at 4 to 32 substeps (python bench/column_lean.py,
bench/results/column_lean.*), those that fell had margins of up to 0.80 sqrt(e S), those that stood
0.94 sqrt(e S) or more; columns it was not fitted on (random masses, plates, bars, a turned column,
one over a table's edge) fell up to 0.54 and stood from 0.66.  The plan asks for LEAN_SAFETY = 2
times it.  S falls as omega^-2, so sqrt(e S) as the substep h (column_sag.contact_hertz: omega =
2 pi / (4 h)), and a column that needs margin d' at n substeps needs d' n / n' at n'.

``lean_terms`` finds the supports a scene starts with: a box resting flat on the top face of a box
below it (dynamic or static, the faces within TOUCH_SHARE of the thinner body's thickness of each
other and overlapping) or on the ground.  A body on two supports or more (a brick bridging two
others) shares its load in a way these springs alone do not say, so its supports and those below
them are not checked, nor is a centre of mass on its support's edge (EDGE_TIE) or past it.
Spheres rest on a point and are skipped (a ball on a ball stands on no margin).  Only the columns a scene starts with are planned; piles that form later are not
foreseen, as with the sag.
"""

from __future__ import annotations

import math

import numpy as np

from .types import SHAPE_BOX

# A face lies flat when its normal is within this angle's cosine of up (1 degree)
FLAT_COS = math.cos(math.radians(1.0))
# Two faces touch when they are this share of the thinner body's thickness apart, or nearer
TOUCH_SHARE = 0.02
# Set down cold, a leaning column needs a margin of LEAN_SAFETY sqrt(e S) (module docstring); the
# columns measured fell up to 0.80 sqrt(e S) and stood from 0.94 (bench/column_lean.py)
LEAN_SAFETY = 2.0
# A centre of mass within this share of the box's size of its support's edge lies on the edge (a
# running-bond wall's end bricks, placed half over the brick below): neutral balance, which no
# substeps make stand, so it is not checked (float noise is ~1e-7 of it; the table tests' 2.5 mm
# on a 1 m block is 2.5e-3)
EDGE_TIE = 1.0e-4


def _box_faces(pos, rot, size, up):
    """Each box's face most nearly along up: (how flat it lies, |its normal . up|; the face's two
    half-extent vectors; the box's half thickness along up)."""
    alignment = np.abs(np.einsum("nij,i->nj", rot, up))
    axis = np.argmax(alignment, axis=1)
    rows = np.arange(len(pos))
    first = (axis + 1) % 3
    second = (axis + 2) % 3
    d1 = rot[rows, :, first] * size[rows, first][:, None]
    d2 = rot[rows, :, second] * size[rows, second][:, None]
    half_height = size[rows, axis] * alignment[rows, axis]
    return alignment[rows, axis], d1, d2, half_height


def _interfaces(rows, single, load, moment, bottom, inv_mass, inv_inertia, rot, pos, dynamic, e1, e2, up):
    """Per checked body (``rows``), its support's (tilt [rad] times omega^2 / g, unit lean direction,
    height, centre of mass of the load (horizontal, height), margin, load offset e), all bodies at
    once: each support's polygon padded to 12 points of no weight (two rectangles meet in at most 8)."""
    count = len(rows)
    rows = np.asarray(rows)
    support = np.array([single[u][0] for u in rows])
    points = np.zeros((count, 12, 2))
    used = np.zeros((count, 12), dtype=bool)
    for k, u in enumerate(rows):
        polygon = np.array(single[u][1])[:12]
        points[k, :len(polygon)] = polygon
        used[k, :len(polygon)] = True
    level = bottom[rows]
    com = moment[rows] / load[rows][:, None]
    world = points[..., 0:1] * e1 + points[..., 1:2] * e2 + level[:, None, None] * up
    has_support = support >= 0
    other = np.where(has_support, support, 0)
    k_n = (inv_mass[rows] + np.where(has_support, inv_mass[other], 0.0))[:, None] + np.zeros((count, 12))
    for body, present in ((rows, np.ones(count, dtype=bool)), (other, has_support & dynamic[other])):
        inertia = np.einsum("nij,nj,nkj->nik", rot[body], inv_inertia[body], rot[body])
        arm = np.cross(world - pos[body][:, None, :], up)
        k_n = k_n + np.where(present[:, None], np.einsum("npi,nij,npj->np", arm, inertia, arm), 0.0)
    weight = np.where(used, 1.0 / np.where(used, k_n, 1.0), 0.0)  # each point's effective mass
    centre = (weight[..., None] * points).sum(1) / weight.sum(1)[:, None]
    lean = com[:, :2] - centre
    offset = np.linalg.norm(lean, axis=1)
    direction = lean / np.maximum(offset, 1e-300)[:, None]
    arms = np.einsum("npi,ni->np", points - centre[:, None, :], direction)
    stiffness = (weight * arms * arms).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tilt = np.where(offset > 1e-12, load[rows] * offset / stiffness, 0.0)
    margin = np.array([_margin(single[u][1], com[k, :2]) for k, u in enumerate(rows)])
    return tilt, direction, level, com, margin, offset


def _candidates(uppers, lowers, bottom, top, flat2, reach, band: float, dynamic):
    """(upper, lower) index pairs worth a closer look: the lower's top within ``band`` of the
    upper's bottom and their centres within reach of each other.  Dynamic lowers are hashed by
    height band and a horizontal grid of the uppers' largest reach (a lattice of touching cubes
    compares each cube with its nine neighbours below, not a whole layer); static ones, which may
    be far larger (a table), are compared with every upper."""
    band = max(band, 1e-9)
    cell = 2.0 * float(reach[uppers].max())
    pairs_u, pairs_l = [], []
    moving = lowers[dynamic[lowers]]
    if len(moving) and len(uppers):
        def keys(index, height):
            ij = np.floor(flat2[index] / cell).astype(np.int64)
            return np.floor(height / band).astype(np.int64), ij[:, 0], ij[:, 1]

        lb, lx, lz = keys(moving, top[moving])
        ub, ux, uz = keys(uppers, bottom[uppers])
        lowest = np.array([min(lb.min(), ub.min()), min(lx.min(), ux.min()), min(lz.min(), uz.min())]) - 1
        span = np.array([max(lb.max(), ub.max()), max(lx.max(), ux.max()), max(lz.max(), uz.max())]) + 2 - lowest

        def combine(b, x, z):
            return ((b - lowest[0]) * span[1] + (x - lowest[1])) * span[2] + (z - lowest[2])

        order = np.argsort(combine(lb, lx, lz), kind="stable")
        sorted_keys = combine(lb, lx, lz)[order]
        for db in (-1, 0, 1):
            for dx in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    query = combine(ub + db, ux + dx, uz + dz)
                    first = np.searchsorted(sorted_keys, query, "left")
                    count = np.searchsorted(sorted_keys, query, "right") - first
                    total = int(count.sum())
                    if total == 0:
                        continue
                    starts = np.repeat(first - np.cumsum(count) + count, count)
                    pairs_u.append(np.repeat(uppers, count))
                    pairs_l.append(moving[order[starts + np.arange(total)]])
    still = lowers[~dynamic[lowers]]
    chunk = max(1, (1 << 22) // max(len(still), 1))  # a few million pairs at a time
    for k in range(0, len(uppers) if len(still) else 0, chunk):
        grid_u, grid_l = np.meshgrid(uppers[k:k + chunk], still, indexing="ij")
        grid_u, grid_l = grid_u.ravel(), grid_l.ravel()
        near = np.abs(top[grid_l] - bottom[grid_u]) <= band
        pairs_u.append(grid_u[near])
        pairs_l.append(grid_l[near])
    if not pairs_u:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    upper, lower = np.concatenate(pairs_u), np.concatenate(pairs_l)
    close = np.linalg.norm(flat2[upper] - flat2[lower], axis=1) < reach[upper] + reach[lower]
    return upper[close], lower[close]


def _rectangles_overlap(c_a, a1, a2, c_b, b1, b2) -> np.ndarray:
    """Whether two rectangles in the plane (centres, half-extent vectors) share an area: separating
    axes, the four edge directions; faces meeting along an edge or at a corner only do not count
    (a lattice's neighbours)."""
    delta = c_b - c_a
    overlap = np.ones(len(delta), dtype=bool)
    for axis in (a1, a2, b1, b2):
        length = np.linalg.norm(axis, axis=1)
        unit = axis / np.maximum(length, 1e-300)[:, None]

        def radius(v1, v2):
            return np.abs(np.sum(v1 * unit, 1)) + np.abs(np.sum(v2 * unit, 1))

        reach = radius(a1, a2) + radius(b1, b2)
        overlap &= np.abs(np.sum(delta * unit, 1)) < reach * (1.0 - 1e-6)
    return overlap


def _clip(subject: list, clip: list) -> list:
    """The intersection of two convex polygons in the plane (counter-clockwise vertex lists):
    Sutherland-Hodgman."""
    out = subject
    for k in range(len(clip)):
        a, b = clip[k], clip[(k + 1) % len(clip)]
        edge = b - a
        inside = lambda p: edge[0] * (p[1] - a[1]) - edge[1] * (p[0] - a[0]) >= 0.0  # noqa: E731
        points, out = out, []
        for i in range(len(points)):
            p, q = points[i], points[(i + 1) % len(points)]
            if inside(q):
                if not inside(p):
                    out.append(_cross_point(p, q, a, b))
                out.append(q)
            elif inside(p):
                out.append(_cross_point(p, q, a, b))
        if not out:
            return []
    return out


def _cross_point(p, q, a, b):
    d = q - p
    e = b - a
    denom = d[0] * e[1] - d[1] * e[0]
    t = ((a[0] - p[0]) * e[1] - (a[1] - p[1]) * e[0]) / denom if denom != 0.0 else 0.0
    return p + t * d


def _rectangle(centre, d1, d2):
    """A face's corners in the horizontal plane, counter-clockwise."""
    corners = [centre + d1 + d2, centre - d1 + d2, centre - d1 - d2, centre + d1 - d2]
    area = (corners[1][0] - corners[0][0]) * (corners[2][1] - corners[0][1]) - \
        (corners[2][0] - corners[0][0]) * (corners[1][1] - corners[0][1])
    return corners if area > 0.0 else corners[::-1]


def _margin(polygon: list, point) -> float:
    """The distance from ``point`` to the edge of a convex polygon, negative outside it."""
    best = math.inf
    for k in range(len(polygon)):
        a, b = polygon[k], polygon[(k + 1) % len(polygon)]
        edge = b - a
        length = math.hypot(edge[0], edge[1])
        if length == 0.0:
            continue
        best = min(best, (edge[0] * (point[1] - a[1]) - edge[1] * (point[0] - a[0])) / length)
    return best


def lean_terms(host, pos, rot, up, terrain_height=None):
    """The leaning columns a scene starts with: a list of (shift coefficient, e, margin), one a
    checked interface, where g / omega^2 times the coefficient is the static shift S [m] of the
    centre of mass resting on it (module docstring), e [m] that centre's offset from the
    interface's stiffness centre, and margin [m] how far inside the shared area it lies.

    ``terrain_height(x, z)``: the ground's height where up is +y (None: no ground supports).
    """
    inv_mass = np.asarray(host["body_inv_mass"], dtype=np.float64)
    shape = np.asarray(host["body_shape"])
    size = np.asarray(host["body_size"], dtype=np.float64)
    inv_inertia = np.asarray(host["body_inv_inertia"], dtype=np.float64)
    pos = np.asarray(pos, dtype=np.float64)
    rot = np.asarray(rot, dtype=np.float64)
    n = len(pos)
    box = shape == SHAPE_BOX
    flatness, d1, d2, half_height = _box_faces(pos, rot, size, up)
    flat = box & (flatness >= FLAT_COS)
    dynamic = inv_mass > 0.0
    if not np.any(flat & dynamic):
        return []
    # horizontal frame
    a = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    e1 = np.cross(up, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    height = pos @ up
    top = height + half_height
    bottom = height - half_height
    thickness = 2.0 * half_height
    tolerance = TOUCH_SHARE * thickness
    flat2 = np.stack([pos @ e1, pos @ e2], 1)
    f1 = np.stack([d1 @ e1, d1 @ e2], 1)
    f2 = np.stack([d2 @ e1, d2 @ e2], 1)
    reach = np.sqrt(np.sum(f1 * f1, 1)) + np.sqrt(np.sum(f2 * f2, 1))

    # supports: a flat box whose top face lies at a flat dynamic box's bottom face, overlapping it
    uppers = np.flatnonzero(flat & dynamic)
    lowers = np.flatnonzero(flat)
    upper, lower = _candidates(uppers, lowers, bottom, top, flat2, reach, TOUCH_SHARE * float(thickness[flat].max()),
                               dynamic)
    gap = np.abs(bottom[upper] - top[lower])
    keep = (upper != lower) & (gap <= TOUCH_SHARE * np.minimum(thickness[upper], thickness[lower]))
    keep &= _rectangles_overlap(flat2[upper], f1[upper], f2[upper], flat2[lower], f1[lower], f2[lower])
    supports: dict[int, list] = {int(u): [] for u in uppers}
    for u, s in zip(upper[keep], lower[keep]):
        polygon = _clip(_rectangle(flat2[u], f1[u], f2[u]), _rectangle(flat2[s], f1[s], f2[s]))
        if len(polygon) >= 3:
            supports[int(u)].append((int(s), polygon))
    ground = {}
    if terrain_height is not None and len(uppers):
        below = np.asarray(terrain_height(pos[uppers, 0], pos[uppers, 2]), dtype=np.float64)
        for u in uppers[np.abs(bottom[uppers] - below) <= tolerance[uppers]]:
            ground[int(u)] = _rectangle(flat2[u], f1[u], f2[u])

    # loads: each body's own mass plus what rests on it alone, from the top down; a body on two
    # supports or more spoils the count of those below it
    mass = np.where(dynamic, 1.0 / np.where(dynamic, inv_mass, 1.0), 0.0)
    load = mass.copy()
    moment = mass[:, None] * np.c_[flat2, height]
    clean = np.ones(n, dtype=bool)
    single = {}
    for u in sorted(supports, key=lambda k: -height[k]):
        count = len(supports[u]) + (u in ground)
        if count != 1:
            for s, _ in supports[u]:
                clean[s] = False
            continue
        if supports[u]:
            s, polygon = supports[u][0]
            single[u] = (s, polygon)
            if dynamic[s]:
                load[s] += load[u]
                moment[s] += moment[u]
                clean[s] &= clean[u]
        else:
            single[u] = (-1, ground[u])

    rows = [u for u in single if clean[u]]
    if not rows:
        return []
    row_of = {u: k for k, u in enumerate(rows)}
    tilt, direction, level, com, margin, offset = _interfaces(
        rows, single, load, moment, bottom, inv_mass, inv_inertia, rot, pos, dynamic, e1, e2, up)
    terms = []
    for u in rows:
        k = row_of[u]
        if single[u][0] < 0 or margin[k] <= EDGE_TIE * reach[u] or not np.isfinite(tilt[k]):
            continue  # the ground reaches on (no margin to check there); on or past its edge it falls
        # the tilts of this interface and of every clean one below it carry the load sideways
        shift = np.zeros(2)
        body = u
        while True:
            j = row_of[body]
            shift += tilt[j] * direction[j] * (com[k, 2] - level[j])
            below = single[body][0]
            if below < 0 or not dynamic[below] or below not in row_of:
                break
            body = below
        terms.append((float(np.linalg.norm(shift)), float(offset[k]), float(margin[k])))
    return terms
