"""The capturable exclusive scan (warp_sim/prefix_sum.py) against NumPy, on the sizes where its
chunk levels change (one chunk, one past it, exact powers of the chunk, ragged tails) and for
both integer widths the broad phases scan."""

import numpy as np
import pytest
import warp as wp

from warp_sim.prefix_sum import SCAN_CHUNK, ExclusiveScan, level_sizes

SIZES = [1, 2, SCAN_CHUNK - 1, SCAN_CHUNK, SCAN_CHUNK + 1, SCAN_CHUNK**2, SCAN_CHUNK**2 + 1, 5 * SCAN_CHUNK**2 - 3,
         SCAN_CHUNK**3 + 7, 70_001]


@pytest.mark.parametrize("dtype", [wp.int32, wp.int64])
@pytest.mark.parametrize("n", SIZES)
def test_exclusive_scan_equals_numpy(device, n, dtype):
    rng = np.random.default_rng(n)
    np_type = np.int32 if dtype == wp.int32 else np.int64
    high = 50 if dtype == wp.int32 else 3_000_000_000  # int64 row counts exceed int32 per row
    values = rng.integers(0, high, n).astype(np_type)
    capacity = n + 37  # a scan built for more than it is asked to sum
    scan = ExclusiveScan(capacity, device, dtype)
    src = wp.array(np.concatenate([values, np.full(37, 9, np_type)]), dtype=dtype, device=device)
    out = wp.full(capacity, -1, dtype=dtype, device=device)
    scan.run(src, out, n)
    got = out.numpy()
    want = np.concatenate([[0], np.cumsum(values, dtype=np.int64)[:-1]]).astype(np_type)
    np.testing.assert_array_equal(got[:n], want)
    assert (got[n:] == -1).all()  # nothing past the live count is written


def test_levels_shrink_by_the_chunk_until_one_chunk_is_left():
    assert level_sizes(SCAN_CHUNK) == []
    assert level_sizes(SCAN_CHUNK + 1) == [2]
    assert level_sizes(SCAN_CHUNK**3 + 1) == [SCAN_CHUNK**2 + 1, SCAN_CHUNK + 1, 2]


def test_a_scan_refuses_more_values_or_another_type_than_it_was_built_for():
    scan = ExclusiveScan(10, "cpu", wp.int32)
    a = wp.zeros(20, dtype=wp.int32)
    with pytest.raises(ValueError, match="ExclusiveScan of 11 values"):
        scan.run(a, a, 11)
    b = wp.zeros(10, dtype=wp.int64)
    with pytest.raises(ValueError, match="int64"):
        scan.run(b, b, 5)
