"""``essm``: exponential soft shadow mapping (Shen, Feng & Yang), all of it.

Passes (each timed in the stats: Table 1's EB, STG and Shadow):

1. ``essm_basis`` — the light-space *linear* depth map's min/max pyramid (a hierarchical
   shadow map) gives the effective depth range [z_min, z_max] (``depth_range=pyramid``; or
   the scene's bounds in light space, ``bounds``). Depth is normalised to z in [0, 1] and three
   channels are written: ``esm = e^{cz}``, ``esm-z = z e^{cz}`` and ``z``. For integer storage
   they are normalised to [0, 1] first (§6.2): ``(e^{cz} - 1)/(e^c - 1)`` and ``z e^{cz}/e^c``.
   The mean pyramid of the channels follows (for the tile-size test).
2. ``essm_sat`` — a summed-area table of the three channels (:mod:`wsoft.accel.sat`):
   ``tiles`` (uint32 SAT tile grid, μ precision bits, tile size from the pyramid test, §6.1),
   ``uint32`` (one integer SAT) or ``float32`` (one float SAT), built by recursive doubling
   with ``reads`` texels per pass or by a direct row/column scan; the pass count is reported.
3. ``essm_shadow`` — per eye sample (a light across the receiver's tangent plane: both kernels
   move to its front part's window and V is scaled by that part's share of the light,
   :func:`~wsoft.lightspace.halfspace.kernel_front`):

   * the search kernel: the light's spread from z_min to the receiver (a rectangle);
   * ESM-Z (§4.2): Z_occ = (Z_avg − e^{−cd} [w * z e^{cz}]) / (1 − s_f), s_f = e^{−cd}[w * e^{cz}];
   * the penumbra kernel from Z_occ as in PCSS, taken as a Gaussian with the variance of that
     box; with ``anisotropic`` the pixel's footprint on the map (from the G-buffer's
     neighbouring samples, a unit pixel box) is added to its covariance (§5.1); the ellipse
     of the sum (Mahalanobis radius 2) is cut into N = ceil(Y/H) rectangles (Level0), or
     with ``level`` = X ≥ 1 each inner row is split into its inscribed rectangle and two side
     rectangles, which are cut into 2^(X−1) x 2^(X−1) cells: cells inside the ellipse weigh 1,
     cells crossing it 0.5, cells outside 0 (runs of equal cells are one look-up);
   * micro-subdivision (§5.2): every rectangle is split into n x n sub-kernels and each is
     classified (``subdivide=always``, the paper's reading; ``flagged`` splits only a rectangle
     whose own ESM value exceeds 1 + ε); a non-planar sub-kernel (value above 1 + ε) falls back
     to 2x2 PCF on the depth map, each texel compared with the receiver plane at its centre;
     shadow and blocker depth are combined as in the paper. With ``subdivision=1`` the value is
     only clamped to 1 (the artifact the paper fixes). The default bias is derived from ε
     (e^{c bias} < 1 + ε) so that lit planar kernels are not taken as non-planar.

Optimal exponent (§7): c = R / (z_max − z_min) in depth units, i.e. R on the normalised depth,
where R is the largest exponent the storage holds: μ ln 2 for integer storage (the basis spans
e^R = 2^μ, so e^{c z_min} is still one integer unit) and, for a float32 SAT (not in the paper),
24 ln 2 − 2 ln N from its 24-bit mantissa (:func:`optimal_exponent`). ``c`` overrides it.

Not from the paper (each a parameter): ``round_up`` counts an integer SAT's half unit of rounding
of e^{cz} in the receiver's favour (a receiver near the nearest caster, where e^{c z_min} is one
unit, otherwise reads up to a third of its light as occluded: a closed sphere's lit top at min V
0.73); ``plane_slope_bias`` takes the receiver's depth that many texels of its tangent plane's
depth step nearer, against the map's own error at grazing angles (docs/techniques.md);
``beyond_range=flat`` compares a receiver past the effective range's far end (hidden behind the
map's farthest caster: a room under its ceiling, the ground under a closed lamp shade; its depth
clamps to 1) as a plane square to the light, where its tangent plane, tilted from beyond the range,
reaches back across the kernel to the casters' depths and lets their light through
(``reports/adversarial.md``'s ``room_ceiling`` and ``lamp_sphere``: mean V 0.068 and 0.085 with
``plane``, 0.000 and 0.006 with ``flat``; ``greece``'s MAE the same to four places).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from wsoft.accel.pyramid import effective_depth_range
from wsoft.accel.sat import SAT, box_area, build_sat, check_sat_params, mean_pyramid, sat_box
from wsoft.lightspace.halfspace import front_box, kernel_front
from wsoft.lightspace.light import CYLINDER_KERNEL, LightKernel, light_kernel, spread_texels
from wsoft.lightspace.view import (
    ViewGPU,
    map_coords,
    normalised_depth,
    plane_depth_step,
    receiver_plane_depth_or,
    texel_of,
    view_dir,
    view_of,
)
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered, gb_mapped_receiver, gb_neighbour
from wsoft.params import LightViewParams, check_ranges
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, check, param

FLT_MAX_LOG = math.log(np.finfo(np.float32).max)


@dataclass(frozen=True)
class ESSMParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map (a power of two)", range=(256, 8192))
    sat: str = param("tiles", "summed-area table: tiles (uint32 tile grid), uint32 (full) or float32 (full)")
    build: str = param("doubling", "SAT build: doubling (recursive doubling, counted passes) or scan (row/column scans)")
    reads: int = param(8, "texels read per recursive-doubling pass (X in the paper)", range=(2, 64))
    mu: int = param(20, "precision bits of the integer SATs (mu)", range=(8, 31))
    tile: int = param(0, "SAT tile size in texels, a power of two (0: from the mip-pyramid overflow test)", range=(0, 8192))
    c: float = param(0.0, "exponent on the normalised depth (0: the optimal R of the storage)", range=(0.0, 87.0))
    depth_range: str = param("pyramid", "effective depth range: pyramid (min/max of the map) or bounds (scene bounds)")
    H: float = param(5.0, "height of the rectangles the ellipse kernel is cut into, in texels", range=(0.25, 256.0))
    level: int = param(0, "ellipse rasterization level X (0: Level0)", range=(0, 5))
    subdivision: int = param(3, "micro-subdivision n x n of the kernels (1: off, values clamped)", range=(1, 8))
    subdivide: str = param("always", "always: every kernel is cut into n x n sub-kernels, each classified (§5.2); flagged: only a kernel above 1 + epsilon")
    epsilon: float = param(0.02, "non-planarity threshold: an ESM value above 1 + epsilon", range=(0.0, 1.0))
    anisotropic: bool = param(True, "convolve the penumbra kernel with the pixel footprint on the map")
    bias: float = param(0.0, "depth bias on the normalised depth [0, 1]; 0: ln(1 + epsilon) / (2c), so that a lit planar kernel (e^{c bias}) stays below 1 + epsilon", range=(0.0, 0.5))
    min_radius: float = param(0.5, "smallest penumbra half-width in texels", range=(0.01, 4096.0))
    max_radius: float = param(512.0, "largest search and penumbra half-width in texels", range=(0.01, 4096.0))
    plane_slope_bias: float = param(0.25, "texels of the receiver's tangent-plane depth step per texel taken off its depth (the map's own error at grazing angles)", range=(0.0, 16.0))
    beyond_range: str = param("flat", "a receiver past the effective range's far end (hidden behind the map's farthest caster): flat "
                                      "(compared as a plane square to the light at the far end) or plane (its tangent plane, tilted from "
                                      "beyond the range)", choices=("flat", "plane"))
    round_up: bool = param(True, "integer SATs: count the half unit of rounding of e^{cz} in the receiver's favour (off: the paper's reading, which self-shadows receivers near the nearest caster)")

    def __post_init__(self):
        check_ranges(self)
        check_sat_params(self)
        n = self.shadow_map_size
        check(self.tile == 0 or (1 <= self.tile <= n and self.tile & (self.tile - 1) == 0), f"tile {self.tile} must be 0 or a power of two <= shadow_map_size")
        check(self.depth_range in ("pyramid", "bounds"), f"depth_range {self.depth_range!r} is not pyramid or bounds")
        check(self.subdivide in ("always", "flagged"), f"subdivide {self.subdivide!r} is not always or flagged")


def optimal_exponent(storage: str, mu: int, n: int) -> float:
    """R (§7): the largest exponent the storage holds on the normalised depth [0, 1].

    Integer storage (the paper's, §6.2): μ ln 2, the basis spans e^R = 2^μ. A float32 SAT (not
    from the paper): its corner sums reach n² e^R and float32 keeps 24 bits, so they stay exact to
    one unit of the smallest basis value (e^0 = 1, an occluder nearest the light) only while
    n² e^R <= 2^24: R = 24 ln 2 − 2 ln n (2.8 at 1024², 1.4 at 2048², at least 1). The overflow
    bound (ln FLT_MAX − ln n² − ln 2, 74.2 at 1024²) never binds first; taken as R it made small
    kernels noise (MAE 0.77 on ogre, 0.93 on dinosaurs at 1024²)."""
    if storage == "float32":
        return min(FLT_MAX_LOG - 2.0 * math.log(n) - math.log(2.0), max(24.0 * math.log(2.0) - 2.0 * math.log(n), 1.0))
    return mu * math.log(2.0)


@wp.struct
class ESSMConsts:
    """What the shading kernel needs to turn SAT box sums into ESM values."""

    n: int
    tile: int
    unit: wp.float64  # basis units per stored unit
    c: wp.float64  # exponent on the normalised depth
    a0: wp.float64  # e^{cz} = mean(ch0) * a0 + b0
    b0: wp.float64
    e_round: wp.float64  # the most a box mean of e^{cz} can be off by through the storage's rounding (counted as lit)
    a1: wp.float64  # z e^{cz} = mean(ch1) * a1
    zmin: float
    zrange: float
    bias: float
    eps: float
    nsub: int
    always: int  # micro-subdivide every kernel (1) or only flagged ones (0)
    h: float
    level: int
    aniso: int
    min_r: float
    max_r: float
    slope: float  # texels of the receiver plane's depth step taken off its depth
    flat_beyond: int  # a receiver past the range's far end compares as a plane square to the light (1) or its tangent plane (0)


@wp.kernel
def essm_basis_kernel(
    offset: int,
    depth: wp.array2d[float],
    n: int,
    zmin: float,
    zrange: float,
    c: float,
    normalise: int,
    # outputs
    out: wp.array3d[float],
):
    i = wp.tid() + offset
    y = i / n
    x = i - y * n
    z = normalised_depth(depth[y, x], zmin, zrange)
    if normalise != 0:
        # (e^{cz} - 1) / (e^c - 1) and z e^{cz} / e^c, evaluated without overflow
        em = wp.exp(-c)
        e = wp.exp(c * (z - 1.0))
        out[0, y, x] = (e - em) / (1.0 - em)
        out[1, y, x] = z * e
    else:
        e = wp.exp(c * z)
        out[0, y, x] = e
        out[1, y, x] = z * e
    out[2, y, x] = z


@wp.func
def norm_depth(q: ESSMConsts, depth: wp.array2d[float], x: int, y: int) -> float:
    n = q.n
    if x < 0 or y < 0 or x >= n or y >= n:
        return 1.0
    return normalised_depth(depth[y, x], q.zmin, q.zrange)


@wp.func
def tangent_plane_depth(q: ESSMConsts, plane: wp.vec3, tc: wp.vec2, x: float, y: float) -> float:
    """Biased normalised depth of the receiver's tangent plane at texel coordinates (x, y)."""
    return wp.clamp(plane[0] + plane[1] * (x - tc[0]) + plane[2] * (y - tc[1]), 0.0, 1.0) - q.bias


@wp.func
def pcf2x2(q: ESSMConsts, depth: wp.array2d[float], u0: float, u1: float, v0: float, v1: float, plane: wp.vec3, tc: wp.vec2) -> wp.vec3:
    """2x2 PCF at the centres of the box's quadrants against the receiver plane:
    (visibility, mean occluding depth x occluded fraction, 1). Each texel's stored depth is
    compared with the plane at *that texel's centre* (where the depth was sampled), as PCF with a
    receiver-plane bias does: at the sample point, up to half a texel away, a tilted lit receiver
    shadows itself in stripes."""
    lit = float(0.0)
    occ = float(0.0)
    for a in range(2):
        for b in range(2):
            x = u0 + (float(a) + 0.5) * 0.5 * (u1 - u0)
            y = v0 + (float(b) + 0.5) * 0.5 * (v1 - v0)
            tx = wp.floor(x)
            ty = wp.floor(y)
            z = norm_depth(q, depth, int(tx), int(ty))
            if z < tangent_plane_depth(q, plane, tc, tx + 0.5, ty + 0.5):
                occ += 0.25 * z
            else:
                lit += 0.25
    return wp.vec3(lit, occ, 1.0)


@wp.func
def esm_box(q: ESSMConsts, data: wp.array3d(dtype=Any), u0: float, u1: float, v0: float, v1: float, dn: float, want_z: int) -> wp.vec3:
    """ESM over a box: (s, Zavg - e^{-cd} [w * z e^{cz}] (the occluded fraction times its mean depth), non-planar flag).
    Parts of the box outside the map count as lit, unoccluded texels at depth 1."""
    full = (u1 - u0) * (v1 - v0)
    a = box_area(q.n, u0, u1, v0, v1)
    if full <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)
    if a <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)
    wa = wp.float64(a)
    fa = wp.float64(full)
    ecd = wp.exp(-q.c * wp.float64(dn))
    e = (sat_box(data, 0, q.n, q.tile, u0, u1, v0, v1) * q.unit / wa) * q.a0 + q.b0
    # outside the map: lit at depth 1 -> e^{c}; the ESM of that part is e^{c(1-d)} >= 1
    s64 = (ecd * e * wa + (fa - wa) * wp.exp(q.c * (wp.float64(1.0) - wp.float64(dn)))) / fa
    flag = 0.0
    if s64 > wp.float64(1.0 + q.eps):
        flag = 1.0
    # the storage's rounding counted as lit in the value, not in the non-planarity test
    s = float(wp.min(s64 + ecd * q.e_round * wa / fa, wp.float64(1.0)))
    bw = float(0.0)
    if want_z != 0:
        ze = (sat_box(data, 1, q.n, q.tile, u0, u1, v0, v1) * q.unit / wa) * q.a1
        zavg = sat_box(data, 2, q.n, q.tile, u0, u1, v0, v1) * q.unit / wa
        occ = (zavg - ecd * ze) * wa / fa  # the outside part holds no occluders
        bw = wp.clamp(float(occ), 0.0, (1.0 - s) * dn)
    return wp.vec3(s, bw, flag)


@wp.func
def region(q: ESSMConsts, data: wp.array3d(dtype=Any), depth: wp.array2d[float], u0: float, u1: float, v0: float, v1: float,
           plane: wp.vec3, tc: wp.vec2, want_z: int) -> wp.vec4:
    """A kernel rectangle with micro-subdivision: (s, occluded-depth weight, look-ups, PCF fallbacks).
    Each (sub-)kernel is tested against the receiver plane's depth at its centre. ``q.always``
    (§5.2): the kernel is cut into n x n sub-kernels and each is classified; otherwise only a
    kernel whose own value exceeds 1 + epsilon is cut (which misses kernels whose lit texels and
    leaking occluded ones average below the threshold)."""
    looks = float(0.0)
    if q.always == 0 or q.nsub <= 1:
        r = esm_box(q, data, u0, u1, v0, v1, tangent_plane_depth(q, plane, tc, 0.5 * (u0 + u1), 0.5 * (v0 + v1)), want_z)
        looks = 1.0
        if r[2] == 0.0 or q.nsub <= 1:
            return wp.vec4(r[0], r[1], looks, 0.0)
    m = q.nsub
    du = (u1 - u0) / float(m)
    dv = (v1 - v0) / float(m)
    s = float(0.0)
    bw = float(0.0)
    fb = float(0.0)
    for a in range(m):
        for b in range(m):
            x0 = u0 + float(a) * du
            y0 = v0 + float(b) * dv
            ri = esm_box(q, data, x0, x0 + du, y0, y0 + dv, tangent_plane_depth(q, plane, tc, x0 + 0.5 * du, y0 + 0.5 * dv), want_z)
            looks += 1.0
            if ri[2] != 0.0:
                ri = pcf2x2(q, depth, x0, x0 + du, y0, y0 + dv, plane, tc)
                fb += 1.0
            s += ri[0]
            bw += ri[1]
    inv = 1.0 / float(m * m)
    return wp.vec4(s * inv, bw * inv, looks, fb)


@wp.func
def inside_ellipse(ixx: float, ixy: float, iyy: float, x: float, y: float) -> bool:
    return ixx * x * x + 2.0 * ixy * x * y + iyy * y * y <= 4.0


@wp.func
def ellipse_span(sxx: float, sxy: float, syy: float, det: float, y: float) -> wp.vec2:
    """Horizontal chord of the ellipse x^T S^-1 x <= 4 at height y: (x_left, x_right)."""
    xc = sxy / syy * y
    t = 1.0 - y * y / (4.0 * syy)
    hw = 2.0 * wp.sqrt(det / syy) * wp.sqrt(wp.max(t, 0.0))
    return wp.vec2(xc - hw, xc + hw)


@wp.func
def footprint_axis(gb: GBufferGPU, i: int, dx: int, dy: int) -> wp.vec3:
    """World-space step from sample ``i`` to the neighbouring pixel (dx, dy) on the same surface
    plane (forward, else backward, negated), or zero."""
    p = gb.pos[i]
    nn = gb.nrm[i]
    fwd = gb_neighbour(gb, i, dx, dy)
    if fwd >= 0:
        if gb_covered(gb, fwd):
            dp = gb.pos[fwd] - p
            if wp.abs(wp.dot(dp, nn)) <= 0.05 * wp.length(dp):
                return dp
    bwd = gb_neighbour(gb, i, -dx, -dy)
    if bwd >= 0:
        if gb_covered(gb, bwd):
            dp = p - gb.pos[bwd]
            if wp.abs(wp.dot(dp, nn)) <= 0.05 * wp.length(dp):
                return dp
    return wp.vec3(0.0, 0.0, 0.0)


@wp.kernel
def essm_shade(
    offset: int,
    lv: ViewGPU,
    k: LightKernel,
    q: ESSMConsts,
    data: wp.array3d(dtype=Any),
    depth: wp.array2d[float],
    gb: GBufferGPU,
    # outputs
    vis: wp.array[float],
    looks: wp.array[wp.int32],
    fallbacks: wp.array[wp.int32],
):
    i = wp.tid() + offset
    looks[i] = 0
    fallbacks[i] = 0
    vis[i] = 1.0
    mapped, pv, mc, tc = gb_mapped_receiver(lv, gb, i)
    if not mapped:
        return
    d_lin = pv[2]
    nv = view_dir(lv, gb.nrm[i])
    # nearer by a fraction of the plane's depth step per texel: the map's own error at grazing angles
    dn = normalised_depth(d_lin - q.slope * plane_depth_step(lv, pv, nv, d_lin), q.zmin, q.zrange) - q.bias
    # the receiver's tangent plane in normalised depth per texel (receiver-plane depth)
    m0 = map_coords(lv, pv)
    tu = 1.0 / lv.scale[0]
    tv = 1.0 / lv.scale[1]
    gu = (receiver_plane_depth_or(lv, pv, nv, wp.vec2(m0[0] + tu, m0[1]), pv[2]) - receiver_plane_depth_or(lv, pv, nv, wp.vec2(m0[0] - tu, m0[1]), pv[2])) * 0.5 / q.zrange
    gv = (receiver_plane_depth_or(lv, pv, nv, wp.vec2(m0[0], m0[1] + tv), pv[2]) - receiver_plane_depth_or(lv, pv, nv, wp.vec2(m0[0], m0[1] - tv), pv[2])) * 0.5 / q.zrange
    # only a receiver that faces the light's centre is in the map around its texel: for one that
    # faces away the plane says nothing about the stored depths (and is not used)
    towards = -pv
    if lv.persp == 0:
        towards = wp.vec3(0.0, 0.0, -1.0)
    if wp.dot(nv, towards) <= 0.0:
        gu = 0.0
        gv = 0.0
    # a receiver past the range's far end (hidden behind the map's farthest caster, its depth clamped
    # to 1) is behind every stored depth: its plane, tilted from beyond the range, says nothing there
    if q.flat_beyond != 0 and d_lin > q.zmin + q.zrange:
        gu = 0.0
        gv = 0.0
    plane = wp.vec3(dn + q.bias, gu, gv)
    # 1. blocker search over the light's spread from the nearest depth (ESM-Z, micro-subdivided)
    # the light clipped to the receiver's front half-space: search and filter its part's window
    mid, hs, front = kernel_front(lv, k, pv, nv)
    if front <= 0.0:
        vis[i] = 0.0
        return
    sh = spread_texels(lv, k, q.zmin, d_lin, 0.5, q.max_r)
    b = front_box(tc, sh, mid, hs, 0.5)
    r = region(q, data, depth, b[0], b[1], b[2], b[3], plane, tc, 1)
    nlook = r[2]
    nfb = r[3]
    occluded = 1.0 - r[0]
    if occluded <= 1.0e-4:
        vis[i] = front
        looks[i] = int(nlook)
        fallbacks[i] = int(nfb)
        return
    z_occ = wp.clamp(r[1] / occluded, 0.0, wp.max(dn, 0.0))
    # 2. penumbra from the average blocker depth, as a Gaussian with the box's variance
    pen = spread_texels(lv, k, q.zmin + z_occ * q.zrange, d_lin, q.min_r, q.max_r)
    # its centre ``fc`` and size those of the light's front part
    fc = wp.vec2(tc[0] + mid[0] * pen[0], tc[1] + mid[1] * pen[1])
    pen = wp.vec2(wp.where(hs[0] < 1.0, wp.max(pen[0] * hs[0], 0.5), pen[0]), wp.where(hs[1] < 1.0, wp.max(pen[1] * hs[1], 0.5), pen[1]))
    sxx = pen[0] * pen[0] / 3.0
    syy = pen[1] * pen[1] / 3.0
    sxy = float(0.0)
    if q.aniso != 0:
        # the pixel's footprint on the map (a unit pixel box, variance 1/12 per screen axis)
        ex = footprint_axis(gb, i, 1, 0)
        ey = footprint_axis(gb, i, 0, 1)
        jx = texel_of(lv, view_of(lv, gb.pos[i] + ex)) - tc
        jy = texel_of(lv, view_of(lv, gb.pos[i] + ey)) - tc
        f = 1.0 / 12.0
        sxx += f * (jx[0] * jx[0] + jy[0] * jy[0])
        syy += f * (jx[1] * jx[1] + jy[1] * jy[1])
        sxy += f * (jx[0] * jx[1] + jy[0] * jy[1])
    det = sxx * syy - sxy * sxy
    det = wp.max(det, 1.0e-6 * sxx * syy)
    ixx = syy / det
    iyy = sxx / det
    ixy = -sxy / det
    ymax = 2.0 * wp.sqrt(syy)
    rows = wp.max(int(wp.ceil(2.0 * ymax / q.h)), 1)
    rows = wp.min(rows, 4096)
    hgt = 2.0 * ymax / float(rows)
    total = float(0.0)
    wsum = float(0.0)
    for row in range(rows):
        yl = -ymax + float(row) * hgt
        yh = yl + hgt
        if q.level == 0 or row == 0 or row == rows - 1:
            sp = ellipse_span(sxx, sxy, syy, det, 0.5 * (yl + yh))
            if sp[1] > sp[0]:
                rr = region(q, data, depth, fc[0] + sp[0], fc[0] + sp[1], fc[1] + yl, fc[1] + yh, plane, tc, 0)
                a = (sp[1] - sp[0]) * hgt
                total += a * rr[0]
                wsum += a
                nlook += rr[2]
                nfb += rr[3]
        else:
            lo = ellipse_span(sxx, sxy, syy, det, yl)
            hi = ellipse_span(sxx, sxy, syy, det, yh)
            ia = wp.max(lo[0], hi[0])
            ib = wp.min(lo[1], hi[1])
            if ib > ia:
                rr = region(q, data, depth, fc[0] + ia, fc[0] + ib, fc[1] + yl, fc[1] + yh, plane, tc, 0)
                a = (ib - ia) * hgt
                total += a * rr[0]
                wsum += a
                nlook += rr[2]
                nfb += rr[3]
            # the two side rectangles, 3 corners in and 1 out
            for side in range(2):
                xa = wp.min(lo[0], hi[0])
                xb = ia
                if side == 1:
                    xa = ib
                    xb = wp.max(lo[1], hi[1])
                if xb > xa:
                    if q.level == 1:
                        rr = region(q, data, depth, fc[0] + xa, fc[0] + xb, fc[1] + yl, fc[1] + yh, plane, tc, 0)
                        a = 0.5 * (xb - xa) * hgt
                        total += a * rr[0]
                        wsum += a
                        nlook += rr[2]
                        nfb += rr[3]
                    else:
                        m = int(wp.pow(2.0, float(q.level - 1)) + 0.5)
                        cw = (xb - xa) / float(m)
                        ch = hgt / float(m)
                        for cy in range(m):
                            y0 = yl + float(cy) * ch
                            run_start = xa
                            run_w = float(-1.0)
                            for cx in range(m + 1):
                                w = float(-1.0)
                                x0 = xa + float(cx) * cw
                                if cx < m:
                                    cnt = int(0)
                                    if inside_ellipse(ixx, ixy, iyy, x0, y0):
                                        cnt += 1
                                    if inside_ellipse(ixx, ixy, iyy, x0 + cw, y0):
                                        cnt += 1
                                    if inside_ellipse(ixx, ixy, iyy, x0, y0 + ch):
                                        cnt += 1
                                    if inside_ellipse(ixx, ixy, iyy, x0 + cw, y0 + ch):
                                        cnt += 1
                                    w = 0.5
                                    if cnt == 4:
                                        w = 1.0
                                    if cnt == 0:
                                        w = 0.0
                                if w != run_w:
                                    # close the running run of equal cells
                                    if run_w > 0.0 and x0 > run_start:
                                        rr = region(q, data, depth, fc[0] + run_start, fc[0] + x0, fc[1] + y0, fc[1] + y0 + ch, plane, tc, 0)
                                        a = run_w * (x0 - run_start) * ch
                                        total += a * rr[0]
                                        wsum += a
                                        nlook += rr[2]
                                        nfb += rr[3]
                                    run_start = x0
                                    run_w = w
    v = float(1.0)
    if wsum > 0.0:
        v = wp.clamp(total / wsum, 0.0, 1.0)
    vis[i] = front * v
    looks[i] = int(nlook)
    fallbacks[i] = int(nfb)


for _t in (wp.uint32, wp.float32):
    wp.overload(essm_shade, {"data": wp.array3d(dtype=_t)})


@dataclass
class Basis:
    """The ESSM basis of one light: channels [esm, esm-z, z] over the map, the depth range and exponent."""

    basis: wp.array
    pyramid: list
    zmin: float
    zmax: float
    c: float  # on the normalised depth
    normalised: bool
    empty: bool

    def arrays(self) -> dict[str, wp.array]:
        out = {"basis": self.basis}
        for j, lv in enumerate(self.pyramid[1:], 1):
            out[f"pyramid{j}"] = lv
        return out


def make_basis(dm, *, storage: str, mu: int, c: float, mode: str, scene, device: str, pyramid: bool) -> Basis:
    n = dm.depth.shape[0]
    zmin, rng, empty = effective_depth_range(dm, mode, scene, device)
    cc = c if c > 0 else optimal_exponent(storage, mu, n)
    normalise = storage != "float32"
    basis = wp.empty((3, n, n), dtype=float, device=device)
    launch_chunked(essm_basis_kernel, n * n, inputs=[dm.depth, n, zmin, rng, cc, int(normalise)], outputs=[basis], device=device, min_chunk=4096)
    pyr = mean_pyramid(basis, device) if pyramid else [basis]
    return Basis(basis, pyr, zmin, zmin + rng, cc, normalise, empty)


def effective_bias(p, c: float) -> float:
    """The bias on the normalised depth: ``p.bias``, or (0) half of ln(1 + epsilon)/c. A lit planar
    kernel's ESM value is e^{c bias}; at or above 1 + epsilon every such kernel would be taken as
    non-planar and fall back to PCF (the paper's defaults give e^{13.9 x 0.002} = 1.028 > 1.02)."""
    if p.bias > 0.0:
        return p.bias
    return 0.5 * math.log1p(p.epsilon) / max(c, 1e-6) if p.epsilon > 0.0 else 0.0


def consts_for(b: Basis, sat: SAT, p) -> ESSMConsts:
    q = ESSMConsts()
    q.n = sat.n
    q.tile = sat.tile
    q.unit = wp.float64(sat.unit)
    q.c = wp.float64(b.c)
    if b.normalised:
        q.a0 = wp.float64(math.expm1(b.c))
        q.b0 = wp.float64(1.0)
        q.a1 = wp.float64(math.exp(b.c))
    else:
        q.a0 = wp.float64(1.0)
        q.b0 = wp.float64(0.0)
        q.a1 = wp.float64(1.0)
    # integer storage rounds each texel's (e^{cz} - 1) / (e^c - 1) to 2^-mu: a box mean is off by at
    # most half a unit, (e^c - 1) 2^-mu / 2 in e^{cz}, about 1/2 at the optimal c, where e^{c z_min}
    # is 1: a receiver near the nearest caster (e^{cd} near 1) reads up to a third of its light
    # as occluded. Counting it in the receiver's favour keeps it lit; farther receivers
    # (e^{cd} >> 1) hardly change.
    q.e_round = wp.float64(0.5 * sat.unit * math.expm1(b.c) if (b.normalised and p.round_up) else 0.0)
    q.zmin = b.zmin
    q.zrange = b.zmax - b.zmin
    q.bias = effective_bias(p, b.c)
    q.slope = p.plane_slope_bias
    q.flat_beyond = int(p.beyond_range == "flat")
    q.eps = p.epsilon
    q.nsub = p.subdivision
    q.always = int(p.subdivide == "always")
    q.h = p.H
    q.level = p.level
    q.aniso = int(p.anisotropic)
    q.min_r = p.min_radius
    q.max_r = p.max_radius
    return q


class ESSM(Technique):
    """Exponential soft shadow mapping: ESM-Z blockers, SAT tile grids, anisotropic ellipse kernels, micro-subdivision."""

    name = "essm"
    distant_angle_limit = 50.0  # max point error 0.076 at 50 degrees, 0.195 at 60
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    summary = "exponential soft shadow mapping: ESM-Z blocker depth, overflow-free SAT tile grids, anisotropic kernels, micro-subdivision"
    Params = ESSMParams
    passes = (
        PassSpec("basis", reads=("light_depth",), writes=("essm_basis",)),
        PassSpec("sat", reads=("essm_basis",), writes=("essm_sat",)),
        PassSpec("shadow", reads=("gbuffer", "light_depth", "essm_basis", "essm_sat"), writes=("visibility",)),
    )
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"
    quality = (
        Quality("H", (10.0, 5.0, 2.0), "thinner rectangles: a closer fit of the elliptic kernel, more look-ups"),
        Quality("subdivision", (1, 3, 5), "finer micro-subdivision of the kernels: fewer wrong lit kernels, more look-ups"),
        Quality("level", (0, 1, 2), "LevelX rasterization: the ellipse's sides cut finer, more look-ups"),
    )
    tolerance = Tolerance(mae=0.001, mae_penumbra=0.025)
    distance_refusal = "its summed-area tables of exp(-c z) sum every caster of a kernel together, so they cannot tell which lie within the distance"
    ellipsoid_caveat = "its bounding sphere (search and penumbra kernels sized by its largest semi-axis)"
    cylinder_model = CYLINDER_KERNEL

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        depth = ctx.light_depth(light, size=p.shadow_map_size, soft=True, view=p.view)
        out = ctx.visibility_key(light)
        # the basis and its SAT depend on the storage, not on how the kernel is shaded: instances
        # that differ only in H, level, subdivision, epsilon or bias share them
        bkey = ctx.shared_key("essm_basis", light, p.shadow_map_size, "sat", "mu", "c", "depth_range", "tile")
        skey = ctx.shared_key("essm_sat", light, p.shadow_map_size, "sat", "mu", "c", "depth_range", "tile", "build", "reads")

        def run_basis(res):
            b = make_basis(res[depth], storage=p.sat, mu=p.mu, c=p.c, mode=p.depth_range, scene=ctx.scene, device=ctx.device,
                           pyramid=p.sat == "tiles" and p.tile == 0)
            return {bkey: b}

        def run_sat(res):
            b = res[bkey]
            sat = build_sat(b.basis, storage=p.sat, mu=p.mu, build=p.build, reads=p.reads, tile=p.tile or None, device=ctx.device,
                            pyramid=b.pyramid if len(b.pyramid) > 1 else None)
            return {skey: sat}

        def run_shadow(res):
            gb, dm, b, sat = res[gbuf], res[depth], res[bkey], res[skey]
            n = gb.count
            vis = wp.empty(n, dtype=float, device=ctx.device)
            looks = wp.empty(n, dtype=wp.int32, device=ctx.device)
            fb = wp.empty(n, dtype=wp.int32, device=ctx.device)
            launch_chunked(essm_shade, n, inputs=[dm.view.gpu(), light_kernel(light, dm.view), consts_for(b, sat, p), sat.data, dm.depth, gb.gpu()],
                           outputs=[vis, looks, fb], device=ctx.device, min_chunk=64)
            lk = looks.numpy()
            hit = gb.prim.numpy() >= 0
            c = ctx.counters(light)
            c["z_range"] = [b.zmin, b.zmax]
            c["c_normalised"] = b.c
            c["c_per_depth_unit"] = b.c / (b.zmax - b.zmin)
            c["sat"] = {"storage": sat.storage, "tile": sat.tile, "tiles_per_side": sat.tiles_per_side, "build": sat.build,
                        "passes": sat.passes, "bytes": sat.memory_bytes(), **sat.tile_test}
            c["lookups_per_sample"] = float(lk[hit].mean()) if hit.any() else 0.0
            c["pcf_fallbacks"] = int(fb.numpy().sum())
            c["pcf_fallbacks_per_sample"] = float(fb.numpy()[hit].mean()) if hit.any() else 0.0
            c["bias_normalised"] = effective_bias(p, b.c)
            return {out: ctx.visibility(vis)}

        ctx.add_pass(str(bkey), inputs=(depth,), outputs=(bkey,), run=run_basis, stage="basis", light=light)
        ctx.add_pass(str(skey), inputs=(bkey,), outputs=(skey,), run=run_sat, stage="sat", light=light)
        return ctx.add_pass(ctx.pass_name("essm_shadow", light), inputs=(gbuf, depth, bkey, skey), outputs=(out,), run=run_shadow, stage="shadow", light=light)
