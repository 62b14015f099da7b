"""``salzman``: Salzman's "Simpler Soft Shadow Mapping" (2007), for lightmapped scenes.

Only *dynamic casters* go into the shadow map (prims with time-sampled points or transforms, or
``wsoft:dynamic = true``; with ``casters = auto`` a scene without any uses every prim). The
map, cleared to depth 1 and mask 0, holds per texel

* ``d``: the casters' normalised depth (1 where none) and ``m``: the mask (1 on a caster),
* ``f``: the far bound — the nearest *receiver* behind the casters, rendered with the inverted
  depth test (1 where none) — so a shadow stops at the surface right behind its caster,
* ``o``: the casters' opacity (the transparency extension; ``m`` for opaque casters),

all blurred by one separable linear filter. Shading reconstructs the unfiltered caster depth
``s = (d - 1) / m + 1`` (and the far bound the same way); a receiver farther than ``s`` (and
nearer than the far bound) is shadowed with intensity ``o`` (``m`` without transparency). Where
``m`` is ~0 nothing is reconstructed (lit). The blur runs only inside rectangles merged from a
coarse grid of the casters' bounding squares (rows as bit vectors, run-length merged); the same
grid rejects receivers outside every caster's influence. ``bits = 8`` stores the filtered map
in 8 bits per component, as the paper suggests is feasible.

Known failure (pinned by a test): a receiver between two casters along a light ray gets a
reconstructed depth averaged behind it and escapes the shadow. The far bound belongs to the
paper's lightmapped scene (``far_bound=auto`` draws it where the map holds the dynamic casters
only): where every prim casts, the first surface behind a caster is itself a caster, and the bound
would let every receiver behind two casters out of the shadow (``reports/adversarial.md``'s
``room_ceiling``: mean V 0.83 with ``far_bound=on``, 0.000 with ``auto``).

UsdLux: only the casters a light's ``collection:shadowLink`` includes go into its map (prims it
leaves out still receive its shadow); a finite ``inputs:shadow:distance`` is declined (the
blurred map keeps no caster's own distance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.blur import blur_vec4_within
from wsoft.accel.grid import build_grid
from wsoft.lightspace.view import DEPTH_CLEAR, ViewGPU, bilinear, normalised_depth
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_mapped_receiver
from wsoft.raster.depth_map import rasterize
from wsoft.params import LightViewParams, check_ranges
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param


FAR_BOUNDS = ("auto", "on", "off")  # SalzmanParams.far_bound
_FAR_BOUND_WORDS = {"true": "on", "1": "on", "yes": "on", "false": "off", "0": "off", "no": "off"}


@dataclass(frozen=True)
class SalzmanParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the map", range=(256, 8192))
    filter: str = param("gaussian", "blur: box or gaussian")
    radius: int = param(4, "blur radius in texels", range=(0, 64))
    far_bound: str = param("auto", "stop the shadow at the first receiver behind the casters: auto (where the map holds the dynamic "
                                   "casters only, the paper's lightmapped scene; not where every prim casts), on or off "
                                   "(true and false read as on and off)", choices=FAR_BOUNDS)
    transparency: bool = param(True, "shadow with the casters' opacity instead of the mask")
    bits: int = param(32, "storage of the filtered map: 32 (float) or 8 bits per component", range=(8, 32))
    grid: int = param(32, "cells per side of the caster grid (0: blur everything, no rejection)", range=(0, 1024))
    casters: str = param("auto", "which prims cast: dynamic, all, or auto (dynamic if any)")
    bias: float = param(1e-4, "depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))

    def __post_init__(self):
        if str(self.far_bound).strip().lower() in _FAR_BOUND_WORDS:
            object.__setattr__(self, "far_bound", _FAR_BOUND_WORDS[str(self.far_bound).strip().lower()])
        check_ranges(self)
        check(self.filter in ("box", "gaussian"), f"filter {self.filter!r} is not box or gaussian")
        check(self.bits in (8, 32), "bits must be 8 or 32")
        check(self.grid == 0 or 2 <= self.grid <= 1024, "grid must be 0 or in [2, 1024]")
        check(self.casters in ("auto", "dynamic", "all"), f"casters {self.casters!r} is not auto, dynamic or all")


@wp.func
def salzman_shadow(e: wp.vec4, z: float, bias: float, far_bound: int, transparency: int) -> float:
    """Shadow intensity at normalised receiver depth ``z`` from a filtered texel (d, m, f, o)."""
    m = e[1]
    if m < 1.0e-3:  # no caster influence: nothing to reconstruct (guards the division)
        return 0.0
    s = (e[0] - 1.0) / m + 1.0
    if z <= s + bias:
        return 0.0
    if far_bound != 0:
        f = (e[2] - 1.0) / m + 1.0
        if z > f + bias:
            return 0.0
    if transparency != 0:
        return wp.clamp(e[3], 0.0, 1.0)
    return wp.clamp(m, 0.0, 1.0)


@wp.kernel
def make_salzman_map(
    offset: int,
    caster: wp.array[float],
    far: wp.array[float],
    opacity: wp.array[float],
    znear: float,
    zfar: float,
    # outputs
    out: wp.array[wp.vec4],
):
    i = wp.tid() + offset
    c = caster[i]
    if c >= DEPTH_CLEAR:
        out[i] = wp.vec4(1.0, 0.0, 1.0, 0.0)
        return
    zrange = zfar - znear
    out[i] = wp.vec4(normalised_depth(c, znear, zrange), 1.0, normalised_depth(far[i], znear, zrange), opacity[i])


@wp.kernel
def quantize8(
    offset: int,
    # outputs
    m: wp.array[wp.vec4],
):
    i = wp.tid() + offset
    v = m[i]
    m[i] = wp.vec4(
        wp.round(wp.clamp(v[0], 0.0, 1.0) * 255.0) / 255.0,
        wp.round(wp.clamp(v[1], 0.0, 1.0) * 255.0) / 255.0,
        wp.round(wp.clamp(v[2], 0.0, 1.0) * 255.0) / 255.0,
        wp.round(wp.clamp(v[3], 0.0, 1.0) * 255.0) / 255.0,
    )


@wp.kernel
def shade_salzman(
    offset: int,
    lv: ViewGPU,
    smap: wp.array2d[wp.vec4],
    cells: wp.array[wp.int32],
    gsize: int,
    znear: float,
    zfar: float,
    gb: GBufferGPU,
    bias: float,
    far_bound: int,
    transparency: int,
    # outputs
    vis: wp.array[float],
    rejected: wp.array[wp.int32],
):
    i = wp.tid() + offset
    vis[i] = 1.0
    rejected[i] = 0
    mapped, pv, m, t = gb_mapped_receiver(lv, gb, i)
    if not mapped:
        return
    if gsize > 0:
        cx = int(t[0]) * gsize / lv.width
        cy = int(t[1]) * gsize / lv.height
        if cells[cy * gsize + cx] == 0:  # outside every caster's influence
            rejected[i] = 1
            return
    z = normalised_depth(pv[2], znear, zfar - znear)
    vis[i] = 1.0 - salzman_shadow(bilinear(lv, smap, m), z, bias, far_bound, transparency)


class Salzman(Technique):
    """Salzman's depth + mask map of dynamic casters, with far bound, transparency and a caster grid."""

    name = "salzman"
    distant_angle_limit = 150.0  # its soft view, widened by tan(angle / 2), coarsens its blur: wide_sun's check fails from 160
    instancing_refusal = "its static/dynamic split and gated maps work on the soup's triangle lists"
    summary = "Salzman 2007: blurred depth+mask map of dynamic casters, reconstructed caster depth, far bound, transparency, caster grid, 8-bit option"
    Params = SalzmanParams
    passes = (
        PassSpec("map", reads=("scene", "light_view"), writes=("salzman_map",)),
        PassSpec("shadow", reads=("gbuffer", "light_view", "salzman_map"), writes=("visibility",)),
    )
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"
    quality = (Quality("radius", (2, 4, 8), "a wider blur: wider (uniform) penumbrae, more time"),)
    # one blur width for every penumbra: the parallel-rectangle penumbra is matched only roughly
    tolerance = Tolerance(mae=0.007, mae_penumbra=0.28)
    distance_refusal = "its blurred depth and mask reconstruct one averaged caster depth per texel, not each caster's distance"
    cylinder_model = ("the shadow of its centre through a filtered map (its size plays no part), in a light view that looks at the "
                      "receivers as a sphere light's does")

    def supports(self, scene, light) -> str | None:
        why = super().supports(scene, light)
        if why is not None:
            return why
        if self.params.casters == "dynamic" and (scene.tri_dynamic is None or not scene.tri_dynamic.any()):
            return "casters=dynamic but the scene has no dynamic prims (nothing would cast a shadow)"
        return None

    def caster_triangles(self, scene, light=None) -> tuple[np.ndarray, str]:
        """The triangles drawn into the map (the dynamic casters, or all) and the mode used; with
        ``light``, only those its ``collection:shadowLink`` lets cast."""
        dyn = scene.tri_dynamic if scene.tri_dynamic is not None else np.zeros(scene.triangle_count, bool)
        mode = self.params.casters
        if mode == "auto":
            mode = "dynamic" if dyn.any() else "all"
        sel = dyn if mode == "dynamic" else np.ones(scene.triangle_count, bool)
        link = scene.casting_mask(light) if light is not None else None
        if link is not None:
            sel = sel & link
        return np.flatnonzero(sel).astype(np.int32), mode

    def far_bound_applies(self, mode: str) -> bool:
        """Whether the far bound is drawn when the map holds ``mode``'s casters (``dynamic`` or
        ``all``): ``far_bound=auto`` draws it for the dynamic casters only. The paper's far bound is
        the static receiver behind a dynamic caster (the lightmap holds the static shadows beyond
        it); where every prim casts, the surface right behind a caster is itself a caster, and the
        bound would let every receiver behind two casters out of the shadow."""
        f = self.params.far_bound
        return f == "on" or (f == "auto" and mode == "dynamic")

    def cube_guard_texels(self) -> float:
        """Its blur's radius and the bilinear tap's texel."""
        return float(self.params.radius) + 2.0

    def add_passes(self, ctx, light):
        p = self.params
        scene = ctx.scene
        gbuf = ctx.gbuffer()
        sk = ctx.scene_arrays()
        view_key = ctx.light_view(light, p.shadow_map_size, soft=True, view=p.view)
        map_key = ctx.key("salzman_map", light, variant=f"@{p.shadow_map_size}")
        counters = ctx.counters(light)
        out = ctx.visibility_key(light)
        casters, mode = self.caster_triangles(scene, light)
        far = self.far_bound_applies(mode)
        receivers = np.setdiff1d(np.arange(scene.triangle_count, dtype=np.int32), self.caster_triangles(scene)[0]) if mode == "dynamic" \
            else np.arange(scene.triangle_count, dtype=np.int32)  # excluded casters still receive
        mats = scene.materials
        tri_opacity = np.array([1.0 if m.is_cutout else min(max(m.opacity, 0.0), 1.0) for m in mats], np.float32)[scene.tri_material]

        def build(res):
            ds, view = res[sk], res[view_key]
            dev = ctx.device
            n = view.width * view.height
            alpha = scene.has_cutouts
            cmap = rasterize(ds, view, alpha, triangles=casters)
            # opacity of the casters per texel: the strongest caster covering it (one pass per opacity)
            omap = np.zeros(n, np.float32)
            for o in np.unique(tri_opacity[casters]) if len(casters) else []:
                sub = casters[tri_opacity[casters] == o]
                covered = rasterize(ds, view, alpha, triangles=sub).depth.numpy().reshape(-1) < DEPTH_CLEAR
                omap[covered] = np.maximum(omap[covered], o)
            fmap = rasterize(ds, view, alpha, triangles=receivers, behind=cmap.depth) if far and len(receivers) else None
            cd = cmap.depth.numpy()
            has = cd < DEPTH_CLEAR
            znear = float(cd[has].min()) * 0.99 if has.any() else view.near
            zfar = float(view.far)
            smap = wp.empty(n, dtype=wp.vec4, device=dev)
            launch_chunked(
                make_salzman_map, n,
                inputs=[cmap.depth.reshape(-1), (fmap.depth if fmap is not None else cmap.depth).reshape(-1) if fmap is not None else wp.full(n, DEPTH_CLEAR, dtype=float, device=dev),
                        wp.array(omap, dtype=float, device=dev), znear, zfar],
                outputs=[smap], device=dev, min_chunk=1 << 15,
            )
            smap = smap.reshape((view.height, view.width))
            # the caster grid: bounding squares of the caster prims, grown by the blur radius
            gsize = p.grid
            if gsize > 0:
                squares = []
                for prim_id in np.unique(scene.tri_prim[casters]) if len(casters) else []:
                    pts = scene.points[scene.triangles[casters[scene.tri_prim[casters] == prim_id]].ravel()]
                    xs, ys = view.texel_coords(pts)
                    if len(xs) == 0:
                        continue
                    g = p.radius + 1
                    squares.append((xs.min() - g, xs.max() + g, ys.min() - g, ys.max() + g))
                grid = build_grid(squares, view.width, view.height, gsize)
                texels = grid.texels(view.width, view.height)
                cells = grid.marked().astype(np.int32).ravel()
                counters["grid_rectangles"] = len(grid.rects)
            else:
                texels = np.arange(n, dtype=np.int32)
                cells = np.ones(1, np.int32)
            counters["fraction_blurred"] = len(texels) / n
            counters["casters"] = mode
            counters["far_bound"] = far
            counters["caster_triangles"] = int(len(casters))
            blurred = blur_vec4_within(smap, texels, p.filter, p.radius)
            if p.bits == 8:
                launch_chunked(quantize8, n, inputs=[], outputs=[blurred.reshape(-1)], device=dev, min_chunk=1 << 15)
            return {map_key: SalzmanMap(blurred, wp.array(cells, dtype=wp.int32, device=dev), gsize, znear, zfar)}

        def run(res):
            gb, view, sm = res[gbuf], res[view_key], res[map_key]
            bias = p.bias * view.extent / max(sm.zfar - sm.znear, 1e-12)
            if p.bits == 8:
                bias = max(bias, 1.5 / 255.0)
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            rej = wp.empty(gb.count, dtype=wp.int32, device=ctx.device)
            launch_chunked(
                shade_salzman, gb.count,
                inputs=[view.gpu(), sm.map, sm.cells, sm.grid, sm.znear, sm.zfar, gb.gpu(), bias, int(far), int(p.transparency)],
                outputs=[vis, rej], device=ctx.device,
            )
            covered = int((gb.prim.numpy() >= 0).sum())
            counters["receivers_rejected_by_grid"] = int(rej.numpy().sum()) / max(covered, 1)
            return {out: ctx.visibility(vis)}

        ctx.add_pass(ctx.pass_name("salzman_map", light, f"@{p.shadow_map_size}"), inputs=(sk, view_key), outputs=(map_key,), run=build, stage="map", light=light)
        return ctx.add_pass(ctx.pass_name("salzman", light), inputs=(gbuf, view_key, map_key), outputs=(out,), run=run, stage="shadow", light=light)


@dataclass
class SalzmanMap:
    map: wp.array  # [H, W] vec4 (d, m, f, o), filtered
    cells: wp.array  # [G*G] int32 marked cells
    grid: int
    znear: float
    zfar: float

    def arrays(self) -> dict[str, wp.array]:
        return {"map": self.map, "cells": self.cells}
