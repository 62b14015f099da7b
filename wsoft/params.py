"""Parameter declarations shared by techniques and the structures they configure.

A technique's parameters are a frozen dataclass whose fields are made with :func:`param`
(default, meaning, and for numbers the finite range the value must lie in); ``__post_init__``
validates with :func:`check` (a ``ValueError`` that callers report as a
:class:`~wsoft.errors.ParameterError`).
"""

from __future__ import annotations

import dataclasses
import math


def param(default, help: str, *, range: tuple[float, float] | None = None, choices: tuple[str, ...] | None = None, **kw):
    """A parameter field with its meaning (shown by ``wsoft techniques``).

    ``range``: for numbers, the closed interval a value must lie in (checked by
    :func:`check_ranges`, shown in the manual). Floats always must be finite unless the range's
    upper end is ``inf`` (``budget = inf`` means unbounded). ``choices``: the values a text
    parameter may take (checked by :func:`check_ranges`, shown in the manual's range column)."""
    meta = {"help": help, **kw}
    if range is not None:
        meta["range"] = range
    if choices is not None:
        meta["choices"] = tuple(choices)
    return dataclasses.field(default=default, metadata=meta)


def check(cond: bool, msg: str) -> None:
    """Validation helper for ``Params.__post_init__``: raises ValueError (reported as a parameter error)."""
    if not cond:
        raise ValueError(msg)


def check_ranges(p) -> None:
    """Check every numeric field of the dataclass ``p`` against its declared ``range``, and that
    float values are finite (``inf`` only where the range allows it), and every field with declared
    ``choices`` against them. NaN is never valid."""
    for f in dataclasses.fields(p):
        v = getattr(p, f.name)
        choices = f.metadata.get("choices")
        if choices is not None:
            check(v in choices, f"{f.name} {v!r} is not one of {', '.join(choices)}")
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        lo, hi = f.metadata.get("range", (-math.inf, math.inf))
        if isinstance(v, float):
            check(not math.isnan(v), f"{f.name} is NaN")
            check(math.isfinite(v) or (v == math.inf and hi == math.inf), f"{f.name} = {v} must be finite")
        check(lo <= v <= hi, f"{f.name} = {v:g} out of range [{lo:g}, {hi:g}]")


def range_text(f) -> str:
    """The declared range (or choices) of a field as text (empty if none)."""
    if "choices" in f.metadata:
        return ", ".join(f.metadata["choices"])
    r = f.metadata.get("range")
    if r is None:
        return ""
    lo, hi = r
    return f"{lo:g}..{hi:g}"


VIEWS = ("fitted", "stable", "sequence")
CUBE_MODES = ("auto", "always", "never")  # wsoft.lightspace.cube: when a light's views form a cube map
"""How a shadow-map technique's light view is fitted (:class:`LightViewParams`)."""


@dataclasses.dataclass(frozen=True)
class LightViewParams:
    """The light view of a technique that reads a light depth map fitted to the receivers (``hard``,
    ``pcf``, ``pcss``, the prefiltered and SAT-based maps, ``salzman``, ``ssm``): a technique's own
    ``Params`` subclasses it. ``fitted``: per frame, tight around the receivers the camera sees
    (:func:`~wsoft.lightspace.fit.fit_light_view`); ``stable``: a view whose texel size and texel grid
    stay put while the camera turns or moves a little (:func:`~wsoft.lightspace.stable.fit_stable_view`),
    against shimmering shadow edges in motion; ``sequence``: the stable view fitted once to the
    receivers of every frame of a sequence (:mod:`wsoft.pipeline.sequence`; a single frame: ``stable``)."""

    view: str = param("fitted", "light view: fitted (per frame, tight around the receivers in view), stable (size on a 2^(1/4) ladder, "
                                "window on whole texels of a fixed grid, depth range snapped: edges that do not shimmer in motion, "
                                "texels up to 19 % coarser) or sequence (the stable view fitted once to the receivers of every frame "
                                "of a sequence)", choices=VIEWS)
    cube: str = param("auto", "cube map of a sphere, point or cylinder light (wsoft.lightspace.cube): auto (where its receivers lie more "
                              "than 75 degrees off one axis), always, or never (one frustum; receivers beyond it left lit, with a warning)",
                      choices=CUBE_MODES)


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
