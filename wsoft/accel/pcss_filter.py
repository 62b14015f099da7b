"""Percentage-closer soft shadows for one receiver on one depth map (Fernando 2005): the blocker
search, the penumbra from the average blocker depth and the light-shaped percentage-closer filter,
as :mod:`wsoft.techniques.pcss` describes them, for any technique that reads a depth map per
receiver (``csm``'s cascades).

The filter's depth bias is ``bias`` plus ``bias_per_texel`` times the filter's half-width in
texels (0: the same bias for search and filter, as ``pcss``).
"""

from __future__ import annotations

import warp as wp

from wsoft.accel.filters import pcf_visibility
from wsoft.lightspace.halfspace import kernel_front
from wsoft.lightspace.light import LightKernel, spread
from wsoft.lightspace.samples import to_light_coords
from wsoft.lightspace.view import ViewGPU, depth_at, map_coords, receiver_tap_depth, texel_center, texel_size, within_distance


@wp.func
def clamp_half(lv: ViewGPU, h: wp.vec2, lo_texels: float, hi_texels: float) -> wp.vec2:
    """A half-size in window units clamped to ``[lo_texels, hi_texels]`` texels on each axis."""
    t = texel_size(lv)
    return wp.vec2(wp.clamp(h[0], lo_texels * t[0], hi_texels * t[0]), wp.clamp(h[1], lo_texels * t[1], hi_texels * t[1]))


@wp.func
def pcss_filter(
    lv: ViewGPU,
    k: LightKernel,
    depth: wp.array2d[float],
    pv: wp.vec3,
    nv: wp.vec3,
    btaps: wp.array[wp.vec2],
    nb: int,
    ftaps: wp.array[wp.vec2],
    nf: int,
    z_caster_min: float,
    bias: float,
    bias_per_texel: float,
    plane_slope: float,
    min_radius: float,
    max_radius: float,
    dmax: float,
) -> wp.vec3:
    """PCSS of the receiver at view-space point ``pv`` (normal ``nv``) on the map ``depth`` of view
    ``lv``: (visibility, average blocker depth (0: no blocker found), filter half-width in texels
    (0: no filter ran)). The search covers where any caster at depth ``z_caster_min`` or beyond
    could cover part of the light; search and filter are clamped to ``[1, max_radius]`` and
    ``[min_radius, max_radius]`` texels, and move to the part of the light in front of the
    receiver's tangent plane (:func:`~wsoft.lightspace.halfspace.kernel_front`)."""
    m0 = map_coords(lv, pv)
    mid, hs, front = kernel_front(lv, k, pv, nv)
    if front <= 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    # 1. blocker search over the region where any caster could cover part of the light
    search = clamp_half(lv, spread(lv, k, z_caster_min, pv[2]), 1.0, max_radius)
    mc = wp.vec2(m0[0] + mid[0] * search[0], m0[1] + mid[1] * search[1])
    search = wp.vec2(search[0] * hs[0], search[1] * hs[1])
    total = float(0.0)
    count = float(0.0)
    for s in range(nb):
        o = to_light_coords(btaps[s], k.disk)
        m = wp.vec2(mc[0] + o[0] * search[0], mc[1] + o[1] * search[1])
        d = depth_at(lv, depth, m)
        c = texel_center(lv, m)
        zr = receiver_tap_depth(lv, pv, nv, m, plane_slope)
        if d < zr - bias:
            if dmax < 0.0 or within_distance(lv, pv, wp.vec2(c[0], c[1]), d, dmax):
                total += d
                count += 1.0
    if count == 0.0:
        return wp.vec3(front, 0.0, 0.0)
    z_avg = total / count
    # 2. penumbra from the average blocker depth; 3. PCF over it, shaped like the light
    pen = clamp_half(lv, spread(lv, k, z_avg, pv[2]), min_radius, max_radius)
    mf = wp.vec2(m0[0] + mid[0] * pen[0], m0[1] + mid[1] * pen[1])
    pen = wp.vec2(pen[0] * hs[0], pen[1] * hs[1])
    t = texel_size(lv)
    texels = wp.max(pen[0] / t[0], pen[1] / t[1])
    v = pcf_visibility(lv, depth, pv, nv, mf, pen, k.disk, ftaps, nf, bias + bias_per_texel * texels, 1, plane_slope, dmax)
    return wp.vec3(front * v, z_avg, texels)
