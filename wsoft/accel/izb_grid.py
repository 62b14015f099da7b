"""The irregular z-buffer (Johnson et al.): eye-view shadow samples bucketed by light-view cell.

A *grid of lists*: every sample is projected onto the light view's image plane (a perspective
frustum from a local light's centre, an orthographic box for a distant light) and keyed by the
cell it falls in; the keys are sorted with their sample indices (``wp.utils.radix_sort_pairs``,
on CPU and CUDA alike), and each cell keeps the range ``[start, end)`` of its samples in the
sorted order, found by a scan of the sorted keys in which only the first and last sample of a
run write their cell (no atomics: Warp's are plain read-modify-write on CPU). The samples' rays
are gathered into sorted order, so a cell's list is contiguous in memory.

The light pass (:func:`izb_test`, a fragment of the rasterizer factory) is run with
*conservative* rasterization: every cell a triangle touches, so every sample whose ray the
triangle can block is tested. The test is exact: Warp's watertight ray-triangle test
(:func:`~wsoft.scene.rays.ray_triangle`, the one the BVH any-hit uses) on the sample's ray
toward the light's centre, alpha-tested at the hit through cutouts. A cell whose samples all lie
nearer the light than the triangle's nearest depth over the cell is skipped. The fragment writes
only what belongs to its cell (the flags of its own samples, its counters), so the CPU scheduler
may run it in private targets merged by OR / sum, or in disjoint bands of rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.lightspace.view import LightView, ViewGPU, texel_of, view_of
from wsoft.parallel import ensure_loaded, launch_chunked
from wsoft.raster.rasterizer import fragment
from wsoft.scene.surfaces import Surfaces, surface_present
from wsoft.scene.rays import ray_triangle


@wp.struct
class IzbTarget:
    """What the light pass reads (the grid, the sorted samples' rays, the triangles) and writes
    (``blocked`` per sorted sample, ``pairs`` and ``tests`` per cell)."""

    start: wp.array2d[wp.int32]  # [H, W] first sorted sample of the cell
    end: wp.array2d[wp.int32]  # [H, W] one past its last (start = end: empty)
    zmax: wp.array2d[float]  # [H, W] the farthest light depth of the cell's samples
    tol: float  # depth tolerance of the cell skip
    origin: wp.array[wp.vec3]  # sorted samples' ray origins
    dir: wp.array[wp.vec3]  # unit directions toward the light's centre
    tmax: wp.array[float]  # ray lengths
    points: wp.array[wp.vec3]
    indices: wp.array[wp.int32]
    cut: Surfaces
    has_cutouts: int
    blocked: wp.array[wp.int32]  # [samples] 1: a triangle blocks the ray
    pairs: wp.array2d[wp.int32]  # [H, W] triangles that reached the (non-empty) cell
    tests: wp.array2d[wp.int32]  # [H, W] ray-triangle tests run in the cell


@wp.kernel
def fill_int(
    offset: int,
    value: int,
    # outputs
    dst: wp.array[wp.int32],
):
    dst[wp.tid() + offset] = value


@wp.kernel
def merge_or(
    offset: int,
    src: wp.array[wp.int32],
    # outputs
    dst: wp.array[wp.int32],
):
    i = wp.tid() + offset
    dst[i] = wp.max(dst[i], src[i])


@wp.kernel
def merge_sum(
    offset: int,
    src: wp.array[wp.int32],
    # outputs
    dst: wp.array[wp.int32],
):
    i = wp.tid() + offset
    dst[i] = dst[i] + src[i]


def _outputs(t: IzbTarget):
    return (t.blocked, t.pairs.reshape(-1), t.tests.reshape(-1))


def _private(t: IzbTarget, device):
    ensure_loaded(fill_int, device)
    p = IzbTarget()
    for name in IzbTarget.vars:
        setattr(p, name, getattr(t, name))
    p.blocked = wp.empty_like(t.blocked)
    p.pairs = wp.empty_like(t.pairs)
    p.tests = wp.empty_like(t.tests)
    return p


def _clear(t: IzbTarget, device):
    """Zero a target's outputs (runs inside its worker's task on CPU: one thread)."""
    ensure_loaded(fill_int, device)
    for a in _outputs(t):
        if a.size:
            wp.launch(fill_int, dim=a.size, inputs=[0, 0], outputs=[a], device=device)


def _merge(privates, t: IzbTarget, device):
    for p in privates:
        for k, (src, dst) in enumerate(zip(_outputs(p), _outputs(t))):
            if dst.size:
                launch_chunked(merge_or if k == 0 else merge_sum, dst.size, inputs=[src], outputs=[dst], device=device, min_chunk=1 << 16)


@fragment(IzbTarget, private=_private, clear=_clear, merge=_merge)
def izb_test(t: IzbTarget, x: int, y: int, z: float, bary: wp.vec3, tri: int):
    """Test the samples of cell (x, y) against triangle ``tri`` (``z``: its nearest depth over the cell)."""
    s0 = t.start[y, x]
    s1 = t.end[y, x]
    if s1 > s0:
        wp.atomic_add(t.pairs, y, x, 1)
        if z <= t.zmax[y, x] + t.tol:
            a = t.points[t.indices[3 * tri]]
            b = t.points[t.indices[3 * tri + 1]]
            c = t.points[t.indices[3 * tri + 2]]
            n = int(0)
            for k in range(s0, s1):
                if t.blocked[k] == 0:
                    n += 1
                    h = ray_triangle(t.origin[k], t.dir[k], a, b, c)
                    if h[0] != 0.0 and h[1] >= 0.0 and h[1] < t.tmax[k]:
                        # warp: p = a*u + b*v + c*(1-u-v)
                        if t.has_cutouts == 0 or surface_present(t.cut, tri, h[2], h[3], 1.0 - h[2] - h[3]):
                            t.blocked[k] = 1
            wp.atomic_add(t.tests, y, x, n)


# --------------------------------------------------------------------------- building the grid


@wp.kernel
def cell_keys(
    offset: int,
    lv: ViewGPU,
    origin: wp.array[wp.vec3],
    insert: wp.array[wp.int32],
    # outputs
    keys: wp.array[wp.int32],
    values: wp.array[wp.int32],
):
    """Key of sample i: its cell ``y * W + x``; ``W * H`` (sorted last) when it is not inserted
    (``insert[i] == 0``: -1 more, to count those that fell outside the view)."""
    i = wp.tid() + offset
    outside = lv.width * lv.height
    key = outside + 1
    if insert[i] != 0:
        key = outside
        v = view_of(lv, origin[i])
        if lv.persp == 0 or v[2] > lv.near:
            t = texel_of(lv, v)
            x = int(wp.floor(t[0]))
            y = int(wp.floor(t[1]))
            if x >= 0 and y >= 0 and x < lv.width and y < lv.height and t[0] == t[0] and t[1] == t[1]:
                key = y * lv.width + x
    keys[i] = key
    values[i] = i


@wp.kernel
def cell_ranges(
    offset: int,
    n: int,
    width: int,
    cells: int,
    keys: wp.array[wp.int32],
    depth: wp.array[float],
    # outputs
    start: wp.array2d[wp.int32],
    end: wp.array2d[wp.int32],
    zmax: wp.array2d[float],
):
    """Each run of equal keys writes its cell's range: its first sample the start, its last the end
    and the run's farthest light depth (cells without samples are never read: no pass over them)."""
    k = wp.tid() + offset
    key = keys[k]
    if key < cells:
        y = key // width
        x = key - y * width
        if k == 0 or keys[k - 1] != key:
            start[y, x] = k
        if k == n - 1 or keys[k + 1] != key:
            end[y, x] = k + 1
            m = float(-1.0e30)
            j = k
            while j >= 0 and keys[j] == key:
                m = wp.max(m, depth[j])
                j -= 1
            zmax[y, x] = m


@wp.kernel
def gather_sorted(
    offset: int,
    lv: ViewGPU,
    order: wp.array[wp.int32],
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    # outputs
    s_origin: wp.array[wp.vec3],
    s_dir: wp.array[wp.vec3],
    s_tmax: wp.array[float],
    s_depth: wp.array[float],
    rank: wp.array[wp.int32],
):
    k = wp.tid() + offset
    i = order[k]
    s_origin[k] = origin[i]
    s_dir[k] = dir[i]
    s_tmax[k] = tmax[i]
    s_depth[k] = view_of(lv, origin[i])[2]
    rank[i] = k


@dataclass
class IzbGrid:
    """A built grid: ``view`` (its cells are the view's texels), the target the light pass fills,
    ``rank`` (sample -> sorted position, -1 when not in the grid), and what it holds."""

    view: LightView
    target: IzbTarget
    rank: wp.array
    inserted: int  # samples in the grid
    outside: int  # samples to insert that fell outside the view (left unshadowed)
    list_lengths: np.ndarray  # lengths of the non-empty cells' lists

    @property
    def grid_bytes(self) -> int:
        """The cells: start, end, farthest depth (4 bytes each) and the two per-cell counters."""
        return 5 * 4 * self.view.width * self.view.height

    @property
    def list_bytes(self) -> int:
        """The sorted samples: key and index (sort buffers, twice each), origin, direction, length,
        depth, rank and the blocked flag."""
        return self.inserted * 4 * (4 + 3 + 3 + 1 + 1 + 1 + 1)


def build_grid(view: LightView, origin: wp.array, dir: wp.array, tmax: wp.array, insert: wp.array,
               points: wp.array, indices: wp.array, cut: Surfaces, has_cutouts: int, device: str) -> IzbGrid:
    """Bucket the samples with ``insert[i] != 0`` into the cells of ``view``."""
    n = int(origin.shape[0])
    lv = view.gpu()
    w, h = view.width, view.height
    cells = w * h
    keys = wp.empty(2 * max(n, 1), dtype=wp.int32, device=device)
    values = wp.empty(2 * max(n, 1), dtype=wp.int32, device=device)
    if n:
        launch_chunked(cell_keys, n, inputs=[lv, origin, insert], outputs=[keys, values], device=device)
        wp.utils.radix_sort_pairs(keys, values, n)
    k_host = keys.numpy()[:n]
    inserted = int(np.searchsorted(k_host, cells, side="left"))
    outside = int(np.count_nonzero(k_host == cells))
    t = IzbTarget()
    t.start = wp.zeros((h, w), dtype=wp.int32, device=device)
    t.end = wp.zeros((h, w), dtype=wp.int32, device=device)
    t.zmax = wp.empty((h, w), dtype=float, device=device)
    t.tol = float(1e-5 * max(abs(view.far), abs(view.near), view.far - view.near))
    m = max(inserted, 1)
    t.origin = wp.empty(m, dtype=wp.vec3, device=device)
    t.dir = wp.empty(m, dtype=wp.vec3, device=device)
    t.tmax = wp.empty(m, dtype=float, device=device)
    depth = wp.empty(m, dtype=float, device=device)
    rank = wp.full(max(n, 1), -1, dtype=wp.int32, device=device)
    if inserted:
        launch_chunked(gather_sorted, inserted, inputs=[lv, values, origin, dir, tmax], outputs=[t.origin, t.dir, t.tmax, depth, rank], device=device)
        launch_chunked(cell_ranges, inserted, inputs=[inserted, w, cells, keys, depth], outputs=[t.start, t.end, t.zmax], device=device)
    t.points, t.indices, t.cut, t.has_cutouts = points, indices, cut, int(has_cutouts)
    t.blocked = wp.empty(m, dtype=wp.int32, device=device)
    t.pairs = wp.empty((h, w), dtype=wp.int32, device=device)
    t.tests = wp.empty((h, w), dtype=wp.int32, device=device)
    lengths = np.diff(np.flatnonzero(np.r_[True, k_host[1:inserted] != k_host[:inserted - 1], True])) if inserted else np.zeros(0, np.int64)
    return IzbGrid(view=view, target=t, rank=rank, inserted=inserted, outside=outside, list_lengths=lengths)
