"""``rtdenoise``: a few ray-traced shadow rays per pixel, then a shadow denoiser (one frame, spatial only).

Today's production answer to soft shadows on ray-tracing hardware: 1 to 8 shadow rays per pixel
toward points of the light and a denoiser that turns their noisy visible fraction into a smooth
penumbra, guided by the G-buffer.

**Rays.** The reference's own (:mod:`wsoft.reference`): the same stratified per-pixel sample sets
(``samples`` 1 to 8; a jittered ``m x m`` grid for 1 and 4, else the randomly shifted rank-1
lattice; every receiver's set drawn from its own key (counter-based), so the noise is decorrelated
between pixels), the same offset origins, ray lengths, light points and receiver's horizon (a
sample behind the tangent plane is blocked). With ``seed`` equal, a receiver's rays are exactly the
rays of ``reference samples=N`` with the same ``N``, and ``denoiser=none`` is that reference bit for
bit. Each ray is a *closest-hit* query (:func:`~wsoft.scene.rays.blocker_distance`: alpha-tested
through cutouts, through the prims the light's ``collection:shadowLink`` leaves out, ending at
``inputs:shadow:distance``, through the instances of an instanced stage), so each pixel keeps the
distance to its blockers (the mean over its blocked rays): the penumbra estimate needs it, an
any-hit test does not give it.

**A DomeLight** (the sky, :mod:`wsoft.scene.dome`): the dome reference's own rays
(:mod:`wsoft.reference.dome`: the same per-receiver keys, strategies and points, the same offset
origins, rays to the sky or to ``inputs:shadow:distance``), as closest-hit queries (:func:`trace_sky`):
with ``seed`` equal, ``denoiser=none`` is ``reference samples=N`` bit for bit. A constant dome:
cosine-distributed directions about the normal (Malley's method,
:func:`~wsoft.lightspace.sky.cosine_direction`), V the visible fraction. A latlong texture: multiple
importance sampling, ceil(N/2) cosine rays and floor(N/2) drawn from the texture's luminance x solid
angle table, balance-heuristic weights, V = sum a vis / sum a (one ray: a cosine ray alone; a pixel
none of whose rays has weight takes its neighbours' through the denoiser, or 1 with
``denoiser=none``). Each blocked ray's penumbra radius is half its blocker's distance times
``radius_scale`` (the sky subtends a hemisphere: a penumbra as wide as the blocker is far). The
denoisers are the same; there is no front-fraction pass (every ray is in front). V is the visible
fraction of the dome's irradiance, the dome reference's quantity. Counters add ``dome_rays``
(``cosine`` or ``cosine+texture``). Measured on a box on a ground at 96 x 72 against 1024 cosine
rays: MAE 0.097 (1 ray, ``denoiser=none``), 0.037 (8 rays), 0.014 (2 rays, ``penumbra``), 0.012 (2
rays, ``atrous``); ``docs/techniques.md``.

**Penumbra radius** (what NRD SIGMA's front end packs per pixel, ``SIGMA_FrontEnd_PackPenumbra``):
per blocked ray ``d tan(a) / 2``, ``d`` the blocker's distance and ``a`` the light's angular radius
seen from the blocker (``tan a = r / (D - d)``: ``r`` half a rect light's mean side (a cylinder
light's: of length by diameter), a disk's or sphere's radius, 0 for a point light, whose shadows
are not blurred; ``D`` the light point's distance; a distant light: the tangent of its half
angle), a quarter of the penumbra's geometric
width ``2 r d / (D - d)``. This is NRD's directional front end (``d`` times the tangent of the
angular radius, halved) for every light; NRD's local-light front end halves the full width instead,
a radius twice as large (``radius_scale = 2``). Penumbra MAE against 256 reference samples with 2
rays at 640 x 480 on ``box_plane``, ``contact``, ``penumbra_ramp``: 0.026, 0.029, 0.031 at
``radius_scale = 1``, 0.057, 0.037, 0.067 at 2 (one frame's blur over half the width darkens the lit
end of the penumbra and lightens the umbra's).

**Denoisers** (:mod:`wsoft.accel.denoise`; ``denoiser=``):

* ``penumbra`` (the default) — SIGMA-style: ``tile`` x ``tile`` pixel tiles all lit or all in umbra
  are skipped unless a neighbouring tile's penumbra reaches them (``tiles_skipped`` and
  ``samples_skipped`` in the counters), then SIGMA's blur and post-blur: a 5 x 5 estimate of the
  penumbra radius, and ``taps`` Poisson taps over it in pixels (projected through the G-buffer
  point's depth and the camera's field of view, at most ``max_radius``), weighted by the distance
  to the centre's tangent plane (``plane_sensitivity`` of the frustum's size: no blur across a
  depth discontinuity), a Gaussian and SIGMA's umbra-leak guard. SIGMA keeps a pixel's own value
  below 2 pixels of penumbra radius, for a signal its temporal pass accumulates; one frame keeps
  its own value only below ``sharp_below`` = 0.5 pixel (a hard shadow stays sharp): 0.053, 0.059,
  0.045 at 160 x 120 where SIGMA's 2 pixels give 0.060, 0.068, 0.048 (at 640 x 480 within 0.001).
* ``atrous`` — SVGF's spatial part (Schied et al. 2017): a 7 x 7 spatial variance estimate (the
  frame has no history), then ``iterations`` edge-avoiding à-trous steps weighted by the camera
  distance and its screen-space gradient (``sigma_z``), the normal (``sigma_n``) and the visibility
  against its variance (``sigma_l``, SVGF's luminance weight). 3 steps (the paper: 5) and no
  variance boost (Falcor's: x 4 without history) measured best: 0.019, 0.032, 0.027 at 640 x 480,
  where 5 steps give 0.019, 0.032, 0.031 and the boost 0.020, 0.035, 0.029. Its depth weight grows
  with the step, so a depth step smaller than the gradient times the tap's distance is blurred
  across; on 2 CPU cores at 640 x 480 it takes 1.7 to 2.6 times the reference's 16 samples.
* ``none`` — the rays' raw visible fraction.

**The horizon.** The rays test it per sample, as the reference does. The denoisers filter the
visible fraction of the rays *in front of* the receiver's tangent plane and multiply it by the
light's front fraction (the shared exact pass, :mod:`wsoft.raster.horizon`), so a wall the light
straddles is not noisy where half its rays leave behind it; a pixel none of whose rays is in front
takes its neighbours' fraction (or 0 when none has one).

**Temporal accumulation** (in a sequence, :mod:`wsoft.pipeline.sequence`; ``history`` > 1
frames at most; :mod:`wsoft.accel.temporal`): each sample's point reprojected into the previous
frame through the G-buffer's points and the previous camera, kept where that frame saw the same
surface point (within half a pixel footprint, normals within 0.9), the history clamped to the
current 3 x 3 neighbourhood's range and averaged with weight ``1 / n`` (``n`` the history's length,
at most ``history``); each frame draws other rays (the seed plus the frame's index).
``temporal_order=after`` (the default) accumulates the spatially filtered fraction and clamps it to
the filtered neighbourhood, as SIGMA's temporal stabilisation does; ``before`` accumulates the rays'
raw fraction before the spatial filter, SVGF's order (§4.1). Measured at 128 x 96 against 64
reference samples (penumbra MAE, history 1 / before 8 / after 8): a still stage (``ramp_static``,
12 frames) 0.063 / 0.048 / 0.048 with flicker 0.0039 / 0.0009 / 0.0008; a sliding rect light
(``ramp_slide``) 0.064 / 0.060 / 0.062; the sun turning (``bridge_sun_sweep``) 0.144 / 0.294 /
0.302; a flight over ``city`` (``city_flyby``) 0.140 / 0.158 / 0.158 with flicker 0.0059 / 0.0141 /
0.0140. A shadow that moves over a still surface (a moving light) is not surface motion: the
reprojected history trails it, and a 3 x 3 clamp of a 2-ray signal rarely cuts it off. So the
default is ``history=1`` (none); 8 is the setting for still lights and slow cameras. The counters
say ``history`` (``first frame`` or ``reprojected``), ``history_samples``, ``disoccluded`` and
``history_mean_length``. A single frame is spatial only. Bakes need ``denoiser=none`` (a bake point
has no pixel neighbours to filter with).

**Defaults by measurement** (penumbra MAE against 256 reference samples, ``box_plane``,
``contact``, ``penumbra_ramp``, 640 x 480): 2 rays (0.026, 0.029, 0.031; 1 ray: 0.041, 0.040,
0.044), the ``penumbra`` denoiser (``atrous``: 0.019, 0.032, 0.027, at three to four times its
time), SIGMA's 8 taps (16 taps: 0.025, 0.028, 0.030). The penumbra's width in pixels decides: at
160 x 120 the same defaults give 0.053, 0.059, 0.045.

Counters (``stats["counters"]["techniques"]["rtdenoise"][light]``): ``samples``, ``denoiser``,
``rays`` (traced: in front of the receiver's plane), ``rays_blocked``, ``penumbra_samples`` (pixel
samples with both blocked and unblocked rays), and for ``penumbra`` ``tiles``, ``tiles_skipped``,
``samples_skipped``.

Example::

    frame = wsoft.render(scene, "rtdenoise", width=640, height=480, samples=2, denoiser="penumbra")
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.denoise import LIT, UNKNOWN, atrous_filter, penumbra_filter
from wsoft.accel.temporal import accumulate
from wsoft.lightspace.light import LightGPU, disk_shaped, in_front, light_point
from wsoft.lightspace.sky import cosine_direction
from wsoft.lightspace.samples import LightSamples, counter_draw, pixel_key, sample_coords
from wsoft.params import check_ranges
from wsoft.parallel import launch_chunked
from wsoft.raster.camera import camera_gpu
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.raster.shadow_rays import ray_origin, receiver_begin, shadow_ray_length
from wsoft.reference import reference_pattern
from wsoft.reference.dome import LATTICE, SKY_DISTANCE, DomeGPU, dome_gpu, dome_sample, dome_texel, strategy_point
from wsoft.scene.dome import is_dome
from wsoft.scene.offsets import ray_offset
from wsoft.scene.rays import Occluders, blocker_distance, occluders
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_DISK, LIGHT_DISTANT, LIGHT_RECT, LIGHT_SPHERE
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param

DENOISERS = ("penumbra", "atrous", "none")
TEMPORAL_ORDERS = ("after", "before")
TILES = (8, 16)


@dataclass(frozen=True)
class RTDenoiseParams:
    samples: int = param(2, "shadow rays per pixel sample (the reference's stratified per-pixel sets)", range=(1, 8))
    denoiser: str = param("penumbra", "penumbra (SIGMA-style: a radius from the blockers' distance, tiles skipped), atrous (SVGF's "
                                      "spatial à-trous wavelet filter), none (the raw visible fraction)")
    seed: int = param(0, "random seed of the light samples (equal seeds: the reference's rays)", range=(0, 2**31 - 1))
    iterations: int = param(3, "atrous: à-trous steps (2^k pixels apart at step k; the paper: 5)", range=(3, 5))
    sigma_z: float = param(1.0, "atrous: depth weight's tolerance, in units of the depth gradient times the distance", range=(0.01, 100.0))
    sigma_n: float = param(128.0, "atrous: normal weight's exponent (max(0, n.n')^sigma_n)", range=(1.0, 1024.0))
    sigma_l: float = param(4.0, "atrous: visibility weight's tolerance, in standard deviations of the visibility", range=(0.1, 100.0))
    variance_boost: float = param(1.0, "atrous: the spatial variance estimate's factor (Falcor's SVGF: 4 for a frame without "
                                       "history; the paper: none)", range=(0.25, 16.0))
    taps: int = param(8, "penumbra: Poisson taps per pass beyond the 5 x 5 window (SIGMA's 8)", range=(4, 64))
    radius_scale: float = param(1.0, "penumbra: the filter's radius over NRD's, a quarter of the penumbra's width (2: NRD's "
                                     "local-light front end)", range=(0.125, 8.0))
    max_radius: float = param(32.0, "penumbra: the largest filter radius, pixels (SIGMA: 32)", range=(1.0, 128.0))
    sharp_below: float = param(0.5, "penumbra: below this penumbra radius (pixels) the filter gives way to the pixel's own estimate "
                                    "(a smoothstep; SIGMA: 2, for a signal its temporal pass has accumulated)", range=(0.05, 8.0))
    tile: int = param(16, "penumbra: tile side in pixels for skipping all-lit and all-umbra tiles (8 or 16; SIGMA: 16)", range=(8, 16))
    history: int = param(1, "in a sequence: temporal accumulation over at most this many frames (the previous frame reprojected "
                            "through the G-buffer's points, disocclusions restart, history clamped to the 3 x 3 neighbourhood; 1: none, "
                            "the default: under moving lights and cameras it lags, see the docstring); a single frame has no history",
                         range=(1, 64))
    temporal_order: str = param("after", "in a sequence: accumulate after the spatial filter, clamped to the filtered neighbourhood "
                                         "(SIGMA's temporal stabilisation) or before it, on the rays' visible fraction (SVGF's order)")
    plane_sensitivity: float = param(0.02, "penumbra: largest distance to the centre's tangent plane a tap may have, a fraction of "
                                           "the frustum's size at the centre (SIGMA's planeDistanceSensitivity)", range=(0.001, 1.0))

    def __post_init__(self):
        check_ranges(self)
        check(self.denoiser in DENOISERS, f"denoiser {self.denoiser!r} is not one of {', '.join(DENOISERS)}")
        check(self.tile in TILES, f"tile {self.tile} is not 8 or 16")
        check(self.temporal_order in TEMPORAL_ORDERS, f"temporal_order {self.temporal_order!r} is not one of {', '.join(TEMPORAL_ORDERS)}")


@wp.kernel
def trace_blockers(
    offset: int,
    occ: Occluders,
    light: LightGPU,
    ls: LightSamples,
    gb: GBufferGPU,
    dmax: float,
    radius: float,
    distant: int,
    radius_scale: float,
    # outputs
    vis: wp.array[float],
    frac: wp.array[float],
    hit: wp.array[float],
    pen: wp.array[float],
    traced: wp.array[wp.int32],
    blocked: wp.array[wp.int32],
):
    """Per G-buffer sample, the reference's shadow rays as closest-hit queries: the visible
    fraction, the visible fraction of the rays in front of the tangent plane
    (:data:`~wsoft.accel.denoise.UNKNOWN` when none is), the mean distance from the surface to the
    blockers (-1: none), the penumbra radius (world units; :data:`~wsoft.accel.denoise.LIT` when no
    ray met a blocker), and the rays traced and blocked."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        frac[i] = 1.0
        hit[i] = -1.0
        pen[i] = LIT
        traced[i] = 0
        blocked[i] = 0
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    off, o, state, base, rot = receiver_begin(gb, ls, i)
    visible = int(0)
    front = int(0)
    nb = int(0)
    dsum = float(0.0)
    rsum = float(0.0)
    samples = ls.count
    for s in range(samples):
        c, state = sample_coords(ls, state, base, rot, s)
        r = light_point(light, p, c)
        d = wp.vec3(r[0], r[1], r[2])
        if in_front(n, d):
            front += 1
            t = blocker_distance(occ, o, d, shadow_ray_length(r[3], dmax, off))
            if t < 0.0:
                visible += 1
            else:
                db = t + off  # from the surface point
                nb += 1
                dsum += db
                tan_a = radius  # a distant light: the tangent of its half angle
                if distant == 0:
                    tan_a = radius / wp.max(r[3] - db, 1.0e-6 * r[3])
                rsum += 0.5 * db * tan_a * radius_scale
    vis[i] = float(visible) / float(samples)
    frac[i] = wp.where(front > 0, float(visible) / float(wp.max(front, 1)), UNKNOWN)
    traced[i] = front
    blocked[i] = nb
    if nb == 0:
        hit[i] = -1.0
        pen[i] = LIT
    else:
        hit[i] = dsum / float(nb)
        pen[i] = rsum / float(nb)


@wp.kernel
def times_front(
    offset: int,
    frac: wp.array[float],
    front: wp.array[float],
    # outputs
    vis: wp.array[float],
):
    """V = the light's front fraction times the denoised visible fraction of the part in front (0
    where nothing around says how much of it is visible)."""
    i = wp.tid() + offset
    f = frac[i]
    vis[i] = wp.where(f == UNKNOWN, 0.0, front[i] * f)


@wp.kernel
def trace_sky(
    offset: int,
    occ: Occluders,
    gb: GBufferGPU,
    dome: DomeGPU,
    samples: int,
    grid: int,
    seed: int,
    dmax: float,
    radius_scale: float,
    # outputs
    vis: wp.array[float],
    frac: wp.array[float],
    hit: wp.array[float],
    pen: wp.array[float],
    traced: wp.array[wp.int32],
    blocked: wp.array[wp.int32],
):
    """:func:`trace_blockers` for a dome: per G-buffer sample, the dome reference's ``samples`` rays
    (:func:`~wsoft.reference.dome.trace_dome_visibility`: the same keys, strategies and points) as
    closest-hit queries. A constant dome: cosine-distributed about the normal, V = the visible
    fraction. A latlong texture: ceil(N/2) cosine-distributed rays and floor(N/2) drawn from the
    texture's table, each weighted by the balance heuristic ``a = L cos / (n_c cos / pi + n_l p_l)``,
    V = sum a vis / sum a (``frac``: :data:`~wsoft.accel.denoise.UNKNOWN` where no ray has weight).
    Penumbra radius per blocked ray: half its blocker's distance (the sky subtends a hemisphere: a
    penumbra as wide as the blocker is far)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        frac[i] = 1.0
        hit[i] = -1.0
        pen[i] = LIT
        traced[i] = 0
        blocked[i] = 0
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    off = ray_offset(p, gb.err[i])
    o = ray_origin(p, n, off)
    tm = shadow_ray_length(SKY_DISTANCE, dmax, off)
    key = pixel_key(seed, i)
    num = float(0.0)
    den = float(0.0)
    front = int(0)
    nb = int(0)
    dsum = float(0.0)
    rsum = float(0.0)
    nc = samples
    if dome.textured != 0:
        nc = (samples + 1) / 2
    nl = samples - nc
    for s in range(samples):
        d = wp.vec3(0.0)
        if s < nc:
            d = cosine_direction(n, strategy_point(key, s, s, nc, grid, 0))
        else:
            d = dome_sample(dome, strategy_point(key, s, s - nc, nl, grid, 4), wp.vec2(counter_draw(key, s, 8), counter_draw(key, s, 9)))
        cn = wp.dot(n, d)
        a = float(0.0)
        if cn > 0.0:
            a = 1.0
            if dome.textured != 0:
                a = 0.0
                k = dome_texel(dome, d)
                pl = dome.prob[k] / wp.max(dome.area[k / dome.w], 1.0e-30)
                q = float(nc) * cn / wp.pi + float(nl) * pl
                if q > 0.0:
                    a = dome.lum[k] * cn / q
        if a > 0.0:
            front += 1
            den += a
            t = blocker_distance(occ, o, d, tm)
            if t < 0.0:
                num += a
            else:
                db = t + off
                nb += 1
                dsum += db
                rsum += 0.5 * db * radius_scale
    if dome.textured != 0:
        vis[i] = wp.where(den > 0.0, wp.clamp(num / wp.max(den, 1.0e-30), 0.0, 1.0), 1.0)
    else:
        vis[i] = num / float(samples)
    frac[i] = wp.where(den > 0.0, wp.clamp(num / wp.max(den, 1.0e-30), 0.0, 1.0), UNKNOWN)
    traced[i] = front
    blocked[i] = nb
    if nb == 0:
        hit[i] = -1.0
        pen[i] = LIT
    else:
        hit[i] = dsum / float(nb)
        pen[i] = rsum / float(nb)


@wp.kernel
def known_or_lit(
    offset: int,
    frac: wp.array[float],
    # outputs
    vis: wp.array[float],
):
    """A dome's V: the denoised visible fraction, 1 where nothing around says (no ray in front)."""
    i = wp.tid() + offset
    f = frac[i]
    vis[i] = wp.where(f == UNKNOWN, 1.0, f)


def light_radius(light) -> tuple[float, bool]:
    """(the light's radius in ``tan a = r / (D - d)``: half a rect light's mean side (a cylinder
    light's, the rectangle of its length by its diameter), a disk's or
    sphere's radius (an ellipse's or ellipsoid's smallest semi-axis: the filter is round, and a
    radius from a longer axis blurs across the short one), 0 for a point light; for a distant light
    the tangent of its half angle, True)."""
    if light.kind == LIGHT_DISTANT:
        return math.tan(math.radians(0.5 * light.angle_deg)), True
    if light.kind in (LIGHT_RECT, LIGHT_CYLINDER):
        return 0.5 * float(light.half_size[0] + light.half_size[1]), False
    if light.kind in (LIGHT_DISK, LIGHT_SPHERE):
        return float(min(light.semi_axes)) if light.elliptical else float(light.radius), False
    return 0.0, False


@dataclass
class RayEstimate:
    """What a pixel's shadow rays found, flat float32 per G-buffer sample: ``vis`` the visible
    fraction, ``frac`` that of the rays in front of the tangent plane (``UNKNOWN``: none), ``hit``
    the mean blocker distance (-1: none), ``pen`` the penumbra radius (world units, ``LIT``); the
    counts of rays ``traced`` and ``blocked`` (int32)."""

    vis: wp.array
    frac: wp.array
    hit: wp.array
    pen: wp.array
    traced: wp.array
    blocked: wp.array


def trace_estimate(ds, L: LightGPU, light, gb, samples: int, seed: int, radius_scale: float) -> RayEstimate:
    """Trace ``samples`` of the reference's shadow rays per G-buffer sample with closest hits."""
    n = gb.count
    dev = ds.device
    out = RayEstimate(*(wp.empty(n, dtype=float, device=dev) for _ in range(4)),
                      *(wp.empty(n, dtype=wp.int32, device=dev) for _ in range(2)))
    radius, distant = light_radius(light)
    dmax = float(light.shadow_distance) if light.shadow_distance >= 0.0 else -1.0
    pattern = reference_pattern(samples, seed, True)
    launch_chunked(trace_blockers, n,
                   inputs=[occluders(ds, light.shadow_excluded), L, pattern.on(dev, disk_shaped(light)), gb.gpu(),
                           dmax, radius, int(distant), float(radius_scale)],
                   outputs=[out.vis, out.frac, out.hit, out.pen, out.traced, out.blocked], device=dev, min_chunk=256, per_thread=32)
    return out


def trace_sky_estimate(ds, light, gb, samples: int, seed: int, radius_scale: float) -> tuple[RayEstimate, str]:
    """Trace the dome reference's ``samples`` rays toward ``light``'s dome per G-buffer sample
    (:func:`trace_sky`); and how they were drawn (``cosine``, or ``cosine+texture`` for a latlong texture)."""
    n = gb.count
    dev = ds.device
    out = RayEstimate(*(wp.empty(n, dtype=float, device=dev) for _ in range(4)),
                      *(wp.empty(n, dtype=wp.int32, device=dev) for _ in range(2)))
    dmax = float(light.shadow_distance) if light.shadow_distance >= 0.0 else -1.0
    launch_chunked(trace_sky, n,
                   inputs=[occluders(ds, light.shadow_excluded), gb.gpu(), dome_gpu(light, ds.device), int(samples), LATTICE, int(seed),
                           dmax, float(radius_scale)],
                   outputs=[out.vis, out.frac, out.hit, out.pen, out.traced, out.blocked], device=dev, min_chunk=256, per_thread=32)
    return out, "cosine" if light.dome.constant else "cosine+texture"


class RTDenoise(Technique):
    """A few ray-traced shadow rays per pixel (the reference's, closest-hit; toward the sky for a
    DomeLight: cosine-distributed, and for a texture also drawn from its radiance), denoised in screen space
    by a SIGMA-style penumbra filter or SVGF's à-trous wavelet filter."""

    name = "rtdenoise"
    distant_angle_limit = 40.0  # its denoiser's d tan(angle / 2) / 2 filter: max point error 0.087 at 40 degrees, 0.183 at 50
    summary = ("1-8 of the reference's shadow rays per pixel (closest hit: blocker distance), then a denoiser: SIGMA-style penumbra "
               "filter with tile skipping, SVGF à-trous, or none")
    Params = RTDenoiseParams
    passes = (
        PassSpec("trace", reads=("gbuffer", "scene"), writes=("rtdenoise_rays",)),
        PassSpec("denoise", reads=("gbuffer", "rtdenoise_rays"), optional=("front",), writes=("visibility",)),
    )
    quality = (Quality("samples", (1, 2, 4, 8), "more rays per pixel: less noise for the denoiser to remove, time up about linearly in "
                                                "the rays"),
               Quality("denoiser", ("none", "penumbra", "atrous"), "the raw rays, the SIGMA-style filter (tiles skipped), SVGF's "
                                                                  "à-trous steps over every pixel"))
    quick_params = {"samples": 1}
    # measured 0.0024, 0.0615 at 128 x 96 (seeds 1-3: 0.057-0.067), where the penumbra is 4 pixels
    # wide; at 640 x 480 against 256 reference samples the penumbra MAE is 0.026
    tolerance = Tolerance(mae=0.003, mae_penumbra=0.075)
    instancing_refusal = ""  # closest-hit rays go through the instances' top-level BVH (wsoft.scene.rays.blocker_distance)
    dome_refusal = ""  # a dome: rays toward the sky (trace_sky), the same denoisers
    horizon = "exact"  # per ray, and the denoised part in front times the exact front fraction
    cylinder_model = ("the reference's rays to its silhouette rectangle; the denoiser's penumbra radius from half its mean side, "
                      "(length / 2 + radius) / 2, as a rect light's")

    def bake_support(self) -> str | None:
        if self.params.denoiser != "none":
            return (f"denoiser={self.params.denoiser} filters over an eye view's pixel neighbours, which bake points have none of; "
                    f"bake with denoiser=none (the raw visible fraction of the rays) or with reference")
        return None

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        scene_key = ctx.scene_arrays()
        rays_key = ctx.key("rtdenoise_rays", light)
        dome = is_dome(light)
        L = None if dome else ctx.light_gpu(light)

        def run_trace(res):
            c = ctx.counters(light)
            if dome:
                est, how = trace_sky_estimate(res[scene_key], light, res[gbuf], p.samples, ctx.frame_seed(p.seed), p.radius_scale)
                c["dome_rays"] = how
            else:
                est = trace_estimate(res[scene_key], L, light, res[gbuf], p.samples, ctx.frame_seed(p.seed), p.radius_scale)
            traced, blocked = est.traced.numpy(), est.blocked.numpy()
            c.update(samples=p.samples, denoiser=p.denoiser, rays=int(traced.astype(np.int64).sum()),
                     rays_blocked=int(blocked.astype(np.int64).sum()), penumbra_samples=int(((blocked > 0) & (blocked < traced)).sum()))
            return {rays_key: est}

        ctx.add_pass(ctx.pass_name("rtdenoise_trace", light), inputs=(gbuf, scene_key), outputs=(rays_key,), run=run_trace, stage="trace",
                     light=light)
        out = ctx.visibility_key(light)
        front_key = ctx.front_fraction(light) if p.denoiser != "none" and not dome else None  # a dome's rays are all in front

        def run_denoise(res):
            gb, est = res[gbuf], res[rays_key]
            if p.denoiser == "none":
                return {out: ctx.visibility(est.vis)}
            frac = est.frac
            temporal = ctx.in_sequence and p.history > 1

            def accumulated(signal):
                prev = ctx.previous(light)
                acc, state = accumulate(gb, camera_gpu(ctx.camera), ctx.origin, signal, prev["temporal"] if prev else None, p.history,
                                        ctx.device, counters=ctx.counters(light))
                ctx.keep(light, {"temporal": state})
                return acc

            if temporal and p.temporal_order == "before":
                frac = accumulated(frac)
            if p.denoiser == "atrous":
                frac = atrous_filter(gb, frac, p.iterations, p.sigma_z, p.sigma_n, p.sigma_l, ctx.device, boost=p.variance_boost)
            else:
                frac = penumbra_filter(gb, camera_gpu(ctx.camera), frac, est.pen, tile=p.tile, taps=p.taps, max_radius=p.max_radius,
                                       sharp_below=p.sharp_below, plane_sensitivity=p.plane_sensitivity, seed=p.seed, device=ctx.device,
                                       counters=ctx.counters(light))
            if temporal and p.temporal_order == "after":
                frac = accumulated(frac)
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            if dome:
                launch_chunked(known_or_lit, gb.count, inputs=[frac], outputs=[vis], device=ctx.device)
            else:
                launch_chunked(times_front, gb.count, inputs=[frac, res[front_key]], outputs=[vis], device=ctx.device)
            return {out: ctx.visibility(vis)}

        inputs = (gbuf, rays_key) + ((front_key,) if front_key is not None else ())
        return ctx.add_pass(ctx.pass_name("rtdenoise", light), inputs=inputs, outputs=(out,), run=run_denoise, stage="denoise", light=light)
