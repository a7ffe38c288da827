"""Broad phase: every method against a NumPy brute-force reference, sorted and deterministic
output, unbounded coordinates, overflow reporting and the margin boundary."""

import numpy as np
import pytest
import warp as wp

from warp_sim.collide.broad_phase import BROAD_PHASES, BroadPhaseOverflowError, make_broad_phase, triangle_pair
from warp_sim.collide.broad_phase_grid import ROW_STASH, table_layout_host

FILTERED = ["bounding_sphere", "grid", "grid_sorted", "grid_hash"]


def scene(count: int, layout: str, seed: int, static_fraction=0.2, offset=(0.0, 0.0, 0.0)):
    """Random bodies with radii 0.05-1.0 m: ``spread`` uniformly, ``clustered`` in a few blobs."""
    rng = np.random.default_rng(seed)
    if layout == "spread":
        side = (count * 8.0) ** (1.0 / 3.0)  # about one body per 8 m^3
        pos = rng.uniform(-side / 2, side / 2, size=(count, 3))
    else:
        centres = rng.uniform(-20.0, 20.0, size=(5, 3))
        pos = centres[rng.integers(0, 5, count)] + rng.normal(0.0, 1.5, size=(count, 3))
    pos = (pos + np.asarray(offset)).astype(np.float32)
    radius = rng.uniform(0.05, 1.0, size=count).astype(np.float32)
    inv_mass = np.where(rng.random(count) < static_fraction, 0.0, 1.0).astype(np.float32)
    return pos, radius, inv_mass


def reference_pairs(pos, radius, inv_mass, margin, test_distance=True) -> np.ndarray:
    """Sorted (i, j), i < j, by brute force in float64."""
    p = pos.astype(np.float64)
    r = radius.astype(np.float64)
    keep = np.ones((len(p), len(p)), dtype=bool)
    if test_distance:
        d2 = ((p[:, None, :] - p[None, :, :]) ** 2).sum(-1)
        keep = d2 < (r[:, None] + r[None, :] + margin) ** 2
    if inv_mass is not None:
        static = inv_mass == 0.0
        keep &= ~(static[:, None] & static[None, :])
    i, j = np.nonzero(np.triu(keep, 1))
    return np.stack([i, j], axis=1).astype(np.int32)


def run(method, pos, radius, inv_mass, margin, capacity=None, device="cpu", body_count=None):
    n = len(pos)
    if capacity is None:
        capacity = n * (n - 1) // 2 if method == "all_pairs" else 8 * n
    bp = make_broad_phase(method, n if body_count is None else body_count, capacity, device)
    positions = wp.array(pos, dtype=wp.vec3, device=device)
    radii = wp.array(radius, dtype=float, device=device)
    inv = None if inv_mass is None else wp.array(inv_mass, dtype=float, device=device)
    count = bp.find_pairs(positions, radii, inv, margin)
    pairs = bp.pairs()
    assert len(pairs) == count
    return pairs


@pytest.mark.parametrize("layout", ["spread", "clustered"])
@pytest.mark.parametrize("count", [50, 300, 2000])
def test_methods_match_reference(count, layout, device):
    """bounding_sphere and both grids return exactly the brute-force pair list; all_pairs
    returns every pair that is not static-static, N(N-1)/2 - S(S-1)/2 of them."""
    pos, radius, inv_mass = scene(count, layout, seed=count)
    margin = 0.05
    expected = reference_pairs(pos, radius, inv_mass, margin)
    assert len(expected) > 0
    if layout == "clustered" and count >= 300:
        # grid_sorted copies rows of up to ROW_STASH pairs and scans longer ones again: both occur
        rows = np.bincount(expected[:, 0], minlength=count)
        assert rows.max() > ROW_STASH and np.any((rows > 0) & (rows <= ROW_STASH))
    for method in FILTERED:
        # capacity == demand exactly is not an overflow
        pairs = run(method, pos, radius, inv_mass, margin, capacity=len(expected), device=device)
        np.testing.assert_array_equal(pairs, expected, err_msg=method)
    everything = run("all_pairs", pos, radius, inv_mass, margin, device=device)
    statics = int((inv_mass == 0).sum())
    assert len(everything) == count * (count - 1) // 2 - statics * (statics - 1) // 2
    np.testing.assert_array_equal(everything, reference_pairs(pos, radius, inv_mass, margin, test_distance=False))


def test_without_inv_mass_keeps_static_pairs(device):
    """inv_mass=None means no body is treated as static."""
    pos, radius, inv_mass = scene(300, "clustered", seed=3, static_fraction=0.5)
    expected = reference_pairs(pos, radius, None, 0.0)
    assert len(expected) > len(reference_pairs(pos, radius, inv_mass, 0.0))
    for method in FILTERED:
        np.testing.assert_array_equal(run(method, pos, radius, None, 0.0, capacity=len(expected), device=device),
                                      expected, err_msg=method)
    assert len(run("all_pairs", pos, radius, None, 0.0, device=device)) == 300 * 299 // 2


def test_sorted_and_deterministic_across_runs_and_threads(device, monkeypatch):
    """The pair list is strictly increasing in (i, j) and bit-identical between two runs, also
    when the CPU launch is split into a different number of chunks."""
    pos, radius, inv_mass = scene(10000, "spread", seed=11)
    for method in ["grid_sorted", "grid_hash"]:
        monkeypatch.setenv("WARP_SIM_CPU_THREADS", "1")
        first = run(method, pos, radius, inv_mass, 0.02, device=device)
        monkeypatch.setenv("WARP_SIM_CPU_THREADS", "4")
        second = run(method, pos, radius, inv_mass, 0.02, device=device)
        third = run(method, pos, radius, inv_mass, 0.02, device=device)
        keys = first[:, 0].astype(np.int64) * len(pos) + first[:, 1]
        assert np.all(np.diff(keys) > 0), method
        assert np.all(first[:, 0] < first[:, 1]), method
        np.testing.assert_array_equal(first, second, err_msg=method)
        np.testing.assert_array_equal(second, third, err_msg=method)


def test_far_from_origin_and_negative_coordinates(device):
    """Bodies around x = 1e4 and at negative coordinates (cells on both sides of 0)."""
    for offset in [(1.0e4, 0.0, 0.0), (-1.0e4, -3.0e3, 5.0e3), (-0.5, -0.5, -0.5)]:
        pos, radius, inv_mass = scene(2000, "spread", seed=5, offset=offset)
        expected = reference_pairs(pos, radius, inv_mass, 0.1)
        assert len(expected) > 0
        for method in FILTERED:
            np.testing.assert_array_equal(run(method, pos, radius, inv_mass, 0.1, device=device), expected,
                                          err_msg=f"{method} at {offset}")


def test_very_different_sizes(device):
    """One body 40x larger than the rest: the cell comes from the largest radius, and its long
    row of pairs (sorted by heapsort) is still exact."""
    pos, radius, inv_mass = scene(2000, "spread", seed=8)
    radius = radius * 0.2
    radius[17] = 8.0
    expected = reference_pairs(pos, radius, inv_mass, 0.0)
    assert (expected[:, 0] == 17).sum() + (expected[:, 1] == 17).sum() > 100
    for method in FILTERED:
        np.testing.assert_array_equal(run(method, pos, radius, inv_mass, 0.0, device=device), expected, err_msg=method)


@pytest.mark.parametrize("method", sorted(BROAD_PHASES))
def test_overflow_raises_with_capacity_and_demand(method, device):
    pos, radius, inv_mass = scene(300, "clustered", seed=2)
    demand = len(reference_pairs(pos, radius, inv_mass, 0.05, test_distance=method != "all_pairs"))
    with pytest.raises(BroadPhaseOverflowError, match=rf"found {demand} candidate pairs .* holds 7\b") as info:
        run(method, pos, radius, inv_mass, 0.05, capacity=7, device=device)
    assert info.value.capacity == 7 and info.value.demand == demand
    bp = make_broad_phase(method, 300, 7, device)
    count = bp.find_pairs(wp.array(pos, dtype=wp.vec3, device=device), wp.array(radius, dtype=float, device=device),
                          wp.array(inv_mass, dtype=float, device=device), 0.05, check=False)
    assert count == demand and len(bp.pairs()) == 7


@pytest.mark.parametrize("method", FILTERED)
def test_margin_boundary(method, device):
    """Centres r_i + r_j + margin apart are not a pair (strict <); 1 mm closer they are, 1 mm
    farther they are not; touching spheres need margin > 0."""
    r = 0.5
    margin = 0.25
    gap = 2 * r + margin
    xs = [0.0, gap - 1e-3, 10.0, 10.0 + gap, 20.0, 20.0 + gap + 1e-3, 30.0, 30.0 + 2 * r]
    pos = np.array([[x, 0.0, 0.0] for x in xs], dtype=np.float32)
    radius = np.full(len(xs), r, dtype=np.float32)
    found = {tuple(p) for p in run(method, pos, radius, None, margin, device=device)}
    assert found == {(0, 1), (6, 7)}
    found = {tuple(p) for p in run(method, pos, radius, None, 0.0, device=device)}
    assert found == set()  # at margin 0 exactly touching (bodies 6, 7) is not a pair
    found = {tuple(p) for p in run(method, pos, radius, None, 1e-3, device=device)}
    assert found == {(6, 7)}


def test_small_and_empty_scenes(device):
    """0, 1 and 2 bodies, also fewer than the broad phase was sized for."""
    for method in BROAD_PHASES:
        for n in (0, 1):
            pos = np.zeros((n, 3), dtype=np.float32)
            assert len(run(method, pos, np.ones(n, dtype=np.float32), None, 0.1, capacity=4, device=device)) == 0
        pos = np.array([[0, 0, 0], [0.5, 0, 0]], dtype=np.float32)
        for body_count in (2, 100):
            pairs = run(method, pos, np.ones(2, dtype=np.float32), None, 0.0, capacity=4, device=device,
                        body_count=body_count)
            np.testing.assert_array_equal(pairs, [[0, 1]])


def test_factory():
    assert make_broad_phase("grid", 10, 10).name in ("grid_sorted", "grid_hash")
    with pytest.raises(ValueError, match="unknown broad phase 'sap'"):
        make_broad_phase("sap", 10, 10)
    with pytest.raises(ValueError, match="at most 65536 bodies"):
        make_broad_phase("all_pairs", 70000, 10)


@wp.kernel
def triangle_pair_kernel(n: int, k: wp.array(dtype=wp.int64), out: wp.array(dtype=wp.vec2i)):
    t = wp.tid()
    out[t] = triangle_pair(k[t], wp.int64(n))


@pytest.mark.parametrize("n", [2, 3, 7, 1000, 65536])
def test_triangle_index_mapping(n, device):
    """Linear index -> (i, j) of the upper triangle at row starts and ends, up to the largest N."""
    rows = np.unique(np.linspace(0, n - 2, min(n - 1, 500)).astype(np.int64))
    start = rows * (2 * n - rows - 1) // 2
    length = n - 1 - rows
    k = np.concatenate([start, start + length - 1, start + length // 2])
    i = np.concatenate([rows, rows, rows])
    j = np.concatenate([rows + 1, np.full_like(rows, n - 1), rows + 1 + length // 2])
    out = wp.zeros(len(k), dtype=wp.vec2i, device=device)
    wp.launch(triangle_pair_kernel, dim=len(k), inputs=[n, wp.array(k, dtype=wp.int64, device=device), out],
              device=device)
    np.testing.assert_array_equal(out.numpy(), np.stack([i, j], axis=1))


def test_table_layout_follows_world_shape():
    """A flat world gets few bits across its thin axis and more along the wide ones."""
    assert table_layout_host(np.array([-60, 0, -60, 59, 10, 59]), 18) == (7, 4, 7)
    assert table_layout_host(np.array([0, 0, 0, 0, 0, 0]), 6) == (2, 2, 2)
    assert sum(table_layout_host(np.array([-10**9, 0, 0, 10**9, 1000, 1000]), 12)) == 12


def test_device_table_layout_matches_host(device):
    pos, radius, _ = scene(2000, "clustered", seed=4)
    bp = make_broad_phase("grid_sorted", 2000, 8 * 2000, device)
    bp.find_pairs(wp.array(pos, dtype=wp.vec3, device=device), wp.array(radius, dtype=float, device=device),
                  check=False)
    assert tuple(bp.table_layout.numpy()[0]) == table_layout_host(bp.cell_bounds.numpy(), bp.table_bits)
