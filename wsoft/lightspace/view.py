"""Views and texel maths: where a light (or a camera) looks, and how points map to its texels.

A :class:`LightView` is a perspective frustum from a local light's centre (rect, disk, sphere,
point, cylinder) or an orthographic box along a distant light, fitted to the receivers the camera sees
(:func:`~wsoft.lightspace.fit.fit_light_view`). On the device a view is a :class:`ViewGPU`. Coordinates, from world to texel:

* **view space** (:func:`view_of`): x, y along the view's axes, z the *linear* depth along its
  axis (what depth maps store);
* **window coordinates** (:func:`map_coords`): tangents (x/z, y/z) for a perspective view, world
  units for an orthographic one; the window ``(l, r, b, t)`` spans the map;
* **texel coordinates** (:func:`texel_of`): texel (i, j) covers ``[i, i+1) x [j, j+1)``, its
  centre at ``(i + 0.5, j + 0.5)``; texel (0, 0) is at window corner (l, b).

Everything else a shadow-map technique asks of a point lives here once: is it inside the map
(:func:`inside_map`), the receiver's tangent plane's depth along another ray
(:func:`receiver_plane_depth`), depth normalised to [0, 1] (:func:`normalised_depth`), bilinear
reads and the slope-scaled receiver bias.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from wsoft.scene.types import LIGHT_DISTANT, Light

DEPTH_CLEAR = 1.0e30  # value of texels no surface covers (finite on purpose)
MISS = wp.constant(-3.0e38)  # receiver_plane_depth: the ray does not meet the plane in front of the view
MAX_HALF_ANGLE = 80.0  # degrees: the widest half-angle a perspective light view may open
MAX_TAN = math.tan(math.radians(MAX_HALF_ANGLE))


def outside_view_warning(light: Light, what: str, remedy: str) -> str:
    """The warning for receivers a light's single-frustum view leaves out (``what``: how many of
    what, "12 of 3000 visible samples"): they are left unshadowed; ``remedy``: what the user can do
    (:func:`~wsoft.lightspace.cube.outside_view_remedy`)."""
    return (f"light {light.path}: {what} lie outside its single-frustum view (more than {MAX_HALF_ANGLE:g} degrees off its axis) and are "
            f"left unshadowed; {remedy}")


def to_frame(p: np.ndarray, origin: np.ndarray, axes: np.ndarray, threads: bool = True) -> np.ndarray:
    """``(p - origin) @ axes`` for an (N, 3) array (float64), without BLAS: a BLAS matrix product
    leaves OpenBLAS's threads spinning, taking the cores from the Warp launches that follow. Large
    arrays go in row blocks over the CPU thread pool (NumPy releases the GIL in its loops): the
    same operations on every element, so the same result. ``threads=False`` inside a pool task
    (a task waiting on tasks of the same pool could wait forever)."""
    p = np.asarray(p)
    out = np.empty((len(p), 3), np.float64)

    def block(a: int, b: int) -> None:
        for s in range(a, b, 8192):  # small blocks: the temporaries stay in cache
            e = min(s + 8192, b)
            d = p[s:e] - origin
            o = out[s:e]
            np.multiply(d[:, 0:1], axes[0], out=o)
            o += d[:, 1:2] * axes[1]
            o += d[:, 2:3] * axes[2]

    if not threads:
        block(0, len(p))
        return out
    from wsoft.parallel import run_row_blocks

    run_row_blocks(len(p), block)
    return out


@wp.struct
class ViewGPU:
    """A view on the device: a light view, or any pinhole / orthographic view a rasterizer targets."""

    origin: wp.vec3
    ax: wp.vec3
    ay: wp.vec3
    az: wp.vec3  # view axis (depth grows along it)
    persp: int
    window: wp.vec4  # l, r, b, t (tangents for perspective, world units for orthographic)
    scale: wp.vec2  # texels per window unit: width / (r - l), height / (t - b)
    near: float
    far: float
    width: int
    height: int


def boxes_in_view(view: "LightView", lo: np.ndarray, hi: np.ndarray, pad_texels: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Which world boxes (``lo``, ``hi``: [N, 3]) can put a fragment in ``view``, conservatively: a
    box is out when it lies wholly beyond the far depth, wholly before a perspective view's near
    plane, or (wholly in front of the view's origin) wholly outside its window widened by
    ``pad_texels``. Also per box whether a perspective view's origin lies inside it (its closed
    surfaces then keep every face). Returns (seen [N] bool, origin_inside [N] bool)."""
    lo = np.asarray(lo, np.float64).reshape(-1, 3)
    hi = np.asarray(hi, np.float64).reshape(-1, 3)
    n = len(lo)
    if n == 0:
        return np.zeros(0, bool), np.zeros(0, bool)
    corners = np.stack([np.where([(k >> 0) & 1, (k >> 1) & 1, (k >> 2) & 1], hi, lo) for k in range(8)], axis=1)  # [N, 8, 3]
    v = to_frame(corners.reshape(-1, 3), view.origin, view.axes).reshape(n, 8, 3)
    z = v[..., 2]
    l, r, b, t = view.window
    px = pad_texels * (r - l) / view.width
    py = pad_texels * (t - b) / view.height
    seen = ~(z.min(axis=1) > view.far)
    if view.persp:
        seen &= ~(z.max(axis=1) < view.near)
        front = z.min(axis=1) > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            x = v[..., 0] / np.where(front[:, None], z, 1.0)
            y = v[..., 1] / np.where(front[:, None], z, 1.0)
        out = front & ((x.max(axis=1) < l - px) | (x.min(axis=1) > r + px) | (y.max(axis=1) < b - py) | (y.min(axis=1) > t + py))
        seen &= ~out
        o = np.asarray(view.origin, np.float64)
        inside = np.all((lo <= o) & (o <= hi), axis=1)
    else:
        out = (v[..., 0].max(axis=1) < l - px) | (v[..., 0].min(axis=1) > r + px) | (v[..., 1].max(axis=1) < b - py) | (v[..., 1].min(axis=1) > t + py)
        seen &= ~out
        inside = np.zeros(n, bool)
    return seen, inside


@dataclass
class LightView:
    """Where a light looks: frame, window and depth range. Texel (0, 0) is at (l, b)."""

    light_path: str
    persp: bool
    origin: np.ndarray
    axes: np.ndarray  # 3x3 columns: x, y, view axis
    window: tuple[float, float, float, float]
    near: float
    far: float
    width: int
    height: int
    receivers_outside: int = 0
    receivers_behind: int = 0  # receivers behind a rect or disk light's emitting plane (neither fitted nor outside)
    extent: float = 1.0  # the frame's scale: diagonal of the receivers' bounds with the light's position (see frame_extent)
    growth: float = 0.0  # how far a soft view's window was widened for casters beyond the receivers (window units)
    # a stable view's quantities (wsoft.lightspace.stable): ladder radius, texel size (window units),
    # window centre in whole texels from its anchor (snap_offset), depth step; None: a fitted view
    snap: dict | None = None
    face: int = -1  # a cube map's face (wsoft.lightspace.cube.FACE_NAMES); -1: a single view
    nearest_caster: float = math.inf  # a local light's view: depth of the nearest caster vertex in front of it (inf: none known)

    def gpu(self) -> ViewGPU:
        g = ViewGPU()
        g.origin = wp.vec3(*self.origin)
        g.ax = wp.vec3(*self.axes[:, 0])
        g.ay = wp.vec3(*self.axes[:, 1])
        g.az = wp.vec3(*self.axes[:, 2])
        g.persp = int(self.persp)
        g.window = wp.vec4(*self.window)
        l, r, b, t = self.window
        g.scale = wp.vec2(self.width / (r - l), self.height / (t - b))
        g.near = float(self.near)
        g.far = float(self.far)
        g.width = int(self.width)
        g.height = int(self.height)
        return g

    def to_view(self, p: np.ndarray) -> np.ndarray:
        return to_frame(np.asarray(p, np.float64), self.origin, self.axes)

    def texel_coords(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Continuous texel coordinates (x, y) of the world points ``p`` in front of the view
        (perspective: beyond the near plane), as the rasterizer places them."""
        v = self.to_view(p)
        if self.persp:
            v = v[v[:, 2] > self.near]
            x, y = v[:, 0] / v[:, 2], v[:, 1] / v[:, 2]
        else:
            x, y = v[:, 0], v[:, 1]
        l, r, b, t = self.window
        return (x - l) / (r - l) * self.width, (y - b) / (t - b) * self.height


LIGHT_REACH = 4.0  # a local light counts in the frame's extent up to this many receiver diagonals from the receivers' bounds


def frame_extent(receivers: np.ndarray, light: Light | None = None) -> float:
    """The frame's scale, which every scale-dependent default (depth biases, ray offsets, near
    planes) is a fraction of: the diagonal of the bounds of the receivers the camera sees, with a
    local light's position (its reach) moved to within :data:`LIGHT_REACH` receiver diagonals of
    them. Geometry out of view (a far ground, a stray huge triangle) does not change it, unlike the
    scene's bounds, and neither does a light's distance: a lamp kilometres away scales nothing
    (offsets and biases proportional to its distance would step over the casters)."""
    rec = np.asarray(receivers, np.float64).reshape(-1, 3)
    if len(rec) == 0:
        return frame_extent_of_bounds(None, None, light)
    return frame_extent_of_bounds(rec.min(axis=0), rec.max(axis=0), light)


def far_light(light: Light, lo: np.ndarray | None, hi: np.ndarray | None) -> bool:
    """Is a local light farther than :data:`LIGHT_REACH` receiver diagonals from the receivers'
    bounds ``lo``, ``hi`` (where :func:`frame_extent` stops following it)?"""
    if light.kind == LIGHT_DISTANT or lo is None:
        return False
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    reach = LIGHT_REACH * float(np.linalg.norm(hi - lo))
    q = np.asarray(light.position, np.float64)
    return bool(reach > 0.0 and np.any((q < lo - reach) | (q > hi + reach)))


def frame_extent_of_bounds(lo: np.ndarray | None, hi: np.ndarray | None, light: Light | None = None) -> float:
    """:func:`frame_extent` from the receivers' bounds (``None``: no receiver)."""
    pts = [] if lo is None else [np.asarray(lo, np.float64), np.asarray(hi, np.float64)]
    if light is not None and light.kind != LIGHT_DISTANT:
        q = np.asarray(light.position, np.float64)
        if pts:
            reach = LIGHT_REACH * float(np.linalg.norm(pts[1] - pts[0]))
            if reach > 0.0:
                q = np.clip(q, pts[0] - reach, pts[1] + reach)
        pts.append(q)
    if not pts:
        return 1.0
    box = np.stack(pts)
    ext = float(np.linalg.norm(box.max(axis=0) - box.min(axis=0)))
    return ext if math.isfinite(ext) and ext > 0.0 else max(float(np.abs(box).max(initial=0.0)), 1e-6)


# --------------------------------------------------------------------------- device maths


@wp.func
def view_of(lv: ViewGPU, p: wp.vec3) -> wp.vec3:
    """A world point in view space (x, y, linear depth z)."""
    d = p - lv.origin
    return wp.vec3(wp.dot(d, lv.ax), wp.dot(d, lv.ay), wp.dot(d, lv.az))


@wp.func
def view_dir(lv: ViewGPU, n: wp.vec3) -> wp.vec3:
    """A world direction in view space."""
    return wp.vec3(wp.dot(n, lv.ax), wp.dot(n, lv.ay), wp.dot(n, lv.az))


@wp.func
def in_front_of_light(lv: ViewGPU, v: wp.vec3) -> bool:
    """Is the view-space point inside the view's depth range on the light's side (perspective:
    beyond the near plane)? Receivers that are not have nothing mapped between them and the light."""
    return lv.persp == 0 or v[2] > lv.near


@wp.func
def map_coords(lv: ViewGPU, v: wp.vec3) -> wp.vec2:
    """Window coordinates of a view-space point."""
    if lv.persp != 0:
        return wp.vec2(v[0] / v[2], v[1] / v[2])
    return wp.vec2(v[0], v[1])


@wp.func
def texel_of(lv: ViewGPU, v: wp.vec3) -> wp.vec2:
    """Continuous texel coordinates of a view-space point (texel centres at integer + 0.5)."""
    x = v[0]
    y = v[1]
    if lv.persp != 0:
        inv = 1.0 / v[2]
        x = x * inv
        y = y * inv
    return wp.vec2((x - lv.window[0]) * lv.scale[0], (y - lv.window[2]) * lv.scale[1])


@wp.func
def window_to_texel(lv: ViewGPU, m: wp.vec2) -> wp.vec2:
    """Texel coordinates of window coordinates ``m``."""
    return wp.vec2((m[0] - lv.window[0]) * lv.scale[0], (m[1] - lv.window[2]) * lv.scale[1])


@wp.func
def inside_map(lv: ViewGPU, t: wp.vec2) -> bool:
    """Do continuous texel coordinates ``t`` fall on a texel of the map (0 <= t < size)?"""
    return t[0] >= 0.0 and t[1] >= 0.0 and t[0] < float(lv.width) and t[1] < float(lv.height)


@wp.func
def texel_size(lv: ViewGPU) -> wp.vec2:
    """One texel in window units, along x and y."""
    return wp.vec2((lv.window[1] - lv.window[0]) / float(lv.width), (lv.window[3] - lv.window[2]) / float(lv.height))


@wp.func
def texel_center(lv: ViewGPU, m: wp.vec2) -> wp.vec3:
    """Snap window coordinates to the centre of their texel: (cx, cy, 1), or (mx, my, 0) outside the map."""
    t = window_to_texel(lv, m)
    if not inside_map(lv, t):
        return wp.vec3(m[0], m[1], 0.0)
    x = wp.floor(t[0])
    y = wp.floor(t[1])
    return wp.vec3(lv.window[0] + (x + 0.5) / lv.scale[0], lv.window[2] + (y + 0.5) / lv.scale[1], 1.0)


@wp.func
def depth_at(lv: ViewGPU, depth: wp.array2d[float], m: wp.vec2) -> float:
    """Stored depth of the texel holding window coordinates ``m`` (``DEPTH_CLEAR`` outside the map)."""
    t = window_to_texel(lv, m)
    if not inside_map(lv, t):
        return DEPTH_CLEAR
    return depth[int(t[1]), int(t[0])]


@wp.func
def caster_distance(lv: ViewGPU, pv: wp.vec3, m: wp.vec2, d: float) -> float:
    """Distance from the receiver (view-space point ``pv``) to the caster a depth map records at
    window coordinates ``m`` with linear depth ``d``: the point at depth ``d`` on the view's ray
    through ``m`` (through the light's centre for a perspective view, along the view axis for an
    orthographic one). With ``m`` the receiver's own map coordinates this is the distance along the
    receiver's ray toward the light's centre, (z - d) |pv| / z, exactly; it is what
    ``inputs:shadow:distance`` limits."""
    c = wp.vec3(m[0], m[1], d)
    if lv.persp != 0:
        c = wp.vec3(m[0] * d, m[1] * d, d)
    return wp.length(c - pv)


@wp.func
def within_distance(lv: ViewGPU, pv: wp.vec3, m: wp.vec2, d: float, dmax: float) -> bool:
    """Does the caster at (``m``, ``d``) count for the receiver ``pv``: always when ``dmax < 0`` (no
    ``inputs:shadow:distance``), else when it lies within ``dmax`` of it (:func:`caster_distance`)."""
    if dmax < 0.0:
        return True
    return caster_distance(lv, pv, m, d) <= dmax


@wp.func
def normalised_depth(d: float, zmin: float, zrange: float) -> float:
    """Linear depth ``d`` mapped to [0, 1] over [zmin, zmin + zrange]; empty texels
    (``DEPTH_CLEAR``) at 1, the far end."""
    if d >= DEPTH_CLEAR:
        return 1.0
    return wp.clamp((d - zmin) / zrange, 0.0, 1.0)


@wp.func
def receiver_plane_depth(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3, m: wp.vec2) -> float:
    """Depth at which the ray of window coordinates ``m`` meets the receiver's tangent plane
    (point ``pv``, normal ``nv``, view space): the receiver-plane depth. ``MISS`` where the ray
    runs along the plane or meets it behind a perspective view's origin."""
    if lv.persp != 0:
        den = nv[0] * m[0] + nv[1] * m[1] + nv[2]
        if wp.abs(den) < 1.0e-6:
            return MISS
        z = wp.dot(nv, pv) / den
        if z <= 0.0:
            return MISS
        return z
    if wp.abs(nv[2]) < 1.0e-6:
        return MISS
    return pv[2] - (nv[0] * (m[0] - pv[0]) + nv[1] * (m[1] - pv[1])) / nv[2]


@wp.func
def receiver_plane_affine(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3):
    """The receiver's tangent plane (point ``pv``, normal ``nv``, view space) over the map's texel
    coordinates, where it is affine in q = depth (orthographic) or q = 1 / depth (perspective):
    (ok, texel of ``pv``, q there, dq/dx, dq/dy). Not ok where the light sees the plane edge-on."""
    xp = texel_of(lv, pv)
    if lv.persp != 0:
        npv = wp.dot(nv, pv)
        if pv[2] <= 0.0 or wp.abs(npv) < 1.0e-6 * wp.length(pv):
            return False, xp, 0.0, 0.0, 0.0
        k = 1.0 / npv  # q(m) = k (nv . (m, 1)) over window coordinates m
        return True, xp, 1.0 / pv[2], k * nv[0] / lv.scale[0], k * nv[1] / lv.scale[1]
    if wp.abs(nv[2]) < 1.0e-6:
        return False, xp, 0.0, 0.0, 0.0
    return True, xp, pv[2], -nv[0] / (nv[2] * lv.scale[0]), -nv[1] / (nv[2] * lv.scale[1])


@wp.func
def receiver_plane_range(lv: ViewGPU, xp: wp.vec2, qp: float, gx: float, gy: float, xa: float, ya: float, xb: float, yb: float) -> wp.vec2:
    """The nearest and farthest depths of a plane (:func:`receiver_plane_affine`) over the texel
    rectangle [xa, xb] x [ya, yb]; (-1, 1e30) where it passes behind a perspective view's origin
    there (no bound)."""
    qc = qp + gx * (0.5 * (xa + xb) - xp[0]) + gy * (0.5 * (ya + yb) - xp[1])
    h = 0.5 * ((xb - xa) * wp.abs(gx) + (yb - ya) * wp.abs(gy))
    if lv.persp != 0:
        if qc - h <= 0.0:
            return wp.vec2(-1.0, 1.0e30)
        return wp.vec2(1.0 / (qc + h), 1.0 / (qc - h))
    return wp.vec2(qc - h, qc + h)


@wp.func
def receiver_plane_at(lv: ViewGPU, ok: bool, xp: wp.vec2, qp: float, gx: float, gy: float, t: wp.vec2, fallback: float) -> float:
    """The depth of a plane (:func:`receiver_plane_affine`: ``ok``, ``xp``, ``qp``, ``gx``,
    ``gy``) at texel coordinates ``t``; ``fallback`` where it is not ok or passes behind a
    perspective view's origin there."""
    if not ok:
        return fallback
    q = qp + gx * (t[0] - xp[0]) + gy * (t[1] - xp[1])
    if lv.persp != 0:
        if q <= 0.0:
            return fallback
        return 1.0 / q
    return q


@wp.func
def receiver_plane_depth_or(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3, m: wp.vec2, fallback: float) -> float:
    """:func:`receiver_plane_depth`, or ``fallback`` where the ray misses the plane."""
    z = receiver_plane_depth(lv, pv, nv, m)
    if z <= MISS:
        return fallback
    return z


@wp.func
def light_facing(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3) -> wp.vec3:
    """The receiver's normal (view space) turned toward the light's centre."""
    to_light = wp.vec3(0.0, 0.0, -1.0)
    if lv.persp != 0:
        to_light = -pv
    if wp.dot(nv, to_light) < 0.0:
        return -nv
    return nv


@wp.func
def plane_depth_step(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3, z: float) -> float:
    """How much the depth of the receiver's tangent plane (point ``pv``, normal ``nv``, view space)
    changes across one texel (|dz/dx| + |dz/dy|, texel coordinates) where it lies at depth ``z``,
    at most that of a plane at tan 10 to the view's rays (edge-on planes do not run to infinity)."""
    tx = 1.0 / lv.scale[0]
    ty = 1.0 / lv.scale[1]
    cap = 10.0 * wp.max(tx, ty)
    if lv.persp != 0:
        cap = cap * z
        npv = wp.dot(nv, pv)
        if wp.abs(npv) < 1.0e-12:
            return cap
        # q = 1/z is affine over window coordinates: dq/dm = nv.xy / (nv . pv), dz = -z^2 dq
        return wp.min(z * z * (wp.abs(nv[0]) * tx + wp.abs(nv[1]) * ty) / wp.abs(npv), cap)
    if wp.abs(nv[2]) < 1.0e-12:
        return cap
    return wp.min((wp.abs(nv[0]) * tx + wp.abs(nv[1]) * ty) / wp.abs(nv[2]), cap)


@wp.func
def receiver_tap_depth(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3, m: wp.vec2, slope_texels: float) -> float:
    """The depth a filter tap at window coordinates ``m`` compares the receiver (view-space point
    ``pv``, normal ``nv``) at, the receiver-plane depth bias: its tangent plane's depth at the
    centre of the tap's texel (where the map was sampled), nearer by ``slope_texels`` times the
    plane's depth step per texel there (:func:`plane_depth_step`). The step covers the map's own
    error, which grows with it: a plane seen at a grazing angle changes depth fast across a texel,
    and a float32 rasterizer interpolating 1/z from corners clipped near the light misplaces it by
    a small fraction of a texel. ``pv``'s own depth where the tap is off the map or its ray misses
    the plane."""
    c = texel_center(lv, m)
    if c[2] == 0.0:
        return pv[2]
    z = receiver_plane_depth(lv, pv, nv, wp.vec2(c[0], c[1]))
    if z <= MISS:
        return pv[2]
    return z - slope_texels * plane_depth_step(lv, pv, nv, z)


@wp.func
def normal_offset(lv: ViewGPU, pv: wp.vec3, nv: wp.vec3, texels: float) -> wp.vec3:
    """The receiver (view-space point ``pv``, normal ``nv``) moved toward the light along its
    light-facing normal by ``texels`` times a texel's world size at its depth (the normal-offset
    bias)."""
    t = wp.max(1.0 / lv.scale[0], 1.0 / lv.scale[1])
    if lv.persp != 0:
        t = t * wp.abs(pv[2])
    return pv + light_facing(lv, pv, nv) * (texels * t)


@wp.func
def bilinear_cell(lv: ViewGPU, m: wp.vec2) -> wp.vec4:
    """Bilinear footprint of window coordinates ``m``: (x0, y0, ax, ay) with the texel pair
    (x0, x0 + 1) x (y0, y0 + 1) and weights ax, ay toward the second of each pair."""
    t = window_to_texel(lv, m)
    fx = t[0] - 0.5
    fy = t[1] - 0.5
    x0 = wp.floor(fx)
    y0 = wp.floor(fy)
    return wp.vec4(x0, y0, fx - x0, fy - y0)


@wp.func
def bilinear(lv: ViewGPU, tex: wp.array2d(dtype=Any), m: wp.vec2):
    """Bilinear read of a map (any vector or float texel type) at window coordinates ``m``, clamped at the edges."""
    c = bilinear_cell(lv, m)
    xa = wp.clamp(int(c[0]), 0, lv.width - 1)
    xb = wp.clamp(int(c[0]) + 1, 0, lv.width - 1)
    ya = wp.clamp(int(c[1]), 0, lv.height - 1)
    yb = wp.clamp(int(c[1]) + 1, 0, lv.height - 1)
    top = tex[ya, xa] * (1.0 - c[2]) + tex[ya, xb] * c[2]
    bot = tex[yb, xa] * (1.0 - c[2]) + tex[yb, xb] * c[2]
    return top * (1.0 - c[3]) + bot * c[3]
