"""Exact answers of the test scenes whose occluders are parallel to a square light and the ground:
the visible fraction of the light from ground points, in closed form (what the ``box_plane`` and
``cutout`` renders are measured against where a test or a sweep's target asks for the exact answer).

A planar occluder parallel to the light at height ``occ_z`` projects from a ground point ``p``
onto the light's plane (height ``light_z``) as itself scaled by ``s = light_z / occ_z`` about
``p``; an axis-aligned rectangle stays one, and the covered part of a square light is the product
of two 1-D overlaps. Disjoint rectangles (a checkerboard's opaque cells) add up.
"""

from __future__ import annotations

import numpy as np


def _overlap(p, lo, hi, s: float, light_half: float):
    """The fraction of the light's side [-light_half, light_half] covered by [lo, hi] (world, on the
    occluder's plane) projected from ground coordinate ``p`` (array)."""
    a = p + (lo - p) * s
    b = p + (hi - p) * s
    return np.clip(np.minimum(b, light_half) - np.maximum(a, -light_half), 0.0, None) / (2.0 * light_half)


def parallel_rect_exact(px, py, light_z, occ_z, occ_half, light_half):
    """Exact visible fraction of a square light (side 2*light_half at height light_z, centred on the
    z axis) seen from ground points (px, py, 0) past a square occluder (side 2*occ_half at occ_z)."""
    s = light_z / occ_z
    px, py = np.asarray(px, np.float64), np.asarray(py, np.float64)
    return 1.0 - _overlap(px, -occ_half, occ_half, s, light_half) * _overlap(py, -occ_half, occ_half, s, light_half)


def checker_exact(px, py, light_z, occ_z, occ_half, light_half, cells: int, opaque_parity: int):
    """Exact visible fraction of a square light (as :func:`parallel_rect_exact`) past a square
    occluder of ``cells`` x ``cells`` checkerboard cells (side 2*occ_half at occ_z), the cell
    (i, j) (i along x, j along y, from the occluder's lower corner) opaque when
    ``(i + j) % 2 == opaque_parity``."""
    s = light_z / occ_z
    px, py = np.asarray(px, np.float64), np.asarray(py, np.float64)
    w = 2.0 * occ_half / cells
    edges = -occ_half + w * np.arange(cells + 1)
    ox = [_overlap(px, edges[i], edges[i + 1], s, light_half) for i in range(cells)]
    oy = [_overlap(py, edges[j], edges[j + 1], s, light_half) for j in range(cells)]
    covered = np.zeros(np.broadcast(px, py).shape)
    for i in range(cells):
        for j in range(cells):
            if (i + j) % 2 == opaque_parity:
                covered = covered + ox[i] * oy[j]
    return 1.0 - covered


# cutout.usda: a 2 x 2 fence at z = 1 under a 0.5 x 0.5 rect light at z = 4; its alpha texture
# (textures/checker_alpha.png, 64 x 64, threshold 0.5) is 8 x 8 cells of 8 texels, the cell at
# st = (0, 0) transparent; bilinear filtering puts the 0.5 contour on the cells' borders exactly.
# The opaque Leaf box (x in [2, 3]) shadows no ground point with x < 1.9.
CUTOUT = {"light_z": 4.0, "occ_z": 1.0, "occ_half": 1.0, "light_half": 0.25, "cells": 8, "opaque_parity": 1, "x_max": 1.9}


def cutout_exact(px, py):
    """:func:`checker_exact` for the bundled ``cutout`` stage's ground (valid where x < 1.9)."""
    c = CUTOUT
    return checker_exact(px, py, c["light_z"], c["occ_z"], c["occ_half"], c["light_half"], c["cells"], c["opaque_parity"])
