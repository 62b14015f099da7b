"""``msm``: moment shadow maps (Peters & Klein 2015, "Moment Shadow Mapping"), filtered like ``vsm``.

The depth map, normalised to [0, 1] between the light view's near and far planes (empty texels at
1), becomes four moments (z, z^2, z^3, z^4) per texel, blurred separably (box or Gaussian of
``radius`` texels, ``vsm``'s blur) and read bilinearly. A receiver at normalised depth z (less the
depth ``bias``) gets the shadow intensity G of the Hamburger four-moment bound (the paper's
Hamburger 4MSM, :func:`wsoft.lightspace.moments.hamburger_bound`) on the biased moments
b' = (1 - alpha) b + alpha (1/2, 1/2, 1/2, 1/2), and V = 1 - G', G' = (G - alpha / 2) / (1 - alpha)
(clamped to [0, 1]): the bias's own share in front of z taken off (half of the mixed-in
distribution sits at depth 0; not in the paper, whose G leaves a lit receiver alone in its kernel
up to alpha / 2 = 1.5e-5 below 1; G' leaves it at 1, and every other V moves by at most 1.5e-5).
G is the sharpest lower bound on the fraction of the kernel's depths in front of z given the four
moments, where Chebyshev's bound on two moments (``vsm``) is far looser: two occluders at
different depths leak much less light.

``storage``: ``float32`` (128 bits a texel) or ``optimised16``, the paper's 64-bit variant: the
moments go through its optimised quantisation transform (an affine map into [0, 1]^4,
:data:`wsoft.lightspace.moments.QUANTISATION`) and are stored as 16-bit unsigned normalised
integers, the moment map and each blur pass alike, as a GPU stores them in a UNORM16 render
target; the shading reads them bilinearly (in float) and applies the inverse transform.

Moment bias ``moment_bias`` (alpha): 3e-5 for both storages, the value Peters & Klein give for
their 16-bit quantisation. For ``float32`` it is a measured choice: the shading's float32
arithmetic, not the storage, sets the floor. At 96 x 72 on ``ogre`` (64 reference samples) MAE is
0.0210 at 3e-5, 0.0219 at 3e-6, 0.057 at 1e-6 and 0.22 at 3e-7 (rounding noise in lit areas); the
``stacked_plates`` leak is 1.41% at 3e-5 and 1.33% at 3e-6. Values below 3e-6 are refused, and
``optimised16`` needs alpha at least its 16-bit step, 1.5e-5 (at 3e-6 ``ogre``'s MAE is 0.19).

Known limits: light still leaks where three or more depths overlap in one kernel (four moments
pin a three-point canonical distribution).
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from wsoft.accel.blur import blur_moments4
from wsoft.lightspace.moments import (
    bias_moments,
    depth_moments4,
    dequantise_moments,
    hamburger_bound,
    quantise_moments,
    unbiased_intensity,
    unorm,
)
from wsoft.lightspace.view import ViewGPU, bilinear, normalised_depth
from wsoft.parallel import launch_chunked
from wsoft.params import LightViewParams, check_ranges
from wsoft.raster.gbuffer import GBufferGPU, gb_mapped_depth
from wsoft.techniques._prefiltered import Prefiltered, normalised_bias, prefiltered_passes
from wsoft.techniques.base import Quality, Tolerance, check, param

STORAGES = ("float32", "optimised16")
UNORM16 = wp.constant(65535.0)


@dataclass(frozen=True)
class MSMParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map", range=(256, 8192))
    filter: str = param("gaussian", "prefilter: box or gaussian")
    radius: int = param(2, "prefilter radius in texels (0: none)", range=(0, 64))
    storage: str = param("float32", "moment storage: float32 (128 bits a texel) or optimised16 (the paper's 64-bit optimised quantisation)")
    moment_bias: float = param(3e-5, "moment bias alpha: the weight of the moments (1/2, 1/2, 1/2, 1/2) mixed in (optimised16: at least 1.5e-5, its 16-bit step)",
                               range=(3e-6, 0.1))
    bias: float = param(1e-4, "depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))

    def __post_init__(self):
        check_ranges(self)
        check(self.filter in ("box", "gaussian"), f"filter {self.filter!r} is not box or gaussian")
        check(self.storage in STORAGES, f"storage {self.storage!r} is not one of {', '.join(STORAGES)}")
        check(self.storage != "optimised16" or self.moment_bias >= 1.5e-5,
              f"moment_bias {self.moment_bias:g} is below optimised16's 16-bit step (1.5e-5): its rounding would show as noise")


@wp.kernel
def make_moments4(
    offset: int,
    depth: wp.array[float],
    near: float,
    far: float,
    quantised: int,
    # outputs
    out: wp.array[wp.vec4],
):
    i = wp.tid() + offset
    b = depth_moments4(normalised_depth(depth[i], near, far - near))
    if quantised != 0:
        q = quantise_moments(b)
        b = wp.vec4(unorm(q[0], UNORM16), unorm(q[1], UNORM16), unorm(q[2], UNORM16), unorm(q[3], UNORM16))
    out[i] = b


@wp.kernel
def shade_msm(
    offset: int,
    lv: ViewGPU,
    mom: wp.array2d[wp.vec4],
    gb: GBufferGPU,
    quantised: int,
    alpha: float,
    bias: float,
    # outputs
    vis: wp.array[float],
):
    i = wp.tid() + offset
    mapped, z, m = gb_mapped_depth(lv, gb, i, bias)
    if not mapped:
        vis[i] = 1.0
        return
    b = bilinear(lv, mom, m)
    if quantised != 0:
        b = dequantise_moments(b)
    vis[i] = 1.0 - unbiased_intensity(hamburger_bound(bias_moments(b, alpha), z), alpha, z)


class MSM(Prefiltered):
    """Moment shadow maps: blurred four depth moments and the Hamburger four-moment bound."""

    name = "msm"
    summary = "moment shadow maps: blurred (z, z^2, z^3, z^4) moments, Hamburger 4-moment bound, optional 16-bit optimised quantisation"
    Params = MSMParams
    map_kind, map_stage, map_params = "msm_moments", "moments", ("filter", "radius", "storage")
    passes = prefiltered_passes(map_kind, map_stage)
    quick_params = {"shadow_map_size": 256}

    quality = (Quality("radius", (1, 2, 4), "a wider prefilter: softer edges (not wider penumbrae), a little more time"),)
    tolerance = Tolerance(mae=0.007, mae_penumbra=0.28)  # measured 0.00537, 0.219 (optimised16 the same)
    distance_refusal = "its blurred moments (four powers of the depths) cannot tell which casters lie within the distance"

    def prefilter(self, dm, device):
        p = self.params
        v = dm.view
        flat = wp.empty(v.width * v.height, dtype=wp.vec4, device=device)
        q = int(p.storage == "optimised16")
        launch_chunked(make_moments4, flat.shape[0], inputs=[dm.depth.reshape(-1), v.near, v.far, q], outputs=[flat], device=device,
                       min_chunk=1 << 15)
        return blur_moments4(flat.reshape((v.height, v.width)), p.filter, p.radius, bits=16 if q else 0)

    def shade(self, gb, dm, fmap, device):
        p = self.params
        vis = wp.empty(gb.count, dtype=float, device=device)
        launch_chunked(shade_msm, gb.count, inputs=[dm.view.gpu(), fmap, gb.gpu(), int(p.storage == "optimised16"), p.moment_bias,
                                                    normalised_bias(p.bias, dm.view)], outputs=[vis], device=device)
        return vis
