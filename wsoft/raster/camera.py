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


# --------------------------------------------------------------------------- sub-pixel sample patterns

SUBPIXEL_PATTERNS = ("rotated_grid", "jittered")
ROTATED_GRID_4 = ((0.375, 0.125), (0.875, 0.375), (0.125, 0.625), (0.625, 0.875))  # RGSS 4x: one sample per row and column of a 4x4 grid


def subpixel_pattern(n: int, kind: str, seed: int = 0) -> np.ndarray:
    """``n`` sample offsets inside a pixel, ``[n, 2]`` float32 in ``[0, 1)^2`` ((0, 0) the pixel's
    top-left corner), the same for every pixel.

    ``rotated_grid``: the 4x rotated-grid pattern (``n = 4`` only); ``jittered``: one uniform point
    per cell of an ``a x b`` grid with ``a b = n`` and ``a`` the largest divisor of ``n`` not above
    its square root (2 x 4 for 8, 4 x 4 for 16), from a fixed seed."""
    if kind == "rotated_grid":
        if n != 4:
            raise ValueError(f"the rotated grid has 4 samples, not {n}")
        return np.asarray(ROTATED_GRID_4, np.float32)
    if kind != "jittered":
        raise ValueError(f"sub-pixel pattern {kind!r} is not one of {', '.join(SUBPIXEL_PATTERNS)}")
    a = max(d for d in range(1, int(np.sqrt(n)) + 1) if n % d == 0)
    b = n // a
    rng = np.random.default_rng(seed)
    cells = np.array([(i % b, i // b) for i in range(n)], np.float64)
    pts = (cells + rng.random((n, 2))) / np.array([b, a], np.float64)
    return np.minimum(pts, np.nextafter(1.0, 0.0)).astype(np.float32)
