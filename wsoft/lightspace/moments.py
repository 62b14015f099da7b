"""Depth distributions known by their first two moments (variance shadow maps and their soft and
mip-mapped kinds): the variance with its floor, and the one-tailed Chebyshev (Cantelli) bound."""

from __future__ import annotations

import warp as wp


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
