"""The receiver's horizon: what part of a light lies in front of a visible point's tangent plane,
and whether the light emits toward the point at all.

A point on a surface sees only the part of a light in front of its visible side's tangent plane
(the side the camera sees, ``N`` in the G-buffer): a light wholly behind it gives V = 0, one
straddling the plane counts its front part. A rect or disk light emits from its front only: a
point on or behind its plane gets none of it (V = 0). The reference applies both rules per light
sample (:func:`~wsoft.lightspace.light.lit_along`); a technique's visibility is capped by the light's
*front fraction* computed here once per light (:func:`front_fraction`), ``V = min(V, front)``
(:func:`clip_to_front`; a technique that answers for the light's centre alone, ``hard``, is
zeroed where the centre is behind the plane; the techniques that integrate or filter over the light
clip it to the plane themselves, :mod:`wsoft.lightspace.halfspace`, and give no more than the
front fraction), so a thin sheet lit from behind (a leaf, a wall, a ground seen from
below) is dark for every technique, not lit through its own sheet, and so is everything behind a
light that faces away.

The front fraction is exact (0 or 1) wherever the light's bounds lie on one side of the plane
or the point lies behind a one-sided light, and counted over a regular grid of
:data:`FRONT_SAMPLES` light samples where the bounds straddle the plane.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.lightspace.light import LightGPU, emits_along, in_front, light_center_dir, light_point, light_side, lit_along
from wsoft.lightspace.samples import LightSamples, SamplePattern, sample_coords, sampling_begin
from wsoft.parallel import launch_chunked
from wsoft.raster.gbuffer import GBufferGPU, gb_covered, gb_pixel

FRONT_SAMPLES = 256  # a 16 x 16 grid over the light where it straddles a receiver's plane


@wp.kernel
def front_fraction_kernel(
    offset: int,
    L: LightGPU,
    ls: LightSamples,
    gb: GBufferGPU,
    centre: int,
    # outputs
    front: wp.array[float],
):
    i = wp.tid() + offset
    if not gb_covered(gb, i):
        front[i] = 1.0
        return
    p = gb.pos[i]
    n = gb.nrm[i]
    if not emits_along(L, L.position - p):  # behind a rect or disk light's emitting plane: none of it reaches p
        front[i] = 0.0
        return
    if centre != 0:
        d = light_center_dir(L, p)
        front[i] = wp.where(in_front(n, wp.vec3(d[0], d[1], d[2])), 1.0, 0.0)
        return
    side = light_side(L, p, n)
    if side != 0:
        front[i] = wp.where(side > 0, 1.0, 0.0)
        return
    xy = gb_pixel(gb, i)
    state, base, rot = sampling_begin(ls, i, xy[0], xy[1])
    k = int(0)
    for s in range(ls.count):
        c, state = sample_coords(ls, state, base, rot, s)
        r = light_point(L, p, c)
        if lit_along(L, n, wp.vec3(r[0], r[1], r[2])):
            k += 1
    front[i] = float(k) / float(ls.count)


@wp.kernel
def clip_to_front_kernel(
    offset: int,
    vis: wp.array[float],
    front: wp.array[float],
    # outputs
    out: wp.array[float],
):
    i = wp.tid() + offset
    out[i] = wp.min(vis[i], front[i])


def front_fraction(L: LightGPU, gb, disk: bool, device: str, centre: bool = False) -> wp.array:
    """Per G-buffer sample, the fraction of the light in front of its tangent plane that emits toward
    it (1 off surfaces; 0 behind a rect or disk light's plane); ``centre``: 1 or 0, whether the
    light's centre is in front and emits toward it (for techniques that answer for it)."""
    front = wp.empty(gb.count, dtype=float, device=device)
    ls = SamplePattern("regular", FRONT_SAMPLES).on(device, disk)
    launch_chunked(front_fraction_kernel, gb.count, inputs=[L, ls, gb.gpu(), int(centre)], outputs=[front], device=device, min_chunk=1 << 12)
    return front


def clip_to_front(vis: wp.array, front: wp.array) -> wp.array:
    """``min(vis, front)`` per sample, as a new array."""
    out = wp.empty_like(vis)
    launch_chunked(clip_to_front_kernel, vis.shape[0], inputs=[vis, front], outputs=[out], device=str(vis.device), min_chunk=1 << 15)
    return out


def front_counts(front: wp.array, covered: np.ndarray) -> dict[str, int]:
    """How many covered samples get none of the light (wholly behind their plane, or they lie behind a
    rect or disk light's emitting plane), and how many straddle it."""
    f = front.numpy()[covered]
    return {"light_behind": int(np.count_nonzero(f == 0.0)), "light_straddles": int(np.count_nonzero((f > 0.0) & (f < 1.0)))}
