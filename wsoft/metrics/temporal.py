"""Error in time: flicker against the reference, a stochastic technique's crawl, and the
reprojection that pairs the pixels of consecutive frames.

A frame-to-frame change of a technique's visibility is right when the reference changes as much:
**flicker** is the mean over paired pixels and frame pairs of ``|ΔV_t − ΔV_ref,t|`` (ΔV_t = V_t −
V_{t−1} at the same surface point). Where the camera stands still the pairs are the same pixel
(what moves in the image moves in the reference too). Where it moves, a pixel of frame t is
paired with the pixel of frame t−1 its world point (the G-buffer's ``P``) projects to, and kept
only if frame t−1 saw that same point there (the surfaces seen in both; a disocclusion, a point
off screen, or a surface that moved is left out), so a shadow that stays put in the world must stay
put in the image.

The reference is itself an estimate: its own frame-to-frame noise, from its standard errors
(``V_stderr``), is :func:`flicker_noise`, the flicker a perfect technique would measure against it
when the reference's noise is independent between frames; a flicker near or below it is not
resolved. The **temporal standard deviation** of a static sequence (nothing moves) is a
stochastic technique's crawl: per pixel the standard deviation of V over the frames, averaged.

Everything here is numpy on the host over per-pixel channels (``P.X``, ``P.Y``, ``P.Z``, ``A``,
``V``) and the frames' cameras (:class:`FrameCamera`, from a frame's ``stats["camera_model"]``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SAME_POINT = 0.5
"""A pixel of frame t reprojected into frame t−1 keeps its pair when the point frame t−1 saw there
lies within this many pixel footprints (the width a pixel covers at that distance) of its own
point: the previous frame sampled (nearly) the same world point, so a shadow edge that stays put
in the world gives the same V in both (a looser pairing compares points a pixel apart, across
which a sharp edge changes V though nothing moved). A point hidden in the previous frame, off its
image, or on a surface that moved is left without a pair, as are the points that fell between the
previous frame's samples."""


@dataclass(frozen=True)
class FrameCamera:
    """The camera a frame was rendered with, as the G-buffer casts its rays
    (:func:`wsoft.raster.gbuffer.camera_ray`): ``to_world`` 4x4 (column vectors, looking down −Z),
    ``tan_half`` (perspective: tangents of the half fields; orthographic: half extents),
    ``offset``, the full image's ``width`` x ``height`` and the frame's data window in it
    (``crop`` x0, y0, x1, y1: the frame's channels are those pixels)."""

    to_world: tuple
    tan_half: tuple[float, float]
    offset: tuple[float, float]
    orthographic: bool
    width: int
    height: int
    crop: tuple[int, int, int, int]

    @staticmethod
    def of(stats: dict) -> "FrameCamera":
        """The camera of a frame, from its ``stats["camera_model"]``."""
        m = stats["camera_model"]
        crop = m.get("crop") or (0, 0, m["width"], m["height"])
        return FrameCamera(tuple(map(tuple, m["to_world"])), tuple(m["tan_half"]), tuple(m["offset"]), bool(m["orthographic"]),
                           int(m["width"]), int(m["height"]), tuple(int(c) for c in crop))

    def same_view(self, other: "FrameCamera") -> bool:
        """Do both frames see through the same pixels (a camera standing still)?"""
        return (np.allclose(np.asarray(self.to_world), np.asarray(other.to_world), rtol=0.0, atol=1e-9 * _scale(self))
                and self.tan_half == other.tan_half and self.offset == other.offset and self.orthographic == other.orthographic
                and (self.width, self.height, self.crop) == (other.width, other.height, other.crop))

    def project(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World points ``p`` [N, 3] -> (column, row) in the frame's channels (pixel units, (0, 0)
        the top-left corner of the data window) and ``ok`` (in front of the camera)."""
        M = np.asarray(self.to_world, np.float64)
        local = (p - M[:3, 3]) @ np.linalg.inv(M[:3, :3]).T
        if self.orthographic:
            wx, wy, ok = local[:, 0], local[:, 1], np.ones(len(p), bool)
        else:
            depth = -local[:, 2]
            ok = depth > 0.0
            safe = np.where(ok, depth, 1.0)
            wx, wy = local[:, 0] / safe, local[:, 1] / safe
        ndc_x = (wx - self.offset[0]) / self.tan_half[0]
        ndc_y = (wy - self.offset[1]) / self.tan_half[1]
        fx = (ndc_x + 1.0) * 0.5 * self.width - self.crop[0]
        fy = (1.0 - ndc_y) * 0.5 * self.height - self.crop[1]
        return fx, fy, ok

    def footprint(self, p: np.ndarray) -> np.ndarray:
        """The world width a pixel covers at the points ``p`` [N, 3]."""
        if self.orthographic:
            return np.full(len(p), 2.0 * self.tan_half[0] / self.width)
        d = np.linalg.norm(p - np.asarray(self.to_world, np.float64)[:3, 3], axis=1)
        return d * 2.0 * self.tan_half[0] / self.width


def _scale(cam: FrameCamera) -> float:
    return max(1.0, float(np.abs(np.asarray(cam.to_world, np.float64)[:3, 3]).max()))


def positions(channels: dict) -> np.ndarray:
    """The G-buffer's world positions ``P`` as [H, W, 3] float64."""
    return np.stack([channels["P.X"], channels["P.Y"], channels["P.Z"]], -1).astype(np.float64)


@dataclass
class Pairs:
    """Pixels of frame t (``cur``, flat indices) paired with pixels of frame t−1 (``prev``) that saw
    the same surface point; ``covered`` counts frame t's covered pixels, ``disoccluded`` those left
    without a pair (seen only in frame t, off frame t−1's image, on a surface that moved, or between
    the previous frame's samples)."""

    cur: np.ndarray
    prev: np.ndarray
    covered: int
    disoccluded: int
    reprojected: bool


def pair_pixels(prev: dict, cur: dict, cam_prev: FrameCamera, cam_cur: FrameCamera, same_point: float = SAME_POINT) -> Pairs:
    """Pair the covered pixels of frame t (``cur`` channels) with frame t−1's (``prev``): the same
    pixel when the camera stood still, else the pixel of frame t−1 that frame t's world point
    projects to, kept when frame t−1 saw a point within ``same_point`` pixel footprints of it
    there (:class:`Pairs`)."""
    a_cur = np.asarray(cur["A"]) > 0
    a_prev = np.asarray(prev["A"]) > 0
    h, w = a_cur.shape
    covered = int(a_cur.sum())
    if cam_prev.same_view(cam_cur) and a_prev.shape == a_cur.shape:
        both = (a_cur & a_prev).reshape(-1)
        idx = np.flatnonzero(both)
        return Pairs(idx, idx, covered, covered - len(idx), False)
    p_cur = positions(cur).reshape(-1, 3)
    idx = np.flatnonzero(a_cur.reshape(-1))
    pts = p_cur[idx]
    fx, fy, ok = cam_prev.project(pts)
    hp, wp_ = a_prev.shape
    col = np.floor(fx).astype(np.int64)
    row = np.floor(fy).astype(np.int64)
    ok &= (col >= 0) & (col < wp_) & (row >= 0) & (row < hp) & np.isfinite(fx) & np.isfinite(fy)
    col, row = np.where(ok, col, 0), np.where(ok, row, 0)
    j = row * wp_ + col
    ok &= a_prev.reshape(-1)[j]
    p_prev = positions(prev).reshape(-1, 3)[j]
    tol = same_point * np.maximum(cam_prev.footprint(pts), cam_cur.footprint(pts))
    ok &= np.linalg.norm(p_prev - pts, axis=1) <= tol
    return Pairs(idx[ok], j[ok], covered, covered - int(ok.sum()), True)


def flicker(v_prev: np.ndarray, v_cur: np.ndarray, r_prev: np.ndarray, r_cur: np.ndarray, pairs: Pairs) -> dict:
    """Flicker of one frame pair against the reference: the mean over paired pixels of
    ``|(V_t − V_{t−1}) − (R_t − R_{t−1})|``, and the mean ``|V_t − V_{t−1}|`` (the technique's own
    change) and ``|R_t − R_{t−1}|`` (the reference's) beside it. A non-finite V counts as a change
    of 1 and is counted in ``nonfinite``."""
    vc, vp = np.asarray(v_cur, np.float64).reshape(-1)[pairs.cur], np.asarray(v_prev, np.float64).reshape(-1)[pairs.prev]
    rc, rp = np.asarray(r_cur, np.float64).reshape(-1)[pairs.cur], np.asarray(r_prev, np.float64).reshape(-1)[pairs.prev]
    dv = vc - vp
    dr = rc - rp
    bad = ~np.isfinite(dv)
    diff = np.where(bad, 1.0, np.abs(dv - dr))
    n = len(diff)
    return {"pixels": n, "flicker": float(diff.mean()) if n else 0.0, "flicker_sd": float(diff.std()) if n else 0.0,
            "change": float(np.where(bad, 1.0, np.abs(dv)).mean()) if n else 0.0,
            "reference_change": float(np.abs(dr).mean()) if n else 0.0, "nonfinite": int(bad.sum()),
            "disoccluded": pairs.disoccluded, "covered": pairs.covered, "reprojected": pairs.reprojected}


def flicker_noise(se_prev: np.ndarray, se_cur: np.ndarray, pairs: Pairs) -> float:
    """The flicker a technique equal to the truth would measure against a reference whose frames'
    noise is independent with standard errors ``se``: the mean over paired pixels of
    E|N(0, se_t² + se_{t−1}²)| = sqrt(2/π) sqrt(se_t² + se_{t−1}²). A reference with the same
    light samples in every frame (a fixed seed) has correlated noise and less flicker than this:
    it bounds the reference's contribution from above."""
    a = np.asarray(se_cur, np.float64).reshape(-1)[pairs.cur]
    b = np.asarray(se_prev, np.float64).reshape(-1)[pairs.prev]
    if len(a) == 0:
        return 0.0
    return float(np.mean(np.sqrt(2.0 / math.pi) * np.sqrt(a * a + b * b)))


def temporal_std(vs: list[np.ndarray], covered: np.ndarray) -> float:
    """Mean over the ``covered`` pixels (bool [H, W]) of the standard deviation of V over the frames
    ``vs`` (a static sequence: a deterministic technique gives 0, a stochastic one its crawl)."""
    if len(vs) < 2 or not covered.any():
        return 0.0
    stack = np.stack([np.asarray(v, np.float64)[covered] for v in vs])
    return float(np.std(stack, axis=0, ddof=1).mean())


def sequence_summary(per_pair: list[dict], errors: list[dict], times: list[float], noise: list[float] | None = None,
                     own_noise: list[float] | None = None) -> dict:
    """One technique over a sequence: flicker (mean over frame pairs, each weighted by its paired
    pixels) and its standard error (``flicker_se``: the pixels' spread over the square root of
    their number, pairs combined), the mean and worst per-frame error (``errors``: the metric pass's
    dicts, one per frame); with ``noise`` (the reference's :func:`flicker_noise` per pair) the mean
    noise floor ``flicker_noise``; with ``own_noise`` (the technique's own, from its standard
    errors) ``own_noise`` and ``flicker_excess`` = flicker − own_noise, what its noise does not
    explain (within ``flicker_se`` of 0: its frames change by their noise only)."""
    n = sum(p["pixels"] for p in per_pair)
    out = {
        "frames": len(errors),
        "pairs": len(per_pair),
        "flicker": float(sum(p["flicker"] * p["pixels"] for p in per_pair) / n) if n else 0.0,
        "flicker_se": float(math.sqrt(sum(p["pixels"] * p.get("flicker_sd", 0.0) ** 2 for p in per_pair)) / n) if n else 0.0,
        "change": float(sum(p["change"] * p["pixels"] for p in per_pair) / n) if n else 0.0,
        "reference_change": float(sum(p["reference_change"] * p["pixels"] for p in per_pair) / n) if n else 0.0,
        "paired_pixels": n,
        "disoccluded": int(sum(p["disoccluded"] for p in per_pair)),
        "mae": float(np.mean([e["mae"] for e in errors])) if errors else 0.0,
        "mae_penumbra": float(np.mean([e["mae_penumbra"] for e in errors])) if errors else 0.0,
    }
    if errors:
        worst = int(np.argmax([e["mae_penumbra"] if e["penumbra_pixels"] else e["mae"] for e in errors]))
        out["worst_frame"] = {"time": times[worst], "mae": errors[worst]["mae"], "mae_penumbra": errors[worst]["mae_penumbra"]}
    w = [p["pixels"] for p in per_pair]
    if noise is not None and per_pair:
        out["flicker_noise"] = float(np.average(noise, weights=w)) if sum(w) else 0.0
    if own_noise is not None and per_pair and sum(w):
        out["own_noise"] = float(np.average(own_noise, weights=w))
        out["flicker_excess"] = out["flicker"] - out["own_noise"]
    return out
