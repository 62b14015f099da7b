"""A simple diffuse shading of every G-buffer sample with the lights' emission and visibilities (``R G B``).

Each light adds its irradiance, ``E = emission x omega x S x max(0, N.L)``: ``emission`` its UsdLux
radiance (:func:`emission_of`: ``intensity x 2^exposure x color``, times the blackbody colour of
``colorTemperature`` where ``enableColorTemperature`` is on, over the light's size where
``normalize`` is on), ``omega`` the solid angle it fills seen from the sample (:func:`light_omega`),
``L`` toward its centre, and ``UsdLux.ShapingAPI``'s cone, softness, focus, focusTint and IES profile
(:func:`~wsoft.lightspace.light.shaping_weight`) along the direction from its centre to the sample
(an area light's whole emission shaped as its centre's). Several lights sum. The image is exposed once per frame so that it is not
blown out: the sum without shadows (every ``S`` = 1) is scaled so that its 99th percentile over the
samples a light reaches (of each sample's brightest channel) is 1 (:func:`frame_exposure`); the shadows do not move the exposure,
so every technique's image of a frame is exposed alike and only its shadows differ. A surface shows
``albedo x (ambient + (1 - ambient) x exposed irradiance)``, clamped to [0, 1].

A dome light (the sky) adds its irradiance about the sample's normal times its ``S``
(:mod:`wsoft.raster.shade_dome`).

Surfaces with baked lighting (``primvars:wsoft:bakedLight``) are lit by it, masked by the lights'
``S`` weighted by their irradiance there (a lightmap masked by a shadow map, as Salzman intends).

S is a light's *shadowed transmission*, ``V + shadow_color (1 - V)`` per colour channel: UsdLux's
``inputs:shadow:color`` ("the color of shadows cast by the light ... the default is to cast black
shadows") tints the shadowed part of the light's contribution, so a black shadow colour gives
S = V and a white one no shadow at all. ``V`` itself stays the geometric visible fraction.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.lightspace.light import LINE_WIDTH, LightGPU, light_center_dir, shaping_weight
from wsoft.raster.shade_dome import add_dome
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_DISK, LIGHT_DISTANT, LIGHT_DOME, LIGHT_RECT, LIGHT_SPHERE, Light

AMBIENT = 0.12  # share of the exposed image that is unshadowed ambient
EXPOSURE_PERCENTILE = 99.0  # the unshadowed irradiance's percentile (brightest channel, samples lit) exposed to 1


@wp.func
def shadowed_transmission(v: float, shadow_color: wp.vec3) -> wp.vec3:
    """S = V + shadow_color (1 - V) per channel: the light's contribution with its shadow tinted
    (``inputs:shadow:color``; black: S = V exactly)."""
    return wp.vec3(v) + shadow_color * (1.0 - v)


@wp.func
def light_omega(L: LightGPU, area: float, omega_far: float, d: wp.vec4) -> float:
    """The solid angle (projected by the light's own emitting cosine) a light fills seen from a
    sample at distance ``d[3]`` along ``d`` (unit, toward its centre): a distant light's
    ``omega_far``; a local one's emitting ``area`` as an on-axis disk of that area gives it,
    ``area / (dist^2 + area / pi)`` (at most pi, the hemisphere), times ``cos`` of the emitting
    normal for a rect or disk light."""
    if L.kind == 3:
        return omega_far
    w = area / (d[3] * d[3] + area / wp.pi)
    if L.kind == 0 or L.kind == 1:  # rect, disk: emit along -Z
        w = w * wp.max(wp.dot(L.az, wp.vec3(d[0], d[1], d[2])), 0.0)
    return w


@wp.kernel
def accumulate_light(
    offset: int,
    L: LightGPU,
    gb: GBufferGPU,
    vis: wp.array[float],
    shadow_color: wp.vec3,
    emission: wp.vec3,
    area: float,
    omega_far: float,
    # outputs
    lum: wp.array[wp.vec3],
    unshadowed: wp.array[wp.vec3],
    mask_num: wp.array[wp.vec3],
    mask_den: wp.array[wp.vec3],
):
    """Per sample: lum += E S, unshadowed += E, with E = emission shaping omega max(0, N . L) (L toward the
    light's centre, shaping :func:`~wsoft.lightspace.light.shaping_weight` along -L); mask_num += E_0 S, mask_den += E_0 with E_0 the irradiance without the cosine
    (the baked light's mask; S: :func:`shadowed_transmission` of V, per colour channel)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        return
    d = light_center_dir(L, gb.pos[i])
    s = shadowed_transmission(vis[i], shadow_color)
    e0 = wp.cw_mul(emission, shaping_weight(L, -wp.vec3(d[0], d[1], d[2]))) * light_omega(L, area, omega_far, d)
    e = e0 * wp.max(wp.dot(gb.nrm[i], wp.vec3(d[0], d[1], d[2])), 0.0)
    lum[i] = lum[i] + wp.cw_mul(e, s)
    unshadowed[i] = unshadowed[i] + e
    mask_num[i] = mask_num[i] + wp.cw_mul(e0, s)
    mask_den[i] = mask_den[i] + e0


@wp.kernel
def finish_shading(
    offset: int,
    gb: GBufferGPU,
    tri_albedo: wp.array[wp.vec3],
    tri_baked: wp.array[wp.vec3],
    tri_has_baked: wp.array[wp.int32],
    lum: wp.array[wp.vec3],
    mask_num: wp.array[wp.vec3],
    mask_den: wp.array[wp.vec3],
    ambient: float,
    exposure: float,
    # outputs
    rgb: wp.array[wp.vec3],
):
    i = wp.tid() + offset
    f = gb.prim[i]
    if f < 0:
        rgb[i] = wp.vec3(0.0)
        return
    c = wp.cw_mul(tri_albedo[f], wp.vec3(ambient) + (1.0 - ambient) * exposure * lum[i])
    if tri_has_baked[f] != 0:
        b = gb.bary[i]
        light = tri_baked[3 * f] * b[0] + tri_baked[3 * f + 1] * b[1] + tri_baked[3 * f + 2] * (1.0 - b[0] - b[1])
        n = mask_num[i]
        m = mask_den[i]
        mask = wp.vec3(1.0)
        for k in range(3):
            if m[k] > 0.0:
                mask[k] = n[k] / m[k]
        c = wp.cw_mul(wp.cw_mul(tri_albedo[f], light), mask)
    rgb[i] = wp.vec3(wp.clamp(c[0], 0.0, 1.0), wp.clamp(c[1], 0.0, 1.0), wp.clamp(c[2], 0.0, 1.0))


def emitting_area(light: Light) -> float:
    """The area :func:`light_omega` spreads a local light's emission over: a rect's, a disk's
    (its ellipse's), a sphere's silhouette disk, a cylinder's silhouette rectangle (length x
    diameter; a line light the strip the techniques draw, :data:`~wsoft.lightspace.light.LINE_WIDTH`
    of its length wide); a point light (radius 0) counts as a unit area (its intensity read as that
    of a unit-area emitter at its place)."""
    a = light.aspect
    if light.kind == LIGHT_RECT:
        return 4.0 * light.half_size[0] * light.half_size[1]
    if light.kind == LIGHT_DISK:
        return math.pi * light.radius ** 2 * a[0] * a[1]
    if light.kind == LIGHT_SPHERE:
        return math.pi * light.radius ** 2 * a[0] * a[1]
    if light.kind == LIGHT_CYLINDER:
        length = 2.0 * light.half_size[0]
        return length * (2.0 * light.half_size[1] if light.half_size[1] > 0.0 else float(LINE_WIDTH) * length)
    return 1.0  # LIGHT_POINT


def distant_omega(light: Light) -> float:
    """A distant light's projected solid angle facing it: pi sin^2 of its half angle (pi past 90
    degrees: the whole hemisphere)."""
    half = min(math.radians(0.5 * light.angle_deg), 0.5 * math.pi)
    return math.pi * math.sin(half) ** 2 if light.kind == LIGHT_DISTANT else 0.0


def frame_exposure(unshadowed: np.ndarray) -> float:
    """The factor that takes the :data:`EXPOSURE_PERCENTILE` of the unshadowed irradiance's
    brightest channel over the samples a light reaches to 1 (1 when no light reaches any)."""
    y = unshadowed.max(axis=1)
    y = y[y > 0]
    if not len(y):
        return 1.0
    top = float(np.percentile(y, EXPOSURE_PERCENTILE))
    k = 1.0 / top if top > 0.0 else 1.0
    return k if math.isfinite(k) and k < 3.0e38 else 1.0


def shade(ds, gb, lights_and_vis: list[tuple]) -> wp.array:
    """RGB per G-buffer sample (vec3, background black): albedo x (ambient + (1 - ambient) x exposed
    sum over lights of emission x omega x S x cos) (module docstring).

    ``lights_and_vis``: per light ``(LightGPU, V, Light)`` or ``(LightGPU, V, Light, shadow colour)``
    (an RGB triple, ``inputs:shadow:color``; default the light's own)."""
    n = gb.count
    g = gb.gpu()
    dev = ds.device
    lum, unshadowed, num, den = (wp.zeros(n, dtype=wp.vec3, device=dev) for _ in range(4))
    radiance = [item[2].intensity * np.asarray(item[2].color, np.float64) for item in lights_and_vis]
    top = max([float(r.max()) for r in radiance] + [0.0])
    unit = 1.0 / top if top > 0.0 else 1.0  # the brightest light's radiance as 1: the exposure is relative, float32 keeps its range
    for item, rad in zip(lights_and_vis, radiance):
        L, vis, light = item[0], item[1], item[2]
        sc = item[3] if len(item) > 3 else light.shadow_color
        if light.kind == LIGHT_DOME:  # the sky: its irradiance about each normal (wsoft.raster.shade_dome)
            add_dome(light, gb, vis, sc, unit, lum, unshadowed, num, den, dev)
            continue
        em = wp.vec3(*(rad * unit))
        area = emitting_area(light) if light.kind != LIGHT_DISTANT else 0.0
        launch_chunked(accumulate_light, n, inputs=[L, g, vis, wp.vec3(*sc), em, float(area), distant_omega(light)],
                       outputs=[lum, unshadowed, num, den], device=dev, min_chunk=1 << 14)
    exposure = frame_exposure(unshadowed.numpy())
    rgb = wp.empty(n, dtype=wp.vec3, device=dev)
    launch_chunked(
        finish_shading, n, inputs=[g, ds.tri_albedo, ds.tri_baked, ds.tri_has_baked, lum, num, den, AMBIENT, float(exposure)],
        outputs=[rgb], device=dev, min_chunk=1 << 14,
    )
    return rgb
