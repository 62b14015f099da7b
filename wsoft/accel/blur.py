"""Separable blurs of light-space maps, chunked across CPU threads.

``blur_moments`` filters a ``[H, W]`` vec2 map linearly (VSM moments), ``blur_moments4`` a vec4
map (MSM's four moments, EVSM's two warps' moments), each pass optionally stored as unsigned
normalised integers (a 16-bit render target); ``blur_log`` filters a
float map of logarithms in log space (``log sum w exp(L)``, evaluated stably around the window's
maximum) so exponential maps never overflow (ESM). Both clamp at the map's edges.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.parallel import launch_chunked


def blur_weights(kind: str, radius: int) -> np.ndarray:
    """Normalised 1-D weights of ``2*radius+1`` taps: a box, or a Gaussian with sigma = radius / 2."""
    if radius <= 0:
        return np.ones(1, np.float32)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    if kind == "box":
        w = np.ones_like(x)
    elif kind == "gaussian":
        sigma = max(radius / 2.0, 1e-3)
        w = np.exp(-0.5 * (x / sigma) ** 2)
    else:
        raise ValueError(f"unknown filter {kind!r}")
    return (w / w.sum()).astype(np.float32)


@wp.kernel
def blur_vec2_pass(
    offset: int,
    src: wp.array2d[wp.vec2],
    weights: wp.array[float],
    radius: int,
    axis: int,
    # outputs
    dst: wp.array2d[wp.vec2],
):
    i = wp.tid() + offset
    w = src.shape[1]
    h = src.shape[0]
    y = i // w
    x = i - y * w
    acc = wp.vec2(0.0)
    for k in range(-radius, radius + 1):
        if axis == 0:
            acc += src[y, wp.clamp(x + k, 0, w - 1)] * weights[k + radius]
        else:
            acc += src[wp.clamp(y + k, 0, h - 1), x] * weights[k + radius]
    dst[y, x] = acc


@wp.kernel
def blur_vec4_pass(
    offset: int,
    src: wp.array2d[wp.vec4],
    weights: wp.array[float],
    radius: int,
    axis: int,
    levels: float,
    # outputs
    dst: wp.array2d[wp.vec4],
):
    """One pass of a separable blur of a vec4 map; with ``levels`` > 0 each result is stored as an
    unsigned normalised integer of ``levels`` + 1 steps (clamped to [0, 1]) and read back."""
    i = wp.tid() + offset
    w = src.shape[1]
    h = src.shape[0]
    y = i // w
    x = i - y * w
    acc = wp.vec4(0.0)
    for k in range(-radius, radius + 1):
        if axis == 0:
            acc += src[y, wp.clamp(x + k, 0, w - 1)] * weights[k + radius]
        else:
            acc += src[wp.clamp(y + k, 0, h - 1), x] * weights[k + radius]
    if levels > 0.0:
        for c in range(4):
            acc[c] = wp.round(wp.clamp(acc[c], 0.0, 1.0) * levels) / levels
    dst[y, x] = acc


@wp.kernel
def blur_log_pass(
    offset: int,
    src: wp.array2d[float],
    weights: wp.array[float],
    radius: int,
    axis: int,
    # outputs
    dst: wp.array2d[float],
):
    i = wp.tid() + offset
    w = src.shape[1]
    h = src.shape[0]
    y = i // w
    x = i - y * w
    m = float(-1.0e30)
    for k in range(-radius, radius + 1):
        v = float(0.0)
        if axis == 0:
            v = src[y, wp.clamp(x + k, 0, w - 1)]
        else:
            v = src[wp.clamp(y + k, 0, h - 1), x]
        m = wp.max(m, v)
    s = float(0.0)
    for k in range(-radius, radius + 1):
        v = float(0.0)
        if axis == 0:
            v = src[y, wp.clamp(x + k, 0, w - 1)]
        else:
            v = src[wp.clamp(y + k, 0, h - 1), x]
        s += weights[k + radius] * wp.exp(v - m)
    dst[y, x] = m + wp.log(s)


def _separable(kernel, src: wp.array, kind: str, radius: int) -> wp.array:
    if radius <= 0:
        return src
    dev = str(src.device)
    weights = wp.array(blur_weights(kind, radius), dtype=float, device=dev)
    tmp = wp.empty_like(src)
    out = wp.empty_like(src)
    n = src.shape[0] * src.shape[1]
    launch_chunked(kernel, n, inputs=[src, weights, radius, 0], outputs=[tmp], device=dev, min_chunk=1 << 14)
    launch_chunked(kernel, n, inputs=[tmp, weights, radius, 1], outputs=[out], device=dev, min_chunk=1 << 14)
    return out


def blur_moments(src: wp.array, kind: str, radius: int) -> wp.array:
    """Separable linear blur of a vec2 map (box or Gaussian, ``radius`` texels)."""
    return _separable(blur_vec2_pass, src, kind, radius)


def blur_moments4(src: wp.array, kind: str, radius: int, bits: int = 0) -> wp.array:
    """Separable linear blur of a vec4 map (box or Gaussian, ``radius`` texels); ``bits`` > 0: each
    pass's result stored as ``bits``-bit unsigned normalised integers, as a blur into a UNORM
    render target stores it (values clamped to [0, 1])."""
    if radius <= 0:
        return src
    dev = str(src.device)
    weights = wp.array(blur_weights(kind, radius), dtype=float, device=dev)
    levels = float(2**bits - 1) if bits > 0 else 0.0
    tmp = wp.empty_like(src)
    out = wp.empty_like(src)
    n = src.shape[0] * src.shape[1]
    launch_chunked(blur_vec4_pass, n, inputs=[src, weights, radius, 0, levels], outputs=[tmp], device=dev, min_chunk=1 << 14)
    launch_chunked(blur_vec4_pass, n, inputs=[tmp, weights, radius, 1, levels], outputs=[out], device=dev, min_chunk=1 << 14)
    return out


def blur_log(src: wp.array, kind: str, radius: int) -> wp.array:
    """Separable blur of ``exp(src)`` kept in log space: returns ``log(blur(exp(src)))``."""
    return _separable(blur_log_pass, src, kind, radius)



@wp.kernel
def blur_vec4_listed(
    offset: int,
    texels: wp.array[wp.int32],
    src: wp.array2d[wp.vec4],
    weights: wp.array[float],
    radius: int,
    axis: int,
    # outputs
    dst: wp.array2d[wp.vec4],
):
    """One pass of a separable blur, written only at the listed texels (flat indices)."""
    t = texels[wp.tid() + offset]
    w = src.shape[1]
    h = src.shape[0]
    y = t // w
    x = t - y * w
    acc = wp.vec4(0.0)
    for k in range(-radius, radius + 1):
        if axis == 0:
            acc += src[y, wp.clamp(x + k, 0, w - 1)] * weights[k + radius]
        else:
            acc += src[wp.clamp(y + k, 0, h - 1), x] * weights[k + radius]
    dst[y, x] = acc


def blur_vec4_within(src: wp.array, texels: np.ndarray, kind: str, radius: int) -> wp.array:
    """Separable blur of a vec4 map computed only at ``texels`` (flat indices); other texels keep
    their values. Exact where every texel within ``radius`` of a changing value is listed."""
    dev = str(src.device)
    out = wp.clone(src)
    if radius <= 0 or len(texels) == 0:
        return out
    weights = wp.array(blur_weights(kind, radius), dtype=float, device=dev)
    idx = wp.array(np.asarray(texels, np.int32), dtype=wp.int32, device=dev)
    tmp = wp.clone(src)
    n = len(texels)
    launch_chunked(blur_vec4_listed, n, inputs=[idx, src, weights, radius, 0], outputs=[tmp], device=dev, min_chunk=1 << 14)
    launch_chunked(blur_vec4_listed, n, inputs=[idx, tmp, weights, radius, 1], outputs=[out], device=dev, min_chunk=1 << 14)
    return out
