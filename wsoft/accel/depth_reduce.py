"""Reductions over the G-buffer's visible samples for cascaded maps (Sample Distribution Shadow
Maps, Lauritzen, Salvi and Lefohn 2011): the range of their camera view depths
(:func:`sample_depth_range`), and per depth range (a cascade's) the light-space bounds of the
samples that fall in it (:func:`cascade_bounds`).

Each kernel thread reduces one block of :data:`BLOCK` samples into its own row of partial results
(no atomics, so no two chunks ever write the same element); NumPy combines the rows. Depth is
``(p - eye) . forward`` (the camera's view depth); light space is ``(p - anchor)`` on the light
view's axes.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.parallel import launch_chunked

BLOCK = 4096  # samples one thread reduces into one row of partials
BIG = wp.constant(wp.float64(1.0e300))
COLUMNS = 7  # per cascade: count, min x, max x, min y, max y, min z, max z


@wp.kernel
def depth_range_partials(
    offset: int,
    n: int,
    pos: wp.array[wp.vec3],
    prim: wp.array[wp.int32],
    eye: wp.vec3d,
    forward: wp.vec3d,
    # outputs
    part: wp.array2d[wp.float64],
):
    """Per block of :data:`BLOCK` samples: count, min and max view depth of the covered ones."""
    b = wp.tid() + offset
    lo = BIG
    hi = -BIG
    count = wp.float64(0.0)
    for i in range(b * BLOCK, wp.min(b * BLOCK + BLOCK, n)):
        if prim[i] >= 0:
            p = pos[i]
            d = wp.dot(wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2])) - eye, forward)
            lo = wp.min(lo, d)
            hi = wp.max(hi, d)
            count += wp.float64(1.0)
    part[b, 0] = count
    part[b, 1] = lo
    part[b, 2] = hi


@wp.kernel
def cascade_bounds_partials(
    offset: int,
    n: int,
    pos: wp.array[wp.vec3],
    prim: wp.array[wp.int32],
    eye: wp.vec3d,
    forward: wp.vec3d,
    anchor: wp.vec3d,
    axes: wp.mat33d,
    ranges: wp.array2d[wp.float64],
    cascades: int,
    # outputs
    part: wp.array2d[wp.float64],
):
    """Per block of :data:`BLOCK` samples and per cascade ``k`` (view depth in ``ranges[k]``, both
    ends included): the count and light-space min/max x, y, z of the covered samples in it
    (columns ``7k .. 7k + 6``; a sample may fall in two overlapping ranges)."""
    b = wp.tid() + offset
    for k in range(cascades):
        c = COLUMNS * k
        part[b, c] = wp.float64(0.0)
        for j in range(3):
            part[b, c + 1 + 2 * j] = BIG
            part[b, c + 2 + 2 * j] = -BIG
    for i in range(b * BLOCK, wp.min(b * BLOCK + BLOCK, n)):
        if prim[i] < 0:
            continue
        p = pos[i]
        q = wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2]))
        d = wp.dot(q - eye, forward)
        v = wp.transpose(axes) * (q - anchor)
        for k in range(cascades):
            if d >= ranges[k, 0] and d <= ranges[k, 1]:
                c = COLUMNS * k
                part[b, c] = part[b, c] + wp.float64(1.0)
                for j in range(3):
                    part[b, c + 1 + 2 * j] = wp.min(part[b, c + 1 + 2 * j], v[j])
                    part[b, c + 2 + 2 * j] = wp.max(part[b, c + 2 + 2 * j], v[j])


def _blocks(n: int) -> int:
    return max(1, (n + BLOCK - 1) // BLOCK)


def sample_depth_range(pos: wp.array, prim: wp.array, eye: np.ndarray, forward: np.ndarray) -> tuple[int, float, float]:
    """(count, min, max) of the covered samples' view depths (``pos`` vec3 [N], ``prim`` int32 [N],
    -1 for the background); (0, inf, -inf) when none is covered."""
    n = int(pos.shape[0])
    nb = _blocks(n)
    dev = str(pos.device)
    part = wp.empty((nb, 3), dtype=wp.float64, device=dev)
    launch_chunked(depth_range_partials, nb, inputs=[n, pos, prim, wp.vec3d(*eye), wp.vec3d(*forward)], outputs=[part],
                   device=dev, min_chunk=1)
    a = part.numpy()
    count = int(a[:, 0].sum())
    if count == 0:
        return 0, np.inf, -np.inf
    return count, float(a[:, 1].min()), float(a[:, 2].max())


def cascade_bounds(pos: wp.array, prim: wp.array, eye: np.ndarray, forward: np.ndarray, anchor: np.ndarray, axes: np.ndarray,
                   ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per cascade (``ranges``: [K, 2] view-depth intervals) the count of covered samples in it and
    their light-space bounds: (count [K] int, lo [K, 3], hi [K, 3]); an empty cascade's bounds are
    +inf / -inf."""
    n = int(pos.shape[0])
    nb = _blocks(n)
    dev = str(pos.device)
    k = len(ranges)
    part = wp.empty((nb, COLUMNS * k), dtype=wp.float64, device=dev)
    launch_chunked(cascade_bounds_partials, nb,
                   inputs=[n, pos, prim, wp.vec3d(*eye), wp.vec3d(*forward), wp.vec3d(*anchor), wp.mat33d(*np.asarray(axes, np.float64).ravel()),
                           wp.array(np.asarray(ranges, np.float64), dtype=wp.float64, device=dev), k],
                   outputs=[part], device=dev, min_chunk=1)
    a = part.numpy().reshape(nb, k, COLUMNS)
    count = a[:, :, 0].sum(axis=0).astype(np.int64)
    lo = a[:, :, [1, 3, 5]].min(axis=0)
    hi = a[:, :, [2, 4, 6]].max(axis=0)
    lo[count == 0] = np.inf
    hi[count == 0] = -np.inf
    return count, lo, hi
