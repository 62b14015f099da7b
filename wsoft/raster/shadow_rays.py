"""A receiver's shadow rays: where they start and how far they look.

Every pass that traces shadow rays from G-buffer samples (the reference, and the techniques that
test rays of their own: ``dcs``, ``pwedge``, ``izb``) builds them the same way: from the surface point moved off its surface along
the camera-facing normal by :func:`ray_offset` (a fraction :data:`RAY_EPSILON` of the frame's
extent, :func:`ray_epsilon`, at least a few float32 ulps of the point), to a point on the light,
for :func:`shadow_ray_length` (the light point, or ``inputs:shadow:distance``).
:func:`receiver_begin` sets up one receiver's rays and its light-sample stream.
"""

from __future__ import annotations

import warp as wp

from wsoft.lightspace.samples import LightSamples, sampling_begin
from wsoft.lightspace.view import frame_extent_of_bounds
from wsoft.raster.gbuffer import GBufferGPU, gb_pixel

RAY_EPSILON = 2.0e-5  # shadow-ray offset as a fraction of the frame's extent


@wp.func
def ray_offset(p: wp.vec3, eps: float) -> float:
    """The offset of a shadow ray's origin: ``eps`` (a fraction of the frame's extent), at least a
    few float32 ulps of the point's largest coordinate (far from the origin a fixed offset is lost)."""
    m = wp.max(wp.abs(p[0]), wp.max(wp.abs(p[1]), wp.abs(p[2])))
    return wp.max(eps, 2.0e-6 * m)


@wp.func
def ray_origin(p: wp.vec3, n: wp.vec3, off: float) -> wp.vec3:
    """Shadow-ray origin: ``p`` moved ``off`` (:func:`ray_offset`) off its surface along the
    (camera-facing) normal ``n``, to the visible side. Rays that would leave through the back
    (``not in_front(n, d)``) are never traced: the surface's own sheet blocks them
    (:mod:`wsoft.raster.horizon`)."""
    return p + n * off


@wp.func
def receiver_begin(gb: GBufferGPU, ls: LightSamples, eps: float, i: int):
    """A receiver's shadow rays begin: (their offset, their origin, and the light-sample stream's
    state, first table index and rotation)."""
    p = gb.pos[i]
    off = ray_offset(p, eps)
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


def ray_epsilon(gb, light) -> float:
    """Offset of shadow-ray origins along the normal: a fraction of the frame's extent (the
    receivers in view and the light, :func:`~wsoft.lightspace.view.frame_extent`), not of the
    scene's bounds, which a far or huge triangle can make as large as the whole frame."""
    b = gb.receiver_bounds()
    return RAY_EPSILON * (frame_extent_of_bounds(*b, light) if b is not None else frame_extent_of_bounds(None, None, light))
