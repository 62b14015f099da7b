"""Cascades of a distant light's orthographic map over a camera's depth range (cascaded shadow
maps, :mod:`wsoft.techniques.csm`): where the splits fall and the light-space window of each.

Depth here is the camera's view depth ``d = (p - eye) . forward`` (``forward`` the camera's −Z),
the quantity the splits cut. Cascade ``k`` owns ``[s_k, s_{k+1})``; its map also holds the band
``[s_k - b_{k-1}, s_k)`` at the end of cascade ``k - 1`` (``b_k = blend (s_{k+1} - s_k)``), where a
receiver's visibility is blended from both (:func:`blend_band`).

Splits:

* **practical** (:func:`practical_splits`, Zhang et al. 2006; NVIDIA's "Cascaded Shadow Maps"):
  ``s_i = lam n (f / n)^(i / N) + (1 - lam) (n + (f - n) i / N)``, a blend of the logarithmic
  and the uniform split by ``lam`` in [0, 1];
* **sdsm** (:func:`log_splits`, Lauritzen, Salvi and Lefohn 2011, "Sample Distribution Shadow
  Maps"): the logarithmic split over ``[d_min, d_max]`` of the depths the frame's visible samples
  actually have (a reduction over the G-buffer, :mod:`wsoft.accel.depth_reduce`), each cascade's
  window the tight light-space bounds of the samples that fall in it.

Windows (:func:`cascade_window`): ``stable`` — a square around the bounding sphere of the cascade's
region (its radius rounded up on the 2^(1/4) ladder of :mod:`wsoft.lightspace.stable`), its centre
on whole texels of a light-space grid anchored at the world origin, so that a camera that moves
by less than a texel leaves every cascade's texel grid where it was; ``fitted`` — the tight
light-space box of the region, which follows the camera and shimmers in motion.
"""

from __future__ import annotations

import math

import numpy as np

from wsoft.lightspace.stable import ladder_up, snapped_window

PARTITIONS = ("practical", "sdsm")


def practical_splits(near: float, far: float, n: int, lam: float) -> np.ndarray:
    """The ``n + 1`` split depths of the practical scheme between ``near`` and ``far`` (``0 < near
    < far``): ``lam`` times the logarithmic split plus ``1 - lam`` times the uniform one."""
    i = np.arange(n + 1, dtype=np.float64) / n
    s = lam * near * (far / near) ** i + (1.0 - lam) * (near + (far - near) * i)
    s[0], s[-1] = near, far
    return s


def log_splits(d_min: float, d_max: float, n: int) -> np.ndarray:
    """SDSM's logarithmic partition of ``[d_min, d_max]`` (the sampled depths) into ``n``."""
    return practical_splits(d_min, d_max, n, 1.0)


def blend_band(splits: np.ndarray, blend: float) -> np.ndarray:
    """Per cascade the width of the blend band at its far end: ``blend`` of its depth range (the
    last cascade has no successor: 0)."""
    b = blend * np.diff(np.asarray(splits, np.float64))
    b[-1] = 0.0
    return b


def cascade_ranges(splits: np.ndarray, band: np.ndarray) -> np.ndarray:
    """``[n, 2]``: the depth range each cascade's map must hold, its own ``[s_k, s_{k+1}]`` and the
    band before it (``s_k - b_{k-1}``)."""
    s = np.asarray(splits, np.float64)
    lo = s[:-1].copy()
    lo[1:] -= band[:-1]
    return np.stack([lo, s[1:]], axis=1)


def slice_sphere(a: float, b: float, tan_x: float, tan_y: float, ortho: bool = False) -> tuple[float, float]:
    """The smallest sphere centred on the camera's axis around the slice ``[a, b]`` of its frustum:
    ``(depth of its centre, radius)``. ``tan_x, tan_y``: the window's half-extent as tangents (the
    farthest corner's, off-centre windows included); ``ortho``: half-extents in world units. It
    depends on ``a``, ``b`` and the window alone, not on where the camera looks, so a turning camera
    keeps the cascade's size."""
    if ortho:
        return 0.5 * (a + b), math.sqrt((0.5 * (b - a)) ** 2 + tan_x * tan_x + tan_y * tan_y)
    k2 = tan_x * tan_x + tan_y * tan_y
    c = min(0.5 * (a + b) * (1.0 + k2), b)  # equidistant from the near and far corners, at most the far plane
    r = math.sqrt((b - c) ** 2 + b * b * k2)
    return c, r


def slice_corners(eye: np.ndarray, axes: np.ndarray, a: float, b: float, window: tuple[float, float, float, float],
                  ortho: bool = False) -> np.ndarray:
    """The 8 world corners of the camera's frustum between view depths ``a`` and ``b``: ``axes``
    the camera's columns x, y, forward; ``window`` (l, r, b, t) as tangents (or world units,
    ``ortho``)."""
    pts = []
    for d in (a, b):
        s = 1.0 if ortho else d
        for x in window[:2]:
            for y in window[2:]:
                pts.append(eye + axes[:, 2] * d + axes[:, 0] * (x * s) + axes[:, 1] * (y * s))
    return np.array(pts)


def cascade_window(lo: np.ndarray, hi: np.ndarray, size: int, stable: bool, grow: float, margin_texels: float = 1.0,
                   radius: float | None = None) -> tuple[tuple[float, float, float, float], float, dict]:
    """The light-space window (l, r, b, t) of a cascade whose region spans ``lo .. hi`` on the
    light's x and y (coordinates from the anchor), grown by ``grow`` on every side (casters of the
    light's cone beyond the receivers), with ``size`` texels a side. ``stable``: a square of half-side
    ``radius`` (default: the box's half-diagonal) rounded up on the ladder, on whole texels
    (:func:`~wsoft.lightspace.stable.snapped_window`); else the box itself, ``margin_texels`` texels
    wider. Returns (window, texel size in world units, what was snapped)."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    if stable:
        r = (0.5 * float(np.linalg.norm(hi - lo)) if radius is None else float(radius)) + grow
        c = 0.5 * (lo + hi)
        r = ladder_up(max(r, 1e-12))
        l, rr, tx, ix = snapped_window(c[0] - r, c[0] + r, size, margin_texels)
        b, t, _, iy = snapped_window(c[1] - r, c[1] + r, size, margin_texels)
        return (l, rr, b, t), tx, {"radius": r, "snap_offset": [ix, iy]}
    span = np.maximum(hi - lo, 1e-12) + 2.0 * grow
    texel = span / max(size - 2.0 * margin_texels, 1.0)
    c = 0.5 * (lo + hi)
    half = 0.5 * size * texel
    return (c[0] - half[0], c[0] + half[0], c[1] - half[1], c[1] + half[1]), float(max(texel)), {}
