"""``msm_soft``: moment soft shadow mapping (Peters, Münstermann, Wetzstein & Klein 2016, "Beyond
Hard Shadows: Moment Shadow Maps for Single Scattering, Soft Shadows and Translucent Occluders"):
PCSS with both of its steps answered by four depth moments from summed-area tables. Not the
multi-scale shadow map (``ssm``'s ``structure=mssm``): "MSM" here is "moment shadow map".

1. Moments: the light-space linear depth normalised to z in [0, 1] over the map's effective depth
   range (its min/max pyramid, as ``vssm`` and ``essm`` take it; empty texels at 1), its four
   moments (z, z^2, z^3, z^4) through Peters & Klein's optimised quantisation transform (an affine
   map into [0, 1]^4, :data:`wsoft.lightspace.moments.QUANTISATION`), into a 4-channel
   summed-area table (:mod:`wsoft.accel.sat`).
2. Blocker search over the light's spread from the nearest caster depth to the receiver (the
   region where any caster could cover part of the light, a rectangle, as ``pcss`` and ``vssm``
   size it): the box's mean moments, biased (moment bias alpha), give the canonical three-point
   representation holding the receiver's depth z_f (:func:`wsoft.lightspace.moments.hamburger_canonical`);
   the weights of its points in front of z_f sum to the blocker search's shadow intensity G_s and
   their weighted mean depth is the average blocker depth z_occ (the paper's estimate, as the
   shader code of its extended version, Peters et al. JCGT 2017, computes it; the parts of the
   box outside the map count as lit at depth 1). G_s <= 1e-4 (the bias's share taken off, as in
   step 3): lit (that code instead blends z_occ toward z_f with a small weight, which ends lit
   there too).
3. Penumbra from z_occ as in PCSS (``wsoft.lightspace.light.spread``: w (1/z_occ - 1/z_f) for a
   local light of half-extent w, (z_f - z_occ) tan a for a distant one), clamped to
   [``min_radius``, ``max_radius``] texels; visibility 1 - G', G the Hamburger bound of the
   penumbra box's mean moments at z_f and G' = (G - alpha / 2) / (1 - alpha) with the moment
   bias's own share in front taken off (``msm``'s reading, not the paper's).

Storage (``sat``): ``tiles`` (the default: uint32 SAT tile grid with ``mu`` precision bits, tiles
sized by the overflow test, exact box sums of any size; the project's structure from ``essm``),
``uint32`` (the JCGT 2017 code's: one full integer SAT whose fixed-point precision is what its largest box,
2 ``max_radius`` + 2 texels a side, leaves: ``mu`` = 0 takes the most bits that keep that box's
sum below 2^32, a larger ``mu`` is a parameter error, since its sums would wrap) or ``float32``
(one full float SAT: its cancellation makes small kernels noise at large maps).

The moment bias alpha (``moment_bias``, 0: 1e-4 for an integer SAT of at least 16 bits, 1e-3
for fewer bits and for float32) and the depth bias (``bias``, 0.002 on the normalised depth) are
measured choices: at 96 x 72 against 256 reference samples,
penumbra MAE on ``ogre`` / ``dinosaurs`` 0.0263 / 0.0411 at the defaults, 0.0276 / 0.0379 at
alpha 3e-5, 0.0253 / 0.0430 at 3e-4; the full uint32 SAT at max_radius 512 (11 bits) 0.0257 /
0.0411 at 1e-4 but MAE 0.0103 on ``ogre`` (0.0050 at 1e-3); bias 0.005 gives 0.0249 / 0.0459.

A light across the receiver's tangent plane: only its front part lights the receiver
(:mod:`wsoft.lightspace.halfspace`). The blocker search and the filter move to that part's
bounding window (:func:`~wsoft.lightspace.halfspace.kernel_front`) and V is the window's visible
fraction times the part's share of the light: exact for a rect light cut along an axis,
approximate for an oblique cut or a disk; a light wholly in front keeps the kernel as it is.

Known limits: like ``pcss`` it takes one blocker depth per receiver, so overlapping blockers at
different depths give one penumbra; a receiver's own surface inside a large kernel (a curved or
tilted receiver) counts as a blocker in front of it unless ``bias`` covers it (the JCGT 2017 code
scales its depth bias with the kernel size; here it is constant).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from wsoft.accel.pyramid import effective_depth_range
from wsoft.accel.sat import Moments, box_area, build_sat, check_sat_params, mean_pyramid, sat_box
from wsoft.lightspace.halfspace import front_box, kernel_front
from wsoft.lightspace.light import CYLINDER_KERNEL, LightKernel, light_kernel, spread_texels
from wsoft.lightspace.moments import (
    QUANTISATION,
    QUANTISATION_OFFSET,
    bias_moments,
    depth_moments4,
    dequantise_moments,
    hamburger_canonical,
    quantise_moments,
    unbiased_intensity,
)
from wsoft.lightspace.view import ViewGPU, normalised_depth, view_dir
from wsoft.parallel import launch_chunked
from wsoft.params import LightViewParams, check_ranges
from wsoft.raster.gbuffer import GBufferGPU, gb_mapped_receiver
from wsoft.techniques.base import PassSpec, Technique, Tolerance, check, param

LIT_BELOW = 1.0e-4  # a blocker search whose shadow intensity is below this finds no blocker


def largest_box(max_radius: float) -> float:
    """Texels a side of the largest box a lookup sums: a kernel of half-width ``max_radius`` plus the
    partly covered texel at each end."""
    return 2.0 * max_radius + 2.0


def full_uint32_mu(max_radius: float) -> int:
    """The most precision bits a full uint32 SAT of values in [0, 1] can have so that the sum over
    the largest box (:func:`largest_box`) stays below 2^32 (each texel rounds to at most 2^mu)."""
    return int(math.floor(32.0 - math.log2(largest_box(max_radius) ** 2 * (1.0 + 2.0 ** -20))))


@dataclass(frozen=True)
class MSMSoftParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map (a power of two)", range=(256, 8192))
    sat: str = param("tiles", "summed-area table: tiles (uint32 tile grid), uint32 (one full integer SAT, the paper's) or float32 (full)")
    build: str = param("doubling", "SAT build: doubling or scan")
    mu: int = param(0, "precision bits of the integer SATs (0: 20 for tiles; for uint32 the most its largest box allows)", range=(0, 31))
    moment_bias: float = param(0.0, "moment bias alpha (0: 1e-4 for an integer SAT of at least 16 bits, 1e-3 for fewer and for float32)", range=(0.0, 0.1))
    bias: float = param(0.002, "depth bias on the normalised depth [0, 1]", range=(0.0, 0.5))
    min_radius: float = param(0.5, "smallest penumbra half-width in texels", range=(0.01, 4096.0))
    max_radius: float = param(512.0, "largest search and penumbra half-width in texels", range=(0.01, 4096.0))

    def __post_init__(self):
        check_ranges(self)
        check_sat_params(self)
        if self.sat == "uint32":
            most = full_uint32_mu(self.max_radius)
            check(most >= 8, f"sat=uint32 with max_radius {self.max_radius:g}: a box of {largest_box(self.max_radius):g}^2 texels leaves "
                             f"{most} precision bits (at least 8 needed); use sat=tiles or a smaller max_radius")
            check(self.mu <= most, f"sat=uint32 with mu={self.mu} wraps: a box of {largest_box(self.max_radius):g}^2 texels holds at most "
                                   f"{most} bits (mu=0 takes them; or lower max_radius)")
        elif self.sat == "tiles":
            check(self.mu == 0 or self.mu >= 8, f"mu {self.mu} must be 0 or at least 8")

    @property
    def bits(self) -> int:
        """The integer SAT's precision bits in force (0 for float32)."""
        if self.sat == "float32":
            return 0
        if self.mu:
            return self.mu
        return 20 if self.sat == "tiles" else full_uint32_mu(self.max_radius)

    @property
    def alpha(self) -> float:
        """The moment bias in force."""
        if self.moment_bias > 0.0:
            return self.moment_bias
        return 1e-4 if self.bits >= 16 else 1e-3


@wp.struct
class MSMSoftConsts:
    n: int
    tile: int
    unit: wp.float64
    outside: wp.vec4  # the quantised moments of depth 1 (parts of a box outside the map)
    zmin: float
    zrange: float
    bias: float
    alpha: float
    min_r: float
    max_r: float


@wp.kernel
def msm_soft_basis(
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
    q = quantise_moments(depth_moments4(normalised_depth(depth[y, x], zmin, zrange)))
    for c in range(4):
        out[c, y, x] = wp.clamp(q[c], 0.0, 1.0)


@wp.func
def box_moments(q: MSMSoftConsts, data: wp.array3d(dtype=Any), u0: float, u1: float, v0: float, v1: float) -> wp.vec4:
    """The biased canonical moments of the box [u0, u1] x [v0, v1] (texels): the SAT's mean of the
    quantised moments, the part outside the map lit at depth 1, the inverse transform, the moment bias."""
    fa = (u1 - u0) * (v1 - v0)
    a = box_area(q.n, u0, u1, v0, v1)
    m = wp.vec4(q.outside)
    if fa > 0.0 and a > 0.0:
        out = wp.float64(fa - a)
        for c in range(4):
            m[c] = float((sat_box(data, c, q.n, q.tile, u0, u1, v0, v1) * q.unit + out * wp.float64(q.outside[c])) / wp.float64(fa))
    return bias_moments(dequantise_moments(m), q.alpha)


@wp.kernel
def msm_soft_shade(
    offset: int,
    lv: ViewGPU,
    k: LightKernel,
    q: MSMSoftConsts,
    data: wp.array3d(dtype=Any),
    gb: GBufferGPU,
    # outputs
    vis: wp.array[float],
    blocker: wp.array[float],
):
    i = wp.tid() + offset
    vis[i] = 1.0
    blocker[i] = -1.0
    mapped, pv, m, tc = gb_mapped_receiver(lv, gb, i)
    if not mapped:
        return
    d_lin = pv[2]
    zf = normalised_depth(d_lin, q.zmin, q.zrange) - q.bias
    # the light clipped to the receiver's front half-space: search and filter its part's window
    mid, hs, front = kernel_front(lv, k, pv, view_dir(lv, gb.nrm[i]))
    if front <= 0.0:
        vis[i] = 0.0
        return
    # 1. blocker search over the region where any caster could cover part of the light
    sh = spread_texels(lv, k, q.zmin, d_lin, 0.5, q.max_r)
    b = front_box(tc, sh, mid, hs, 0.5)
    r = hamburger_canonical(box_moments(q, data, b[0], b[1], b[2], b[3]), zf)
    if unbiased_intensity(r[0], q.alpha, zf) <= LIT_BELOW:
        vis[i] = front
        return
    z_occ = wp.clamp(r[1] / r[0], 0.0, wp.max(zf, 0.0))
    blocker[i] = z_occ
    # 2. penumbra from the average blocker depth, as in PCSS; 3. the Hamburger bound over it
    pen = spread_texels(lv, k, q.zmin + z_occ * q.zrange, d_lin, q.min_r, q.max_r)
    b = front_box(tc, pen, mid, hs, 0.5)
    g = hamburger_canonical(box_moments(q, data, b[0], b[1], b[2], b[3]), zf)[0]
    vis[i] = front * (1.0 - unbiased_intensity(g, q.alpha, zf))


for _t in (wp.uint32, wp.float32):
    wp.overload(msm_soft_shade, {"data": wp.array3d(dtype=_t)})


class MSMSoft(Technique):
    """Moment soft shadow mapping: SATs of four depth moments, the moments' blocker depth, PCSS kernels, the Hamburger bound."""

    name = "msm_soft"
    distant_angle_limit = 50.0  # max point error 0.074 at 50 degrees, 0.146 at 60
    instancing_refusal = ""  # its maps draw instances (wsoft.raster.depth_map.instance_runs)
    summary = "moment soft shadow mapping (moment shadow maps, not MSSM): SAT of four depth moments, blocker depth from the canonical 3-point distribution, PCSS kernel, Hamburger bound"
    Params = MSMSoftParams
    passes = (
        PassSpec("moments", reads=("light_depth",), writes=("msm_soft_moments",)),
        PassSpec("sat", reads=("msm_soft_moments",), writes=("msm_soft_sat",)),
        PassSpec("shadow", reads=("gbuffer", "light_depth", "msm_soft_moments", "msm_soft_sat"), writes=("visibility",)),
    )
    quick_params = {"shadow_map_size": 256}
    size_param = "shadow_map_size"
    tolerance = Tolerance(mae=0.0003, mae_penumbra=0.01)  # measured 0.00013, 0.0054
    distance_refusal = "its summed-area tables of depth moments sum every caster of a kernel together, so they cannot tell which lie within the distance"
    cylinder_model = CYLINDER_KERNEL

    def add_passes(self, ctx, light):
        p = self.params
        gbuf = ctx.gbuffer()
        depth = ctx.light_depth(light, size=p.shadow_map_size, soft=True, view=p.view)
        out = ctx.visibility_key(light)
        mkey = ctx.shared_key("msm_soft_moments", light, p.shadow_map_size, "sat")
        skey = ctx.shared_key("msm_soft_sat", light, p.shadow_map_size, "sat", "mu", "max_radius", "build")

        def run_moments(res):
            dm = res[depth]
            n = dm.depth.shape[0]
            zmin, rng, _ = effective_depth_range(dm, "pyramid", ctx.scene, ctx.device)
            basis = wp.empty((4, n, n), dtype=float, device=ctx.device)
            launch_chunked(msm_soft_basis, n * n, inputs=[dm.depth, n, zmin, rng], outputs=[basis], device=ctx.device, min_chunk=4096)
            pyr = mean_pyramid(basis, ctx.device) if p.sat == "tiles" else [basis]
            return {mkey: Moments(basis, pyr, zmin, zmin + rng)}

        def run_sat(res):
            m = res[mkey]
            sat = build_sat(m.basis, storage=p.sat, mu=p.bits or 20, build=p.build, device=ctx.device,
                            pyramid=m.pyramid if len(m.pyramid) > 1 else None)
            return {skey: sat}

        def run_shadow(res):
            gb, dm, m, sat = res[gbuf], res[depth], res[mkey], res[skey]
            q = MSMSoftConsts()
            q.n, q.tile, q.unit = sat.n, sat.tile, wp.float64(sat.unit)
            q.outside = wp.vec4(*np.clip(QUANTISATION @ np.ones(4) + QUANTISATION_OFFSET, 0.0, 1.0).astype(np.float32))
            q.zmin, q.zrange = m.zmin, m.zmax - m.zmin
            q.bias, q.alpha = p.bias, p.alpha
            q.min_r, q.max_r = p.min_radius, p.max_radius
            vis = wp.empty(gb.count, dtype=float, device=ctx.device)
            blk = wp.empty(gb.count, dtype=float, device=ctx.device)
            launch_chunked(msm_soft_shade, gb.count, inputs=[dm.view.gpu(), light_kernel(light, dm.view), q, sat.data, gb.gpu()], outputs=[vis, blk],
                           device=ctx.device, min_chunk=64)
            c = ctx.counters(light)
            c["z_range"] = [m.zmin, m.zmax]
            c["sat"] = {"storage": sat.storage, "tile": sat.tile, "mu": p.bits, "build": sat.build, "passes": sat.passes,
                        "bytes": sat.memory_bytes()}
            c["moment_bias"] = p.alpha
            c["samples_with_blockers"] = int(np.count_nonzero(blk.numpy() >= 0.0))
            return {out: ctx.visibility(vis)}

        ctx.add_pass(str(mkey), inputs=(depth,), outputs=(mkey,), run=run_moments, stage="moments", light=light)
        ctx.add_pass(str(skey), inputs=(mkey,), outputs=(skey,), run=run_sat, stage="sat", light=light)
        return ctx.add_pass(ctx.pass_name("msm_soft_shadow", light), inputs=(gbuf, depth, mkey, skey), outputs=(out,), run=run_shadow,
                            stage="shadow", light=light)
