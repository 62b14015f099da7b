"""Dual-paraboloid maps: two hemispherical light views around a local light that surrounds its
receivers, the alternative to a cube map's six faces (:mod:`wsoft.lightspace.cube`) for the
techniques that take ``omni=paraboloid`` (``hard``, ``pcf``).

A direction ``q`` from the light's centre, in the light's cube frame
(:func:`~wsoft.lightspace.cube.cube_frame`), belongs to hemisphere 0 when ``q_z >= 0`` and to
hemisphere 1 otherwise, and lands at ``(u, v) = (q_x, q_y) / (1 + |q_z|)`` on its paraboloid (Heidrich
and Seidel's parabolic map): the hemisphere fills the unit disk. The inverse,
``q = (2u, 2v, ±(1 - u² - v²)) / (1 + u² + v²)``, holds past the unit disk too, where it gives the
directions just across the equator: each hemisphere's window is the disk of radius ``R > 1``, a
*guard band* of the technique's kernel width (as a cube face's), so a kernel that crosses the
equator reads the neighbouring directions from its own map.

A texel holds the **distance** from the light's centre to the first caster along its centre's
direction (a paraboloid has no one view axis to measure depth along). The receiver's depth at a
tap is the distance along the tap texel's direction to the receiver's tangent plane (exact for a
planar receiver), less ``plane_slope`` times that distance's step to the next texel and a
constant bias: the receiver-plane bias of the perspective views, in the paraboloid's terms.

Angular texel size varies across a hemisphere: ``dθ = 2 du cos²(θ/2)``, the axis's texels twice
as wide as the equator's; at one map size per side a paraboloid's texels at its axis are about
twice as wide as a cube face's at its centre (``4R/size`` radians against ``2T/size``).

The maps are drawn by one BVH ray per texel (:mod:`wsoft.raster.paraboloid`): a paraboloid bends
a triangle's edges, which a triangle rasterizer draws straight (it would need the triangles
tessellated finely enough for the bend to vanish)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.lightspace.samples import to_light_coords
from wsoft.lightspace.view import to_frame
from wsoft.scene.types import Light

OMNI_MAPS = ("cube", "paraboloid")
"""What a technique with ``omni`` draws where a light's receivers call for more than one frustum."""
HEMISPHERES = ("+z", "-z")


@wp.struct
class ParaboloidGPU:
    """A dual-paraboloid map's geometry on the device."""

    origin: wp.vec3
    rows: wp.mat33  # world direction -> the light's cube frame (rows are its axes)
    size: int  # texels per side of each hemisphere's map
    radius: float  # the window's half-width in paraboloid coordinates (R: 1 plus the guard band)
    near: float  # rays start this far from the centre (outside the light's bound)
    drawn0: int  # hemisphere 0 drawn (1) or empty (0)
    drawn1: int


@dataclass
class ParaboloidView:
    """The host side of a dual-paraboloid map (:func:`fit_paraboloid_view`)."""

    light_path: str
    origin: np.ndarray  # the light's centre
    frame: np.ndarray  # 3 x 3, columns: the cube frame's axes (the paraboloids' axes are ±frame[:, 2])
    size: int
    radius: float
    near: float
    drawn: tuple[int, ...]  # the hemispheres drawn (0, 1)
    extent: float  # the frame's extent (receivers in view and the light): biases are fractions of it
    receivers: dict  # receivers per hemisphere (by name)
    at_light: int  # receivers at the light's centre (no direction to it)

    def gpu(self) -> ParaboloidGPU:
        g = ParaboloidGPU()
        g.origin = wp.vec3(*[float(x) for x in self.origin])
        g.rows = wp.mat33(*[float(x) for x in self.frame.T.ravel()])
        g.size = int(self.size)
        g.radius = float(self.radius)
        g.near = float(self.near)
        g.drawn0 = int(0 in self.drawn)
        g.drawn1 = int(1 in self.drawn)
        return g

    @property
    def texels(self) -> int:
        return len(self.drawn) * self.size * self.size


def hemisphere_of(q: np.ndarray) -> np.ndarray:
    """The hemisphere of each direction (rows of ``q``, in the cube frame): 0 where ``q_z >= 0``."""
    return (np.asarray(q, np.float64).reshape(-1, 3)[:, 2] < 0.0).astype(np.int32)


def fit_paraboloid_view(light: Light, receivers: np.ndarray, size: int, guard_texels: float, extent: float) -> ParaboloidView:
    """The dual-paraboloid map of ``light`` for ``receivers`` (world [N, 3]): the hemispheres that
    own a receiver are drawn; rays start outside the light's bound (its enclosing ball), or at half
    the nearest receiver's distance if that is nearer."""
    from wsoft.lightspace.cube import cube_frame, guard_window
    from wsoft.lightspace.light import light_bound

    rec = np.asarray(receivers, np.float64).reshape(-1, 3)
    origin = np.asarray(light.position, np.float64)
    frame = cube_frame(light)
    q = to_frame(rec, origin, frame)
    dist = np.linalg.norm(q, axis=1)
    at_light = dist <= 1e-7 * extent
    hemi = hemisphere_of(q)
    hemi[at_light] = -1
    # a hemisphere is drawn when it owns a receiver, or one within rounding of the equator (float32 on the device may place it there)
    band = np.abs(q[:, 2]) <= 1e-5 * dist
    drawn = tuple(h for h in (0, 1) if np.any(hemi == h) or np.any(band & ~at_light))
    _, bound, _ = light_bound(light)
    near = max(1.0001 * bound, 1e-4 * extent, 1e-7)
    if np.any(~at_light):
        near = min(near, 0.5 * float(dist[~at_light].min()))
    return ParaboloidView(light_path=light.path, origin=origin.copy(), frame=frame, size=int(size),
                          radius=guard_window(guard_texels, size), near=float(near), drawn=drawn, extent=float(extent),
                          receivers={HEMISPHERES[h]: int(np.count_nonzero(hemi == h)) for h in (0, 1)},
                          at_light=int(at_light.sum()))


@wp.func
def paraboloid_coords(dp: ParaboloidGPU, d: wp.vec3) -> wp.vec3:
    """(hemisphere, x, y) of the direction ``d`` (world, any length): continuous texel coordinates
    in its hemisphere's map."""
    q = wp.normalize(dp.rows * d)
    h = float(0.0)
    if q[2] < 0.0:
        h = 1.0
    s = 1.0 + wp.abs(q[2])
    scale = 0.5 * float(dp.size) / dp.radius
    return wp.vec3(h, (q[0] / s + dp.radius) * scale, (q[1] / s + dp.radius) * scale)


@wp.func
def paraboloid_direction(dp: ParaboloidGPU, h: int, x: float, y: float) -> wp.vec3:
    """The world unit direction at texel coordinates (``x``, ``y``) of hemisphere ``h``'s map
    (past the unit disk: the directions across the equator)."""
    u = (2.0 * x / float(dp.size) - 1.0) * dp.radius
    v = (2.0 * y / float(dp.size) - 1.0) * dp.radius
    r2 = u * u + v * v
    z = 1.0 - r2
    if h != 0:
        z = -z
    q = wp.vec3(2.0 * u, 2.0 * v, z) / (1.0 + r2)
    return wp.transpose(dp.rows) * q


@wp.func
def plane_distance(rel: wp.vec3, n: wp.vec3, d: wp.vec3, dist: float) -> float:
    """Distance from the light's centre along the unit direction ``d`` to the receiver's tangent
    plane (through ``rel``, the receiver relative to the centre, normal ``n``), kept within
    [dist/2, 2 dist] of the receiver's own distance ``dist`` (a tap whose ray runs nearly along the
    plane would reach it far away)."""
    den = wp.dot(d, n)
    num = wp.dot(rel, n)
    t = dist
    if wp.abs(den) > 1.0e-8 and num * den > 0.0:
        t = num / den
    return wp.clamp(t, 0.5 * dist, 2.0 * dist)


@wp.kernel
def shade_paraboloid(
    offset: int,
    dp: ParaboloidGPU,
    depth: wp.array3d[float],
    pos: wp.array[wp.vec3],
    nrm: wp.array[wp.vec3],
    prim: wp.array[wp.int32],
    taps: wp.array[wp.vec2],
    ntaps: int,
    disk: int,
    radius: float,
    bias: float,
    plane_slope: float,
    dmax: float,
    eps: float,
    # outputs
    vis: wp.array[float],
    state: wp.array[wp.int32],
):
    """Per G-buffer sample, the fraction of ``taps`` (unit-square points, offsets of ``radius``
    texels around the receiver's texel coordinates; ``ntaps`` 1 with ``radius`` 0: the classic
    shadow map's one texel) where the receiver is lit. ``state``: the hemisphere read, 2 for
    background, -1 for a receiver at the light's centre (no direction: V = 1)."""
    i = wp.tid() + offset
    if prim[i] < 0:
        vis[i] = 1.0
        state[i] = 2
        return
    rel = pos[i] - dp.origin
    dist = wp.length(rel)
    if dist <= eps:
        vis[i] = 1.0
        state[i] = -1
        return
    n = nrm[i]
    c = paraboloid_coords(dp, rel)
    h = int(c[0])
    state[i] = h
    last = dp.size - 1
    lit = float(0.0)
    for k in range(ntaps):
        o = to_light_coords(taps[k], disk)
        x = wp.clamp(int(wp.floor(c[1] + o[0] * radius)), 0, last)
        y = wp.clamp(int(wp.floor(c[2] + o[1] * radius)), 0, last)
        xc = float(x) + 0.5
        yc = float(y) + 0.5
        zr = plane_distance(rel, n, paraboloid_direction(dp, h, xc, yc), dist)
        step_x = wp.abs(plane_distance(rel, n, paraboloid_direction(dp, h, xc + 1.0, yc), dist) - zr)
        step_y = wp.abs(plane_distance(rel, n, paraboloid_direction(dp, h, xc, yc + 1.0), dist) - zr)
        zr = zr - plane_slope * wp.max(step_x, step_y) - bias
        d = depth[h, y, x]
        if zr <= d:
            lit += 1.0
        elif dmax >= 0.0 and zr - d > dmax:  # inputs:shadow:distance: a caster farther from the receiver does not count
            lit += 1.0
    vis[i] = lit / float(ntaps)


@dataclass
class ParaboloidMap:
    """A dual-paraboloid depth map: ``depth`` [2, size, size] float32, distances from the light's
    centre (``DEPTH_CLEAR`` where nothing was hit, outside the window and in a hemisphere not drawn)."""

    view: ParaboloidView
    depth: wp.array
    alpha_tested: bool
    rays: int



def guard_texels_for(kernel_radius: float) -> float:
    """The guard band (texels past the unit disk) a kernel of half-width ``kernel_radius`` texels
    reads across the equator: its half-width, a texel for the tap's rounding and one for the
    receiver-plane step."""
    return float(kernel_radius) + 2.0


def paraboloid_visibility(dm: ParaboloidMap, gb, taps, ntaps: int, disk: bool, radius: float, bias: float, plane_slope: float,
                          dmax: float, device: str) -> tuple[wp.array, int]:
    """Per G-buffer sample of ``gb``, the fraction of ``taps`` lit in ``dm`` (:func:`shade_paraboloid`;
    ``bias`` a fraction of the map's extent); and how many covered samples lie at the light's centre
    (V = 1 there: they have no direction to it)."""
    from wsoft.parallel import launch_chunked

    vis = wp.empty(gb.count, dtype=float, device=device)
    state = wp.empty(gb.count, dtype=wp.int32, device=device)
    launch_chunked(shade_paraboloid, gb.count,
                   inputs=[dm.view.gpu(), dm.depth, gb.pos, gb.nrm, gb.prim, taps, int(ntaps), int(disk), float(radius),
                           float(bias) * dm.view.extent, float(plane_slope), float(dmax), float(1e-7 * dm.view.extent)],
                   outputs=[vis, state], device=device, min_chunk=256)
    return vis, int(np.count_nonzero(state.numpy() == -1))
