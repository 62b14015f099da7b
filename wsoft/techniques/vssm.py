"""``vssm``: variance soft shadow mapping (Yang, Dong, Feng, Seidel & Kautz 2010), the
pre-filtered baseline ESSM is compared against. It shares ESSM's summed-area tables
(:mod:`wsoft.accel.sat`: float32 by default, as in the paper, or the uint32 SAT / tile grid)
and its depth range (the map's min/max pyramid).

1. Moments: normalised linear depth z in [0, 1] and z² (empty texels at 1), in a 2-channel SAT.
2. Blocker search over the light's spread from z_min to the receiver: with mean μ and variance
   σ² of the kernel, Chebyshev's one-tailed bound p = σ² / (σ² + (d − μ)²) estimates the
   unoccluded fraction for d > μ; taking the unoccluded texels at the receiver's depth d,
   μ = p d + (1 − p) z_occ gives the average blocker depth z_occ = (μ − p d) / (1 − p).
3. Penumbra from z_occ as in PCSS (a rectangle the light's shape); visibility p over it.
4. Kernel subdivision: a kernel with d <= μ (Chebyshev says "lit", but blockers may hide under
   the mean, the non-planarity problem) is split into n x n sub-kernels, each evaluated the
   same way (sub-kernels still with d <= μ count as lit); blocker depths are combined weighted
   by their occluded fractions.

Two departures from the paper, each a parameter whose off value is the paper's reading
(measured in docs/techniques.md, the adversarial corpus's ``sphere``): ``receiver_plane``, each
sub-kernel compares against the receiver's tangent plane at its centre, not the centre's depth
(off centre the receiver's own texels are nearer or farther by the plane's slope, and a curved
receiver's lit top shadowed itself: min V 0.83 at 256²); ``direct_small``, a float32 SAT's boxes
of at most 4 texels a side are summed from the moments themselves (the table's corner sums of up
to N² values are each off by about 2^-24 of themselves, more than the bias on a box of a few
texels: min V 0.02 at 1024²). The receiver's depth is taken ``plane_slope_bias`` texels of its
plane's depth step nearer (:func:`~wsoft.lightspace.view.plane_depth_step`), against the map's own
error at grazing angles.

A light across the receiver's tangent plane: only its front part lights the receiver
(:mod:`wsoft.lightspace.halfspace`). The blocker search and the filter move to that part's
bounding window (:func:`~wsoft.lightspace.halfspace.kernel_front`) and V is the window's visible
fraction times the part's share of the light: exact for a rect light cut along an axis,
approximate for an oblique cut or a disk; a light wholly in front keeps the kernel as it is.

Known failure: light bleeding with stacked occluders (``bleed`` reduces it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import warp as wp

from wsoft.accel.pyramid import effective_depth_range
from wsoft.accel.sat import DIRECT_TEXELS, Moments, box_area, build_sat, check_sat_params, direct_box, mean_pyramid, sat_box
from wsoft.lightspace.halfspace import front_box, kernel_front
from wsoft.lightspace.light import CYLINDER_KERNEL, LightKernel, light_kernel, spread_texels
from wsoft.lightspace.moments import chebyshev_bound, moments_variance
from wsoft.lightspace.view import ViewGPU, normalised_depth, plane_depth_step, receiver_plane_affine, receiver_plane_at, view_dir
from wsoft.params import LightViewParams, check_ranges
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_mapped_receiver
from wsoft.techniques.base import PassSpec, Quality, Technique, Tolerance, param


@dataclass(frozen=True)
class VSSMParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map (a power of two)", range=(256, 8192))
    sat: str = param("float32", "summed-area table: float32 (full), uint32 (full) or tiles (uint32 tile grid)")
    build: str = param("doubling", "SAT build: doubling or scan")
    mu: int = param(20, "precision bits of the integer SATs", range=(8, 31))
    subdivision: int = param(5, "n x n subdivision of non-planar kernels (1: off)", range=(1, 8))
    min_variance: float = param(1e-6, "variance floor on the normalised depth", range=(0.0, 0.25))
    bleed: float = param(0.0, "light-bleeding reduction amount", range=(0.0, 0.99))
    bias: float = param(0.002, "depth bias on the normalised depth [0, 1]", range=(0.0, 0.5))
    min_radius: float = param(0.5, "smallest penumbra half-width in texels", range=(0.01, 4096.0))
    max_radius: float = param(512.0, "largest search and penumbra half-width in texels", range=(0.01, 4096.0))
    direct_small: bool = param(True, "float32 SAT: boxes of at most 4 texels per side summed from the moments themselves (the table's rounding exceeds the bias there)")
    plane_slope_bias: float = param(0.25, "texels of the receiver's tangent-plane depth step per texel taken off its depth (the map's own error at grazing angles)", range=(0.0, 16.0))
    receiver_plane: bool = param(True, "sub-kernels compare against the receiver's tangent plane at their centres (off: the receiver's own depth, the paper's reading)")

    def __post_init__(self):
        check_ranges(self)
        check_sat_params(self)


@wp.struct
class VSSMConsts:
    n: int
    tile: int
    unit: wp.float64
    zmin: float
    zrange: float
    bias: float
    nsub: int
    min_var: float
    bleed: float
    min_r: float
    max_r: float
    plane: int
    direct: int
    slope: float


@wp.struct
class ReceiverPlane:
    """The receiver's tangent plane over the map's texels (:func:`receiver_plane_affine`)."""

    ok: int
    pv: wp.vec3
    nv: wp.vec3
    xp: wp.vec2
    qp: float
    gx: float
    gy: float


@wp.kernel
def vssm_basis_kernel(
    offset: int,
    depth: wp.array2d[float],
    n: int,
    zmin: float,
    zrange: float,
    # outputs
    out: wp.array3d[float],
):
    i = wp.tid() + offset
    y = i / n
    x = i - y * n
    z = normalised_depth(depth[y, x], zmin, zrange)
    out[0, y, x] = z
    out[1, y, x] = z * z


@wp.func
def chebyshev(q: VSSMConsts, data: wp.array3d(dtype=Any), basis: wp.array3d[float], u0: float, u1: float, v0: float, v1: float, d: float) -> wp.vec3:
    """(p, blocker-depth weight (1 - p) z_occ, non-planar flag) of a box; outside the map is lit at depth 1."""
    fa = (u1 - u0) * (v1 - v0)
    a = box_area(q.n, u0, u1, v0, v1)
    if fa <= 0.0 or a <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)
    outside = wp.float64(fa - a)
    s1 = wp.float64(0.0)
    s2 = wp.float64(0.0)
    if q.direct != 0 and u1 - u0 <= DIRECT_TEXELS and v1 - v0 <= DIRECT_TEXELS:
        s1 = direct_box(basis, 0, q.n, u0, u1, v0, v1)
        s2 = direct_box(basis, 1, q.n, u0, u1, v0, v1)
    else:
        s1 = sat_box(data, 0, q.n, q.tile, u0, u1, v0, v1) * q.unit
        s2 = sat_box(data, 1, q.n, q.tile, u0, u1, v0, v1) * q.unit
    m1 = float((s1 + outside) / wp.float64(fa))
    m2 = float((s2 + outside) / wp.float64(fa))
    var = moments_variance(m1, m2, q.min_var)
    if d <= m1:
        flag = float(0.0)
        if var > q.min_var * 4.0:
            flag = 1.0
        return wp.vec3(1.0, 0.0, flag)
    p = chebyshev_bound(m1, var, d)
    if q.bleed > 0.0:
        p = wp.clamp((p - q.bleed) / (1.0 - q.bleed), 0.0, 1.0)
    bw = wp.clamp(m1 - p * d, 0.0, (1.0 - p) * d)
    return wp.vec3(p, bw, 0.0)


@wp.func
def plane_depth(q: VSSMConsts, lv: ViewGPU, pl: ReceiverPlane, u: float, v: float, d: float) -> float:
    """The receiver's tangent plane's normalised depth at texel (u, v), less the bias; ``d``
    where the light sees the plane edge-on or it passes behind the light there."""
    if pl.ok == 0:
        return d
    z = receiver_plane_at(lv, True, pl.xp, pl.qp, pl.gx, pl.gy, wp.vec2(u, v), -1.0)
    if z < 0.0:
        return d
    return normalised_depth(z - q.slope * plane_depth_step(lv, pl.pv, pl.nv, z), q.zmin, q.zrange) - q.bias


@wp.func
def vregion(q: VSSMConsts, lv: ViewGPU, pl: ReceiverPlane, data: wp.array3d(dtype=Any), basis: wp.array3d[float], u0: float, u1: float, v0: float, v1: float, d: float) -> wp.vec3:
    """A kernel with subdivision of non-planar kernels: (p, blocker weight, look-ups). Each
    sub-kernel compares against the receiver's tangent plane at its centre (receiver-plane
    depth): the receiver's own texels in a sub-kernel off its centre lie nearer or farther than
    ``d`` by the plane's slope, and compared against ``d`` they would shadow it."""
    r = chebyshev(q, data, basis, u0, u1, v0, v1, d)
    if r[2] == 0.0 or q.nsub <= 1:
        return wp.vec3(r[0], r[1], 1.0)
    m = q.nsub
    du = (u1 - u0) / float(m)
    dv = (v1 - v0) / float(m)
    p = float(0.0)
    bw = float(0.0)
    for a in range(m):
        for b in range(m):
            x0 = u0 + float(a) * du
            y0 = v0 + float(b) * dv
            ri = chebyshev(q, data, basis, x0, x0 + du, y0, y0 + dv, plane_depth(q, lv, pl, x0 + 0.5 * du, y0 + 0.5 * dv, d))
            p += ri[0]
            bw += ri[1]
    inv = 1.0 / float(m * m)
    return wp.vec3(p * inv, bw * inv, 1.0 + float(m * m))


@wp.kernel
def vssm_shade(
    offset: int,
    lv: ViewGPU,
    k: LightKernel,
    q: VSSMConsts,
    data: wp.array3d(dtype=Any),
    basis: wp.array3d[float],
    gb: GBufferGPU,
    # outputs
    vis: wp.array[float],
    looks: wp.array[wp.int32],
):
    i = wp.tid() + offset
    vis[i] = 1.0
    looks[i] = 0
    mapped, pv, m, tc = gb_mapped_receiver(lv, gb, i)
    if not mapped:
        return
    d_lin = pv[2]
    nv = view_dir(lv, gb.nrm[i])
    d = normalised_depth(d_lin - q.slope * plane_depth_step(lv, pv, nv, d_lin), q.zmin, q.zrange) - q.bias
    pl = ReceiverPlane()
    pl.ok = 0
    pl.pv = pv
    pl.nv = nv
    if q.plane != 0:
        ok, xp, qp, gx, gy = receiver_plane_affine(lv, pv, nv)
        pl.ok = int(ok)
        pl.xp = xp
        pl.qp = qp
        pl.gx = gx
        pl.gy = gy
    # the light clipped to the receiver's front half-space: search and filter its part's window
    mid, hs, front = kernel_front(lv, k, pv, nv)
    if front <= 0.0:
        vis[i] = 0.0
        return
    sh = spread_texels(lv, k, q.zmin, d_lin, 0.5, q.max_r)
    b = front_box(tc, sh, mid, hs, 0.5)
    r = vregion(q, lv, pl, data, basis, b[0], b[1], b[2], b[3], d)
    nl = r[2]
    occ = 1.0 - r[0]
    if occ <= 1.0e-4:
        vis[i] = front
        looks[i] = int(nl)
        return
    z_occ = wp.clamp(r[1] / occ, 0.0, wp.max(d, 0.0))
    pen = spread_texels(lv, k, q.zmin + z_occ * q.zrange, d_lin, q.min_r, q.max_r)
    b = front_box(tc, pen, mid, hs, 0.5)
    s = vregion(q, lv, pl, data, basis, b[0], b[1], b[2], b[3], d)
    vis[i] = front * wp.clamp(s[0], 0.0, 1.0)
    looks[i] = int(nl + s[2])


for _t in (wp.uint32, wp.float32):
    wp.overload(vssm_shade, {"data": wp.array3d(dtype=_t)})


class VSSM(Technique):
    """Variance soft shadow mapping: SAT of depth moments, Chebyshev blocker estimate, kernel subdivision."""

    name = "vssm"
    distant_angle_limit = 50.0  # max point error 0.076 at 50 degrees, 0.147 at 60
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    summary = "variance soft shadow mapping: SAT of depth moments, Chebyshev blocker estimate, subdivision of non-planar kernels"
    Params = VSSMParams
    passes = (
        PassSpec("moments", reads=("light_depth",), writes=("vssm_moments",)),
        PassSpec("sat", reads=("vssm_moments",), writes=("vssm_sat",)),
        PassSpec("shadow", reads=("gbuffer", "light_depth", "vssm_moments", "vssm_sat"), writes=("visibility",)),
    )
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"
    quality = (Quality("subdivision", (1, 3, 5), "finer subdivision of non-planar kernels: less light leaking, more look-ups"),)
    tolerance = Tolerance(mae=0.0003, mae_penumbra=0.01)
    distance_refusal = "its summed-area tables of depth moments sum every caster of a kernel together, so they cannot tell which lie within the distance"
    ellipsoid_caveat = "its bounding sphere (search and penumbra kernels sized by its largest semi-axis)"
    cylinder_model = CYLINDER_KERNEL

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        depth = ctx.light_depth(light, size=p.shadow_map_size, soft=True, view=p.view)
        out = ctx.visibility_key(light)
        mkey = ctx.shared_key("vssm_moments", light, p.shadow_map_size, "sat")
        skey = ctx.shared_key("vssm_sat", light, p.shadow_map_size, "sat", "mu", "build")

        def run_moments(res):
            dm = res[depth]
            n = dm.depth.shape[0]
            zmin, rng, _ = effective_depth_range(dm, "pyramid", ctx.scene, ctx.device)
            basis = wp.empty((2, n, n), dtype=float, device=ctx.device)
            launch_chunked(vssm_basis_kernel, n * n, inputs=[dm.depth, n, zmin, rng], outputs=[basis], device=ctx.device, min_chunk=4096)
            pyr = mean_pyramid(basis, ctx.device) if p.sat == "tiles" else [basis]
            return {mkey: Moments(basis, pyr, zmin, zmin + rng)}

        def run_sat(res):
            m = res[mkey]
            sat = build_sat(m.basis, storage=p.sat, mu=p.mu, build=p.build, device=ctx.device, pyramid=m.pyramid if len(m.pyramid) > 1 else None)
            return {skey: sat}

        def run_shadow(res):
            gb, dm, m, sat = res[gbuf], res[depth], res[mkey], res[skey]
            q = VSSMConsts()
            q.n, q.tile, q.unit = sat.n, sat.tile, wp.float64(sat.unit)
            q.zmin, q.zrange = m.zmin, m.zmax - m.zmin
            q.bias, q.nsub, q.min_var, q.bleed = p.bias, p.subdivision, p.min_variance, p.bleed
            q.min_r, q.max_r = p.min_radius, p.max_radius
            q.plane = int(p.receiver_plane)
            q.slope = p.plane_slope_bias
            q.direct = int(p.direct_small and sat.storage == "float32")
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            looks = wp.empty(gb.count, dtype=wp.int32, device=ctx.device)
            launch_chunked(vssm_shade, gb.count, inputs=[dm.view.gpu(), light_kernel(light, dm.view), q, sat.data, m.basis, gb.gpu()], outputs=[vis, looks],
                           device=ctx.device, min_chunk=64)
            hit = gb.prim.numpy() >= 0
            c = ctx.counters(light)
            c["z_range"] = [m.zmin, m.zmax]
            c["sat"] = {"storage": sat.storage, "tile": sat.tile, "build": sat.build, "passes": sat.passes, "bytes": sat.memory_bytes()}
            c["lookups_per_sample"] = float(looks.numpy()[hit].mean()) if hit.any() else 0.0
            return {out: ctx.visibility(vis)}

        ctx.add_pass(str(mkey), inputs=(depth,), outputs=(mkey,), run=run_moments, stage="moments", light=light)
        ctx.add_pass(str(skey), inputs=(mkey,), outputs=(skey,), run=run_sat, stage="sat", light=light)
        return ctx.add_pass(ctx.pass_name("vssm_shadow", light), inputs=(gbuf, depth, mkey, skey), outputs=(out,), run=run_shadow, stage="shadow", light=light)
