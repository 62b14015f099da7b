"""``pcf``: percentage-closer filtering of the light's depth map (Reeves et al. 1987).

Each G-buffer sample is compared against the depth map at ``taps`` points of a square kernel of
``radius`` texels (a disk for the Poisson pattern) around its projection; the visibility is the
fraction of taps where the sample is not behind the stored depth. The depth bias
(``receiver_bias``):

* ``plane`` (the default): the sample's depth at each tap is that of its tangent plane at the
  tap's texel centre, nearer by ``plane_slope_bias`` times the plane's depth step per texel there
  (receiver-plane depth bias, :func:`~wsoft.lightspace.view.receiver_tap_depth`), so wide kernels
  do not shadow sloped receivers, and grazing ones (80-88 degrees from the light, where the map's
  own depth is off by a fraction of a texel's step) stay lit;
* ``normal``: the sample moved toward the light along its normal by ``normal_offset`` texels
  (times the kernel's half-width plus one), its own depth compared at every tap (normal offset);
* ``centre``: the sample's own depth at every tap, with a slope-scaled bias as in ``hard``.

``plane`` is the default by measurement (``wsoft.stages.grazing``, tests/test_grazing.py):
``normal`` needs an offset that grows with the kernel to keep a grazing plane lit, and that
offset lifts contact shadows off their casters; ``centre`` shadows wide kernels' sloped
receivers.

UsdLux shadow controls: the map holds only the light's casters (``collection:shadowLink``); with
a finite ``inputs:shadow:distance`` a tap's caster counts only when its point (the tap texel's
ray at the stored depth) lies within the distance of the receiver. Known limit, as ``hard``'s: a
map keeps the caster nearest the light, so one beyond the distance hides one behind it within
it; the render warns when a distance is in force.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import warp as wp

from wsoft.accel.filters import RECEIVER_BIASES, pcf_visibility, taps_on
from wsoft.lightspace.light import LightGPU, receiver_bias
from wsoft.lightspace.view import ViewGPU, map_coords, normal_offset, texel_size, view_dir
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_receiver
from wsoft.lightspace.paraboloid import OMNI_MAPS
from wsoft.params import LightViewParams, check_ranges
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param


SEAMS = ("guard", "lookup")  # how a cube map's filter crosses a face's edge (PCFParams.seams)


@dataclass(frozen=True)
class PCFParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map", range=(256, 8192))
    radius: float = param(2.0, "kernel half-width in texels", range=(0.0, 512.0))
    taps: int = param(16, "depth comparisons per sample (a perfect square for the grid pattern)", range=(1, 1024))
    pattern: str = param("grid", "tap pattern: grid (square kernel) or poisson (disk kernel)")
    bias: float = param(1e-4, "constant depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))
    receiver_bias: str = param("plane", "depth bias: plane (the receiver's tangent plane at each tap), normal (normal offset) or centre (slope-scaled, as hard)")
    plane_slope_bias: float = param(0.25, "receiver_bias=plane: texels of the tangent plane's depth step per texel taken off at each tap", range=(0.0, 16.0))
    normal_offset: float = param(1.0, "receiver_bias=normal: the offset along the normal in texels, times the kernel's half-width plus one", range=(0.0, 64.0))
    slope_bias: float = param(1.5, "receiver_bias=centre: slope-scaled bias in texels", range=(0.0, 64.0))

    omni: str = param("cube", "where a light's receivers call for more than one frustum (cube=auto or always): cube (six 90-degree faces) "
                              "or paraboloid (two hemispheres, drawn by one ray per texel; the receiver-plane bias; "
                              "wsoft.lightspace.paraboloid)", choices=OMNI_MAPS)
    seams: str = param("guard", "a cube map's face edges: guard (each face drawn with a guard band of the kernel's width) or lookup "
                                "(a tap past its face's edge reads the face its direction belongs to, as a cube-map sampler; "
                                "wsoft.accel.cube_filter; receiver_bias=plane)", choices=SEAMS)

    def __post_init__(self):
        check_ranges(self)
        check(self.seams == "guard" or self.receiver_bias == "plane", f"seams=lookup compares taps by the receiver's plane: receiver_bias "
              f"{self.receiver_bias!r} must be plane")
        check(self.pattern in ("grid", "poisson"), f"pattern {self.pattern!r} is not grid or poisson")
        check(self.receiver_bias in RECEIVER_BIASES, f"receiver_bias {self.receiver_bias!r} is not one of {', '.join(RECEIVER_BIASES)}")
        check(self.pattern != "grid" or math.isqrt(self.taps) ** 2 == self.taps, f"the grid pattern needs a square tap count, not {self.taps}")


@wp.kernel
def shade_pcf(
    offset: int,
    lv: ViewGPU,
    L: LightGPU,
    depth: wp.array2d[float],
    gb: GBufferGPU,
    taps: wp.array[wp.vec2],
    ntaps: int,
    disk: int,
    radius: float,
    bias: float,
    mode: int,
    plane_slope: float,
    offset_texels: float,
    slope_texels: float,
    dmax: float,
    # outputs
    vis: wp.array[float],
):
    i = wp.tid() + offset
    r = gb_receiver(lv, gb, i)
    if r[3] == 0.0:
        vis[i] = 1.0
        return
    p = gb.pos[i]
    pv = wp.vec3(r[0], r[1], r[2])
    nv = view_dir(lv, gb.nrm[i])
    b = bias
    if mode == 1:  # normal offset
        pv = normal_offset(lv, pv, nv, offset_texels * (radius + 1.0))
    elif mode == 2:  # the centre's depth, slope-scaled
        b = receiver_bias(lv, L, p, gb.nrm[i], pv[2], bias, slope_texels)
    half = texel_size(lv) * radius
    vis[i] = pcf_visibility(lv, depth, pv, nv, map_coords(lv, pv), half, disk, taps, ntaps, b, int(mode == 0), plane_slope, dmax)


class PCF(Technique):
    """Percentage-closer filtering with a fixed kernel."""

    name = "pcf"
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    summary = "percentage-closer filtering: fixed kernel, grid or Poisson taps, receiver-plane bias"
    Params = PCFParams
    passes = (PassSpec("shadow", reads=("gbuffer", "light_depth"), writes=("visibility",)),)
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"
    # a finite inputs:shadow:distance is tested against the caster the map keeps per texel
    distance_caveat = "the caster nearest the light in each texel of the depth map"
    quality = (Quality("taps", (4, 16, 64), "more taps: a smoother filter, linearly more time"),)
    # a fixed 2-texel kernel: nearly as hard as `hard`
    tolerance = Tolerance(mae=0.0075, mae_penumbra=0.3)
    cylinder_model = ("the shadow of its centre filtered over a fixed kernel (its size plays no part), in a light view that looks at the "
                      "receivers as a sphere light's does")

    def cube_guard_texels(self) -> float:
        """Its kernel's half-width and the bilinear tap's texel (``seams=lookup``: the texel alone;
        taps past a face's edge read the neighbouring face)."""
        return 2.0 if self.params.seams == "lookup" else float(self.params.radius) + 2.0

    def add_cube_passes(self, ctx, light, faces):
        """``seams=guard``: the taps on each face's own map (:meth:`Technique.add_cube_passes`);
        ``seams=lookup``: one pass over every face's map, each tap read from the face its direction
        belongs to (:func:`~wsoft.accel.cube_filter.shade_pcf_cube`)."""
        p = self.params
        if p.seams == "guard":
            return super().add_cube_passes(ctx, light, faces)
        from wsoft.accel.cube_filter import shade_pcf_cube
        from wsoft.lightspace.cube import cube_frame, vec6i
        from wsoft.lightspace.view import ViewGPU

        gbuf = ctx.gbuffer()
        depths = [ctx.light_depth(f, size=p.shadow_map_size, view=p.view) for f in faces]
        out = ctx.visibility_key(light)
        frame = cube_frame(light)
        name = ctx.pass_name("pcf_cube_lookup", light)

        def run(res):
            gb = res[gbuf]
            maps = {f.face: res[k] for f, k in zip(faces, depths)}
            first = next(iter(maps.values()))
            slots = [k if k in maps else -1 for k in range(6)]
            views = wp.array([maps.get(k, first).view.gpu() for k in range(6)], dtype=ViewGPU, device=ctx.device)
            arrays = [maps.get(k, first).depth for k in range(6)]
            taps = taps_on(ctx.device, p.pattern, p.taps)
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            face_of = wp.empty(gb.count, dtype=wp.int32, device=ctx.device)
            ext = first.view.extent
            launch_chunked(
                shade_pcf_cube, gb.count,
                inputs=[views, vec6i(*slots), wp.mat33(*frame.T.ravel()), *arrays, gb.gpu(), taps.array, taps.count,
                        int(p.pattern == "poisson"), p.radius, p.bias * ext, p.plane_slope_bias, light.shadow_distance,
                        float(1e-7 * ctx.ctx.scene.diagonal)],
                outputs=[vis, face_of], device=ctx.device, min_chunk=256,
            )
            ctx.ctx.report_cube_faces(ctx, light, faces, face_of, sum(m.view.width * m.view.height for m in maps.values()), name)
            return {out: ctx.visibility(vis)}

        return ctx.add_pass(name, inputs=(gbuf, *depths), outputs=(out,), run=run, stage="shadow", light=light)

    def add_paraboloid_passes(self, ctx, light):
        """The light's dual-paraboloid map (``omni=paraboloid``): the same taps over ``radius`` texels of its hemisphere's map."""
        p = self.params
        return self.paraboloid_shadow(ctx, light, size=p.shadow_map_size, pattern=p.pattern, taps=p.taps, radius=p.radius, bias=p.bias,
                                      plane_slope=p.plane_slope_bias)

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        depth = ctx.light_depth(light, size=p.shadow_map_size, view=p.view)
        out = ctx.visibility_key(light)
        L = ctx.light_gpu(light)

        def run(res):
            gb, dm = res[gbuf], res[depth]
            bias = p.bias * dm.view.extent
            taps = taps_on(ctx.device, p.pattern, p.taps)
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            launch_chunked(
                shade_pcf, gb.count,
                inputs=[dm.view.gpu(), L, dm.depth, gb.gpu(), taps.array, taps.count, int(p.pattern == "poisson"),
                        p.radius, bias, RECEIVER_BIASES.index(p.receiver_bias), p.plane_slope_bias, p.normal_offset, p.slope_bias,
                        light.shadow_distance],
                outputs=[vis], device=ctx.device, min_chunk=256,
            )
            return {out: ctx.visibility(vis)}

        name = ctx.pass_name("pcf", light)
        return ctx.add_pass(name, inputs=(gbuf, depth), outputs=(out,), run=run, stage="shadow", light=light)
