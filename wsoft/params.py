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
