"""A dome light's (the sky's) part of the shaded image (:mod:`wsoft.raster.shade`).

Each G-buffer sample gets the dome's unoccluded irradiance about its normal, ``E(n)``, from the
order-2 spherical-harmonic irradiance of the dome (:func:`wsoft.scene.dome.irradiance_sh`, Ramamoorthi
and Hanrahan 2001: exact for a constant dome, ``E = pi x color x intensity``; for a latlong texture
within a few percent), times the dome's shadowed transmission ``S`` (``V_dome`` with
``inputs:shadow:color`` applied): ``lum += E S``, ``unshadowed += E``.
"""

from __future__ import annotations

import numpy as np
import warp as wp

import wsoft.parallel  # noqa: F401  (Warp configured before this module's kernels are defined)
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.scene.dome import irradiance_sh


@wp.func
def sh_irradiance(coeff: wp.array[wp.vec3], n: wp.vec3) -> wp.vec3:
    """The irradiance about unit normal ``n`` from 9 cosine-convolved SH coefficients (``coeff``), clamped at 0."""
    x = n[0]
    y = n[1]
    z = n[2]
    e = coeff[0] * 0.282095 + coeff[1] * (0.488603 * y) + coeff[2] * (0.488603 * z) + coeff[3] * (0.488603 * x)
    e = e + coeff[4] * (1.092548 * x * y) + coeff[5] * (1.092548 * y * z) + coeff[6] * (0.315392 * (3.0 * z * z - 1.0))
    e = e + coeff[7] * (1.092548 * x * z) + coeff[8] * (0.546274 * (x * x - y * y))
    return wp.vec3(wp.max(e[0], 0.0), wp.max(e[1], 0.0), wp.max(e[2], 0.0))


@wp.kernel
def accumulate_dome(
    offset: int,
    gb: GBufferGPU,
    vis: wp.array[float],
    shadow_color: wp.vec3,
    coeff: wp.array[wp.vec3],
    # outputs
    lum: wp.array[wp.vec3],
    unshadowed: wp.array[wp.vec3],
    mask_num: wp.array[wp.vec3],
    mask_den: wp.array[wp.vec3],
):
    """Per sample: lum += E S, unshadowed += E (E the dome's irradiance about the sample's normal,
    S = V + shadow_color (1 - V)); the baked light's mask sums the same."""
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        return
    e = sh_irradiance(coeff, gb.nrm[i])
    v = vis[i]
    s = wp.vec3(v) + shadow_color * (1.0 - v)
    lum[i] = lum[i] + wp.cw_mul(e, s)
    unshadowed[i] = unshadowed[i] + e
    mask_num[i] = mask_num[i] + wp.cw_mul(e, s)
    mask_den[i] = mask_den[i] + e


def add_dome(light, gb, vis, shadow_color, unit: float, lum, unshadowed, mask_num, mask_den, device: str) -> None:
    """Add the dome ``light``'s ``E x S`` to the shading sums (``unit``: the scale :func:`~wsoft.raster.shade.shade`
    puts every light's radiance in)."""
    coeff = wp.array((irradiance_sh(light) * unit).astype(np.float32), dtype=wp.vec3, device=device)
    launch_chunked(accumulate_dome, gb.count, inputs=[gb.gpu(), vis, wp.vec3(*shadow_color), coeff],
                   outputs=[lum, unshadowed, mask_num, mask_den], device=device, min_chunk=1 << 14)
