"""A pixel's footprint in a light view: where the camera rays through its corners meet a plane,
in the view's texel coordinates (the shadow-edge stencils' look-up regions)."""

from __future__ import annotations

import warp as wp

from wsoft.lightspace.view import ViewGPU, texel_of, view_of
from wsoft.raster.camera import CameraGPU
from wsoft.raster.gbuffer import camera_ray
from wsoft.raster.shadow_rays import ray_offset, ray_origin


@wp.func
def pixel_footprint(lv: ViewGPU, cam: CameraGPU, width: int, height: int, xy: wp.vec2i, p: wp.vec3, n: wp.vec3, eps: float,
                    off_surface: int, centre: int):
    """The footprint of pixel ``xy`` on the plane (``p``, ``n``) seen from the light view ``lv``:
    the camera rays through the pixel's four corners meet the plane (with ``centre``, the point
    ``p`` counts too), each point moved off the surface as a shadow ray's origin is (with
    ``off_surface``: ``ray_offset(q, eps)`` along ``n``). Returns (1, its texel box (xmin, ymin,
    xmax, ymax), its view depths (zmin, zmax)), or 0 first where a corner's ray grazes the plane
    or meets it behind the camera, or a point lies behind a perspective view's near plane."""
    xmin = float(1.0e30)
    xmax = float(-1.0e30)
    ymin = float(1.0e30)
    ymax = float(-1.0e30)
    zmin = float(1.0e30)
    zmax = float(-1.0e30)
    for c in range(4 + centre):
        q = p
        if c < 4:
            o, d, t0, t1 = camera_ray(cam, width, height, float(xy[0] + c % 2), float(xy[1] + c / 2))
            den = wp.dot(d, n)
            if wp.abs(den) < 1.0e-8:
                return 0, wp.vec4(0.0), wp.vec2(0.0)
            s = wp.dot(p - o, n) / den
            if s <= 0.0:
                return 0, wp.vec4(0.0), wp.vec2(0.0)
            q = o + d * s
        if off_surface != 0:
            q = ray_origin(q, n, ray_offset(q, eps))
        v = view_of(lv, q)
        if lv.persp != 0 and v[2] <= lv.near:
            return 0, wp.vec4(0.0), wp.vec2(0.0)
        t = texel_of(lv, v)
        xmin = wp.min(xmin, t[0])
        xmax = wp.max(xmax, t[0])
        ymin = wp.min(ymin, t[1])
        ymax = wp.max(ymax, t[1])
        zmin = wp.min(zmin, v[2])
        zmax = wp.max(zmax, v[2])
    return 1, wp.vec4(xmin, ymin, xmax, ymax), wp.vec2(zmin, zmax)
