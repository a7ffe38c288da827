"""The terrain formula in Warp equals its float64 NumPy twin; the sphere query finds the true
closest point; plane queries are exact on slopes."""

import math

import numpy as np
import pytest
import warp as wp

from warp_sim import FourierTerrain, ModelBuilder, PlaneTerrain, SimConfig, Simulator
from warp_sim.builder import random_quaternions
from warp_sim.terrain import fourier_height_slope, fourier_sample, terrain_model_fields

TERRAINS = [
    FourierTerrain(),
    FourierTerrain(terms=3, frequency=0.8, amplitude=2.0, phase=1.1, seed=7),
    FourierTerrain(terms=8, frequency=0.2, amplitude=0.7, seed=3, scale=(2.0, 0.5, 3.0), offset=(1.0, -2.0, 4.0)),
    FourierTerrain(terms=2, frequency=1.0, amplitude=1.0, amplitudes=[[0, 1], [0.5, 0.25]],
                   phases=[[0, 0.3], [1.2, 2.0]]),
]


@wp.kernel
def sample_kernel(
    terrain_coef: wp.array(dtype=wp.vec2),
    terrain_terms: int,
    terrain_frequency: float,
    terrain_scale: wp.vec3,
    terrain_offset: wp.vec3,
    points: wp.array(dtype=wp.vec2),
    out_height: wp.array(dtype=float),
    out_grad: wp.array(dtype=wp.vec2),
    out_hess: wp.array(dtype=wp.vec3),
    out_slope_mismatch: wp.array(dtype=int),
):
    i = wp.tid()
    s = fourier_sample(terrain_coef, terrain_terms, terrain_frequency, terrain_scale, terrain_offset,
                       points[i][0], points[i][1])
    out_height[i] = s.height
    out_grad[i] = s.grad
    out_hess[i] = s.hess
    # the height-and-slope sample (box checkpoints) must be the same numbers, bit for bit
    q = fourier_height_slope(terrain_coef, terrain_terms, terrain_frequency, terrain_scale, terrain_offset,
                             points[i][0], points[i][1])
    out_slope_mismatch[i] = int(q.height != s.height or q.grad[0] != s.grad[0] or q.grad[1] != s.grad[1])


def warp_sample(terrain, xz, device):
    f = terrain_model_fields(terrain)
    n = len(xz)
    h = wp.zeros(n, dtype=float, device=device)
    g = wp.zeros(n, dtype=wp.vec2, device=device)
    hs = wp.zeros(n, dtype=wp.vec3, device=device)
    mismatch = wp.zeros(n, dtype=int, device=device)
    wp.launch(sample_kernel, dim=n, device=device, inputs=[
        wp.array(f["terrain_coef"], dtype=wp.vec2, device=device), f["terrain_terms"], f["terrain_frequency"],
        wp.vec3(*f["terrain_scale"]), wp.vec3(*f["terrain_offset"]),
        wp.array(xz.astype(np.float32), dtype=wp.vec2, device=device), h, g, hs, mismatch])
    assert not mismatch.numpy().any(), "fourier_height_slope differs from fourier_sample"
    return h.numpy(), g.numpy(), hs.numpy()


@pytest.mark.parametrize("terrain", TERRAINS, ids=range(len(TERRAINS)))
def test_height_and_gradient_match_numpy_twin(terrain, device):
    """|Warp - NumPy| <= 1e-5 relative to the terrain's height scale sum|A| s_y.

    Float32 error budget: the phase f (m u + n w) is rounded once per power of e^{i f u} with
    relative error 2^-24, so a term's phase error is about k f |u| 2^-24 <= 8 * 0.8 * 20 * 6e-8
    = 8e-6 rad at |x| <= 20 m, times the term amplitude; sums of k^2 terms add ~k^2 2^-24.
    Both stay under 1e-5 of sum|A|, which is why the domain is |x|, |z| <= 20.
    """
    rng = np.random.default_rng(0)
    xz = rng.uniform(-20.0, 20.0, size=(500, 2))
    h, g, _ = warp_sample(terrain, xz, device)
    scale = terrain.max_height_deviation()
    ref_h = terrain.height(xz[:, 0], xz[:, 1])
    ref_gx, ref_gz = terrain.gradient(xz[:, 0], xz[:, 1])
    np.testing.assert_allclose(h, ref_h, rtol=0, atol=1e-5 * scale)
    grad_scale = terrain.slope_bound()
    np.testing.assert_allclose(g[:, 0], ref_gx, rtol=0, atol=1e-5 * grad_scale)
    np.testing.assert_allclose(g[:, 1], ref_gz, rtol=0, atol=1e-5 * grad_scale)


def test_hessian_matches_finite_difference_of_twin_gradient(device):
    """Central differences of the float64 gradient have error O(eps^2 H'''') ~ 1e-8 at eps = 1e-4."""
    terrain = TERRAINS[2]
    rng = np.random.default_rng(1)
    xz = rng.uniform(-10.0, 10.0, size=(200, 2))
    _, _, hess = warp_sample(terrain, xz, device)
    eps = 1e-4
    gxp, gzp = terrain.gradient(xz[:, 0] + eps, xz[:, 1])
    gxm, gzm = terrain.gradient(xz[:, 0] - eps, xz[:, 1])
    _, gz_zp = terrain.gradient(xz[:, 0], xz[:, 1] + eps)
    _, gz_zm = terrain.gradient(xz[:, 0], xz[:, 1] - eps)
    fd = np.stack([(gxp - gxm) / (2 * eps), (gzp - gzm) / (2 * eps), (gz_zp - gz_zm) / (2 * eps)], axis=1)
    curvature_scale = np.abs(fd).max()
    np.testing.assert_allclose(hess, fd, rtol=0, atol=1e-4 * curvature_scale)


def test_model_transform_inverse_maps_points_into_terrain_space():
    """H(x, z) = o.y + s.y T((x - o.x)/s.x, (z - o.z)/s.z) with T the untransformed terrain."""
    base = FourierTerrain(terms=4, seed=5)
    moved = FourierTerrain(terms=4, seed=5, scale=(2.0, 3.0, 0.5), offset=(1.0, -1.0, 2.0))
    x, z = np.array([0.3, -4.0, 7.5]), np.array([1.0, 2.0, -3.0])
    np.testing.assert_allclose(moved.height(x, z), -1.0 + 3.0 * base.height((x - 1.0) / 2.0, (z - 2.0) / 0.5))


def test_explicit_tables_override_the_seeded_draw():
    t = TERRAINS[3]
    a = t.amplitude_table()
    assert a[0, 0] == 0.0
    assert a[0, 1] == pytest.approx(1.0)
    assert a[1, 1] == pytest.approx(0.25 / math.sqrt(2.0))
    assert t.phase_table()[1, 0] == pytest.approx(1.2)


def sphere_sim(terrain, centers, radius, device="cpu"):
    b = ModelBuilder()
    b.set_terrain(terrain)
    for c in centers:
        b.add_sphere(radius, 1.0, position=tuple(c))
    return Simulator(b.finalize(device), SimConfig(device=device))


def test_sphere_query_finds_the_true_closest_point(device):
    """The deepest of a sphere's slots equals r minus the brute-force distance to the surface
    (grid search, 5 mm cells, so the oracle itself is within 5 mm / 2 * slope of the truth: 0.6 cm
    tolerance).  r 0.5 exceeds this terrain's curvature radius bound (0.41 m): 5 slots each."""
    terrain = FourierTerrain()
    rng = np.random.default_rng(2)
    radius = 0.5
    xz = rng.uniform(-10, 10, size=(60, 2))
    centers = np.stack([xz[:, 0], terrain.height(xz[:, 0], xz[:, 1]) + rng.uniform(-0.3, 0.6, 60), xz[:, 1]], 1)
    sim = sphere_sim(terrain, centers, radius, device)
    probe = sim.probe_contacts()
    sim.collide(sim.state, probe, 1.0 / 240.0, 10.0)
    start, count = sim.model.host["body_checkpoint_start"], sim.model.host["body_checkpoint_count"]
    assert np.all(count == 5)
    slot_depth = np.where(probe.terrain_contact_active.numpy() != 0, probe.terrain_contact_depth.numpy(), -np.inf)
    depth = [slot_depth[s:s + n].max() for s, n in zip(start, count)]
    g = np.linspace(-1.2, 1.2, 481)
    for i, c in enumerate(centers):
        gx, gz = np.meshgrid(c[0] + g, c[2] + g)
        dist = np.sqrt((gx - c[0]) ** 2 + (terrain.height(gx, gz) - c[1]) ** 2 + (gz - c[2]) ** 2).min()
        signed = -dist if c[1] < terrain.height(c[0], c[2]) else dist
        assert depth[i] == pytest.approx(radius - signed, abs=6e-3), f"sphere {i}"


def test_sphere_on_30_degree_plane_gets_exact_normal_and_depth(device):
    """Not a vertical test: on a slope the depth is measured along the plane normal."""
    plane = PlaneTerrain.from_slope(30.0)
    n = np.array(plane.normal)
    radius = 0.5
    center = np.array([2.0, 0.0, 1.0])
    center = center - (center @ n) * n + n * (radius - 0.01)  # 1 cm into the plane
    sim = sphere_sim(plane, [center], radius, device)
    probe = sim.probe_contacts()
    sim.collide(sim.state, probe, 1.0 / 240.0, 0.0)
    assert probe.terrain_contact_active.numpy()[0] == 1
    assert probe.terrain_contact_depth.numpy()[0] == pytest.approx(0.01, abs=1e-6)
    np.testing.assert_allclose(probe.terrain_contact_normal.numpy()[0], n, atol=1e-6)


@pytest.mark.parametrize("terrain", TERRAINS, ids=range(len(TERRAINS)))
def test_cubic_bound_bounds_every_third_directional_derivative(terrain):
    """d^3/ds^3 H(p + s e) = sum A (f k . e')^3 sin(phase) exactly (e' = e scaled by 1/s.x, 1/s.z);
    the bound used to skip box checkpoints must hold at every point and in every direction."""
    rng = np.random.default_rng(5)
    k = terrain.terms
    a = terrain.amplitude_table()
    p = terrain.phase_table()
    m, n = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    angle = rng.uniform(0.0, 2.0 * math.pi, 4000)
    u = rng.uniform(-30.0, 30.0, 4000)
    w = rng.uniform(-30.0, 30.0, 4000)
    eu = np.cos(angle) / terrain.scale[0]
    ew = np.sin(angle) / terrain.scale[2]
    f = terrain.frequency
    rate = f * (m[None] * eu[:, None, None] + n[None] * ew[:, None, None])
    phase = f * (m[None] * u[:, None, None] + n[None] * w[:, None, None]) + p[None]
    third = terrain.scale[1] * np.sum(a[None] * rate**3 * np.sin(phase), axis=(1, 2))
    bound = terrain.cubic_bound()
    assert np.abs(third).max() <= bound
    assert np.abs(third).max() > 0.2 * bound  # and it is not vacuous


@pytest.mark.parametrize("moving", [True, False], ids=["moving", "at_rest"])
@pytest.mark.parametrize("terrain", TERRAINS, ids=range(len(TERRAINS)))
def test_box_checkpoint_cull_changes_no_contact(terrain, moving, device):
    """Skipping checkpoints that provably cannot reach the surface (collide/terrain_contact.py)
    must give exactly the contacts of testing every checkpoint: boxes of random size and
    orientation, from 0.3 reach below the surface to 1.2 reach above it.  Moving and spinning
    with the default margin; and at rest with no margin, where the window is h^2 g and the skip
    is decided within millimetres of the surface (a bound 2 cm too low fails this case)."""
    rng = np.random.default_rng(6)
    count = 300
    b = ModelBuilder()
    b.set_terrain(terrain)
    xz = rng.uniform(-15.0, 15.0, size=(count, 2))
    quats = random_quaternions(rng, count)
    for i in range(count):
        half = rng.uniform(0.1, 0.6, 3)
        reach = float(np.linalg.norm(half))
        ground = float(terrain.height(xz[i, 0], xz[i, 1]))
        pos = (xz[i, 0], ground + rng.uniform(-0.3, 1.2) * reach, xz[i, 1])
        speed = 1.0 if moving else 0.0
        b.add_box(tuple(half), 1.0, position=pos, orientation=tuple(quats[i]),
                  velocity=tuple(speed * rng.normal(0.0, 2.0, 3)),
                  angular_velocity=tuple(speed * rng.normal(0.0, 3.0, 3)))
    sim = Simulator(b.finalize(device), SimConfig(sleep=False, device=device))
    results = []
    for cull in (False, True):
        sim.terrain_cull = cull
        probe = sim.model.contacts()
        if moving:
            sim.collide(sim.state, probe, 1.0 / 60.0, 0.02)
        else:
            sim.collide(sim.state, probe, 1.0 / 240.0, 0.0)
        active = probe.terrain_contact_active.numpy().astype(bool)
        results.append((active, probe.terrain_contact_depth.numpy()[active],
                        probe.terrain_contact_normal.numpy()[active], probe.terrain_contact_point.numpy()[active]))
    full, culled = results
    assert 0 < full[0].sum() < 0.6 * len(full[0])  # both kinds of slot occur
    for a, c in zip(full, culled):
        np.testing.assert_array_equal(a, c)
