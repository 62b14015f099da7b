"""``evsm``: exponential variance shadow maps (Lauritzen & McCool 2008, "Layered Variance Shadow
Maps"), filtered like ``vsm``.

The depth map, normalised to z in [0, 1] between the light view's near and far planes (empty
texels at 1), is mapped to x = 2z - 1 in [-1, 1] (MJP's "Shadows" sample's reading: both halves of
float32's exponent range) and warped by the positive warp p = e^{c+ x} and, with ``moments=4``,
the negative warp n = -e^{-c- x}; the moments (p, p^2) and (n, n^2) are blurred separably (box or
Gaussian of ``radius`` texels, ``vsm``'s blur) and read bilinearly. A receiver's warped depths get
Chebyshev's bound each (``vsm``'s, on the warped moments), visibility is the smaller of the two
(``moments=2``: the positive one alone), through the light-bleeding reduction
``(p - amount) / (1 - amount)``, clamped. The variance floor ``min_variance`` is on the
normalised depth and carried through each warp by its slope at the receiver (Var[warp] ~
warp'(z)^2 Var[z]).

The warps make light bleeding much rarer than ``vsm``'s (the positive warp pulls a receiver's
warped depth far from occluders' in front of it; the negative warp covers where the positive one
bleeds), at a cost: near contacts exp(-c (z - d)) stays above 0, as in ``esm``.

Float32's range: e^{c x} and its square, the second moment, must be finite for every x in
[-1, 1]: 2c <= ln FLT_MAX = 88.72. Both exponents are at most
:data:`wsoft.lightspace.moments.EVSM_MAX_EXPONENT` = 42 (e^{84} = 3.0e36, a factor above 100
below FLT_MAX for the filter's sums and the variance's products): a larger value is a parameter
error, and the warp itself clamps to it. The warps depend on the normalised depth only, so no
depth range or map size overflows them.
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from wsoft.accel.blur import blur_moments, blur_moments4
from wsoft.lightspace.moments import EVSM_MAX_EXPONENT, evsm_warp, warped_chebyshev
from wsoft.lightspace.view import ViewGPU, bilinear, normalised_depth
from wsoft.parallel import launch_chunked
from wsoft.params import LightViewParams, check_ranges
from wsoft.raster.gbuffer import GBufferGPU, gb_mapped_depth
from wsoft.techniques._prefiltered import Prefiltered, normalised_bias, prefiltered_passes
from wsoft.techniques.base import Quality, Tolerance, check, param


@dataclass(frozen=True)
class EVSMParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map", range=(256, 8192))
    moments: int = param(4, "4: positive and negative warps (EVSM4); 2: the positive warp only (EVSM2)", range=(2, 4))
    c_pos: float = param(40.0, "positive warp exponent c+ on the depth mapped to [-1, 1] (at most 42: e^{2 c+} finite in float32)",
                         range=(0.5, EVSM_MAX_EXPONENT))
    c_neg: float = param(5.0, "negative warp exponent c- on the depth mapped to [-1, 1] (at most 42)", range=(0.5, EVSM_MAX_EXPONENT))
    filter: str = param("gaussian", "prefilter: box or gaussian")
    radius: int = param(2, "prefilter radius in texels (0: none)", range=(0, 64))
    min_variance: float = param(1e-6, "smallest variance, in normalised depth squared (carried through each warp by its slope)",
                                range=(0.0, 0.25))
    bleed_reduction: float = param(0.0, "light-bleeding reduction amount", range=(0.0, 0.99))
    bias: float = param(1e-4, "depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))

    def __post_init__(self):
        check_ranges(self)
        check(self.moments in (2, 4), f"moments {self.moments} is not 2 or 4")
        check(self.filter in ("box", "gaussian"), f"filter {self.filter!r} is not box or gaussian")


@wp.kernel
def make_warped_moments2(
    offset: int,
    depth: wp.array[float],
    near: float,
    far: float,
    c_pos: float,
    # outputs
    out: wp.array[wp.vec2],
):
    i = wp.tid() + offset
    w = evsm_warp(normalised_depth(depth[i], near, far - near), c_pos, 1.0)
    out[i] = wp.vec2(w[0], w[0] * w[0])


@wp.kernel
def make_warped_moments4(
    offset: int,
    depth: wp.array[float],
    near: float,
    far: float,
    c_pos: float,
    c_neg: float,
    # outputs
    out: wp.array[wp.vec4],
):
    i = wp.tid() + offset
    w = evsm_warp(normalised_depth(depth[i], near, far - near), c_pos, c_neg)
    out[i] = wp.vec4(w[0], w[0] * w[0], w[1], w[1] * w[1])


@wp.func
def reduce_bleeding(p: float, amount: float) -> float:
    return wp.clamp((p - amount) / (1.0 - amount), 0.0, 1.0)


@wp.kernel
def shade_evsm2(
    offset: int,
    lv: ViewGPU,
    mom: wp.array2d[wp.vec2],
    gb: GBufferGPU,
    c_pos: float,
    bias: float,
    min_variance: float,
    bleed: float,
    # outputs
    vis: wp.array[float],
):
    i = wp.tid() + offset
    mapped, z, m = gb_mapped_depth(lv, gb, i, bias)
    if not mapped:
        vis[i] = 1.0
        return
    w = evsm_warp(z, c_pos, 1.0)
    e = bilinear(lv, mom, m)
    cp = wp.min(c_pos, EVSM_MAX_EXPONENT)
    vis[i] = reduce_bleeding(warped_chebyshev(e[0], e[1], w[0], 2.0 * cp * w[0], min_variance), bleed)


@wp.kernel
def shade_evsm4(
    offset: int,
    lv: ViewGPU,
    mom: wp.array2d[wp.vec4],
    gb: GBufferGPU,
    c_pos: float,
    c_neg: float,
    bias: float,
    min_variance: float,
    bleed: float,
    # outputs
    vis: wp.array[float],
):
    i = wp.tid() + offset
    mapped, z, m = gb_mapped_depth(lv, gb, i, bias)
    if not mapped:
        vis[i] = 1.0
        return
    w = evsm_warp(z, c_pos, c_neg)
    e = bilinear(lv, mom, m)
    cp = wp.min(c_pos, EVSM_MAX_EXPONENT)
    cn = wp.min(c_neg, EVSM_MAX_EXPONENT)
    pos = warped_chebyshev(e[0], e[1], w[0], 2.0 * cp * w[0], min_variance)
    neg = warped_chebyshev(e[2], e[3], w[1], -2.0 * cn * w[1], min_variance)
    vis[i] = reduce_bleeding(wp.min(pos, neg), bleed)


class EVSM(Prefiltered):
    """Exponential variance shadow maps: blurred moments of a positive and a negative exponential warp of the depth."""

    name = "evsm"
    summary = "exponential variance shadow maps: blurred moments of the positive (and negative) exponential depth warps, Chebyshev bound on each, light-bleeding reduction"
    Params = EVSMParams
    map_kind, map_stage, map_params = "evsm_moments", "moments", ("moments", "c_pos", "c_neg", "filter", "radius")
    passes = prefiltered_passes(map_kind, map_stage)
    quick_params = {"shadow_map_size": 256}

    quality = (Quality("moments", (2, 4), "the negative warp too: less light bleeding, twice the map"),
               Quality("radius", (1, 2, 4), "a wider prefilter: softer edges (not wider penumbrae), a little more time"))
    tolerance = Tolerance(mae=0.007, mae_penumbra=0.28)  # measured 0.0054, 0.219 (moments=2: 0.0055, 0.220)
    distance_refusal = "its blurred moments of warped depths cannot tell which casters lie within the distance"

    def prefilter(self, dm, device):
        p = self.params
        v = dm.view
        n = v.width * v.height
        if p.moments == 2:
            flat = wp.empty(n, dtype=wp.vec2, device=device)
            launch_chunked(make_warped_moments2, n, inputs=[dm.depth.reshape(-1), v.near, v.far, p.c_pos], outputs=[flat], device=device,
                           min_chunk=1 << 15)
            return blur_moments(flat.reshape((v.height, v.width)), p.filter, p.radius)
        flat = wp.empty(n, dtype=wp.vec4, device=device)
        launch_chunked(make_warped_moments4, n, inputs=[dm.depth.reshape(-1), v.near, v.far, p.c_pos, p.c_neg], outputs=[flat],
                       device=device, min_chunk=1 << 15)
        return blur_moments4(flat.reshape((v.height, v.width)), p.filter, p.radius)

    def shade(self, gb, dm, fmap, device):
        p = self.params
        vis = wp.empty(gb.count, dtype=float, device=device)
        bias = normalised_bias(p.bias, dm.view)
        if p.moments == 2:
            launch_chunked(shade_evsm2, gb.count, inputs=[dm.view.gpu(), fmap, gb.gpu(), p.c_pos, bias, p.min_variance, p.bleed_reduction],
                           outputs=[vis], device=device)
        else:
            launch_chunked(shade_evsm4, gb.count, inputs=[dm.view.gpu(), fmap, gb.gpu(), p.c_pos, p.c_neg, bias, p.min_variance,
                                                          p.bleed_reduction], outputs=[vis], device=device)
        return vis
