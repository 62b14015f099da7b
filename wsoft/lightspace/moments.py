"""Depth distributions known by their moments, for the filterable shadow maps.

* Two moments (variance shadow maps and their soft and mip-mapped kinds: ``vsm``, ``vssm``,
  ``izb``): the variance with its floor, and the one-tailed Chebyshev (Cantelli) bound.
* Four moments (moment shadow maps: ``msm``, ``msm_soft``; Peters & Klein 2015): the moments
  (z, z^2, z^3, z^4) of a normalised depth, the moment bias, the Hamburger four-moment bound (the
  sharpest lower bound on the mass in front of a depth among all distributions on the real line
  with those moments, from the canonical three-point representation that holds that depth) and
  the average depth of that representation's points in front (Peters et al. 2016's blocker
  depth), and the paper's optimised 16-bit quantisation (an affine map of the four moments into
  [0, 1]^4, and its inverse).
* Exponential warps (exponential variance shadow maps, ``evsm``; Lauritzen & McCool 2008): the
  positive and negative warps of a depth and the largest exponent float32 holds.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

# --------------------------------------------------------------------------- two moments


@wp.func
def moments_variance(m1: float, m2: float, min_var: float) -> float:
    """The variance of a distribution with moments ``m1 = E[d]``, ``m2 = E[d^2]``, at least ``min_var``."""
    return wp.max(m2 - m1 * m1, min_var)


@wp.func
def chebyshev_bound(mean: float, var: float, t: float) -> float:
    """The one-tailed Chebyshev (Cantelli) bound var / (var + (t - mean)^2): for ``t`` past the
    mean, at most this much of the distribution lies beyond ``t`` on that side."""
    d = t - mean
    return var / (var + d * d)


# --------------------------------------------------------------------------- four moments

#: Peters & Klein 2015's optimised quantisation (their 64-bit moment shadow maps):
#: q = QUANTISATION @ (z, z^2, z^3, z^4) + QUANTISATION_OFFSET maps the moments of every
#: distribution on [0, 1] into [0, 1]^4 (to 1e-7), spreading them so that 16 bits per channel keep
#: what the Hamburger bound needs.
QUANTISATION = np.array([
    [-2.07224649, 32.23703778, -68.571074599, 39.3703274134],
    [13.7948857237, -59.4683975703, 82.0359750338, -35.364903257],
    [0.105877704, -1.9077466311, 9.3496555107, -6.6543490743],
    [9.7924062118, -33.7652110555, 47.9456096605, -23.9728048165],
], np.float64)
QUANTISATION_OFFSET = np.array([0.035955884801, 0.0, 0.0, 0.0], np.float64)
#: The exact inverse (float64) of :data:`QUANTISATION` (the paper prints it to 10 digits; they agree to 6e-11).
DEQUANTISATION = np.linalg.inv(QUANTISATION)

_Q = wp.constant(wp.mat44(*QUANTISATION.astype(np.float32).ravel()))
_QI = wp.constant(wp.mat44(*DEQUANTISATION.astype(np.float32).ravel()))
_QO = wp.constant(wp.vec4(*QUANTISATION_OFFSET.astype(np.float32)))

#: The moments of the distribution the moment bias mixes in: half at 0, half at 1 (all moments 1/2).
BIAS_MOMENTS = wp.constant(wp.vec4(0.5, 0.5, 0.5, 0.5))


@wp.func
def depth_moments4(z: float) -> wp.vec4:
    """The four moments (z, z^2, z^3, z^4) of a single depth ``z``."""
    z2 = z * z
    return wp.vec4(z, z2, z2 * z, z2 * z2)


@wp.func
def quantise_moments(b: wp.vec4) -> wp.vec4:
    """The paper's optimised quantisation transform of the moments ``b`` (into [0, 1]^4 for depths in [0, 1])."""
    return _Q * b + _QO


@wp.func
def dequantise_moments(q: wp.vec4) -> wp.vec4:
    """The moments whose :func:`quantise_moments` is ``q``."""
    return _QI * (q - _QO)


@wp.func
def unorm(v: float, levels: float) -> float:
    """``v`` stored as an unsigned normalised integer of ``levels`` + 1 steps (``levels`` = 2^bits - 1), read back."""
    return wp.round(wp.clamp(v, 0.0, 1.0) * levels) / levels


@wp.func
def bias_moments(b: wp.vec4, alpha: float) -> wp.vec4:
    """The moment bias (1 - alpha) b + alpha (1/2, 1/2, 1/2, 1/2): the moments of the distribution
    mixed with weight ``alpha`` with one half at 0 and half at 1, which keeps the Hankel matrix
    positive definite through rounding."""
    return b * (1.0 - alpha) + BIAS_MOMENTS * alpha


@wp.func
def safe_den(d: float) -> float:
    """``d`` kept at least 1e-30 away from zero (its sign kept): a denominator that rounding can cancel."""
    if d >= 0.0:
        return wp.max(d, 1.0e-30)
    return wp.min(d, -1.0e-30)


@wp.func
def hamburger_canonical(b: wp.vec4, z: float) -> wp.vec2:
    """The Hamburger four-moment bound at depth ``z`` of a distribution with (biased) moments ``b``
    = (E[x], E[x^2], E[x^3], E[x^4]): (G, I), G the sharpest lower bound on the mass strictly in
    front of ``z`` (x < z) among all distributions on the real line with these moments, and I the
    sum of w_i z_i over the points z_i < z of the canonical representation that G comes from (I /
    G is its average depth in front: Peters et al. 2016's blocker depth).

    The canonical representation holding ``z``: the three-point distribution on {z, z2, z3} with the
    four moments, z2 and z3 the roots of the quadratic c1 + c2 x + c3 x^2 whose coefficients solve
    B c = (1, z, z^2), B the Hankel matrix of (1, b) (here by an LDL^T factorisation, scaled by
    the last pivot so that a singular B, a distribution of two points, still gives its two
    points). G sums the weights (from the first three moments: Lagrange on the three points) of
    the points in front of ``z``. Rounding is guarded, never hidden as a NaN: a kernel holding one
    depth (variance below 1e-12) is that depth's step, a negative discriminant or last pivot is
    taken as 0 (their true values are >= 0), a root beyond 1e8 is taken at 1e8 (its weight is
    below 1e-8 there), and G is clamped to [0, 1]."""
    b0 = b[0]
    b1 = b[1]
    d2 = b1 - b0 * b0
    if d2 < 1.0e-12:
        step = wp.where(b0 < z, 1.0, 0.0)
        return wp.vec2(step, step * b0)
    l32 = (b[2] - b0 * b1) / d2
    d3 = wp.max(b[3] - b1 * b1 - l32 * l32 * d2, 0.0)
    # B c = (1, z, z^2): forward substitution, the pivots, back substitution, all times d3
    y2 = (z - b0) / d2
    c3 = z * z - b1 - l32 * (z - b0)
    c2 = y2 * d3 - l32 * c3
    c1 = d3 - b0 * c2 - b1 * c3
    disc = wp.max(c2 * c2 - 4.0 * c1 * c3, 0.0)
    s = wp.sqrt(disc)
    q = -0.5 * (c2 + wp.where(c2 >= 0.0, s, -s))
    big = float(1.0e8)
    ra = float(0.0)
    rb = float(0.0)
    if q == 0.0:
        # c2 = 0 and c1 c3 = 0: a double root at 0 (c1 = 0) or none in reach (c3 = 0)
        if c3 != 0.0:
            ra = 0.0
            rb = 0.0
        else:
            ra = -big
            rb = big
    else:
        ra = wp.clamp(c1 / q, -big, big)
        if wp.abs(c3) * big > wp.abs(q):
            rb = wp.clamp(q / c3, -big, big)
        else:
            rb = wp.where(q * c3 >= 0.0, big, -big)
    z2 = wp.min(ra, rb)
    z3 = wp.max(ra, rb)
    if z <= z2:
        return wp.vec2(0.0, 0.0)
    w2 = (b1 - b0 * (z + z3) + z * z3) / safe_den((z2 - z) * (z2 - z3))
    if z <= z3:
        g = wp.clamp(w2, 0.0, 1.0)
        return wp.vec2(g, g * z2)
    w3 = (b1 - b0 * (z + z2) + z * z2) / safe_den((z3 - z) * (z3 - z2))
    w0 = (b1 - b0 * (z2 + z3) + z2 * z3) / safe_den((z - z2) * (z - z3))
    g = wp.clamp(1.0 - w0, 0.0, 1.0)
    return wp.vec2(g, w2 * z2 + w3 * z3)


@wp.func
def hamburger_bound(b: wp.vec4, z: float) -> float:
    """The Hamburger four-moment bound (Peters & Klein 2015's Hamburger 4MSM): the sharpest lower bound
    on the mass of a distribution with (biased) moments ``b`` strictly in front of ``z``, the
    shadow intensity; :func:`hamburger_canonical`'s G."""
    return hamburger_canonical(b, z)[0]


@wp.func
def unbiased_intensity(g: float, alpha: float, z: float) -> float:
    """A lower bound ``g`` on the mass in front of ``z`` of moments biased by :func:`bias_moments`
    turned into one on the kernel's own distribution: the biased distribution's mass in front of
    z > 0 is (1 - alpha) P + alpha / 2 (half of the mixed-in distribution sits at depth 0), so
    P >= (g - alpha / 2) / (1 - alpha), clamped to [0, 1]. A lit receiver alone in its kernel then
    gets 0, where ``g`` alone leaves up to alpha / 2."""
    h = g
    if z > 0.0:
        h = g - 0.5 * alpha
    return wp.clamp(h / (1.0 - alpha), 0.0, 1.0)


# --------------------------------------------------------------------------- exponential warps

#: The largest exponent of an EVSM warp on depth mapped to [-1, 1]: e^c and its square e^{2c}, the
#: second moment, must stay finite in float32 (ln FLT_MAX = 88.72, so c <= 44.36); 42 keeps a
#: factor e^{4.7} > 100 in hand for the filter's weighted sums and the variance's products.
EVSM_MAX_EXPONENT = 42.0
assert 2.0 * EVSM_MAX_EXPONENT + math.log(100.0) < math.log(float(np.finfo(np.float32).max))


@wp.func
def evsm_warp(z: float, c_pos: float, c_neg: float) -> wp.vec2:
    """The positive and negative exponential warps of a normalised depth ``z`` in [0, 1], mapped to
    x = 2z - 1 in [-1, 1]: (e^{c_pos x}, -e^{-c_neg x}). Both increase with depth. The exponents are
    clamped to :data:`EVSM_MAX_EXPONENT`, so neither warp nor its square overflows."""
    x = 2.0 * wp.clamp(z, 0.0, 1.0) - 1.0
    cp = wp.min(c_pos, EVSM_MAX_EXPONENT)
    cn = wp.min(c_neg, EVSM_MAX_EXPONENT)
    return wp.vec2(wp.exp(cp * x), -wp.exp(-cn * x))


@wp.func
def warped_chebyshev(mean: float, m2: float, t: float, slope: float, min_var: float) -> float:
    """Chebyshev's bound on a warped depth: the fraction lit at warped receiver depth ``t`` of a
    kernel whose warped depths have moments ``mean``, ``m2``; 1 when ``t`` is not past the mean.
    The variance floor ``min_var`` is on the normalised depth and carried through the warp by its
    slope there (``slope`` = d warp / dz at the receiver): (slope^2) min_var."""
    if t <= mean:
        return 1.0
    var = wp.max(m2 - mean * mean, slope * slope * min_var)
    return chebyshev_bound(mean, var, t)
