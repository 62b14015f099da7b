"""``vsmap``: virtual shadow maps with a PCF lookup, as engines ship them for large worlds (Unreal
Engine 5's Virtual Shadow Maps; Blender EEVEE's shadows). ``vsm`` is the variance shadow map.

Per light a virtual depth map of ``virtual_size`` texels a side (16384 by default) in pages of
``page_size`` texels (128): a distant light has ``clip_levels`` clipmap levels around the camera,
each a ``virtual_size`` map twice as wide as the one before (level 0 ``first_extent`` world units
wide; 0: the last level spans 16 scene diagonals); a rect, disk or sphere light one perspective
map over its fitted light view, with mips. Each covered pixel asks for the page at the level whose
texel is at most its footprint (``lod_bias`` -1: log2 of texel over footprint), with the pages
under the filter's reach; only those pages are drawn, into a pool of at most ``pool_pages``
physical pages (2048 by default: 128 MiB of float32 at 128-texel pages; it grows as pages are
asked for). When more are asked for than the pool holds, the
finest level's requests move to the level above (counter ``overflow_pages``, one warning), and a
lookup reads the finest level that holds a page there: coarser, never a hole. In a sequence the
pages stay resident and are reused while valid: all of a light's pages go when the light (or the
levels' frame) moves, a page goes when a dynamic caster moved within it, and pages nobody asked
for are evicted least recently used first when the pool is full
(:mod:`wsoft.accel.virtual_pages`).

The lookup is PCF over ``taps`` grid taps within ``radius`` texels of the level the pixel reads,
each compared by the receiver's tangent plane at the tap's texel centre (the receiver-plane depth
bias of ``pcf``, nearer by ``plane_slope_bias`` depth steps per texel) less ``bias``. Like ``pcf``
it is the shadow of the light's centre, filtered: its penumbrae do not widen with the light.

Counters (``frame.counters()``): ``requested``, ``rendered``, ``reused``, ``evicted``,
``invalidated``, ``overflow_pages``, ``resident``, ``pool_pages``, ``dense_pages`` (the pages of
every level's full map), ``tiles_drawn``, ``unmapped_samples``, ``pool_mib``.

Refused: point lights, lights whose receivers need more than one frustum (a cube map), and a
finite ``inputs:shadow:distance``.

Example::

    frame = wsoft.render("city", "vsmap", width=640, height=480, pool_pages=4096)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import warp as wp

from wsoft.accel.virtual_pages import UNMAPPED, VirtualMapGPU, level_texel, level_view, virtual_depth
from wsoft.accel.virtual_passes import add_page_pass, report_unmapped
from wsoft.lightspace.view import map_coords, receiver_tap_depth, view_dir, view_of
from wsoft.params import check_ranges
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU
from wsoft.techniques._virtual import VirtualMapTechnique
from wsoft.techniques.base import PassSpec, Quality, Tolerance, check, param


@dataclass(frozen=True)
class VSMapParams:
    virtual_size: int = param(16384, "texels a side of each level's virtual map (a local light's finest mip)", range=(256, 1 << 20))
    page_size: int = param(128, "texels a side of a page", range=(16, 1024))
    pool_pages: int = param(2048, "physical pages in the pool (each page_size^2 float32)", range=(1, 1 << 20))
    clip_levels: int = param(16, "distant lights: clipmap levels around the camera", range=(1, 24))
    first_extent: float = param(0.0, "distant lights: world width of level 0 (0: the last level spans 16 scene diagonals)", range=(0.0, 1e12))
    lod_bias: float = param(-1.0, "log2 of a page texel over the pixel footprint a sample asks for (negative: finer pages, more of them)",
                            range=(-8.0, 8.0))
    footprint: float = param(0.0, "world units every sample asks texels for (with lod_bias), as a bake needs (it has no camera); 0: "
                                  "each pixel's footprint", range=(0.0, 1e12))
    radius: float = param(1.5, "PCF kernel half-width in texels of the level read", range=(0.0, 16.0))
    taps: int = param(9, "PCF taps (a perfect square: a grid)", range=(1, 256))
    bias: float = param(1e-5, "constant depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))
    plane_slope_bias: float = param(0.25, "texels of the tangent plane's depth step per texel taken off at each tap", range=(0.0, 16.0))

    def __post_init__(self):
        check_ranges(self)
        check(self.virtual_size % self.page_size == 0 and self.virtual_size >= self.page_size,
              f"virtual_size {self.virtual_size} must be a multiple of page_size {self.page_size}")
        check(math.isqrt(self.taps) ** 2 == self.taps, f"taps must be a perfect square, not {self.taps}")
        n = self.virtual_size // self.page_size
        check(n & (n - 1) == 0, f"virtual_size / page_size must be a power of two, not {n}")


@wp.kernel
def shade_vsmap(
    offset: int,
    vm: VirtualMapGPU,
    gb: GBufferGPU,
    level_of: wp.array[wp.int32],
    side: int,
    radius: float,
    bias: float,
    plane_slope: float,
    # outputs
    vis: wp.array[float],
    unmapped: wp.array[wp.int32],
):
    """PCF through the page table: ``side`` x ``side`` taps over +-``radius`` texels of the sample's level."""
    i = wp.tid() + offset
    k = level_of[i]
    unmapped[i] = 0
    if k < 0:
        vis[i] = 1.0
        if k == -1 and gb.prim[i] >= 0:
            unmapped[i] = 1
        return
    v = view_of(vm.view, gb.pos[i])
    nv = view_dir(vm.view, gb.nrm[i])
    m0 = map_coords(vm.view, v)
    t = level_texel(vm, k)
    lit = float(0.0)
    miss = int(0)
    for a in range(side):
        for b in range(side):
            ox = float(0.0)
            oy = float(0.0)
            if side > 1:
                ox = (2.0 * float(a) / float(side - 1) - 1.0) * radius
                oy = (2.0 * float(b) / float(side - 1) - 1.0) * radius
            m = wp.vec2(m0[0] + ox * t, m0[1] + oy * t)
            dl = virtual_depth(vm, k, m)
            if dl[0] == UNMAPPED:
                miss += 1
                lit += 1.0
                continue
            lv = level_view(vm, int(dl[1]))
            zr = receiver_tap_depth(lv, v, nv, m, plane_slope) - bias
            if zr <= dl[0]:
                lit += 1.0
    if miss > 0 and vm.view.persp == 0:  # a local light's taps past its view's edge read nothing, as any map's
        unmapped[i] = 1
    vis[i] = lit / float(side * side)


class VSMap(VirtualMapTechnique):
    """Virtual shadow maps (clipmaps / mips in pages, a cached physical pool) with a PCF lookup."""

    name = "vsmap"
    summary = "virtual shadow map: 16K^2 clipmap/mip levels in 128^2 pages, only requested pages drawn and cached; PCF lookup"
    Params = VSMapParams
    passes = (PassSpec("pages", reads=("scene", "gbuffer"), optional=("light_view",), writes=("virtual_pages",)),
              PassSpec("shadow", reads=("gbuffer", "virtual_pages"), writes=("visibility",)))
    quick_params = {"virtual_size": 2048, "pool_pages": 256}
    size_param = "virtual_size"
    quality = (Quality("lod_bias", (0.0, -1.0, -2.0, -3.0), "finer pages: sharper edges, up to 4x the pages per step"),)
    # the light's centre filtered over a 3-texel kernel: a hard shadow's penumbra error
    tolerance = Tolerance(mae=0.006, mae_penumbra=0.2)
    horizon = "centre"
    point_refusal = "a virtual map here is one perspective map a light; a point light needs six (use pcf or pcss)"
    cube_refusal = "a virtual map here is one perspective map a light; receivers all around a light need a cube map (use pcf or pcss)"

    def add_passes(self, ctx, light):
        p = self.params
        side = math.isqrt(p.taps)
        pages = add_page_pass(self, ctx, light, reach_texels=p.radius + 1.0, soft=False)
        gbuf = ctx.gbuffer()
        out = ctx.visibility_key(light)
        name = ctx.pass_name("vsmap", light)

        def run(res):
            gb, vp = res[gbuf], res[pages]
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            unmapped = wp.empty(gb.count, dtype=wp.int32, device=ctx.device)
            launch_chunked(shade_vsmap, gb.count, inputs=[vp["map"], gb.gpu(), vp["level_of"], side, float(p.radius), p.bias * vp["extent"],
                                                          p.plane_slope_bias], outputs=[vis, unmapped], device=ctx.device, min_chunk=256)
            report_unmapped(ctx, light, name, unmapped)
            return {out: ctx.visibility(vis)}

        return ctx.add_pass(name, inputs=(gbuf, pages), outputs=(out,), run=run, stage="shadow", light=light)
