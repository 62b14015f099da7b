"""Filtering a depth map with taps: the percentage-closer filter shared by PCF and PCSS.

Taps are a :class:`~wsoft.lightspace.samples.SamplePattern` (unit-square points) seen as offsets
in the kernel's shape by :func:`~wsoft.lightspace.samples.to_light_coords`: ``[-1, 1]^2`` for a
square kernel, the unit disk for a disk-shaped light.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.lightspace.samples import SamplePattern, to_light_coords
from wsoft.lightspace.view import ViewGPU, depth_at, receiver_tap_depth, texel_center, within_distance

# a filter's depth bias, by name (its kernels' mode is the index): the receiver's tangent plane at
# each tap (receiver_tap_depth), the receiver moved along its normal (normal_offset), or its own
# depth with a slope-scaled bias (receiver_bias)
RECEIVER_BIASES = ("plane", "normal", "centre")

TAP_SEED = 7  # the Poisson taps' seed (deterministic patterns)


@dataclass
class Taps:
    """A tap pattern on a device (``wp.array`` of unit-square vec2) and its size."""

    array: wp.array
    count: int


def tap_pattern(pattern: str, n: int) -> np.ndarray:
    """``n`` taps in the unit square: ``grid`` (the centres of an m x m grid, n = m^2) or
    ``poisson`` (dart throwing with a shrinking radius, deterministic)."""
    kind = {"grid": "regular", "poisson": "poisson"}[pattern]
    return SamplePattern(kind, n, seed=TAP_SEED).points()[0]


def taps_on(device: str, pattern: str, n: int) -> Taps:
    pts = tap_pattern(pattern, n)
    return Taps(wp.array(pts.astype(np.float32), dtype=wp.vec2, device=device), len(pts))


@wp.func
def tap_lit(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3, m: wp.vec2, d: float, bias: float, use_plane: int, plane_slope: float,
            dmax: float) -> float:
    """1 where the receiver (view-space point ``pv``, normal ``nv``) is lit at the tap of window
    coordinates ``m`` whose texel stores depth ``d``, else 0: its depth there (with ``use_plane``
    its tangent plane's at the tap's texel centre less ``plane_slope`` of the plane's step per
    texel, :func:`~wsoft.lightspace.view.receiver_tap_depth`; else ``pv``'s own) less ``bias`` is
    not behind ``d``, or (``dmax >= 0``, ``inputs:shadow:distance``) the tap's caster lies farther
    than ``dmax`` from the receiver (:func:`~wsoft.lightspace.view.within_distance`)."""
    zr = pv[2]
    if use_plane != 0:
        zr = receiver_tap_depth(lv, pv, nv, m, plane_slope)
    if zr - bias <= d:
        return 1.0
    if dmax >= 0.0:
        c = texel_center(lv, m)
        if not within_distance(lv, pv, wp.vec2(c[0], c[1]), d, dmax):
            return 1.0
    return 0.0


@wp.func
def pcf_visibility(
    lv: ViewGPU,
    depth: wp.array2d[float],
    pv: wp.vec3,
    nv: wp.vec3,
    m0: wp.vec2,
    half: wp.vec2,
    disk: int,
    taps: wp.array[wp.vec2],
    ntaps: int,
    bias: float,
    use_plane: int,
    plane_slope: float,
    dmax: float,
) -> float:
    """Fraction of ``taps`` (offsets ``half`` x pattern around ``m0``, window units) where the
    receiver (view-space point ``pv``, normal ``nv``) is lit. With ``use_plane`` the receiver's
    depth at a tap is its tangent plane's at the tap's texel centre, less ``plane_slope`` times
    the plane's depth step per texel (:func:`~wsoft.lightspace.view.receiver_tap_depth`);
    otherwise ``pv``'s own depth. ``bias`` is subtracted either way. ``dmax >= 0``
    (``inputs:shadow:distance``): a tap's caster counts only within ``dmax`` of the receiver (the
    caster's point on the tap texel's ray, :func:`~wsoft.lightspace.view.caster_distance`)."""
    lit = float(0.0)
    for i in range(ntaps):
        o = to_light_coords(taps[i], disk)
        m = wp.vec2(m0[0] + o[0] * half[0], m0[1] + o[1] * half[1])
        lit += tap_lit(lv, pv, nv, m, depth_at(lv, depth, m), bias, use_plane, plane_slope, dmax)
    return lit / float(ntaps)
