"""Cutout textures written as PNG: RGBA images whose alpha is 255 where opaque and 0 elsewhere."""

from __future__ import annotations

import os

import numpy as np
from PIL import Image


def write_checker_png(path: str, size: int = 64, cells: int = 8) -> None:
    """RGBA checker: cell (row, col) of the *image* (row 0 = top) is opaque
    (alpha 255, orange) when (row + col) is even, else transparent (alpha 0)."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    cell = size // cells
    yy, xx = np.mgrid[0:size, 0:size]
    opaque = ((yy // cell + xx // cell) % 2) == 0
    img = np.zeros((size, size, 4), dtype=np.uint8)
    img[opaque] = (230, 120, 40, 255)
    img[~opaque] = (0, 0, 0, 0)
    Image.fromarray(img, "RGBA").save(path, format="PNG", optimize=False)


def write_alpha_png(path: str, opaque: np.ndarray, rgb=(120, 120, 125)) -> None:
    """RGBA PNG, alpha 255 where ``opaque`` (row 0 = the image's top), else 0."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    img = np.zeros(opaque.shape + (4,), np.uint8)
    img[opaque] = (*rgb, 255)
    Image.fromarray(img, "RGBA").save(path, format="PNG", optimize=False)
