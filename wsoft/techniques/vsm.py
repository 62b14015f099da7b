"""``vsm``: variance shadow maps (Donnelly and Lauritzen 2006).

The depth map, normalised to [0, 1] between the light view's near and far planes (empty texels
at 1), becomes two moments (d, d^2), blurred separably (box or Gaussian of ``radius`` texels)
and read bilinearly. A receiver at normalised depth z behind the mean mu is lit with
Chebyshev's bound p = s^2 / (s^2 + (z - mu)^2), s^2 = max(E[d^2] - mu^2, min_variance); the
light-bleeding reduction maps p through ``(p - amount) / (1 - amount)``, clamped.

Known failure (pinned by a test): with two occluders stacked over a receiver, the variance
of their two depths lets light "bleed" into the lower occluder's umbra.
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from wsoft.accel.blur import blur_moments
from wsoft.lightspace.moments import chebyshev_bound, moments_variance
from wsoft.lightspace.view import ViewGPU, bilinear, normalised_depth
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_mapped_depth
from wsoft.params import LightViewParams, check_ranges
from wsoft.techniques._prefiltered import Prefiltered, normalised_bias, prefiltered_passes
from wsoft.techniques.base import Quality, Tolerance, check, param


@dataclass(frozen=True)
class VSMParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map", range=(256, 8192))
    filter: str = param("gaussian", "prefilter: box or gaussian")
    radius: int = param(2, "prefilter radius in texels (0: none)", range=(0, 64))
    min_variance: float = param(1e-6, "smallest variance, in normalised depth squared", range=(0.0, 0.25))
    bleed_reduction: float = param(0.2, "light-bleeding reduction amount", range=(0.0, 0.99))
    bias: float = param(1e-4, "depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))

    def __post_init__(self):
        check_ranges(self)
        check(self.filter in ("box", "gaussian"), f"filter {self.filter!r} is not box or gaussian")


@wp.kernel
def make_moments(
    offset: int,
    depth: wp.array[float],
    near: float,
    far: float,
    # outputs
    out: wp.array[wp.vec2],
):
    i = wp.tid() + offset
    d = normalised_depth(depth[i], near, far - near)
    out[i] = wp.vec2(d, d * d)


@wp.kernel
def shade_vsm(
    offset: int,
    lv: ViewGPU,
    mom: wp.array2d[wp.vec2],
    gb: GBufferGPU,
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
    e = bilinear(lv, mom, m)
    mu = e[0]
    if z <= mu:
        vis[i] = 1.0
        return
    p = chebyshev_bound(mu, moments_variance(mu, e[1], min_variance), z)
    vis[i] = wp.clamp((p - bleed) / (1.0 - bleed), 0.0, 1.0)


class VSM(Prefiltered):
    """Variance shadow maps: blurred depth moments and Chebyshev's bound."""

    name = "vsm"
    summary = "variance shadow maps: blurred (d, d^2) moments, Chebyshev bound, light-bleeding reduction"
    Params = VSMParams
    map_kind, map_stage, map_params = "vsm_moments", "moments", ("filter", "radius")
    passes = prefiltered_passes(map_kind, map_stage)
    quick_params = {"shadow_map_size": 256}

    quality = (Quality("radius", (1, 2, 4), "a wider prefilter: softer edges (not wider penumbrae), a little more time"),)
    tolerance = Tolerance(mae=0.0085, mae_penumbra=0.34)
    distance_refusal = "its blurred moments (mean and variance of the depths) cannot tell which casters lie within the distance"

    def prefilter(self, dm, device):
        v = dm.view
        flat = wp.empty(v.width * v.height, dtype=wp.vec2, device=device)
        launch_chunked(make_moments, flat.shape[0], inputs=[dm.depth.reshape(-1), v.near, v.far], outputs=[flat], device=device, min_chunk=1 << 15)
        return blur_moments(flat.reshape((v.height, v.width)), self.params.filter, self.params.radius)

    def shade(self, gb, dm, fmap, device):
        p = self.params
        vis = wp.empty(gb.count, dtype=float, device=device)
        launch_chunked(shade_vsm, gb.count, inputs=[dm.view.gpu(), fmap, gb.gpu(), normalised_bias(p.bias, dm.view), p.min_variance, p.bleed_reduction],
                       outputs=[vis], device=device)
        return vis
