"""When a stage's values change: what USD says may vary over time, and the stage's time range.

Every answer comes from USD's own value resolution (layer offsets, value clips and splines
applied): an attribute varies when ``UsdAttribute.ValueMightBeTimeVarying`` says it may (time
samples, a spline, value clips), and a point-based prim or PointInstancer also moves when its
time-sampled points or positions carry ``velocities``, ``accelerations`` or ``angularVelocities``
(USD extrapolates them between and beyond samples: ``UsdGeomPointBased.ComputePointsAtTime``,
``UsdGeomPointInstancer.ComputeInstanceTransformsAtTime``). The stage's time range is its authored
``startTimeCode``–``endTimeCode``, else the span of every time sample and spline knot in stage time
(:func:`time_range`).

The stage is visited once per question: every prim outside instances, and each instance
prototype once (:func:`stage_prims`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


def stage_prims(stage):
    """Every prim of ``stage`` once: the stage's own (``Usd.PrimRange`` from the root, which does
    not enter instances) and each instance prototype's (:meth:`Usd.Stage.GetPrototypes`)."""
    from pxr import Usd

    for root in [stage.GetPseudoRoot(), *stage.GetPrototypes()]:
        yield from Usd.PrimRange(root)


def moves_by_velocity(prim) -> bool:
    """Does USD move ``prim``'s points (a ``UsdGeom.PointBased``) or instances (a
    ``UsdGeom.PointInstancer``) by velocity: time-sampled (or clipped) points / positions with
    authored ``velocities``, ``accelerations`` or ``angularVelocities``?"""
    from pxr import Usd, UsdGeom

    if prim.IsA(UsdGeom.PointBased):
        pb = UsdGeom.PointBased(prim)
        where, motion = pb.GetPointsAttr(), (pb.GetVelocitiesAttr(), pb.GetAccelerationsAttr())
    elif prim.IsA(UsdGeom.PointInstancer):
        pi = UsdGeom.PointInstancer(prim)
        where, motion = pi.GetPositionsAttr(), (pi.GetVelocitiesAttr(), pi.GetAccelerationsAttr(), pi.GetAngularVelocitiesAttr())
    else:
        return False
    if not any(a and a.HasValue() for a in motion):
        return False
    source = where.GetResolveInfo().GetSource() if where else None
    return source in (Usd.ResolveInfoSourceTimeSamples, Usd.ResolveInfoSourceValueClips)


def prim_varies(prim) -> bool:
    """Does any value of ``prim`` vary over time: an authored attribute USD says may vary
    (``ValueMightBeTimeVarying``: time samples, a spline, value clips), or points or instances
    moved by velocity (:func:`moves_by_velocity`)?"""
    return any(a.ValueMightBeTimeVarying() for a in prim.GetAuthoredAttributes()) or moves_by_velocity(prim)


def attribute_span(attr) -> tuple[float, float] | None:
    """The first and last time (stage time: layer offsets and value clips applied) at which ``attr``
    authors a time sample or a spline knot; None when it authors neither."""
    if attr.HasSpline():
        knots = list(attr.GetSpline().GetKnots().keys())  # GetSpline applies the layer offsets
        return (float(min(knots)), float(max(knots))) if knots else None
    first = attr.GetBracketingTimeSamples(-math.inf)  # (first, first); () without samples
    if not first:
        return None
    last = attr.GetBracketingTimeSamples(math.inf)
    return float(first[0]), float(last[1])


@dataclass
class Animation:
    """What varies on a stage: ``prims`` (the paths of the prims with a value that may vary,
    :func:`prim_varies`) and ``span`` (the first and last time sample or spline knot in stage time,
    None without any)."""

    prims: list[str]
    span: tuple[float, float] | None

    @property
    def animated(self) -> bool:
        return bool(self.prims)


def stage_animation(stage) -> Animation:
    """The :class:`Animation` of ``stage``: every prim visited once (:func:`stage_prims`)."""
    prims, lo, hi = [], math.inf, -math.inf
    for prim in stage_prims(stage):
        varies = moves_by_velocity(prim)
        for attr in prim.GetAuthoredAttributes():
            span = attribute_span(attr)
            if span is not None:
                lo, hi = min(lo, span[0]), max(hi, span[1])
            varies = varies or attr.ValueMightBeTimeVarying()
        if varies:
            prims.append(str(prim.GetPath()))
    return Animation(prims, (lo, hi) if lo <= hi else None)


def earliest_time(stage) -> float | None:
    """The earliest time sample or spline knot of any authored attribute of ``stage`` (stage time),
    None when it has none."""
    span = stage_animation(stage).span
    return None if span is None else span[0]


@dataclass
class TimeRange:
    """A stage's time range: ``start``, ``end`` and ``source`` (``authored``: its ``startTimeCode``
    and ``endTimeCode``; ``derived``: the span of its time samples and spline knots)."""

    start: float
    end: float
    source: str

    def describe(self) -> str:
        how = ("startTimeCode, endTimeCode" if self.source == "authored"
               else "its first and last time sample or spline knot; it authors no startTimeCode / endTimeCode")
        return f"[{self.start:g}, {self.end:g}] ({how})"


def time_range(stage, animation: Animation | None = None) -> TimeRange | None:
    """``stage``'s time range: its authored ``startTimeCode``–``endTimeCode``, else the span of its
    time samples and spline knots (``animation``, or :func:`stage_animation`), else None."""
    if stage.HasAuthoredTimeCodeRange():
        return TimeRange(float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode()), "authored")
    span = (animation or stage_animation(stage)).span
    return None if span is None else TimeRange(span[0], span[1], "derived")


def _view_only(prim) -> bool:
    """Is ``prim`` a camera, a light or a render settings prim with no geometry below it (instances
    entered)?"""
    from pxr import Usd, UsdGeom, UsdLux, UsdRender

    if not (prim.IsA(UsdGeom.Camera) or prim.HasAPI(UsdLux.LightAPI) or prim.IsA(UsdRender.SettingsBase) or prim.IsA(UsdRender.Var)):
        return False
    below = Usd.PrimRange(prim, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate))
    return not any(d.IsA(UsdGeom.Gprim) or d.IsA(UsdGeom.PointInstancer) or d.IsInstance() for d in below)


def static_geometry(stage) -> bool:
    """Is nothing a render draws animated on ``stage``: every prim whose values may vary
    (:func:`prim_varies`) a camera, a light or a render settings prim with no geometry below it
    (instances entered)? (Then the geometry read at one time code holds at every other.)"""
    return all(_view_only(stage.GetPrimAtPath(p)) for p in stage_animation(stage).prims)
