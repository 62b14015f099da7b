"""Backprojection soft shadow mapping: the per-receiver kernels of the ``ssm`` technique.

Coordinates. Level-0 texel coordinates ``(tx, ty)`` of the square ``N``-texel map (texel ``(x, y)``
covers ``[x, x + 1) x [y, y + 1)``; window coordinates ``l + tx * tw``). The light is the
square ``[-1, 1]^2`` of *light coordinates*: for a local light the plane ``z = 0`` of the light
view, scaled by the light's half extents (a rect light exactly; disk and sphere lights by their
bounding square, their bitmask samples restricted to the disk); for a distant light the
tangents of directions around the view axis, scaled by ``tan`` of the sun's half angle.

A micro-occluder at depth ``d`` covering window ``[u0, u1] x [v0, v1]`` backprojects from the
receiver ``p`` (view space) onto the rectangle of light coordinates
``(p_x + (u d - p_x) p_z / (p_z - d)) / w`` (perspective) or ``((u - p_x) / (p_z - d)) / tan a``
(orthographic), increasing in ``u`` so a rectangle stays a rectangle.

Kernels, in frame order (Schwarz & Stamminger 2008, Fig. 3):

1. :func:`search_areas` — per receiver: the search area from the light's pyramid through the
   receiver, refined with the pruning structure's depth range (``z_min``), the umbra / fully-lit
   classification (no backprojection), the fractional level ``l = log2(size / b_mo)`` (LOQ map),
   with the query grown to the support of the level's micro-occluders (§6, over-precision).
2. :func:`smooth_loq` — the separable bilateral smoothing of the LOQ map (one axis a launch),
   stopping at depth discontinuities and at receivers that need no backprojection.
3. :func:`backproject` — visibility from the micro-occluders of level ``floor(l)`` and
   ``ceil(l)``, blended by the fraction (or ``ceil(l)`` alone without blending): area
   accumulation (clamped sum) or an occlusion bitmask over light samples.
4. :func:`resolve_samples` — visibility of every G-buffer sample from the per-pixel visibility
   (§7: same depth within tau, else the 4-neighbour whose depth is closest).
"""

from __future__ import annotations

import warp as wp

from wsoft.accel.ssm_structures import DepthRanges, depth_range, pyr_at
from wsoft.raster.gbuffer import GBufferGPU, gb_covered, gb_index, gb_neighbour, gb_pixel
from wsoft.lightspace.bitmask import mask_behind, mask_quad, mask_rect, mask_t, mask_visibility
from wsoft.lightspace.halfspace import box_in_front, clip_half, front_part, polygon_area, view_front_line
from wsoft.lightspace.halfspace import poly_t as poly2_t
from wsoft.lightspace.light import LightKernel, spread
from wsoft.lightspace.view import (
    DEPTH_CLEAR,
    MISS,
    ViewGPU,
    in_front_of_light,
    light_facing,
    receiver_plane_depth,
    texel_of,
    view_dir,
    view_of,
)

STATUS_LIT = 0
STATUS_UMBRA = 1
STATUS_PENUMBRA = 2  # needs backprojection
STATUS_BACKGROUND = 3

OCC_MICROPATCH = 0
OCC_MICROQUAD = 1
OCC_MICRORECT = 2

poly_t = wp.types.vector(length=8, dtype=float)


@wp.struct
class SSMSetup:
    """What every SSM kernel needs besides the maps: light view, light, settings."""

    lv: ViewGPU
    k: LightKernel
    occluder: int  # OCC_*
    bitmask: int  # 0: area accumulation, 1: occlusion bitmask
    n: int  # bitmask samples per side
    pattern: int  # PATTERN_*
    gap_fill: int
    overprecision: int
    gather_extent: int  # microrects: also the cells one beyond the search area's +x and +y sides (up to (b+2)² a level)
    refine: int  # search-area refinement iterations
    bias: float  # world units
    blend: int


@wp.func
def budget_level(size: float, b: float) -> float:
    """Fractional level at which a search area of ``size`` level-0 texels spans ``b`` texels."""
    if b >= 1.0e30 or size <= b:
        return 0.0
    return wp.log2(size / b)


@wp.func
def grown_bounds(x0: float, x1: float, cell: int, extra: int) -> wp.vec2i:
    """Inclusive level-0 texel range covering [x0, x1], snapped out to cells of ``cell`` texels
    (the support of the level's micro-occluders), plus ``extra`` cells each side."""
    a = int(wp.floor(x0 / float(cell))) - extra
    b = int(wp.floor(x1 / float(cell))) + extra
    return wp.vec2i(a * cell, (b + 1) * cell - 1)


@wp.func
def plane_min_over(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3, x0: int, y0: int, x1: int, y1: int) -> float:
    """Nearest depth of the receiver's tangent plane over level-0 texels [x0, x1] x [y0, y1] (its
    corners: the depth is monotonic along lines of the window while the plane stays in front)."""
    u0 = lv.window[0] + float(x0) / lv.scale[0]
    u1 = lv.window[0] + float(x1 + 1) / lv.scale[0]
    v0 = lv.window[2] + float(y0) / lv.scale[1]
    v1 = lv.window[2] + float(y1 + 1) / lv.scale[1]
    a = receiver_plane_depth(lv, pv, nv, wp.vec2(u0, v0))
    b = receiver_plane_depth(lv, pv, nv, wp.vec2(u1, v0))
    c = receiver_plane_depth(lv, pv, nv, wp.vec2(u0, v1))
    d = receiver_plane_depth(lv, pv, nv, wp.vec2(u1, v1))
    if a <= MISS or b <= MISS or c <= MISS or d <= MISS:
        return MISS
    return wp.min(wp.min(a, b), wp.min(c, d))


@wp.kernel
def search_areas(
    offset: int,
    st: SSMSetup,
    acc: DepthRanges,
    gb: GBufferGPU,
    rid: wp.array[wp.int32],
    budget: wp.array[float],
    z_first: float,
    # outputs
    area: wp.array[wp.vec4],
    status: wp.array[wp.int32],
    loq: wp.array[float],
    cam: wp.array[float],
):
    """Search area (level-0 texel coordinates x0, y0, x1, y1), status and LOQ of each receiver."""
    i = wp.tid() + offset
    s = rid[i]
    area[i] = wp.vec4(0.0)
    loq[i] = 0.0
    cam[i] = gb.dist[s]
    if not gb_covered(gb, s):
        status[i] = STATUS_BACKGROUND
        return
    lv = st.lv
    pv = view_of(lv, gb.pos[s])
    if not in_front_of_light(lv, pv):
        status[i] = STATUS_LIT
        return
    zr = pv[2]
    nv = view_dir(lv, gb.nrm[s])
    tc = texel_of(lv, pv)
    n = lv.width
    b = budget[i]
    z = z_first
    if z >= zr - st.bias:
        status[i] = STATUS_LIT
        return
    extra = int(0)
    if st.occluder == OCC_MICRORECT or st.occluder == OCC_MICROQUAD:
        extra = 1
    hx = float(0.0)
    hy = float(0.0)
    for it in range(st.refine + 1):
        h = spread(lv, st.k, z, zr)
        hx = h[0] * lv.scale[0]
        hy = h[1] * lv.scale[1]
        cell = int(1)
        ex = int(0)
        if st.overprecision != 0:
            lev = budget_level(2.0 * wp.max(hx, hy), b)
            cell = 1 << int(wp.ceil(lev))
            if cell > 1:
                ex = extra
        # the region grown to the support of the level's micro-occluders (§6) decides lit / umbra
        # only; the search area itself drives the refinement and the level, so every occluder type
        # is compared on the same search areas and levels
        gx = grown_bounds(tc[0] - hx, tc[0] + hx, cell, ex)
        gy = grown_bounds(tc[1] - hy, tc[1] + hy, cell, ex)
        r = depth_range(acc, gx[0], gy[0], gx[1], gy[1])
        if r[0] >= zr - st.bias:
            status[i] = STATUS_LIT
            return
        # umbra: every texel of the area is nearer than the receiver's tangent plane anywhere in
        # it (so none of them is the receiver's own surface) and the area lies inside the map
        inside = gx[0] >= 0 and gy[0] >= 0 and gx[1] < n and gy[1] < n
        if inside and r[1] < zr - st.bias and r[1] < plane_min_over(lv, pv, nv, gx[0], gy[0], gx[1], gy[1]) - st.bias:
            status[i] = STATUS_UMBRA
            return
        zs = r[0]
        if cell > 1 or ex > 0:
            sx = grown_bounds(tc[0] - hx, tc[0] + hx, 1, 0)
            sy = grown_bounds(tc[1] - hy, tc[1] + hy, 1, 0)
            zs = depth_range(acc, sx[0], sy[0], sx[1], sy[1])[0]
        if zs <= z or zs >= zr - st.bias:
            break
        z = zs
        if it == st.refine:
            h = spread(lv, st.k, z, zr)
            hx = h[0] * lv.scale[0]
            hy = h[1] * lv.scale[1]
    status[i] = STATUS_PENUMBRA
    area[i] = wp.vec4(tc[0] - hx, tc[1] - hy, tc[0] + hx, tc[1] + hy)
    loq[i] = budget_level(2.0 * wp.max(hx, hy), b)


@wp.kernel
def smooth_loq(
    offset: int,
    src: wp.array[float],
    status: wp.array[wp.int32],
    cam: wp.array[float],
    gb: GBufferGPU,
    radius: int,
    axis: int,
    threshold: float,
    # outputs
    dst: wp.array[float],
):
    """One axis of the LOQ smoothing: the mean over the run of backprojecting receivers within
    ``radius`` that is not cut by a camera-depth jump larger than ``threshold`` (relative).
    Receivers are laid out as the G-buffer's samples (one layer per pixel sample, or one layer)."""
    i = wp.tid() + offset
    v = src[i]
    dst[i] = v
    if status[i] != STATUS_PENUMBRA or radius <= 0:
        return
    total = v
    count = float(1.0)
    for side in range(2):
        step = 1 - 2 * side
        prev = cam[i]
        for k in range(1, radius + 1):
            q = gb_neighbour(gb, i, step * k * (1 - axis), step * k * axis)
            if q < 0:
                break
            if status[q] != STATUS_PENUMBRA:
                break
            if wp.abs(cam[q] - prev) > threshold * wp.max(prev, 1.0e-20):
                break
            total += src[q]
            count += 1.0
            prev = cam[q]
    dst[i] = total / count


# -- light coordinates -----------------------------------------------------------------------


@wp.func
def light_x(lv: ViewGPU, k: LightKernel, pv: wp.vec3, u: float, d: float, axis: int) -> float:
    """Light coordinate (along ``axis``) of the ray from the receiver through window coordinate
    ``u`` at depth ``d``."""
    pa = pv[axis]
    if lv.persp != 0:
        return (pa + (u * d - pa) * pv[2] / (pv[2] - d)) / k.half[axis]
    return (u - pa) / (pv[2] - d) / k.half[axis]


@wp.func
def front_distance(lv: ViewGPU, pv: wp.vec3, nl: wp.vec3, d: float, cu: float, cv: float, hu: float, hv: float) -> float:
    """Smallest signed distance, over the window rectangle centred at (cu, cv) with half sizes
    (hu, hv) placed at depth ``d``, in front of the receiver's tangent plane (normal ``nl``
    toward the light). Only what lies in front of that plane can be between the receiver and
    the light."""
    if lv.persp != 0:
        return d * (nl[0] * cu + nl[1] * cv + nl[2] - wp.abs(nl[0]) * hu - wp.abs(nl[1]) * hv) - wp.dot(nl, pv)
    return nl[0] * cu + nl[1] * cv + nl[2] * d - wp.abs(nl[0]) * hu - wp.abs(nl[1]) * hv - wp.dot(nl, pv)


# -- area accumulation -----------------------------------------------------------------------


@wp.func
def rect_area(lo: wp.vec2, hi: wp.vec2) -> float:
    """Share of the light square [-1, 1]^2 covered by the rectangle [lo, hi]."""
    w = wp.min(hi[0], 1.0) - wp.max(lo[0], -1.0)
    h = wp.min(hi[1], 1.0) - wp.max(lo[1], -1.0)
    if w <= 0.0 or h <= 0.0:
        return 0.0
    return 0.25 * w * h


@wp.func
def clip_polygon(xs: poly_t, ys: poly_t, n: int, axis: int, sign: float):
    """Clip a polygon (n <= 7 corners) to sign * coordinate[axis] <= 1 (Sutherland-Hodgman)."""
    ox = poly_t()
    oy = poly_t()
    m = int(0)
    for i in range(n):
        j = (i + n - 1) % n
        ci = xs[i]
        cj = xs[j]
        if axis == 1:
            ci = ys[i]
            cj = ys[j]
        fi = sign * ci - 1.0
        fj = sign * cj - 1.0
        if (fi <= 0.0) != (fj <= 0.0) and m < 8:
            t = fj / (fj - fi)
            ox[m] = xs[j] + (xs[i] - xs[j]) * t
            oy[m] = ys[j] + (ys[i] - ys[j]) * t
            m += 1
        if fi <= 0.0 and m < 8:
            ox[m] = xs[i]
            oy[m] = ys[i]
            m += 1
    return ox, oy, m


@wp.func
def quad_area(a: wp.vec2, b: wp.vec2, c: wp.vec2, d: wp.vec2, front: wp.vec3) -> float:
    """Share of the light square covered by the quadrilateral a b c d in front of the receiver's
    line ``front`` (:func:`~wsoft.lightspace.halfspace.view_front_line`; clipped, shoelace)."""
    xs = poly_t()
    ys = poly_t()
    xs[0] = a[0]
    ys[0] = a[1]
    xs[1] = b[0]
    ys[1] = b[1]
    xs[2] = c[0]
    ys[2] = c[1]
    xs[3] = d[0]
    ys[3] = d[1]
    n = int(4)
    xs, ys, n = clip_polygon(xs, ys, n, 0, 1.0)
    xs, ys, n = clip_polygon(xs, ys, n, 0, -1.0)
    xs, ys, n = clip_polygon(xs, ys, n, 1, 1.0)
    xs, ys, n = clip_polygon(xs, ys, n, 1, -1.0)
    P = poly2_t()
    for i in range(n):
        P[i, 0] = xs[i]
        P[i, 1] = ys[i]
    P, n = clip_half(P, n, front)
    return 0.25 * wp.abs(polygon_area(P, n))


# -- backprojection --------------------------------------------------------------------------


@wp.func
def cell_depth(st: SSMSetup, occ: DepthRanges, mr_dep: wp.array[float], j: int, x: int, y: int) -> float:
    n = occ.size >> j
    if x < 0 or y < 0 or x >= n or y >= n:
        return DEPTH_CLEAR
    if st.occluder == OCC_MICRORECT:
        return mr_dep[occ.pyr_off[j] + y * n + x]
    return pyr_at(occ, j, x, y)[0]


@wp.func
def occludes(st: SSMSetup, pv: wp.vec3, nl: wp.vec3, d: float, t0: wp.vec2, t1: wp.vec2) -> bool:
    """Is a micro-occluder of depth ``d`` over level-0 texels [t0, t1] nearer to the light than
    the receiver and wholly in front of its tangent plane (by the bias)?"""
    if d >= pv[2] - st.bias:
        return False
    lv = st.lv
    u0 = lv.window[0] + t0[0] / lv.scale[0]
    u1 = lv.window[0] + t1[0] / lv.scale[0]
    v0 = lv.window[2] + t0[1] / lv.scale[1]
    v1 = lv.window[2] + t1[1] / lv.scale[1]
    return front_distance(lv, pv, nl, d, 0.5 * (u0 + u1), 0.5 * (v0 + v1), 0.5 * (u1 - u0), 0.5 * (v1 - v0)) > st.bias


@wp.func
def level_visibility(
    st: SSMSetup,
    occ: DepthRanges,
    mr_ext: wp.array[wp.vec4i],
    mr_dep: wp.array[float],
    samples: wp.array[wp.vec2],
    pv: wp.vec3,
    nv: wp.vec3,
    a: wp.vec4,
    j: int,
    front: wp.vec3,
) -> wp.vec2:
    """(visibility, micro-occluders processed) from the level-``j`` micro-occluders of the
    search area ``a`` (level-0 texel coordinates), over the part of the light in front of the
    receiver's line ``front`` (:func:`~wsoft.lightspace.halfspace.view_front_line`): the samples
    behind it are blocked from the start, areas are clipped to it."""
    lv = st.lv
    k = st.k
    cell = 1 << j
    fc = float(cell)
    n = occ.size >> j
    cx0 = int(wp.floor(a[0] / fc))
    cx1 = int(wp.floor(a[2] / fc))
    cy0 = int(wp.floor(a[1] / fc))
    cy1 = int(wp.floor(a[3] / fc))
    if st.occluder == OCC_MICROQUAD:  # a quad spans from one texel centre to the next
        cx0 -= 1
        cy0 -= 1
    if st.occluder == OCC_MICRORECT and st.gather_extent != 0:
        # a level-j microrect's extent holds its reference point (cx 2^j, cy 2^j) and no other, so
        # it lies within one cell of it: the cells [floor(a0 / 2^j), floor(a2 / 2^j) + 1] hold
        # every microrect that can reach the area (the +1 cell's extent may reach back into it;
        # the -1 cell's ends at cx0 2^j <= a0). Those whose extent misses the area are skipped below.
        cx1 += 1
        cy1 += 1
    cx0 = wp.max(cx0, 0)
    cy0 = wp.max(cy0, 0)
    cx1 = wp.min(cx1, n - 1)
    cy1 = wp.min(cy1, n - 1)
    m = mask_t()
    if st.bitmask != 0:
        m = mask_behind(m, st.n, samples, front)
    covered = float(0.0)
    count = int(0)
    tw = 1.0 / lv.scale[0]
    th = 1.0 / lv.scale[1]
    for cy in range(cy0, cy1 + 1):
        for cx in range(cx0, cx1 + 1):
            if st.occluder == OCC_MICROQUAD:
                if cx + 1 >= n or cy + 1 >= n:
                    continue
                count += 1
                d00 = cell_depth(st, occ, mr_dep, j, cx, cy)
                d10 = cell_depth(st, occ, mr_dep, j, cx + 1, cy)
                d01 = cell_depth(st, occ, mr_dep, j, cx, cy + 1)
                d11 = cell_depth(st, occ, mr_dep, j, cx + 1, cy + 1)
                t0 = wp.vec2((float(cx) + 0.5) * fc, (float(cy) + 0.5) * fc)
                t1 = wp.vec2((float(cx) + 1.5) * fc, (float(cy) + 1.5) * fc)
                dmax = wp.max(wp.max(d00, d10), wp.max(d01, d11))
                if not occludes(st, pv, nv, dmax, t0, t1):
                    continue
                u0 = lv.window[0] + t0[0] * tw
                u1 = lv.window[0] + t1[0] * tw
                v0 = lv.window[2] + t0[1] * th
                v1 = lv.window[2] + t1[1] * th
                qa = wp.vec2(light_x(lv, k, pv, u0, d00, 0), light_x(lv, k, pv, v0, d00, 1))
                qb = wp.vec2(light_x(lv, k, pv, u1, d10, 0), light_x(lv, k, pv, v0, d10, 1))
                qc = wp.vec2(light_x(lv, k, pv, u1, d11, 0), light_x(lv, k, pv, v1, d11, 1))
                qd = wp.vec2(light_x(lv, k, pv, u0, d01, 0), light_x(lv, k, pv, v1, d01, 1))
                lo = wp.min(wp.min(qa, qb), wp.min(qc, qd))
                hi = wp.max(wp.max(qa, qb), wp.max(qc, qd))
                if hi[0] <= -1.0 or hi[1] <= -1.0 or lo[0] >= 1.0 or lo[1] >= 1.0:
                    continue
                if st.bitmask != 0:
                    m = mask_quad(m, st.n, st.pattern, samples, qa, qb, qc, qd)
                else:
                    covered += quad_area(qa, qb, qc, qd, front)
                continue
            # micropatches and microrects: rectangles
            t0 = wp.vec2(float(cx * cell), float(cy * cell))
            t1 = wp.vec2(float((cx + 1) * cell), float((cy + 1) * cell))
            d = float(0.0)
            if st.occluder == OCC_MICRORECT:
                e = mr_ext[occ.pyr_off[j] + cy * n + cx]
                if float(e[0]) > a[2] or float(e[2] + 1) < a[0] or float(e[1]) > a[3] or float(e[3] + 1) < a[1]:
                    continue
                t0 = wp.vec2(float(e[0]), float(e[1]))
                t1 = wp.vec2(float(e[2] + 1), float(e[3] + 1))
                d = mr_dep[occ.pyr_off[j] + cy * n + cx]
            else:
                d = pyr_at(occ, j, cx, cy)[0]
            count += 1
            if not occludes(st, pv, nv, d, t0, t1):
                continue
            u0 = lv.window[0] + t0[0] * tw
            u1 = lv.window[0] + t1[0] * tw
            v0 = lv.window[2] + t0[1] * th
            v1 = lv.window[2] + t1[1] * th
            lo = wp.vec2(light_x(lv, k, pv, u0, d, 0), light_x(lv, k, pv, v0, d, 1))
            hi = wp.vec2(light_x(lv, k, pv, u1, d, 0), light_x(lv, k, pv, v1, d, 1))
            if st.occluder == OCC_MICROPATCH and st.gap_fill != 0:
                # extend toward the left and bottom neighbours: covers the gap their projections leave
                if cx > 0:
                    dl = pyr_at(occ, j, cx - 1, cy)[0]
                    if occludes(st, pv, nv, dl, wp.vec2(t0[0] - fc, t0[1]), wp.vec2(t0[0], t1[1])):
                        lo = wp.vec2(wp.min(lo[0], light_x(lv, k, pv, u0, dl, 0)), lo[1])
                if cy > 0:
                    db = pyr_at(occ, j, cx, cy - 1)[0]
                    if occludes(st, pv, nv, db, wp.vec2(t0[0], t0[1] - fc), wp.vec2(t1[0], t0[1])):
                        lo = wp.vec2(lo[0], wp.min(lo[1], light_x(lv, k, pv, v0, db, 1)))
            if hi[0] <= -1.0 or hi[1] <= -1.0 or lo[0] >= 1.0 or lo[1] >= 1.0:
                continue
            if st.bitmask != 0:
                m = mask_rect(m, st.n, st.pattern, samples, lo, hi)
            else:
                covered += box_in_front(lo, hi, front)
    vis = float(0.0)
    if st.bitmask != 0:
        vis = mask_visibility(m, st.n)
    else:
        lit = front_part(wp.vec2(1.0, 1.0), 0, front)
        vis = lit - wp.min(covered, lit)
    return wp.vec2(vis, float(count))


@wp.kernel
def backproject(
    offset: int,
    st: SSMSetup,
    occ: DepthRanges,
    mr_ext: wp.array[wp.vec4i],
    mr_dep: wp.array[float],
    samples: wp.array[wp.vec2],
    gb: GBufferGPU,
    rid: wp.array[wp.int32],
    area: wp.array[wp.vec4],
    status: wp.array[wp.int32],
    loq_raw: wp.array[float],
    loq: wp.array[float],
    # outputs
    vis: wp.array[float],
    processed: wp.array[wp.int32],
):
    """Visibility of each receiver: 1 lit, 0 umbra, else backprojected at level ceil(loq) or
    blended between floor(loq) and ceil(loq)."""
    i = wp.tid() + offset
    processed[i] = 0
    stt = status[i]
    if stt == STATUS_UMBRA:
        vis[i] = 0.0
        return
    if stt != STATUS_PENUMBRA:
        vis[i] = 1.0
        return
    s = rid[i]
    pv = view_of(st.lv, gb.pos[s])
    nr = view_dir(st.lv, gb.nrm[s])
    nv = light_facing(st.lv, pv, nr)
    front = view_front_line(st.lv, st.k, pv, nr)  # the light clipped to the receiver's front half-space
    a = area[i]
    top = occ.top
    if st.blend == 0:
        j = wp.min(int(wp.ceil(loq_raw[i] - 1.0e-6)), top)
        r = level_visibility(st, occ, mr_ext, mr_dep, samples, pv, nv, a, j, front)
        vis[i] = r[0]
        processed[i] = int(r[1])
        return
    lev = wp.min(loq[i], float(top))
    j0 = int(wp.floor(lev))
    alpha = lev - float(j0)
    r0 = level_visibility(st, occ, mr_ext, mr_dep, samples, pv, nv, a, j0, front)
    v = r0[0]
    cnt = int(r0[1])
    if alpha > 1.0e-4 and j0 < top:
        r1 = level_visibility(st, occ, mr_ext, mr_dep, samples, pv, nv, a, j0 + 1, front)
        v = (1.0 - alpha) * v + alpha * r1[0]
        cnt += int(r1[1])
    vis[i] = v
    processed[i] = cnt


@wp.kernel
def pick_receivers(
    offset: int,
    gb: GBufferGPU,
    # outputs
    rid: wp.array[wp.int32],
):
    """One receiver per pixel: its first covered G-buffer sample, else sample 0."""
    p = wp.tid() + offset  # the pixel, as its sample in layer 0
    rid[p] = p
    xy = gb_pixel(gb, p)
    for s in range(gb.spp):
        q = gb_index(gb, xy[0], xy[1], s)
        if gb_covered(gb, q):
            rid[p] = q
            return


@wp.kernel
def resolve_samples(
    offset: int,
    vis_pix: wp.array[float],
    rid: wp.array[wp.int32],
    gb: GBufferGPU,
    tau: float,
    interpolate: int,
    # outputs
    vis: wp.array[float],
):
    """Visibility of G-buffer sample ``i`` from the per-pixel visibility (§7): the pixel's own
    where the sample's camera depth is within ``tau`` (relative) of the pixel's representative
    sample ``rid[p]``, else (with ``interpolate``) that of the pixel or 4-neighbour whose
    representative depth is closest to the sample's. Pixel ``p`` is its sample in layer 0."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        vis[i] = 1.0
        return
    xy = gb_pixel(gb, i)
    p = gb_index(gb, xy[0], xy[1], 0)
    v = vis_pix[p]
    z = gb.dist[i]
    zp = gb.dist[rid[p]]
    if interpolate == 0 or wp.abs(z - zp) <= tau * zp:
        vis[i] = v
        return
    best = wp.abs(z - zp)
    for k in range(4):
        dx = int(0)
        dy = int(0)
        if k == 0:
            dx = -1
        elif k == 1:
            dx = 1
        elif k == 2:
            dy = -1
        else:
            dy = 1
        pn = gb_neighbour(gb, p, dx, dy)
        if pn < 0:
            continue
        q = rid[pn]
        if not gb_covered(gb, q):
            continue
        e = wp.abs(z - gb.dist[q])
        if e < best:
            best = e
            v = vis_pix[pn]
    vis[i] = v
