"""What shadow-map filters share: map coordinates, the receiver plane, the light as a filter
kernel, tap patterns and depth look-ups.

Map coordinates are window units: tangents (x/z, y/z) for a perspective light view, world
units for an orthographic one; texel (i, j) covers ``[l + i*tw, l + (i+1)*tw]`` with
``tw = (r - l) / width``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from wsoft.raster.lightview import DEPTH_CLEAR, LightViewGPU
from wsoft.scene.light_gpu import concentric_disk
from wsoft.scene.types import LIGHT_DISTANT, LIGHT_RECT, Light


@wp.struct
class LightKernel:
    """The light as a filter sees it from the light view's centre.

    ``disk``: 1 for a disk-shaped light (disk, sphere, distant), 0 for a rectangle.
    ``half``: local lights: half-extent in world units along the map's x and y;
    distant lights: tan of the cone's half angle (both components).
    """

    disk: int
    half: wp.vec2


def light_kernel(light: Light) -> LightKernel:
    k = LightKernel()
    if light.kind == LIGHT_RECT:
        k.disk = 0
        k.half = wp.vec2(*light.half_size)
    elif light.kind == LIGHT_DISTANT:
        k.disk = 1
        t = math.tan(math.radians(0.5 * light.angle_deg))
        k.half = wp.vec2(t, t)
    else:
        k.disk = 1
        k.half = wp.vec2(light.radius, light.radius)
    return k


@wp.func
def map_coords(lv: LightViewGPU, v: wp.vec3) -> wp.vec2:
    """Window coordinates of a view-space point."""
    if lv.persp != 0:
        return wp.vec2(v[0] / v[2], v[1] / v[2])
    return wp.vec2(v[0], v[1])


@wp.func
def texel_size(lv: LightViewGPU) -> wp.vec2:
    """One texel in window units, along x and y."""
    return wp.vec2((lv.window[1] - lv.window[0]) / float(lv.width), (lv.window[3] - lv.window[2]) / float(lv.height))


@wp.func
def texel_center(lv: LightViewGPU, m: wp.vec2) -> wp.vec3:
    """Snap window coordinates to the centre of their texel: (cx, cy, valid)."""
    fx = (m[0] - lv.window[0]) * lv.scale[0]
    fy = (m[1] - lv.window[2]) * lv.scale[1]
    if fx < 0.0 or fy < 0.0 or fx >= float(lv.width) or fy >= float(lv.height):
        return wp.vec3(m[0], m[1], 0.0)
    x = wp.floor(fx)
    y = wp.floor(fy)
    return wp.vec3(lv.window[0] + (x + 0.5) / lv.scale[0], lv.window[2] + (y + 0.5) / lv.scale[1], 1.0)


@wp.func
def depth_at(lv: LightViewGPU, depth: wp.array2d[float], m: wp.vec2) -> float:
    """Stored depth of the texel holding window coordinates ``m`` (``DEPTH_CLEAR`` outside)."""
    fx = (m[0] - lv.window[0]) * lv.scale[0]
    fy = (m[1] - lv.window[2]) * lv.scale[1]
    if fx < 0.0 or fy < 0.0 or fx >= float(lv.width) or fy >= float(lv.height):
        return DEPTH_CLEAR
    return depth[int(fy), int(fx)]


@wp.func
def bilinear_cell(lv: LightViewGPU, m: wp.vec2) -> wp.vec4:
    """Bilinear footprint of window coordinates ``m``: (x0, y0, ax, ay) with the texel pair
    (x0, x0 + 1) x (y0, y0 + 1) and weights ax, ay toward the second of each pair."""
    fx = (m[0] - lv.window[0]) * lv.scale[0] - 0.5
    fy = (m[1] - lv.window[2]) * lv.scale[1] - 0.5
    x0 = wp.floor(fx)
    y0 = wp.floor(fy)
    return wp.vec4(x0, y0, fx - x0, fy - y0)


@wp.func
def bilinear(lv: LightViewGPU, tex: wp.array2d(dtype=Any), m: wp.vec2):
    """Bilinear read of a map (any vector or float texel type) at window coordinates ``m``, clamped at the edges."""
    c = bilinear_cell(lv, m)
    xa = wp.clamp(int(c[0]), 0, lv.width - 1)
    xb = wp.clamp(int(c[0]) + 1, 0, lv.width - 1)
    ya = wp.clamp(int(c[1]), 0, lv.height - 1)
    yb = wp.clamp(int(c[1]) + 1, 0, lv.height - 1)
    top = tex[ya, xa] * (1.0 - c[2]) + tex[ya, xb] * c[2]
    bot = tex[yb, xa] * (1.0 - c[2]) + tex[yb, xb] * c[2]
    return top * (1.0 - c[3]) + bot * c[3]


@wp.func
def receiver_depth(lv: LightViewGPU, pv: wp.vec3, nv: wp.vec3, m: wp.vec2) -> float:
    """Depth at which the ray of window coordinates ``m`` meets the receiver's tangent plane
    (point ``pv``, normal ``nv``, view space): the receiver-plane depth. Falls back to the
    receiver's own depth where the plane is seen edge-on."""
    if lv.persp != 0:
        d = wp.vec3(m[0], m[1], 1.0)
        den = wp.dot(nv, d)
        if wp.abs(den) < 1.0e-6:
            return pv[2]
        z = wp.dot(nv, pv) / den
        if z <= 0.0:
            return pv[2]
        return z
    if wp.abs(nv[2]) < 1.0e-6:
        return pv[2]
    return pv[2] - (nv[0] * (m[0] - pv[0]) + nv[1] * (m[1] - pv[1])) / nv[2]


@wp.func
def view_dir(lv: LightViewGPU, n: wp.vec3) -> wp.vec3:
    """A world direction in view space."""
    return wp.vec3(wp.dot(n, lv.ax), wp.dot(n, lv.ay), wp.dot(n, lv.az))


@wp.func
def spread(lv: LightViewGPU, k: LightKernel, zb: float, zr: float) -> wp.vec2:
    """Half-size (window units) of the region over which a blocker at depth ``zb`` covers the
    light as seen from a receiver at depth ``zr``: w (1/zb - 1/zr) for a local light of
    half-extent w, (zr - zb) tan(a) for a distant light."""
    if lv.persp != 0:
        f = 1.0 / wp.max(zb, 1.0e-20) - 1.0 / wp.max(zr, 1.0e-20)
        return k.half * wp.max(f, 0.0)
    return k.half * wp.max(zr - zb, 0.0)


@wp.func
def spread_texels(lv: LightViewGPU, k: LightKernel, zb: float, zr: float, lo: float, hi: float) -> wp.vec2:
    """:func:`spread` in texels along x and y, clamped to [lo, hi]."""
    h = spread(lv, k, zb, zr)
    return wp.vec2(wp.clamp(h[0] * lv.scale[0], lo, hi), wp.clamp(h[1] * lv.scale[1], lo, hi))


@wp.func
def tap_offset(disk: int, u: wp.vec2) -> wp.vec2:
    """A tap in [-1, 1]^2 placed in the kernel's shape (the unit disk via the concentric map)."""
    if disk != 0:
        return concentric_disk(0.5 * (u[0] + 1.0), 0.5 * (u[1] + 1.0))
    return u


def tap_pattern(pattern: str, n: int, seed: int = 7) -> np.ndarray:
    """``n`` taps in [-1, 1]^2: a regular grid (n must be a perfect square) or a Poisson-disk set
    (dart throwing with a shrinking radius, deterministic)."""
    if pattern == "grid":
        m = math.isqrt(n)
        c = (np.arange(m) + 0.5) / m * 2.0 - 1.0
        gx, gy = np.meshgrid(c, c)
        return np.stack([gx.ravel(), gy.ravel()], -1).astype(np.float32)
    rng = np.random.default_rng(seed)
    r = 1.6 / math.sqrt(n)
    pts: list[np.ndarray] = []
    while len(pts) < n:
        for _ in range(2000):
            c = rng.uniform(-1.0, 1.0, 2)
            if all(np.hypot(*(c - q)) >= r for q in pts):
                pts.append(c)
                if len(pts) == n:
                    break
        r *= 0.9
    return np.asarray(pts, np.float32)


@dataclass
class Taps:
    """A tap pattern on a device (``wp.array`` of vec2) and its size."""

    array: wp.array
    count: int


def taps_on(device: str, pattern: str, n: int) -> Taps:
    pts = tap_pattern(pattern, n)
    return Taps(wp.array(pts, dtype=wp.vec2, device=device), len(pts))
