"""How far a scene's soft contacts let its tallest column sag, and the substeps that keep it short.

A soft contact (solvers/soft_step.py) holds a load W by compressing until its spring pushes back:
a point of effective mass m_eff sags W / (m_eff omega^2), omega = 2 pi f.  The sag does not shrink
with iterations, it is what the spring is.  Down a column every contact carries all the weight
above it, so the column's top sinks by the sum

    sag = sum over the column's contacts  g W_above / (M_contact omega^2)

with M_contact the sum of the effective masses of the contact's points, each pushing back as a
spring of stiffness m_eff omega^2 (``contact_masses``): m_eff = 1 / k_n, k_n = sum over the two
bodies of 1/m + (r x n) . I^-1 (r x n), r the point's arm.  A sphere touches at one point under
its centre (r x n = 0), so M_contact is the pair's reduced mass m_a m_b / (m_a + m_b) (the body's
own mass on the ground or on a static body).  A box resting on a face touches at the face's four
corners, and for cubes that gives the reduced mass too (each corner's k_n is 4 / m against the
ground), but not for other boxes: a corner's arm turns a flat box more easily, so a plate of
0.6 x 0.2 x 0.6 m has M_contact = 0.625 m on the ground and 0.3125 m on another plate, and its
column sags 1.6 times as far as its masses alone say (measured: 25 such plates sank 11.0 mm under
a plan that took them for cubes and expected 7.5).  A tall box's arms are short, so it sags less.
On curved terrain a box's face also has points between its corners (builder.py), which only makes
the contact stiffer than estimated.  40 unit cubes: (40 + 2 (1 + ... + 39)) g / omega^2 =
1600 g / omega^2 = 110 mm at 60 Hz, as measured.

The stiffness cannot simply be raised: above a quarter of the substep rate the sweeps'
Gauss-Seidel no longer settles a column within its 2 + 1 sweeps and it starts to jitter (measured:
a 20-cube stack at 120 Hz with 4 substeps of 1/60 s gained 0.7 J).  What does keep it still is a
shorter substep: f follows the substep rate (f = 1 / (4 h) unless ``contact_hertz`` caps it), so
the sag falls as h^2, and a column that would sag by s at n substeps sags s (n / n')^2 at n'.

``plan_substeps`` estimates the sag of the columns a scene starts with and picks the fewest
substeps, at least the configured ones, that keep it under ``column_sag``; the estimate bins the
dynamic bodies into vertical columns one body wide (two grids offset by half a column, so no column
is split by a grid line) and sums the series above from the bottom of each.  Piles that form later
(a rain) are not foreseen: the estimate sees the layers the scene starts with.

Landing on a pile.  A column that starts with gaps between its bodies (layers of a rain) lands on
itself: the k-th body meets the bodies stopped below it at v_k = sqrt(2 g (gap_1 + ... + gap_k)),
the top one fastest.  The impact stage (solvers/impact.py) stops such a blow only as far as its
Gauss-Seidel sweeps carry it down the pile; the soft solve takes the rest and lets the contacts
give by about that residual speed times the substep, so the deepest transient of a landing pile
grows as v h.  Calibrated on the layered rains of plates (0.6 x 0.2 x 0.6 m, 360 bodies) and of
mixed boxes and balls (mixed_rain.toml, 1,000 bodies), 10 layers each (bench/audit_stacks.
thin_box_rains, the audit's item 11), layouts of seeds 1 to 15, 5 s, the deepest body-body pair
found after every step, against v the plan's landing speed (9.24 and 10.1 m/s):

    substeps   plates: worst (seeds)                 mixed: worst (seeds)
       7       13.8 mm = 0.63 v h (1-10; 7 over 1 cm)  21.9 mm = 0.91 v h (1-10; 2 over)
       8       12.8 mm = 0.67 v h (1-5; 4 over)        11.9 mm = 0.56 v h (1-5; 1 over)
       9       10.9 mm = 0.64 v h (1-15; 1 over)        7.9 mm = 0.42 v h (1-10; none over)
      10            -                                   8.1 mm = 0.48 v h (1-10; none over)
      11        9.5 mm = 0.68 v h (1-15; none over)      -
      12            -                                   9.5 mm = 0.68 v h (1-10; none over)

The deepest pair of a seed is one rare blow (a plate's corner onto a tilted plate, a spinning
box's edge), so it scatters from seed to seed and is not monotonic in the substeps, but the
plates' worst stays at 0.63 to 0.68 v h from 7 to 11 substeps, and the mixed rain's reaches 0.68
at 12: the soft contact gives by a fixed share of what the impact sweeps leave of the blow,
times h.  LANDING_RESIDUAL is that envelope rounded up, 0.69 (the mixed rain's 0.91, one spinning
box at 7 substeps, is far below it at the substeps this plans: 11 for the plates, 12 for the
mixed rain).  An earlier 0.40, the worst of 6 seeds of rains a third the size, planned 7
substeps for both rains, where 9 of the 20 full-size runs of seeds 1-10 went deeper than 1 cm.
So the plan also keeps

    LANDING_RESIDUAL v h  <=  landing_depth      (columns of 3 bodies or more)

(a body landing on one other is a two-body impact, which the sweeps resolve exactly).

The table was measured before box-box manifolds kept the point that closes first
(collide/box_box.py), which removed the plates' rarest blows: at the 11 substeps planned, layouts
1-20 went from 9.5 to 6.2 mm worst (probed every 0.1 s), and at 8 substeps layouts 1-5, probed
after every step, from 12.8 mm (4 over 1 cm) to 9.3 mm (none over), 0.48 v h.  The constant is
kept until it is measured again on 15 layouts a setting.

A gap is the centre distance less the two bodies' volume-equivalent radii (the sphere's radius,
the box's cube-root mean half extent).  A stack that starts touching has no gaps and no landing.

Budgets scale with the bodies.  The sag of a column is a length fixed by g / omega^2, whatever the
size of its bodies, so budgets in metres alone let small bodies sink by a large share of
themselves: ten 1 cm cubes were planned at 4 substeps for a 6.9 mm sag, under the 7.5 mm
``column_sag``, and the column fell over (5 cm cubes sank 13 % of a cube).  The settings are
therefore budgets for bodies CALIBRATION_THICKNESS (0.2 m, the plates they were calibrated on,
the table above) thick or thicker, and the plan scales them down in proportion for a scene whose
median body is thinner (its thinnest dimension: a sphere's diameter, a box's smallest side): at
the defaults 3.75 % and 5 % of that thickness.  A raised setting is kept in the same proportion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .column_lean import LEAN_SAFETY, lean_terms
from .types import SHAPE_SPHERE

MAX_AUTO_SUBSTEPS = 64
LANDING_RESIDUAL = 0.69  # deepest transient / (v h) of a pile landed on, worst measured (module docstring)
LANDING_PILE = 3  # bodies in a column from which a landing counts
# the body thickness the budgets column_sag and landing_depth hold for (module docstring: the
# plates' 0.2 m, on which their defaults were calibrated); thinner bodies get them scaled down
CALIBRATION_THICKNESS = 0.2


def contact_hertz(h: float, setting: float | None) -> float:
    """The soft contact's frequency at substep h: a quarter of the substep rate, capped by the
    ``contact_hertz`` setting when one is given (solvers/soft_step.soft_coefficients)."""
    quarter = 0.25 / h
    return quarter if setting is None else min(float(setting), quarter)


def contact_omega(h: float, setting: float | None) -> float:
    return 2.0 * math.pi * contact_hertz(h, setting)


@dataclass
class SubstepPlan:
    requested: int  # SimConfig.substeps: the fewest
    substeps: int  # what the simulator runs
    column_bodies: int  # bodies in the column of the largest sag
    sag_requested: float  # that column's estimated sag at the requested substeps [m]
    sag: float  # ... at the substeps run [m]
    budget: float  # SimConfig.column_sag, or less for small bodies (plan_budgets) [m]
    auto: bool
    landing_speed: float = 0.0  # [m/s] the fastest landing on a pile the scene starts with
    landing_depth: float = 0.01  # SimConfig.landing_depth, or less for small bodies (plan_budgets) [m]
    landing_dt: float = 0.0  # the step dt the landing was planned for [s]
    raised_by: str = ""  # "sag", "landing" or "lean": the budget the last substep added was for
    lean_margin: float = 0.0  # [m] the checked leaning column's margin that asks the most substeps (0: none)
    lean_need_requested: float = 0.0  # [m] the margin it needs to stand at the requested substeps
    lean_need: float = 0.0  # [m] ... at the substeps run (column_lean.py)

    def landing_transient(self, substeps: int | None = None) -> float:
        """The deepest transient of the fastest landing at ``substeps`` (default: the ones run) [m]."""
        return landing_transient(self.landing_speed, self.landing_dt, self.substeps if substeps is None else substeps)

    def reason(self) -> str:
        """Why auto_substeps runs more than requested, in a few words ("" when it does not)."""
        if self.substeps == self.requested:
            return ""
        if self.raised_by == "sag":
            return f"a column would sag {self.sag_requested * 1000:.0f} mm"
        if self.raised_by == "lean":
            return (f"a column leaning {self.lean_margin * 1000:.0f} mm inside its support's edge needs "
                    f"{self.lean_need_requested * 1000:.0f} mm to stand")
        return f"a landing on a pile would sink {self.landing_transient(self.requested) * 1000:.0f} mm"

    def describe(self) -> str:
        head = f"{self.substeps} substeps"
        if self.lean_margin > 0.0:
            head += (f" (leaning column: {self.lean_margin * 1000:.1f} mm inside its support's edge, "
                     f"{self.lean_need * 1000:.1f} mm needed)")
        if self.column_bodies < 2:
            return head
        text = (f"{head}: tallest column {self.column_bodies} bodies, soft-contact sag "
                f"{self.sag * 1000:.1f} mm")
        if self.landing_speed > 0.0:
            text += (f", landing on a pile at {self.landing_speed:.1f} m/s (transient "
                     f"{self.landing_transient() * 1000:.1f} mm, budget {self.landing_depth * 1000:g} mm)")
        if self.substeps != self.requested and self.sag_requested > self.budget:
            text += (f" (at the {self.requested} requested: {self.sag_requested * 1000:.1f} mm, over the "
                     f"sag budget of {self.budget * 1000:g} mm)")
        landing_requested = self.landing_transient(self.requested)
        if self.substeps != self.requested and landing_requested > self.landing_depth:
            text += (f" (at the {self.requested} requested the landing transient is "
                     f"{landing_requested * 1000:.1f} mm, over the landing_depth budget)")
        if self.sag > self.budget or self.landing_transient() > self.landing_depth or self.lean_need > self.lean_margin:
            reason = "auto_substeps is off" if not self.auto else f"auto_substeps stops at {MAX_AUTO_SUBSTEPS}"
            text += f"; still over the budget: {reason}"
        return text


def resting_faces(shape: np.ndarray, size: np.ndarray, rot: np.ndarray, inv_inertia: np.ndarray,
                  inv_mass: np.ndarray, up: np.ndarray):
    """What ``contact_masses`` needs of each body's face that looks most nearly down: (c1, c2,
    inv_inertia_world, area, ground), where the face's corners are the arms r = +-d1 +- d2 (d1, d2
    its half-extent vectors) and c_i = d_i x n, n = up, so r x n = +-c1 +- c2; the world inverse
    inertia R diag(I^-1) R^T; the face's area; M_contact on the ground.  A sphere's single point
    lies under its centre: c1 = c2 = 0, area 0, M_contact its mass."""
    n = len(shape)
    alignment = np.abs(np.einsum("nij,i->nj", rot, up))  # |body axis . up|
    normal_axis = np.argmax(alignment, axis=1)
    first = (normal_axis + 1) % 3
    second = (normal_axis + 2) % 3
    rows = np.arange(n)
    sphere = (shape == SHAPE_SPHERE)[:, None]
    c1 = np.where(sphere, 0.0, np.cross(rot[rows, :, first] * size[rows, first][:, None], up))
    c2 = np.where(sphere, 0.0, np.cross(rot[rows, :, second] * size[rows, second][:, None], up))
    inv_inertia_world = (rot * inv_inertia[:, None, :]) @ np.transpose(rot, (0, 2, 1))
    area = np.where(sphere[:, 0], 0.0, 4.0 * size[rows, first] * size[rows, second])
    diagonal = quadratic(inv_inertia_world, c1, c1) + quadratic(inv_inertia_world, c2, c2)
    ground = np.where(area == 0.0, 1.0 / inv_mass,
                      corner_masses(inv_mass, diagonal, quadratic(inv_inertia_world, c1, c2)))
    return c1, c2, inv_inertia_world, area, ground


def quadratic(matrix: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x . M y for stacks of 3-vectors and 3 x 3 matrices."""
    return np.einsum("ni,nij,nj->n", x, matrix, y)


def corner_masses(k0: np.ndarray, diagonal: np.ndarray, cross_term: np.ndarray) -> np.ndarray:
    """Sum of 1 / k_n over a face's four corners r x n = +-c1 +- c2, where k_n = k0 + diagonal
    +- 2 cross_term (diagonal the c1 and c2 terms of (r x n) . I^-1 (r x n), cross_term c1 . I^-1 c2)."""
    return 2.0 / (k0 + diagonal + 2.0 * cross_term) + 2.0 / (k0 + diagonal - 2.0 * cross_term)


def contact_masses(faces, inv_mass: np.ndarray, below: np.ndarray, on_ground: np.ndarray) -> np.ndarray:
    """M_contact (module docstring) of each body's lower contact: on the ground (``on_ground``),
    or on the body ``below`` it in its column.  Two boxes touch over the smaller of their faces,
    taken as centred on both (a column is one body wide); a sphere on either side makes it one
    point under the centres.  Two unit cubes: 4 corners of k_n = 8 / m, the reduced mass m / 2."""
    c1, c2, inertia, area, ground = faces
    single = area == 0.0
    # a pair: the smaller face's corners, as arms of both bodies
    own = (area <= area[below])[:, None]
    s1 = np.where(own, c1, c1[below])
    s2 = np.where(own, c2, c2[below])
    k0 = inv_mass + inv_mass[below]
    lower = inertia[below]
    # (I_a^-1 + I_b^-1) applied to the shared face's c1 and c2: both bodies turn about the same arms
    m1 = np.einsum("nij,nj->ni", inertia, s1) + np.einsum("nij,nj->ni", lower, s1)
    m2 = np.einsum("nij,nj->ni", inertia, s2) + np.einsum("nij,nj->ni", lower, s2)
    diagonal = np.sum(s1 * m1, axis=1) + np.sum(s2 * m2, axis=1)
    cross_term = np.sum(s1 * m2, axis=1)
    pair = np.where(single | single[below], 1.0 / k0, corner_masses(k0, diagonal, cross_term))
    return np.where(on_ground, ground, pair)


def column_weights(pos: np.ndarray, mass: np.ndarray, width: float, up: np.ndarray, radius: np.ndarray, faces):
    """The column of the largest sag: (sum of its g-free sag terms W_above / M_contact, its
    bodies), and the longest fall onto a pile (the gaps summed up a column of LANDING_PILE bodies
    or more, ``radius`` the volume-equivalent radii).  Only the series is computed here; multiply
    by g / omega^2 for metres.  ``faces``: ``resting_faces`` of the bodies."""
    a = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    e1 = np.cross(up, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    across = np.stack([pos @ e1, pos @ e2], 1) / width  # horizontal coordinates, in columns
    height = pos @ up
    best_terms, best_count = 0.0, 0
    columns = []
    for offset in (0.0, 0.5):
        cells = np.floor(across + offset).astype(np.int64)
        order = np.lexsort((height, cells[:, 1], cells[:, 0]))
        keys = cells[order]
        m = mass[order]
        r = radius[order]
        y = height[order]
        starts = np.flatnonzero(np.r_[True, np.any(keys[1:] != keys[:-1], axis=1)])
        counts = np.diff(np.r_[starts, len(order)])
        first = np.repeat(starts, counts)  # each body's column start
        total = np.add.reduceat(m, starts)
        prefix = np.cumsum(m)
        prefix_before = np.where(first > 0, prefix[np.maximum(first - 1, 0)], 0.0)
        above = np.repeat(total, counts) - (prefix - prefix_before) + m  # weight on the body's lower contact
        on_ground = np.arange(len(m)) == first  # a column's bottom body rests on the ground
        below = np.maximum(np.arange(len(m)) - 1, 0)  # the body under each, in column order
        pair = contact_masses(tuple(f[order] for f in faces), 1.0 / m, below, on_ground)
        terms = np.add.reduceat(above / pair, starts)
        terms = np.where(counts >= 2, terms, 0.0)
        k = int(np.argmax(terms))
        if terms[k] > best_terms:
            best_terms, best_count = float(terms[k]), int(counts[k])
        # the gap under each body but a column's bottom one
        gap = np.r_[0.0, np.maximum(y[1:] - y[:-1] - r[1:] - r[:-1], 0.0)]
        gap[starts] = 0.0
        columns.append((gap, starts, counts))
    # A column one body wide misses the bodies of a jittered layer that fell just outside it, and
    # its gap then spans several layers (a rain of 10 jittered layers 0.9 m apart: a column of
    # layers 0, 6 and 9 "fell" 7.4 m).  A gap longer than twice the scene's median gap is taken
    # as such a miss and counted as two median gaps; a lone body high above a stack keeps its
    # whole gap (it is the only one, so it is the median).
    positive = np.concatenate([gap[gap > 0.0] for gap, _, _ in columns])
    cap = 2.0 * float(np.median(positive)) if positive.size else 0.0
    best_fall = 0.0
    for gap, starts, counts in columns:
        fall = np.add.reduceat(np.minimum(gap, cap), starts)
        fall = np.where(counts >= LANDING_PILE, fall, 0.0)
        best_fall = max(best_fall, float(fall.max()))
    return best_terms, best_count, best_fall


def landing_transient(speed: float, dt: float, substeps: int) -> float:
    """LANDING_RESIDUAL v h: the deepest transient of a landing at ``speed`` (module docstring)."""
    return LANDING_RESIDUAL * speed * dt / substeps


def volume_radius(shape: np.ndarray, size: np.ndarray) -> np.ndarray:
    """The radius of the sphere, or the half side of the cube, of a body's volume (a box's
    cube-root mean half extent)."""
    box = np.cbrt(np.prod(np.abs(size), axis=1))
    return np.where(shape == SHAPE_SPHERE, size[:, 0], box)


def body_thickness(shape: np.ndarray, size: np.ndarray) -> np.ndarray:
    """A body's thinnest dimension: a sphere's diameter, a box's smallest side."""
    return 2.0 * np.where(shape == SHAPE_SPHERE, size[:, 0], np.min(np.abs(size), axis=1))


def budget_scale(model) -> float:
    """The share of column_sag and landing_depth the plan keeps: the median dynamic body's
    thickness over CALIBRATION_THICKNESS, at most 1 (module docstring)."""
    host = model.host
    dynamic = host["body_inv_mass"] > 0
    if not np.any(dynamic):
        return 1.0
    thickness = float(np.median(body_thickness(host["body_shape"][dynamic],
                                               np.asarray(host["body_size"], dtype=np.float64)[dynamic])))
    return min(1.0, thickness / CALIBRATION_THICKNESS)


def plan_budgets(model, config) -> tuple[float, float]:
    """The column sag and landing depth the plan keeps [m]: the settings, scaled down for thin
    bodies (budget_scale)."""
    scale = budget_scale(model)
    return scale * float(config.column_sag), scale * float(config.landing_depth)


def standing_poses(model, state=None) -> tuple:
    """Body positions and rotation matrices as the model places them, or as ``state`` holds them: read
    back at build and between steps (Simulator.update_settings), never inside a step."""
    host = model.host
    if state is None:
        return host["body_pos"], host["body_rot"]
    return state.body_pos.numpy(), state.body_rot.numpy()


def scene_lean(model, config, state=None) -> list:
    """column_lean.lean_terms of the columns ``model`` starts with (or stands in ``state``): what
    plan_substeps checks leaning columns against."""
    g = float(np.linalg.norm(config.gravity))
    host = model.host
    if g == 0.0 or not config.body_contact or np.count_nonzero(host["body_inv_mass"] > 0) < 2:
        return []
    up = -np.asarray(config.gravity, dtype=np.float64) / g
    pos, rot = standing_poses(model, state)
    terrain = getattr(model, "terrain", None)
    height = getattr(terrain, "height", None) if up[1] > 1.0 - 1e-9 else None  # the ground is a height in y
    return lean_terms(host, pos, rot, up, height)


def lean_need(lean: list, g: float, omega: float) -> tuple[float, float]:
    """The checked interface that asks the most of its margin at contact frequency ``omega``:
    (its margin, the margin it needs) [m], or (0, 0) when there is none (column_lean.py)."""
    best, margin, need = 0.0, 0.0, 0.0
    for coefficient, offset, edge in lean:
        needed = LEAN_SAFETY * math.sqrt(offset * coefficient * g) / omega
        if needed / edge > best:  # a load over its support's centre (e = 0) needs nothing
            best, margin, need = needed / edge, edge, needed
    return margin, need


def plan_substeps(model, config, state=None, lean=None) -> SubstepPlan:
    """The substeps to run for ``config`` on ``model``, its bodies posed as in ``state`` (default:
    as the model places them).  ``lean``: the scene's leaning columns (scene_lean) when already
    known; the Simulator keeps those it was built with, so a setting changed later plans for them
    too."""
    requested = int(config.substeps)
    g = float(np.linalg.norm(config.gravity))
    host = model.host
    dynamic = host["body_inv_mass"] > 0
    sag_budget, landing_budget = plan_budgets(model, config)
    terms, count, fall = 0.0, 0, 0.0
    if g > 0.0 and config.body_contact and np.count_nonzero(dynamic) >= 2:
        up = -np.asarray(config.gravity, dtype=np.float64) / g
        pos, rot = standing_poses(model, state)
        p = np.asarray(pos, dtype=np.float64)[dynamic]
        mass = 1.0 / host["body_inv_mass"][dynamic].astype(np.float64)
        # a column one body wide: the median body's volume-equivalent diameter
        width = 2.0 * float(np.median(host["body_bound_radius"][dynamic])) / math.sqrt(3.0)
        radius = volume_radius(host["body_shape"][dynamic], np.asarray(host["body_size"], dtype=np.float64)[dynamic])
        size = np.asarray(host["body_size"], dtype=np.float64)[dynamic]
        rotation = np.asarray(rot, dtype=np.float64)[dynamic]
        inv_inertia = np.asarray(host["body_inv_inertia"], dtype=np.float64)[dynamic]
        faces = resting_faces(host["body_shape"][dynamic], size, rotation, inv_inertia, 1.0 / mass, up)
        terms, count, fall = column_weights(p, mass, max(width, 1e-6), up, radius, faces)

    def sag(n: int) -> float:
        return g * terms / contact_omega(config.dt / n, config.contact_hertz) ** 2

    if lean is None:
        lean = scene_lean(model, config, state)

    def leaning(n: int) -> tuple[float, float]:
        return lean_need(lean, g, contact_omega(config.dt / n, config.contact_hertz))

    speed = math.sqrt(2.0 * g * fall)
    chosen, raised_by = requested, ""
    if config.auto_substeps:
        while chosen < MAX_AUTO_SUBSTEPS:
            if landing_transient(speed, config.dt, chosen) > landing_budget:
                raised_by = "landing"
            elif sag(chosen) > sag_budget:
                raised_by = "sag"
            elif leaning(chosen)[1] > leaning(chosen)[0]:
                raised_by = "lean"
            else:
                break
            chosen += 1
    margin, need_requested = leaning(requested)
    return SubstepPlan(requested, chosen, count, sag(requested), sag(chosen), sag_budget,
                       bool(config.auto_substeps), speed, landing_budget, float(config.dt), raised_by,
                       margin, need_requested, leaning(chosen)[1])
