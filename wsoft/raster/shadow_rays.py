"""A receiver's shadow rays: where they start and how far they look.

Every pass that traces shadow rays from G-buffer samples (the reference, and the techniques that
test rays of their own: ``dcs``, ``pwedge``, ``rtdenoise``) builds them the same way: from the
surface point moved off its surface along the camera-facing normal by a few float32 ulps of its
coordinates and its triangle's (:func:`~wsoft.scene.offsets.ray_offset` of the sample's ``err``,
never a fraction of the scene), to a point on the light, for :func:`shadow_ray_length` (the light
point, or ``inputs:shadow:distance``). :func:`receiver_begin` sets up one receiver's rays and its
light-sample stream. ``izb``'s sub-samples, points of their own with no triangle's scale kept,
take the frame's largest (:func:`ray_epsilon`).
"""

from __future__ import annotations

import warp as wp

from wsoft.lightspace.samples import LightSamples, sampling_begin
from wsoft.raster.gbuffer import GBufferGPU, gb_pixel
from wsoft.scene.offsets import ray_offset


@wp.func
def ray_origin(p: wp.vec3, n: wp.vec3, off: float) -> wp.vec3:
    """Shadow-ray origin: ``p`` moved ``off`` (:func:`~wsoft.scene.offsets.ray_offset`) off its
    surface along the (camera-facing) normal ``n``, to the visible side. Rays that would leave
    through the back (``not in_front(n, d)``) are never traced: the surface's own sheet blocks them
    (:mod:`wsoft.raster.horizon`)."""
    return p + n * off


@wp.func
def receiver_begin(gb: GBufferGPU, ls: LightSamples, i: int):
    """A receiver's shadow rays begin: (their offset, their origin, and the light-sample stream's
    state, first table index and rotation)."""
    p = gb.pos[i]
    off = ray_offset(p, gb.err[i])
    o = ray_origin(p, gb.nrm[i], off)
    xy = gb_pixel(gb, i)
    state, base, rot = sampling_begin(ls, i, xy[0], xy[1])
    return off, o, state, base, rot


@wp.func
def shadow_ray_length(to_light: float, dmax: float, off: float) -> float:
    """How far a shadow ray from a receiver (its origin ``off`` off the surface) looks for a caster:
    to the light point (``to_light`` from the surface), or only ``dmax`` (``inputs:shadow:distance``,
    measured from the surface point) when ``dmax >= 0``."""
    t = to_light
    if dmax >= 0.0:
        t = wp.min(t, dmax)
    return wp.max(t - off, 0.0)


def ray_epsilon(gb) -> float:
    """The rounding scale of points on the frame's surfaces that keep no triangle of their own
    (``izb``'s sub-samples, :func:`~wsoft.scene.offsets.ray_offset`'s ``scale``): the largest of the
    G-buffer's per-sample ``err`` (the coordinates of the triangles in view), 0 with none."""
    e = gb.gpu().err.numpy()
    return float(e.max()) if e.size else 0.0
