"""One USD stage being read at one time code: what every part of the loader shares.

:class:`StageContext` holds the stage, its file (how errors and warnings name it), the time code,
one ``UsdGeom.XformCache`` for the load, the render settings (:mod:`wsoft.scene.render_settings`:
their ``includedPurposes`` decide which prims load) and the warnings collected so far; it turns
problems into a :class:`~wsoft.errors.SceneError` naming the file and the prim, reads authored
values at the time code and places prims in the world.
"""

from __future__ import annotations

import math

import numpy as np

from wsoft.errors import SceneError
from wsoft.scene.render_settings import DEFAULT_PURPOSES, read_render_settings
from wsoft.scene.usd_time import earliest_time, moves_by_velocity

MATERIAL_PURPOSES = ("full", "preview")  # the UsdShade material purposes a load resolves bindings for (load_scene's material_purpose)


def pxr():
    """usd-core's modules (``Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade``); a missing install is a
    :class:`SceneError` that says how to install it."""
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade  # noqa: F401
    except ImportError as exc:  # pragma: no cover - install problem
        raise SceneError(f"usd-core is not installed ({exc}); run `pip install usd-core`") from None
    return Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade


def earliest_time_sample(stage) -> float | None:
    """The earliest time sample or spline knot of any authored attribute of ``stage`` (in stage
    time: layer offsets and value clips applied), None when it has none
    (:func:`wsoft.scene.usd_time.earliest_time`)."""
    return earliest_time(stage)


class StageContext:
    """``stage`` read at ``time`` (None: the start time code when the stage authors a time range,
    else its earliest time sample (:func:`earliest_time_sample`, with a warning naming it), else
    the default time) with the render settings ``render_settings`` (a prim path; None: the
    stage's own). Material bindings resolve for ``material_purpose`` (one of
    :data:`MATERIAL_PURPOSES`; a prim without a binding of that purpose takes its all-purpose one,
    as ``UsdShade.MaterialBindingAPI.ComputeBoundMaterial`` resolves it)."""

    def __init__(self, stage, file: str, time: float | None, render_settings: str | None = None, material_purpose: str = "full"):
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        if material_purpose not in MATERIAL_PURPOSES:
            raise SceneError(f"material purpose {material_purpose!r} is not one of {', '.join(MATERIAL_PURPOSES)}", file=file)
        self.stage = stage
        self.file = file
        self.material_purpose = material_purpose
        self.warnings: list[str] = []
        if time is not None:
            self.timecode = Usd.TimeCode(float(time))
        elif stage.HasAuthoredTimeCodeRange():
            self.timecode = Usd.TimeCode(stage.GetStartTimeCode())
        elif (first := earliest_time_sample(stage)) is not None:
            self.timecode = Usd.TimeCode(first)
            self.warn(None, f"time samples or splines but no time range (startTimeCode, endTimeCode): loaded at time code {first:g}, "
                      "the earliest time sample or spline knot (--time, or time=, picks another)")
        else:
            self.timecode = Usd.TimeCode.Default()
        self.time = None if self.timecode.IsDefault() else float(self.timecode.GetValue())
        self.xf = UsdGeom.XformCache(self.timecode)
        self.world_override = None  # (prototype root prim, its world matrix) while reading a prototype in its own frame
        self.dynamic_cache: dict[str, bool] = {}
        self.dynamic_stop = None  # a prim is_dynamic does not walk up past (an instance prim, while reading its prototype)
        self.render_settings, self.render_settings_source = read_render_settings(self, render_settings)
        self.purposes = self.render_settings.included_purposes if self.render_settings else DEFAULT_PURPOSES

    def warn(self, prim, msg: str):
        where = f"{self.file}: {prim.GetPath()}: " if prim is not None else f"{self.file}: "
        self.warnings.append(where + msg)

    def bound_material(self, prim):
        """The ``UsdShade.Material`` bound to ``prim`` for :attr:`material_purpose` (its all-purpose
        binding where it has none of that purpose), or an invalid one when nothing is bound."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(self.material_purpose)
        return material

    def err(self, prim, msg: str) -> SceneError:
        return SceneError(msg, file=self.file, prim=str(prim.GetPath()) if prim is not None else None)

    def world(self, prim) -> np.ndarray:
        """``prim``'s local-to-world matrix (4 x 4, column-vector convention); relative to the
        prototype root of :attr:`world_override` and placed by its matrix while one is set."""
        if self.world_override is not None:  # a prototype's mesh, placed by its PointInstancer
            rel, _ = self.xf.ComputeRelativeTransform(prim, self.world_override[0])
            return self.world_override[1] @ np.array(rel, dtype=np.float64).T
        m = self.xf.GetLocalToWorldTransform(prim)
        return np.array(m, dtype=np.float64).T  # column-vector convention

    def finite(self, prim, name: str, value) -> float:
        """``value`` as a float; a NaN or infinite one is an error naming the attribute."""
        v = float(value)
        if not math.isfinite(v):
            raise self.err(prim, f"{name} = {v} is not a finite number")
        return v

    def size(self, prim, name: str, value) -> float:
        """A size attribute (a light's, a shape's): finite and >= 0."""
        v = self.finite(prim, name, value)
        if v < 0:
            raise self.err(prim, f"{name} = {v:g} is negative")
        return v

    def get(self, attr, default=None):
        """``attr``'s value at the time code; ``default`` when it has none."""
        if not attr or not attr.HasAuthoredValue() and attr.Get(self.timecode) is None:
            return default
        v = attr.Get(self.timecode)
        return default if v is None else v

    def points(self, prim):
        """The points of the ``UsdGeom.PointBased`` ``prim`` at the time code as USD computes them:
        extrapolated by ``velocities`` and ``accelerations`` from the time sample at or before it
        (``UsdGeomPointBased.ComputePointsAtTime``) where USD moves them by velocity
        (:func:`~wsoft.scene.usd_time.moves_by_velocity`), else the value at the time code; None
        without points."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        pb = UsdGeom.PointBased(prim)
        if not self.timecode.IsDefault() and moves_by_velocity(prim):
            points = pb.ComputePointsAtTime(self.timecode, self.timecode)
            if points is not None and len(points):
                return points
        return self.get(pb.GetPointsAttr())

    def is_dynamic(self, prim, shaping=()) -> bool:
        """A *dynamic caster* (Salzman's sense): ``shaping`` attributes (a mesh's points, a shape's
        size, radius, height...) whose value may vary (``ValueMightBeTimeVarying``: time samples, a
        spline, value clips), points USD moves by velocity
        (:func:`~wsoft.scene.usd_time.moves_by_velocity`), a time-varying transform on the prim or an
        ancestor, or ``wsoft:dynamic = true`` on the prim or an ancestor."""
        Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade = pxr()
        if any(a and a.ValueMightBeTimeVarying() for a in shaping) or moves_by_velocity(prim):
            return True
        p = prim
        while p and not p.IsPseudoRoot() and p != self.dynamic_stop:
            key = str(p.GetPath())
            if key not in self.dynamic_cache:
                attr = p.GetAttribute("wsoft:dynamic")
                flag = bool(attr and attr.HasAuthoredValue() and attr.Get(self.timecode))
                if not flag and p.IsA(UsdGeom.Xformable):
                    flag = UsdGeom.Xformable(p).TransformMightBeTimeVarying()
                self.dynamic_cache[key] = flag
            if self.dynamic_cache[key]:
                return True
            p = p.GetParent()
        return False
