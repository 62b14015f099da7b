"""The min/max depth pyramid of a square power-of-two depth map (a hierarchical shadow map), and
the effective depth range techniques normalise depth over.

Levels ``k = 0..log2 N`` of ``N >> k`` texels per side, each texel the (min, max) of the 2 x 2
texels below, stored flat (vec2) with the level offsets of :func:`level_offsets`. Empty texels
(``DEPTH_CLEAR``) follow one of two conventions, chosen by the caller:

* ``skip_empty = False`` — an empty texel is a surface at ``DEPTH_CLEAR``: a range whose max is
  ``DEPTH_CLEAR`` holds a texel through which the light passes (backprojection's umbra test
  needs this);
* ``skip_empty = True`` — empty texels are ignored: the top level is the range of the covered
  texels, ``(DEPTH_CLEAR, -DEPTH_CLEAR)`` if there are none (the depth range of a map).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import warp as wp

from wsoft.lightspace.view import DEPTH_CLEAR
from wsoft.parallel import launch_chunked


@wp.func
def merge_range(a: wp.vec2, b: wp.vec2) -> wp.vec2:
    return wp.vec2(wp.min(a[0], b[0]), wp.max(a[1], b[1]))


@wp.func
def texels_below(pyr: wp.array(dtype=Any), src_off: int, n: int, i: int):
    """The 2 x 2 texels of the level below (2n per side, at ``src_off``) under texel ``i`` of a level of ``n`` per side."""
    y = i // n
    x = i - y * n
    m = 2 * n
    return (pyr[src_off + (2 * y) * m + 2 * x], pyr[src_off + (2 * y) * m + 2 * x + 1],
            pyr[src_off + (2 * y + 1) * m + 2 * x], pyr[src_off + (2 * y + 1) * m + 2 * x + 1])


@wp.kernel
def pyramid_base(
    offset: int,
    depth: wp.array2d[float],
    skip_empty: int,
    # outputs
    pyr: wp.array[wp.vec2],
):
    i = wp.tid() + offset
    n = depth.shape[1]
    y = i // n
    x = i - y * n
    d = depth[y, x]
    if skip_empty != 0 and d >= DEPTH_CLEAR:
        pyr[i] = wp.vec2(DEPTH_CLEAR, -DEPTH_CLEAR)
    else:
        pyr[i] = wp.vec2(d, d)


@wp.kernel
def pyramid_level(
    offset: int,
    src_off: int,
    dst_off: int,
    n: int,
    # outputs
    pyr: wp.array[wp.vec2],
):
    """Level of ``n`` per side from the level below (2n per side)."""
    i = wp.tid() + offset
    a, b, c, d = texels_below(pyr, src_off, n, i)
    pyr[dst_off + i] = merge_range(merge_range(a, b), merge_range(c, d))


@wp.kernel
def pyramid_base_bounds(
    offset: int,
    near0: wp.array2d[float],
    near1: wp.array2d[float],
    near2: wp.array2d[float],
    far: wp.array2d[float],
    # outputs
    pyr: wp.array[wp.vec4],
):
    i = wp.tid() + offset
    n = near0.shape[1]
    y = i // n
    x = i - y * n
    pyr[i] = wp.vec4(near0[y, x], near1[y, x], near2[y, x], far[y, x])


@wp.kernel
def pyramid_level_bounds(
    offset: int,
    src_off: int,
    dst_off: int,
    n: int,
    # outputs
    pyr: wp.array[wp.vec4],
):
    """Level of ``n`` per side from the level below: min, min, min, max of the 2 x 2 texels."""
    i = wp.tid() + offset
    a, b, c, d = texels_below(pyr, src_off, n, i)
    lo = wp.min(wp.min(a, b), wp.min(c, d))
    hi = wp.max(wp.max(a, b), wp.max(c, d))
    pyr[dst_off + i] = wp.vec4(lo[0], lo[1], lo[2], hi[3])


def log2_exact(n: int) -> int:
    k = int(round(math.log2(n))) if n > 0 else -1
    if k < 0 or 1 << k != n:
        raise ValueError(f"map size {n} is not a power of two")
    return k


def level_offsets(size: int) -> np.ndarray:
    """Flat offsets of the levels of a full mip chain of a ``size``-square map (and the total)."""
    offs = [0]
    n = size
    while n >= 1:
        offs.append(offs[-1] + n * n)
        n //= 2
    return np.asarray(offs, np.int32)


def build_minmax_pyramid(depth: wp.array, device: str, *, skip_empty: bool) -> tuple[wp.array, np.ndarray]:
    """The min/max pyramid of a square power-of-two ``[N, N]`` depth map: (flat vec2 levels, offsets)."""
    n = depth.shape[1]
    if depth.shape[0] != n:
        raise ValueError("the map must be square")
    log2_exact(n)
    offs = level_offsets(n)
    pyr = wp.empty(int(offs[-1]), dtype=wp.vec2, device=device)
    launch_chunked(pyramid_base, n * n, inputs=[depth, int(skip_empty)], outputs=[pyr], device=device)
    _build_levels(pyramid_level, pyr, offs, n, device)
    return pyr, offs


def build_bounds_pyramid(near: list, far: wp.array, device: str) -> tuple[wp.array, np.ndarray]:
    """One pyramid of four square power-of-two maps of one view: per texel of every level (vec4),
    the min of each of the three ``near`` maps and the max of ``far`` over the texels below (empty
    texels are ``DEPTH_CLEAR`` surfaces, as ``skip_empty = False``)."""
    n = far.shape[1]
    if far.shape[0] != n or any(m.shape != far.shape for m in near) or len(near) != 3:
        raise ValueError("three near maps and a far map, square and of one size")
    log2_exact(n)
    offs = level_offsets(n)
    pyr = wp.empty(int(offs[-1]), dtype=wp.vec4, device=device)
    launch_chunked(pyramid_base_bounds, n * n, inputs=[*near, far], outputs=[pyr], device=device, min_chunk=1 << 14)
    _build_levels(pyramid_level_bounds, pyr, offs, n, device)
    return pyr, offs


def _build_levels(level_kernel, pyr: wp.array, offs: np.ndarray, n: int, device: str) -> None:
    """Levels 1.. of a pyramid whose base (level 0, ``n`` per side) is written, each from the one below."""
    k, m = 0, n // 2
    while m >= 1:
        launch_chunked(level_kernel, m * m, inputs=[int(offs[k]), int(offs[k + 1]), m], outputs=[pyr], device=device, min_chunk=1 << 14)
        k += 1
        m //= 2


@wp.kernel
def moments_base(
    offset: int,
    depth: wp.array2d[float],
    near: float,
    far: float,
    # outputs
    pyr: wp.array[wp.vec2],
):
    i = wp.tid() + offset
    n = depth.shape[1]
    y = i // n
    x = i - y * n
    d = depth[y, x]
    t = float(1.0)  # empty: nothing between the light and anything mapped (the far end of the range)
    if d < DEPTH_CLEAR:
        t = wp.clamp((d - near) / (far - near), 0.0, 1.0)
    pyr[i] = wp.vec2(t, t * t)


@wp.kernel
def moments_level(
    offset: int,
    src_off: int,
    dst_off: int,
    n: int,
    # outputs
    pyr: wp.array[wp.vec2],
):
    """Level of ``n`` per side: the mean of the 2 x 2 texels below (the moments of their union)."""
    i = wp.tid() + offset
    a, b, c, d = texels_below(pyr, src_off, n, i)
    pyr[dst_off + i] = (a + b + c + d) * 0.25


def build_moments_pyramid(depth: wp.array, near: float, far: float, device: str) -> tuple[wp.array, np.ndarray]:
    """The mip chain of a variance shadow map: per texel the first two moments (E[x], E[x^2]) of the
    depth normalised to ``[near, far]`` (empty texels at 1), each level the mean of the 2 x 2 below,
    so a texel of level k holds the moments of the depths of its 2^k x 2^k base texels exactly.
    Returns (flat vec2 levels, offsets) in the layout of :func:`build_minmax_pyramid`."""
    n = depth.shape[1]
    if depth.shape[0] != n:
        raise ValueError("the map must be square")
    log2_exact(n)
    offs = level_offsets(n)
    pyr = wp.empty(int(offs[-1]), dtype=wp.vec2, device=device)
    launch_chunked(moments_base, n * n, inputs=[depth, float(near), float(far if far > near else near + 1.0)], outputs=[pyr], device=device)
    _build_levels(moments_level, pyr, offs, n, device)
    return pyr, offs


def minmax_range(depth: wp.array, device: str) -> tuple[float, float]:
    """(z_min, z_max) of the covered texels of a square depth map from its pyramid's top;
    ``(inf, -inf)`` for an empty map."""
    pyr, _ = build_minmax_pyramid(depth, device, skip_empty=True)
    top = pyr[pyr.shape[0] - 1 :].numpy()[0]
    zmin, zmax = float(top[0]), float(top[1])
    if zmin > zmax:
        return math.inf, -math.inf
    return zmin, zmax


def effective_depth_range(dm, mode: str, scene, device: str) -> tuple[float, float, bool]:
    """The effective depth range that normalises a depth map's linear depth: (z_min, z_max - z_min,
    empty). ``pyramid``: from the map's min/max pyramid; ``bounds``: the scene bounds in light
    space. An empty map gives (0, 1, True). The range is never narrower than 1% of the view's depth
    span (far - near): a map holding one depth only (a flat receiver square to the light, nothing
    above it) would otherwise normalise float32 noise into the whole [0, 1] range and shadow itself."""
    if mode == "bounds":
        lo, hi = scene.bounds
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], np.float64)
        zv = dm.view.to_view(corners)[:, 2]
        near = dm.view.near if dm.view.persp else float(zv.min())
        zmin, zmax = max(float(zv.min()), near), float(zv.max())
    else:
        zmin, zmax = minmax_range(dm.depth, device)
    empty = not math.isfinite(zmin)
    if empty:
        zmin, zmax = 0.0, 1.0
    floor = max(1e-2 * (dm.view.far - dm.view.near), 1e-6 * abs(zmax), 1e-30)  # relative: a scene a billionth of a unit wide keeps its depths
    return zmin, max(zmax - zmin, floor), empty
