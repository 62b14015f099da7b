"""The regression gate's two tests, on plain numbers (no rows, no files).

**Time** (after airspeed velocity's ``asv continuous`` and its ``is_different``): the ratio of the
medians new/old of a metric's per-round times, judged against the rounds' spread. A slowdown counts
when the ratio exceeds ``1 + threshold`` *and* a two-sided Mann-Whitney U test over the rounds
(``scipy.stats.mannwhitneyu``) gives p at most the run's corrected level: ``ALPHA`` (0.05) is the
chance of any false alarm over the run's k time comparisons, so each comparison is tested at
Šidák's ``1 - (1 - ALPHA) ** (1 / k)`` (:func:`sidak`; 40 comparisons: 0.00128). Both conditions are
required: a significant change below the threshold is unchanged, and so is a ratio beyond it that
the rounds' spread does not confirm. Speed-ups are judged the same way, mirrored (ratio below
``1 / (1 + threshold)``). The test can reject only when its smallest attainable p-value,
``2 / C(m + n, m)`` for m old and n new rounds (every new round beyond every old one), is at most
that level (:func:`min_p`; 3 against 3: 0.1, 8 against 8: 0.00016); a metric whose rounds cannot
reach it is "too few rounds", never judged, and the report says so: the gate's timed rounds
(:mod:`wsoft.bench.regress_rounds`, 16 by default) reach any level a run needs. An
infinite threshold judges no time (the gate on accuracy alone).

**Accuracy** (penumbra MAE, ꟻLIP, flicker: lower is better): the change ``d = new - old`` counts
when ``|d| > max(floor, Z * sqrt(se_old**2 + se_new**2))``, with each side's standard error as
its row carries it (the flicker's ``flicker_se``, the spread of per-frame values ``stdev / sqrt(n)``)
and 0 where the row carries none: a single-frame row renders a deterministic technique against
the same cached, seeded reference in both runs, so the reference's Monte Carlo noise is the same
on both sides and cancels from ``d``. ``floor`` is a metric's smallest change that matters
(:data:`FLOORS`). A value that turns NaN, or a NaN-pixel count that grows, is a regression.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

ALPHA = 0.05  # the chance of any time false alarm in one comparison of two runs (Šidák-corrected per comparison)
Z = 3.0  # standard errors an accuracy change must exceed
TIME_THRESHOLD = 0.10  # default: a slowdown counts from 10 % on
DEFAULT_TIMER = "host"  # the time the gate judges by default (wsoft.bench.regress_rounds; docs/ci.md: the proof's runs)
# the smallest change of each accuracy metric that counts (absolute, in the metric's units):
# MAE in the penumbra: half of one 8-bit display step (1/255 = 0.0039), a shift no 8-bit image
# shows on average over the penumbra; ꟻLIP (the frame's mean, on its 0-1 scale) and flicker (the
# mean frame-to-frame change of V where the reference holds still): 0.001, a tenth of a percent
# of their range and below the gaps between the sweeps' techniques (ꟻLIP of pcss 0.0011 against
# pcf 0.0043 in `wsoft bench filtered --quick`)
FLOORS = {"mae_penumbra": 0.002, "flip": 0.001, "flicker": 0.001}


@dataclass
class Verdict:
    """What a test found: ``kind`` is "worse", "better", "same", "not judged" or (a time metric)
    "too few rounds"; ``how`` says why
    in a few words (the ratio and p-value, or the change and its tolerance)."""

    kind: str
    how: str
    ratio: float | None = None  # a time metric's ratio of medians new/old


def _finite(xs) -> list[float]:
    return [float(x) for x in xs if x is not None and math.isfinite(float(x))]


def sidak(alpha: float, k: int) -> float:
    """The level of each of ``k`` independent tests that keeps the chance of any false rejection at
    ``alpha`` (Šidák): ``1 - (1 - alpha) ** (1 / k)``."""
    return 1.0 - (1.0 - alpha) ** (1.0 / max(k, 1))


def min_p(m: int, n: int) -> float:
    """The smallest p-value a two-sided U test of m against n samples can give: ``2 / C(m+n, m)``
    (every sample of one side beyond every sample of the other), at most 1."""
    return min(1.0, 2.0 / math.comb(m + n, m)) if m and n else 1.0


def time_verdict(old, new, threshold: float = TIME_THRESHOLD, alpha: float = ALPHA) -> Verdict:
    """Judge per-round times ``old`` against ``new`` at the per-comparison level ``alpha`` (the
    caller's Šidák-corrected level, :func:`sidak`; see the module docstring). ``kind`` is
    "too few rounds" when the rounds cannot reach ``alpha`` whatever they hold."""
    a, b = _finite(old), _finite(new)
    if not b:
        return Verdict("worse", "no finite time")
    if not a:
        return Verdict("not judged", "no old time")
    ratio = statistics.median(b) / statistics.median(a) if statistics.median(a) > 0 else math.inf
    if math.isinf(threshold):
        return Verdict("not judged", f"x{ratio:.2f} (no threshold)", ratio)
    hi, lo = 1.0 + threshold, 1.0 / (1.0 + threshold)
    floor_p = min_p(len(a), len(b))
    if floor_p > alpha:
        return Verdict("too few rounds", f"x{ratio:.2f}; {len(a)} vs {len(b)} rounds: smallest p {floor_p:.3g} > level {alpha:.3g}", ratio)
    if lo <= ratio <= hi:
        return Verdict("same", f"x{ratio:.2f}", ratio)
    from scipy.stats import mannwhitneyu

    p = float(mannwhitneyu(b, a, alternative="two-sided").pvalue)
    how = f"x{ratio:.2f}, U test p={p:.2g} (level {alpha:.2g}, {len(a)} vs {len(b)} rounds)"
    if p > alpha:
        return Verdict("same", how, ratio)
    return Verdict("worse" if ratio > hi else "better", how, ratio)


def spread_se(samples) -> float:
    """The standard error of the mean of ``samples`` (``stdev / sqrt(n)``; 0 for fewer than 2)."""
    xs = _finite(samples or [])
    return statistics.stdev(xs) / math.sqrt(len(xs)) if len(xs) >= 2 else 0.0


def accuracy_verdict(old: float | None, new: float | None, se_old: float = 0.0, se_new: float = 0.0, floor: float = 0.0,
                     z: float = Z) -> Verdict:
    """Judge an error metric (lower is better) ``old`` against ``new`` (see the module docstring)."""
    old_nan = old is None or not math.isfinite(old)
    new_nan = new is None or not math.isfinite(new)
    if new_nan and not old_nan:
        return Verdict("worse", "became NaN")
    if old_nan and not new_nan:
        return Verdict("better", "NaN became finite")
    if old_nan and new_nan:
        return Verdict("same", "NaN on both sides")
    tol = max(floor, z * math.sqrt(se_old ** 2 + se_new ** 2))
    d = new - old
    how = f"{d:+.4f} vs tolerance {tol:.4f}"
    if d > tol:
        return Verdict("worse", how)
    if d < -tol:
        return Verdict("better", how)
    return Verdict("same", how)


def count_verdict(old: float | None, new: float | None) -> Verdict:
    """A count that must not grow (NaN pixels): more than before is a regression."""
    o, n = float(old or 0), float(new if new is not None else math.inf)
    if n > o:
        return Verdict("worse", f"{o:g} -> {n:g} NaN pixels")
    if n < o:
        return Verdict("better", f"{o:g} -> {n:g} NaN pixels")
    return Verdict("same", f"{n:g} NaN pixels")
