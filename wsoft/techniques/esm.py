"""``esm``: exponential shadow maps (Annen et al. 2008), filtered in log space.

The normalised depth d in [0, 1] (between the light view's near and far planes; empty texels
at 1) is stored as its exponent c*d; the separable prefilter and the bilinear read combine
exp(c*d) in log space (``log sum w exp``) so nothing overflows for any ``c``. A receiver at
normalised depth z is lit by clamp(exp(c * d_filtered - c * z), 0, 1).

Known failure (pinned by a test): near a contact the receiver is only slightly behind the
occluder, exp(-c (z - d)) stays well above 0, and light leaks into the contact shadow.
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from wsoft.accel.blur import blur_log
from wsoft.lightspace.view import ViewGPU, bilinear_cell, normalised_depth
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_mapped_depth
from wsoft.params import LightViewParams, check_ranges
from wsoft.techniques._prefiltered import Prefiltered, normalised_bias, prefiltered_passes
from wsoft.techniques.base import Quality, Tolerance, check, param


@dataclass(frozen=True)
class ESMParams(LightViewParams):
    shadow_map_size: int = param(1024, "texels per side of the light depth map", range=(256, 8192))
    c: float = param(80.0, "exponent on the normalised depth: larger is sharper and leaks less", range=(0.01, 10000.0))
    filter: str = param("gaussian", "prefilter: box or gaussian")
    radius: int = param(2, "prefilter radius in texels (0: none)", range=(0, 64))
    bias: float = param(1e-4, "depth bias as a fraction of the frame's extent (receivers in view and the light)", range=(0.0, 0.1))

    def __post_init__(self):
        check_ranges(self)
        check(self.filter in ("box", "gaussian"), f"filter {self.filter!r} is not box or gaussian")


@wp.kernel
def make_exponent(
    offset: int,
    depth: wp.array[float],
    near: float,
    far: float,
    c: float,
    # outputs
    out: wp.array[float],
):
    i = wp.tid() + offset
    out[i] = c * normalised_depth(depth[i], near, far - near)


@wp.func
def bilinear_log(lv: ViewGPU, lmap: wp.array2d[float], m: wp.vec2) -> float:
    """log of the bilinear interpolation of exp(lmap), evaluated around the largest of the four."""
    cell = bilinear_cell(lv, m)
    ax = cell[2]
    ay = cell[3]
    xa = wp.clamp(int(cell[0]), 0, lv.width - 1)
    xb = wp.clamp(int(cell[0]) + 1, 0, lv.width - 1)
    ya = wp.clamp(int(cell[1]), 0, lv.height - 1)
    yb = wp.clamp(int(cell[1]) + 1, 0, lv.height - 1)
    a = lmap[ya, xa]
    b = lmap[ya, xb]
    c = lmap[yb, xa]
    d = lmap[yb, xb]
    mx = wp.max(wp.max(a, b), wp.max(c, d))
    s = (1.0 - ax) * (1.0 - ay) * wp.exp(a - mx) + ax * (1.0 - ay) * wp.exp(b - mx) + (1.0 - ax) * ay * wp.exp(c - mx) + ax * ay * wp.exp(d - mx)
    return mx + wp.log(wp.max(s, 1.0e-30))


@wp.kernel
def shade_esm(
    offset: int,
    lv: ViewGPU,
    lmap: wp.array2d[float],
    gb: GBufferGPU,
    c: float,
    bias: float,
    # outputs
    vis: wp.array[float],
):
    i = wp.tid() + offset
    mapped, z, m = gb_mapped_depth(lv, gb, i, bias)
    if not mapped:
        vis[i] = 1.0
        return
    vis[i] = wp.clamp(wp.exp(wp.min(bilinear_log(lv, lmap, m) - c * z, 0.0)), 0.0, 1.0)


class ESM(Prefiltered):
    """Exponential shadow maps with log-space filtering."""

    name = "esm"
    summary = "exponential shadow maps: exp(c d) prefiltered in log space"
    Params = ESMParams
    map_kind, map_stage, map_params = "esm_basis", "basis", ("c", "filter", "radius")
    passes = prefiltered_passes(map_kind, map_stage)
    quick_params = {"shadow_map_size": 256}

    quality = (Quality("c", (40.0, 80.0, 160.0), "a larger exponent: less light leaking near contacts, harder edges; same time"),)
    tolerance = Tolerance(mae=0.008, mae_penumbra=0.33)
    distance_refusal = "its prefiltered exp(c d) map mixes every caster's depth, so it cannot tell which lie within the distance"

    def prefilter(self, dm, device):
        p = self.params
        v = dm.view
        flat = wp.empty(v.width * v.height, dtype=float, device=device)
        launch_chunked(make_exponent, flat.shape[0], inputs=[dm.depth.reshape(-1), v.near, v.far, p.c], outputs=[flat], device=device,
                       min_chunk=1 << 15)
        return blur_log(flat.reshape((v.height, v.width)), p.filter, p.radius)

    def shade(self, gb, dm, fmap, device):
        p = self.params
        vis = wp.empty(gb.count, dtype=float, device=device)
        launch_chunked(shade_esm, gb.count, inputs=[dm.view.gpu(), fmap, gb.gpu(), p.c, normalised_bias(p.bias, dm.view)], outputs=[vis],
                       device=device)
        return vis
