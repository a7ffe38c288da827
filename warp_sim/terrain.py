"""Procedural terrain: one Python source of coefficients, mirrored in Warp, NumPy and GLSL.

The Fourier terrain is the thesis's height formula (SEED.md 5), in *terrain space* (u, w):

    T(u, w) = sum_{m,n < k, (m,n) != (0,0)} A(m,n) cos(f (m u + n w) + P(m,n) + phase)
    A(m,n)  = amplitude * A0(m,n) / sqrt(m^2 + n^2)

A0 in [0, 1) and P in [0, 2 pi) are drawn from ``seed`` unless explicit k x k tables are given
(the tables replace the draw; the amplitude factor and the 1/sqrt law still apply, and the
(0, 0) entry is ignored because its 1/sqrt(0) is undefined).

The model transform is a per-axis scale and a translation (SEED.md 4.3): a world point p maps
to terrain space by the inverse transform u = (p.x - o.x) / s.x, w = (p.z - o.z) / s.z, and the
world height is H(x, z) = o.y + s.y T(u, w).  Everything below works on H directly.

Evaluation trick (why the Warp function is not a double loop of cos calls): each term is the
real part of C(m,n) e^{i f m u} e^{i f n w} with C = A e^{i(P + phase)}.  Two sincos calls give
e^{i f u} and e^{i f w}; powers follow by complex multiplication.  Height, gradient and Hessian
then cost a few multiply-adds per term instead of a transcendental each.  The NumPy twin below
uses the plain cos/sin formula in float64 so it is an independent oracle for the tests.

The plane terrain is the half-space n . p <= d (``normal`` need not be vertical); it exists
for analytic tests (slopes, bounces).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

TERRAIN_NONE = 0
TERRAIN_PLANE = 1
TERRAIN_FOURIER = 2

TERRAIN_KINDS = {"none": TERRAIN_NONE, "plane": TERRAIN_PLANE, "fourier": TERRAIN_FOURIER}


@dataclass
class FourierTerrain:
    """Fourier-series heightfield. Lengths in [m], frequency in [rad/m] of terrain space."""

    terms: int = 5
    frequency: float = 0.35
    amplitude: float = 0.5
    phase: float = 0.0
    seed: int = 1
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    amplitudes: np.ndarray | None = None
    phases: np.ndarray | None = None
    kind: str = field(default="fourier", init=False)

    def __post_init__(self):
        from .validation import FOURIER_SCHEMA, check_fields, check_terrain_tables

        check_fields(self, FOURIER_SCHEMA, "FourierTerrain")
        check_terrain_tables(self, "FourierTerrain")

    def base_tables(self) -> tuple[np.ndarray, np.ndarray]:
        """A0 and P tables (k x k), drawn from the seed unless given explicitly."""
        k = self.terms
        rng = np.random.default_rng(self.seed)
        a0 = rng.uniform(0.0, 1.0, size=(k, k))
        p = rng.uniform(0.0, 2.0 * math.pi, size=(k, k))
        if self.amplitudes is not None:
            a0 = np.asarray(self.amplitudes, dtype=np.float64).reshape(k, k)
        if self.phases is not None:
            p = np.asarray(self.phases, dtype=np.float64).reshape(k, k)
        return a0, p

    def amplitude_table(self) -> np.ndarray:
        """A(m, n) including the 1/sqrt(m^2+n^2) law; A(0, 0) = 0."""
        k = self.terms
        a0, _ = self.base_tables()
        m, n = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
        radius = np.sqrt(m * m + n * n)
        radius[0, 0] = 1.0
        table = self.amplitude * a0 / radius
        table[0, 0] = 0.0
        return table

    def phase_table(self) -> np.ndarray:
        """P(m, n) plus the global phase offset."""
        _, p = self.base_tables()
        return p + self.phase

    def complex_coefficients(self) -> np.ndarray:
        """C(m, n) = A e^{i(P + phase)} as (k*k, 2) float32, row-major in m: what Warp and GLSL read."""
        c = self.amplitude_table() * np.exp(1j * self.phase_table())
        return np.stack([c.real.ravel(), c.imag.ravel()], axis=1).astype(np.float32)

    def slope_bound(self) -> float:
        """An upper bound of |grad H| over the whole plane (Lipschitz constant).

        |dT/du| <= sum |A| f m, |dT/dw| <= sum |A| f n; the world slopes scale by s.y/s.x and
        s.y/s.z.  Used to skip the closest-point search for bodies that cannot reach the surface.
        """
        k = self.terms
        a = np.abs(self.amplitude_table())
        m, n = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
        gu = float(np.sum(a * self.frequency * m)) * self.scale[1] / self.scale[0]
        gw = float(np.sum(a * self.frequency * n)) * self.scale[1] / self.scale[2]
        return math.hypot(gu, gw)

    def directional_bound(self, order: int) -> float:
        """An upper bound of every ``order``-th directional derivative of H (unit horizontal
        direction e).

        d^p/ds^p of A cos(f k . (e_x / s.x, e_z / s.z) s + ...) is at most |A| (f |k . e'|)^p, and
        |k . e'| <= sqrt(m^2 / s.x^2 + n^2 / s.z^2) (Cauchy-Schwarz); times s.y for world heights.
        """
        k = self.terms
        a = np.abs(self.amplitude_table())
        m, n = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
        reach = np.sqrt((m / self.scale[0]) ** 2 + (n / self.scale[2]) ** 2)
        return float(np.sum(a * (self.frequency * reach) ** order)) * abs(self.scale[1])

    def curvature_bound(self) -> float:
        """Bounds the surface's curvature too: |H''| / (1 + H'^2)^(3/2) <= |H''|."""
        return self.directional_bound(2)

    def cubic_bound(self) -> float:
        return self.directional_bound(3)

    def max_height_deviation(self) -> float:
        """sum |A| * s.y: no point of the surface lies further than this from o.y."""
        return float(np.sum(np.abs(self.amplitude_table()))) * self.scale[1]

    # NumPy twin: float64 cos/sin, the test oracle.
    def height(self, x, z):
        x = np.asarray(x, dtype=np.float64)
        z = np.asarray(z, dtype=np.float64)
        sx, sy, sz = self.scale
        ox, oy, oz = self.offset
        u = (x - ox) / sx
        w = (z - oz) / sz
        a = self.amplitude_table()
        p = self.phase_table()
        total = np.zeros(np.broadcast(u, w).shape)
        for m in range(self.terms):
            for n in range(self.terms):
                if a[m, n] != 0.0:
                    total = total + a[m, n] * np.cos(self.frequency * (m * u + n * w) + p[m, n])
        return oy + sy * total

    def gradient(self, x, z):
        """(dH/dx, dH/dz) in world units."""
        x = np.asarray(x, dtype=np.float64)
        z = np.asarray(z, dtype=np.float64)
        sx, sy, sz = self.scale
        ox, _, oz = self.offset
        u = (x - ox) / sx
        w = (z - oz) / sz
        a = self.amplitude_table()
        p = self.phase_table()
        f = self.frequency
        gu = np.zeros(np.broadcast(u, w).shape)
        gw = np.zeros_like(gu)
        for m in range(self.terms):
            for n in range(self.terms):
                if a[m, n] != 0.0:
                    s = np.sin(f * (m * u + n * w) + p[m, n])
                    gu = gu - a[m, n] * f * m * s
                    gw = gw - a[m, n] * f * n * s
        return gu * sy / sx, gw * sy / sz

    def glsl_uniforms(self) -> dict:
        """What the tessellation evaluation shader needs (shaders/terrain_common.glsl)."""
        return {
            "terrain_terms": int(self.terms),
            "terrain_frequency": float(self.frequency),
            "terrain_scale": tuple(float(v) for v in self.scale),
            "terrain_offset": tuple(float(v) for v in self.offset),
            "terrain_coef": self.complex_coefficients(),
        }


@dataclass
class PlaneTerrain:
    """Half-space n . p <= offset, n normalised on construction."""

    normal: tuple[float, float, float] = (0.0, 1.0, 0.0)
    offset: float = 0.0
    kind: str = field(default="plane", init=False)

    def __post_init__(self):
        from .validation import PLANE_SCHEMA, check_fields, unit_rows

        check_fields(self, PLANE_SCHEMA, "PlaneTerrain")
        n = np.asarray(self.normal, dtype=np.float64)
        self.normal = tuple(float(v) for v in unit_rows(n))

    def height(self, x, z):
        """Height of the plane above (x, z); only defined for non-vertical planes."""
        nx, ny, nz = self.normal
        return (self.offset - nx * np.asarray(x) - nz * np.asarray(z)) / ny

    def signed_distance(self, p):
        return np.asarray(p) @ np.asarray(self.normal) - self.offset

    @staticmethod
    def from_slope(angle_deg: float, offset: float = 0.0) -> "PlaneTerrain":
        """A plane rising along +x by ``angle_deg``: down-slope is -x."""
        from .validation import Number, check

        a = math.radians(check(Number(), angle_deg, "angle_deg"))
        return PlaneTerrain(normal=(-math.sin(a), math.cos(a), 0.0), offset=offset)


@dataclass
class NoTerrain:
    kind: str = field(default="none", init=False)


Terrain = FourierTerrain | PlaneTerrain | NoTerrain


# ----------------------------------------------------------------------------------------------
# Warp mirror.  Arguments are the flat model fields: terrain_coef (k*k complex as vec2),
# terrain_terms, terrain_frequency, terrain_scale, terrain_offset, terrain_plane (n, d).


@wp.struct
class HeightSample:
    """World height H, gradient (dH/dx, dH/dz), Hessian (Hxx, Hxz, Hzz) and third derivatives
    (Hxxx, Hxxz, Hxzz, Hzzz) at one (x, z); each only where the evaluation's order asks for it,
    else 0."""

    height: float
    grad: wp.vec2
    hess: wp.vec3
    third: wp.vec4


@wp.func
def fourier_evaluate(
    terrain_coef: wp.array(dtype=wp.vec2),
    terrain_terms: int,
    terrain_frequency: float,
    terrain_scale: wp.vec3,
    terrain_offset: wp.vec3,
    x: float,
    z: float,
    order: int,
) -> HeightSample:
    """The series and its derivatives at (x, z) up to ``order`` (1: height and slope, 2: and the
    Hessian, 3: and the third derivatives; the rest are 0): a sample that needs only height and
    slope skips a third of the work per term."""
    f = terrain_frequency
    u = (x - terrain_offset[0]) / terrain_scale[0]
    w = (z - terrain_offset[2]) / terrain_scale[2]
    ex = wp.vec2(wp.cos(f * u), wp.sin(f * u))
    ez = wp.vec2(wp.cos(f * w), wp.sin(f * w))
    h = float(0.0)
    hu = float(0.0)
    hw = float(0.0)
    huu = float(0.0)
    huw = float(0.0)
    hww = float(0.0)
    huuu = float(0.0)
    huuw = float(0.0)
    huww = float(0.0)
    hwww = float(0.0)
    pm = wp.vec2(1.0, 0.0)
    for m in range(terrain_terms):
        pn = pm
        fm = f * float(m)
        for n in range(terrain_terms):
            c = terrain_coef[m * terrain_terms + n]
            re = c[0] * pn[0] - c[1] * pn[1]
            im = c[0] * pn[1] + c[1] * pn[0]
            fn = f * float(n)
            h += re
            hu -= fm * im
            hw -= fn * im
            if order >= 2:
                huu -= fm * fm * re
                huw -= fm * fn * re
                hww -= fn * fn * re
            if order >= 3:
                # d/du multiplies a term by i f m: three times, -i (f m)^3, whose real part is + im
                huuu += fm * fm * fm * im
                huuw += fm * fm * fn * im
                huww += fm * fn * fn * im
                hwww += fn * fn * fn * im
            pn = wp.vec2(pn[0] * ez[0] - pn[1] * ez[1], pn[0] * ez[1] + pn[1] * ez[0])
        pm = wp.vec2(pm[0] * ex[0] - pm[1] * ex[1], pm[0] * ex[1] + pm[1] * ex[0])
    sx = terrain_scale[0]
    sy = terrain_scale[1]
    sz = terrain_scale[2]
    s = HeightSample()
    s.height = terrain_offset[1] + sy * h
    s.grad = wp.vec2(hu * sy / sx, hw * sy / sz)
    s.hess = wp.vec3(huu * sy / (sx * sx), huw * sy / (sx * sz), hww * sy / (sz * sz))
    s.third = wp.vec4(huuu * sy / (sx * sx * sx), huuw * sy / (sx * sx * sz), huww * sy / (sx * sz * sz),
                      hwww * sy / (sz * sz * sz))
    return s


@wp.func
def fourier_sample(
    terrain_coef: wp.array(dtype=wp.vec2),
    terrain_terms: int,
    terrain_frequency: float,
    terrain_scale: wp.vec3,
    terrain_offset: wp.vec3,
    x: float,
    z: float,
) -> HeightSample:
    return fourier_evaluate(terrain_coef, terrain_terms, terrain_frequency, terrain_scale, terrain_offset, x, z, 2)


@wp.func
def fourier_height_slope(
    terrain_coef: wp.array(dtype=wp.vec2),
    terrain_terms: int,
    terrain_frequency: float,
    terrain_scale: wp.vec3,
    terrain_offset: wp.vec3,
    x: float,
    z: float,
) -> HeightSample:
    """Height and gradient only (hess is 0)."""
    return fourier_evaluate(terrain_coef, terrain_terms, terrain_frequency, terrain_scale, terrain_offset, x, z, 1)


@wp.func
def fourier_normal(grad: wp.vec2) -> wp.vec3:
    """Upward unit normal of y = H(x, z): (-Hx, 1, -Hz) normalised."""
    return wp.normalize(wp.vec3(-grad[0], 1.0, -grad[1]))


def terrain_model_fields(terrain: Terrain) -> dict:
    """Host values of the flat terrain_* model fields for a terrain description."""
    out = {
        "terrain_kind": TERRAIN_KINDS[terrain.kind],
        "terrain_coef": np.zeros((1, 2), dtype=np.float32),
        "terrain_terms": 0,
        "terrain_frequency": 0.0,
        "terrain_scale": (1.0, 1.0, 1.0),
        "terrain_offset": (0.0, 0.0, 0.0),
        "terrain_plane": (0.0, 1.0, 0.0, 0.0),
        "terrain_slope_bound": 0.0,
        "terrain_curvature_bound": 0.0,
        "terrain_cubic_bound": 0.0,
        "terrain_quartic_bound": 0.0,
    }
    if isinstance(terrain, FourierTerrain):
        out.update(
            terrain_coef=terrain.complex_coefficients(),
            terrain_terms=terrain.terms,
            terrain_frequency=terrain.frequency,
            terrain_scale=tuple(terrain.scale),
            terrain_offset=tuple(terrain.offset),
            terrain_slope_bound=terrain.slope_bound(),
            terrain_curvature_bound=terrain.curvature_bound(),
            terrain_cubic_bound=terrain.cubic_bound(),
            terrain_quartic_bound=terrain.directional_bound(4),
        )
    elif isinstance(terrain, PlaneTerrain):
        out["terrain_plane"] = (*terrain.normal, terrain.offset)
    return out
