"""``hard``: the classic shadow map, from the light's centre. The template for new techniques.

A depth map is rasterized from the light's centre (alpha-tested when the scene has
cutouts); each G-buffer sample is lit when its light-space depth, less a bias, is not
behind the stored depth of its texel. The bias (``receiver_bias``): ``plane`` (the default)
compares the receiver's tangent plane at the texel's centre, where the map was sampled, nearer by
``plane_slope_bias`` times the plane's depth step per texel
(:func:`~wsoft.lightspace.view.receiver_tap_depth`, as ``pcf``'s taps), which holds at grazing
incidence (a floor 88-90 degrees off a lamp's rays); ``centre`` compares the receiver's own depth
less ``slope_bias`` texels times the tangent of its incidence, capped at 10 (beyond 84 degrees
such a floor stripes). The result is binary and matches the reference
with one sample at the light's centre.

Which texels are drawn (``map_texels``): ``all`` rasterizes the whole map; ``read`` draws only the
texel each receiver reads, one BVH ray through its centre (:func:`~wsoft.raster.raycast.raycast_read`:
the nearest caster there, as the rasterizer finds it, up to texel centres on a triangle's edge),
the rest of the map left empty; ``auto`` (the default) reads where the light's casting triangles,
instances placed, outnumber the frame's samples :data:`READ_FACTOR` to one (an instanced forest of
56M placed triangles at 640 x 480: 0.2 s of rays against 2.8-4.6 s of rasterizing,
``reports/instancing.md``), and rasterizes otherwise.

UsdLux shadow controls: the map holds only the light's casters (``collection:shadowLink``); with
a finite ``inputs:shadow:distance`` the texel's caster shadows only when it lies within the
distance of the receiver along the receiver's ray to the light's centre (exact:
(z - d) |p| / z in light space). Known limit: the map keeps the caster *nearest the light*, so a
caster beyond the distance hides one behind it within the distance (and a closed caster is
measured from its surface facing the light); the render warns when a distance is in force.

Example::

    frame = wsoft.render(scene, "hard", width=640, height=480, shadow_map_size=2048)
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from wsoft.lightspace.light import LightGPU, receiver_bias
from wsoft.lightspace.view import ViewGPU, light_facing, receiver_tap_depth, view_dir, within_distance
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_mapped_receiver
from wsoft.lightspace.paraboloid import OMNI_MAPS
from wsoft.errors import ParameterError
from wsoft.params import LightViewParams, check_ranges
from wsoft.techniques.base import PassSpec, Technique, Tolerance, param


READ_FACTOR = 16  # map_texels=auto: rays for the read texels where the casting triangles outnumber the samples this many to one


@dataclass(frozen=True)
class HardParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map", range=(256, 8192))
    bias: float = param(1e-4, "constant depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))
    slope_bias: float = param(1.5, "receiver_bias=centre: slope-scaled depth bias in texels (times tan of the incidence angle, capped at 10)",
                              range=(0.0, 64.0))
    receiver_bias: str = param("plane", "depth bias: plane (the receiver's tangent plane at the texel's centre) or centre (its own depth, "
                                        "slope-scaled)", choices=("plane", "centre"))
    plane_slope_bias: float = param(0.25, "receiver_bias=plane: texels of the tangent plane's depth step per texel taken off", range=(0.0, 16.0))
    conservative: bool = param(False, "conservative rasterization: every texel a triangle touches")
    map_texels: str = param("auto", "texels of the depth map drawn: all (rasterized), read (only those the receivers read, one BVH ray "
                                    "each: the same depths at their centres; wsoft.raster.raycast), or auto (read where the light's "
                                    "casting triangles, instances placed, outnumber the frame's samples "
                                    f"{READ_FACTOR} to one)", choices=("auto", "all", "read"))

    omni: str = param("cube", "where a light's receivers call for more than one frustum (cube=auto or always): cube (six 90-degree faces) "
                              "or paraboloid (two hemispheres, drawn by one ray per texel; the receiver-plane bias; "
                              "wsoft.lightspace.paraboloid)", choices=OMNI_MAPS)
    def __post_init__(self):
        check_ranges(self)
        if self.map_texels == "read" and self.conservative:
            raise ParameterError("hard: map_texels=read draws texel centres; conservative=true needs the rasterizer (map_texels=all or auto)")


@wp.kernel
def shade_hard(
    offset: int,
    lv: ViewGPU,
    L: LightGPU,
    depth: wp.array2d[float],
    gb: GBufferGPU,
    bias: float,
    slope_texels: float,
    use_plane: int,
    plane_slope: float,
    dmax: float,
    # outputs
    vis: wp.array[float],
):
    i = wp.tid() + offset
    mapped, v, m, t = gb_mapped_receiver(lv, gb, i)
    if not mapped:
        vis[i] = 1.0  # background, or outside the light's view: nothing between it and the light was mapped
        return
    x = int(wp.floor(t[0]))
    y = int(wp.floor(t[1]))
    zr = v[2] - receiver_bias(lv, L, gb.pos[i], gb.nrm[i], v[2], bias, slope_texels)
    if use_plane != 0:
        zr = receiver_tap_depth(lv, v, light_facing(lv, v, view_dir(lv, gb.nrm[i])), m, plane_slope) - bias
    d = depth[y, x]
    blocked = zr > d
    if blocked and dmax >= 0.0:  # inputs:shadow:distance: a caster farther from the receiver does not count
        blocked = within_distance(lv, v, m, d, dmax)
    vis[i] = wp.where(blocked, 0.0, 1.0)


class Hard(Technique):
    """Classic (hard) shadow map from the light's centre."""

    name = "hard"
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    summary = "classic shadow map from the light's centre (binary visibility)"
    Params = HardParams
    passes = (PassSpec("shadow", reads=("gbuffer", "light_depth"), writes=("visibility",)),)
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"
    # a finite inputs:shadow:distance is tested against the caster the map keeps per texel
    distance_caveat = "the caster nearest the light in each texel of the depth map"
    # a binary shadow of the light's centre: right in the umbra and the fully lit region, wrong by
    # up to 1 in the penumbra (about half of it on box_plane)
    tolerance = Tolerance(mae=0.009, mae_penumbra=0.36)
    horizon = "centre"  # binary: dark where the light's centre is behind the receiver's plane
    cylinder_model = "the shadow of its centre (its size plays no part), in a light view that looks at the receivers as a sphere light's does"

    def reads_texels(self, ctx, light) -> bool:
        """Does the light's depth map draw only the texels the receivers read (``map_texels``)?"""
        p = self.params
        if p.map_texels != "auto":
            return p.map_texels == "read"
        if p.conservative:
            return False
        casting = ctx.scene.casting_mask(light)
        triangles = ctx.scene.total_triangles if casting is None or ctx.scene.instanced else int(casting.sum())
        return triangles > READ_FACTOR * ctx.width * ctx.height * ctx.pixel_samples

    def add_paraboloid_passes(self, ctx, light):
        """The light's dual-paraboloid map (``omni=paraboloid``): one texel per receiver, its tangent plane's distance along the texel's direction."""
        p = self.params
        return self.paraboloid_shadow(ctx, light, size=p.shadow_map_size, pattern="grid", taps=1, radius=0.0, bias=p.bias,
                                      plane_slope=p.plane_slope_bias)

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        depth = ctx.light_depth(light, size=p.shadow_map_size, conservative=p.conservative, view=p.view,
                                read=0 if self.reads_texels(ctx, light) else None)
        out = ctx.visibility_key(light)
        L = ctx.light_gpu(light)

        def run(res):
            gb, dm = res[gbuf], res[depth]
            bias = p.bias * dm.view.extent
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            launch_chunked(shade_hard, gb.count, inputs=[dm.view.gpu(), L, dm.depth, gb.gpu(), bias, p.slope_bias,
                                                          int(p.receiver_bias == "plane"), p.plane_slope_bias, light.shadow_distance],
                           outputs=[vis], device=ctx.device)
            return {out: ctx.visibility(vis)}

        name = ctx.pass_name("hard", light)
        return ctx.add_pass(name, inputs=(gbuf, depth), outputs=(out,), run=run, stage="shadow", light=light)
