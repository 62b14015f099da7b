"""ꟻLIP (NVIDIA's perceptual difference of two images, the ``flip-evaluator`` package) between a
technique's shaded image and the reference's.

The images compared are the ones a person sees in the PNGs: :func:`ldr_image` is
:func:`wsoft.io.to_srgb8` of ``R``, ``G``, ``B`` divided by 255, which ꟻLIP's LDR mode reads as
sRGB-encoded. :func:`flip_error` returns the mean of ꟻLIP's per-pixel map over the whole image
(the number ꟻLIP reports), the mean over the covered pixels (the reference's ``A`` > 0: the
background is black in both images, so the whole-image mean shrinks with the share of background)
and the map. A pixel whose ``R``, ``G`` or ``B`` is not finite in either image is counted, warned
about and scored 1 (ꟻLIP's largest error), never dropped. :func:`magma` colours a map as ꟻLIP's
own ``applyMagma`` does.
"""

from __future__ import annotations

import warnings

import numpy as np

from wsoft.io import to_srgb8

RGB = ("R", "G", "B")


def has_rgb(channels: dict) -> bool:
    """Does ``channels`` carry a shaded image (``R``, ``G`` and ``B``)?"""
    return all(c in channels for c in RGB)


def ldr_image(channels: dict) -> np.ndarray:
    """The shaded image as its PNG shows it: float32 ``[H, W, 3]`` in [0, 1], sRGB-encoded, the
    8-bit values of :func:`wsoft.io.to_srgb8` (``R``, ``G``, ``B``) over 255."""
    return np.stack([to_srgb8(channels[c]) for c in RGB], -1).astype(np.float32) / np.float32(255.0)


def nonfinite_pixels(channels: dict) -> np.ndarray:
    """bool ``[H, W]``: pixels whose ``R``, ``G`` or ``B`` is NaN or inf."""
    return np.logical_or.reduce([~np.isfinite(np.asarray(channels[c])) for c in RGB])


def flip_error(channels: dict, reference: dict) -> tuple[dict, np.ndarray]:
    """ꟻLIP (LDR, its default 67 pixels per degree) of ``channels``' shaded image against
    ``reference``'s (both dicts with ``R``, ``G``, ``B``: float32 ``[H, W]``, linear; ``reference``
    may carry ``A``, the coverage).

    Returns ``({"flip", "flip_covered", "flip_nan_pixels"}, map)``: the mean of the map over every
    pixel and over the covered ones (``A`` > 0; every pixel without ``A``; 0 when none is covered),
    the pixels not finite in either image (each scored 1 in the map), and the map (float32
    ``[H, W]`` in [0, 1]). The means are float64 sums of the map."""
    import flip_evaluator

    ref_img, test_img = ldr_image(reference), ldr_image(channels)
    if ref_img.shape != test_img.shape:
        raise ValueError(f"image {test_img.shape[:2]} and reference {ref_img.shape[:2]} differ in size")
    err, _, _ = flip_evaluator.evaluate(ref_img, test_img, "LDR", applyMagma=False)
    err = np.ascontiguousarray(np.asarray(err, np.float32).reshape(ref_img.shape[:2]))
    bad = nonfinite_pixels(channels) | nonfinite_pixels(reference)
    n_bad = int(bad.sum())
    if n_bad:
        warnings.warn(f"{n_bad} pixels of the shaded image or the reference's are not finite; each counts as a ꟻLIP error of 1",
                      RuntimeWarning, stacklevel=2)
        err[bad] = 1.0
    covered = np.asarray(reference["A"]) > 0 if "A" in reference else np.ones(err.shape, bool)
    out = {"flip": float(err.mean(dtype=np.float64)),
           "flip_covered": float(err[covered].mean(dtype=np.float64)) if covered.any() else 0.0,
           "flip_nan_pixels": n_bad}
    return out, err


def magma(error_map: np.ndarray) -> np.ndarray:
    """uint8 ``[H, W, 3]``: a ꟻLIP map (values in [0, 1]) in the magma colour map, entry
    ``round(255 * value)`` of matplotlib's 256-entry ``magma``, the table ꟻLIP's ``applyMagma`` uses."""
    from matplotlib import colormaps

    lut = (colormaps["magma"](np.arange(256))[:, :3] * 255.0 + 0.5).astype(np.uint8)
    idx = np.clip(np.nan_to_num(np.asarray(error_map, np.float64), nan=1.0) * 255.0 + 0.5, 0, 255).astype(np.intp)
    return lut[idx]


def write_flip_png(path: str, error_map: np.ndarray) -> None:
    """The map as a magma-coloured PNG (:func:`magma`)."""
    import os

    from PIL import Image

    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    Image.fromarray(magma(error_map), "RGB").save(path)
