"""Temporal accumulation of a per-sample signal over a sequence's frames: each G-buffer sample's
world point reprojected into the previous frame through its camera, a disocclusion test, the history
clamped to the current frame's neighbourhood, and a running mean over at most ``max_length`` frames
(SVGF's temporal accumulation, Schied et al. 2017 §4.1, with the colour clamp of TAA against
ghosting).

:func:`accumulate` takes the current frame's G-buffer and signal and the previous frame's
:class:`TemporalState` (None: the first frame, every sample starts its history) and returns the
accumulated signal and the state to keep for the next frame. A sample keeps its history when the
pixel of the previous frame its point projects to saw a point within :data:`SAME_POINT` pixel
footprints of it with a normal within :data:`SAME_NORMAL` (the surfaces seen in both frames);
otherwise (the point was hidden or off screen, the surface moved) it is *disoccluded* and starts
again from this frame's value. The history is clamped to the range of the current values in the
3 x 3 pixel neighbourhood (a shadow that moved leaves no ghost), then blended with weight
``1 / n`` for the current value, ``n`` the history's length plus one, at most ``max_length``: the
plain mean of the frames seen so far, then an exponential average of weight ``1 / max_length``.

Signals use :data:`~wsoft.accel.denoise.UNKNOWN` (a sample with no estimate this frame) as the
denoisers do: such a sample is carried as unknown and its history restarts.

The camera is assumed rigid (its ``to_world`` orthonormal, as USD cameras are authored); points and
cameras are in the render's frame plus ``origin`` (its offset from the world origin,
:func:`wsoft.pipeline.framing.local_origin`), so frames with different local origins reproject.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.accel.denoise import UNKNOWN, sample_at
from wsoft.parallel import launch_chunked
from wsoft.raster.camera import CameraGPU
from wsoft.raster.gbuffer import GBufferGPU, gb_covered, gb_index, gb_layer, gb_pixel

SAME_POINT = 0.5  # the previous point within this many pixel footprints: the same surface point
SAME_NORMAL = 0.9  # and its normal's cosine to this one at least this

REPROJECTED = wp.constant(1)
DISOCCLUDED = wp.constant(2)


@dataclass
class TemporalState:
    """What a frame keeps for the next: its G-buffer (points, normals, coverage; sample-major
    ``spp x height x width``), the camera, the local origin, and per sample the accumulated signal
    and its history's length."""

    gb: GBufferGPU
    cam: CameraGPU
    origin: wp.vec3
    signal: wp.array
    length: wp.array


@wp.func
def project_to_pixel(cam: CameraGPU, width: int, height: int, p: wp.vec3) -> wp.vec3:
    """World point ``p`` (in the camera's frame) -> (column, row, ok) in the image the camera's rays
    are cast through (:func:`wsoft.raster.gbuffer.camera_ray`); ok = 1 in front of the camera."""
    d = p - cam.origin
    lx = wp.dot(d, cam.ax)
    ly = wp.dot(d, cam.ay)
    lz = wp.dot(d, cam.az)
    ok = 1.0
    wx = lx
    wy = ly
    if cam.ortho == 0:
        if -lz <= 0.0:
            ok = 0.0
            return wp.vec3(-1.0, -1.0, ok)
        wx = lx / (-lz)
        wy = ly / (-lz)
    fx = ((wx - cam.offset[0]) / cam.tan_half[0] + 1.0) * 0.5 * float(width)
    fy = (1.0 - (wy - cam.offset[1]) / cam.tan_half[1]) * 0.5 * float(height)
    return wp.vec3(fx, fy, ok)


@wp.func
def pixel_footprint(cam: CameraGPU, width: int, p: wp.vec3) -> float:
    """The world width one pixel of the camera covers at ``p``."""
    if cam.ortho != 0:
        return 2.0 * cam.tan_half[0] / float(width)
    return wp.length(p - cam.origin) * 2.0 * cam.tan_half[0] / float(width)


@wp.kernel
def accumulate_history(
    offset: int,
    gb: GBufferGPU,
    cam: CameraGPU,
    origin: wp.vec3,
    cur: wp.array[float],
    prev_gb: GBufferGPU,
    prev_cam: CameraGPU,
    prev_origin: wp.vec3,
    prev_signal: wp.array[float],
    prev_length: wp.array[wp.int32],
    has_prev: int,
    max_length: int,
    # outputs
    acc: wp.array[float],
    length: wp.array[wp.int32],
    flag: wp.array[wp.int32],
):
    """Per sample: the previous frame's accumulated value at the same surface point, clamped to the
    current 3 x 3 neighbourhood's range, blended with the current value (see the module)."""
    i = wp.tid() + offset
    c = cur[i]
    flag[i] = 0
    if not gb_covered(gb, i) or c == UNKNOWN:
        acc[i] = c
        length[i] = 0
        return
    px = gb_pixel(gb, i)
    layer = gb_layer(gb, i)
    lo = c
    hi = c
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            j = sample_at(gb, px[0] + dx, px[1] + dy, layer)
            if j >= 0:
                v = cur[j]
                if v != UNKNOWN:
                    lo = wp.min(lo, v)
                    hi = wp.max(hi, v)
    n = 1
    out = c
    if has_prev != 0:
        # this sample's point in the previous frame's coordinates
        p = gb.pos[i] + origin - prev_origin
        q = project_to_pixel(prev_cam, prev_gb.width, prev_gb.height, p)
        x = int(wp.floor(q[0]))
        y = int(wp.floor(q[1]))
        flag[i] = DISOCCLUDED
        if q[2] > 0.0 and x >= 0 and y >= 0 and x < prev_gb.width and y < prev_gb.height:
            k = gb_index(prev_gb, x, y, wp.min(layer, prev_gb.spp - 1))
            if gb_covered(prev_gb, k):
                h = prev_signal[k]
                near = wp.length(prev_gb.pos[k] - p) <= SAME_POINT * wp.max(pixel_footprint(prev_cam, prev_gb.width, p), pixel_footprint(cam, gb.width, gb.pos[i]))
                facing = wp.dot(prev_gb.nrm[k], gb.nrm[i]) >= SAME_NORMAL
                if near and facing and h != UNKNOWN and prev_length[k] > 0:
                    n = wp.min(prev_length[k] + 1, max_length)
                    h = wp.min(wp.max(h, lo), hi)
                    out = h + (c - h) / float(n)
                    flag[i] = REPROJECTED
    acc[i] = out
    length[i] = n


def accumulate(gb, cam: CameraGPU, origin, signal: wp.array, previous: TemporalState | None, max_length: int, device: str,
               counters: dict | None = None) -> tuple[wp.array, TemporalState]:
    """Accumulate ``signal`` (flat float32 per G-buffer sample) over the sequence's frames (see the
    module): (the accumulated signal, the state to keep). ``gb``: the frame's :class:`GBuffer`;
    ``origin``: the render's local origin in world space (None: world space). ``counters`` gets
    ``history`` (``first frame``, else ``reprojected``), ``history_samples`` (samples that kept
    their history), ``disoccluded`` and ``history_mean_length``."""
    n = gb.count
    g = gb.gpu()
    o = wp.vec3(*(np.asarray(origin, np.float64) if origin is not None else np.zeros(3)))
    acc = wp.empty(n, dtype=float, device=device)
    length = wp.empty(n, dtype=wp.int32, device=device)
    flag = wp.empty(n, dtype=wp.int32, device=device)
    prev = previous if previous is not None else TemporalState(g, cam, o, signal, wp.zeros(n, dtype=wp.int32, device=device))
    launch_chunked(accumulate_history, n,
                   inputs=[g, cam, o, signal, prev.gb, prev.cam, prev.origin, prev.signal, prev.length, int(previous is not None), int(max_length)],
                   outputs=[acc, length, flag], device=device)
    if counters is not None:
        f = flag.numpy()
        ln = length.numpy()
        kept = int((f == 1).sum())
        counters.update(history="reprojected" if previous is not None else "first frame", history_samples=kept,
                        disoccluded=int((f == 2).sum()), history_mean_length=round(float(ln[ln > 0].mean()) if (ln > 0).any() else 0.0, 3))
    return acc, TemporalState(g, cam, o, acc, length)
