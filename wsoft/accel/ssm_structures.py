"""Search-area pruning structures of soft shadow mapping, and microrects.

All three answer "depth range (min, max) of the level-0 texels in a rectangle" for a square,
power-of-two shadow map of ``N`` texels per side (empty texels hold ``DEPTH_CLEAR``):

* **HSM** (hierarchical shadow map, Guennebaud et al. 2006): a min/max pyramid, levels
  ``k = 0..log2 N`` of ``N >> k`` texels per side, stored flat (``pyr``, offsets ``pyr_off``).
  A query reads at most 2 x 2 texels of the finest level at which the rectangle spans at most
  two texels per axis: conservative (the range of a superset).
* **MSSM** (multi-scale shadow map, Schwarz & Stamminger 2007): for every texel ``(x, y)`` and
  scale ``s = 0..log2 N`` the range of the ``2^s x 2^s`` neighbourhood ``[x, x + 2^s) x [y, y + 2^s)``
  (clipped to the map). A query tiles the rectangle with at most 16 such squares: exact.
* **YSM** (Y shadow map, Schwarz & Stamminger 2008, §6): the full HSM plus an MSSM built from
  HSM level ``n - 1`` (``ysm_size`` texels per side, 256 by default; its scale 0 is that HSM
  level and is not stored again). Rectangles narrow enough for HSM levels below ``n - 1`` are
  answered by the HSM, wider ones exactly on the ``ysm_size`` grid by the MSSM part.

**Microrects** (§5) generalise micropatches: the level-``i`` microrect of texel ``(a, b)`` has
the reference point ``(a 2^i, b 2^i)`` (a level-0 texel), an integer extent in level-0 texels
that contains it and no other level-``i`` reference point, and the minimum depth of what it
covers. Level ``i + 1`` is derived from level ``i`` by the greedy two-pass merge: each retained
microrect (even ``a, b``) first merges its neighbours in +x and +y when their depth is closer
to it than to the next retained one (the last ones of a row always), then the diagonal one if
the merged extent contains it (always at the map's edge); in the second pass it merges the
neighbours in -x, -y and the diagonal that no one took in the first. With ``diagonal="nearest"``
(not the paper's) a diagonal that the first pass leaves goes to the retained neighbour of nearest
depth. Extents (``wp.vec4i``: x0, y0, x1, y1 inclusive) and depths are two textures with full mip
chains, flat like ``pyr``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.pyramid import build_minmax_pyramid, level_offsets, log2_exact, merge_range, pyramid_base
from wsoft.lightspace.view import DEPTH_CLEAR
from wsoft.parallel import launch_chunked

MODE_HSM = 0
MODE_MSSM = 1
MODE_YSM = 2
MODES = {"hsm": MODE_HSM, "mssm": MODE_MSSM, "ysm": MODE_YSM}
MAX_TILES = wp.constant(16)  # MSSM squares a query may read before it coarsens its scale


@wp.struct
class DepthRanges:
    """A pruning structure on the device (see the module docstring).

    ``pyr``: flat vec2 (min, max) of every HSM level, level ``k`` at ``pyr_off[k]``, row-major,
    ``size >> k`` per side; ``top``: the last level (``log2 size``). ``mssm``: flat vec2, scale
    ``s`` at ``(s - mssm_first) * mssm_m * mssm_m``, over a grid of ``mssm_m`` per side whose
    scale 0 is HSM level ``mssm_base``; ``mssm_top``: its largest scale.
    """

    mode: int
    size: int
    top: int
    pyr: wp.array[wp.vec2]
    pyr_off: wp.array[wp.int32]
    mssm: wp.array[wp.vec2]
    mssm_m: int
    mssm_base: int
    mssm_first: int
    mssm_top: int


@wp.func
def pyr_at(acc: DepthRanges, k: int, x: int, y: int) -> wp.vec2:
    """HSM level ``k`` texel (x, y)."""
    n = acc.size >> k
    return acc.pyr[acc.pyr_off[k] + y * n + x]


@wp.func
def mssm_at(acc: DepthRanges, s: int, x: int, y: int) -> wp.vec2:
    """Range of the 2^s neighbourhood of MSSM-grid texel (x, y)."""
    if s < acc.mssm_first:
        return pyr_at(acc, acc.mssm_base, x, y)
    m = acc.mssm_m
    return acc.mssm[(s - acc.mssm_first) * m * m + y * m + x]


@wp.func
def ilog2_floor(v: int) -> int:
    k = int(0)
    while (1 << (k + 1)) <= v:
        k += 1
    return k


@wp.func
def hsm_range(acc: DepthRanges, x0: int, y0: int, x1: int, y1: int) -> wp.vec2:
    """Conservative range over level-0 texels [x0, x1] x [y0, y1] (inclusive, inside the map)."""
    k = int(0)
    while k < acc.top and ((x1 >> k) - (x0 >> k) > 1 or (y1 >> k) - (y0 >> k) > 1):
        k += 1
    r = wp.vec2(DEPTH_CLEAR, -DEPTH_CLEAR)
    for y in range(y0 >> k, (y1 >> k) + 1):
        for x in range(x0 >> k, (x1 >> k) + 1):
            r = merge_range(r, pyr_at(acc, k, x, y))
    return r


@wp.func
def tile_starts(lo: int, hi: int, t: int, i: int) -> int:
    """Start of the i-th of the squares of side ``t`` tiling [lo, hi]: the last one ends at hi."""
    return wp.max(lo, wp.min(lo + i * t, hi - t + 1))


@wp.func
def mssm_range(acc: DepthRanges, x0: int, y0: int, x1: int, y1: int) -> wp.vec2:
    """Range over MSSM-grid texels [x0, x1] x [y0, y1]: exact while at most MAX_TILES squares
    tile it (otherwise the scale grows and the squares overhang: conservative)."""
    lx = x1 - x0 + 1
    ly = y1 - y0 + 1
    s = wp.min(ilog2_floor(wp.min(lx, ly)), acc.mssm_top)
    t = 1 << s
    nx = (lx + t - 1) // t
    ny = (ly + t - 1) // t
    while nx * ny > MAX_TILES and s < acc.mssm_top:
        s += 1
        t = 1 << s
        nx = (lx + t - 1) // t
        ny = (ly + t - 1) // t
    r = wp.vec2(DEPTH_CLEAR, -DEPTH_CLEAR)
    for j in range(ny):
        ty = tile_starts(y0, y1, t, j)
        for i in range(nx):
            tx = tile_starts(x0, x1, t, i)
            r = merge_range(r, mssm_at(acc, s, tx, ty))
    return r


@wp.func
def depth_range(acc: DepthRanges, x0: int, y0: int, x1: int, y1: int) -> wp.vec2:
    """(min, max) depth over level-0 texels [x0, x1] x [y0, y1], clipped to the map; an empty
    rectangle gives (DEPTH_CLEAR, -DEPTH_CLEAR)."""
    n = acc.size
    ax = wp.max(x0, 0)
    ay = wp.max(y0, 0)
    bx = wp.min(x1, n - 1)
    by = wp.min(y1, n - 1)
    if ax > bx or ay > by:
        return wp.vec2(DEPTH_CLEAR, -DEPTH_CLEAR)
    if acc.mode == 1:
        return mssm_range(acc, ax, ay, bx, by)
    if acc.mode == 2:
        b = acc.mssm_base
        k = int(0)
        while k < acc.top and ((bx >> k) - (ax >> k) > 1 or (by >> k) - (ay >> k) > 1):
            k += 1
        if k < b:
            return hsm_range(acc, ax, ay, bx, by)
        return mssm_range(acc, ax >> b, ay >> b, bx >> b, by >> b)
    return hsm_range(acc, ax, ay, bx, by)


# -- construction ---------------------------------------------------------------------------


@wp.kernel
def mssm_scale(
    offset: int,
    src: wp.array[wp.vec2],
    src_off: int,
    m: int,
    h: int,
    dst_off: int,
    # outputs
    dst: wp.array[wp.vec2],
):
    """Scale s from scale s - 1 (h = 2^(s-1)): the four half-size squares that tile the square."""
    i = wp.tid() + offset
    y = i // m
    x = i - y * m
    r = src[src_off + i]
    if x + h < m:
        r = merge_range(r, src[src_off + i + h])
    if y + h < m:
        r = merge_range(r, src[src_off + i + h * m])
        if x + h < m:
            r = merge_range(r, src[src_off + i + h * m + h])
    dst[dst_off + i] = r


@wp.kernel
def mssm_copy(
    offset: int,
    src: wp.array[wp.vec2],
    src_off: int,
    # outputs
    dst: wp.array[wp.vec2],
):
    i = wp.tid() + offset
    dst[i] = src[src_off + i]


@dataclass
class PruningStructure:
    """A built HSM, MSSM or YSM: the device struct and its arrays (``arrays()`` for memory stats)."""

    kind: str
    size: int
    gpu: DepthRanges
    pyr: wp.array
    pyr_off: wp.array
    mssm: wp.array
    build_ms: float
    ysm_size: int = 0

    def arrays(self) -> dict[str, wp.array]:
        out = {}
        if self.kind in ("hsm", "ysm"):
            out["hsm"] = self.pyr
        if self.kind in ("mssm", "ysm"):
            out["mssm"] = self.mssm
        return out

    def memory_bytes(self) -> int:
        return sum(int(a.size) * 8 for a in self.arrays().values())


def build_mssm(src: wp.array, src_off: int, m: int, first: int, device: str) -> wp.array:
    """Scales ``first..log2 m`` of the MSSM over an ``m``-square vec2 map (at ``src[src_off:]``)."""
    top = log2_exact(m)
    nlev = top + 1 - first
    out = wp.empty(max(nlev, 1) * m * m, dtype=wp.vec2, device=device)
    if nlev <= 0:
        return out
    if first == 0:
        launch_chunked(mssm_copy, m * m, inputs=[src, src_off], outputs=[out], device=device)
        prev, prev_off, s = out, 0, 1
    else:
        prev, prev_off, s = src, src_off, 1
    while s <= top:
        dst_off = (s - first) * m * m
        launch_chunked(mssm_scale, m * m, inputs=[prev, prev_off, m, 1 << (s - 1), dst_off], outputs=[out], device=device)
        prev, prev_off = out, dst_off
        s += 1
    return out


def build_structure(kind: str, depth: wp.array, device: str, ysm_size: int = 256, pyramid=None) -> PruningStructure:
    """Build ``kind`` (hsm, mssm or ysm) over ``depth`` (``[N, N]`` float32, N a power of two).

    ``pyramid``: an HSM already built over the same map (reused by the YSM; the MSSM ignores it).
    ``build_ms`` is the wall time of the build (device synchronised)."""
    if kind not in MODES:
        raise ValueError(f"unknown pruning structure {kind!r}")
    n = depth.shape[1]
    if depth.shape[0] != n:
        raise ValueError("the map must be square")
    top = log2_exact(n)
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    g = DepthRanges()
    g.mode = MODES[kind]
    g.size = n
    g.top = top
    if kind == "mssm":
        base = wp.empty(n * n, dtype=wp.vec2, device=device)
        launch_chunked(pyramid_base, n * n, inputs=[depth, 0], outputs=[base], device=device)
        mssm = build_mssm(base, 0, n, 0, device)
        pyr, offs = base, np.asarray([0, n * n], np.int32)
        g.mssm_m, g.mssm_base, g.mssm_first, g.mssm_top = n, 0, 0, top
    else:
        pyr, offs = pyramid if pyramid is not None else build_minmax_pyramid(depth, device, skip_empty=False)
        if kind == "ysm":
            m = min(ysm_size, n)
            b = log2_exact(n // m)
            mssm = build_mssm(pyr, int(offs[b]), m, 1, device)
            g.mssm_m, g.mssm_base, g.mssm_first, g.mssm_top = m, b, 1, log2_exact(m)
        else:
            mssm = wp.empty(1, dtype=wp.vec2, device=device)
            g.mssm_m, g.mssm_base, g.mssm_first, g.mssm_top = 1, 0, 1, 0
    wp.synchronize_device(device)
    ms = 1e3 * (time.perf_counter() - t0)
    off_arr = wp.array(offs, dtype=wp.int32, device=device)
    g.pyr = pyr
    g.pyr_off = off_arr
    g.mssm = mssm
    return PruningStructure(kind, n, g, pyr, off_arr, mssm, ms, ysm_size if kind == "ysm" else 0)


# -- microrects -------------------------------------------------------------------------------


@wp.func
def rect_union(a: wp.vec4i, b: wp.vec4i) -> wp.vec4i:
    return wp.vec4i(wp.min(a[0], b[0]), wp.min(a[1], b[1]), wp.max(a[2], b[2]), wp.max(a[3], b[3]))


@wp.func
def rect_contains(a: wp.vec4i, b: wp.vec4i) -> bool:
    return a[0] <= b[0] and a[1] <= b[1] and a[2] >= b[2] and a[3] >= b[3]


@wp.func
def closer_to_first(d: float, d_first: float, d_second: float, tie: float) -> bool:
    """Is depth ``d`` at least as close to ``d_first`` as to ``d_second`` (merge partner choice)?
    Differences within ``tie`` (relative to ``|d|``) count as equal: the rounding of a flat
    occluder's rasterized depth then does not decide, and a tie goes to ``d_first``."""
    return wp.abs(d - d_first) <= wp.abs(d - d_second) + tie * wp.abs(d)


@wp.func
def first_pass(ext: wp.array[wp.vec4i], dep: wp.array[float], off: int, n: int, a: int, b: int, tie: float) -> wp.vec4i:
    """Extent after the first pass of the retained level-i microrect (a, b) (a, b even); the
    merged depth is recomputed by :func:`first_pass_depth`."""
    e = ext[off + b * n + a]
    d = dep[off + b * n + a]
    if a + 1 < n:
        db = dep[off + b * n + a + 1]
        if a + 2 >= n or closer_to_first(db, d, dep[off + b * n + a + 2], tie):
            e = rect_union(e, ext[off + b * n + a + 1])
    if b + 1 < n:
        dd = dep[off + (b + 1) * n + a]
        if b + 2 >= n or closer_to_first(dd, d, dep[off + (b + 2) * n + a], tie):
            e = rect_union(e, ext[off + (b + 1) * n + a])
    return e


@wp.func
def takes_diagonal(ext: wp.array[wp.vec4i], off: int, n: int, a: int, b: int, e1: wp.vec4i) -> bool:
    """Does the retained microrect (a, b), with first-pass extent ``e1``, take its +x+y diagonal?"""
    if a + 1 >= n or b + 1 >= n:
        return False
    if a + 2 >= n or b + 2 >= n:
        return True  # nobody else can take it
    return rect_contains(e1, ext[off + (b + 1) * n + a + 1])


@wp.func
def diagonal_owner(ext: wp.array[wp.vec4i], dep: wp.array[float], off: int, n: int, dx: int, dy: int, nearest: int, tie: float) -> wp.vec2i:
    """The retained level-i microrect that takes the diagonal microrect ``(dx, dy)`` (both odd).

    §5.2: the one at ``(dx - 1, dy - 1)`` when its first-pass extent contains it, else the one at
    ``(dx + 1, dy + 1)`` in the second pass, whatever the depths. With ``nearest`` (not the
    paper's), the second choice is the one of its (up to four) retained neighbours whose own depth
    is nearest to it, ties in the paper's order: a ground microrect then does not take a caster's
    diagonal (and its minimum depth) across an edge."""
    a = dx - 1
    b = dy - 1
    if takes_diagonal(ext, off, n, a, b, first_pass(ext, dep, off, n, a, b, tie)):
        return wp.vec2i(a, b)
    if nearest == 0:
        return wp.vec2i(dx + 1, dy + 1)
    d = dep[off + dy * n + dx]
    best = wp.vec2i(dx + 1, dy + 1)
    bd = wp.abs(d - dep[off + (dy + 1) * n + dx + 1])
    c = wp.abs(d - dep[off + (dy - 1) * n + dx + 1])
    if c < bd:
        best = wp.vec2i(dx + 1, dy - 1)
        bd = c
    c = wp.abs(d - dep[off + (dy + 1) * n + dx - 1])
    if c < bd:
        best = wp.vec2i(dx - 1, dy + 1)
        bd = c
    c = wp.abs(d - dep[off + b * n + a])
    if c < bd:
        best = wp.vec2i(a, b)
    return best


@wp.kernel
def microrect_level(
    offset: int,
    off: int,
    n: int,
    dst_off: int,
    nearest: int,
    tie: float,
    # outputs
    ext: wp.array[wp.vec4i],
    dep: wp.array[float],
):
    """Level-(i+1) microrects (n/2 per side) from level i (n per side, at ``off``)."""
    i = wp.tid() + offset
    h = n // 2
    yy = i // h
    xx = i - yy * h
    a = 2 * xx
    b = 2 * yy
    d0 = dep[off + b * n + a]
    d = d0
    # first pass: +x, +y (the diagonals are settled below, by diagonal_owner)
    e = ext[off + b * n + a]
    if a + 1 < n:
        db = dep[off + b * n + a + 1]
        if a + 2 >= n or closer_to_first(db, d0, dep[off + b * n + a + 2], tie):
            e = rect_union(e, ext[off + b * n + a + 1])
            d = wp.min(d, db)
    if b + 1 < n:
        dd = dep[off + (b + 1) * n + a]
        if b + 2 >= n or closer_to_first(dd, d0, dep[off + (b + 2) * n + a], tie):
            e = rect_union(e, ext[off + (b + 1) * n + a])
            d = wp.min(d, dd)
    # second pass: -x, -y that no one took in the first
    if a >= 2:
        dl = dep[off + b * n + a - 1]
        if not closer_to_first(dl, dep[off + b * n + a - 2], d0, tie):
            e = rect_union(e, ext[off + b * n + a - 1])
            d = wp.min(d, dl)
    if b >= 2:
        dl = dep[off + (b - 1) * n + a]
        if not closer_to_first(dl, dep[off + (b - 2) * n + a], d0, tie):
            e = rect_union(e, ext[off + (b - 1) * n + a])
            d = wp.min(d, dl)
    # the diagonals this one owns (the paper's rule: +x+y when contained, -x-y when its owner
    # did not take it; with ``nearest`` any of the four by depth)
    for sy in range(2):
        for sx in range(2):
            dx = a - 1 + 2 * sx
            dy = b - 1 + 2 * sy
            if dx < 0 or dy < 0 or dx >= n or dy >= n:
                continue
            o = diagonal_owner(ext, dep, off, n, dx, dy, nearest, tie)
            if o[0] == a and o[1] == b:
                e = rect_union(e, ext[off + dy * n + dx])
                d = wp.min(d, dep[off + dy * n + dx])
    ext[dst_off + i] = e
    dep[dst_off + i] = d


@wp.kernel
def microrect_base(
    offset: int,
    depth: wp.array2d[float],
    # outputs
    ext: wp.array[wp.vec4i],
    dep: wp.array[float],
):
    i = wp.tid() + offset
    n = depth.shape[1]
    y = i // n
    x = i - y * n
    ext[i] = wp.vec4i(x, y, x, y)
    dep[i] = depth[y, x]


@dataclass
class MicroRects:
    """Microrect extents (flat ``wp.vec4i``, level-0 texels, inclusive) and depths (flat float32),
    full mip chains laid out like the HSM (offsets ``off``)."""

    size: int
    ext: wp.array
    dep: wp.array
    off: np.ndarray
    build_ms: float

    def arrays(self) -> dict[str, wp.array]:
        return {"microrect_extent": self.ext, "microrect_depth": self.dep}

    def level(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Level ``i`` as numpy: extents [n, n, 4] and depths [n, n] (row = y)."""
        n = self.size >> i
        a, b = int(self.off[i]), int(self.off[i + 1])
        return self.ext.numpy()[a:b].reshape(n, n, 4), self.dep.numpy()[a:b].reshape(n, n)


def build_microrects(depth: wp.array, device: str, diagonal: str = "paper", tie: float = 1e-6) -> MicroRects:
    """Microrects of every level from the level-0 depth map; ``diagonal`` picks who takes a
    diagonal neighbour in the second pass (:func:`diagonal_owner`): ``paper`` or ``nearest``;
    ``tie``: relative depth difference within which two merge partners are equally near
    (:func:`closer_to_first`; 0: exact comparison)."""
    if diagonal not in ("paper", "nearest"):
        raise ValueError(f"diagonal {diagonal!r} is not paper or nearest")
    if not 0.0 <= tie < 1.0:
        raise ValueError(f"tie {tie} is not in [0, 1)")
    n = depth.shape[1]
    log2_exact(n)
    offs = level_offsets(n)
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    ext = wp.empty(int(offs[-1]), dtype=wp.vec4i, device=device)
    dep = wp.empty(int(offs[-1]), dtype=float, device=device)
    launch_chunked(microrect_base, n * n, inputs=[depth], outputs=[ext, dep], device=device)
    k, m = 0, n
    while m >= 2:
        launch_chunked(microrect_level, (m // 2) ** 2, inputs=[int(offs[k]), m, int(offs[k + 1]), int(diagonal == "nearest"), float(tie)], outputs=[ext, dep], device=device)
        k += 1
        m //= 2
    wp.synchronize_device(device)
    return MicroRects(n, ext, dep, offs, 1e3 * (time.perf_counter() - t0))


@wp.kernel
def query_ranges(
    offset: int,
    acc: DepthRanges,
    rects: wp.array[wp.vec4i],
    # outputs
    out: wp.array[wp.vec2],
):
    """(min, max) of each rectangle (x0, y0, x1, y1 inclusive, level-0 texels): for tests and tools."""
    i = wp.tid() + offset
    r = rects[i]
    out[i] = depth_range(acc, r[0], r[1], r[2], r[3])


def query(structure: PruningStructure, rects: np.ndarray, device: str) -> np.ndarray:
    """Depth ranges [R, 2] of rectangles [R, 4] (x0, y0, x1, y1 inclusive) on the host."""
    r = wp.array(np.asarray(rects, np.int32).reshape(-1, 4), dtype=wp.vec4i, device=device)
    out = wp.empty(r.shape[0], dtype=wp.vec2, device=device)
    launch_chunked(query_ranges, r.shape[0], inputs=[structure.gpu, r], outputs=[out], device=device)
    return out.numpy()
