"""Screen-space denoisers of a noisy per-pixel visibility, guided by the G-buffer: one frame, spatial only.

Both filters read a visibility estimate per G-buffer sample (a few shadow rays' visible fraction,
or :data:`UNKNOWN` where no ray was cast: such a sample takes its value from its neighbours and
gives none) and the G-buffer itself; each pass reads one buffer and writes another (a pixel's
result never depends on the order in which chunks run). Samples gather from their own layer's
pixel neighbours (:func:`sample_at`); background samples are neither filtered nor read, and a bake
G-buffer (no pixel grid) has no neighbours.

**Edge-avoiding à-trous wavelet filter** (:func:`atrous_filter`; Schied et al. 2017,
"Spatiotemporal Variance-Guided Filtering", its spatial part, read with the implementation in
Falcor's ``SVGFPass``). A single frame has no history, so the variance comes from SVGF's spatial
fallback for a history shorter than 4 frames: the first and second moments of the visibility over a
7 x 7 cross-bilateral window (depth, normal and visibility weights; the depth weight 3 times as
tolerant), times ``boost`` (Falcor's ``SVGFFilterMoments`` multiplies by 4 / history length, 4 for
a single frame; the paper gives no factor). The window's filtered visibility is the first step's
input, as Falcor's pass returns it (the paper's text estimates only the variance there, leaving the
input raw: measured worse at 640 x 480, better at 160 x 120). Then ``iterations`` à-trous steps
(5 x 5 taps of the B3 spline, ``{1, 2/3, 1/6}`` per axis, 2^k pixels apart at step k) weighted by

* depth: ``exp(-|z_p - z_q| / (sigma_z |grad z_p| |p - q|))``, ``z`` the G-buffer's camera distance
  and ``|grad z|`` its screen-space gradient (per axis the smaller of the two one-sided differences,
  so that a pixel beside a depth step keeps its own surface's gradient; the larger axis; at least
  1e-7 of ``z``, a floor relative to the depth where Falcor's is 1e-8 in absolute units);
* normal: ``max(0, n_p . n_q)^sigma_n``;
* visibility (SVGF's luminance weight on V): ``exp(-|V_p - V_q| / (sigma_l sqrt(g(var_p)) + eps))``,
  ``g`` a 3 x 3 Gaussian of the variance;

the centre tap weight 1, and the variance carried to the next step with the squared weights
(``sum w^2 var / (sum w)^2``).

**SIGMA-style penumbra filter** (:func:`penumbra_filter`; NVIDIA's NRD SIGMA shadow denoiser,
``SIGMA_ClassifyTiles``, ``SIGMA_Blur``, read from NVIDIAGameWorks/RayTracingDenoiser). Input: per
sample a world-space penumbra radius (:data:`LIT` where no shadow ray met a blocker), from which the
filter's radius in pixels follows.

1. *Tiles* of ``tile x tile`` pixels: a tile whose covered samples are all lit or all in umbra
   (every ray blocked; an :data:`UNKNOWN` sample fits either) is *uniform*; every other tile
   *mixed*, with the largest penumbra radius in pixels of its samples (a tile of unknown samples
   only is filtered, reaching no other). A uniform tile is skipped (its samples keep their
   estimate, its unknown ones take the tile's 1 or 0) unless a mixed tile's penumbra reaches it:
   within ``max(1, ceil(radius / tile))`` tiles of that mixed tile (SIGMA smooths its tile map with
   a Gaussian whose width follows each tile's radius and reads it bicubically, scaling the blur
   radius by it; here the reach is a yes or no).
2. *Blur* and *post-blur*, the same gather twice (the second reads the first's shadow and its
   penumbra estimate): a dense 5 x 5 window (SIGMA's 5 x 5 radius estimation) estimates the
   penumbra radius as the blockers' radii weighted toward the smaller (``w pixel / (pixel + r)``,
   lit samples left out) and averages the visibility; below ``sharp_below`` pixels of penumbra
   radius the window's average gives way to the centre (a smoothstep ``f``: a hard shadow stays
   sharp; SIGMA's 2 pixels, where its temporal pass removes the centre's noise), and the dense sum
   then counts as ``g = lerp(4, 1, f)`` taps. Then ``taps`` Poisson-disk taps over the estimated
   radius in pixels times ``g`` (at most ``max_radius``; SIGMA's code scales the estimate by ``g``
   before it takes the radius), turned by a random angle per pixel and per pass (SIGMA turns its
   kernel per frame; one frame with one angle for every pixel leaves a pattern), foreshortened
   along the surface's tilt (SIGMA's screen-space skew), snapped to pixel centres. Weights: the
   distance to the centre's tangent plane, ``smoothstep(1, 0, |n . (x_q - x_p)| / (plane_sensitivity
   x frustum size))`` (the frustum's smaller side at the centre's depth: what keeps the filter from
   blurring across a depth discontinuity), a Gaussian ``exp(-0.66 r^2)`` of the tap's normalised
   distance, and against umbra leaking into a wide penumbra ``min(1, r_q / r_estimated)``.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from wsoft.lightspace.samples import SamplePattern
from wsoft.parallel import launch_chunked
from wsoft.raster.camera import CameraGPU
from wsoft.raster.gbuffer import GBufferGPU, gb_covered, gb_index, gb_layer, gb_pixel

LIT = wp.constant(1.0e30)  # penumbra radius of a sample none of whose rays met a blocker
UNKNOWN = wp.constant(-1.0)  # the visibility of a sample no ray was cast from: its neighbours decide
ROTATION_SALT = wp.constant(0x3C6EF372)  # the per-pixel kernel rotation's stream, apart from the light samples'
ATROUS_KERNEL = wp.constant(wp.vec3(1.0, 2.0 / 3.0, 1.0 / 6.0))  # B3 spline per axis, centre weight 1 (SVGF)
DEPTH_FLOOR = 1.0e-7  # the depth gradient's floor, a fraction of the depth


@wp.func
def sample_at(gb: GBufferGPU, x: int, y: int, layer: int) -> int:
    """The covered sample of pixel (x, y) in ``layer``, or -1: outside the image, the background,
    or any pixel of a bake G-buffer (its samples are independent points, no one's neighbour)."""
    if gb.grid == 0 or x < 0 or y < 0 or x >= gb.width or y >= gb.height:
        return -1
    j = gb_index(gb, x, y, layer)
    if not gb_covered(gb, j):
        return -1
    return j


@wp.func
def in_unit(v: float) -> float:
    """``v`` limited to [0, 1] without turning a NaN into a number."""
    return wp.where(v > 1.0, 1.0, wp.where(v < 0.0, 0.0, v))


# --------------------------------------------------------------------------- à-trous (SVGF, spatial)


@wp.func
def one_sided_min(gb: GBufferGPU, x: int, y: int, layer: int, z: float, dx: int, dy: int) -> float:
    """The smaller of the two one-sided differences of the camera distance along (dx, dy) (-1: none)."""
    best = float(-1.0)
    a = sample_at(gb, x + dx, y + dy, layer)
    if a >= 0:
        best = wp.abs(gb.dist[a] - z)
    b = sample_at(gb, x - dx, y - dy, layer)
    if b >= 0:
        d = wp.abs(gb.dist[b] - z)
        if best < 0.0 or d < best:
            best = d
    return best


@wp.kernel
def depth_gradient(
    offset: int,
    gb: GBufferGPU,
    # outputs
    grad: wp.array[float],
):
    """Per sample the screen-space gradient of the camera distance (module docstring)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        grad[i] = 0.0
        return
    z = gb.dist[i]
    xy = gb_pixel(gb, i)
    layer = gb_layer(gb, i)
    gx = one_sided_min(gb, xy[0], xy[1], layer, z, 1, 0)
    gy = one_sided_min(gb, xy[0], xy[1], layer, z, 0, 1)
    grad[i] = wp.max(wp.max(gx, gy), DEPTH_FLOOR * z)


@wp.func
def svgf_weight(zc: float, zq: float, phi_z: float, nc: wp.vec3, nq: wp.vec3, sigma_n: float, lc: float, lq: float, phi_l: float) -> float:
    """SVGF's edge-stopping weight: depth, normal and visibility (Falcor's ``computeWeight``)."""
    wn = wp.pow(wp.max(wp.dot(nc, nq), 0.0), sigma_n)
    return wp.exp(-wp.abs(lc - lq) / phi_l - wp.abs(zc - zq) / phi_z) * wn


@wp.kernel
def svgf_moments(
    offset: int,
    gb: GBufferGPU,
    vis: wp.array[float],
    grad: wp.array[float],
    sigma_z: float,
    sigma_n: float,
    sigma_l: float,
    boost: float,
    # outputs
    out: wp.array[float],
    var: wp.array[float],
):
    """SVGF's spatial moments (a history under 4 frames): the 7 x 7 cross-bilateral average of V
    and the variance of V over the same weights, times ``boost``."""
    i = wp.tid() + offset
    vc = vis[i]
    out[i] = vc
    var[i] = 0.0
    if not gb_covered(gb, i):
        return
    zc = gb.dist[i]
    nc = gb.nrm[i]
    phi_z = grad[i] * sigma_z * 3.0
    xy = gb_pixel(gb, i)
    layer = gb_layer(gb, i)
    sw = float(0.0)
    m1 = float(0.0)
    m2 = float(0.0)
    for dy in range(-3, 4):
        for dx in range(-3, 4):
            j = sample_at(gb, xy[0] + dx, xy[1] + dy, layer)
            if j >= 0:
                vq = vis[j]
                if vq != UNKNOWN:
                    w = float(1.0)
                    if dx != 0 or dy != 0:
                        dist = wp.sqrt(float(dx * dx + dy * dy))
                        w = svgf_weight(zc, gb.dist[j], phi_z * dist, nc, gb.nrm[j], sigma_n, vc, vq, sigma_l)
                    sw += w
                    m1 += w * vq
                    m2 += w * vq * vq
    if sw > 0.0:
        m1 = m1 / sw
        m2 = m2 / sw
        out[i] = m1
        var[i] = wp.max(m2 - m1 * m1, 0.0) * boost


@wp.func
def centre_variance(gb: GBufferGPU, var: wp.array[float], x: int, y: int, layer: int) -> float:
    """A 3 x 3 Gaussian of the variance about pixel (x, y) (covered neighbours, renormalised)."""
    s = float(0.0)
    t = float(0.0)
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            j = sample_at(gb, x + dx, y + dy, layer)
            if j >= 0:
                k = 0.25
                if dx != 0 and dy != 0:
                    k = 0.0625
                elif dx != 0 or dy != 0:
                    k = 0.125
                s += k * var[j]
                t += k
    return s / t


@wp.kernel
def svgf_atrous_step(
    offset: int,
    gb: GBufferGPU,
    vis: wp.array[float],
    var: wp.array[float],
    grad: wp.array[float],
    step: int,
    sigma_z: float,
    sigma_n: float,
    sigma_l: float,
    # outputs
    out: wp.array[float],
    out_var: wp.array[float],
):
    """One à-trous step: 5 x 5 taps ``step`` pixels apart, edge-stopping weights, the variance
    carried with the squared weights."""
    i = wp.tid() + offset
    vc = vis[i]
    out[i] = vc
    out_var[i] = var[i]
    if not gb_covered(gb, i) or vc == UNKNOWN:  # a sample the moments' window found no value for
        return
    zc = gb.dist[i]
    nc = gb.nrm[i]
    xy = gb_pixel(gb, i)
    layer = gb_layer(gb, i)
    phi_l = sigma_l * wp.sqrt(wp.max(centre_variance(gb, var, xy[0], xy[1], layer), 0.0) + 1.0e-10)
    phi_z = grad[i] * sigma_z * float(step)
    sw = float(1.0)
    sv = vc
    svar = var[i]
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            if dx != 0 or dy != 0:
                j = sample_at(gb, xy[0] + dx * step, xy[1] + dy * step, layer)
                if j >= 0:
                    vq = vis[j]
                    if vq != UNKNOWN:
                        dist = wp.sqrt(float(dx * dx + dy * dy))
                        k = ATROUS_KERNEL[wp.abs(dx)] * ATROUS_KERNEL[wp.abs(dy)]
                        w = svgf_weight(zc, gb.dist[j], phi_z * dist, nc, gb.nrm[j], sigma_n, vc, vq, phi_l) * k
                        sw += w
                        sv += w * vq
                        svar += w * w * var[j]
    out[i] = in_unit(sv / sw)
    out_var[i] = svar / (sw * sw)


def atrous_filter(gb, vis: wp.array, iterations: int, sigma_z: float, sigma_n: float, sigma_l: float, device: str,
                  boost: float = 1.0) -> wp.array:
    """SVGF's spatial filter of ``vis`` (flat float32 per G-buffer sample): the spatial moments (their
    variance times ``boost``), then ``iterations`` à-trous steps (module docstring). Returns the
    filtered visibility."""
    n = gb.count
    g = gb.gpu()
    grad = wp.empty(n, dtype=float, device=device)
    launch_chunked(depth_gradient, n, inputs=[g], outputs=[grad], device=device)
    a = wp.empty(n, dtype=float, device=device)
    va = wp.empty(n, dtype=float, device=device)
    launch_chunked(svgf_moments, n, inputs=[g, vis, grad, sigma_z, sigma_n, sigma_l, boost], outputs=[a, va], device=device)
    b = wp.empty(n, dtype=float, device=device)
    vb = wp.empty(n, dtype=float, device=device)
    for k in range(iterations):
        launch_chunked(svgf_atrous_step, n, inputs=[g, a, va, grad, 1 << k, sigma_z, sigma_n, sigma_l], outputs=[b, vb], device=device)
        a, b = b, a
        va, vb = vb, va
    return a


# --------------------------------------------------------------------------- SIGMA-style penumbra filter


@wp.func
def pixel_size(cam: CameraGPU, p: wp.vec3, width: int, height: int) -> wp.vec2:
    """World size of a pixel (x, y) at the depth of ``p`` (a perspective camera; the window's
    constant pixel of an orthographic one)."""
    sx = 2.0 * cam.tan_half[0] / float(width)
    sy = 2.0 * cam.tan_half[1] / float(height)
    if cam.ortho == 0:
        z = wp.max(wp.dot(p - cam.origin, -cam.az), 0.0)
        sx = sx * z
        sy = sy * z
    return wp.vec2(sx, sy)


TILE_MIXED = wp.constant(0)  # neither all lit nor all in umbra: filtered
TILE_LIT = wp.constant(1)  # every known sample lit
TILE_UMBRA = wp.constant(2)  # every known sample in umbra
TILE_UNKNOWN = wp.constant(3)  # no known sample: filtered (its samples gather from their neighbours), reaching no other tile


@wp.kernel
def classify_tiles(
    offset: int,
    gb: GBufferGPU,
    cam: CameraGPU,
    vis: wp.array[float],
    pen: wp.array[float],
    tile: int,
    tiles_x: int,
    tiles_y: int,
    max_radius: float,
    # outputs
    kind: wp.array[wp.int32],
    radius: wp.array[float],
):
    """Per tile: its kind (``TILE_MIXED``, ``TILE_LIT``, ``TILE_UMBRA``, ``TILE_UNKNOWN``; a tile with
    no covered sample is lit) and the largest penumbra radius (pixels, at most ``max_radius``) of
    its samples."""
    t = wp.tid() + offset
    per_layer = tiles_x * tiles_y
    layer = t / per_layer
    r = t - layer * per_layer
    ty = r / tiles_x
    tx = r - ty * tiles_x
    all_lit = int(1)
    all_umbra = int(1)
    known = int(0)
    unknown = int(0)
    rmax = float(0.0)
    for y in range(ty * tile, wp.min((ty + 1) * tile, gb.height)):
        for x in range(tx * tile, wp.min((tx + 1) * tile, gb.width)):
            i = (layer * gb.height + y) * gb.width + x
            if gb_covered(gb, i):
                v = vis[i]
                h = pen[i]
                if v == UNKNOWN:
                    unknown = 1
                else:
                    known = 1
                    if v != 1.0:
                        all_lit = 0
                    if v != 0.0:
                        all_umbra = 0
                if h > 0.0 and h < LIT:
                    ps = pixel_size(cam, gb.pos[i], gb.width, gb.height)
                    rmax = wp.max(rmax, wp.min(h / (0.5 * (ps[0] + ps[1])), max_radius))
    k = TILE_MIXED
    if known == 0:
        k = wp.where(unknown != 0, TILE_UNKNOWN, TILE_LIT)
    elif all_lit != 0:
        k = TILE_LIT
    elif all_umbra != 0:
        k = TILE_UMBRA
    kind[t] = k
    radius[t] = rmax


@wp.kernel
def reach_tiles(
    offset: int,
    kind: wp.array[wp.int32],
    radius: wp.array[float],
    tile: int,
    tiles_x: int,
    tiles_y: int,
    span: int,
    # outputs
    active: wp.array[wp.int32],
):
    """Per tile: 1 when it is mixed or unknown, or a mixed tile's penumbra reaches it (within
    ``max(1, ceil(radius / tile))`` tiles of it; ``span`` the farthest any reaches)."""
    t = wp.tid() + offset
    per_layer = tiles_x * tiles_y
    layer = t / per_layer
    r = t - layer * per_layer
    ty = r / tiles_x
    tx = r - ty * tiles_x
    on = wp.where(kind[t] == TILE_MIXED or kind[t] == TILE_UNKNOWN, 1, 0)
    for dy in range(-span, span + 1):
        for dx in range(-span, span + 1):
            x = tx + dx
            y = ty + dy
            if on == 0 and x >= 0 and y >= 0 and x < tiles_x and y < tiles_y:
                u = layer * per_layer + y * tiles_x + x
                if kind[u] == TILE_MIXED:
                    reach = wp.max(1, int(wp.ceil(radius[u] / float(tile))))
                    if wp.abs(dx) <= reach and wp.abs(dy) <= reach:
                        on = 1
    active[t] = on


@wp.func
def plane_weight(n: wp.vec3, p: wp.vec3, q: wp.vec3, inv_norm: float) -> float:
    """SIGMA's geometry weight: ``smoothstep(1, 0, |n . (q - p)| / norm)``."""
    x = wp.min(wp.abs(wp.dot(n, q - p)) * inv_norm, 1.0)
    return 1.0 - x * x * (3.0 - 2.0 * x)


@wp.func
def smallest_first(ps: float, h: float) -> float:
    """The weight of a sample's radius in the penumbra estimate: toward the smaller, lit ones out."""
    return wp.where(h > 0.0 and h < LIT, ps / (ps + h), 0.0)


@wp.kernel
def keep_skipped(
    offset: int,
    gb: GBufferGPU,
    shadow: wp.array[float],
    pen: wp.array[float],
    kind: wp.array[wp.int32],
    active: wp.array[wp.int32],
    tile: int,
    tiles_x: int,
    tiles_y: int,
    # outputs
    out1: wp.array[float],
    pen1: wp.array[float],
    out2: wp.array[float],
    pen2: wp.array[float],
    skipped: wp.array[wp.int32],
):
    """Per skipped tile: both passes' results over its pixels, its samples' own estimate (its
    unknown samples take the tile's 1 or 0), and how many covered samples it holds (``skipped``;
    0 for a filtered tile, whose pixels are left to :func:`sigma_blur`)."""
    t = wp.tid() + offset
    skipped[t] = 0
    if active[t] != 0:
        return
    per_layer = tiles_x * tiles_y
    layer = t / per_layer
    r = t - layer * per_layer
    ty = r / tiles_x
    tx = r - ty * tiles_x
    fill = wp.where(kind[t] == TILE_UMBRA, 0.0, 1.0)
    count = int(0)
    for y in range(ty * tile, wp.min((ty + 1) * tile, gb.height)):
        for x in range(tx * tile, wp.min((tx + 1) * tile, gb.width)):
            i = gb_index(gb, x, y, layer)
            v = shadow[i]
            if gb_covered(gb, i):
                count += 1
                if v == UNKNOWN:
                    v = fill
            out1[i] = v
            out2[i] = v
            pen1[i] = pen[i]
            pen2[i] = pen[i]
    skipped[t] = count


@wp.kernel
def sigma_blur(
    offset: int,
    gb: GBufferGPU,
    cam: CameraGPU,
    shadow: wp.array[float],
    pen: wp.array[float],
    filtered: wp.array[wp.int32],
    tile: int,
    tiles_x: int,
    tiles_y: int,
    taps: wp.array[wp.vec3],
    max_radius: float,
    sharp_below: float,
    plane_sensitivity: float,
    seed: int,
    # outputs
    out: wp.array[float],
    out_pen: wp.array[float],
):
    """One SIGMA blur pass (module docstring) over the pixels of the tiles listed in ``filtered``
    (``tile * tile`` threads a tile): the dense 5 x 5 estimate, then the sparse taps."""
    k = wp.tid() + offset
    area = tile * tile
    t = filtered[k / area]
    q = k - (k / area) * area
    per_layer = tiles_x * tiles_y
    layer = t / per_layer
    r = t - layer * per_layer
    ty = r / tiles_x
    tx = r - ty * tiles_x
    x0 = tx * tile + q % tile
    y0 = ty * tile + q / tile
    if x0 >= gb.width or y0 >= gb.height:
        return
    i = gb_index(gb, x0, y0, layer)
    sc = shadow[i]
    hc = pen[i]
    out[i] = sc
    out_pen[i] = hc
    if not gb_covered(gb, i):
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    ps2 = pixel_size(cam, p, gb.width, gb.height)
    ps = 0.5 * (ps2[0] + ps2[1])
    frustum = wp.min(ps2[0] * float(gb.width), ps2[1] * float(gb.height))
    inv_norm = 1.0 / wp.max(plane_sensitivity * frustum, 1.0e-30)
    xy = wp.vec2i(x0, y0)
    # dense 5 x 5: the penumbra estimate and a first average
    res = float(0.0)
    sx = float(0.0)
    est = float(0.0)
    sy = float(0.0)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            j = sample_at(gb, xy[0] + dx, xy[1] + dy, layer)
            if j >= 0:
                sq = shadow[j]
                if sq != UNKNOWN:
                    hq = pen[j]
                    w = float(1.0)
                    if dx != 0 or dy != 0:
                        w = plane_weight(n, p, gb.pos[j], inv_norm) * wp.exp(-0.165 * float(dx * dx + dy * dy))  # exp(-0.66 (r / 2)^2)
                    res += sq * w
                    sx += w
                    w2 = w * smallest_first(ps, hq)
                    est += wp.where(w2 > 0.0, hq * w2, 0.0)
                    sy += w2
    if sx == 0.0:  # nothing known around an unknown sample
        return
    res = res / sx
    est = est / wp.max(sy, 1.0e-30)
    f = wp.clamp(est / (ps * sharp_below), 0.0, 1.0)
    f = f * f * (3.0 - 2.0 * f)
    if sc != UNKNOWN:
        res = sc + (res - sc) * f
    # the dense window counts as g = lerp(4, 1, f) sparse taps
    g = 4.0 + (1.0 - 4.0) * f
    res = res * g
    sx = g
    est = est * g
    sy = wp.where(sy != 0.0, g, 0.0)
    radius = wp.min(est / ps, max_radius)
    # foreshortening: the kernel shrinks along the surface's tilt (SIGMA's screen-space skew)
    nv = wp.vec2(wp.dot(n, cam.ax), wp.dot(n, cam.ay))
    view = -cam.az
    if cam.ortho == 0:
        view = wp.normalize(p - cam.origin)
    nov = wp.abs(wp.dot(n, view))
    kx = (1.0 - wp.abs(nv[0])) * (1.0 - nov) + nov
    ky = (1.0 - wp.abs(nv[1])) * (1.0 - nov) + nov
    km = wp.max(wp.max(kx, ky), 1.0e-6)
    kx = kx / km * radius * ps / ps2[0]
    ky = ky / km * radius * ps / ps2[1]
    state = wp.rand_init(seed ^ ROTATION_SALT, i)
    a = 2.0 * wp.pi * wp.randf(state)
    ca = wp.cos(a)
    sa = wp.sin(a)
    inv_est = 1.0 / wp.max(est, 1.0e-30)
    for k in range(taps.shape[0]):
        o = taps[k]
        ox = (ca * o[0] - sa * o[1]) * kx
        oy = (sa * o[0] + ca * o[1]) * ky
        qx = int(wp.floor(float(xy[0]) + 0.5 + ox))
        qy = int(wp.floor(float(xy[1]) + 0.5 + oy))
        j = sample_at(gb, qx, qy, layer)
        if j >= 0:
            sq = shadow[j]
            if sq != UNKNOWN:
                hq = pen[j]
                w = plane_weight(n, p, gb.pos[j], inv_norm) * wp.exp(-0.66 * o[2] * o[2])
                w = w * wp.where(hq >= LIT, 1.0, wp.min(wp.max(hq, 0.0) * inv_est, 1.0))  # no umbra leaking into a wide penumbra
                res += sq * w
                sx += w
                w2 = w * smallest_first(ps, hq)
                est += wp.where(w2 > 0.0, hq * w2, 0.0)
                sy += w2
    out[i] = in_unit(res / sx)
    out_pen[i] = wp.where(sy == 0.0, hc, est / sy)


def poisson_taps(count: int, device: str) -> wp.array:
    """``count`` Poisson-disk taps on the unit disk (the shared sample generator's dart throwing,
    through the concentric map): (x, y, distance from the centre)."""
    xy = SamplePattern("poisson", count, seed=0).light_coords(device, True).numpy().astype(np.float64)
    r = np.hypot(xy[:, 0], xy[:, 1])
    return wp.array(np.column_stack([xy, r]).astype(np.float32), dtype=wp.vec3, device=device)


def penumbra_filter(gb, cam: CameraGPU, vis: wp.array, pen: wp.array, *, tile: int, taps: int, max_radius: float, sharp_below: float,
                    plane_sensitivity: float, seed: int, device: str, counters: dict | None = None) -> wp.array:
    """The SIGMA-style filter of ``vis`` guided by the per-sample penumbra radii ``pen`` (world
    units, :data:`LIT` where none was blocked): tiles, then the blur and post-blur passes (module
    docstring). ``counters`` receives ``tiles``, ``tiles_skipped`` and ``samples_skipped`` (covered
    samples in skipped tiles)."""
    n = gb.count
    g = gb.gpu()
    tiles_x = (gb.width + tile - 1) // tile
    tiles_y = (gb.height + tile - 1) // tile
    nt = tiles_x * tiles_y * gb.spp
    kind = wp.empty(nt, dtype=wp.int32, device=device)
    radius = wp.empty(nt, dtype=float, device=device)
    launch_chunked(classify_tiles, nt, inputs=[g, cam, vis, pen, tile, tiles_x, tiles_y, float(max_radius)], outputs=[kind, radius],
                   device=device, min_chunk=16)
    active = wp.empty(nt, dtype=wp.int32, device=device)
    span = max(1, math.ceil(max_radius / tile))
    launch_chunked(reach_tiles, nt, inputs=[kind, radius, tile, tiles_x, tiles_y, span], outputs=[active], device=device, min_chunk=64)
    tp = poisson_taps(taps, device)
    s1 = wp.empty(n, dtype=float, device=device)
    p1 = wp.empty(n, dtype=float, device=device)
    s2 = wp.empty(n, dtype=float, device=device)
    p2 = wp.empty(n, dtype=float, device=device)
    skipped = wp.empty(nt, dtype=wp.int32, device=device)
    launch_chunked(keep_skipped, nt, inputs=[g, vis, pen, kind, active, tile, tiles_x, tiles_y], outputs=[s1, p1, s2, p2, skipped],
                   device=device, min_chunk=16)
    on = active.numpy()
    listed = np.nonzero(on)[0].astype(np.int32)
    if len(listed):
        filtered = wp.array(listed, dtype=wp.int32, device=device)
        m = len(listed) * tile * tile
        for src, spen, dst, dpen, k in ((vis, pen, s1, p1, 0), (s1, p1, s2, p2, 1)):
            launch_chunked(sigma_blur, m, inputs=[g, cam, src, spen, filtered, tile, tiles_x, tiles_y, tp, float(max_radius),
                                                  float(sharp_below), float(plane_sensitivity), int(seed) + k],
                           outputs=[dst, dpen], device=device, min_chunk=256, per_thread=16)
    if counters is not None:
        counters["tiles"] = int(nt)
        counters["tiles_skipped"] = int((on == 0).sum())
        counters["samples_skipped"] = int(skipped.numpy().astype(np.int64).sum())
    return s2
