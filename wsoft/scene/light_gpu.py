"""Lights on the device and how to sample a point (or direction) on them."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from wsoft.scene.types import LIGHT_DISK, LIGHT_DISTANT, LIGHT_POINT, LIGHT_RECT, LIGHT_SPHERE, Light  # noqa: F401


@wp.struct
class LightGPU:
    kind: int  # LIGHT_RECT, LIGHT_DISK, LIGHT_SPHERE, LIGHT_DISTANT, LIGHT_POINT
    position: wp.vec3
    ax: wp.vec3  # unit X axis
    ay: wp.vec3  # unit Y axis
    az: wp.vec3  # unit Z axis (rect/disk emit along -Z; distant light comes from +Z)
    half_size: wp.vec2  # rect half width / height
    radius: float  # disk / sphere radius
    cos_max: float  # distant: cosine of the cone half angle
    far: float  # distant: length of shadow rays


def light_gpu(light: Light, scene_diagonal: float) -> LightGPU:
    g = LightGPU()
    g.kind = int(light.kind)
    g.position = wp.vec3(*np.asarray(light.position, np.float64))
    g.ax = wp.vec3(*light.frame[:, 0])
    g.ay = wp.vec3(*light.frame[:, 1])
    g.az = wp.vec3(*light.frame[:, 2])
    g.half_size = wp.vec2(*light.half_size)
    g.radius = float(light.radius)
    g.cos_max = float(math.cos(math.radians(0.5 * light.angle_deg)))
    g.far = float(4.0 * scene_diagonal)
    return g


@wp.func
def concentric_disk(u1: float, u2: float) -> wp.vec2:
    """Shirley-Chiu concentric map of [0,1)^2 onto the unit disk (keeps strata compact)."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    if a == 0.0 and b == 0.0:
        return wp.vec2(0.0, 0.0)
    r = float(0.0)
    phi = float(0.0)
    if wp.abs(a) > wp.abs(b):
        r = a
        phi = (wp.pi / 4.0) * (b / a)
    else:
        r = b
        phi = (wp.pi / 2.0) - (wp.pi / 4.0) * (a / b)
    return wp.vec2(r * wp.cos(phi), r * wp.sin(phi))


@wp.func
def light_sample(L: LightGPU, p: wp.vec3, u1: float, u2: float) -> wp.vec4:
    """A shadow ray from ``p`` toward the light sample (u1, u2): unit direction (xyz) and length (w)."""
    target = L.position
    if L.kind == 0:  # rect: uniform in the rectangle
        target = L.position + L.ax * ((2.0 * u1 - 1.0) * L.half_size[0]) + L.ay * ((2.0 * u2 - 1.0) * L.half_size[1])
    elif L.kind == 1:  # disk: concentric map
        d = concentric_disk(u1, u2)
        target = L.position + (L.ax * d[0] + L.ay * d[1]) * L.radius
    elif L.kind == 2:  # sphere: the silhouette disk seen from p
        to_c = L.position - p
        dist = wp.length(to_c)
        if dist > L.radius * 1.0001:
            n = to_c / dist
            helper = wp.vec3(1.0, 0.0, 0.0)
            if wp.abs(n[0]) > 0.9:
                helper = wp.vec3(0.0, 1.0, 0.0)
            tx = wp.normalize(wp.cross(helper, n))
            ty = wp.cross(n, tx)
            rr = L.radius * L.radius / dist
            rad = L.radius * wp.sqrt(wp.max(1.0 - rr / dist, 0.0))
            d = concentric_disk(u1, u2)
            target = L.position - n * rr + (tx * d[0] + ty * d[1]) * rad
    elif L.kind == 3:  # distant: uniform in the cone's solid angle
        d = concentric_disk(u1, u2)
        rho2 = d[0] * d[0] + d[1] * d[1]
        cos_t = 1.0 - rho2 * (1.0 - L.cos_max)
        sin_t = wp.sqrt(wp.max(1.0 - cos_t * cos_t, 0.0))
        rho = wp.sqrt(rho2)
        dx = float(0.0)
        dy = float(0.0)
        if rho > 0.0:
            dx = d[0] / rho
            dy = d[1] / rho
        dir = wp.normalize(L.az * cos_t + (L.ax * dx + L.ay * dy) * sin_t)
        return wp.vec4(dir[0], dir[1], dir[2], L.far)
    v = target - p
    dist = wp.length(v)
    if dist <= 0.0:
        return wp.vec4(L.az[0], L.az[1], L.az[2], 0.0)
    dir = v / dist
    return wp.vec4(dir[0], dir[1], dir[2], dist)


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
