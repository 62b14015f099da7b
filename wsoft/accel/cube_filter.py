"""Percentage-closer filtering across a cube map's faces by direction (``pcf seams=lookup``).

Each receiver filters in the window of the face its direction from the light's centre belongs to;
a tap whose direction falls past that face's edge reads the face that direction belongs to, as a
GPU's cube-map sampler does: the tap's world direction is projected into the neighbouring face's
window and the receiver's tangent plane is compared at the same direction there. The faces then
need no guard band wider than the bilinear tap's texel. The alternative, faces drawn with a guard
band of the kernel's width (each face's own map holds the directions past its edge), is
:func:`~wsoft.lightspace.cube.fit_cube_views`'s ``guard_texels``; ``wsoft bench cube`` measures both.
"""

from __future__ import annotations

import warp as wp

from wsoft.accel.filters import tap_lit
from wsoft.lightspace.cube import owner_face, vec6i
from wsoft.lightspace.samples import to_light_coords
from wsoft.lightspace.view import ViewGPU, depth_at, map_coords, texel_center, texel_size, view_dir, view_of
from wsoft.raster.gbuffer import GBufferGPU, gb_covered


@wp.func
def face_depth(k: int, lv: ViewGPU, d0: wp.array2d[float], d1: wp.array2d[float], d2: wp.array2d[float], d3: wp.array2d[float],
               d4: wp.array2d[float], d5: wp.array2d[float], m: wp.vec2) -> float:
    """The stored depth at window coordinates ``m`` of face ``k``'s map (view ``lv``)."""
    if k == 0:
        return depth_at(lv, d0, m)
    if k == 1:
        return depth_at(lv, d1, m)
    if k == 2:
        return depth_at(lv, d2, m)
    if k == 3:
        return depth_at(lv, d3, m)
    if k == 4:
        return depth_at(lv, d4, m)
    return depth_at(lv, d5, m)


@wp.kernel
def shade_pcf_cube(
    offset: int,
    views: wp.array[ViewGPU],
    drawn: vec6i,
    frame: wp.mat33,
    d0: wp.array2d[float],
    d1: wp.array2d[float],
    d2: wp.array2d[float],
    d3: wp.array2d[float],
    d4: wp.array2d[float],
    d5: wp.array2d[float],
    gb: GBufferGPU,
    taps: wp.array[wp.vec2],
    ntaps: int,
    disk: int,
    radius: float,
    bias: float,
    plane_slope: float,
    dmax: float,
    eps: float,
    # outputs
    vis: wp.array[float],
    face_of: wp.array[wp.int32],
):
    """Per G-buffer sample, the fraction of ``taps`` (``radius`` texels of its own face, a disk for
    ``disk``) where it is lit, each tap read from the face its direction belongs to (``views[k]``
    and ``dk`` face ``k``'s view and map where ``drawn[k] >= 0``; ``frame``'s rows are the cube's
    axes), against the receiver's tangent plane there less ``plane_slope`` of its step per texel and
    ``bias``. ``face_of`` as :func:`~wsoft.lightspace.cube.select_cube_face`'s: the sample's face; 6
    for background, -1 at the light's centre, -2 in a face not drawn (V = 1 for the three)."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        face_of[i] = 6
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    lv = views[0]
    d = p - lv.origin
    if wp.length(d) <= eps:
        vis[i] = 1.0
        face_of[i] = -1
        return
    k = owner_face(frame, d)
    face_of[i] = k
    if drawn[k] < 0:
        vis[i] = 1.0
        face_of[i] = -2
        return
    lv = views[k]
    pv = view_of(lv, p)
    if pv[2] <= lv.near:
        vis[i] = 1.0
        return
    m0 = map_coords(lv, pv)
    half = texel_size(lv) * radius
    lit = float(0.0)
    for t in range(ntaps):
        o = to_light_coords(taps[t], disk)
        m = wp.vec2(m0[0] + o[0] * half[0], m0[1] + o[1] * half[1])
        c = texel_center(lv, m)
        w = lv.ax * c[0] + lv.ay * c[1] + lv.az  # the tap texel's direction (world)
        k2 = owner_face(frame, w)
        tv = lv
        tm = m
        if k2 != k and drawn[k2] >= 0:
            tv = views[k2]
            tz = wp.dot(w, tv.az)
            tm = wp.vec2(wp.dot(w, tv.ax) / tz, wp.dot(w, tv.ay) / tz)
        else:
            k2 = k
        lit += tap_lit(tv, view_of(tv, p), view_dir(tv, n), tm, face_depth(k2, tv, d0, d1, d2, d3, d4, d5, tm), bias, 1, plane_slope,
                       dmax)
    vis[i] = lit / float(ntaps)
