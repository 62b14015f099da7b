"""Summed-area tables (wsoft.accel.sat): builds, look-ups, tile sizes and precision."""

import math

import numpy as np
import pytest
import warp as wp

from wsoft.accel import sat as S


def _boxes(rng, n, count, max_size):
    u0 = rng.uniform(-4, n, count)
    v0 = rng.uniform(-4, n, count)
    b = np.stack([u0, u0 + rng.uniform(0, max_size, count), v0, v0 + rng.uniform(0, max_size, count)], -1)
    return b.astype(np.float32).astype(np.float64)  # look-ups take float32 corners


@pytest.mark.parametrize("storage", S.STORAGES)
@pytest.mark.parametrize("build", S.BUILDS)
def test_box_sums_match_float64(storage, build, device):
    """Every storage and build gives the float64 integral of fractional boxes, also across tile
    boundaries and map edges; integer storage within its rounding (half a unit per texel)."""
    rng = np.random.default_rng(1)
    n, mu = 128, 20
    b = (rng.random((3, n, n)) ** 3).astype(np.float32)
    sat = S.build_sat(wp.array(b, dtype=float, device=device), storage=storage, build=build, mu=mu, tile=16 if storage == "tiles" else None, device=device)
    boxes = _boxes(rng, n, 3000, 70)
    boxes[:50, 1] = boxes[:50, 0] + rng.uniform(0, 0.9, 50)  # inside one texel column
    boxes[50:100, 3] = boxes[50:100, 2]  # empty
    boxes = boxes.astype(np.float32).astype(np.float64)
    for ch in (0, 2):
        got = S.box_sums(sat, boxes, channel=ch, device=device)
        ref = S.reference_box_sums(b[ch], boxes)
        area = np.clip(boxes[:, 1], 0, n) - np.clip(boxes[:, 0], 0, n)
        area *= np.clip(boxes[:, 3], 0, n) - np.clip(boxes[:, 2], 0, n)
        area = np.maximum(area, 0)
        err = np.abs(got - ref)
        if storage == "float32":
            assert np.all(err <= 1e-4 * np.maximum(ref, 1.0) + 1e-3)
        else:
            # rounding: at most half a unit per touched texel (the box plus its one-texel border)
            touched = area + 2 * np.sqrt(area) * 2 + 4
            assert np.all(err <= touched * 0.5 * 2.0 ** -mu + 1e-9)
    assert sat.tile == (16 if storage == "tiles" else n)


def test_builds_agree_and_count_passes(device):
    """Recursive doubling and the direct scan give the same table; doubling passes are
    2 ceil(log_X T) as in §6.1 (X = 8: 6 / 8 / 8 / 8 passes at 512..4096, 4 for 64-texel tiles)."""
    rng = np.random.default_rng(2)
    n = 256
    b = wp.array(rng.random((1, n, n)).astype(np.float32), dtype=float, device=device)
    for storage, tile in (("uint32", None), ("tiles", 64), ("tiles", 8)):
        a = S.build_sat(b, storage=storage, build="doubling", reads=8, tile=tile, device=device)
        c = S.build_sat(b, storage=storage, build="scan", tile=tile, device=device)
        assert np.array_equal(a.data.numpy(), c.data.numpy())
        assert c.passes == 2
        assert a.passes == 2 * S.doubling_passes(a.tile, 8)
    assert [2 * S.doubling_passes(n, 8) for n in (512, 1024, 2048, 4096)] == [6, 8, 8, 8]
    assert 2 * S.doubling_passes(64, 8) == 4
    assert 2 * S.doubling_passes(4096, 2) == 24
    f = S.build_sat(b, storage="uint32", build="doubling", reads=2, device=device)
    assert f.passes == 16


def test_tile_size_from_the_pyramid(device):
    """§6.1: the first pyramid level (top-down) whose blocks sum below 2^32 as integers."""
    n, mu = 256, 20
    ones = wp.array(np.ones((2, n, n), np.float32), dtype=float, device=device)
    sat = S.build_sat(ones, storage="tiles", mu=mu, device=device)
    # a full block of 2^L x 2^L ones holds 4^L 2^20: L = 5 is the largest below 2^32
    assert sat.tile == 32 and sat.tiles_per_side == 8
    assert sat.data.numpy().max() == 32 * 32 * 2**20
    sparse = np.zeros((2, n, n), np.float32)
    sparse[:, 10, 10] = 1.0
    sat2 = S.build_sat(wp.array(sparse, dtype=float, device=device), storage="tiles", mu=mu, device=device)
    assert sat2.tile == n  # one texel at 1.0 fits the whole map in one tile
    assert sat2.tile_test["levels_tested"][0]["passes"]
    # every tile's total stays below 2^32 (no overflow anywhere)
    half = wp.array(np.full((1, n, n), 0.49, np.float32), dtype=float, device=device)
    sat3 = S.build_sat(half, storage="tiles", mu=24, device=device)
    t = sat3.tile
    totals = sat3.data.numpy()[0, t - 1 :: t, t - 1 :: t].astype(np.float64)
    exact = 0.49 * 2**24 * t * t
    assert totals.max() < 2**32 and np.allclose(totals, round(0.49 * 2**24) * t * t) and exact < 2**32


def test_uint32_full_sat_overflows_where_tiles_do_not(device):
    """μ = 20 and a 4096-texel box of ones: the full uint32 SAT's box sum wraps (2^32 = 0), the
    tile grid splits the box at its tiles and stays exact."""
    n, mu = 256, 20
    ones = wp.array(np.ones((1, n, n), np.float32), dtype=float, device=device)
    box = np.array([[10.0, 74.0, 20.0, 84.0]])  # 64 x 64 texels: 2^12 * 2^20 = 2^32
    full = S.build_sat(ones, storage="uint32", mu=mu, device=device)
    tiles = S.build_sat(ones, storage="tiles", mu=mu, device=device)
    assert S.box_sums(full, box, device=device)[0] == pytest.approx(0.0)
    assert S.box_sums(tiles, box, device=device)[0] == pytest.approx(4096.0, rel=1e-12)


def test_float32_sat_loses_precision_at_4096_tile_grid_does_not(device):
    """Precision at 4096²: an ESM basis. Box sums of 3x3 kernels near the far corner
    from a float32 full SAT are measurably wrong against float64 (> 1% median relative error);
    the uint32 tile grid (μ = 20) stays within 2^-μ per texel of the box (relative to its area)."""
    n, mu = 4096, 20
    rng = np.random.default_rng(3)
    z = rng.uniform(0.6, 1.0, (n, n)).astype(np.float32)
    c = mu * math.log(2.0)
    basis = ((np.exp(c * (z - 1.0)) - np.exp(-c)) / (1.0 - np.exp(-c))).astype(np.float32)[None]
    arr = wp.array(basis, dtype=float, device=device)
    boxes = np.array([[x, x + 3.0, y, y + 3.0] for x in range(n - 40, n - 3, 7) for y in range(n - 40, n - 3, 7)], np.float64)
    ref = S.reference_box_sums(basis[0], boxes)
    f32 = S.build_sat(arr, storage="float32", build="scan", device=device)
    rel32 = np.abs(S.box_sums(f32, boxes, device=device) - ref) / ref
    del f32
    tiles = S.build_sat(arr, storage="tiles", build="scan", mu=mu, device=device)
    got = S.box_sums(tiles, boxes, device=device)
    assert tiles.tile < n
    assert np.median(rel32) > 1e-2
    assert np.all(np.abs(got - ref) <= 9.0 * 2.0**-mu)
    assert np.all(np.isfinite(got))


def test_bad_input():
    b = wp.array(np.zeros((1, 96, 96), np.float32), dtype=float, device="cpu")
    with pytest.raises(ValueError, match="power-of-two"):
        S.build_sat(b, storage="tiles")
    b = wp.array(np.zeros((1, 64, 64), np.float32), dtype=float, device="cpu")
    with pytest.raises(ValueError, match="storage"):
        S.build_sat(b, storage="float16")
    with pytest.raises(ValueError, match="tile size"):
        S.build_sat(b, storage="tiles", tile=24)
