"""``izb``: irregular z-buffer shadows (Johnson et al.) with adaptive eye-view anti-aliasing
(Galoppo, "Eye-View Pixel Anti-Aliasing for Irregular Shadow Mapping", GPU Pro 1.6).

Hard shadows of the light's centre (a point light exactly; an area light from its centre, as
``hard``), pixel-exact: the shadow is decided per eye sample by an exact ray-triangle test, not
by a depth map, so there is no light-view aliasing at any grid size.

Steps of one light (the paper's eight, as passes):

1. ``izb_stencil`` (``aa=adaptive``) — the *shadow-edge stencil*, the pixels that get sub-samples.
   ``stencil=bounds`` (default) proves, per pixel, that its samples agree or flags it: the plane
   its samples' shadow rays start from (moved off the surface as :func:`~wsoft.techniques.izb.samples.shadow_ray` moves them),
   the pixel's footprint on it projected into the light's maps, and per texel of the finest
   pyramid level holding the footprint in ``bounds_texels`` texels per side
   (:func:`~wsoft.techniques.izb.stencil.footprint_certainty`): *certainly lit* when nothing touching the texel (a conservative
   map, cutouts opaque) is nearer than the plane's nearest point there, no back face of a closed
   surface (every ray through a closed blocker leaves it by one) and, on a closed receiver, no
   open surface is nearer than the plane's farthest footprint point there; *certainly shadowed*
   when a blocker covers the texel whole (an inner-coverage map) nearer than the plane anywhere in
   the footprint. Pixels whose neighbours see another surface (or whose centre is a cutout) cast
   their sub-pixel eye rays and test each surface met likewise. ``stencil=vsm`` is the paper's:
   a variance shadow map from a light depth map rendered with conservative rasterization
   (``stencil_raster=ordinary`` renders it with ordinary rasterization, the paper's Fig. 1.6.7),
   mip-mapped (:func:`~wsoft.accel.pyramid.build_moments_pyramid`). Per pixel: the pixel's
   footprint on its tangent plane projected into the map, widened by one texel, picks the mip
   level whose texels are at least as large; the moments of the (at most 2 x 2) texels it
   overlaps; the nearest light depth t of the footprint less a slack (the receiver's own depth
   change over two texels, plus ``stencil_bias``); the one-tailed Chebyshev bounds of the
   occluder mass below t (``certainly lit`` when below ``edge_threshold``) and of the mass at or
   beyond t (``certainly shadowed``). A potential edge is a pixel that is neither
   (``stencil_rule=cull``: the paper's text, "bounds ... to cull eye-view pixels"); Listing 1.6.1
   returns *true* when either bound is below the threshold, which read literally flags the
   certain pixels instead (``stencil_rule=listing``, kept to measure it). The VSM's bounds are
   probabilistic and its receivers are in its own map: it misses aliased pixels
   (``reports/izb.md``). A conservative map serves the *lit* bound (no occluder escapes a texel
   it touches) but not the *shadowed* one: it spreads an occluder over every texel it touches, so
   a partly lit pixel beside a thin occluder reads as certainly shadowed; this is why the
   conservative map misses more aliased pixels than the ordinary one (all the extra misses are
   "certainly shadowed" verdicts). ``shadowed_map=inner`` reads the shadowed bound from a VSM of
   an inner-coverage map (an occluder counts only in texels it covers whole). Its remaining misses
   are pixels whose centre lies on the occluder and whose sub-samples see the receiver behind it:
   both bounds test the centre's plane only (an ordinary map flags many of them by chance, the
   receiver seen through the occluder's gaps widening the variance); ``flag_mixed`` flags every
   pixel next to another surface as well.
2. ``izb_samples`` — the shadow samples: one per pixel (the G-buffer's, at the pixel centre),
   and for potential-edge pixels (``adaptive``) or every pixel (``supersample``) ``samples``
   sub-pixel samples (rotated grid 4x, or jittered 8x / 16x) at their sub-pixel offsets
   (``subsamples``): on the centre's plane where the pixel sees that plane alone (its 8
   neighbours on it, its centre no cutout: the camera ray meets the plane, no scene query), their
   eye rays *re-cast* through the scene elsewhere (:func:`~wsoft.raster.gbuffer.cast_primary`):
   exact surface points where a pixel straddles a silhouette or a crease, which a reconstruction
   from the depth buffer (``subsamples=plane``) gets wrong; ``recast`` re-casts all. Where the
   ``bounds`` stencil already cast a pixel's eye rays (probing it), their hits are taken, not cast
   again. A multi-sampled pixel's
   visibility is the mean over its sub-samples that hit a surface (its centre sample is not
   inserted unless none did; ``keep_centre``, the paper's step 4, keeps it besides them: the mean
   over the N + 1). ``subsamples=gbuffer`` reads them from a multi-sampled eye view of every
   pixel at the same pattern (pass ``izb_gbuffer``: the paper's source, its eye view's 4x
   rotated-grid render), the same points ``recast`` finds. The pipeline's own multi-sampled
   G-buffer (``pixel_samples > 1``) is refused with ``aa != none``: izb writes one visibility per
   G-buffer sample and treats each as a pixel centre, its pattern is not the rotated grid, and it
   has no centre sample.
3. ``izb_grid`` — the irregular z-buffer: a light view fitted to the inserted samples
   (``grid_size`` cells per side) and a grid of lists (:mod:`wsoft.accel.izb_grid`).
4. ``izb_light`` — occluder triangles rasterized conservatively over the grid; every sample of a
   touched cell is tested exactly (:func:`~wsoft.accel.izb_grid.izb_test`).
5. ``izb_resolve`` — per pixel, the mean over its samples.

Every sample's shadow ray starts at its surface point moved off the surface along the normal (as
the reference's) and goes to the light's centre; where the light's centre lies behind the tangent
plane the sample is shadowed without a test (the receiver's own horizon, applied per sample). The
reference's ray leaves the same origin in the direction from the *surface point* to the light, so
it passes the light's centre at the offset's distance; this one aims at the centre, because a ray
through the light's centre projects to one point of the light's view, the point the grid lists it
at. On a point light the two agree but for knife-edge rays, which pass within the offset of an
edge (``tests/test_izb.py::test_none_differs_from_the_reference_only_where_their_ray_conventions_do``).

UsdLux shadow controls are exact: the light pass draws only the triangles the light's
``collection:shadowLink`` lets cast (and its stencil's maps hold only them), and a finite
``inputs:shadow:distance`` ends every sample's ray that far from its surface point. The stencil's
maps cannot tell a caster's distance, so with a distance no pixel is "certainly shadowed" by a
blocker: such pixels get sub-samples too (correct, a little slower).

Example::

    frame = wsoft.render(scene, "izb", width=640, height=480, aa="adaptive", samples=4)
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import warp as wp

from wsoft.accel.izb_grid import build_grid, izb_test
from wsoft.errors import ParameterError
from wsoft.lightspace.cube import outside_view_remedy
from wsoft.lightspace.fit import fit_light_view
from wsoft.lightspace.light import reach_mask
from wsoft.lightspace.view import outside_view_warning
from wsoft.params import check_ranges
from wsoft.raster.camera import camera_gpu
from wsoft.raster.rasterizer import make_rasterizer
from wsoft.raster.shadow_rays import ray_epsilon
from wsoft.scene.surfaces import without_culling
from wsoft.scene.types import LIGHT_DISTANT, LIGHT_KIND_NAMES, LIGHT_POINT
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param
from wsoft.techniques.izb.samples import SUBSAMPLES, multisampled_gbuffer, place_samples, resolve_samples
from wsoft.techniques.izb.stencil import bounds_stencil_pass, vsm_stencil_pass

AA_MODES = ("none", "adaptive", "supersample")
PATTERNS = ("auto", "rotated_grid", "jittered")
STENCILS = ("bounds", "vsm")
STENCIL_RASTER = ("conservative", "ordinary")
STENCIL_RULES = ("cull", "listing")

SHADOWED_MAPS = ("same", "inner")

STENCIL_PARAMS = {"vsm": ("edge_threshold", "stencil_raster", "stencil_rule", "stencil_bias", "min_variance", "shadowed_map",
                          "flag_mixed"),
                  "bounds": ("bounds_bias", "bounds_texels")}


@dataclass(frozen=True)
class IZBParams:
    grid_size: int = param(1024, "cells per side of the irregular z-buffer's grid (its light view)", range=(256, 8192))
    aa: str = param("adaptive", "eye-view anti-aliasing: none (one sample per pixel), adaptive (sub-samples on potential shadow-edge "
                                "pixels, the paper), supersample (sub-samples on every pixel)")
    samples: int = param(4, "sub-pixel samples of a multi-sampled pixel: 4, 8 or 16", range=(4, 16))
    pattern: str = param("auto", "sub-pixel pattern: rotated_grid (4 only), jittered, auto (rotated grid at 4, else jittered)")
    seed: int = param(0, "seed of the jittered pattern", range=(0, 2**31 - 1))
    subsamples: str = param("auto", "where sub-samples lie: auto (on the centre's plane, where the camera ray meets it, in pixels "
                                    "whose 8 neighbours see that plane too and whose centre is not a cutout; re-cast through the scene "
                                    "elsewhere), recast (every sub-sample's eye ray re-cast: exact surface points everywhere), plane "
                                    "(always on the centre's plane, as a reconstruction from depth: no scene query, wrong across "
                                    "silhouettes) or gbuffer (read from a multi-sampled eye-view G-buffer of every pixel at the "
                                    "sub-pixel pattern, the paper's source: its pass izb_gbuffer renders it)")
    keep_centre: bool = param(False, "a multi-sampled pixel keeps its centre sample besides its N sub-samples (the paper's step 4: "
                                     "N extra samples); its visibility is the mean over the N + 1 samples that hit a surface")
    stencil: str = param("bounds", "adaptive's shadow-edge stencil: bounds (exact depth bounds from a conservative and an "
                                   "inner-coverage map, per pixel plane: certain only where the maps prove it) or vsm (the paper: "
                                   "one-tailed Chebyshev bounds of a mip-mapped variance shadow map, probabilistic)")
    shadow_map_size: int = param(512, "texels per side of the stencil's light maps (a power of two)", range=(256, 4096))
    bounds_bias: float = param(1e-5, "stencil=bounds: depth tolerance (fraction of the map's depth range) between a map and the "
                                     "receiver's plane, for rounding", range=(0.0, 0.05))
    bounds_texels: int = param(8, "stencil=bounds: texels per side compared per footprint (the finest pyramid level that covers "
                                  "the pixel's footprint in as many)", range=(1, 64))
    edge_threshold: float = param(0.01, "stencil=vsm: a Chebyshev bound below this marks a pixel certainly lit or certainly shadowed",
                                  range=(1e-6, 0.5))
    stencil_raster: str = param("conservative", "stencil=vsm: rasterization of its depth map: conservative (the paper) or ordinary "
                                                "(Fig. 1.6.7)")
    stencil_rule: str = param("cull", "stencil=vsm: cull (a potential edge is neither certainly lit nor certainly shadowed, the paper's "
                                      "text) or listing (Listing 1.6.1 read literally: either bound below the threshold)")
    stencil_bias: float = param(0.015, "stencil=vsm: depth offset (fraction of the map's depth range) an occluder must lie in front of "
                                       "a receiver; at least 10 sqrt(min_variance) for a receiver ever to be certainly lit", range=(0.0, 0.5))
    min_variance: float = param(1e-6, "stencil=vsm: the variance floor of the Chebyshev bounds (normalised depth)", range=(0.0, 0.01))
    shadowed_map: str = param("same", "stencil=vsm: the map the certainly-shadowed bound reads: same (the one VSM both bounds read, "
                                      "the paper's) or inner (a VSM of an inner-coverage map, where an occluder counts only in texels "
                                      "it covers whole; a conservative map spreads an occluder over every texel it touches, which "
                                      "makes partly lit pixels 'certainly shadowed')")
    flag_mixed: bool = param(False, "stencil=vsm: also flag every pixel next to another surface (a neighbour on another plane or "
                                    "on nothing, or a cutout under its centre): the bounds test the centre's plane only, and such "
                                    "a pixel's sub-samples may lie on a surface behind it")

    def __post_init__(self):
        check_ranges(self)
        check(self.aa in AA_MODES, f"aa {self.aa!r} is not one of {', '.join(AA_MODES)}")
        check(self.samples in (4, 8, 16), f"samples {self.samples} is not 4, 8 or 16")
        check(self.subsamples in SUBSAMPLES, f"subsamples {self.subsamples!r} is not one of {', '.join(SUBSAMPLES)}")
        check(self.pattern in PATTERNS, f"pattern {self.pattern!r} is not one of {', '.join(PATTERNS)}")
        check(not (self.pattern == "rotated_grid" and self.samples != 4), f"the rotated grid has 4 samples, not {self.samples}")
        m = self.shadow_map_size
        check(m & (m - 1) == 0, f"shadow_map_size {m} is not a power of two in [256, 4096]")
        check(self.stencil in STENCILS, f"stencil {self.stencil!r} is not one of {', '.join(STENCILS)}")
        for other, names in STENCIL_PARAMS.items():
            if other != self.stencil:
                stray = [f.name for f in fields(self) if f.name in names and getattr(self, f.name) != f.default]
                check(not stray, f"{', '.join(stray)}: only stencil={other} reads {'it' if len(stray) == 1 else 'them'}, "
                                 f"and this is stencil={self.stencil}")
        check(self.stencil_raster in STENCIL_RASTER, f"stencil_raster {self.stencil_raster!r} is not one of {', '.join(STENCIL_RASTER)}")
        check(self.stencil_rule in STENCIL_RULES, f"stencil_rule {self.stencil_rule!r} is not one of {', '.join(STENCIL_RULES)}")
        check(self.shadowed_map in SHADOWED_MAPS, f"shadowed_map {self.shadowed_map!r} is not one of {', '.join(SHADOWED_MAPS)}")
        check(isinstance(self.keep_centre, bool), f"keep_centre {self.keep_centre!r} is not true or false")
        check(isinstance(self.flag_mixed, bool), f"flag_mixed {self.flag_mixed!r} is not true or false")
        check(not (self.aa == "none" and (self.keep_centre or self.subsamples != "auto")),
              "keep_centre and subsamples place sub-samples, and aa=none places none")

    @property
    def pattern_kind(self) -> str:
        if self.pattern != "auto":
            return self.pattern
        return "rotated_grid" if self.samples == 4 else "jittered"


class IZB(Technique):
    """Irregular z-buffer hard shadows (exact per eye sample) with adaptive eye-view anti-aliasing."""

    name = "izb"
    instancing_refusal = "its light pass, stencil maps and sub-pixel rays walk the triangle soup"
    summary = "irregular z-buffer: exact hard shadows of the light's centre per eye sample, adaptive eye-view anti-aliasing (Galoppo)"
    Params = IZBParams
    passes = (
        PassSpec("stencil_bounds", reads=("gbuffer", "scene", "light_depth"), writes=("izb_stencil", "izb_probes"),
                 when="aa=adaptive and stencil=bounds"),
        PassSpec("stencil_vsm", reads=("gbuffer", "scene", "light_depth"), writes=("izb_stencil", "izb_verdict"),
                 when="aa=adaptive and stencil=vsm"),
        PassSpec("gbuffer_ms", reads=("scene",), writes=("izb_msaa",), when="aa!=none and subsamples=gbuffer"),
        PassSpec("samples", reads=("gbuffer", "scene"), optional=("izb_stencil", "izb_probes", "izb_msaa"), writes=("izb_samples",)),
        PassSpec("grid", reads=("scene", "izb_samples"), writes=("izb_grid",)),
        PassSpec("light", reads=("scene", "izb_grid"), writes=("izb_blocked",)),
        PassSpec("resolve", reads=("gbuffer", "izb_samples", "izb_grid", "izb_blocked"), writes=("visibility",)),
    )
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"  # its stencil's maps (its grid's size changes only the time its exact tests take)
    quality = (
        Quality("aa", ("none", "adaptive", "supersample"), "sub-pixel samples on no pixel, on potential shadow edges, on every pixel"),
        Quality("samples", (4, 8, 16), "sub-samples of a multi-sampled pixel"),
    )
    # a binary shadow of the light's centre (as hard): exact where the light is a point
    tolerance = Tolerance(mae=0.009, mae_penumbra=0.36)
    horizon = "exact"  # per sample: the light's centre behind the tangent plane is shadowed
    cylinder_model = "the exact hard shadow of its centre (its size plays no part)"

    @staticmethod
    def treatment(light) -> str:
        kind = LIGHT_KIND_NAMES.get(light.kind, str(light.kind))
        return "exact (point light)" if light.kind == LIGHT_POINT else f"from the light's centre ({kind} light: the hard shadow of its centre)"

    def bake_support(self) -> str | None:
        if self.params.aa != "none":
            return (f"aa={self.params.aa} anti-aliases over the eye view's pixels (sub-pixel eye rays, a screen-space shadow-edge "
                    f"stencil) and a bake has no camera; bake with aa=none (the exact hard shadow of the light's centre at each point)")
        return None

    # its light pass tests each inserted sample against the triangles over one grid in one light
    # frustum (the paper's); six grids, one per face, are not built
    cube_refusal = "its irregular z-buffer is one grid in one light frustum (no cube map of grids is built)"

    def add_passes(self, ctx, light):
        p = self.params
        if p.aa != "none" and ctx.pixel_samples != 1:
            raise ParameterError(f"izb: aa={p.aa} places its own sub-pixel samples and needs pixel_samples=1 "
                                 f"(got {ctx.pixel_samples}); use aa=none with G-buffer multi-sampling")
        gbuf = ctx.gbuffer()
        sk = ctx.scene_arrays()
        L = ctx.light_gpu(light)
        cam = camera_gpu(ctx.camera) if p.aa != "none" else None  # only anti-aliasing casts eye rays (a bake has no camera)
        dev = ctx.device
        counters = ctx.counters(light)
        counters["light"] = self.treatment(light)
        n_sub = p.samples if p.aa != "none" else 0
        dmax = float(light.shadow_distance)  # inputs:shadow:distance (-1: none): each sample's ray ends there
        may_shadow = int(not light.distance_limited)  # the stencil's maps cannot tell a caster's distance

        stencil = probes = None
        if p.aa == "adaptive" and p.stencil == "bounds":
            maps = (ctx.light_depth(light, size=p.shadow_map_size, conservative=True, opaque=True),
                    ctx.light_depth(light, size=p.shadow_map_size, conservative=True, opaque=True, faces="back"),
                    ctx.light_depth(light, size=p.shadow_map_size, conservative=True, opaque=True, faces="open"),
                    ctx.light_depth(light, size=p.shadow_map_size, inner=True))
            stencil = ctx.key("izb_stencil", light)
            probes = ctx.key("izb_probes", light)

            def run_bounds(res):
                gb = res[gbuf]
                edge, hits = bounds_stencil_pass(p, gb, res[sk], *(res[k] for k in maps), cam, L, ray_epsilon(gb), may_shadow, n_sub,
                                                 dev, counters)
                return {stencil: edge, probes: hits}

            ctx.add_pass(ctx.pass_name("izb_stencil", light), inputs=(gbuf, sk, *maps), outputs=(stencil, probes), run=run_bounds,
                         stage="stencil_bounds", light=light)
        elif p.aa == "adaptive":
            depth = ctx.light_depth(light, size=p.shadow_map_size, conservative=p.stencil_raster == "conservative")
            inner = ctx.light_depth(light, size=p.shadow_map_size, inner=True) if p.shadowed_map == "inner" else None
            stencil = ctx.key("izb_stencil", light)
            verdict = ctx.key("izb_verdict", light)

            def run_stencil(res):
                edge, verdicts = vsm_stencil_pass(p, res[gbuf], res[depth], cam, may_shadow, dev, counters,
                                                  inner=res[inner] if inner is not None else None,
                                                  cutouts=res[sk].cutouts if p.flag_mixed else None)
                return {stencil: edge, verdict: verdicts}

            ctx.add_pass(ctx.pass_name("izb_stencil", light), inputs=(gbuf, sk, depth) + ((inner,) if inner is not None else ()),
                         outputs=(stencil, verdict), run=run_stencil, stage="stencil_vsm", light=light)

        msaa = None
        if p.aa != "none" and p.subsamples == "gbuffer":
            msaa = ctx.key("izb_msaa", light)

            def run_msaa(res):
                return {msaa: multisampled_gbuffer(p, res[sk], cam, ctx.width, ctx.height, n_sub, dev)}

            ctx.add_pass(ctx.pass_name("izb_gbuffer", light), inputs=(sk,), outputs=(msaa,), run=run_msaa, stage="gbuffer_ms", light=light)

        samples_key = ctx.key("izb_samples", light)

        def run_samples(res):
            gb = res[gbuf]
            smp = place_samples(p, gb, res[sk], cam, L, ray_epsilon(gb), dmax, n_sub, dev, counters,
                                stencil=res[stencil] if stencil is not None else None, probes=res[probes] if probes is not None else None,
                                msaa=res[msaa] if msaa is not None else None)
            return {samples_key: smp}

        ins = (gbuf, sk) + tuple(k for k in (stencil, probes, msaa) if k is not None)
        ctx.add_pass(ctx.pass_name("izb_samples", light), inputs=ins, outputs=(samples_key,), run=run_samples, stage="samples", light=light)
        grid_key = self.add_grid_pass(ctx, light, sk, samples_key, counters)
        lit_key = self.add_light_pass(ctx, light, sk, grid_key, counters)
        out = ctx.visibility_key(light)

        def run_resolve(res):
            return {out: ctx.visibility(resolve_samples(res[gbuf], res[samples_key], res[grid_key].rank, res[lit_key], n_sub, dev,
                                                        keep_centre=p.keep_centre))}

        return ctx.add_pass(ctx.pass_name("izb_resolve", light), inputs=(gbuf, samples_key, grid_key, lit_key), outputs=(out,),
                            run=run_resolve, stage="resolve", light=light)

    def add_grid_pass(self, ctx, light, sk, samples_key, counters):
        """The irregular z-buffer: a light view fitted to the inserted samples and its grid of lists."""
        p = self.params
        scene = ctx.scene
        dev = ctx.device
        grid_key = ctx.key("izb_grid", light)
        grid_pass = ctx.pass_name("izb_grid", light)

        def run_grid(res):
            ds, smp = res[sk], res[samples_key]
            ins_h = smp["insert"].numpy() != 0
            insert = smp["insert"]
            if light.shaping.coned:  # samples outside a shaped light's cone are masked (docs/outputs.md): not inserted
                ins_h &= reach_mask(light, smp["origin"].numpy())
                insert = wp.array(ins_h.astype(np.int32), dtype=wp.int32, device=dev)
            pts = smp["origin"].numpy()[ins_h]
            lo, hi = scene.bounds
            view = fit_light_view(light, pts if len(pts) else np.zeros((1, 3)), lo, hi, p.grid_size,
                                  casters=scene.caster_points if light.kind == LIGHT_DISTANT else None,
                                  all_casters=lambda: scene.caster_points)
            grid = build_grid(view, smp["origin"], smp["dir"], smp["tmax"], insert, ds.points, ds.indices,
                              without_culling(ds.cutouts, ds.tri_total, dev), ds.has_cutouts, dev)
            ll = grid.list_lengths
            counters.update(
                samples_inserted=grid.inserted, samples_outside=grid.outside, cells=view.width * view.height,
                cells_occupied=int(len(ll)), list_max=int(ll.max()) if len(ll) else 0,
                list_mean=float(ll.mean()) if len(ll) else 0.0, list_p99=float(np.percentile(ll, 99)) if len(ll) else 0.0,
                grid_bytes=grid.grid_bytes, list_bytes=grid.list_bytes,
            )
            if grid.outside:
                from wsoft.techniques import unmapped_techniques

                remedy = outside_view_remedy(light, None, unmapped_techniques(), no_cube=f"izb builds no cube map ({self.cube_refusal})")
                ctx.ctx.warn(grid_pass, outside_view_warning(light, f"{grid.outside} shadow samples", remedy))
            return {grid_key: grid}

        ctx.add_pass(grid_pass, inputs=(sk, samples_key), outputs=(grid_key,), run=run_grid, stage="grid", light=light)
        return grid_key

    def add_light_pass(self, ctx, light, sk, grid_key, counters):
        """The occluders rasterized conservatively over the grid; every sample of a touched cell tested exactly."""
        dev = ctx.device
        casting = ctx.scene.casting_triangles(light)  # collection:shadowLink: the light pass draws only these (None: all)
        lit_key = ctx.key("izb_blocked", light)

        def run_light(res):
            ds, grid = res[sk], res[grid_key]
            if grid.inserted:
                r = make_rasterizer(grid.view, izb_test, conservative=True)
                tris = None if casting is None else wp.array(casting, dtype=wp.int32, device=dev)
                st = r.run(ds.points, ds.indices, grid.target.cut, grid.view, grid.target, dev, triangles=tris, initialized=False)
                counters["cpu_private_targets"] = st.private_targets
                t = grid.target
                counters["triangle_cell_pairs"] = int(t.pairs.numpy().sum(dtype=np.int64))
                counters["sample_tests"] = int(t.tests.numpy().sum(dtype=np.int64))
                counters["samples_blocked"] = int(t.blocked.numpy()[: grid.inserted].sum())
            else:
                grid.target.blocked.zero_()
                counters.update(triangle_cell_pairs=0, sample_tests=0, samples_blocked=0)
            return {lit_key: grid.target.blocked}

        ctx.add_pass(ctx.pass_name("izb_light", light), inputs=(sk, grid_key), outputs=(lit_key,), run=run_light, stage="light", light=light)
        return lit_key
