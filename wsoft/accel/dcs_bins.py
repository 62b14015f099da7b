"""Light-space bins for depth complexity sampling: which receivers a silhouette edge's wedge (or a
perforated triangle's soft textured shadow volume) can reach, as per-cell lists of primitives.

The cells are the texels of a light view fitted to the receivers (:func:`~wsoft.lightspace.fit.fit_light_view`:
a perspective frustum from a local light's centre, an orthographic box along a distant light),
resampled to ``size x size``. Each primitive (an edge: 2 corners, a triangle: 3) gets the
conservative rectangle of cells its shadow can reach (:func:`primitive_footprint`), and the
(cell, primitive) pairs are sorted by cell into a CSR list. A receiver then reads the list of its
own cell (a *gather*: each receiver writes only its own result, no atomics and no private count
buffers). One more list, at index ``size * size``, holds every primitive: the receivers outside
the view (beyond its 80 degree window, or behind a perspective view's near plane) read it.

**The footprint.** A caster point ``q`` shadows receiver ``p`` from light point ``x`` when
``q`` lies on the segment ``x p``. With the light inside a ball of radius ``R`` about the view's
origin (a local light; view coordinates, ``z`` the depth) and ``q_z > R``, the window coordinate
``w = (x/z, y/z)`` of ``p`` differs from ``q``'s by at most, per axis,
``|x_xy - x_z w_q| / (q_z - x_z) * (1 - q_z / p_z) <= R (1 + |w_q|) / (q_z - R) * (1 - q_z / zr_max)``
(``zr_max``: the receivers' farthest depth), and ``p_z >= q_z``. Over a primitive: the bounding
box of its corners' window coordinates (a segment or triangle in front of the origin projects to
the segment or triangle of its projected corners), dilated by the bound at its nearest corner
depth. A primitive with a corner at depth ``<= R`` (it reaches into the light's ball, or behind
its centre) covers every cell unless it lies wholly behind the ball (``z < -R``: it can block
nothing). A distant light (half-angle ``a``): ``|w_p - w_q| <= (zr_max - q_z) tan a``, the
spread of :func:`~wsoft.lightspace.light.spread`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import warp as wp

from wsoft.lightspace.view import LightView, ViewGPU, map_coords, texel_of, view_of, window_to_texel
from wsoft.parallel import launch_chunked

ALL_CELLS = wp.constant(-1)
NO_CELL = wp.constant(-2)


@wp.kernel
def primitive_footprint(
    offset: int,
    lv: ViewGPU,
    corners: wp.array2d[wp.vec3],
    ncorners: int,
    radius: float,
    tan_a: float,
    zr_max: float,
    # outputs
    rect: wp.array[wp.vec4i],
):
    """Cells ``(x0, y0, x1, y1)`` (inclusive, clamped to the grid) that primitive ``i`` (corners
    ``corners[i, :ncorners]``) can shadow; ``x0 = ALL_CELLS``: every cell; ``x0 = NO_CELL``: none
    of the grid's cells (the all-receivers list still holds it)."""
    i = wp.tid() + offset
    zmin = float(1.0e30)
    zmax = float(-1.0e30)
    for k in range(ncorners):
        v = view_of(lv, corners[i, k])
        zmin = wp.min(zmin, v[2])
        zmax = wp.max(zmax, v[2])
    out = wp.vec4i(NO_CELL, 0, 0, 0)
    if zmin > zr_max:  # every receiver is nearer the light than the primitive
        rect[i] = out
        return
    wlo = wp.vec2(1.0e30, 1.0e30)
    whi = wp.vec2(-1.0e30, -1.0e30)
    grow = wp.vec2(0.0, 0.0)
    if lv.persp != 0:
        if zmax < -radius:  # wholly behind the light's ball: between no receiver and the light
            rect[i] = out
            return
        if zmin <= radius * 1.0001 + 1.0e-6 * zr_max:
            rect[i] = wp.vec4i(ALL_CELLS, 0, 0, 0)
            return
        wabs = wp.vec2(0.0, 0.0)
        for k in range(ncorners):
            m = map_coords(lv, view_of(lv, corners[i, k]))
            wlo = wp.min(wlo, m)
            whi = wp.max(whi, m)
            wabs = wp.max(wabs, wp.vec2(wp.abs(m[0]), wp.abs(m[1])))
        f = radius / (zmin - radius) * wp.max(1.0 - zmin / zr_max, 0.0)
        grow = wp.vec2(f * (1.0 + wabs[0]), f * (1.0 + wabs[1]))
    else:
        for k in range(ncorners):
            m = map_coords(lv, view_of(lv, corners[i, k]))
            wlo = wp.min(wlo, m)
            whi = wp.max(whi, m)
        g = tan_a * wp.max(zr_max - zmin, 0.0)
        grow = wp.vec2(g, g)
    # a little slack for rounding (a thousandth of the reach, and of a cell)
    grow = grow * 1.001 + wp.vec2(1.0e-3 / lv.scale[0], 1.0e-3 / lv.scale[1])
    lo = window_to_texel(lv, wlo - grow)
    hi = window_to_texel(lv, whi + grow)
    if hi[0] < 0.0 or hi[1] < 0.0 or lo[0] >= float(lv.width) or lo[1] >= float(lv.height) or not (lo[0] == lo[0] and hi[1] == hi[1]):
        rect[i] = out
        return
    x0 = int(wp.floor(wp.max(lo[0], 0.0)))
    y0 = int(wp.floor(wp.max(lo[1], 0.0)))
    x1 = int(wp.floor(wp.min(hi[0], float(lv.width) - 0.5)))
    y1 = int(wp.floor(wp.min(hi[1], float(lv.height) - 0.5)))
    rect[i] = wp.vec4i(x0, y0, x1, y1)


@wp.kernel
def fill_pairs(
    offset: int,
    rect: wp.array[wp.vec4i],
    first: wp.array[wp.int64],
    width: int,
    height: int,
    # outputs
    keys: wp.array[wp.int32],
    values: wp.array[wp.int32],
):
    """Primitive ``i`` writes its pairs at ``first[i]``: its cells, then the all-receivers list
    (each primitive writes only its own slots)."""
    i = wp.tid() + offset
    k = int(first[i])
    r = rect[i]
    if r[0] == ALL_CELLS:
        for c in range(width * height):
            keys[k] = c
            values[k] = i
            k += 1
    elif r[0] != NO_CELL:
        for y in range(r[1], r[3] + 1):
            for x in range(r[0], r[2] + 1):
                keys[k] = y * width + x
                values[k] = i
                k += 1
    keys[k] = width * height
    values[k] = i


@wp.func
def receiver_cell(lv: ViewGPU, x: wp.vec3) -> int:
    """The cell of a receiver at ``x``, or ``width * height`` (the all-primitives list) outside the grid."""
    v = view_of(lv, x)
    outside = lv.width * lv.height
    if lv.persp != 0 and v[2] <= lv.near:
        return outside
    t = texel_of(lv, v)
    if not (t[0] == t[0] and t[1] == t[1]):
        return outside
    if t[0] < 0.0 or t[1] < 0.0 or t[0] >= float(lv.width) or t[1] >= float(lv.height):
        return outside
    return int(wp.floor(t[1])) * lv.width + int(wp.floor(t[0]))


@wp.struct
class BinsGPU:
    """Per-cell lists of primitives: cell ``c`` holds ``items[start[c]:start[c + 1]]``; cell
    ``width * height`` (the last) holds every primitive."""

    lv: ViewGPU
    start: wp.array[wp.int32]
    items: wp.array[wp.int32]


@wp.func
def receiver_items(bins: BinsGPU, x: wp.vec3) -> wp.vec2i:
    """The range ``[first, last)`` of ``bins.items`` a receiver at ``x`` reads: its cell's list."""
    cell = receiver_cell(bins.lv, x)
    return wp.vec2i(bins.start[cell], bins.start[cell + 1])


@dataclass
class Bins:
    view: LightView
    gpu: BinsGPU
    pairs: int  # (cell, primitive) pairs in the lists, the all-primitives list included
    whole: int  # primitives that reach every cell
    cells: int

    @property
    def bytes(self) -> int:
        return 4 * (self.cells + 2) + 4 * self.pairs


def grid_view(view: LightView, size: int) -> LightView:
    """``view`` resampled to ``size x size`` cells (the same window)."""
    return replace(view, width=int(size), height=int(size))


MAX_PAIRS = 1 << 23  # (cell, primitive) pairs a light's lists may hold (32 MiB of items) before the grid is coarsened


def build_bins(view: LightView, corners: np.ndarray, radius: float, tan_a: float, zr_max: float, device: str,
               max_pairs: int = MAX_PAIRS) -> Bins:
    """Bin primitives (``corners`` [N, K, 3] float32, K = 2 edges or 3 triangles) into the cells of
    ``view`` (module docstring); ``radius``: the local light's bounding ball about the view's origin;
    ``tan_a``: a distant light's half-angle tangent; ``zr_max``: the receivers' farthest view depth.
    Wide footprints (a large light over many small casters) would make the lists quadratically
    long: the grid is halved until they hold at most ``max_pairs`` pairs (or it is 8 x 8); a
    receiver then tests a few more primitives, the pairs fall about fourfold per halving."""
    n, k = int(corners.shape[0]), int(corners.shape[1]) if corners.ndim == 3 else 0
    c = wp.array(np.ascontiguousarray(corners, np.float32), dtype=wp.vec3, device=device) if n else None
    rect = wp.empty(max(n, 1), dtype=wp.vec4i, device=device)
    while True:
        lv = view.gpu()
        cells = view.width * view.height
        rect_h = np.zeros((0, 4), np.int32)
        if n:
            launch_chunked(primitive_footprint, n, inputs=[lv, c, k, float(radius), float(tan_a), float(zr_max)], outputs=[rect],
                           device=device, min_chunk=4096)
            rect_h = rect.numpy()[:n]
        whole = rect_h[:, 0] == -1
        none = rect_h[:, 0] == -2
        area = np.where(whole, cells, np.where(none, 0, (rect_h[:, 2] - rect_h[:, 0] + 1).astype(np.int64) * (rect_h[:, 3] - rect_h[:, 1] + 1)))
        if int(area.sum()) + n <= max_pairs or view.width <= 8:
            break
        view = grid_view(view, max(8, view.width // 2))
    per = area.astype(np.int64) + 1
    first = np.zeros(n + 1, np.int64)
    np.cumsum(per, out=first[1:])
    total = int(first[-1])
    keys = wp.empty(2 * max(total, 1), dtype=wp.int32, device=device)
    values = wp.empty(2 * max(total, 1), dtype=wp.int32, device=device)
    if n:
        launch_chunked(fill_pairs, n, inputs=[rect, wp.array(first[:-1], dtype=wp.int64, device=device), view.width, view.height],
                       outputs=[keys, values], device=device, min_chunk=64, per_thread=8)
        wp.utils.radix_sort_pairs(keys, values, total)
    kh = keys.numpy()[:total]
    start = np.searchsorted(kh, np.arange(cells + 2), side="left").astype(np.int32)
    g = BinsGPU()
    g.lv = lv
    g.start = wp.array(start, dtype=wp.int32, device=device)
    g.items = values
    return Bins(view=view, gpu=g, pairs=total, whole=int(whole.sum()), cells=cells)
