"""Smooth deterministic noise, curves through control points and closed swept tubes."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from wsoft.stages.mesh import MeshData


class Ripple:
    """Smooth periodic-in-angle noise: sum of sin(2 pi f t + k theta + phase).

    Frequencies f, integer angular frequencies k and phases come from a seeded
    generator; the result lies roughly in [-1, 1].
    """

    def __init__(self, seed: int, terms: int = 6, fmax: float = 4.0, kmax: int = 4):
        rng = np.random.default_rng(seed)
        self.f = rng.uniform(0.5, fmax, size=terms)
        self.k = rng.integers(0, kmax + 1, size=terms).astype(np.float64)
        self.ph = rng.uniform(0.0, 2.0 * math.pi, size=terms)
        self.a = 1.0 / (1.0 + np.arange(terms))
        self.a /= self.a.sum()

    def __call__(self, t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        out = np.zeros(np.broadcast(t, theta).shape)
        for f, k, ph, a in zip(self.f, self.k, self.ph, self.a):
            out += a * np.sin(2.0 * math.pi * f * t + k * theta + ph)
        return out


def polyline(ctrl: Sequence[Sequence[float]]) -> Callable[[np.ndarray], np.ndarray]:
    """Smooth curve through control points (Catmull-Rom), parameter t in [0, 1]."""
    c = np.asarray(ctrl, dtype=np.float64)
    c = np.concatenate([2 * c[:1] - c[1:2], c, 2 * c[-1:] - c[-2:-1]], axis=0)
    n_seg = len(ctrl) - 1

    def curve(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        s = np.clip(t, 0.0, 1.0) * n_seg
        i = np.minimum(s.astype(np.int64), n_seg - 1)
        u = (s - i)[:, None]
        p0, p1, p2, p3 = c[i], c[i + 1], c[i + 2], c[i + 3]
        return 0.5 * ((2 * p1) + (-p0 + p2) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u * u
                      + (-p0 + 3 * p1 - 3 * p2 + p3) * u * u * u)

    return curve


def tube(curve: Callable[[np.ndarray], np.ndarray],
         radius: Callable[[np.ndarray, np.ndarray], np.ndarray],
         n_along: int, n_around: int, caps: bool = True) -> MeshData:
    """Closed swept tube: n_along rings of n_around points around `curve`.

    Rings sit at t = (1 - cos(pi k / (n_along + 1))) / 2, k = 1..n_along (dense
    near the ends, like sphere stacks); with caps, pole points at curve(0) and
    curve(1) close the ends with triangle fans.  radius(t (n,1), theta (1,m))
    gives the ring radii.  Frames are parallel-transported along the curve.
    Quads between rings, wound outward.  Triangles: 2 * n_along * n_around
    with caps.
    """
    k = np.arange(1, n_along + 1, dtype=np.float64)
    t = 0.5 - 0.5 * np.cos(math.pi * k / (n_along + 1))
    c = curve(t)
    eps = 1e-4
    tan = curve(np.minimum(t + eps, 1.0)) - curve(np.maximum(t - eps, 0.0))
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    ref = np.array([0.0, 0.0, 1.0]) if abs(tan[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    nrm = np.empty_like(tan)
    n0 = np.cross(ref, tan[0])
    nrm[0] = n0 / np.linalg.norm(n0)
    for i in range(1, len(t)):
        v = nrm[i - 1] - np.dot(nrm[i - 1], tan[i]) * tan[i]
        nrm[i] = v / np.linalg.norm(v)
    bin_ = np.cross(tan, nrm)
    th = 2.0 * math.pi * np.arange(n_around) / n_around
    r = radius(t[:, None], th[None, :])
    pts = (c[:, None, :] + r[:, :, None] * (np.cos(th)[None, :, None] * nrm[:, None, :]
                                             + np.sin(th)[None, :, None] * bin_[:, None, :]))
    pts = pts.reshape(-1, 3)
    ring = np.arange(n_along * n_around).reshape(n_along, n_around)
    nxt = np.roll(ring, -1, axis=1)
    quads = np.stack([ring[:-1], nxt[:-1], nxt[1:], ring[1:]], axis=-1).reshape(-1, 4)
    counts = [4] * len(quads)
    idx = quads.reshape(-1).tolist()
    if caps:
        s, e = len(pts), len(pts) + 1
        pts = np.concatenate([pts, curve(np.array([0.0, 1.0]))], axis=0)
        first, last = ring[0], ring[-1]
        fan_s = np.stack([np.full(n_around, s), np.roll(first, -1), first], axis=-1)
        fan_e = np.stack([np.full(n_around, e), last, np.roll(last, -1)], axis=-1)
        counts += [3] * (2 * n_around)
        idx += fan_s.reshape(-1).tolist() + fan_e.reshape(-1).tolist()
    return pts, counts, idx


def rounded(profile: Callable[[np.ndarray], np.ndarray], power: float = 0.5,
            bump: float = 0.0, seed: int = 0, fmax: float = 4.0, kmax: int = 4
            ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Radius function profile(t) * sin(pi t)^power * (1 + bump * noise(t, theta))."""
    noise = Ripple(seed, fmax=fmax, kmax=kmax) if bump else None

    def radius(t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        r = profile(t) * np.sin(math.pi * t) ** power
        r = np.broadcast_to(r, np.broadcast(t, theta).shape).copy()
        if noise is not None:
            r *= 1.0 + bump * noise(t, theta)
        return r

    return radius


def lerp_profile(values: Sequence[float]) -> Callable[[np.ndarray], np.ndarray]:
    """Piecewise-linear radius profile through `values` at equally spaced t."""
    xs = np.linspace(0.0, 1.0, len(values))
    vs = np.asarray(values, dtype=np.float64)
    return lambda t: np.interp(t, xs, vs)
