"""``izb``: irregular z-buffer shadows (Johnson et al.) with adaptive eye-view anti-aliasing
(Galoppo, "Eye-View Pixel Anti-Aliasing for Irregular Shadow Mapping", GPU Pro 1.6).

Hard shadows of the light's centre (a point light exactly; an area light from its centre, as
``hard``), pixel-exact: the shadow is decided per eye sample by an exact ray-triangle test, not
by a depth map, so there is no light-view aliasing at any grid size.

Steps of one light (the paper's eight, as passes):

1. ``izb_stencil`` (``aa=adaptive``) — the *shadow-edge stencil*, the pixels that get sub-samples.
   ``stencil=bounds`` (default) proves, per pixel, that its samples agree or flags it: the plane
   its samples' shadow rays start from (moved off the surface as :func:`shadow_ray` moves them),
   the pixel's footprint on it projected into the light's maps, and per texel of the finest
   pyramid level holding the footprint in ``bounds_texels`` texels per side
   (:func:`footprint_certainty`): *certainly lit* when nothing touching the texel (a conservative
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
   (``reports/izb.md``).
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
   inserted unless none did).
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
from wsoft.accel.pyramid import build_bounds_pyramid, build_moments_pyramid
from wsoft.errors import ParameterError
from wsoft.lightspace.light import LightGPU, in_front, light_center_dir
from wsoft.lightspace.view import ViewGPU, fit_light_view, receiver_plane_affine, receiver_plane_range, texel_of, view_dir, view_of
from wsoft.params import check_ranges
from wsoft.parallel import launch_chunked
from wsoft.raster.camera import CameraGPU, camera_gpu, subpixel_pattern
from wsoft.scene.instancing import InstancesGPU
from wsoft.raster.gbuffer import GBufferGPU, camera_ray, cast_primary, gb_covered, gb_pixel
from wsoft.raster.rasterizer import make_rasterizer
from wsoft.raster.shadow_rays import ray_epsilon, ray_offset, ray_origin
from wsoft.scene.device import face_surfaces
from wsoft.scene.surfaces import CULL_SKIP, Surfaces, without_culling
from wsoft.scene.types import LIGHT_DISTANT, LIGHT_KIND_NAMES, LIGHT_POINT
from wsoft.techniques.base import Quality, Technique, Tolerance, check, param

AA_MODES = ("none", "adaptive", "supersample")
PATTERNS = ("auto", "rotated_grid", "jittered")
STENCILS = ("bounds", "vsm")
SUBSAMPLES = ("auto", "recast", "plane")
STENCIL_RASTER = ("conservative", "ordinary")
STENCIL_RULES = ("cull", "listing")

STENCIL_PARAMS = {"vsm": ("edge_threshold", "stencil_raster", "stencil_rule", "stencil_bias", "min_variance"),
                  "bounds": ("bounds_bias", "bounds_texels")}
RECEIVER_SLACK = wp.constant(3.5)  # the stencil's slack in receiver depth ranges over the texels read

# sample states
BACKGROUND, TEST, HORIZON = 0, 1, 2


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
                                    "elsewhere), recast (every sub-sample's eye ray re-cast: exact surface points everywhere) or plane "
                                    "(always on the centre's plane, as a reconstruction from depth: no scene query, wrong across "
                                    "silhouettes)")
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

    def __post_init__(self):
        check_ranges(self)
        check(self.aa in AA_MODES, f"aa {self.aa!r} is not one of {', '.join(AA_MODES)}")
        check(self.samples in (4, 8, 16), f"samples {self.samples} is not 4, 8 or 16")
        check(self.subsamples in SUBSAMPLES, f"subsamples {self.subsamples!r} is not one of {', '.join(SUBSAMPLES)}")
        check(self.pattern in PATTERNS, f"pattern {self.pattern!r} is not one of {', '.join(PATTERNS)}")
        check(not (self.pattern == "rotated_grid" and self.samples != 4), f"the rotated grid has 4 samples, not {self.samples}")
        check(256 <= self.grid_size <= 8192, f"grid_size {self.grid_size} out of range [256, 8192]")
        m = self.shadow_map_size
        check(256 <= m <= 4096 and m & (m - 1) == 0, f"shadow_map_size {m} is not a power of two in [256, 4096]")
        check(self.stencil in STENCILS, f"stencil {self.stencil!r} is not one of {', '.join(STENCILS)}")
        for other, names in STENCIL_PARAMS.items():
            if other != self.stencil:
                stray = [f.name for f in fields(self) if f.name in names and getattr(self, f.name) != f.default]
                check(not stray, f"{', '.join(stray)}: only stencil={other} reads {'it' if len(stray) == 1 else 'them'}, "
                                 f"and this is stencil={self.stencil}")
        check(self.stencil_raster in STENCIL_RASTER, f"stencil_raster {self.stencil_raster!r} is not one of {', '.join(STENCIL_RASTER)}")
        check(self.stencil_rule in STENCIL_RULES, f"stencil_rule {self.stencil_rule!r} is not one of {', '.join(STENCIL_RULES)}")

    @property
    def pattern_kind(self) -> str:
        if self.pattern != "auto":
            return self.pattern
        return "rotated_grid" if self.samples == 4 else "jittered"


# --------------------------------------------------------------------------- kernels


@wp.func
def shadow_ray(L: LightGPU, p: wp.vec3, n: wp.vec3, eps: float, dmax: float):
    """A sample's ray toward the light's centre: (origin off the surface, unit direction, length,
    state TEST, or HORIZON where the centre lies behind the tangent plane). ``dmax >= 0``
    (``inputs:shadow:distance``): the ray ends that far from the surface point."""
    off = ray_offset(p, eps)
    o = ray_origin(p, n, off)
    c = light_center_dir(L, o)
    d = wp.vec3(c[0], c[1], c[2])
    state = int(1)
    if not in_front(n, d):
        state = 2
    t = c[3]
    if dmax >= 0.0:
        t = wp.max(wp.min(t, dmax - off), 0.0)
    return o, d, t, state


@wp.func
def store_sample(
    i: int,
    found: bool,
    L: LightGPU,
    p: wp.vec3,
    n: wp.vec3,
    eps: float,
    dmax: float,
    may_insert: bool,
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    state: wp.array[wp.int32],
    insert: wp.array[wp.int32],
):
    """Sample i: its shadow ray and state (BACKGROUND where ``found`` is false); inserted when it
    needs a test and ``may_insert``."""
    if not found:
        state[i] = 0
        insert[i] = 0
        origin[i] = wp.vec3(0.0)
        dir[i] = wp.vec3(0.0)
        tmax[i] = 0.0
        return
    o, d, t, st = shadow_ray(L, p, n, eps, dmax)
    origin[i] = o
    dir[i] = d
    tmax[i] = t
    state[i] = st
    insert[i] = wp.where(st == 1 and may_insert, 1, 0)


@wp.kernel
def centre_samples(
    offset: int,
    L: LightGPU,
    gb: GBufferGPU,
    eps: float,
    dmax: float,
    multi: wp.array[wp.int32],
    # outputs
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    state: wp.array[wp.int32],
    insert: wp.array[wp.int32],
):
    """The G-buffer's samples (pixel centres); inserted unless their pixel is multi-sampled."""
    i = wp.tid() + offset
    store_sample(i, gb_covered(gb, i), L, gb.pos[i], gb.nrm[i], eps, dmax, multi[i] < 0, origin, dir, tmax, state, insert)


@wp.kernel
def sub_samples(
    offset: int,
    base: int,
    n_sub: int,
    pixels: wp.array[wp.int32],
    pattern: wp.array[wp.vec2],
    mesh: wp.uint64,
    inst: InstancesGPU,
    cut: Surfaces,
    has_cutouts: int,
    cam: CameraGPU,
    gb: GBufferGPU,
    mixed: wp.array[wp.int32],
    mode: int,
    probed: wp.array[wp.int32],
    slot: wp.array[wp.int32],
    hit_pos: wp.array[wp.vec3],
    hit_nrm: wp.array[wp.vec3],
    hit_found: wp.array[wp.int32],
    L: LightGPU,
    eps: float,
    dmax: float,
    # outputs
    origin: wp.array[wp.vec3],
    dir: wp.array[wp.vec3],
    tmax: wp.array[float],
    state: wp.array[wp.int32],
    insert: wp.array[wp.int32],
    recast: wp.array[wp.int32],
):
    """Sub-sample s of multi-sampled pixel j at its sub-pixel offset: on the plane of the pixel's
    centre (where the camera ray meets it: no scene query) or by re-casting its eye ray through the
    scene. ``mode`` (:data:`SUBSAMPLES`): 0 auto — on the plane where the pixel sees that plane
    alone (``mixed`` 0, :func:`other_surface_near`), else re-cast; 1 recast — always; 2 plane —
    always on the plane (re-cast only where the ray misses it). A pixel the stencil ``probed``
    (:func:`bounds_stencil`) takes the hits its eye rays found there (the same rays, the same
    answer). ``recast`` = 1 where re-cast here, 2 where the stencil's hit was taken."""
    k = wp.tid() + offset
    j = k / n_sub
    s = k - j * n_sub
    pix = pixels[j]
    xy = gb_pixel(gb, pix)
    off = pattern[s]
    fx = float(xy[0]) + off[0]
    fy = float(xy[1]) + off[1]
    recast[k] = 1
    if mode == 0 and mixed[pix] != 0 and probed[pix] != 0:
        h = slot[pix] * n_sub + s
        recast[k] = 2
        store_sample(base + k, hit_found[h] != 0, L, hit_pos[h], hit_nrm[h], eps, dmax, True, origin, dir, tmax, state, insert)
    elif mode == 2 or (mode == 0 and mixed[pix] == 0):
        o, d, t0, t1 = camera_ray(cam, gb.width, gb.height, fx, fy)
        pc = gb.pos[pix]
        nc = gb.nrm[pix]
        den = wp.dot(d, nc)
        if den < -1.0e-8:  # the plane faces the camera (its normal is viewer-facing)
            t = wp.dot(pc - o, nc) / den
            if t >= t0 and t <= t1:
                recast[k] = 0
                store_sample(base + k, True, L, o + d * t, nc, eps, dmax, True, origin, dir, tmax, state, insert)
    if recast[k] == 1:
        found, p, n, face, bu, bv, dist = cast_primary(mesh, cut, has_cutouts, inst, cam, gb.width, gb.height, fx, fy)
        store_sample(base + k, found != 0, L, p, n, eps, dmax, True, origin, dir, tmax, state, insert)


@wp.kernel
def centre_fallback(
    offset: int,
    base: int,
    n_sub: int,
    pixels: wp.array[wp.int32],
    state: wp.array[wp.int32],
    # outputs
    insert: wp.array[wp.int32],
    fallback: wp.array[wp.int32],
):
    """A multi-sampled pixel none of whose sub-samples hit a surface keeps its centre sample."""
    j = wp.tid() + offset
    hit = int(0)
    for s in range(n_sub):
        if state[base + j * n_sub + s] != 0:
            hit = 1
    pix = pixels[j]
    fallback[j] = 0
    if hit == 0 and state[pix] != 0:
        fallback[j] = 1
        insert[pix] = wp.where(state[pix] == 1, 1, 0)


@wp.func
def sample_visible(state: int, r: int, blocked: wp.array[wp.int32]) -> float:
    if state == 1:
        if r >= 0:
            if blocked[r] != 0:
                return 0.0
        return 1.0
    return 0.0


@wp.kernel
def resolve_izb(
    offset: int,
    gb: GBufferGPU,
    multi: wp.array[wp.int32],
    fallback: wp.array[wp.int32],
    base: int,
    n_sub: int,
    state: wp.array[wp.int32],
    rank: wp.array[wp.int32],
    blocked: wp.array[wp.int32],
    # outputs
    vis: wp.array[float],
):
    """A pixel's visibility: its centre sample's, or the mean over its sub-samples that hit a surface."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        return
    j = multi[i]
    if j >= 0 and fallback[j] == 0:
        total = float(0.0)
        hits = int(0)
        for s in range(n_sub):
            q = base + j * n_sub + s
            st = state[q]
            if st != 0:
                hits += 1
                total += sample_visible(st, rank[q], blocked)
        vis[i] = total / float(hits)
        return
    vis[i] = sample_visible(state[i], rank[i], blocked)


@wp.func
def moments_at(pyr: wp.array[wp.vec2], off: int, size: int, x: int, y: int) -> wp.vec2:
    return pyr[off + y * size + x]


@wp.func
def chebyshev(m: wp.vec2, t: float, min_var: float, lower: int) -> float:
    """One-tailed Chebyshev bound of the mass below t (``lower``) or at/above t of the distribution
    with moments m; 1 where t lies on the far side of the mean."""
    mu = m[0]
    var = wp.max(min_var, m[1] - mu * mu)
    d = mu - t
    if lower != 0:
        if d <= 0.0:
            return 1.0
    else:
        if d >= 0.0:
            return 1.0
    return var / (var + d * d)


@wp.kernel
def edge_stencil(
    offset: int,
    gb: GBufferGPU,
    cam: CameraGPU,
    lv: ViewGPU,
    pyr: wp.array[wp.vec2],
    level_off: wp.array[wp.int32],
    levels: int,
    map_size: int,
    depth_scale: float,
    threshold: float,
    min_var: float,
    bias: float,
    listing: int,
    may_shadow: int,
    # outputs
    edge: wp.array[wp.int32],
):
    """Potential shadow-edge pixels (1), from the mip-mapped variance shadow map."""
    i = wp.tid() + offset
    edge[i] = 0
    if not gb_covered(gb, i):
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    xy = gb_pixel(gb, i)
    # the pixel's footprint on its tangent plane: the camera rays through its corners
    xmin = float(1.0e30)
    xmax = float(-1.0e30)
    ymin = float(1.0e30)
    ymax = float(-1.0e30)
    zmin = float(1.0e30)
    zmax = float(-1.0e30)
    bounded = int(1)
    for c in range(5):
        q = p
        if c < 4:
            o, d, t0, t1 = camera_ray(cam, gb.width, gb.height, float(xy[0] + c % 2), float(xy[1] + c / 2))
            den = wp.dot(d, n)
            if wp.abs(den) < 1.0e-8:
                bounded = 0
            else:
                s = wp.dot(p - o, n) / den
                if s <= 0.0:
                    bounded = 0
                q = o + d * s
        v = view_of(lv, q)
        if lv.persp != 0 and v[2] <= lv.near:
            bounded = 0
        else:
            tx = texel_of(lv, v)
            xmin = wp.min(xmin, tx[0])
            xmax = wp.max(xmax, tx[0])
            ymin = wp.min(ymin, tx[1])
            ymax = wp.max(ymax, tx[1])
            zmin = wp.min(zmin, v[2])
            zmax = wp.max(zmax, v[2])
    if bounded == 0 or not (xmax - xmin < 1.0e6 and ymax - ymin < 1.0e6):
        edge[i] = 1  # a grazing or unbounded footprint: nothing can be ruled out
        return
    extent = wp.max(wp.max(xmax - xmin, ymax - ymin), 1.0e-6)
    slope = (zmax - zmin) * depth_scale / extent  # the receiver's normalised depth change per texel
    xmin -= 1.0
    ymin -= 1.0
    xmax += 1.0
    ymax += 1.0
    e = wp.max(xmax - xmin, ymax - ymin)
    lev = int(wp.ceil(wp.log2(wp.max(e, 1.0))))
    lev = wp.clamp(lev, 0, levels - 1)
    # t: the footprint's nearest depth less a slack. The texels read span up to 2^(lev+1) base texels,
    # over which the receiver's own depth (in the map as its nearest depth per texel) spreads by
    # r = slope 2^(lev+1); a receiver alone then has mean >= t_lo - r and standard deviation <= r / sqrt(12),
    # and its Chebyshev bound stays above 1% unless the mean lies 10 deviations past t: slack 3.5 r
    slack = RECEIVER_SLACK * slope * float(2 << lev) + bias
    tn = (zmin - lv.near) * depth_scale - slack
    size = map_size >> lev
    sc = 1.0 / float(1 << lev)
    x0 = int(wp.floor(xmin * sc))
    x1 = int(wp.floor(xmax * sc))
    y0 = int(wp.floor(ymin * sc))
    y1 = int(wp.floor(ymax * sc))
    if x1 < 0 or y1 < 0 or x0 >= size or y0 >= size:
        edge[i] = 1  # outside the map: nothing known
        return
    x0 = wp.clamp(x0, 0, size - 1)
    x1 = wp.clamp(x1, 0, size - 1)
    y0 = wp.clamp(y0, 0, size - 1)
    y1 = wp.clamp(y1, 0, size - 1)
    m = wp.vec2(0.0)
    cnt = float(0.0)
    for y in range(y0, y1 + 1):
        for x in range(x0, x1 + 1):
            m += moments_at(pyr, level_off[lev], size, x, y)
            cnt += 1.0
    m = m / cnt
    lit = chebyshev(m, tn, min_var, 1) < threshold  # occluder mass in front of the footprint: almost none
    shadowed = chebyshev(m, tn, min_var, 0) < threshold and may_shadow != 0  # mass at or beyond it: almost none
    if listing != 0:
        if lit or shadowed:
            edge[i] = 1
    elif not lit and not shadowed:
        edge[i] = 1


@wp.func
def same_plane(p: wp.vec3, n: wp.vec3, q: wp.vec3, m: wp.vec3) -> bool:
    """Does the surface point (q, m) lie on the plane (p, n), to float precision?"""
    return wp.dot(m, n) >= 0.9999 and wp.abs(wp.dot(q - p, n)) <= 1.0e-4 * wp.length(q - p)


@wp.func
def other_surface_near(gb: GBufferGPU, cut: Surfaces, i: int) -> int:
    """1 where pixel i may see more than its centre's plane: a neighbour (of 8) on another plane or
    on nothing, or a cutout under its centre (a hole may open anywhere in the pixel); else 0."""
    if cut.tri_cut[gb.prim[i]] >= 0:
        return 1
    p = gb.pos[i]
    n = gb.nrm[i]
    xy = gb_pixel(gb, i)
    for k in range(9):
        nx = xy[0] + k % 3 - 1
        ny = xy[1] + k / 3 - 1
        if k != 4 and nx >= 0 and ny >= 0 and nx < gb.width and ny < gb.height:
            j = ny * gb.width + nx
            pr = gb.prim[j]
            if pr < 0:
                return 1
            if pr != gb.prim[i] and not same_plane(p, n, gb.pos[j], gb.nrm[j]):  # another triangle, maybe coplanar
                return 1
    return 0


@wp.kernel
def mixed_pixels(
    offset: int,
    gb: GBufferGPU,
    cut: Surfaces,
    # outputs
    mixed: wp.array[wp.int32],
):
    """:func:`other_surface_near` for every covered pixel (0 elsewhere)."""
    i = wp.tid() + offset
    mixed[i] = 0
    if gb_covered(gb, i):
        mixed[i] = other_surface_near(gb, cut, i)


@wp.func
def footprint_certainty(
    lv: ViewGPU,
    cam: CameraGPU,
    width: int,
    height: int,
    xy: wp.vec2i,
    L: LightGPU,
    p: wp.vec3,
    n: wp.vec3,
    closed: bool,
    eps: float,
    bounds: wp.array[wp.vec4],
    level_off: wp.array[wp.int32],
    levels: int,
    map_size: int,
    bias: float,
    max_texels: int,
    may_shadow: int,
) -> wp.vec2i:
    """Is the part of pixel ``xy`` on the plane (``p``, ``n``; ``closed``: of a closed surface)
    certainly lit, certainly shadowed (1 / 0 each)? Exact bounds, no probability: every texel of the
    finest pyramid level that covers the footprint in at most ``max_texels`` per side is compared
    with the plane's own depths over it (``bounds``: per texel the nearest depth of every surface,
    of the back faces of closed surfaces, of open surfaces, all rasterized conservatively, and the
    farthest depth of the inner-coverage map). Certainly lit: nothing touching the texel is nearer
    than the plane's nearest point in the texel (the receiver itself is in that map, at that
    point), no back face of a closed surface is nearer than the plane's farthest point of the
    footprint in the texel (every ray that crosses a closed blocker leaves it through a back face;
    this catches a blocker a steep plane's own depth hides in the first map) and, on a closed
    receiver, no open surface is either. Certainly shadowed: the texel is covered whole by a
    blocker nearer than the plane anywhere in the footprint's part of the texel.

    The plane is the one the samples' shadow rays start from: moved off the surface along ``n`` as
    :func:`shadow_ray` moves them (``eps``); at a grazing light that shift alone moves a point
    across texels. ``may_shadow = 0`` (a finite ``inputs:shadow:distance``, which the maps cannot
    check): never certainly shadowed by a blocker, only by the light's centre being behind the plane."""
    c = light_center_dir(L, p)
    if not in_front(n, wp.vec3(c[0], c[1], c[2])):
        return wp.vec2i(0, 1)  # the light's centre is behind the plane: every sample on it is shadowed
    ok, xp, q0, gx, gy = receiver_plane_affine(lv, view_of(lv, ray_origin(p, n, ray_offset(p, eps))), view_dir(lv, n))
    if not ok:
        return wp.vec2i(0, 0)
    xmin = float(1.0e30)
    xmax = float(-1.0e30)
    ymin = float(1.0e30)
    ymax = float(-1.0e30)
    for k in range(4):
        o, d, t0, t1 = camera_ray(cam, width, height, float(xy[0] + k % 2), float(xy[1] + k / 2))
        den = wp.dot(d, n)
        if wp.abs(den) < 1.0e-8:
            return wp.vec2i(0, 0)
        s = wp.dot(p - o, n) / den
        if s <= 0.0:
            return wp.vec2i(0, 0)
        q = o + d * s
        v = view_of(lv, ray_origin(q, n, ray_offset(q, eps)))
        if lv.persp != 0 and v[2] <= lv.near:
            return wp.vec2i(0, 0)
        corner = texel_of(lv, v)
        xmin = wp.min(xmin, corner[0])
        xmax = wp.max(xmax, corner[0])
        ymin = wp.min(ymin, corner[1])
        ymax = wp.max(ymax, corner[1])
    # a hair wider against rounding; outside the map nothing is known
    xmin -= 0.01
    ymin -= 0.01
    xmax += 0.01
    ymax += 0.01
    fs = float(map_size)
    if not (xmin >= 0.0 and ymin >= 0.0 and xmax < fs and ymax < fs):
        return wp.vec2i(0, 0)
    lev = int(0)
    while lev < levels - 1 and (int(xmax) / (1 << lev) - int(xmin) / (1 << lev) >= max_texels
                                or int(ymax) / (1 << lev) - int(ymin) / (1 << lev) >= max_texels):
        lev += 1
    size = map_size >> lev
    side = float(1 << lev)
    tx0 = int(xmin) >> lev
    ty0 = int(ymin) >> lev
    nx = (int(xmax) >> lev) - tx0 + 1
    count = nx * ((int(ymax) >> lev) - ty0 + 1)
    lit = int(1)
    shadowed = may_shadow
    for k in range(count):
        tx = tx0 + k % nx
        ty = ty0 + k / nx
        j = level_off[lev] + ty * size + tx
        xa = float(tx) * side
        ya = float(ty) * side
        whole = receiver_plane_range(lv, xp, q0, gx, gy, xa, ya, xa + side, ya + side)
        part = receiver_plane_range(lv, xp, q0, gx, gy, wp.max(xa, xmin), wp.max(ya, ymin), wp.min(xa + side, xmax), wp.min(ya + side, ymax))
        m = bounds[j]
        if whole[0] < 0.0 or m[0] < whole[0] - bias or m[1] < part[1] - bias:
            lit = 0
        elif m[2] < wp.where(closed, part[1], whole[0]) - bias:
            lit = 0
        if part[0] < 0.0 or m[3] >= part[0] - bias:
            shadowed = 0
        if lit == 0 and shadowed == 0:
            break
    return wp.vec2i(lit, shadowed)


@wp.kernel
def bounds_stencil(
    offset: int,
    gb: GBufferGPU,
    cam: CameraGPU,
    lv: ViewGPU,
    L: LightGPU,
    bounds: wp.array[wp.vec4],
    closed_faces: wp.array[wp.int32],
    level_off: wp.array[wp.int32],
    levels: int,
    map_size: int,
    bias: float,
    max_texels: int,
    eps: float,
    may_shadow: int,
    pattern: wp.array[wp.vec2],
    mesh: wp.uint64,
    inst: InstancesGPU,
    cut: Surfaces,
    has_cutouts: int,
    mixed: wp.array[wp.int32],
    slot: wp.array[wp.int32],
    # outputs
    edge: wp.array[wp.int32],
    probed: wp.array[wp.int32],
    hit_pos: wp.array[wp.vec3],
    hit_nrm: wp.array[wp.vec3],
    hit_found: wp.array[wp.int32],
):
    """Potential shadow-edge pixels (1) by exact depth bounds (:func:`footprint_certainty`): a pixel
    is certain when its part on its own plane is certainly lit or certainly shadowed and, where a
    neighbour's surface differs (``mixed``: a silhouette or a crease may cross the pixel), so is its
    part on the plane of every surface its sub-pixel eye rays meet (``pattern``, the sub-samples the
    pixel would get). Those rays are all cast (``probed`` = 1) and their hits kept at the pixel's
    ``slot`` for :func:`sub_samples`, which then casts none of them again."""
    i = wp.tid() + offset
    edge[i] = 0
    probed[i] = 0
    if not gb_covered(gb, i):
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    xy = gb_pixel(gb, i)
    r = footprint_certainty(lv, cam, gb.width, gb.height, xy, L, p, n, closed_faces[gb.prim[i]] != CULL_SKIP, eps, bounds, level_off,
                            levels, map_size, bias, max_texels, may_shadow)
    lit = r[0]
    shadowed = r[1]
    if lit == 0 and shadowed == 0:
        edge[i] = 1
        return
    if mixed[i] == 0:
        return
    probed[i] = 1
    ns = pattern.shape[0]
    for s in range(ns):
        off = pattern[s]
        found, q, m, face, bu, bv, dist = cast_primary(mesh, cut, has_cutouts, inst, cam, gb.width, gb.height,
                                                       float(xy[0]) + off[0], float(xy[1]) + off[1])
        h = slot[i] * ns + s
        hit_found[h] = found
        hit_pos[h] = q
        hit_nrm[h] = m
        if found != 0 and (lit != 0 or shadowed != 0):
            if not same_plane(p, n, q, m):
                r = footprint_certainty(lv, cam, gb.width, gb.height, xy, L, q, m, closed_faces[face] != CULL_SKIP, eps, bounds, level_off,
                                        levels, map_size, bias, max_texels, may_shadow)
                lit = lit * r[0]
                shadowed = shadowed * r[1]
    if lit == 0 and shadowed == 0:
        edge[i] = 1


# --------------------------------------------------------------------------- the technique


class IZB(Technique):
    """Irregular z-buffer hard shadows (exact per eye sample) with adaptive eye-view anti-aliasing."""

    name = "izb"
    instancing_refusal = "its light pass, stencil maps and sub-pixel rays walk the triangle soup"
    summary = "irregular z-buffer: exact hard shadows of the light's centre per eye sample, adaptive eye-view anti-aliasing (Galoppo)"
    Params = IZBParams
    reads = ("gbuffer", "scene.triangles", "scene.textures", "light_depth_conservative")
    writes = ("visibility",)
    quality = (
        Quality("aa", ("none", "adaptive", "supersample"), "sub-pixel samples on no pixel, on potential shadow edges, on every pixel"),
        Quality("samples", (4, 8, 16), "sub-samples of a multi-sampled pixel"),
    )
    # a binary shadow of the light's centre (as hard): exact where the light is a point
    tolerance = Tolerance(mae=0.009, mae_penumbra=0.36)
    horizon = "exact"  # per sample: the light's centre behind the tangent plane is shadowed

    @staticmethod
    def treatment(light) -> str:
        kind = LIGHT_KIND_NAMES.get(light.kind, str(light.kind))
        return "exact (point light)" if light.kind == LIGHT_POINT else f"from the light's centre ({kind} light: the hard shadow of its centre)"

    def bake_support(self) -> str | None:
        if self.params.aa != "none":
            return (f"aa={self.params.aa} anti-aliases over the eye view's pixels (sub-pixel eye rays, a screen-space shadow-edge "
                    f"stencil) and a bake has no camera; bake with aa=none (the exact hard shadow of the light's centre at each point)")
        return None

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
        scene = ctx.scene
        counters = ctx.counters(light)
        counters["light"] = self.treatment(light)
        n_sub = p.samples if p.aa != "none" else 0
        dmax = float(light.shadow_distance)  # inputs:shadow:distance (-1: none): each sample's ray ends there
        may_shadow = int(not light.distance_limited)  # the stencil's maps cannot tell a caster's distance
        casting = scene.casting_triangles(light)  # collection:shadowLink: the light pass draws only these (None: all)

        def edge_counters(edge, gb):
            e = edge.numpy()
            covered = int((gb.prim.numpy() >= 0).sum())
            counters["edge_pixels"] = int(e.sum())
            counters["edge_fraction"] = float(e.sum() / covered) if covered else 0.0
            return edge

        stencil = probes = None
        if p.aa == "adaptive" and p.stencil == "bounds":
            outer = ctx.light_depth(light, size=p.shadow_map_size, conservative=True, opaque=True)
            back = ctx.light_depth(light, size=p.shadow_map_size, conservative=True, opaque=True, faces="back")
            opened = ctx.light_depth(light, size=p.shadow_map_size, conservative=True, opaque=True, faces="open")
            inner = ctx.light_depth(light, size=p.shadow_map_size, inner=True)
            stencil = ctx.key("izb_stencil", light)
            probes = ctx.key("izb_probes", light)

            def run_bounds(res):
                gb, dm, di = res[gbuf], res[outer], res[inner]
                v = dm.view
                pyr, offs = build_bounds_pyramid([dm.depth, res[back].depth, res[opened].depth], di.depth, dev)
                closed_faces = face_surfaces(res[sk], v.origin if v.persp else None, "back").cull
                ds = res[sk]
                edge = wp.empty(gb.count, dtype=wp.int32, device=dev)
                probed = wp.empty(gb.count, dtype=wp.int32, device=dev)
                mixed = wp.empty(gb.count, dtype=wp.int32, device=dev)
                launch_chunked(mixed_pixels, gb.count, inputs=[gb.gpu(), ds.cutouts], outputs=[mixed], device=dev)
                # a slot of n_sub hits per pixel that may probe (one next to another surface); host scan: no atomics
                m = mixed.numpy()
                slot_h = np.where(m != 0, np.cumsum(m) - 1, -1).astype(np.int32)
                nhits = max(int(m.sum()) * n_sub, 1)
                hits = {"pos": wp.empty(nhits, dtype=wp.vec3, device=dev), "nrm": wp.empty(nhits, dtype=wp.vec3, device=dev),
                        "found": wp.empty(nhits, dtype=wp.int32, device=dev), "slot": wp.array(slot_h, dtype=wp.int32, device=dev),
                        "probed": probed, "mixed": mixed}
                pat = subpixel_pattern(n_sub, p.pattern_kind, p.seed)
                launch_chunked(bounds_stencil, gb.count,
                               inputs=[gb.gpu(), cam, v.gpu(), L, pyr, closed_faces, wp.array(offs, dtype=wp.int32, device=dev), len(offs) - 1,
                                       p.shadow_map_size, p.bounds_bias * max(v.far - v.near, 1e-12), p.bounds_texels,
                                       ray_epsilon(gb, light), may_shadow, wp.array(pat, dtype=wp.vec2, device=dev), ds.mesh.id, ds.inst, ds.cutouts,
                                       int(ds.has_cutouts), mixed, hits["slot"]],
                               outputs=[edge, probed, hits["pos"], hits["nrm"], hits["found"]], device=dev)
                counters["stencil_probed_pixels"] = int(probed.numpy().sum())
                return {stencil: edge_counters(edge, gb), probes: hits}

            ctx.add_pass(ctx.pass_name("izb_stencil", light), inputs=(gbuf, sk, outer, back, opened, inner), outputs=(stencil, probes),
                         run=run_bounds, light=light)
        elif p.aa == "adaptive":
            depth = ctx.light_depth(light, size=p.shadow_map_size, conservative=p.stencil_raster == "conservative")
            stencil = ctx.key("izb_stencil", light)

            def run_stencil(res):
                gb, dm = res[gbuf], res[depth]
                v = dm.view
                pyr, offs = build_moments_pyramid(dm.depth, v.near, v.far, dev)
                edge = wp.empty(gb.count, dtype=wp.int32, device=dev)
                scale = 1.0 / (v.far - v.near) if v.far > v.near else 1.0
                launch_chunked(edge_stencil, gb.count,
                               inputs=[gb.gpu(), cam, v.gpu(), pyr, wp.array(offs, dtype=wp.int32, device=dev), len(offs) - 1,
                                       p.shadow_map_size, scale, p.edge_threshold, p.min_variance, p.stencil_bias,
                                       int(p.stencil_rule == "listing"), may_shadow],
                               outputs=[edge], device=dev)
                return {stencil: edge_counters(edge, gb)}

            ctx.add_pass(ctx.pass_name("izb_stencil", light), inputs=(gbuf, depth), outputs=(stencil,), run=run_stencil, light=light)

        samples_key = ctx.key("izb_samples", light)

        def run_samples(res):
            gb, ds = res[gbuf], res[sk]
            n0 = gb.count
            covered = gb.prim.numpy() >= 0
            if p.aa == "adaptive":
                pixels = np.flatnonzero(res[stencil].numpy() & covered).astype(np.int32)
            elif p.aa == "supersample":
                pixels = np.flatnonzero(covered).astype(np.int32)
            else:
                pixels = np.zeros(0, np.int32)
            multi_h = np.full(n0, -1, np.int32)
            multi_h[pixels] = np.arange(len(pixels), dtype=np.int32)
            total = n0 + len(pixels) * n_sub
            eps = ray_epsilon(gb, light)
            arr = {
                "origin": wp.empty(total, dtype=wp.vec3, device=dev), "dir": wp.empty(total, dtype=wp.vec3, device=dev),
                "tmax": wp.empty(total, dtype=float, device=dev), "state": wp.empty(total, dtype=wp.int32, device=dev),
                "insert": wp.empty(total, dtype=wp.int32, device=dev),
            }
            outs = [arr["origin"], arr["dir"], arr["tmax"], arr["state"], arr["insert"]]
            multi = wp.array(multi_h, dtype=wp.int32, device=dev)
            pix = wp.array(pixels if len(pixels) else np.zeros(1, np.int32), dtype=wp.int32, device=dev)
            fallback = wp.zeros(max(len(pixels), 1), dtype=wp.int32, device=dev)
            launch_chunked(centre_samples, n0, inputs=[L, gb.gpu(), eps, dmax, multi], outputs=outs, device=dev)
            if len(pixels):
                pat = subpixel_pattern(n_sub, p.pattern_kind, p.seed)
                mode = SUBSAMPLES.index(p.subsamples)
                none1 = wp.zeros(1, dtype=wp.int32, device=dev)
                hits = {"pos": wp.zeros(1, dtype=wp.vec3, device=dev), "nrm": wp.zeros(1, dtype=wp.vec3, device=dev), "found": none1,
                        "slot": none1, "probed": wp.zeros(n0, dtype=wp.int32, device=dev), "mixed": none1}
                if probes is not None:  # the stencil's mixed pixels and the hits of the eye rays it cast
                    hits = res[probes]
                elif p.subsamples == "auto":
                    hits["mixed"] = wp.empty(n0, dtype=wp.int32, device=dev)
                    launch_chunked(mixed_pixels, n0, inputs=[gb.gpu(), ds.cutouts], outputs=[hits["mixed"]], device=dev)
                mixed = hits["mixed"]
                recast = wp.empty(len(pixels) * n_sub, dtype=wp.int32, device=dev)
                launch_chunked(sub_samples, len(pixels) * n_sub,
                               inputs=[n0, n_sub, pix, wp.array(pat, dtype=wp.vec2, device=dev), ds.mesh.id, ds.inst, ds.cutouts,
                                       int(ds.has_cutouts), cam, gb.gpu(), mixed, mode, hits["probed"], hits["slot"], hits["pos"],
                                       hits["nrm"], hits["found"], L, eps, dmax],
                               outputs=outs + [recast], device=dev)
                rc = recast.numpy()
                counters["subsamples_recast"] = int((rc == 1).sum())
                counters["subsamples_from_stencil"] = int((rc == 2).sum())
                launch_chunked(centre_fallback, len(pixels), inputs=[n0, n_sub, pix, arr["state"]], outputs=[arr["insert"], fallback], device=dev)
            st = arr["state"].numpy()
            counters.setdefault("subsamples_recast", 0)
            counters.setdefault("subsamples_from_stencil", 0)
            counters["multisampled_pixels"] = int(len(pixels))
            counters["extra_samples"] = int(len(pixels) * n_sub)
            counters["centre_fallbacks"] = int(fallback.numpy()[: len(pixels)].sum())
            counters["horizon_samples"] = int((st == HORIZON).sum())
            arr.update(multi=multi, fallback=fallback, base=n0, pixels=len(pixels))
            return {samples_key: arr}

        ins = (gbuf, sk) + ((stencil,) if stencil is not None else ()) + ((probes,) if probes is not None else ())
        ctx.add_pass(ctx.pass_name("izb_samples", light), inputs=ins, outputs=(samples_key,), run=run_samples, light=light)

        grid_key = ctx.key("izb_grid", light)
        grid_pass = ctx.pass_name("izb_grid", light)

        def run_grid(res):
            ds, smp = res[sk], res[samples_key]
            ins_h = smp["insert"].numpy() != 0
            pts = smp["origin"].numpy()[ins_h]
            lo, hi = scene.bounds
            view = fit_light_view(light, pts if len(pts) else np.zeros((1, 3)), lo, hi, p.grid_size,
                                  casters=scene.caster_points if light.kind == LIGHT_DISTANT else None)
            T = ds.tri_total
            grid = build_grid(view, smp["origin"], smp["dir"], smp["tmax"], smp["insert"], ds.points, ds.indices,
                              without_culling(ds.cutouts, T, dev), ds.has_cutouts, dev)
            ll = grid.list_lengths
            counters.update(
                samples_inserted=grid.inserted, samples_outside=grid.outside, cells=view.width * view.height,
                cells_occupied=int(len(ll)), list_max=int(ll.max()) if len(ll) else 0,
                list_mean=float(ll.mean()) if len(ll) else 0.0, list_p99=float(np.percentile(ll, 99)) if len(ll) else 0.0,
                grid_bytes=grid.grid_bytes, list_bytes=grid.list_bytes,
            )
            if grid.outside:
                ctx.ctx.warn(grid_pass, f"light {light.path}: {grid.outside} shadow samples lie outside its single-frustum view "
                                        f"(more than 80 degrees off its axis) and are left unshadowed; a light that surrounds its receivers "
                                        f"needs a cube map, which this technique does not build")
            return {grid_key: grid}

        ctx.add_pass(grid_pass, inputs=(sk, samples_key), outputs=(grid_key,), run=run_grid, light=light)

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

        ctx.add_pass(ctx.pass_name("izb_light", light), inputs=(sk, grid_key), outputs=(lit_key,), run=run_light, light=light)

        out = ctx.visibility_key(light)

        def run_resolve(res):
            gb, smp, grid, blocked = res[gbuf], res[samples_key], res[grid_key], res[lit_key]
            vis = wp.empty(gb.count, dtype=float, device=dev)
            launch_chunked(resolve_izb, gb.count,
                           inputs=[gb.gpu(), smp["multi"], smp["fallback"], smp["base"], max(n_sub, 1), smp["state"], grid.rank, blocked],
                           outputs=[vis], device=dev)
            return {out: ctx.visibility(vis)}

        return ctx.add_pass(ctx.pass_name("izb_resolve", light), inputs=(gbuf, samples_key, grid_key, lit_key), outputs=(out,),
                            run=run_resolve, light=light)
