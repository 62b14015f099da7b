"""Light depth maps drawn by one BVH ray per texel centre.

* :func:`raycast_depth` — every texel: the brute-force check the rasterizer
  (:mod:`wsoft.raster.rasterizer`) is tested against and the baseline it is benchmarked against.
* :func:`raycast_read` — only the texels the receivers read: a technique that reads one texel
  per receiver (``hard``) or a small window around it needs no other, and on a stage of many
  placed triangles (an instanced forest) one ray per read texel costs far less than drawing every
  triangle (``map_texels`` of :class:`~wsoft.techniques.hard.HardParams`).

A ray starts on the view's near plane at the texel centre's window coordinates and keeps the
nearest surface it meets, through the soup and the instances (:func:`~wsoft.scene.rays.blocker_distance`:
both sides of every triangle, alpha-tested through cutouts, through the prims a light's
``collection:shadowLink`` leaves out). That is the depth the rasterizer gives a texel whose
centre a triangle covers (the nearest surface seen from outside a closed one is a face turned
toward the light, the one the rasterizer keeps), to float rounding, except where a centre lies on
an edge the two sides break differently. Depth is the light-space linear depth, ``DEPTH_CLEAR``
where a ray misses.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.lightspace.view import DEPTH_CLEAR, LightView, ViewGPU
from wsoft.parallel import launch_chunked
from wsoft.raster.depth_map import DepthMap, fill_depth
from wsoft.raster.gbuffer import GBuffer, GBufferGPU, gb_mapped_receiver
from wsoft.scene.device import DeviceScene
from wsoft.scene.rays import Occluders, blocker_distance, occluders


@wp.kernel
def raycast_texels(
    offset: int,
    listed: int,
    texels: wp.array[wp.int32],
    occ: Occluders,
    lv: ViewGPU,
    max_depth: float,
    # outputs
    depth: wp.array[float],
):
    """Texel ``texels[k]`` (``listed``) or ``k``: the depth of the nearest surface along its centre's ray within ``max_depth``."""
    i = wp.tid() + offset
    if listed != 0:
        i = texels[i]
    y = i // lv.width
    x = i - y * lv.width
    wx = lv.window[0] + (float(x) + 0.5) / float(lv.width) * (lv.window[1] - lv.window[0])
    wy = lv.window[2] + (float(y) + 0.5) / float(lv.height) * (lv.window[3] - lv.window[2])
    o = lv.origin
    d = lv.az  # one unit of view depth along the ray
    if lv.persp != 0:
        d = lv.ax * wx + lv.ay * wy + lv.az
    else:
        o = lv.origin + lv.ax * wx + lv.ay * wy
    step = wp.length(d)
    t = blocker_distance(occ, o + d * lv.near, d / step, (max_depth - lv.near) * step)
    out = float(DEPTH_CLEAR)
    if t >= 0.0:
        out = lv.near + t / step
    depth[i] = out


@wp.kernel
def receiver_texels(
    offset: int,
    lv: ViewGPU,
    gb: GBufferGPU,
    # outputs
    texel: wp.array[wp.int32],
):
    """The texel (row-major index) a G-buffer sample reads in ``lv``, -1 where it reads none."""
    i = wp.tid() + offset
    mapped, v, m, t = gb_mapped_receiver(lv, gb, i)
    out = int(-1)
    if mapped:
        out = int(wp.floor(t[1])) * lv.width + int(wp.floor(t[0]))
    texel[i] = out


def _occluders(ds: DeviceScene, alpha_tested: bool, excluded: tuple[int, ...]) -> Occluders:
    occ = occluders(ds, excluded)
    if alpha_tested or excluded or not occ.has_cutouts:
        return occ
    opaque = Occluders()  # cutouts drawn whole
    opaque.mesh, opaque.cut, opaque.has_cutouts, opaque.inst = occ.mesh, occ.cut, 0, occ.inst
    return opaque


def raycast_depth(ds: DeviceScene, view: LightView, alpha_tested: bool) -> DepthMap:
    """One closest-hit BVH ray per texel centre, unbounded in depth (the brute-force depth map)."""
    n = view.width * view.height
    flat = wp.empty(n, dtype=float, device=ds.device)
    none = wp.zeros(1, dtype=wp.int32, device=ds.device)
    launch_chunked(raycast_texels, n, inputs=[0, none, _occluders(ds, alpha_tested, ()), view.gpu(), 1.0e30], outputs=[flat],
                   device=ds.device)
    return DepthMap(view=view, depth=flat.reshape((view.height, view.width)), alpha_tested=alpha_tested, conservative=False)


def read_texels(gb: GBuffer, view: LightView, radius: int = 0) -> np.ndarray:
    """The texels (row-major indices, ascending, int32) the G-buffer's samples read in ``view``:
    each mapped sample's own texel and those within ``radius`` texels of it (a square window)."""
    dev = str(gb.pos.device)
    idx = wp.empty(gb.count, dtype=wp.int32, device=dev)
    launch_chunked(receiver_texels, gb.count, inputs=[view.gpu(), gb.gpu()], outputs=[idx], device=dev)
    idx = idx.numpy()
    mask = np.zeros((view.height, view.width), bool)
    mask.reshape(-1)[idx[idx >= 0]] = True
    for _ in range(int(radius)):  # grow by one texel per step, rows then columns
        grown = mask.copy()
        grown[1:] |= mask[:-1]
        grown[:-1] |= mask[1:]
        mask = grown.copy()
        mask[:, 1:] |= grown[:, :-1]
        mask[:, :-1] |= grown[:, 1:]
    return np.flatnonzero(mask.reshape(-1)).astype(np.int32)


def raycast_read(ds: DeviceScene, view: LightView, gb: GBuffer, alpha_tested: bool, excluded: tuple[int, ...] = (),
                 radius: int = 0) -> DepthMap:
    """The depth map of ``view`` at the texels :func:`read_texels` gives (one ray each, no deeper than
    the view's far depth, as the rasterizer draws); ``DEPTH_CLEAR`` at every other texel.
    ``excluded``: the prims that cast no shadow of the light (its ``collection:shadowLink``)."""
    dev = ds.device
    n = view.width * view.height
    flat = wp.empty(n, dtype=float, device=dev)
    launch_chunked(fill_depth, n, inputs=[DEPTH_CLEAR], outputs=[flat], device=dev, min_chunk=1 << 18)
    texels = read_texels(gb, view, radius)
    if len(texels):
        launch_chunked(raycast_texels, len(texels),
                       inputs=[1, wp.array(texels, dtype=wp.int32, device=dev), _occluders(ds, alpha_tested, tuple(excluded)), view.gpu(),
                               float(view.far)],
                       outputs=[flat], device=dev, min_chunk=256, per_thread=16)
    return DepthMap(view=view, depth=flat.reshape((view.height, view.width)), alpha_tested=bool(alpha_tested and ds.has_cutouts),
                    conservative=False, texels_read=int(len(texels)))
