"""Parameter declarations shared by techniques and the structures they configure.

A technique's parameters are a frozen dataclass whose fields are made with :func:`param`
(default, meaning, and for numbers the finite range the value must lie in); ``__post_init__``
validates with :func:`check` (a ``ValueError`` that callers report as a
:class:`~wsoft.errors.ParameterError`).
"""

from __future__ import annotations

import dataclasses
import math


def param(default, help: str, *, range: tuple[float, float] | None = None, **kw):
    """A parameter field with its meaning (shown by ``wsoft techniques``).

    ``range``: for numbers, the closed interval a value must lie in (checked by
    :func:`check_ranges`, shown in the manual). Floats always must be finite unless the range's
    upper end is ``inf`` (``budget = inf`` means unbounded)."""
    meta = {"help": help, **kw}
    if range is not None:
        meta["range"] = range
    return dataclasses.field(default=default, metadata=meta)


def check(cond: bool, msg: str) -> None:
    """Validation helper for ``Params.__post_init__``: raises ValueError (reported as a parameter error)."""
    if not cond:
        raise ValueError(msg)


def check_ranges(p) -> None:
    """Check every numeric field of the dataclass ``p`` against its declared ``range``, and that
    float values are finite (``inf`` only where the range allows it). NaN is never valid."""
    for f in dataclasses.fields(p):
        v = getattr(p, f.name)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        lo, hi = f.metadata.get("range", (-math.inf, math.inf))
        if isinstance(v, float):
            check(not math.isnan(v), f"{f.name} is NaN")
            check(math.isfinite(v) or (v == math.inf and hi == math.inf), f"{f.name} = {v} must be finite")
        check(lo <= v <= hi, f"{f.name} = {v:g} out of range [{lo:g}, {hi:g}]")


def range_text(f) -> str:
    """The declared range of a field as text (empty if none)."""
    r = f.metadata.get("range")
    if r is None:
        return ""
    lo, hi = r
    return f"{lo:g}..{hi:g}"


def parse_frames(text: str) -> list[float]:
    """``a:b`` (every time code from a to b, both included, step 1), ``a:b:s`` (step s > 0) or
    ``a`` (one time code) as a list of time codes; a ``ValueError`` naming what is wrong otherwise.
    ``a``, ``b`` and ``s`` are finite numbers, ``a <= b``, at most 100000 time codes."""
    parts = str(text).strip().split(":")
    if not 1 <= len(parts) <= 3 or any(p.strip() == "" for p in parts):
        raise ValueError(f"{text!r} is not a:b, a:b:step or a single time code")
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"{text!r} is not a:b, a:b:step or a single time code (numbers)") from None
    if not all(math.isfinite(x) for x in nums):
        raise ValueError(f"{text!r}: time codes and step must be finite")
    if len(nums) == 1:
        return nums
    a, b = nums[0], nums[1]
    step = nums[2] if len(nums) == 3 else 1.0
    if step <= 0:
        raise ValueError(f"{text!r}: the step must be > 0")
    if b < a:
        raise ValueError(f"{text!r}: the last time code {b:g} is before the first {a:g}")
    n = int(math.floor((b - a) / step + 1e-9)) + 1
    if n > 100000:
        raise ValueError(f"{text!r}: {n} time codes (at most 100000)")
    return [a + i * step for i in range(n)]
