"""A light depth map by casting one BVH ray per texel centre.

Not the main path (the rasterizer in :mod:`wsoft.raster.rasterizer` is): this is the
brute-force check the rasterizer is tested against and the baseline it is benchmarked
against. Depth is the same light-space linear depth, ``DEPTH_CLEAR`` where a ray misses.
"""

from __future__ import annotations

import warp as wp

from wsoft.parallel import launch_chunked
from wsoft.lightspace.view import DEPTH_CLEAR, LightView, ViewGPU
from wsoft.raster.depth_map import DepthMap
from wsoft.scene.device import DeviceScene
from wsoft.scene.surfaces import Surfaces, surface_present


@wp.kernel
def raycast_texels(
    offset: int,
    mesh: wp.uint64,
    cut: Surfaces,
    alpha: int,
    lv: ViewGPU,
    # outputs
    depth: wp.array[float],
):
    i = wp.tid() + offset
    y = i // lv.width
    x = i - y * lv.width
    wx = lv.window[0] + (float(x) + 0.5) / float(lv.width) * (lv.window[1] - lv.window[0])
    wy = lv.window[2] + (float(y) + 0.5) / float(lv.height) * (lv.window[3] - lv.window[2])
    o = lv.origin
    d = lv.az
    tmin = float(0.0)
    if lv.persp != 0:
        d = lv.ax * wx + lv.ay * wy + lv.az  # unit step in view depth
        tmin = lv.near
    else:
        o = lv.origin + lv.ax * wx + lv.ay * wy
        tmin = lv.near
    start = o + d * tmin
    travelled = tmin
    out = float(DEPTH_CLEAR)
    remaining = float(1.0e30)
    for _k in range(64):
        q = wp.mesh_query_ray(mesh, start, d, remaining)
        if not q.result:
            break
        if alpha == 0 or surface_present(cut, q.face, q.u, q.v, 1.0 - q.u - q.v):
            out = travelled + q.t  # |d . az| = 1, so the ray parameter is the view depth
            break
        step = q.t + 1.0e-5 * (cut.step + q.t)
        start = start + d * step
        travelled += step
    depth[i] = out


def raycast_depth(ds: DeviceScene, view: LightView, alpha_tested: bool) -> DepthMap:
    """One any-closest BVH ray per texel centre (the brute-force depth map)."""
    n = view.width * view.height
    flat = wp.empty(n, dtype=float, device=ds.device)
    launch_chunked(raycast_texels, n, inputs=[ds.mesh.id, ds.cutouts, int(alpha_tested and ds.has_cutouts), view.gpu()], outputs=[flat], device=ds.device)
    return DepthMap(view=view, depth=flat.reshape((view.height, view.width)), alpha_tested=alpha_tested, conservative=False)
