"""Lights on the device: how to sample a point (or direction) on them, the light as a filter kernel
(its spread over a map from a blocker's depth), and the slope-scaled receiver bias.

A cylinder light is seen from a point ``p`` as its *silhouette rectangle* (:func:`silhouette_rect`),
as a sphere light is seen as its silhouette disk: the flat rectangle, as long as the cylinder,
between the two lines where the planes through ``p`` tangent to its side touch it. A light point
drawn uniformly on it is uniform in the cylinder's projected area seen from ``p`` (as a rect
light's, and a sphere's silhouette disk's, are), so ``V`` is the unoccluded fraction of the
cylinder's visible side weighted as it is seen, not by its surface area (which would over-count
the flanks seen edge-on). Exact but for the end caps' curved rims, which the rectangle cuts
square (a difference of the order of ``radius / distance``)."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from wsoft.lightspace.view import ViewGPU
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_DISK, LIGHT_DISTANT, LIGHT_RECT, Light
from wsoft.scene.ies import ies_angle

LINE_WIDTH = wp.constant(1.0e-3)
"""The half width, as a fraction of its half length, that a line light (a cylinder light of radius
0) takes where a technique measures the light by its area (``pwedge``'s coverage, the filter
kernels of :func:`light_kernel`): a rectangle that thin covers a segment's fraction to ~1e-3."""


@wp.struct
class LightGPU:
    kind: int  # LIGHT_RECT, LIGHT_DISK, LIGHT_SPHERE, LIGHT_DISTANT, LIGHT_POINT, LIGHT_CYLINDER
    position: wp.vec3
    ax: wp.vec3  # unit X axis (a cylinder's axis)
    ay: wp.vec3  # unit Y axis
    az: wp.vec3  # unit Z axis (rect/disk emit along -Z; distant light comes from +Z)
    half_size: wp.vec2  # rect half width / height; cylinder half length / radius
    radius: float  # disk / sphere / cylinder radius
    cos_max: float  # distant: cosine of the cone half angle
    far: float  # distant: length of shadow rays (4 scene diagonals, at most 1e30)
    aspect: wp.vec3  # disk / sphere: semi-axes along ax, ay, az over radius (the largest); (1, 1, 1) when round
    cone_cos: float  # ShapingAPI: cosine of the cone's angle off -Z (-2: no cone)
    soft_cos: float  # ShapingAPI: cosine of the angle inside which the cone's soft edge ends (= cone_cos: a hard edge)
    focus: float  # ShapingAPI: off-axis cosine power (0: none)
    focus_tint: wp.vec3  # ShapingAPI: the colour the focus fades toward
    shaped: int  # 1 where a cone, a focus or an IES profile shapes the emission (the reference weights its samples)
    ies_on: int  # 1 with an IES profile (shaping:ies:file)
    ies_scale: float  # 1 + shaping:ies:angleScale
    ies_v: wp.array[float]  # the profile's vertical angles (degrees off -Z, ascending); None without a profile
    ies_h: wp.array[float]  # its horizontal angles over 0..360 (degrees from +X toward +Y), symmetries unfolded
    ies_t: wp.array2d[float]  # its values [vertical, horizontal] over Shaping.ies_divisor


_IES_TABLES: dict = {}  # (profile, divisor, device) -> the three arrays: uploaded once per device


def ies_tables(light: Light, device) -> tuple[wp.array, wp.array, wp.array]:
    """The light's IES profile as the device reads it (:class:`LightGPU`'s ``ies_v``, ``ies_h``, ``ies_t``)."""
    sh = light.shaping
    key = (sh.ies, sh.ies_normalize, str(device))
    if key not in _IES_TABLES:
        v, h, t = sh.ies.full_table()
        _IES_TABLES[key] = (wp.array(v.astype(np.float32), dtype=float, device=device),
                            wp.array(h.astype(np.float32), dtype=float, device=device),
                            wp.array((t / sh.ies_divisor()).astype(np.float32), dtype=float, device=device))
    return _IES_TABLES[key]


def light_gpu(light: Light, scene_diagonal: float, device=None) -> LightGPU:
    g = LightGPU()
    g.kind = int(light.kind)
    g.position = wp.vec3(*np.asarray(light.position, np.float64))
    g.ax = wp.vec3(*light.frame[:, 0])
    g.ay = wp.vec3(*light.frame[:, 1])
    g.az = wp.vec3(*light.frame[:, 2])
    g.half_size = wp.vec2(*light.half_size)
    g.radius = float(light.radius)
    g.cos_max = float(math.cos(math.radians(0.5 * light.angle_deg)))
    g.far = float(min(4.0 * scene_diagonal, 1.0e30))  # reaches every caster; finite in float32 arithmetic
    g.aspect = wp.vec3(*light.aspect)
    coned = light.shaping.coned
    g.cone_cos = float(math.cos(math.radians(light.shaping.cone_deg))) if coned else -2.0
    g.soft_cos = float(math.cos(math.radians(light.shaping.cone_deg * (1.0 - light.shaping.softness)))) if coned else -2.0
    g.focus = float(light.shaping.focus) if light.kind != LIGHT_DISTANT else 0.0
    g.focus_tint = wp.vec3(*light.shaping.focus_tint)
    distant = light.kind == LIGHT_DISTANT
    g.shaped = int(light.shaping.shaped and not distant)
    g.ies_on = int(light.shaping.ies is not None and not distant)
    g.ies_scale = float(1.0 + light.shaping.ies_angle_scale)
    if g.ies_on:
        g.ies_v, g.ies_h, g.ies_t = ies_tables(light, device or "cpu")
    return g


@wp.func
def table_interval(a: wp.array[float], x: float) -> int:
    """The index ``i`` of the interval ``a[i] <= x < a[i + 1]`` of the ascending ``a`` (at least 2
    entries), clamped to ``[0, len - 2]`` (bisection)."""
    lo = int(0)
    hi = a.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if a[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@wp.func
def ies_factor(L: LightGPU, d: wp.vec3) -> float:
    """The IES profile's factor (:attr:`~wsoft.scene.shaping.Shaping.ies`, over its divisor) along
    the unit direction ``d`` from the light toward a receiver: its vertical angle ``theta`` off −Z
    taken through ``shaping:ies:angleScale`` (:func:`~wsoft.scene.ies.ies_angle`), its horizontal
    angle from +X toward +Y; bilinear in the two over the profile's angle sets, 0 outside its
    vertical range."""
    c = wp.clamp(-wp.dot(d, L.az), -1.0, 1.0)
    theta = wp.acos(c) * (180.0 / wp.pi)
    t = wp.clamp((theta - 180.0) / L.ies_scale + 180.0, 0.0, 180.0)
    nv = L.ies_v.shape[0]
    if t < L.ies_v[0] or t > L.ies_v[nv - 1]:
        return 0.0
    phi = wp.atan2(wp.dot(d, L.ay), wp.dot(d, L.ax)) * (180.0 / wp.pi)
    if phi < 0.0:
        phi = phi + 360.0
    ih = table_interval(L.ies_h, phi)
    fh = wp.clamp((phi - L.ies_h[ih]) / (L.ies_h[ih + 1] - L.ies_h[ih]), 0.0, 1.0)
    iv = int(0)
    fv = float(0.0)
    if nv > 1:
        iv = table_interval(L.ies_v, t)
        fv = wp.clamp((t - L.ies_v[iv]) / (L.ies_v[iv + 1] - L.ies_v[iv]), 0.0, 1.0)
    iv1 = wp.min(iv + 1, nv - 1)
    lo = (1.0 - fh) * L.ies_t[iv, ih] + fh * L.ies_t[iv, ih + 1]
    hi = (1.0 - fh) * L.ies_t[iv1, ih] + fh * L.ies_t[iv1, ih + 1]
    return (1.0 - fv) * lo + fv * hi


@wp.func
def shaping_weight(L: LightGPU, d: wp.vec3) -> wp.vec3:
    """The ``UsdLux.ShapingAPI`` factor on the light's emission (per colour channel) along the unit
    direction ``d`` from a point of the light toward a receiver, ``c = dot(d, -az)`` the cosine off
    its primary axis: 0 beyond the cone (``c < cos(angle)``); inside it, ``smoothstep`` from
    ``cos(angle)`` to ``cos(angle (1 - softness))`` (the soft edge; softness 0: 1 throughout);
    times ``f + (1 - f) focusTint`` with ``f = max(c, 0)^focus`` (focus 0: f = 1); times the IES
    profile's factor (:func:`ies_factor`) where the light has one."""
    c = -wp.dot(d, L.az)
    w = float(1.0)
    if L.ies_on != 0:
        w = ies_factor(L, d)
    if L.cone_cos > -1.5:
        if c < L.cone_cos:
            return wp.vec3(0.0)
        if L.soft_cos > L.cone_cos:
            w = w * wp.smoothstep(L.cone_cos, L.soft_cos, c)
    if L.focus > 0.0:
        f = wp.pow(wp.max(c, 0.0), L.focus)
        return w * (wp.vec3(f) + (1.0 - f) * L.focus_tint)
    return wp.vec3(w)


@wp.func
def sample_weight(L: LightGPU, d: wp.vec3) -> float:
    """The weight of a light sample seen along the shadow ray direction ``d`` (from the receiver
    toward the sample): the mean over the colour channels of :func:`shaping_weight` along ``-d``
    (from the sample toward the receiver). The reference's ``V = sum(visible w) / sum(w)`` of a
    shaped light."""
    s = shaping_weight(L, -d)
    return (s[0] + s[1] + s[2]) / 3.0


def shaping_weights(light: Light, d: np.ndarray) -> np.ndarray:
    """:func:`shaping_weight` on the host, for unit directions ``d`` ([N, 3], from the light toward
    receivers): [N, 3] factors."""
    d = np.asarray(d, np.float64).reshape(-1, 3)
    c = -(d @ np.asarray(light.frame, np.float64)[:, 2])
    w = np.ones(len(d))
    if light.shaping.coned:
        lo = math.cos(math.radians(light.shaping.cone_deg))
        hi = math.cos(math.radians(light.shaping.cone_deg * (1.0 - light.shaping.softness)))
        if hi > lo:
            t = np.clip((c - lo) / (hi - lo), 0.0, 1.0)
            w = t * t * (3.0 - 2.0 * t)
        w = np.where(c < lo, 0.0, w)
    if light.shaping.ies is not None and light.kind != LIGHT_DISTANT:
        w = w * ies_weights(light, d)
    if light.shaping.focus > 0.0 and light.kind != LIGHT_DISTANT:
        f = np.maximum(c, 0.0) ** light.shaping.focus
        return w[:, None] * (f[:, None] + (1.0 - f[:, None]) * np.asarray(light.shaping.focus_tint, np.float64)[None])
    return np.repeat(w[:, None], 3, axis=1)


def ies_weights(light: Light, d: np.ndarray) -> np.ndarray:
    """:func:`ies_factor` on the host, for unit directions ``d`` ([N, 3], from the light toward
    receivers), in float64: [N] factors."""
    F = np.asarray(light.frame, np.float64)
    c = np.clip(-(d @ F[:, 2]), -1.0, 1.0)
    sh = light.shaping
    theta = ies_angle(np.degrees(np.arccos(c)), sh.ies_angle_scale)
    phi = np.degrees(np.arctan2(d @ F[:, 1], d @ F[:, 0]))
    return sh.ies.sample(theta, phi) / sh.ies_divisor()


REACH_ON_DEVICE = 1 << 14
"""From this many points up :func:`reach_mask` runs :func:`light_reaches` across the CPU threads: on
a 640 x 480 frame's receivers the float64 NumPy test cost 55-85 ms of a shaped light's frame
(``pwedge``'s edge pass, on 2 loaded cores)."""


def reach_flags(light: Light, points: np.ndarray) -> np.ndarray:
    """:func:`light_reaches` for each of ``points`` ([N, 3]) on the CPU device (bool [N])."""
    from wsoft.parallel import launch_chunked

    pts = np.ascontiguousarray(np.asarray(points, np.float32).reshape(-1, 3))
    out = wp.empty(len(pts), dtype=wp.int32, device="cpu")
    launch_chunked(reach_points, len(pts), inputs=[light_gpu(light, 1.0), wp.array(pts, dtype=wp.vec3, device="cpu")],
                   outputs=[out], device="cpu", min_chunk=1 << 14)
    return out.numpy().astype(bool)


def reach_mask(light: Light, points: np.ndarray) -> np.ndarray:
    """Which of ``points`` ([N, 3], world) a shaped light's cone reaches (bool [N]): those within its
    cone's angle off its −Z axis, widened by the angle its bounding ball (:meth:`Light.extent`)
    spans seen from the point (so every point some part of the light's cone reaches is kept; a
    point at or inside that ball is reached). Every point for a light without a cone. Compared in
    cosines: ``cos(off) >= cos(cone + widen)``, with ``sin(widen) = r / d``. From
    :data:`REACH_ON_DEVICE` points up (a frame's receivers), :func:`light_reaches` decides, in float32
    across the CPU threads (the test the techniques' kernels make); below, float64 here."""
    if not light.shaping.coned:
        return np.ones(len(np.asarray(points).reshape(-1, 3)), bool)
    if len(np.asarray(points).reshape(-1, 3)) >= REACH_ON_DEVICE:
        return reach_flags(light, points)
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    v = pts - np.asarray(light.position, np.float64)[None]
    d2 = np.einsum("ij,ij->i", v, v)
    r = light.extent()
    cos_c, sin_c = math.cos(math.radians(light.shaping.cone_deg)), math.sin(math.radians(light.shaping.cone_deg))
    along = -(v @ np.asarray(light.frame, np.float64)[:, 2])  # d cos(off)
    inside = d2 <= r * r
    wrap = (cos_c <= 0.0) & (r * r >= sin_c * sin_c * d2)  # cone + widen reaches 180 degrees
    bound = cos_c * np.sqrt(np.maximum(d2 - r * r, 0.0)) - sin_c * r  # d cos(cone + widen)
    return inside | wrap | (along >= bound - 1e-9 * np.sqrt(d2))


@wp.func
def is_round(L: LightGPU) -> bool:
    """Are a disk's or sphere's semi-axes all ``L.radius``?"""
    return L.aspect[0] == 1.0 and L.aspect[1] == 1.0 and L.aspect[2] == 1.0


@wp.func
def silhouette_disk(L: LightGPU, p: wp.vec3):
    """A ball light (radius ``L.radius`` about ``L.position``) seen from ``p``: the disk its
    silhouette spans, facing ``p`` (centre, unit axes ``tx``, ``ty``, radius). From inside the
    ball (or on it), the light's centre with radius 0."""
    to_c = L.position - p
    dist = wp.length(to_c)
    n = L.az
    if dist > 0.0:
        n = to_c / dist
    helper = wp.vec3(1.0, 0.0, 0.0)
    if wp.abs(n[0]) > 0.9:
        helper = wp.vec3(0.0, 1.0, 0.0)
    tx = wp.normalize(wp.cross(helper, n))
    ty = wp.cross(n, tx)
    centre = L.position
    rad = float(0.0)
    if dist > L.radius * 1.0001:
        rr = L.radius * L.radius / dist
        rad = L.radius * wp.sqrt(wp.max(1.0 - rr / dist, 0.0))
        centre = L.position - n * rr
    return centre, tx, ty, rad


@wp.func
def silhouette_ellipse(L: LightGPU, p: wp.vec3):
    """An ellipsoidal sphere light (semi-axes ``L.radius * L.aspect`` along ``ax``, ``ay``, ``az``)
    seen from ``p``: the ellipse its silhouette spans, the section of the ellipsoid by the plane of
    the curve where the cone of its tangents from ``p`` touches it (centre, unit principal axes
    ``u``, ``v``, semi-axes). It is the affine image of :func:`silhouette_disk` of the unit ball
    under the map that makes the ellipsoid of it, so light coordinates uniform on the unit disk are
    uniform on it. From inside the ellipsoid (or on it), the light's centre with semi-axes 0."""
    s = L.aspect * L.radius
    q = p - L.position
    pu = wp.vec3(wp.dot(q, L.ax) / s[0], wp.dot(q, L.ay) / s[1], wp.dot(q, L.az) / s[2])  # p in the unit ball's space
    d2 = wp.dot(pu, pu)
    if d2 <= 1.0002:
        return L.position, L.ax, L.ay, wp.vec2(0.0, 0.0)
    n = pu / wp.sqrt(d2)
    helper = wp.vec3(1.0, 0.0, 0.0)
    if wp.abs(n[0]) > 0.9:
        helper = wp.vec3(0.0, 1.0, 0.0)
    tx = wp.normalize(wp.cross(helper, n))
    ty = wp.cross(n, tx)
    rad = wp.sqrt(1.0 - 1.0 / d2)
    cu = pu / d2  # the unit silhouette disk's centre
    centre = L.position + L.ax * (cu[0] * s[0]) + L.ay * (cu[1] * s[1]) + L.az * (cu[2] * s[2])
    # conjugate semi-diameters of the ellipse, then its principal axes
    P = (L.ax * (tx[0] * s[0]) + L.ay * (tx[1] * s[1]) + L.az * (tx[2] * s[2])) * rad
    Q = (L.ax * (ty[0] * s[0]) + L.ay * (ty[1] * s[1]) + L.az * (ty[2] * s[2])) * rad
    phi = 0.5 * wp.atan2(2.0 * wp.dot(P, Q), wp.dot(P, P) - wp.dot(Q, Q))
    U = P * wp.cos(phi) + Q * wp.sin(phi)
    V = Q * wp.cos(phi) - P * wp.sin(phi)
    eu = wp.length(U)
    ev = wp.length(V)
    return centre, U / wp.max(eu, 1.0e-30), V / wp.max(ev, 1.0e-30), wp.vec2(eu, ev)


@wp.func
def silhouette_rect(L: LightGPU, p: wp.vec3):
    """A cylinder light (half length ``L.half_size[0]`` along ``ax``, radius ``L.half_size[1]``)
    seen from ``p``: its silhouette rectangle (module docstring), facing ``p`` (centre, unit axes
    ``u`` along the cylinder's axis and ``v`` across it, half extents (half length, half width)).
    In the cross-section through ``p``, at distance ``rho`` from the axis, the tangent points lie
    ``radius^2 / rho`` toward ``p`` from the axis and ``radius sqrt(1 - radius^2 / rho^2)`` to
    either side: the sphere's silhouette disk in two dimensions. From within ``radius`` of the
    axis line (beyond an end, where its side shows only its inside), and for a line light, the
    axis segment itself (half width 0)."""
    q = p - L.position
    qy = wp.dot(q, L.ay)
    qz = wp.dot(q, L.az)
    rho = wp.sqrt(qy * qy + qz * qz)
    r = L.half_size[1]
    if rho <= r * 1.0001 or rho <= 0.0:
        return L.position, L.ax, L.ay, wp.vec2(L.half_size[0], 0.0)
    n = (L.ay * qy + L.az * qz) / rho  # from the axis toward p, across it
    v = L.az * (qy / rho) - L.ay * (qz / rho)
    rr = r * r / rho
    return L.position + n * rr, L.ax, v, wp.vec2(L.half_size[0], r * wp.sqrt(wp.max(1.0 - rr / rho, 0.0)))


@wp.func
def bound_radius(L: LightGPU) -> float:
    """The radius of a local light's enclosing ball about ``L.position``: a rect's half diagonal, a
    cylinder's (half length, radius) diagonal, a disk's or sphere's (largest) radius, 0 for a point."""
    r = L.radius
    if L.kind == 0 or L.kind == 5:
        r = wp.length(L.half_size)
    elif L.kind == 4:
        r = 0.0
    return r


@wp.func
def light_point(L: LightGPU, p: wp.vec3, c: wp.vec2) -> wp.vec4:
    """A shadow ray from ``p`` toward the point of light coordinates ``c`` (``[-1, 1]^2`` on a rect
    or cylinder light, the unit disk on the others, :mod:`wsoft.lightspace.samples`): unit direction (xyz)
    and length (w). A disk light's coordinates are scaled by its two semi-axes (an ellipse); a
    sphere light is its silhouette disk seen from ``p`` (an ellipsoid's silhouette ellipse,
    :func:`silhouette_ellipse`); a cylinder light its silhouette rectangle seen from ``p``
    (:func:`silhouette_rect`; a line light its segment); a distant light's disk is its cone
    (uniform in solid angle); a point light ignores ``c``."""
    target = L.position
    if L.kind == 0:  # rect
        target = L.position + L.ax * (c[0] * L.half_size[0]) + L.ay * (c[1] * L.half_size[1])
    elif L.kind == 1:  # disk: an ellipse of semi-axes radius * aspect (a round one: aspect 1, the same bits)
        target = L.position + (L.ax * (c[0] * L.aspect[0]) + L.ay * (c[1] * L.aspect[1])) * L.radius
    elif L.kind == 2:  # sphere: the silhouette disk (ellipse) seen from p
        if is_round(L):
            centre, tx, ty, rad = silhouette_disk(L, p)
            target = centre + (tx * c[0] + ty * c[1]) * rad
        else:
            ce, u, v, e = silhouette_ellipse(L, p)
            target = ce + u * (c[0] * e[0]) + v * (c[1] * e[1])
    elif L.kind == 5:  # cylinder: the silhouette rectangle seen from p
        ce, u, v, e = silhouette_rect(L, p)
        target = ce + u * (c[0] * e[0]) + v * (c[1] * e[1])
    elif L.kind == 3:  # distant: uniform in the cone's solid angle
        rho2 = c[0] * c[0] + c[1] * c[1]
        cos_t = 1.0 - rho2 * (1.0 - L.cos_max)
        sin_t = wp.sqrt(wp.max(1.0 - cos_t * cos_t, 0.0))
        rho = wp.sqrt(rho2)
        dx = float(0.0)
        dy = float(0.0)
        if rho > 0.0:
            dx = c[0] / rho
            dy = c[1] / rho
        dir = wp.normalize(L.az * cos_t + (L.ax * dx + L.ay * dy) * sin_t)
        return wp.vec4(dir[0], dir[1], dir[2], L.far)
    v = target - p
    dist = wp.length(v)
    if dist <= 0.0:
        return wp.vec4(L.az[0], L.az[1], L.az[2], 0.0)
    dir = v / dist
    return wp.vec4(dir[0], dir[1], dir[2], dist)


def disk_shaped(light: Light) -> bool:
    """Are the light's samples mapped onto a disk (disk, sphere and distant lights) rather than a
    rectangle (rect lights, a cylinder light's silhouette rectangle)?"""
    return light.kind not in (LIGHT_RECT, LIGHT_CYLINDER)


def light_bound(light: Light) -> tuple[np.ndarray, float, bool]:
    """The light's bound on the host, as :func:`~wsoft.accel.stsv.light_ball` on the device:
    (a local light's centre, the radius of its enclosing ball, False) or (a distant light's unit
    direction toward the light, the sine of its cone's half angle, True)."""
    if light.kind == LIGHT_DISTANT:
        return np.asarray(light.frame[:, 2], np.float64), math.sin(math.radians(0.5 * light.angle_deg)), True
    r = float(np.hypot(*light.half_size)) if light.kind in (LIGHT_RECT, LIGHT_CYLINDER) else float(light.radius)
    return np.asarray(light.position, np.float64), r, False


@wp.func
def light_center_dir(L: LightGPU, p: wp.vec3) -> wp.vec4:
    """Unit direction from ``p`` to the light's centre (distant: toward the sun) and its distance."""
    if L.kind == 3:
        return wp.vec4(L.az[0], L.az[1], L.az[2], L.far)
    v = L.position - p
    dist = wp.length(v)
    if dist <= 0.0:
        return wp.vec4(L.az[0], L.az[1], L.az[2], 0.0)
    dir = v / dist
    return wp.vec4(dir[0], dir[1], dir[2], dist)


# --------------------------------------------------------------------------- the light as a filter kernel


@wp.struct
class LightKernel:
    """The light as a filter sees it from the light view's centre.

    ``disk``: 1 for a disk-shaped light (disk, sphere, distant), 0 for a rectangle (a rect light,
    a cylinder light's bound).
    ``half``: local lights: half-extent in world units along the map's x and y;
    distant lights: tan of the cone's half angle (both components).
    """

    disk: int
    half: wp.vec2


CYLINDER_KERNEL = ("its bound seen along the light view's axis (toward the receivers' mean, its x along the cylinder): a rectangle "
                   "of its projected length by its diameter, as a rect light's kernel (a line light: 1e-3 of its length wide)")
"""What a technique whose kernel is :func:`light_kernel` renders of a cylinder light (its ``cylinder_model``)."""


def light_kernel(light: Light, view=None) -> LightKernel:
    """The light's half extents along a light view's x and y (a rect or disk light's view is
    aligned with its X and Y: an elliptical disk's two semi-axes); a sphere light's radius, which
    of an ellipsoid is its bounding sphere's (:attr:`~wsoft.techniques.Technique.ellipsoid_caveat`);
    a cylinder light's bound seen along ``view``'s axis (:func:`cylinder_half_extents`), a rectangle."""
    k = LightKernel()
    if light.kind == LIGHT_RECT:
        k.disk = 0
        k.half = wp.vec2(*light.half_size)
    elif light.kind == LIGHT_CYLINDER:
        k.disk = 0
        k.half = wp.vec2(*cylinder_half_extents(light, None if view is None else view.axes))
    elif light.kind == LIGHT_DISTANT:
        k.disk = 1
        t = math.tan(math.radians(0.5 * light.angle_deg))
        k.half = wp.vec2(t, t)
    elif light.kind == LIGHT_DISK and light.elliptical:
        k.disk = 1
        k.half = wp.vec2(*light.semi_axes)
    else:
        k.disk = 1
        k.half = wp.vec2(light.radius, light.radius)
    return k


def cylinder_half_extents(light: Light, axes: np.ndarray | None) -> tuple[float, float]:
    """A cylinder light's half extents along a view's x and y (``axes``: 3 x 3, columns x, y and the
    view axis): the extent of the cylinder along each, ``h |a . e| + r sqrt(1 - (a . e)^2)`` for
    its axis ``a``, half length ``h`` and radius ``r`` (its support), which is the rectangle of
    its outline projected onto the view's plane (``h`` and ``r`` when the view looks across its
    axis with x along it, as :func:`~wsoft.lightspace.fit.omni_axes` makes it). Without ``axes``:
    ``h`` and ``r``. Each at least :data:`LINE_WIDTH` of ``h`` and of the other (a line light's area,
    seen across or end-on)."""
    h, r = float(light.half_size[0]), float(light.half_size[1])
    if axes is None:
        hx, hy = h, r
    else:
        a = np.asarray(light.frame, np.float64)[:, 0]
        ext = []
        for e in (axes[:, 0], axes[:, 1]):
            c = min(abs(float(np.dot(a, e)) / max(float(np.linalg.norm(e)), 1e-300)), 1.0)
            ext.append(h * c + r * math.sqrt(1.0 - c * c))
        hx, hy = ext
    m = LINE_WIDTH * max(hx, hy, h)
    return max(hx, m), max(hy, m)


@wp.func
def spread(lv: ViewGPU, k: LightKernel, zb: float, zr: float) -> wp.vec2:
    """Half-size (window units) of the region over which a blocker at depth ``zb`` covers the
    light as seen from a receiver at depth ``zr``: w (1/zb - 1/zr) for a local light of
    half-extent w, (zr - zb) tan(a) for a distant light."""
    if lv.persp != 0:
        f = 1.0 / wp.max(zb, 1.0e-20) - 1.0 / wp.max(zr, 1.0e-20)
        return k.half * wp.max(f, 0.0)
    return k.half * wp.max(zr - zb, 0.0)


@wp.func
def spread_texels(lv: ViewGPU, k: LightKernel, zb: float, zr: float, lo: float, hi: float) -> wp.vec2:
    """:func:`spread` in texels along x and y, clamped to [lo, hi]."""
    h = spread(lv, k, zb, zr)
    return wp.vec2(wp.clamp(h[0] * lv.scale[0], lo, hi), wp.clamp(h[1] * lv.scale[1], lo, hi))


@wp.func
def receiver_bias(lv: ViewGPU, L: LightGPU, p: wp.vec3, n: wp.vec3, z: float, bias: float, slope_texels: float) -> float:
    """Constant plus slope-scaled bias (world units) for a receiver at view depth ``z``."""
    texel = wp.max((lv.window[1] - lv.window[0]) / float(lv.width), (lv.window[3] - lv.window[2]) / float(lv.height))
    if lv.persp != 0:
        texel = texel * z
    c = light_center_dir(L, p)
    cos_t = wp.abs(wp.dot(n, wp.vec3(c[0], c[1], c[2])))
    tan_t = wp.min(wp.sqrt(wp.max(1.0 - cos_t * cos_t, 0.0)) / wp.max(cos_t, 1.0e-4), 10.0)
    return bias + slope_texels * texel * tan_t


# --------------------------------------------------------------------------- the receiver's horizon


@wp.func
def in_front(n: wp.vec3, d: wp.vec3) -> bool:
    """Does the direction ``d`` leave the visible side of a surface of normal ``n``? A point sees
    only the part of a light in front of its tangent plane: behind it, the surface's own sheet is in
    the way (the one rule of :mod:`wsoft.raster.horizon`, the reference and every technique)."""
    return wp.dot(n, d) > 0.0


@wp.func
def emits_along(L: LightGPU, d: wp.vec3) -> bool:
    """Does light leave the light back along ``-d``, for ``d`` (any length) pointing from a
    receiver to a point of the light (or to its centre)? A rect or disk light emits from its front
    only: the receiver must lie on the side its −Z axis points to, ``dot(p - q, -az) > 0`` for the
    light point ``q``, i.e. ``dot(d, az) > 0`` (the same for every point of its plane). Sphere,
    point, cylinder and distant lights emit all around."""
    if L.kind == 0 or L.kind == 1:
        return wp.dot(d, L.az) > 0.0
    return True


@wp.func
def lit_along(L: LightGPU, n: wp.vec3, d: wp.vec3) -> bool:
    """Can light from the light along the shadow ray direction ``d`` reach a receiver of normal
    ``n``: ``d`` leaves the receiver's visible side (:func:`in_front`) and the light emits back
    along it (:func:`emits_along`)? The reference's, ``dcs``'s and ``izb``'s test per ray and the
    front fraction's per sample."""
    return in_front(n, d) and emits_along(L, d)


@wp.func
def light_side(L: LightGPU, p: wp.vec3, n: wp.vec3) -> int:
    """Where the whole light lies against the tangent plane at ``p`` (normal ``n``): 1 wholly in
    front, -1 wholly behind (or on it), 0 across it. Bounds: a local light's enclosing sphere
    (:func:`bound_radius`), a distant light's cone."""
    if L.kind == 3:
        s = wp.dot(n, L.az)
        sin_a = wp.sqrt(wp.max(1.0 - L.cos_max * L.cos_max, 0.0))
        if s > sin_a:
            return 1
        if s <= -sin_a:
            return -1
        return 0
    r = bound_radius(L)
    s = wp.dot(n, L.position - p)
    if s > r:
        return 1
    if s <= -r:
        return -1
    return 0


@wp.func
def light_reaches(L: LightGPU, p: wp.vec3) -> bool:
    """:func:`reach_mask` on the device: does the light's cone reach ``p`` (always, without a cone)?"""
    if L.cone_cos < -1.5:
        return True
    v = p - L.position
    d2 = wp.dot(v, v)
    r = bound_radius(L)
    if d2 <= r * r:
        return True
    sin_c = wp.sqrt(wp.max(1.0 - L.cone_cos * L.cone_cos, 0.0))
    if L.cone_cos <= 0.0 and r * r >= sin_c * sin_c * d2:
        return True
    bound = L.cone_cos * wp.sqrt(d2 - r * r) - sin_c * r
    return -wp.dot(v, L.az) >= bound - 1.0e-6 * wp.sqrt(d2)


def cone_meets_balls(light: Light, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Which balls (``centres`` [N, 3], ``radii`` [N]) meet the region a shaped light's cone can
    light, the cone widened by the light's bounding ball (:func:`reach_mask`'s region: the points
    within ``r`` of the cone, ``r`` the light's extent): bool [N], all True without a cone or for a
    cone past 90 degrees (its region is not convex: no caster is ruled out). For a cone up to 90
    degrees the region is convex, so a shadow ray from a point of the light to a reached receiver
    stays in it, and a caster whose bounding ball misses it shadows no reached receiver. A ball
    meets it when its centre lies within ``r + radius`` of the cone."""
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    if not light.shaping.coned or light.shaping.cone_deg > 90.0:
        return np.ones(len(c), bool)
    v = c - np.asarray(light.position, np.float64)[None]
    d = np.linalg.norm(v, axis=1)
    pad = light.extent() + np.asarray(radii, np.float64).reshape(-1)
    along = -(v @ np.asarray(light.frame, np.float64)[:, 2])
    cone = math.radians(light.shaping.cone_deg)
    off = np.arccos(np.clip(along / np.maximum(d, 1e-300), -1.0, 1.0))
    # distance from the centre to the cone: 0 inside; d sin(off - cone) up to 90 degrees past it; d beyond
    dist = np.where(off <= cone, 0.0, np.where(off - cone < 0.5 * math.pi, d * np.sin(np.minimum(off - cone, 0.5 * math.pi)), d))
    return dist <= pad * (1.0 + 1e-9) + 1e-12


@wp.kernel
def reach_points(
    offset: int,
    L: LightGPU,
    pts: wp.array[wp.vec3],
    # outputs
    out: wp.array[wp.int32],
):
    """1 where the light's cone reaches ``pts[i]`` (:func:`light_reaches`), else 0."""
    i = wp.tid() + offset
    out[i] = wp.where(light_reaches(L, pts[i]), 1, 0)


def reached_receivers(light: Light, points: np.ndarray) -> np.ndarray:
    """The rows of ``points`` ([N, 3]) a shaped light's cone reaches (:func:`reach_mask`): the
    receivers its light views are fitted to (all of them for a light without a cone)."""
    return points if not light.shaping.coned else points[reach_mask(light, points)]
