"""``smrt``: shadow-map ray tracing over a virtual shadow map (Unreal Engine 5's SMRT; Blender
EEVEE's shadow tracing), for soft shadows whose penumbrae widen with the distance to the caster.

The light's virtual map is that of ``vsmap`` (:mod:`wsoft.accel.virtual_pages`: clipmap levels for
a distant light, one perspective map with mips for a rect, disk or sphere light; pages requested
from the G-buffer, drawn into a cached pool). Per pixel, ``rays`` rays go from the receiver toward
points on the light (its area, or a distant light's cone), each direction at most
``max_ray_angle`` radians off the direction to the light's centre (the penumbra cap). A ray is
followed across the map for at most ``ray_texels`` texels of the receiver's level (where a
distant light's rays run that far), and no nearer the light than its view's near plane. It is
marched from its far end back to the receiver in ``samples`` steps (spaced by the square of the
step: denser near the receiver), each step comparing the ray's light-space depth with the map's
depth under it:

* the first step (the ray's far end) is a plain shadow-map test: a depth nearer the light there
  blocks the ray (a caster beyond the ray's reach casts a hard shadow from that point);
* a later step whose stored depth lies nearer the light than the ray by more than the ray's own
  depth change since the last step is *behind* a surface (a gap in the single depth layer): the
  occluder is extrapolated from the last two steps in front of it (its slope clamped to
  ``max_slope`` depth per unit of ray time), and the ray is blocked if it passed behind that
  extrapolated surface; otherwise the step is tested against the stored depth.

A step is blocked when the stored depth is nearer the light than the ray by more than ``bias``
(fraction of the frame's extent) and nearer than the receiver's own tangent plane at that texel
(less ``plane_slope_bias`` of the plane's depth step per texel, the receiver-plane bias of
``pcf``): the receiver's own surface never shadows it, and no offset lifts contact shadows off
their casters (``normal_offset`` texels along the normal, 0 by default, moves the ray's start as
engines' normal-offset biases do). Adaptive ray count: ``adaptive_rays`` probes toward points
evenly spread (at a random turn per pixel) on the light's outline go first; when they agree (all
blocked or all free) the pixel takes that answer, otherwise its ``rays`` rays are traced (a
stratified lattice over the light, consecutive rays far apart) and V is their fraction of free
rays.

Failure modes (tests/test_smrt.py provokes the first two: the single layer against the
reference, the cap against ``box_plane``'s exact answer; the third is not provoked by a test):

* **single depth layer**: the map holds only the surface nearest the light, so a receiver whose
  rays pass under a thin or raised caster, behind its front surface, cannot tell a thin plate
  from a solid block. The extrapolation guesses the occluder's extent from its slope; where the
  guess is wrong light leaks through (or darkens) beside the caster's silhouette;
* **penumbra cap**: rays stay within ``max_ray_angle`` (0.03 rad by default) of the light's
  centre and within ``ray_texels`` texels of the receiver, so a light wider than the cap seen
  from the receiver (a large rect light close by) gets penumbrae too narrow, and a caster far
  above a receiver under a distant light casts a penumbra no wider than the ray's reach;
* **unmapped pages**: a ray reaching beyond the pages its receiver requested reads coarser
  levels, or nothing (counted as ``unmapped_samples`` for distant lights, taken as free).

Counters: the virtual map's (``requested``, ``rendered``, ``reused``, ``evicted``, ...), and
``rays_traced`` (rays over every sample, the adaptive count's effect).

Example::

    frame = wsoft.render("city", "smrt", width=640, height=480, rays=7, samples=8)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.virtual_pages import UNMAPPED, VirtualMapGPU, level_texel, level_view, virtual_depth
from wsoft.accel.virtual_passes import add_page_pass, report_unmapped
from wsoft.lightspace.light import LightGPU, light_center_dir, light_point
from wsoft.lightspace.samples import counter_draw, pixel_key, to_light_coords
from wsoft.lightspace.view import ViewGPU, map_coords, receiver_tap_depth, view_dir, view_of
from wsoft.params import check_ranges
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU
from wsoft.scene.types import LIGHT_RECT
from wsoft.techniques._virtual import VirtualMapTechnique
from wsoft.techniques.base import PassSpec, Quality, Tolerance, check, param


@dataclass(frozen=True)
class SMRTParams:
    rays: int = param(7, "rays per pixel toward the light (0: one ray to its centre, a hard shadow)", range=(0, 256))
    samples: int = param(8, "depth comparisons per ray", range=(1, 256))
    max_ray_angle: float = param(0.03, "radians: the widest angle a ray may make with the direction to the light's centre (the penumbra cap)",
                                 range=(0.0, 1.6))
    ray_texels: float = param(32.0, "the farthest a ray is followed across the map, in texels of the receiver's level", range=(1.0, 4096.0))
    adaptive_rays: int = param(4, "probe rays to points evenly spread on the light's outline, traced first: when all are blocked or all "
                                  "free the pixel takes that answer and skips its rays (0: always every ray)", range=(0, 64))
    max_slope: float = param(100.0, "the steepest occluder slope (depth per unit of ray time) extrapolated behind a surface", range=(0.0, 1e6))
    normal_offset: float = param(0.0, "texels of the receiver's level its rays start off its surface, toward the light", range=(0.0, 64.0))
    plane_slope_bias: float = param(0.25, "a stored depth blocks only nearer the light than the receiver's tangent plane at its texel, less "
                                          "this many of the plane's depth steps per texel", range=(0.0, 16.0))
    bias: float = param(1e-5, "depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))
    seed: int = param(0, "random seed of the rays' directions", range=(0, 2**31 - 1))
    virtual_size: int = param(16384, "texels a side of each level's virtual map (a local light's finest mip)", range=(256, 1 << 20))
    page_size: int = param(128, "texels a side of a page", range=(16, 1024))
    pool_pages: int = param(2048, "physical pages in the pool (each page_size^2 float32)", range=(1, 1 << 20))
    clip_levels: int = param(16, "distant lights: clipmap levels around the camera", range=(1, 24))
    first_extent: float = param(0.0, "distant lights: world width of level 0 (0: the last level spans 16 scene diagonals)", range=(0.0, 1e12))
    lod_bias: float = param(-1.0, "log2 of a page texel over the pixel footprint a sample asks for (negative: finer pages, more of them)",
                            range=(-8.0, 8.0))
    footprint: float = param(0.0, "world units every sample asks texels for (with lod_bias), as a bake needs (it has no camera); 0: "
                                  "each pixel's footprint", range=(0.0, 1e12))

    def __post_init__(self):
        check_ranges(self)
        check(self.virtual_size % self.page_size == 0 and self.virtual_size >= self.page_size,
              f"virtual_size {self.virtual_size} must be a multiple of page_size {self.page_size}")
        n = self.virtual_size // self.page_size
        check(n & (n - 1) == 0, f"virtual_size / page_size must be a power of two, not {n}")


@wp.func
def capped_direction(d: wp.vec3, c: wp.vec3, cap: float) -> wp.vec3:
    """``d`` turned toward ``c`` (unit vectors) until it is at most ``cap`` radians off it."""
    cosang = wp.clamp(wp.dot(d, c), -1.0, 1.0)
    if cosang >= wp.cos(cap):
        return d
    perp = d - c * cosang
    n = wp.length(perp)
    if n <= 0.0:
        return c
    return wp.normalize(c * wp.cos(cap) + perp * (wp.sin(cap) / n))


@wp.func
def trace_ray(vm: VirtualMapGPU, k: int, vr: wp.vec3, vd: wp.vec3, length: float, samples: int, jitter: float, max_slope: float,
              bias: float, lv: ViewGPU, pv: wp.vec3, nv: wp.vec3, plane_slope: float) -> wp.vec2:
    """March the ray from view-space ``vr`` along view-space unit ``vd`` over ``length``, from its
    far end back to ``vr``, through level ``k`` (``lv``, and coarser where no page is): (1 if
    blocked else 0, valid steps). A stored depth blocks only where it lies nearer the light than
    the receiver's tangent plane (point ``pv``, light-facing normal ``nv``) at its texel, less
    ``plane_slope`` depth steps (:func:`~wsoft.lightspace.view.receiver_tap_depth`): the receiver's
    own surface never shadows it."""
    have = int(0)
    occ_hist = float(0.0)
    ray_hist = float(0.0)
    time_hist = float(0.0)
    slope = float(0.0)
    valid = int(0)
    for j in range(samples + 1):
        u = wp.clamp(1.0 - (float(j) + jitter) / float(samples), 0.0, 1.0)
        if j == 0:
            u = 1.0
        time = u * u
        q = vr + vd * (time * length)
        zr = q[2]
        if vm.view.persp != 0 and zr <= vm.view.near:
            continue
        dl = virtual_depth(vm, k, map_coords(vm.view, q))
        if dl[0] == UNMAPPED:
            continue  # no depth here: the step tells nothing (and does not disturb the slope's history)
        valid += 1
        occ = dl[0]
        m = map_coords(vm.view, q)
        own = receiver_tap_depth(lv, pv, nv, m, plane_slope) - bias  # the receiver's plane there
        if have == 0:
            if occ < zr - bias and occ < own:
                return wp.vec2(1.0, float(valid))
            have = 1
            occ_hist = occ
            ray_hist = zr
            time_hist = time
            continue
        dt = time - time_hist
        threshold = wp.abs(zr - ray_hist) * 1.05 + bias
        if occ < zr - threshold:  # behind a surface: extrapolate the last one in front
            occ = occ_hist + slope * dt
        elif dt != 0.0:
            slope = wp.clamp((occ - occ_hist) / dt, -max_slope, max_slope)
            occ_hist = occ
            time_hist = time
        if occ < zr - bias and occ < own:
            return wp.vec2(1.0, float(valid))
        ray_hist = zr
    return wp.vec2(0.0, float(valid))


@wp.func
def smrt_ray(vm: VirtualMapGPU, L: LightGPU, k: int, t: float, p: wp.vec3, vr: wp.vec3, centre: wp.vec3, centre_len: float, c: wp.vec2,
             on_light: int, max_angle: float, reach: float, samples: int, jitter: float, max_slope: float, bias: float, lv: ViewGPU,
             pv: wp.vec3, nv: wp.vec3, plane_slope: float) -> wp.vec2:
    """One ray from the receiver (world ``p``, its offset start ``vr`` in view space, level ``k`` of
    texel ``t``) toward light coordinates ``c`` (``on_light`` 0: toward the light's centre), at
    most ``max_angle`` off the centre's direction and ``reach`` texels across the map:
    :func:`trace_ray`'s (blocked, valid steps)."""
    d = centre
    length = centre_len
    if on_light != 0:
        lp = light_point(L, p, c)
        d = capped_direction(wp.vec3(lp[0], lp[1], lp[2]), centre, max_angle)
        length = lp[3]
    vd = view_dir(vm.view, d)
    lateral = float(0.0)
    if vm.view.persp != 0:  # the rate at which the ray crosses the map at its start (window units per unit length)
        sx = (vd[0] * vr[2] - vr[0] * vd[2]) / (vr[2] * vr[2])
        sy = (vd[1] * vr[2] - vr[1] * vd[2]) / (vr[2] * vr[2])
        lateral = wp.sqrt(sx * sx + sy * sy)
        length = 0.999 * length  # stop short of the light's surface
        if vd[2] < 0.0:
            length = wp.min(length, 0.95 * (vr[2] - vm.view.near) / (-vd[2]))
    else:
        lateral = wp.sqrt(vd[0] * vd[0] + vd[1] * vd[1])
        if vd[2] < 0.0:
            length = wp.min(length, vr[2] / (-vd[2]))
    if lateral > 0.0:
        length = wp.min(length, reach * t / lateral)
    return trace_ray(vm, k, vr, vd, wp.max(length, 0.0), samples, jitter, max_slope, bias, lv, pv, nv, plane_slope)


@wp.kernel
def shade_smrt(
    offset: int,
    vm: VirtualMapGPU,
    L: LightGPU,
    gb: GBufferGPU,
    level_of: wp.array[wp.int32],
    rays: int,
    step: int,
    samples: int,
    disk: int,
    max_angle: float,
    reach: float,
    adaptive: int,
    max_slope: float,
    normal_texels: float,
    bias: float,
    plane_slope: float,
    seed: int,
    # outputs
    vis: wp.array[float],
    unmapped: wp.array[wp.int32],
    traced: wp.array[wp.int32],
):
    """Per sample: the fraction of its rays toward the light that no step of the march finds blocked."""
    i = wp.tid() + offset
    k = level_of[i]
    unmapped[i] = 0
    traced[i] = 0
    if k < 0:
        vis[i] = 1.0
        if k == -1 and gb.prim[i] >= 0:
            unmapped[i] = 1
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    cd = light_center_dir(L, p)
    centre = wp.vec3(cd[0], cd[1], cd[2])
    if wp.dot(n, centre) < 0.0:
        n = -n
    t = level_texel(vm, k)
    vr0 = view_of(vm.view, p)
    world_texel = t
    if vm.view.persp != 0:
        world_texel = t * vr0[2]
    start = p + n * (normal_texels * world_texel)
    vr = view_of(vm.view, start)
    lv = level_view(vm, k)
    pv = vr0
    nv = view_dir(vm.view, n)  # turned toward the light above
    key = pixel_key(seed, i)
    done = int(0)
    any_valid = int(0)
    if adaptive > 0 and rays > 0:  # probes on the light's outline: when they agree, the pixel is taken as fully lit or shadowed
        probed = float(0.0)
        rot = counter_draw(key, 0, 3)
        for r in range(adaptive):
            a = 2.0 * wp.pi * (float(r) / float(adaptive) + rot)
            c = wp.vec2(wp.cos(a), wp.sin(a))
            if disk == 0:
                c = c / wp.max(wp.abs(c[0]), wp.abs(c[1]))
            h = smrt_ray(vm, L, k, t, p, vr, centre, cd[3], c, 1, max_angle, reach, samples, counter_draw(key, r + 1, 4), max_slope, bias,
                         lv, pv, nv, plane_slope)
            probed += h[0]
            done += 1
            if h[1] > 0.0:
                any_valid = 1
        if probed == 0.0 or probed == float(adaptive):
            traced[i] = done
            if any_valid == 0 and vm.view.persp == 0:
                unmapped[i] = 1
            vis[i] = 1.0 - probed / float(adaptive)
            return
    n_rays = wp.max(rays, 1)
    blocked = float(0.0)
    for r in range(n_rays):
        s = (r * step) % n_rays  # the lattice point: consecutive rays far apart on the light
        u = wp.vec2(wp.mod((float(s) + counter_draw(key, 0, 0)) / float(n_rays), 1.0),
                    wp.mod(float(s) * 0.6180339887498949 + counter_draw(key, 0, 1), 1.0))
        h = smrt_ray(vm, L, k, t, p, vr, centre, cd[3], to_light_coords(u, disk), int(rays > 0), max_angle, reach, samples,
                     counter_draw(key, r + 1, 2), max_slope, bias, lv, pv, nv, plane_slope)
        blocked += h[0]
        if h[1] > 0.0:
            any_valid = 1
    done += n_rays
    traced[i] = done
    if any_valid == 0 and vm.view.persp == 0:
        unmapped[i] = 1
    vis[i] = 1.0 - blocked / float(n_rays)


def lattice_step(n: int) -> int:
    """The stride through ``n`` rays' lattice points (coprime with ``n``, about ``n / 2``): consecutive
    rays land far apart on the light."""
    s = max(1, n // 2)
    while math.gcd(s, max(n, 1)) != 1:
        s += 1
    return s


class SMRT(VirtualMapTechnique):
    """Shadow-map ray tracing over a virtual shadow map."""

    name = "smrt"
    summary = "shadow-map ray tracing (UE5 SMRT): rays toward the light marched through a virtual shadow map, slope extrapolation"
    Params = SMRTParams
    passes = (PassSpec("pages", reads=("scene", "gbuffer"), optional=("light_view",), writes=("virtual_pages",)),
              PassSpec("shadow", reads=("gbuffer", "virtual_pages"), writes=("visibility",)))
    quick_params = {"virtual_size": 2048, "pool_pages": 256}
    size_param = "virtual_size"
    quality = (Quality("rays", (2, 7, 16), "more rays: less noise in the penumbra, linearly more time"),
               Quality("samples", (4, 8, 16), "more steps: fewer missed thin casters"))
    # at its defaults the penumbra cap (0.03 rad) narrows box_plane's penumbra (the light spans about
    # 0.17 rad from the ground) to a line: a hard shadow's error (tests/test_smrt.py lifts the cap)
    tolerance = Tolerance(mae=0.012, mae_penumbra=0.38)
    point_refusal = "a virtual map here is one perspective map a light; a point light needs six (use pcss or reference)"
    cube_refusal = "a virtual map here is one perspective map a light; receivers all around a light need a cube map (use pcss or reference)"

    def add_passes(self, ctx, light):
        p = self.params
        pages = add_page_pass(self, ctx, light, reach_texels=p.ray_texels + p.normal_offset + 1.0, soft=True)
        gbuf = ctx.gbuffer()
        out = ctx.visibility_key(light)
        name = ctx.pass_name("smrt", light)
        L = ctx.light_gpu(light)
        seed = ctx.frame_seed(p.seed)

        def run(res):
            gb, vp = res[gbuf], res[pages]
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            unmapped = wp.empty(gb.count, dtype=wp.int32, device=ctx.device)
            traced = wp.empty(gb.count, dtype=wp.int32, device=ctx.device)
            launch_chunked(shade_smrt, gb.count,
                           inputs=[vp["map"], L, gb.gpu(), vp["level_of"], p.rays, lattice_step(p.rays), p.samples, int(light.kind != LIGHT_RECT),
                                   float(p.max_ray_angle), float(p.ray_texels), p.adaptive_rays, float(p.max_slope), float(p.normal_offset),
                                   p.bias * vp["extent"], float(p.plane_slope_bias), int(seed)],
                           outputs=[vis, unmapped, traced], device=ctx.device, min_chunk=256)
            report_unmapped(ctx, light, name, unmapped)
            ctx.counters(light)["rays_traced"] = int(traced.numpy().astype(np.int64).sum())
            return {out: ctx.visibility(vis)}

        return ctx.add_pass(name, inputs=(gbuf, pages), outputs=(out,), run=run, stage="shadow", light=light)
