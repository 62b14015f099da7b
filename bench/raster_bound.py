"""A bound on what the light-view rasterizer could reach on the CPU, beside its target (15x one BVH ray per texel).

Two stripped kernels, timed beside the real rasterizer (:func:`wsoft.raster.depth_map.rasterize`)
on the same orthographic view, in the same thread layout (one private map per worker, interleaved
chunks of triangles):

- :func:`fetch_box`: per triangle only what any per-triangle kernel must do first: fetch its three
  projected corners and find the texels its box covers. No drawing. Its time is a floor under any
  kernel that gives a triangle a thread.
- :func:`draw_min`: an idealised depth-only rasterizer: every triangle the real one would draw
  (the far faces it culls are culled for free, from a precomputed list), drawn by a branch-free loop
  over its box (edge functions and depth stepped from the box's first texel centre, the depth min
  written everywhere, ``DEPTH_CLEAR`` where uncovered). No clipping, no spans, no alpha test, no
  bands for large triangles, maps cleared before the clock starts and never merged. It draws the
  same map (``tests/test_raster_bound.py``) with less work than the real rasterizer does. Timed,
  it draws the triangles of the real rasterizer's first pass only (boxes up to
  ``BIG_TRIANGLE_TEXELS``; the few larger ones go to a banded second pass there).

The bound is orthographic only (depth is affine in texel space; a perspective view interpolates
1/z and divides per texel).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.raster.triangle import edge

DEPTH_CLEAR = wp.constant(1.0e30)  # as wsoft.lightspace.view.DEPTH_CLEAR (an empty texel)


@wp.func
def texel_box(a: wp.vec3, b: wp.vec3, c: wp.vec3, width: int, height: int) -> wp.vec4i:
    """The texel centres a triangle's box covers on the map: (x0, x1, y0, y1), empty when x0 > x1 or y0 > y1."""
    return wp.vec4i(wp.max(int(wp.ceil(wp.min(a[0], wp.min(b[0], c[0])) - 0.5)), 0),
                    wp.min(int(wp.floor(wp.max(a[0], wp.max(b[0], c[0])) - 0.5)), width - 1),
                    wp.max(int(wp.ceil(wp.min(a[1], wp.min(b[1], c[1])) - 0.5)), 0),
                    wp.min(int(wp.floor(wp.max(a[1], wp.max(b[1], c[1])) - 0.5)), height - 1))


@wp.kernel
def fetch_box(
    offset: int,
    proj: wp.array[wp.vec3],
    indices: wp.array[wp.int32],
    width: int,
    height: int,
    # outputs
    texels: wp.array[wp.int32],
):
    """Per triangle: the texel centres its box covers on the map (0: none)."""
    t = wp.tid() + offset
    a = proj[indices[3 * t]]
    b = proj[indices[3 * t + 1]]
    c = proj[indices[3 * t + 2]]
    box = texel_box(a, b, c, width, height)
    n = int(0)
    if box[0] <= box[1] and box[2] <= box[3]:
        n = (box[1] - box[0] + 1) * (box[3] - box[2] + 1)
    texels[t] = n


@wp.kernel
def draw_min(
    offset: int,
    proj: wp.array[wp.vec3],
    indices: wp.array[wp.int32],
    skip: wp.array[wp.int32],
    far: float,
    max_texels: int,
    # outputs
    depth: wp.array2d[float],
):
    """The idealised rasterizer: triangle ``t`` (unless ``skip[t]``, or its box holds more than
    ``max_texels`` texel centres) into ``depth`` by the depth min, a branch-free loop over its box;
    texel centres on an edge count as covered."""
    t = wp.tid() + offset
    if skip[t] != 0:
        return
    a = proj[indices[3 * t]]
    b = proj[indices[3 * t + 1]]
    c = proj[indices[3 * t + 2]]
    box = texel_box(a, b, c, depth.shape[1], depth.shape[0])
    x0 = box[0]
    x1 = box[1]
    y0 = box[2]
    y1 = box[3]
    if x0 > x1 or y0 > y1 or (x1 - x0 + 1) * (y1 - y0 + 1) > max_texels:
        return
    area = edge(a[0], a[1], b[0], b[1], c[0], c[1])
    if wp.abs(area) < 1.0e-12:
        return
    ia = 1.0 / area
    px = float(x0) + 0.5
    py = float(y0) + 0.5
    # barycentrics of a and b at the box's first texel centre, and their steps per texel
    l0 = edge(b[0], b[1], c[0], c[1], px, py) * ia
    l1 = edge(c[0], c[1], a[0], a[1], px, py) * ia
    g0x = -(c[1] - b[1]) * ia
    g0y = (c[0] - b[0]) * ia
    g1x = -(a[1] - c[1]) * ia
    g1y = (a[0] - c[0]) * ia
    z0 = l0 * a[2] + l1 * b[2] + (1.0 - l0 - l1) * c[2]
    zx = g0x * a[2] + g1x * b[2] - (g0x + g1x) * c[2]
    zy = g0y * a[2] + g1y * b[2] - (g0y + g1y) * c[2]
    nx = x1 - x0 + 1
    dx = int(0)
    dy = int(0)
    for _k in range(nx * (y1 - y0 + 1)):
        fx = float(dx)
        fy = float(dy)
        e0 = l0 + g0x * fx + g0y * fy
        e1 = l1 + g1x * fx + g1y * fy
        z = z0 + zx * fx + zy * fy
        z = wp.where(wp.min(wp.min(e0, e1), 1.0 - e0 - e1) >= 0.0 and z <= far, z, DEPTH_CLEAR)
        depth[y0 + dy, x0 + dx] = wp.min(depth[y0 + dy, x0 + dx], z)
        dx += 1
        if dx == nx:
            dx = 0
            dy += 1


def culled(ds, view) -> np.ndarray:
    """Per triangle 1 where the real rasterizer skips it in ``view`` (an orthographic one): the
    ``CULL_SKIP`` flag, or a far face of a closed surface (the facing test of
    :mod:`wsoft.raster.rasterizer`)."""
    from wsoft.scene.device import view_cull
    from wsoft.scene.surfaces import CULL_SKIP

    if view.persp:
        raise ValueError("the bound is for orthographic views")
    flags = view_cull(ds, None)
    flags = ds.cull_host if flags is None else flags
    p = ds.points.numpy().astype(np.float64)
    tri = ds.indices.numpy().reshape(-1, 3)
    n = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    toward = n @ np.asarray(view.axes, np.float64)[:, 2] < 0.0
    skip = (flags == int(CULL_SKIP)) | ((flags != 0) & (toward != (flags > 0)))
    return skip.astype(np.int32)


class Bound:
    """The two stripped kernels on one scene and view, in the real rasterizer's CPU layout:
    ``threads`` workers, each with a private map, taking interleaved chunks of ``chunk`` triangles."""

    def __init__(self, ds, view, threads: int, chunk: int):
        from wsoft.raster.rasterizer import project_points

        if ds.instances is not None:
            raise ValueError("the bound draws a flat triangle list, not instances")
        self.ds, self.view, self.threads = ds, view, threads
        dev = ds.device
        self.T = ds.indices.shape[0] // 3
        self.proj = wp.empty(ds.points.shape[0], dtype=wp.vec3, device=dev)
        wp.launch(project_points, ds.points.shape[0], inputs=[0, ds.points, view.gpu()], outputs=[self.proj], device=dev)
        self.skip = wp.array(culled(ds, view), dtype=wp.int32, device=dev)
        self.texels = wp.empty(self.T, dtype=wp.int32, device=dev)
        self.maps = [wp.empty((view.height, view.width), dtype=float, device=dev) for _ in range(threads)]
        self.chunks = [(s, min(chunk, self.T - s)) for s in range(0, self.T, chunk)]
        self.clear()

    def clear(self) -> None:
        for m in self.maps:
            m.fill_(1.0e30)

    def _run(self, launch) -> None:
        from wsoft.parallel import run_tasks

        def worker(m):
            def run():
                for s, c in self.chunks[m::self.threads]:
                    launch(m, s, c)

            return run

        run_tasks([worker(m) for m in range(self.threads)], self.ds.device)

    def fetch(self) -> None:
        ds, v = self.ds, self.view
        self._run(lambda m, s, c: wp.launch(fetch_box, c, inputs=[s, self.proj, ds.indices, v.width, v.height], outputs=[self.texels],
                                            device=ds.device))

    def draw(self, max_texels: int = 2**31 - 1) -> None:
        """Draw every triangle whose box holds at most ``max_texels`` texel centres (the real
        rasterizer leaves larger ones to a second, banded pass)."""
        ds = self.ds
        self._run(lambda m, s, c: wp.launch(draw_min, c, inputs=[s, self.proj, ds.indices, self.skip, float(self.view.far), max_texels],
                                            outputs=[self.maps[m]], device=ds.device))

    def depth(self) -> np.ndarray:
        """The map the idealised kernel drew (the min over the workers' maps)."""
        return np.minimum.reduce([m.numpy() for m in self.maps])
