"""A simple diffuse shading of every G-buffer sample with the lights' visibilities (``R G B``).

Surfaces with baked lighting (``primvars:wsoft:bakedLight``) are lit by it, masked by the mean
visibility of the rendered lights (a lightmap masked by a shadow map, as Salzman intends);
others get albedo x (ambient + mean over lights of S max(0, N.L)).

S is a light's *shadowed transmission*, ``V + shadow_color (1 - V)`` per colour channel: UsdLux's
``inputs:shadow:color`` ("the color of shadows cast by the light ... the default is to cast black
shadows") tints the shadowed part of the light's contribution, so a black shadow colour gives
S = V and a white one no shadow at all. ``V`` itself stays the geometric visible fraction.
"""

from __future__ import annotations

import warp as wp

from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.lightspace.light import LightGPU, light_center_dir

AMBIENT = 0.12  # share of the light that is unshadowed ambient


@wp.func
def shadowed_transmission(v: float, shadow_color: wp.vec3) -> wp.vec3:
    """S = V + shadow_color (1 - V) per channel: the light's contribution with its shadow tinted
    (``inputs:shadow:color``; black: S = V exactly)."""
    return wp.vec3(v) + shadow_color * (1.0 - v)


@wp.kernel
def accumulate_light(
    offset: int,
    L: LightGPU,
    gb: GBufferGPU,
    vis: wp.array[float],
    shadow_color: wp.vec3,
    weight: float,
    # outputs
    lum: wp.array[wp.vec3],
    vmean: wp.array[wp.vec3],
):
    """lum += weight * S * max(0, N . L) per sample, L toward the light's centre; vmean += weight * S
    (S: :func:`shadowed_transmission` of V, per colour channel)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        return
    d = light_center_dir(L, gb.pos[i])
    s = shadowed_transmission(vis[i], shadow_color)
    lum[i] = lum[i] + weight * s * wp.max(wp.dot(gb.nrm[i], wp.vec3(d[0], d[1], d[2])), 0.0)
    vmean[i] = vmean[i] + weight * s


@wp.kernel
def finish_shading(
    offset: int,
    gb: GBufferGPU,
    tri_albedo: wp.array[wp.vec3],
    tri_baked: wp.array[wp.vec3],
    tri_has_baked: wp.array[wp.int32],
    lum: wp.array[wp.vec3],
    vmean: wp.array[wp.vec3],
    ambient: float,
    # outputs
    rgb: wp.array[wp.vec3],
):
    i = wp.tid() + offset
    f = gb.prim[i]
    if f < 0:
        rgb[i] = wp.vec3(0.0)
        return
    c = wp.cw_mul(tri_albedo[f], wp.vec3(ambient) + (1.0 - ambient) * lum[i])
    if tri_has_baked[f] != 0:
        b = gb.bary[i]
        light = tri_baked[3 * f] * b[0] + tri_baked[3 * f + 1] * b[1] + tri_baked[3 * f + 2] * (1.0 - b[0] - b[1])
        c = wp.cw_mul(wp.cw_mul(tri_albedo[f], light), vmean[i])
    rgb[i] = wp.vec3(wp.clamp(c[0], 0.0, 1.0), wp.clamp(c[1], 0.0, 1.0), wp.clamp(c[2], 0.0, 1.0))


def shade(ds, gb, lights_and_vis: list[tuple]) -> wp.array:
    """RGB per G-buffer sample (vec3, background black): albedo x (ambient + mean over lights of S cos).

    ``lights_and_vis``: per light ``(LightGPU, V)`` or ``(LightGPU, V, shadow colour)`` (an RGB
    triple, ``inputs:shadow:color``; default black)."""
    n = gb.count
    g = gb.gpu()
    lum = wp.zeros(n, dtype=wp.vec3, device=ds.device)
    vmean = wp.zeros(n, dtype=wp.vec3, device=ds.device)
    w = 1.0 / max(len(lights_and_vis), 1)
    for item in lights_and_vis:
        L, vis = item[0], item[1]
        sc = wp.vec3(*(item[2] if len(item) > 2 else (0.0, 0.0, 0.0)))
        launch_chunked(accumulate_light, n, inputs=[L, g, vis, sc, w], outputs=[lum, vmean], device=ds.device, min_chunk=1 << 14)
    rgb = wp.empty(n, dtype=wp.vec3, device=ds.device)
    launch_chunked(
        finish_shading, n, inputs=[g, ds.tri_albedo, ds.tri_baked, ds.tri_has_baked, lum, vmean, AMBIENT],
        outputs=[rgb], device=ds.device, min_chunk=1 << 14,
    )
    return rgb
