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


def conform_aperture(cam: Camera, width: int, height: int, pixel_aspect: float = 1.0, policy: str = "adjustApertureHeight") -> Camera:
    """``cam`` with its window conformed to a ``width x height`` image of pixels ``pixel_aspect``
    times as wide as tall, as UsdRender's ``aspectRatioConformPolicy`` resolves a mismatch
    (``UsdRenderComputeSpec``): the image's aspect is ``pixel_aspect * width / height``, the
    aperture's ``tan_half[0] / tan_half[1]`` (the apertures over the focal length, or the half
    extents of an orthographic camera: the same ratio), and the window, centred where it was
    (``offset`` unchanged), becomes

    * ``adjustApertureHeight``: the height, to ``width / image aspect`` (wsoft's choice without
      render settings: the horizontal field of view is kept);
    * ``adjustApertureWidth``: the width, to ``height * image aspect``;
    * ``expandAperture`` (UsdRender's fallback): whichever of the two grows the window, so all of
      the aperture is seen and more;
    * ``cropAperture``: whichever shrinks it, so the image is filled with part of the aperture;
    * ``adjustPixelAspectRatio``: nothing; the pixels take the aspect that makes the image cover
      the aperture exactly (``pixel_aspect`` is disregarded, as UsdRender says).

    The image then spans the window: pixel column ``i`` sees ``ndc_x = (i + 0.5) / width * 2 - 1``
    times ``tan_half[0]`` (plus the offset), row ``j`` ``1 - (j + 0.5) / height * 2`` times
    ``tan_half[1]`` (:func:`wsoft.raster.gbuffer.camera_ray`)."""
    from dataclasses import replace

    tx, ty = cam.tan_half
    if policy == "adjustPixelAspectRatio":
        return cam
    image = pixel_aspect * width / height
    aperture = tx / ty
    adjust = {
        "adjustApertureHeight": "height",
        "adjustApertureWidth": "width",
        "expandAperture": "height" if aperture > image else "width",
        "cropAperture": "width" if aperture > image else "height",
    }.get(policy)
    if adjust is None:
        raise ValueError(f"unknown aspectRatioConformPolicy {policy!r}")
    if adjust == "height":
        ty = tx * height / (width * pixel_aspect)
    else:
        tx = ty * width * pixel_aspect / height
    return replace(cam, tan_half=(tx, ty))


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
