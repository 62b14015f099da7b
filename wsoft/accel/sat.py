"""Summed-area tables for pre-filtered soft shadows (ESSM, VSSM, moment soft shadow mapping): the
full float32 SAT, the full uint32 SAT, and the overflow-free uint32 *SAT tile grid* of Shen, Feng &
Yang (§6).

Layout: ``data[k, y, x]`` holds, for channel ``k``, the inclusive prefix sum over the texels
``[ty*T, y] x [tx*T, x]`` of the tile ``(tx, ty)`` holding ``(x, y)``; a full SAT is the grid
with one tile (``T = N``). Integer channels hold ``round(v * 2^mu)`` of a basis normalised to
[0, 1] and are summed with wrap-around (uint32) arithmetic: a box sum assembled from corner
differences is exact whenever the box's true sum is below 2^32, whatever the corners hold.

Builds (same result, counted passes):

* ``doubling`` — recursive doubling (Hensley et al. 2005): each pass reads ``X`` texels
  ``X^p`` apart, so a phase takes ``ceil(log_X T)`` passes; rows then columns.
* ``scan`` — one sequential scan per row of every tile, then per column (2 passes).

Tile size (§6.1): the mean pyramid of the basis is tested top-down; the first level ``L`` at
which every ``2^L x 2^L`` block sums (as integers) below 2^32 gives tiles of ``2^L`` texels.

Look-ups (:func:`sat_box`): the exact integral of the piecewise-constant texel function over a
box with fractional corners (the bilinear interpolation of the SAT), split along tile
boundaries. Corner differences are taken in the storage type before conversion to float64,
so uint32 wrap-around cancels and float32 cancellation shows as it would on a GPU.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from wsoft.params import check
from wsoft.parallel import launch_chunked

DIRECT_TEXELS = wp.constant(4.0)  # boxes up to this many texels per side are summed from the texels (direct_box), not the table

STORAGES = ("tiles", "uint32", "float32")
BUILDS = ("doubling", "scan")


# --------------------------------------------------------------------------- build kernels


@wp.kernel
def quantize_kernel(
    offset: int,
    src: wp.array3d[float],
    scale: float,
    n: int,
    # outputs
    dst: wp.array3d[wp.uint32],
):
    i = wp.tid() + offset
    k = i / (n * n)
    r = i - k * n * n
    y = r / n
    x = r - y * n
    v = wp.clamp(src[k, y, x], 0.0, 1.0)
    dst[k, y, x] = wp.uint32(v * scale + 0.5)


@wp.kernel
def doubling_rows(
    offset: int,
    src: wp.array3d(dtype=Any),
    n: int,
    tile: int,
    step: int,
    reads: int,
    # outputs
    dst: wp.array3d(dtype=Any),
):
    i = wp.tid() + offset
    k = i / (n * n)
    r = i - k * n * n
    y = r / n
    x = r - y * n
    x0 = (x / tile) * tile
    acc = src[k, y, x]
    for j in range(1, reads):
        xs = x - j * step
        if xs >= x0:
            acc = acc + src[k, y, xs]
    dst[k, y, x] = acc


@wp.kernel
def doubling_cols(
    offset: int,
    src: wp.array3d(dtype=Any),
    n: int,
    tile: int,
    step: int,
    reads: int,
    # outputs
    dst: wp.array3d(dtype=Any),
):
    i = wp.tid() + offset
    k = i / (n * n)
    r = i - k * n * n
    y = r / n
    x = r - y * n
    y0 = (y / tile) * tile
    acc = src[k, y, x]
    for j in range(1, reads):
        ys = y - j * step
        if ys >= y0:
            acc = acc + src[k, ys, x]
    dst[k, y, x] = acc


@wp.kernel
def scan_rows(
    offset: int,
    src: wp.array3d(dtype=Any),
    n: int,
    tile: int,
    # outputs
    dst: wp.array3d(dtype=Any),
):
    # one task per (channel, row, tile column)
    i = wp.tid() + offset
    per_row = n / tile
    k = i / (n * per_row)
    r = i - k * n * per_row
    y = r / per_row
    t = r - y * per_row
    x0 = t * tile
    acc = src[k, y, x0]
    dst[k, y, x0] = acc
    for x in range(x0 + 1, x0 + tile):
        acc = acc + src[k, y, x]
        dst[k, y, x] = acc


@wp.kernel
def scan_cols(
    offset: int,
    n: int,
    tile: int,
    # outputs
    dst: wp.array3d(dtype=Any),
):
    # in place, one task per (channel, column, tile row)
    i = wp.tid() + offset
    per_col = n / tile
    k = i / (n * per_col)
    r = i - k * n * per_col
    x = r / per_col
    t = r - x * per_col
    y0 = t * tile
    acc = dst[k, y0, x]
    for y in range(y0 + 1, y0 + tile):
        acc = acc + dst[k, y, x]
        dst[k, y, x] = acc


@wp.kernel
def mean_down(
    offset: int,
    src: wp.array3d[float],
    n_dst: int,
    # outputs
    dst: wp.array3d[float],
):
    i = wp.tid() + offset
    k = i / (n_dst * n_dst)
    r = i - k * n_dst * n_dst
    y = r / n_dst
    x = r - y * n_dst
    dst[k, y, x] = 0.25 * (src[k, 2 * y, 2 * x] + src[k, 2 * y, 2 * x + 1] + src[k, 2 * y + 1, 2 * x] + src[k, 2 * y + 1, 2 * x + 1])


# --------------------------------------------------------------------------- look-ups


@wp.func
def sat_corner(data: wp.array3d(dtype=Any), k: int, y0: int, x0: int, i: int, j: int):
    """Tile-local exclusive prefix F(i, j): the sum over texels [0, i) x [0, j) of the tile at (x0, y0)."""
    v = data[k, y0 + wp.max(j - 1, 0), x0 + wp.max(i - 1, 0)]
    if i == 0 or j == 0:
        v = v - v
    return v


@wp.func
def sat_box_ypair(data: wp.array3d(dtype=Any), k: int, y0: int, x0: int, i0a: int, i0b: int, i1a: int, i1b: int,
                  f0: float, f1: float, ja: int, jb: int) -> wp.float64:
    """Box integral between tile-local rows ``ja`` and ``jb`` (integers) and fractional columns
    u0 = i0a + f0, u1 = i1a + f1 (i0b = i0a + 1, i1b = i1a + 1, clamped)."""
    d0a = sat_corner(data, k, y0, x0, i0a, jb) - sat_corner(data, k, y0, x0, i0a, ja)
    if i1a == i0a:
        # both ends in one texel column: (u1 - u0) times that column (no negative-width combination,
        # which wrap-around arithmetic could not represent)
        d0n = sat_corner(data, k, y0, x0, i0b, jb) - sat_corner(data, k, y0, x0, i0b, ja)
        return wp.float64(f1 - f0) * wp.float64(d0n - d0a)
    d1a = sat_corner(data, k, y0, x0, i1a, jb) - sat_corner(data, k, y0, x0, i1a, ja)
    g0 = wp.float64(f0)
    g1 = wp.float64(f1)
    one = wp.float64(1.0)
    s = (one - g0) * (one - g1) * wp.float64(d1a - d0a)
    if f0 > 0.0:
        d0b = sat_corner(data, k, y0, x0, i0b, jb) - sat_corner(data, k, y0, x0, i0b, ja)
        s = s + g0 * (one - g1) * wp.float64(d1a - d0b)
        if f1 > 0.0:
            d1b = sat_corner(data, k, y0, x0, i1b, jb) - sat_corner(data, k, y0, x0, i1b, ja)
            s = s + g0 * g1 * wp.float64(d1b - d0b)
    if f1 > 0.0:
        d1b2 = sat_corner(data, k, y0, x0, i1b, jb) - sat_corner(data, k, y0, x0, i1b, ja)
        s = s + (one - g0) * g1 * wp.float64(d1b2 - d0a)
    return s


@wp.func
def sat_tile_box(data: wp.array3d(dtype=Any), k: int, y0: int, x0: int, t: int,
                 u0: float, u1: float, v0: float, v1: float) -> wp.float64:
    """Integral over the tile-local box [u0, u1] x [v0, v1] (0 <= u0 <= u1 <= t)."""
    i0 = int(wp.floor(u0))
    i1 = int(wp.floor(u1))
    j0 = int(wp.floor(v0))
    j1 = int(wp.floor(v1))
    f0 = u0 - float(i0)
    f1 = u1 - float(i1)
    g0 = v0 - float(j0)
    g1 = v1 - float(j1)
    i0b = wp.min(i0 + 1, t)
    i1b = wp.min(i1 + 1, t)
    j0b = wp.min(j0 + 1, t)
    j1b = wp.min(j1 + 1, t)
    if j1 == j0:
        return wp.float64(g1 - g0) * sat_box_ypair(data, k, y0, x0, i0, i0b, i1, i1b, f0, f1, j0, j0b)
    one = wp.float64(1.0)
    h0 = wp.float64(g0)
    h1 = wp.float64(g1)
    s = (one - h0) * (one - h1) * sat_box_ypair(data, k, y0, x0, i0, i0b, i1, i1b, f0, f1, j0, j1)
    if g0 > 0.0:
        s = s + h0 * (one - h1) * sat_box_ypair(data, k, y0, x0, i0, i0b, i1, i1b, f0, f1, j0b, j1)
        if g1 > 0.0:
            s = s + h0 * h1 * sat_box_ypair(data, k, y0, x0, i0, i0b, i1, i1b, f0, f1, j0b, j1b)
    if g1 > 0.0:
        s = s + (one - h0) * h1 * sat_box_ypair(data, k, y0, x0, i0, i0b, i1, i1b, f0, f1, j0, j1b)
    return s


@wp.func
def clip_to_map(n: int, u0: float, u1: float, v0: float, v1: float) -> wp.vec4:
    """The texel-space box [u0, u1] x [v0, v1] clipped to an ``n`` x ``n`` map: (u0, u1, v0, v1)."""
    return wp.vec4(wp.clamp(u0, 0.0, float(n)), wp.clamp(u1, 0.0, float(n)), wp.clamp(v0, 0.0, float(n)), wp.clamp(v1, 0.0, float(n)))


@wp.func
def sat_box(data: wp.array3d(dtype=Any), k: int, n: int, t: int, u0: float, u1: float, v0: float, v1: float) -> wp.float64:
    """Integral of channel ``k`` over the texel-space box [u0, u1] x [v0, v1] (texel i covers
    [i, i+1)), clipped to the map, in storage units (integer units for uint32 storage).
    ``n``: map size; ``t``: tile size (``n`` for a full SAT)."""
    c = clip_to_map(n, u0, u1, v0, v1)
    a0, a1, b0, b1 = c[0], c[1], c[2], c[3]
    s = wp.float64(0.0)
    if a1 <= a0 or b1 <= b0:
        return s
    tx0 = int(a0) / t
    tx1 = wp.min((int(wp.ceil(a1)) - 1) / t, n / t - 1)
    ty0 = int(b0) / t
    ty1 = wp.min((int(wp.ceil(b1)) - 1) / t, n / t - 1)
    ft = float(t)
    for ty in range(ty0, ty1 + 1):
        ly0 = wp.max(b0 - float(ty * t), 0.0)
        ly1 = wp.min(b1 - float(ty * t), ft)
        if ly1 > ly0:
            for tx in range(tx0, tx1 + 1):
                lx0 = wp.max(a0 - float(tx * t), 0.0)
                lx1 = wp.min(a1 - float(tx * t), ft)
                if lx1 > lx0:
                    s = s + sat_tile_box(data, k, ty * t, tx * t, t, lx0, lx1, ly0, ly1)
    return s


@wp.func
def direct_box(basis: wp.array3d[float], k: int, n: int, u0: float, u1: float, v0: float, v1: float) -> wp.float64:
    """Integral of channel ``k`` of the texels themselves (``basis``, shape ``[C, n, n]``) over the
    texel-space box [u0, u1] x [v0, v1] clipped to the map, each texel weighted by its overlap: what
    :func:`sat_box` gives, without a float32 table's rounding (four corner sums of up to n^2 values,
    each off by about 2^-24 of itself: on a box of a few texels that error is larger than a depth
    bias). For boxes of at most :data:`DIRECT_TEXELS` per side (its cost grows with the area)."""
    c = clip_to_map(n, u0, u1, v0, v1)
    a0, a1, b0, b1 = c[0], c[1], c[2], c[3]
    s = wp.float64(0.0)
    if a1 <= a0 or b1 <= b0:
        return s
    i0 = int(a0)
    i1 = wp.min(int(wp.ceil(a1)), n)
    j0 = int(b0)
    j1 = wp.min(int(wp.ceil(b1)), n)
    for j in range(j0, j1):
        wy = wp.min(b1, float(j + 1)) - wp.max(b0, float(j))
        for i in range(i0, i1):
            wx = wp.min(a1, float(i + 1)) - wp.max(a0, float(i))
            s = s + wp.float64(wx * wy) * wp.float64(basis[k, j, i])
    return s


@wp.func
def box_area(n: int, u0: float, u1: float, v0: float, v1: float) -> float:
    """Area of the box clipped to the map."""
    a = wp.min(u1, float(n)) - wp.max(u0, 0.0)
    b = wp.min(v1, float(n)) - wp.max(v0, 0.0)
    return wp.max(a, 0.0) * wp.max(b, 0.0)


for _t in (wp.uint32, wp.float32):
    _a = wp.array3d(dtype=_t)
    wp.overload(doubling_rows, {"src": _a, "dst": _a})
    wp.overload(doubling_cols, {"src": _a, "dst": _a})
    wp.overload(scan_rows, {"src": _a, "dst": _a})
    wp.overload(scan_cols, {"dst": _a})


def check_sat_params(p) -> None:
    """The parameters every SAT-filtered technique (essm, vssm, msm_soft) shares; raises ValueError."""
    n = p.shadow_map_size
    check(256 <= n <= 8192 and n & (n - 1) == 0, f"shadow_map_size {n} must be a power of two in [256, 8192]")
    check(p.sat in STORAGES, f"sat {p.sat!r} is not one of {', '.join(STORAGES)}")
    check(p.build in BUILDS, f"build {p.build!r} is not one of {', '.join(BUILDS)}")
    check(p.min_radius <= p.max_radius, "need min_radius <= max_radius")


# --------------------------------------------------------------------------- host side


@dataclass
class Moments:
    """A light map's depth moments as a SAT's basis ``[C, n, n]`` (``vssm``: z, z²; ``msm_soft``:
    four quantised moments), their mean pyramid (for the tile test; ``[basis]`` without tiles) and
    the effective depth range [zmin, zmax] they were normalised over."""

    basis: wp.array
    pyramid: list
    zmin: float
    zmax: float

    def arrays(self) -> dict[str, wp.array]:
        return {"moments": self.basis}


@dataclass
class SAT:
    """A built SAT (full or tile grid) of ``channels`` channels over an ``n x n`` map."""

    data: wp.array  # [channels, n, n] uint32 or float32
    storage: str
    n: int
    tile: int
    mu: int
    build: str
    reads: int
    passes: int
    build_ms: float
    tile_test: dict

    @property
    def tiles_per_side(self) -> int:
        return self.n // self.tile

    @property
    def unit(self) -> float:
        """Value of one stored unit in basis units (2^-mu for integers, 1 for float32)."""
        return 1.0 if self.storage == "float32" else 2.0 ** -self.mu

    def memory_bytes(self) -> int:
        return int(self.data.size * 4)

    def arrays(self) -> dict[str, wp.array]:
        return {"sat": self.data}


def doubling_passes(tile: int, reads: int) -> int:
    """Passes of one recursive-doubling phase: ceil(log_X T) (0 for a single texel)."""
    if tile <= 1:
        return 0
    p, span = 0, 1
    while span < tile:
        span *= reads
        p += 1
    return p


def mean_pyramid(basis: wp.array, device: str) -> list[wp.array]:
    """Levels 0..log2(n) of the per-channel mean pyramid of ``basis`` [k, n, n] (level 0 is ``basis``)."""
    levels = [basis]
    k, n = basis.shape[0], basis.shape[1]
    while n > 1:
        n //= 2
        dst = wp.empty((k, n, n), dtype=float, device=device)
        launch_chunked(mean_down, k * n * n, inputs=[levels[-1], n], outputs=[dst], device=device, min_chunk=4096)
        levels.append(dst)
    return levels


def tile_from_pyramid(levels: list[wp.array], mu: int) -> tuple[int, dict]:
    """§6.1: top-down, the first level whose every texel passes the overflow test gives the tile size.
    Level L passes when each 2^L x 2^L block, stored as round(v 2^mu) per texel, sums below 2^32."""
    tried = []
    for lv in range(len(levels) - 1, 0, -1):
        m = float(levels[lv].numpy().max())
        area = 4.0 ** lv
        bound = (2.0 ** 32 - 0.5 * area - 1.0) / (area * 2.0 ** mu)
        ok = m < bound
        tried.append({"level": lv, "max_mean": m, "threshold": bound, "passes": bool(ok)})
        if ok:
            return 2 ** lv, {"levels_tested": tried}
    return 1, {"levels_tested": tried}


def build_sat(basis: wp.array, *, storage: str, mu: int = 20, build: str = "doubling", reads: int = 8,
              tile: int | None = None, device: str = "cpu", pyramid: list[wp.array] | None = None) -> SAT:
    """Build a SAT of ``basis`` ([k, n, n] float32, values in [0, 1] for integer storage).

    ``storage``: ``tiles`` (uint32 tile grid, tile size from the pyramid test unless ``tile`` is
    given), ``uint32`` (one full integer SAT) or ``float32`` (one full float SAT).
    """
    if storage not in STORAGES:
        raise ValueError(f"storage {storage!r} is not one of {', '.join(STORAGES)}")
    if build not in BUILDS:
        raise ValueError(f"build {build!r} is not one of {', '.join(BUILDS)}")
    k, n = basis.shape[0], basis.shape[1]
    if basis.shape[2] != n or n & (n - 1):
        raise ValueError(f"SATs need a square power-of-two map, not {basis.shape[1]}x{basis.shape[2]}")
    t0 = time.perf_counter()
    test: dict = {}
    if storage == "tiles":
        if tile is None:
            levels = pyramid if pyramid is not None else mean_pyramid(basis, device)
            tile, test = tile_from_pyramid(levels, mu)
    else:
        tile = n
    if tile < 1 or tile > n or tile & (tile - 1):
        raise ValueError(f"tile size {tile} must be a power of two in [1, {n}]")
    if storage == "float32":
        src = wp.clone(basis)
        dtype = float
    else:
        src = wp.empty((k, n, n), dtype=wp.uint32, device=device)
        launch_chunked(quantize_kernel, k * n * n, inputs=[basis, float(2.0 ** mu), n], outputs=[src], device=device, min_chunk=4096)
        dtype = wp.uint32
    passes = 0
    if build == "scan":
        dst = wp.empty((k, n, n), dtype=dtype, device=device)
        per = n // tile
        if tile > 1:
            launch_chunked(scan_rows, k * n * per, inputs=[src, n, tile], outputs=[dst], device=device, min_chunk=8)
            launch_chunked(scan_cols, k * n * per, inputs=[n, tile], outputs=[dst], device=device, min_chunk=8)
            passes = 2
        else:
            wp.copy(dst, src)
        out = dst
    else:
        other = wp.empty((k, n, n), dtype=dtype, device=device)
        a, b = src, other
        p = doubling_passes(tile, reads)
        for kern in (doubling_rows, doubling_cols):
            step = 1
            for _ in range(p):
                launch_chunked(kern, k * n * n, inputs=[a, n, tile, step, reads], outputs=[b], device=device, min_chunk=4096)
                a, b = b, a
                step *= reads
                passes += 1
        out = a
        del b
    wp.synchronize_device(device)
    ms = 1e3 * (time.perf_counter() - t0)
    return SAT(out, storage, n, tile, mu, build, reads, passes, ms, test)


def reference_box_sums(basis: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """float64 integrals of channel-0 ``basis`` [n, n] over fractional boxes (u0, u1, v0, v1) rows
    (texel i covers [i, i+1)): the exact answer :func:`sat_box` approximates. For tests."""
    n = basis.shape[0]
    f = np.zeros((n + 1, n + 1), np.float64)
    f[1:, 1:] = np.cumsum(np.cumsum(basis.astype(np.float64), 0), 1)

    def F(u, v):
        u = np.clip(u, 0, n)
        v = np.clip(v, 0, n)
        i = np.minimum(np.floor(u).astype(int), n - 1)
        j = np.minimum(np.floor(v).astype(int), n - 1)
        a = u - i
        b = v - j
        return (f[j, i] * (1 - a) * (1 - b) + f[j, i + 1] * a * (1 - b) + f[j + 1, i] * (1 - a) * b + f[j + 1, i + 1] * a * b)

    u0, u1, v0, v1 = boxes.T
    return F(u1, v1) - F(u0, v1) - F(u1, v0) + F(u0, v0)


@wp.kernel
def lookup_kernel(
    offset: int,
    data: wp.array3d(dtype=Any),
    k: int,
    n: int,
    t: int,
    boxes: wp.array[wp.vec4],
    # outputs
    out: wp.array[wp.float64],
):
    i = wp.tid() + offset
    b = boxes[i]
    out[i] = sat_box(data, k, n, t, b[0], b[1], b[2], b[3])


def box_sums(sat: SAT, boxes: np.ndarray, channel: int = 0, device: str = "cpu") -> np.ndarray:
    """Box integrals (in basis units) of a channel over (u0, u1, v0, v1) rows, via :func:`sat_box`."""
    b = wp.array(np.asarray(boxes, np.float32), dtype=wp.vec4, device=device)
    out = wp.empty(len(boxes), dtype=wp.float64, device=device)
    launch_chunked(lookup_kernel, len(boxes), inputs=[sat.data, channel, sat.n, sat.tile, b], outputs=[out], device=device, min_chunk=256)
    return out.numpy() * sat.unit


for _t in (wp.uint32, wp.float32):
    wp.overload(lookup_kernel, {"data": wp.array3d(dtype=_t)})
