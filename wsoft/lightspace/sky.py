"""Directions of the sky: the sets of directions a dome technique draws, and the hemisphere maps it
shares (:mod:`wsoft.scene.dome` holds the dome itself: its radiance, latlong layout and sampling table).

A dome's visibility is V = E_occluded / E_unoccluded, both integrals of the radiance ``L(w)`` times
``max(0, n . w)`` over the sphere. A technique that estimates it from a set of directions ``w_k``
with weights ``a_k`` (:class:`SkyDirections`: the radiance each direction stands for, its
luminance over its probability density and the set's size) computes, per receiver,
``V = sum a_k cos_k vis_k / sum a_k cos_k`` with ``cos_k = max(0, n . w_k)`` (:func:`sky_ratio`
accumulates both sums): the ratio estimator, exact when every direction is visible and unbiased as
the set grows.

* A constant dome: :func:`fibonacci_sphere` — ``count`` directions of equal solid angle over the
  whole sphere (a spherical Fibonacci lattice, turned by ``seed``), equal weights.
* A latlong texture: ``count`` draws from its :class:`~wsoft.scene.dome.SamplingTable` (texel in
  proportion to luminance x solid angle), stratified by a shifted 2D rank-1 lattice for the texel
  and a 2D one inside it; weight = the direction's luminance / its pdf / count.

Per-pixel hemisphere rays: :func:`cosine_direction` maps two uniform numbers to a direction about a
normal with density cos / pi (Malley's method over the concentric disk).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.lightspace.samples import concentric_disk

GOLDEN = 0.6180339887498949
LUMINANCE = (0.2126, 0.7152, 0.0722)  # Rec. 709: the weight of a direction is its radiance's luminance


@dataclass(frozen=True, eq=False)
class SkyDirections:
    """A set of world directions toward the sky and the radiance each stands for.

    ``dirs`` shape ``[N, 3]`` float64, unit, from the receiver toward the sky; ``weights`` shape
    ``[N]`` float64, >= 0 (luminance / pdf / N: their sum estimates the dome's luminance integrated
    over the sphere; a constant dome: 4 pi L / N each)."""

    dirs: np.ndarray
    weights: np.ndarray

    @property
    def count(self) -> int:
        return int(len(self.dirs))


def fibonacci_sphere(count: int, seed: int = 0) -> np.ndarray:
    """``count`` unit directions of equal solid angle over the sphere, ``[count, 3]`` float64: the
    spherical Fibonacci lattice (z uniform in [-1, 1] at the cell centres, longitudes by the golden
    ratio), its longitudes turned by a random angle drawn from ``seed`` (seed 0: no turn)."""
    if count < 1:
        raise ValueError(f"need at least one direction, not {count}")
    k = np.arange(count, dtype=np.float64)
    z = 1.0 - (2.0 * k + 1.0) / count
    turn = 0.0 if seed == 0 else float(np.random.default_rng(seed).random()) * 2.0 * math.pi
    phi = 2.0 * math.pi * np.mod(k * GOLDEN, 1.0) + turn
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _lattice(count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A rank-1 (Fibonacci) lattice of ``count`` points in the unit square, shifted toroidally at random."""
    k = np.arange(count, dtype=np.float64)
    shift = rng.random(2)
    return np.mod((k + 0.5) / count + shift[0], 1.0), np.mod(k * GOLDEN + shift[1], 1.0)


def sky_directions(light, count: int, seed: int = 0) -> SkyDirections:
    """``count`` directions toward ``light``'s dome (``light.dome``, :class:`~wsoft.scene.dome.Dome`)
    with their weights (:class:`SkyDirections`): equal solid angle and equal weights for a constant
    dome (:func:`fibonacci_sphere`); for a latlong texture, draws in proportion to luminance x solid
    angle (stratified), each weighted by its luminance over its pdf, in the world frame (the dome's
    rotation honoured)."""
    from wsoft.scene.dome import radiance, sample_texels

    dome = light.dome
    scale = float(np.asarray(light.color, np.float64) @ np.asarray(LUMINANCE)) * float(light.intensity)
    if dome.texture is None:
        d = fibonacci_sphere(count, seed)
        return SkyDirections(d, np.full(count, 4.0 * math.pi * max(scale, 0.0) / count))
    rng = np.random.default_rng(seed)
    u1, u2 = _lattice(count, rng)
    u3, u4 = _lattice(count, rng)
    rng.shuffle(u3)  # decorrelate the point inside a texel from the texel's draw
    local, pdf = sample_texels(dome.table, u1, u2, u3, u4)
    world = local @ np.asarray(dome.rotation, np.float64).T
    world /= np.linalg.norm(world, axis=1, keepdims=True)
    lum = np.maximum(radiance(light, world) @ np.asarray(LUMINANCE), 0.0)
    w = np.where(pdf > 0.0, lum / np.maximum(pdf, 1e-30), 0.0) / count
    return SkyDirections(world, w)


def effective_count(weights: np.ndarray) -> float:
    """Kish's effective sample size of a weighted set: (sum w)^2 / sum w^2 (``count`` for equal weights)."""
    w = np.asarray(weights, np.float64)
    s2 = float((w * w).sum())
    return float(w.sum() ** 2 / s2) if s2 > 0.0 else 0.0


@wp.func
def tangent_frame(n: wp.vec3):
    """Two unit vectors (t, b) that make (t, b, n) a right-handed orthonormal frame (Duff et al. 2017)."""
    s = wp.where(n[2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (s + n[2])
    b = n[0] * n[1] * a
    t = wp.vec3(1.0 + s * n[0] * n[0] * a, s * b, -s * n[0])
    bb = wp.vec3(b, s + n[1] * n[1] * a, -n[1])
    return t, bb


@wp.func
def cosine_direction(n: wp.vec3, u: wp.vec2) -> wp.vec3:
    """A unit direction about the unit normal ``n`` drawn with density cos(theta) / pi from the
    uniform point ``u`` in [0, 1)^2 (Malley: the concentric disk lifted to the hemisphere)."""
    d = concentric_disk(u[0], u[1])
    z = wp.sqrt(wp.max(0.0, 1.0 - d[0] * d[0] - d[1] * d[1]))
    t, b = tangent_frame(n)
    return wp.normalize(t * d[0] + b * d[1] + n * z)


@wp.kernel
def sky_ratio(
    offset: int,
    num: wp.array[float],
    den: wp.array[float],
    # outputs
    vis: wp.array[float],
):
    """V = num / den per receiver (1 where ``den`` is 0: the dome does not light it, nothing to shadow)."""
    i = wp.tid() + offset
    d = den[i]
    vis[i] = wp.where(d > 0.0, wp.clamp(num[i] / wp.max(d, 1.0e-30), 0.0, 1.0), 1.0)
