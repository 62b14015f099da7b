"""The light-sample generator: each pattern's defining property, on the host and on the device."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from wsoft.lightspace.samples import (
    PAPER_MIN_DISTANCE,
    LightSamples,
    SamplePattern,
    sample_coords,
    sampling_begin,
)


@wp.kernel
def draw(
    ls: LightSamples,
    width: int,
    # outputs
    out: wp.array2d[wp.vec2],
):
    """Light coordinates of every sample of pixel (tid % width, tid / width), pixel index = tid."""
    i = wp.tid()
    state, base, rot = sampling_begin(ls, i, i % width, i / width)
    for s in range(ls.count):
        c, state = sample_coords(ls, state, base, rot, s)
        out[i, s] = c


def device_sets(pattern: SamplePattern, pixels: int, width: int, disk: bool = False, device: str = "cpu") -> np.ndarray:
    out = wp.empty((pixels, pattern.count), dtype=wp.vec2, device=device)
    wp.launch(draw, dim=pixels, inputs=[pattern.on(device, disk), width], outputs=[out], device=device)
    return out.numpy()


def min_distance(pts: np.ndarray) -> float:
    d = np.sqrt(((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1))
    d[np.diag_indices(len(pts))] = np.inf
    return float(d.min())


@pytest.mark.parametrize("kind", ["regular", "jittered", "random", "stratified", "poisson", "sobol02"])
@pytest.mark.parametrize("count", [16, 64])
def test_points_in_the_unit_square_and_deterministic(kind, count):
    p = SamplePattern(kind, count, seed=3)
    a, b = p.points(), p.points()
    assert a.shape == (1, count, 2) and np.array_equal(a, b)
    assert (a >= 0).all() and (a < 1).all()
    if kind not in ("regular",):
        assert not np.array_equal(a, SamplePattern(kind, count, seed=4).points())


@pytest.mark.parametrize("count", [4, 16, 64, 256])
def test_jittered_and_stratified_put_one_point_in_each_cell(count):
    m = math.isqrt(count)
    for kind in ("jittered", "stratified", "regular"):
        pts = SamplePattern(kind, count, seed=1).points()[0]
        cells = np.floor(pts * m).astype(int)
        assert len({(x, y) for x, y in cells}) == count
        assert np.array_equal(cells[:, 1] * m + cells[:, 0], np.arange(count))  # row-major: sample r m + c in cell (c, r)


@given(m=st.integers(min_value=1, max_value=10), seed=st.integers(min_value=0, max_value=2**31 - 1))
@settings(max_examples=30, deadline=None)
def test_sobol02_first_2m_points_are_a_0m2_net(m, seed):
    """Every elementary interval of area 2^-m (2^a x 2^b cells, a + b = m) holds exactly one point."""
    n = 1 << m
    pts = SamplePattern("sobol02", n, seed=seed).points()[0]
    for a in range(m + 1):
        b = m - a
        cx = np.floor(pts[:, 0] * (1 << a)).astype(np.int64)
        cy = np.floor(pts[:, 1] * (1 << b)).astype(np.int64)
        assert len(set(zip(cx.tolist(), cy.tolist()))) == n, (a, b)


@pytest.mark.parametrize("count", [16, 64])
def test_poisson_keeps_the_papers_minimum_distance(count):
    d = PAPER_MIN_DISTANCE[count]
    for seed in range(3):
        pts = SamplePattern("poisson", count, seed=seed, min_distance=d).points()[0]
        assert len(pts) == count and min_distance(pts) >= d


@given(count=st.integers(min_value=1, max_value=80), seed=st.integers(min_value=0, max_value=1000))
@settings(max_examples=25, deadline=None)
def test_poisson_without_a_distance_fits_every_point(count, seed):
    pts = SamplePattern("poisson", count, seed=seed).points()[0]
    assert len(pts) == count and (count == 1 or min_distance(pts) > 0.15 / math.sqrt(count))


def test_poisson_too_far_apart_is_a_clear_error():
    with pytest.raises(ValueError, match="cannot place 64 Poisson-disk samples"):
        SamplePattern("poisson", 64, min_distance=0.3).points()


@pytest.mark.parametrize("bad", [dict(kind="hex"), dict(count=0), dict(kind="jittered", count=15), dict(min_distance=1.5),
                                 dict(min_distance=float("nan")), dict(kind="poisson", per_pixel=True), dict(per_pixel=True, rotate=True),
                                 dict(interleave=0), dict(interleave=17)])
def test_bad_patterns_rejected(bad):
    with pytest.raises(ValueError):
        SamplePattern(**bad)


def test_interleaving_gives_n_by_n_sets_by_pixel():
    p = SamplePattern("poisson", 16, seed=2, interleave=2)
    host = p.points()
    assert host.shape == (4, 16, 2) and len({h.tobytes() for h in host}) == 4
    w = 6
    got = device_sets(p, 24, w)
    for i in range(24):
        x, y = i % w, i // w
        want = 2.0 * host[(y % 2) * 2 + (x % 2)].astype(np.float32) - 1.0
        assert np.allclose(got[i], want, atol=1e-6)


def test_rotation_on_a_disk_turns_the_set_and_keeps_its_radii():
    p = SamplePattern("poisson", 16, seed=5, rotate=True)
    got = device_sets(p, 50, 10, disk=True)
    r = np.linalg.norm(got, axis=-1)
    assert np.allclose(np.sort(r, axis=1), np.sort(r[0])[None, :], atol=1e-5)  # same radii in every pixel
    assert (r <= 1 + 1e-6).all()
    ang = np.arctan2(got[:, 0, 1], got[:, 0, 0])
    assert np.unique(np.round(ang, 3)).size > 40  # and a different angle per pixel


def test_rotation_on_a_rectangle_is_a_toroidal_shift():
    p = SamplePattern("sobol02", 16, seed=5, rotate=True)
    u = (device_sets(p, 40, 8) + 1.0) / 2.0
    assert (u >= -1e-6).all() and (u <= 1 + 1e-6).all()
    base = p.points()[0]
    for i in range(40):
        shift = (u[i] - base) % 1.0
        assert np.allclose(shift, shift[0], atol=1e-5) or np.allclose(np.abs(shift - shift[0]) % 1.0, 0, atol=1e-5)
    assert np.unique(np.round(u[:, 0, 0], 4)).size > 30


def test_per_pixel_stratified_is_a_fresh_jittered_grid_per_pixel():
    p = SamplePattern("stratified", 16, seed=9, per_pixel=True)
    u = (device_sets(p, 30, 6) + 1.0) / 2.0
    cells = np.floor(u * 4).astype(int)
    for i in range(30):
        assert np.array_equal(cells[i, :, 1] * 4 + cells[i, :, 0], np.arange(16))
    assert len({g.tobytes() for g in u}) == 30


@pytest.mark.parametrize("kind", ["regular", "jittered", "stratified", "random", "poisson", "sobol02"])
def test_samples_cover_a_disk_uniformly(kind):
    """Mapped onto a disk: every point inside, and a quarter of them (within noise) inside half the
    radius (over 64 interleaved sets, or a set per pixel: a rotation alone keeps a set's radii)."""
    if kind in ("poisson", "sobol02"):
        p = SamplePattern(kind, 64, seed=11, interleave=8, min_distance=PAPER_MIN_DISTANCE[64] if kind == "poisson" else 0.0)
    else:
        p = SamplePattern(kind, 64, seed=11, per_pixel=True)
    got = device_sets(p, 64, 8, disk=True).reshape(-1, 2)
    r = np.linalg.norm(got, axis=-1)
    assert (r <= 1 + 1e-6).all()
    inner = np.mean(r < 0.5)
    if kind == "poisson":  # dart throwing in the square: denser near its edges (documented in poisson_disk)
        assert 0.20 < inner < 0.25
    else:
        assert abs(inner - 0.25) < 0.025


def pcg_hash_np(v: np.ndarray) -> np.ndarray:
    """:func:`wsoft.lightspace.samples.pcg_hash` in numpy (uint32 arithmetic wraps)."""
    state = v.astype(np.uint32) * np.uint32(747796405) + np.uint32(2891336453)
    word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
    return (word >> np.uint32(22)) ^ word


def counter_draw_np(seed: int, index: np.ndarray, s: np.ndarray, dim: int) -> np.ndarray:
    key = pcg_hash_np(pcg_hash_np(np.array(seed).astype(np.uint32)) + index.astype(np.uint32))
    h = pcg_hash_np(pcg_hash_np(key + s.astype(np.uint32)) + np.uint32(dim))
    return (h >> np.uint32(8)).astype(np.float64) / 16777216.0


@pytest.mark.parametrize("kind", ["random", "jittered", "stratified"])
def test_per_pixel_draws_are_a_hash_of_seed_pixel_sample_and_dimension(kind):
    """Every per-pixel sample is the hash of (seed, pixel, sample, dimension) alone, recomputed on
    the host: no draw depends on an earlier one."""
    with np.errstate(over="ignore"):
        count, pixels = 16, 40
        p = SamplePattern(kind, count, seed=-7, per_pixel=True)
        u = (device_sets(p, pixels, 8) + 1.0) / 2.0
        i, s = np.meshgrid(np.arange(pixels), np.arange(count), indexing="ij")
        a = counter_draw_np(-7, i, s, 0)
        b = counter_draw_np(-7, i, s, 1)
        want = np.stack([a, b], -1) if kind == "random" else np.stack([(s % 4 + a) / 4, (s // 4 + b) / 4], -1)
    assert np.allclose(u, want, atol=1e-6)


def test_per_pixel_lattice_shift_differs_per_pixel_and_draws_are_uniform():
    """Non-square counts: a rank-1 lattice shifted per pixel; the draws fill [0, 1) evenly."""
    p = SamplePattern("stratified", 10, seed=3, per_pixel=True)
    u = (device_sets(p, 64, 8) + 1.0) / 2.0
    assert len({np.round(g[0], 5).tobytes() for g in u}) == 64
    d = u - u[:, :1]
    assert np.allclose((d - d[0] + 0.5) % 1.0, 0.5, atol=1e-5)  # same lattice, shifted
    r = (device_sets(SamplePattern("random", 64, seed=5, per_pixel=True), 256, 16) + 1.0) / 2.0
    hist = np.histogram(r[..., 0], bins=16, range=(0, 1))[0]
    expected = r[..., 0].size / 16
    chi2 = float(((hist - expected) ** 2 / expected).sum())
    assert chi2 < 40.0  # 15 degrees of freedom: p < 0.001 beyond 37.7


def test_per_pixel_draws_of_consecutive_seeds_share_no_pixel():
    """A sequence reseeds per frame (seed + frame index): the seed is hashed before the pixel is
    added, so frame f + 1's sets are no shifted copy of frame f's."""
    a = device_sets(SamplePattern("random", 16, seed=4, per_pixel=True), 64, 8)
    b = device_sets(SamplePattern("random", 16, seed=5, per_pixel=True), 64, 8)
    flat_a = {np.round(s, 6).tobytes() for s in a}
    assert not flat_a & {np.round(s, 6).tobytes() for s in b}
