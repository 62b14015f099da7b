"""Eye-view camera on the device."""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.scene.types import Camera


@wp.struct
class CameraGPU:
    origin: wp.vec3
    ax: wp.vec3  # camera X (right) in world space
    ay: wp.vec3  # camera Y (up)
    az: wp.vec3  # camera Z (the camera looks down -Z)
    tan_half: wp.vec2  # perspective: tan of half fields; orthographic: half extents
    offset: wp.vec2
    ortho: int
    near: float
    far: float


def camera_gpu(cam: Camera) -> CameraGPU:
    c = CameraGPU()
    M = np.asarray(cam.to_world, dtype=np.float64)
    c.origin = wp.vec3(*M[:3, 3])
    c.ax = wp.vec3(*M[:3, 0])
    c.ay = wp.vec3(*M[:3, 1])
    c.az = wp.vec3(*M[:3, 2])
    c.tan_half = wp.vec2(*cam.tan_half)
    c.offset = wp.vec2(*cam.offset)
    c.ortho = int(cam.orthographic)
    c.near = float(cam.clip[0])
    c.far = float(cam.clip[1])
    return c


def fit_aspect(cam: Camera, width: int, height: int) -> Camera:
    """Keep the horizontal field of view; derive the vertical one from the image aspect."""
    from dataclasses import replace

    th = cam.tan_half[0]
    return replace(cam, tan_half=(th, th * height / width))
