"""A warm sphere's closest terrain point from the third-order jet of one sample (collide/closest_jet.py).

The oracle is float64 Newton on the NumPy twin of the terrain.  The search's own stopping
tolerance is tol = 1e-6 + 2e-7 (|x| + |z|) (a step under it ends the search): the jet's point is
accepted only where its bound says it lies as near the closest point as that, so every check
below holds it to tol plus what the float32 series itself moves the closest point by.
"""

import math

import numpy as np
import pytest
import warp as wp

from warp_sim import FourierTerrain, ModelBuilder, cases
from warp_sim.collide.terrain_contact import closest_from, jet_at, sample_at
from warp_sim.kernel_args import TerrainModel, bind
from warp_sim.terrain import fourier_evaluate, fourier_normal, fourier_sample, terrain_model_fields

TERRAINS = [
    FourierTerrain(),
    FourierTerrain(terms=3, frequency=0.8, amplitude=2.0, phase=1.1, seed=7),
    FourierTerrain(terms=8, frequency=0.2, amplitude=0.7, seed=3, scale=(2.0, 0.5, 3.0), offset=(1.0, -2.0, 4.0)),
    FourierTerrain(terms=2, frequency=1.0, amplitude=0.3, amplitudes=np.array([[0.0, 0.0], [1.0, 0.0]]),
                   phases=np.zeros((2, 2))),
]
SPAN = 5.0  # [m] |x|, |z| of the cases: the float32 series' phase error grows with the distance


def directional(terrain, order: int, u, w, angle):
    """d^order/ds^order of H(p + s e) (e at ``angle``), float64, from the series itself."""
    k = terrain.terms
    a = terrain.amplitude_table()
    p = terrain.phase_table()
    m, n = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    f = terrain.frequency
    eu = np.cos(angle) / terrain.scale[0]
    ew = np.sin(angle) / terrain.scale[2]
    uu = (u - terrain.offset[0]) / terrain.scale[0]
    ww = (w - terrain.offset[2]) / terrain.scale[2]
    rate = f * (m[None] * eu[:, None, None] + n[None] * ew[:, None, None])
    phase = f * (m[None] * uu[:, None, None] + n[None] * ww[:, None, None]) + p[None]
    # the order-th derivative of cos(phase) along e: rate^order cos(phase + order pi / 2)
    return terrain.scale[1] * np.sum(a[None] * rate**order * np.cos(phase[...] + order * math.pi / 2.0), axis=(1, 2))


@wp.kernel
def jet_kernel(terrain_coef: wp.array(dtype=wp.vec2), terrain_terms: int, terrain_frequency: float,
               terrain_scale: wp.vec3, terrain_offset: wp.vec3, points: wp.array(dtype=wp.vec2),
               out_third: wp.array(dtype=wp.vec4), out_mismatch: wp.array(dtype=int)):
    i = wp.tid()
    p = points[i]
    s = fourier_evaluate(terrain_coef, terrain_terms, terrain_frequency, terrain_scale, terrain_offset, p[0], p[1], 3)
    q = fourier_sample(terrain_coef, terrain_terms, terrain_frequency, terrain_scale, terrain_offset, p[0], p[1])
    out_third[i] = s.third
    # the orders below are the same numbers as the order-2 sample's, bit for bit
    same = s.height == q.height and s.grad[0] == q.grad[0] and s.grad[1] == q.grad[1]
    same = same and s.hess[0] == q.hess[0] and s.hess[1] == q.hess[1] and s.hess[2] == q.hess[2]
    out_mismatch[i] = int(not same)


@pytest.mark.parametrize("terrain", TERRAINS, ids=range(len(TERRAINS)))
def test_third_derivatives_match_the_series_and_the_quartic_bound_holds(terrain, device):
    """The order-3 sample's (Hxxx, Hxxz, Hxzz, Hzzz), contracted with a direction e, equal the third
    directional derivative of the float64 series, to its float32 error (1e-5 of the cubic bound,
    as the height's 1e-5 of sum|A| in test_terrain.py); and FourierTerrain.directional_bound(4),
    which the jet's acceptance rests on, bounds the fourth at every point and in every direction,
    without being vacuous."""
    rng = np.random.default_rng(11)
    n = 600
    xz = rng.uniform(-SPAN, SPAN, (n, 2))
    angle = rng.uniform(0.0, 2.0 * math.pi, n)
    f = terrain_model_fields(terrain)
    third = wp.zeros(n, dtype=wp.vec4, device=device)
    mismatch = wp.zeros(n, dtype=int, device=device)
    wp.launch(jet_kernel, dim=n, device=device, inputs=[
        wp.array(f["terrain_coef"], dtype=wp.vec2, device=device), f["terrain_terms"], f["terrain_frequency"],
        wp.vec3(*f["terrain_scale"]), wp.vec3(*f["terrain_offset"]),
        wp.array(xz.astype(np.float32), dtype=wp.vec2, device=device), third, mismatch])
    assert not mismatch.numpy().any(), "the order-3 sample's height, gradient or Hessian differ from fourier_sample"
    t = third.numpy().astype(float)
    ex, ez = np.cos(angle), np.sin(angle)
    along = t[:, 0] * ex**3 + 3.0 * t[:, 1] * ex**2 * ez + 3.0 * t[:, 2] * ex * ez**2 + t[:, 3] * ez**3
    expected = directional(terrain, 3, xz[:, 0], xz[:, 1], angle)
    np.testing.assert_allclose(along, expected, rtol=0, atol=1e-5 * terrain.cubic_bound())
    fourth = directional(terrain, 4, rng.uniform(-30, 30, 4000), rng.uniform(-30, 30, 4000),
                         rng.uniform(0.0, 2.0 * math.pi, 4000))
    assert np.abs(fourth).max() <= terrain.directional_bound(4)
    assert np.abs(fourth).max() > 0.2 * terrain.directional_bound(4)


@wp.kernel
def search_kernel(terrain: TerrainModel, centers: wp.array(dtype=wp.vec3), starts: wp.array(dtype=wp.vec2), jet: int,
                  out_point: wp.array(dtype=wp.vec2), out_normal: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    s0 = sample_at(terrain, starts[i])
    if jet != 0:
        s0 = jet_at(terrain, starts[i])
    xz, s = closest_from(terrain, centers[i], starts[i], s0, jet)
    out_point[i] = xz
    out_normal[i] = fourier_normal(s.grad)


def closest_point(terrain, c, p):
    """Float64 Newton for the surface point closest to c from p, stopped at convergence (the Hessian
    by central differences of the twin's gradient, error ~1e-10 at 1e-5)."""
    p = np.array(p, float)
    for _ in range(40):
        g = np.array(terrain.gradient(p[0], p[1]), float).ravel()
        u = float(terrain.height(p[0], p[1])) - c[1]
        e = 1.0e-5
        gx = np.array(terrain.gradient(p[0] + e, p[1])).ravel() - np.array(terrain.gradient(p[0] - e, p[1])).ravel()
        gz = np.array(terrain.gradient(p[0], p[1] + e)).ravel() - np.array(terrain.gradient(p[0], p[1] - e)).ravel()
        hess = np.array([[gx[0], gz[0]], [gx[1], gz[1]]]) / (2.0 * e)
        step = np.linalg.solve(np.eye(2) + np.outer(g, g) + u * 0.5 * (hess + hess.T),
                               np.array([p[0] - c[0] + u * g[0], p[1] - c[2] + u * g[1]]))
        p = p - step
        if np.linalg.norm(step) < 1.0e-13:
            break
    return p


def unit_normal(terrain, p) -> np.ndarray:
    g = np.array(terrain.gradient(p[0], p[1]), float).ravel()
    n = np.array([-g[0], 1.0, -g[1]])
    return n / np.linalg.norm(n)


def oracle(terrain, c, p):
    """The closest point to c (closest_point, from p) and the unit normal there."""
    point = closest_point(terrain, c, p)
    return point, unit_normal(terrain, point)


def moved_spheres(terrain, count: int, move: tuple[float, float], seed: int):
    """Spheres resting 0 to 5 mm deep at the closest points p0 of random places, their centres then
    moved by a random vector of length in ``move``: (centres, starts p0, oracle points, normals)."""
    rng = np.random.default_rng(seed)
    radius = min(0.25, 0.5 / terrain.curvature_bound())  # one slot: under the curvature radius
    centers, starts, points, normals = [], [], [], []
    for p in rng.uniform(-SPAN, SPAN, (count, 2)):
        g = np.array(terrain.gradient(p[0], p[1]), float).ravel()
        n = np.array([-g[0], 1.0, -g[1]]) / math.sqrt(1.0 + g @ g)
        old = np.array([p[0], terrain.height(p[0], p[1]), p[1]]) + (radius - rng.uniform(0.0, 0.005)) * n
        shift = rng.normal(size=3)
        c = (old + shift * rng.uniform(*move) / np.linalg.norm(shift)).astype(np.float32).astype(float)
        point, normal = oracle(terrain, c, p)
        centers.append(c)
        starts.append(p)
        points.append(point)
        normals.append(normal)
    return radius, np.array(centers), np.array(starts, dtype=np.float32), np.array(points), np.array(normals)


def search(terrain, centers, starts, jet: int, device):
    b = ModelBuilder()
    b.set_terrain(terrain)
    b.add_sphere(0.1, 1.0, position=(0.0, 10.0, 0.0))
    m = b.finalize(device)
    n = len(centers)
    point = wp.zeros(n, dtype=wp.vec2, device=device)
    normal = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(search_kernel, dim=n, device=device, inputs=[
        bind(TerrainModel, m, m), wp.array(centers.astype(np.float32), dtype=wp.vec3, device=device),
        wp.array(starts, dtype=wp.vec2, device=device), jet, point, normal])
    return point.numpy().astype(float), normal.numpy().astype(float)


@pytest.mark.parametrize("move", [(0.0, 0.001), (0.001, 0.004), (0.004, 0.012), (0.012, 0.06)],
                         ids=["under_1mm", "1_4mm", "4_12mm", "12_60mm"])
@pytest.mark.parametrize("terrain", TERRAINS, ids=range(len(TERRAINS)))
def test_a_moved_sphere_finds_its_closest_point_within_the_search_tolerance(terrain, move, device):
    """Resting spheres moved by up to 60 mm (a ball at 14 m/s over 1/240 s), searched from their
    last closest point with the jet: the point lies within the search's tolerance of the float64
    closest point, plus what the float32 series moves that point by (its slope is off by up to
    G k f |u| 2^-24 at |u| <= SPAN, test_terrain.py, which moves the point by r times that over
    lambda >= 1 - r K); the normal within K times that plus the slope error and the jet's own
    gradient bound (under tol by its acceptance).  The same holds for the search without the jet,
    the reference the jet stands in for.  And the jet takes over: where the move is under 4 mm,
    at least half the results differ from the full search's (the point or the normal).  Over the
    longest moves a jet taken regardless of its bound would miss by up to B4 |delta|^3 / 6
    (0.5 mm at 4 cm on the shipped terrain): those cases are there to catch an acceptance that
    is too loose."""
    radius, centers, starts, points, normals = moved_spheres(terrain, 150, move, seed=int(1000 * move[1]))
    tol = 1.0e-6 + 2.0e-7 * np.abs(points).sum(axis=1)
    g, k = terrain.slope_bound(), terrain.curvature_bound()
    span_u = SPAN / min(terrain.scale[0], terrain.scale[2]) + max(abs(terrain.offset[0]), abs(terrain.offset[2]))
    slope_error = g * terrain.terms * terrain.frequency * span_u * 2.0**-24
    shift = radius * slope_error / (1.0 - radius * k)
    results = {}
    for jet in (1, 0):
        point, normal = search(terrain, centers, starts, jet, device)
        results[jet] = point, normal
        point_error = np.linalg.norm(point - points, axis=1)
        normal_error = np.linalg.norm(normal - normals, axis=1)
        worst = int(np.argmax(point_error / (tol + shift)))
        assert np.all(point_error <= tol + shift), (jet, worst, point_error[worst], tol[worst] + shift)
        assert np.all(normal_error <= k * (tol + shift) + slope_error + tol), (jet, normal_error.max())
    if move[1] <= 0.004:
        differ = (results[0][0] != results[1][0]).any(axis=1) | (results[0][1] != results[1][1]).any(axis=1)
        assert differ.mean() >= 0.5, differ.mean()


def test_the_jet_changes_no_contact_beyond_the_search_tolerance():
    """One collision pass over 2,000 spheres rolling on the shipped terrain (a second after their
    drop), with and without the jet, from the same state and slots: each search ends within tol
    of the closest point, so their points differ by at most 2 tol; the normals by K times that
    plus the jet's gradient bound (tol); the depths, which a point's error changes only to second
    order, by at most 2 tol.  And the jet took over for most spheres."""
    sim = cases.terrain_drop(2000, "sphere", dt=1.0 / 240.0, substeps=1)
    sim.step(240, check=False)
    contacts = sim.contacts
    names = ("terrain_contact_active", "terrain_contact_surface", "terrain_contact_normal", "terrain_contact_depth",
             "terrain_contact_point")
    saved = {name: getattr(contacts, name).numpy().copy() for name in names}
    out = {}
    for jet in (True, False):
        for name, value in saved.items():
            getattr(contacts, name).assign(value)
        sim.closest_jet = jet
        # every sphere searched (a still one's slots would be carried from the first pass's)
        sim.collide(sim.states[0], contacts, sim.substep_dt, sim.config.speculative_margin, carry_still=False)
        out[jet] = {name: getattr(contacts, name).numpy().astype(float) for name in names}
    active = (out[True]["terrain_contact_active"] != 0) & (out[False]["terrain_contact_active"] != 0)
    assert active.mean() > 0.9
    surface = out[True]["terrain_contact_surface"][active]
    tol = 1.0e-6 + 2.0e-7 * np.abs(surface).sum(axis=1)
    k = cases.DEFAULT_TERRAIN.curvature_bound()
    apart = np.linalg.norm(surface - out[False]["terrain_contact_surface"][active], axis=1)
    assert np.all(apart <= 2.0 * tol), apart.max()
    turned = np.linalg.norm(out[True]["terrain_contact_normal"][active] - out[False]["terrain_contact_normal"][active],
                            axis=1)
    assert np.all(turned <= k * 2.0 * tol + tol), turned.max()
    deeper = np.abs(out[True]["terrain_contact_depth"][active] - out[False]["terrain_contact_depth"][active])
    assert np.all(deeper <= 2.0 * tol), deeper.max()
    differ = (out[True]["terrain_contact_normal"][active] != out[False]["terrain_contact_normal"][active]).any(axis=1)
    assert differ.mean() > 0.5
