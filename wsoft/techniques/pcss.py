"""``pcss``: percentage-closer soft shadows (Fernando 2005).

1. Blocker search: ``blocker_samples`` taps over the region in which any caster could cover
   part of the light, from the nearest caster depth in the map to the receiver (a rectangle for
   a rect light, a disk for disk, sphere and distant lights); taps nearer than the receiver's
   plane (:func:`~wsoft.lightspace.view.receiver_tap_depth`: the plane's depth at the tap's
   texel centre, nearer by ``plane_slope_bias`` times its depth step per texel, so a receiver at
   80-88 degrees from the light finds no blocker in itself) are blockers, and their depths are
   averaged.
2. Penumbra: the region over which a blocker at the average depth covers the light — for a
   local light of half-extent w, w (1/z_blocker - 1/z_receiver) in the map's tangent units; for
   a distant light of cone half-angle a, (z_receiver - z_blocker) tan a.
3. PCF with ``filter_samples`` taps over that region, shaped like the light, with the
   receiver-plane depth at each tap.

A light across the receiver's tangent plane: only its front part lights the receiver
(:mod:`wsoft.lightspace.halfspace`). The blocker search and the filter move to that part's
bounding window (:func:`~wsoft.lightspace.halfspace.kernel_front`) and V is the window's visible
fraction times the part's share of the light: exact for a rect light cut along an axis,
approximate for an oblique cut or a disk; a light wholly in front keeps the kernel as it is.

Exact for a planar occluder parallel to a planar receiver and light (the test scene
``box_plane``); it underestimates the umbra when blockers at different depths overlap (the
average depth is too near), which a test pins.

UsdLux shadow controls: the map holds only the light's casters (``collection:shadowLink``); with
a finite ``inputs:shadow:distance`` a tap (blocker search and filter alike) counts its caster only
when the caster's point (the tap texel's ray at the stored depth) lies within the distance of the
receiver, so the average blocker depth and the penumbra are those of the casters in reach. Known
limit, as ``hard``'s: the map keeps the caster nearest the light; the render warns when a
distance is in force.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.filters import taps_on
from wsoft.accel.pcss_filter import pcss_filter
from wsoft.lightspace.light import CYLINDER_KERNEL, LightKernel, light_kernel
from wsoft.lightspace.view import DEPTH_CLEAR, ViewGPU, view_dir
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_receiver
from wsoft.params import LightViewParams, check_ranges
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param


@dataclass(frozen=True)
class PCSSParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map", range=(256, 8192))
    blocker_samples: int = param(16, "taps of the blocker search", range=(1, 1024))
    filter_samples: int = param(36, "taps of the percentage-closer filter", range=(1, 4096))
    pattern: str = param("grid", "tap pattern: grid (perfect-square counts) or poisson")
    bias: float = param(1e-4, "constant depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))
    plane_slope_bias: float = param(0.25, "texels of the receiver's tangent-plane depth step per texel taken off at each tap (search and filter)", range=(0.0, 16.0))
    min_radius: float = param(1.0, "smallest filter half-width in texels", range=(0.0, 512.0))
    max_radius: float = param(256.0, "largest blocker-search and filter half-width in texels", range=(0.0, 4096.0))

    def __post_init__(self):
        check_ranges(self)
        check(self.pattern in ("grid", "poisson"), f"pattern {self.pattern!r} is not grid or poisson")
        if self.pattern == "grid":
            for n in (self.blocker_samples, self.filter_samples):
                check(math.isqrt(n) ** 2 == n, f"the grid pattern needs square sample counts, not {n}")
        check(self.min_radius <= self.max_radius, "need min_radius <= max_radius")


@wp.kernel
def shade_pcss(
    offset: int,
    lv: ViewGPU,
    k: LightKernel,
    depth: wp.array2d[float],
    gb: GBufferGPU,
    btaps: wp.array[wp.vec2],
    nb: int,
    ftaps: wp.array[wp.vec2],
    nf: int,
    z_caster_min: float,
    bias: float,
    plane_slope: float,
    min_radius: float,
    max_radius: float,
    dmax: float,
    # outputs
    vis: wp.array[float],
    blockers: wp.array[float],
):
    i = wp.tid() + offset
    blockers[i] = 0.0
    r = gb_receiver(lv, gb, i)
    if r[3] == 0.0:
        vis[i] = 1.0
        return
    pv = wp.vec3(r[0], r[1], r[2])
    res = pcss_filter(lv, k, depth, pv, view_dir(lv, gb.nrm[i]), btaps, nb, ftaps, nf, z_caster_min, bias, 0.0, plane_slope, min_radius,
                      max_radius, dmax)
    vis[i] = res[0]
    blockers[i] = res[1]


class PCSS(Technique):
    """Percentage-closer soft shadows: blocker search, penumbra estimate, light-shaped PCF."""

    name = "pcss"
    distant_angle_limit = 70.0  # max point error 0.093 at 70 degrees, 0.126 at 80
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    summary = "percentage-closer soft shadows: blocker search, penumbra from the average blocker depth, light-shaped PCF"
    Params = PCSSParams
    passes = (PassSpec("shadow", reads=("gbuffer", "light_depth"), writes=("visibility",)),)
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"
    # a finite inputs:shadow:distance is tested against the caster the map keeps per texel
    distance_caveat = "the caster nearest the light in each texel of the depth map"
    ellipsoid_caveat = "its bounding sphere (blocker search and filter kernel sized by its largest semi-axis)"

    quality = (Quality("filter_samples", (16, 36, 100), "more filter taps: smoother penumbrae, linearly more time"),)
    tolerance = Tolerance(mae=0.0025, mae_penumbra=0.06)
    cylinder_model = CYLINDER_KERNEL

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        depth = ctx.light_depth(light, size=p.shadow_map_size, soft=True, view=p.view)
        out = ctx.visibility_key(light)

        def run(res):
            gb, dm = res[gbuf], res[depth]
            bias = p.bias * dm.view.extent
            d = dm.depth.numpy()
            covered = d[d < DEPTH_CLEAR]
            z_min = float(covered.min()) if covered.size else float(dm.view.far)
            ctx.counters(light)["nearest_caster_depth"] = z_min
            bt = taps_on(ctx.device, p.pattern, p.blocker_samples)
            ft = taps_on(ctx.device, p.pattern, p.filter_samples)
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            blk = wp.empty(gb.count, dtype=float, device=ctx.device)
            launch_chunked(
                shade_pcss, gb.count,
                inputs=[dm.view.gpu(), light_kernel(light, dm.view), dm.depth, gb.gpu(), bt.array, bt.count, ft.array, ft.count,
                        z_min, bias, p.plane_slope_bias, p.min_radius, p.max_radius, light.shadow_distance],
                outputs=[vis, blk], device=ctx.device, min_chunk=256,
            )
            ctx.counters(light)["samples_with_blockers"] = int(np.count_nonzero(blk.numpy()))
            return {out: ctx.visibility(vis)}

        name = ctx.pass_name("pcss", light)
        return ctx.add_pass(name, inputs=(gbuf, depth), outputs=(out,), run=run, stage="shadow", light=light)
