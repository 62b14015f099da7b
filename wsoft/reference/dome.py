"""Ray-traced ground truth for a dome light (the sky): V = E_occluded / E_unoccluded at each receiver.

Both irradiances are integrals over the receiver's hemisphere (its camera-facing normal ``n``) of the
dome's luminance ``L(w)`` (Rec. 709 luminance of ``color x intensity x texture(w)``,
:func:`wsoft.scene.dome.radiance`) times ``n . w``; E_occluded counts a direction only where the ray
from the receiver toward it leaves the scene (a miss is the sky: rays go to infinity, or to
``inputs:shadow:distance`` where it is authored; prims the dome's ``collection:shadowLink`` leaves
out are passed through; rays start a few ulps off the surface, :mod:`wsoft.scene.offsets`).

Estimators, per receiver, with ``N`` rays:

* **constant dome** (no texture): cosine-weighted directions (Malley's method,
  :func:`~wsoft.lightspace.sky.cosine_direction`) from a rank-1 (Fibonacci) lattice of ``N`` points
  shifted toroidally by a random offset per receiver (each point uniform: unbiased; on the uniform
  dome over a square, ``reports/lights.md``, its error at 256 rays is about 0.6 of a jittered 16 x 16
  grid's, measured). The cosine cancels the integrand's,
  so ``V = k / N`` (k rays that miss) is unbiased, and its standard error is the other references'
  ``sqrt(p(1-p)/N)`` with the pseudo-count ``p = (k + 0.5)/(N + 1)``
  (:func:`~wsoft.reference.visible_fraction`): the independent-sampling bound.
* **latlong texture**: multiple importance sampling of two strategies, ``n_c = ceil(N/2)``
  cosine-weighted rays and ``n_l = floor(N/2)`` rays drawn from the dome's radiance
  (:class:`~wsoft.scene.dome.SamplingTable`: texel in proportion to luminance x solid angle, then
  uniform in solid angle inside the texel), each from its own shifted lattice; every ray gets the balance
  heuristic's weight ``w = L(w) (n . w) / (n_c p_c(w) + n_l p_l(w))`` and ``V`` is the **ratio
  estimator** ``sum w vis / sum w`` (the unoccluded sum estimates E_unoccluded with the same rays,
  so their errors cancel where nothing occludes; consistent, bias O(1/N)). Its standard error is the
  larger of the delta method's ``sqrt(sum w^2 (vis - V)^2) / sum w`` and the other references'
  pseudo-count bound with Kish's effective count, ``sqrt(p (1 - p) / N_eff)``, ``p = (sum w vis +
  0.5 w_mean) / (sum w + w_mean)``, ``N_eff = (sum w)^2 / sum w^2`` (equal weights: exactly the
  others' ``sqrt(p(1-p)/N)``; never 0 where some ray counts). A receiver no sampled
  direction lights (``sum w = 0``: the sky above it is black) has V = 1 and standard error 0.

Draws are counter-based (:func:`~wsoft.lightspace.samples.counter_draw`: a hash of the seed, the
receiver, the ray and the dimension), so any ray is generated without the others. Launches are
chunked over the CPU threads (:func:`~wsoft.parallel.launch_chunked`); each receiver writes only its
own outputs.
"""

from __future__ import annotations

import numpy as np
import warp as wp

import wsoft.parallel  # noqa: F401  (Warp configured before this module's kernels are defined)
from wsoft.lightspace.samples import counter_draw, pixel_key, stratified_sample
from wsoft.lightspace.sky import cosine_direction
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.raster.shadow_rays import ray_origin, shadow_ray_length
from wsoft.reference import visible_fraction
from wsoft.scene.dome import LUMINANCE
from wsoft.scene.offsets import ray_offset
from wsoft.scene.rays import Occluders, occluders, unoccluded

SKY_DISTANCE = 1.0e30  # a dome ray's length: it meets the sky only past every surface


@wp.struct
class DomeGPU:
    """A dome on the device: its world <- dome rotation and, for a latlong texture (``textured`` 1),
    the ``h x w`` texels' luminance (``lum``, flat ``[h * w]``, colour x intensity applied), their
    sampling probabilities (``prob``, ``[h * w]``), one texel's solid angle per row (``area``,
    ``[h]``) and the 2D CDF (``row_cdf`` ``[h + 1]``, ``col_cdf`` ``[h * (w + 1)]``)."""

    rot: wp.mat33
    textured: int
    h: int
    w: int
    lum: wp.array[float]
    prob: wp.array[float]
    area: wp.array[float]
    row_cdf: wp.array[float]
    col_cdf: wp.array[float]


def dome_gpu(light, device: str) -> DomeGPU:
    """The :class:`DomeGPU` of the dome ``light`` on ``device``."""
    dome = light.dome
    g = DomeGPU()
    g.rot = wp.mat33(*np.asarray(dome.rotation, np.float32).ravel())
    scale = np.asarray(light.color, np.float64) * float(light.intensity)
    if dome.texture is None:
        one = wp.zeros(1, dtype=float, device=device)
        g.textured, g.h, g.w = 0, 1, 1
        g.lum = g.prob = g.area = g.row_cdf = g.col_cdf = one
        return g
    t = dome.table
    h, w = t.prob.shape
    lum = (np.asarray(dome.texture, np.float64) * scale) @ np.asarray(LUMINANCE)
    g.textured, g.h, g.w = 1, h, w
    g.lum = wp.array(lum.ravel().astype(np.float32), dtype=float, device=device)
    g.prob = wp.array(t.prob.ravel().astype(np.float32), dtype=float, device=device)
    g.area = wp.array(t.area.astype(np.float32), dtype=float, device=device)
    g.row_cdf = wp.array(t.row_cdf.astype(np.float32), dtype=float, device=device)
    g.col_cdf = wp.array(t.col_cdf.ravel().astype(np.float32), dtype=float, device=device)
    return g


@wp.func
def search_cdf(cdf: wp.array[float], first: int, count: int, u: float) -> int:
    """The last ``k`` in [0, count) with ``cdf[first + k] <= u`` (``cdf[first .. first + count]``
    rising from 0 to 1): the bin ``u`` falls in."""
    lo = int(0)
    hi = count - 1
    while lo < hi:
        mid = (lo + hi + 1) / 2
        if cdf[first + mid] <= u:
            lo = mid
        else:
            hi = mid - 1
    return lo


@wp.func
def dome_texel(dome: DomeGPU, d: wp.vec3) -> int:
    """The flat index (row * w + column) of the texel the world direction ``d`` falls in (OpenEXR's latlong layout)."""
    q = wp.transpose(dome.rot) * d
    lat = wp.asin(wp.clamp(q[1], -1.0, 1.0))
    lon = wp.atan2(q[0], q[2])
    col = wp.clamp(int(wp.floor((wp.pi - lon) / (2.0 * wp.pi) * float(dome.w))), 0, dome.w - 1)
    row = wp.clamp(int(wp.floor((0.5 * wp.pi - lat) / wp.pi * float(dome.h))), 0, dome.h - 1)
    return row * dome.w + col


@wp.func
def dome_sample(dome: DomeGPU, u: wp.vec2, v: wp.vec2) -> wp.vec3:
    """A world direction drawn from the dome's sampling table: the texel by ``u``, the point in it
    (uniform in solid angle) by ``v``."""
    row = search_cdf(dome.row_cdf, 0, dome.h, u[0])
    col = search_cdf(dome.col_cdf, row * (dome.w + 1), dome.w, u[1])
    c0 = wp.cos(wp.pi * float(row) / float(dome.h))
    c1 = wp.cos(wp.pi * float(row + 1) / float(dome.h))
    ct = c0 + (c1 - c0) * v[0]
    st = wp.sqrt(wp.max(0.0, 1.0 - ct * ct))
    lon = wp.pi - 2.0 * wp.pi * (float(col) + v[1]) / float(dome.w)
    q = wp.vec3(st * wp.sin(lon), ct, st * wp.cos(lon))
    return wp.normalize(dome.rot * q)


@wp.func
def strategy_point(key: wp.uint32, s: int, j: int, n: int, m: int, dim: int) -> wp.vec2:
    """Point ``j`` of ``n`` of one strategy's stratified set: with ``m x m == n`` a jittered grid
    (jittered by ray ``s``'s dimensions ``dim``, ``dim + 1``), else the rank-1 lattice shifted by ray
    0's dimensions ``dim + 2``, ``dim + 3`` (the receiver's shift)."""
    jitter = wp.vec2(counter_draw(key, s, dim), counter_draw(key, s, dim + 1))
    shift = wp.vec2(counter_draw(key, 0, dim + 2), counter_draw(key, 0, dim + 3))
    return stratified_sample(j, n, m, jitter, shift)


@wp.kernel
def trace_dome_visibility(
    offset: int,
    occ: Occluders,
    dome: DomeGPU,
    gb: GBufferGPU,
    samples: int,
    grid_c: int,
    grid_l: int,
    seed: int,
    dmax: float,
    # outputs
    vis: wp.array[float],
    stderr: wp.array[float],
):
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        stderr[i] = 0.0
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    off = ray_offset(p, gb.err[i])
    o = ray_origin(p, n, off)
    tm = shadow_ray_length(SKY_DISTANCE, dmax, off)
    key = pixel_key(seed, i)
    if dome.textured == 0:
        visible = int(0)
        for s in range(samples):
            d = cosine_direction(n, strategy_point(key, s, s, samples, grid_c, 0))
            if wp.dot(n, d) > 0.0:
                if unoccluded(occ, o, d, tm):
                    visible += 1
        v, e = visible_fraction(visible, samples)
        vis[i] = v
        stderr[i] = e
        return
    nc = (samples + 1) / 2
    nl = samples / 2
    sw = float(0.0)
    swv = float(0.0)
    sw2 = float(0.0)
    sw2v = float(0.0)
    for s in range(samples):
        d = wp.vec3(0.0)
        if s < nc:
            d = cosine_direction(n, strategy_point(key, s, s, nc, grid_c, 0))
        else:
            j = s - nc
            d = dome_sample(dome, strategy_point(key, s, j, nl, grid_l, 4),
                            wp.vec2(counter_draw(key, s, 8), counter_draw(key, s, 9)))
        c = wp.dot(n, d)
        if c > 0.0:
            k = dome_texel(dome, d)
            pl = dome.prob[k] / wp.max(dome.area[k / dome.w], 1.0e-30)
            den = float(nc) * c / wp.pi + float(nl) * pl
            w = float(0.0)
            if den > 0.0:
                w = dome.lum[k] * c / den
            if w > 0.0:
                sw += w
                sw2 += w * w
                if unoccluded(occ, o, d, tm):
                    swv += w
                    sw2v += w * w
    if sw > 0.0:
        v = swv / sw
        delta = (sw2v * (1.0 - v) * (1.0 - v) + (sw2 - sw2v) * v * v) / (sw * sw)
        mean = sw / float(samples)
        pe = (swv + 0.5 * mean) / (sw + mean)
        vis[i] = wp.clamp(v, 0.0, 1.0)
        stderr[i] = wp.sqrt(wp.max(delta, pe * (1.0 - pe) * sw2 / (sw * sw)))
    else:
        vis[i] = 1.0
        stderr[i] = 0.0


PER_THREAD = 8  # chunks a CPU thread (receivers cost unevenly: open sky against enclosed corners)


LATTICE = 0  # stratified_sample's grid side that selects the shifted rank-1 lattice (0 x 0 is never a count)


def trace_dome_reference(ds, light, gb, samples: int, seed: int, excluded: tuple[int, ...] = (),
                         max_distance: float = -1.0) -> tuple[wp.array, wp.array]:
    """V and its standard error per G-buffer sample (flat float32 arrays) under the dome ``light``,
    ``samples`` rays a receiver (the module's estimators); ``excluded``: prims its
    ``collection:shadowLink`` leaves out; ``max_distance``: ``inputs:shadow:distance`` (-1: none)."""
    if samples < 1:
        raise ValueError(f"samples {samples} must be >= 1")
    n = gb.count
    vis = wp.empty(n, dtype=float, device=ds.device)
    err = wp.empty(n, dtype=float, device=ds.device)
    textured = light.dome.texture is not None
    nc = (samples + 1) // 2 if textured else samples
    nl = samples // 2 if textured else 0
    dmax = float(max_distance) if max_distance >= 0.0 else -1.0
    launch_chunked(
        trace_dome_visibility,
        n,
        inputs=[occluders(ds, tuple(excluded)), dome_gpu(light, ds.device), gb.gpu(), int(samples), LATTICE, LATTICE,
                int(seed), dmax],
        outputs=[vis, err],
        device=ds.device,
        min_chunk=256,
        per_thread=PER_THREAD,
    )
    return vis, err
