"""``skymaps``: the sky's shadow from many directional shadow maps, the classic answer of engines
without ray tracing, on a DomeLight.

``directions`` directions toward the sky (:func:`~wsoft.lightspace.sky.sky_directions`): a
constant dome gets directions of equal solid angle over the whole sphere (a spherical Fibonacci
lattice turned by ``seed``), equal weights; a latlong texture gets draws in proportion to luminance x
solid angle (stratified), each weighted by its luminance over its pdf, so each direction stands for
the radiance of its share of the sky. Each direction is a distant light of zero angle whose depth
map (``shadow_map_size`` texels a side) is drawn and fitted to the receivers in view as a
DistantLight's (:meth:`~wsoft.pipeline.context.RenderContext.light_depth`: the dome's
``collection:shadowLink`` casters only), and filtered by percentage-closer filtering (``taps``
taps of a grid over ``filter_radius`` texels, the receiver's tangent plane at each tap). Per
receiver of normal n::

    V = sum_k a_k max(0, n . w_k) vis_k / sum_k a_k max(0, n . w_k)

(:mod:`wsoft.lightspace.sky`): exact when the receiver sees the whole sky, and the dome reference's
quantity as the directions grow. A receiver outside a direction's map is lit from it. Directions
below the horizon count too (a wall sees the ground's side of the sphere, and the ground shadows
it). Few directions give banded shadows (one hard shadow per direction, softened only by the
filter), the price of its speed. Measured on a box on a ground under a constant dome (96 x 72,
256-texel maps, against 1024 cosine rays): MAE 0.033, 0.010, 0.0034 at 16, 64, 256 directions;
under a sky with a sun, 0.019 and 0.007 at 16 and 64 (``docs/techniques.md``).

UsdLux shadow controls: ``collection:shadowLink`` (each map holds the dome's casters) and a finite
``inputs:shadow:distance`` (a tap's caster counts only within it, the nearest caster per texel as
``hard``'s) are honoured.

Counters: ``directions``, ``effective_directions`` (Kish's n_eff of the weights: the set's size for a
constant dome, fewer where a texture's weights vary), ``texels`` (over all maps).

Example::

    frame = wsoft.render(scene, "skymaps", width=640, height=480, directions=64, shadow_map_size=512)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.filters import pcf_visibility, taps_on
from wsoft.lightspace.sky import effective_count, sky_directions, sky_ratio
from wsoft.lightspace.view import ViewGPU, texel_size, view_dir
from wsoft.params import check_ranges
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered, gb_mapped_receiver
from wsoft.scene.dome import is_dome
from wsoft.scene.types import LIGHT_DISTANT
from wsoft.techniques.base import PassSpec, Quality, Technique, check, param


MAX_TEXELS = 2**28  # every direction's map is held until the shadow pass: 1 GiB of float32 at most


@dataclass(frozen=True)
class SkyMapsParams:
    directions: int = param(64, "directions toward the sky, one distant-light shadow map each", range=(16, 256))
    shadow_map_size: int = param(512, "texels per side of each direction's depth map", range=(256, 4096))
    taps: int = param(9, "percentage-closer filter taps per direction (a square grid)", range=(1, 64))
    filter_radius: float = param(1.5, "half-width of the filter in texels", range=(0.0, 64.0))
    bias: float = param(1e-4, "constant depth bias as a fraction of the frame's extent", range=(0.0, 0.1))
    plane_slope_bias: float = param(0.25, "texels of the receiver's tangent-plane depth step per texel taken off at each tap",
                                    range=(0.0, 16.0))
    seed: int = param(0, "seed of the directions (the constant dome's lattice turn, a texture's strata shifts)", range=(0, 2**31 - 1))

    def __post_init__(self):
        check_ranges(self)
        check(math.isqrt(self.taps) ** 2 == self.taps, f"taps {self.taps} is not a square (the grid pattern)")
        texels = self.directions * self.shadow_map_size ** 2
        check(texels <= MAX_TEXELS, f"directions x shadow_map_size^2 = {texels} texels (float32, all held at once) exceeds {MAX_TEXELS} "
                                    f"(1 GiB): fewer directions or smaller maps")


@wp.kernel
def accumulate_direction(
    offset: int,
    lv: ViewGPU,
    depth: wp.array2d[float],
    gb: GBufferGPU,
    w: wp.vec3,
    weight: float,
    taps: wp.array[wp.vec2],
    ntaps: int,
    radius_texels: float,
    bias: float,
    plane_slope: float,
    dmax: float,
    # outputs
    num: wp.array[float],
    den: wp.array[float],
):
    """Add one direction's share to each receiver's sums: ``den += weight cos``, ``num += weight cos
    vis`` (cos = max(0, n . w); vis the filtered map's lit fraction, 1 outside the map)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        return
    c = wp.dot(gb.nrm[i], w)
    if c <= 0.0:
        return
    mapped, pv, m, t = gb_mapped_receiver(lv, gb, i)
    v = float(1.0)
    if mapped:
        ts = texel_size(lv)
        v = pcf_visibility(lv, depth, pv, view_dir(lv, gb.nrm[i]), m, ts * radius_texels, 0, taps, ntaps, bias, 1, plane_slope, dmax)
    den[i] = den[i] + weight * c
    num[i] = num[i] + weight * c * v


def direction_light(dome, k: int, w: np.ndarray):
    """The distant light (zero angle) of direction ``k`` of ``dome``: it emits along ``-w`` (its frame's Z is ``w``), the dome's shadow controls."""
    z = np.asarray(w, np.float64)
    a = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return dataclasses.replace(dome, path=f"{dome.path}_sky{k:03d}", kind=LIGHT_DISTANT, frame=np.stack([x, y, z], axis=1), angle_deg=0.0,
                               dome=None)


class SkyMaps(Technique):
    """Many directional shadow maps toward the sky, each PCF-filtered, weighted by the radiance each
    direction stands for and the receiver's cosine."""

    name = "skymaps"
    summary = ("N distant-light shadow maps toward the sky (equal solid angle, or importance by a texture's radiance), PCF each, "
               "V the radiance- and cosine-weighted lit fraction; dome lights only")
    Params = SkyMapsParams
    passes = (PassSpec("shadow", reads=("gbuffer", "light_depth"), writes=("visibility",)),)
    quality = (Quality("directions", (16, 64, 256), "more directions: smoother, truer penumbrae; a map and its time per direction"),
               Quality("shadow_map_size", (256, 512, 1024), "finer maps: contact shadows kept; time and memory per map"))
    quick_params = {"directions": 16, "shadow_map_size": 256}
    size_param = "shadow_map_size"
    dome_refusal = ""
    cylinder_model = "none: it shadows a DomeLight alone (a cylinder light is declined)"
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    horizon = "exact"  # the cosine weights bound each receiver's hemisphere
    cube_refusal = "its maps are distant views of the sky, one per direction: no cube map"
    distance_caveat = "the caster nearest the sky in each texel of each direction's depth map"
    not_dome = "skymaps shadows only a DomeLight (the sky): use hard, pcss, rtdenoise or another technique for this light"

    def supports(self, scene, light) -> str | None:
        if not is_dome(light):  # the light's kind first: no other reason applies to a light it never renders
            return self.not_dome
        return super().supports(scene, light)

    def cube_guard_texels(self) -> float:
        return max(2.0, self.params.filter_radius + 1.0)

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        sky = sky_directions(light, p.directions, p.seed)
        lights = [direction_light(light, k, w) for k, w in enumerate(sky.dirs)]
        depths = [ctx.light_depth(dl, size=p.shadow_map_size) for dl in lights]
        out = ctx.visibility_key(light)

        def run(res):
            gb = res[gbuf]
            n = gb.count
            num = wp.zeros(n, dtype=float, device=ctx.device)
            den = wp.zeros(n, dtype=float, device=ctx.device)
            taps = taps_on(ctx.device, "grid", p.taps)
            radius = p.filter_radius if p.taps > 1 else 0.0
            g = gb.gpu()
            for k, key in enumerate(depths):
                if sky.weights[k] <= 0.0:
                    continue
                dm = res[key]
                w = sky.dirs[k]
                launch_chunked(accumulate_direction, n,
                               inputs=[dm.view.gpu(), dm.depth, g, wp.vec3(*w), float(sky.weights[k]), taps.array, taps.count, radius,
                                       p.bias * dm.view.extent, p.plane_slope_bias, light.shadow_distance],
                               outputs=[num, den], device=ctx.device, min_chunk=256)
            vis = wp.empty(n, dtype=float, device=ctx.device)
            launch_chunked(sky_ratio, n, inputs=[num, den], outputs=[vis], device=ctx.device)
            ctx.counters(light).update(directions=sky.count, effective_directions=round(effective_count(sky.weights), 1),
                                       texels=sky.count * p.shadow_map_size ** 2)
            return {out: ctx.visibility(vis)}

        return ctx.add_pass(ctx.pass_name("skymaps", light), inputs=(gbuf, *depths), outputs=(out,), run=run, stage="shadow", light=light)
