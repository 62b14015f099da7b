"""A dual-paraboloid depth map (:mod:`wsoft.lightspace.paraboloid`), drawn by one BVH ray per
texel centre: the distance from the light's centre to the first caster along the texel's
direction, alpha-tested through cutouts, passing through the triangles that do not cast the
light's shadow (its ``collection:shadowLink``). Texels outside the window's disk, and a hemisphere
without receivers, are not traced (``DEPTH_CLEAR``)."""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.lightspace.paraboloid import ParaboloidGPU, ParaboloidMap, ParaboloidView, paraboloid_direction
from wsoft.lightspace.view import DEPTH_CLEAR
from wsoft.parallel import launch_chunked
from wsoft.scene.device import DeviceScene
from wsoft.scene.offsets import step_past
from wsoft.scene.surfaces import Surfaces, surface_present


@wp.kernel
def trace_paraboloid_texels(
    offset: int,
    mesh: wp.uint64,
    cut: Surfaces,
    alpha: int,
    casting: wp.array[wp.int32],
    linked: int,
    dp: ParaboloidGPU,
    # outputs
    depth: wp.array[float],
):
    i = wp.tid() + offset
    n2 = dp.size * dp.size
    h = i // n2
    j = i - h * n2
    y = j // dp.size
    x = j - y * dp.size
    drawn = dp.drawn0
    if h != 0:
        drawn = dp.drawn1
    u = (2.0 * (float(x) + 0.5) / float(dp.size) - 1.0) * dp.radius
    v = (2.0 * (float(y) + 0.5) / float(dp.size) - 1.0) * dp.radius
    if drawn == 0 or u * u + v * v > dp.radius * dp.radius:
        depth[i] = DEPTH_CLEAR
        return
    d = paraboloid_direction(dp, h, float(x) + 0.5, float(y) + 0.5)
    start = dp.origin + d * dp.near
    travelled = dp.near
    out = float(DEPTH_CLEAR)
    for _k in range(64):
        q = wp.mesh_query_ray(mesh, start, d, 1.0e30)
        if not q.result:
            break
        casts = linked == 0 or casting[q.face] != 0
        if casts and (alpha == 0 or surface_present(cut, q.face, q.u, q.v, 1.0 - q.u - q.v)):
            out = travelled + q.t
            break
        start, step = step_past(mesh, q.face, q.u, q.v, start, d)
        travelled += step
    depth[i] = out


def draw_paraboloid(ds: DeviceScene, view: ParaboloidView, alpha_tested: bool, casting: np.ndarray | None) -> ParaboloidMap:
    """The map of ``view`` (``casting``: the triangles that cast the light's shadow; None: all)."""
    n = 2 * view.size * view.size
    flat = wp.empty(n, dtype=float, device=ds.device)
    if casting is not None:
        idx = np.asarray(casting, np.int64)
        flags = np.zeros(max(int(ds.tri_total), int(idx.max()) + 1 if len(idx) else 0, 1), np.int32)
        flags[idx] = 1
        mask = wp.array(flags, dtype=wp.int32, device=ds.device)
    else:
        mask = wp.zeros(1, dtype=wp.int32, device=ds.device)
    alpha = int(alpha_tested and ds.has_cutouts)
    launch_chunked(trace_paraboloid_texels, n, inputs=[ds.mesh.id, ds.cutouts, alpha, mask, int(casting is not None), view.gpu()],
                   outputs=[flat], device=ds.device)
    inside = _window_texels(view.size, view.radius)
    return ParaboloidMap(view=view, depth=flat.reshape((2, view.size, view.size)), alpha_tested=bool(alpha),
                         rays=int(inside * len(view.drawn)))


def _window_texels(size: int, radius: float) -> int:
    """Texels of one hemisphere's map whose centre lies in the window's disk (the rays traced)."""
    c = (2.0 * (np.arange(size) + 0.5) / size - 1.0) * radius
    return int(np.count_nonzero(c[:, None] ** 2 + c[None, :] ** 2 <= radius * radius))
