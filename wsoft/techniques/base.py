"""What every technique is: parameters (a frozen dataclass), the passes it adds to a frame graph
for one light (each with the resources it reads and writes), what it supports, how it trades
quality for time, and the parameters of a quick, CI-sized run.

Copy ``techniques/hard.py`` to add a technique: one module (or package) named after it, holding
one :class:`Technique` subclass whose ``name`` is the module's name. Declare ``Params`` (fields
made with :func:`~wsoft.params.param`, a range for every number), ``passes`` (one
:class:`PassSpec` per pass: the frame graph checks each pass added against it), ``quality`` (the
knobs a sweep should turn), ``quick_params`` (what a quick run changes: smaller maps, fewer
samples), ``tolerance`` (how close it comes to the exact parallel-rectangle answer), and implement
:meth:`Technique.add_passes`, which registers the passes through the
:class:`~wsoft.pipeline.TechniqueContext` it is given (scene arrays, G-buffer, light depth maps) and
returns the key of the visibility it writes. Nothing else lists techniques: the registry
(:mod:`wsoft.techniques`) finds the module, and every test, sweep and report that runs "every
technique" takes it from there. A technique in another package joins through the entry-point
group ``wsoft.techniques`` (see the README).

Override :meth:`Technique.supports` when some lights or scenes are out of the technique's reach:
``wsoft plan`` lists the reason, ``render`` skips the light (or stops with the reason when nothing
is left); a technique that cannot render a point light only sets ``point_refusal``. Override
:meth:`Technique.bake_support` when the technique needs a camera image (``wsoft bake`` refuses it
with the reason).

UsdLux shadow controls: every technique honours a light's ``collection:shadowLink`` (maps from
``ctx.light_depth`` hold only the light's casters, :meth:`Scene.casting_triangles` lists them for
maps drawn otherwise, and ray queries get ``light.shadow_excluded``); one that cannot honour a
finite ``inputs:shadow:distance`` (``light.shadow_distance``) sets ``distance_refusal`` to the
one-line reason, and :meth:`Technique.supports` declines such lights with it.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from typing import Any, ClassVar

from wsoft.errors import DeclarationError, ParameterError
from wsoft.params import check, param, range_text

__all__ = ["PassSpec", "Quality", "Technique", "Tolerance", "check", "param"]


@dataclass(frozen=True)
class Quality:
    """A parameter that trades accuracy for time and the values a sweep should try (cheapest first)."""

    param: str
    values: tuple
    note: str = ""


@dataclass(frozen=True)
class PassSpec:
    """One pass a technique adds per light: its ``stage`` (unique within the technique), the kinds
    of the resources it reads and writes (:attr:`wsoft.graph.Key.kind`: the shared ``scene``,
    ``gbuffer``, ``light_view``, ``light_depth``, a technique's own ``vsm_moments``, and
    ``visibility`` for its result), ``optional``: kinds it reads only in some graphs (a pass that
    runs only with cutouts feeds it), ``when``: in words, when the pass runs at all (empty: always).
    ``wsoft techniques`` prints the declarations and the frame graph checks each pass against its own."""

    stage: str
    reads: tuple[str, ...]
    writes: tuple[str, ...]
    optional: tuple[str, ...] = ()
    when: str = ""

    def describe(self) -> dict:
        return {"stage": self.stage, "reads": list(self.reads), "optional": list(self.optional), "writes": list(self.writes),
                "when": self.when}

    def text(self) -> str:
        """``stage: reads [, optional?] -> writes (when ...)``."""
        ins = list(self.reads) + [f"{k}?" for k in self.optional]
        return f"{self.stage}: {', '.join(ins) or '-'} -> {', '.join(self.writes)}" + (f" (when {self.when})" if self.when else "")


@dataclass(frozen=True)
class Tolerance:
    """How close the technique must come to the exact answer of ``box_plane`` (a square occluder
    parallel to a square light and the ground) at its default parameters: MAE over the ground and
    MAE over the exact penumbra."""

    mae: float
    mae_penumbra: float


def _convert(name: str, typ, value, technique: str):
    if isinstance(typ, str):
        typ = {"int": int, "float": float, "bool": bool, "str": str}.get(typ, str)
    if isinstance(value, typ) and not (typ is int and isinstance(value, bool)):
        return value
    try:
        if typ is bool:
            if isinstance(value, str):
                low = value.strip().lower()
                if low in ("1", "true", "yes", "on"):
                    return True
                if low in ("0", "false", "no", "off"):
                    return False
                raise ValueError(value)
            if isinstance(value, (int, float)) and value in (0, 1):
                return bool(value)
            raise ValueError(value)
        if typ is int:
            f = float(value)
            if not f.is_integer():
                raise ValueError(value)
            return int(f)
        if typ is float:
            return float(value)
        return typ(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{technique}: parameter {name}={value!r} is not a valid {typ.__name__}") from None


LIGHT_MAP_KINDS = ("light_view", "light_depth")
"""The resource kinds a technique that draws a light's map reads (a single frustum or a cube map)."""


class Technique:
    """Base class. Subclasses set the class attributes below and implement ``add_passes``."""

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    Params: ClassVar[type]
    # the passes it adds per light, declared once: the frame graph checks every pass against them
    passes: ClassVar[tuple[PassSpec, ...]] = ()
    quality: ClassVar[tuple[Quality, ...]] = ()
    # parameters of a quick, CI-sized run (tests, --quick sweeps, the adversarial corpus): smaller
    # maps and grids, fewer samples; {} when the defaults are already cheap
    quick_params: ClassVar[dict[str, Any]] = {}
    # the parameter setting the resolution of the light-space map or grid it works on (texels or
    # cells per side): the one sweeps over map sizes turn; None when it has none
    size_param: ClassVar[str | None] = None
    tolerance: ClassVar[Tolerance | None] = None
    # the receiver's horizon (wsoft.raster.horizon): "fraction" caps V by the part of the light in
    # front of the tangent plane, "centre" zeroes V where the light's centre is behind it (a
    # technique that answers for the centre alone), "exact": the technique applies it itself
    horizon: ClassVar[str] = "fraction"
    # UsdLux inputs:shadow:distance: "" when the technique honours it, else why it cannot (one
    # line); supports() then refuses a light with a finite distance, naming the attribute. Every
    # technique honours collection:shadowLink (its maps and rays see only a light's casters).
    distance_refusal: ClassVar[str] = ""
    # a technique that honours inputs:shadow:distance only for some casters: which ones it tests
    # (e.g. "the caster nearest the light in each texel of the depth map"); every frame with a
    # finite distance then warns that a caster behind that one within the distance is missed
    distance_caveat: ClassVar[str] = ""
    # a technique that sizes its penumbrae by a filter kernel which cannot follow an ellipsoidal
    # sphere light's silhouette (a SphereLight under a non-uniform scale) names what it uses instead
    # (e.g. "its bounding sphere"); every frame with such a light then warns. "" when it samples the
    # silhouette ellipse (light_point, lightspace.coverage) or does not size its shadow by the light
    ellipsoid_caveat: ClassVar[str] = ""
    # instanced stages (load_scene(..., instancing=True)): "" when the technique's passes draw and
    # trace instances as they are (prototypes once, wsoft.scene.instancing), else why it needs the
    # triangle soup; the frame graph then flattens the stage for it (wsoft.pipeline.instancing_plan)
    instancing_refusal: ClassVar[str] = "its passes read the flattened triangle soup"
    # point lights: "" when the technique renders them, else why it cannot (one line, naming what
    # to use instead); supports() then refuses them with it
    point_refusal: ClassVar[str] = ""
    # dome lights (UsdLux DomeLight, wsoft.scene.dome): "" when the technique renders the sky's
    # visibility (V = E_occluded / E_unoccluded over the receiver's hemisphere), else why it cannot;
    # supports() refuses a dome with it
    dome_refusal: ClassVar[str] = "it shadows an emitter of finite extent, not the sky: render a DomeLight with the reference or a dome technique"
    # cylinder lights (UsdLux CylinderLight, a line light at radius 0): what the technique renders of
    # one, in a line (`wsoft techniques` and `wsoft plan` show it); "" where it does not say
    cylinder_model: ClassVar[str] = ""
    # cube maps (wsoft.lightspace.cube): a technique with light views (its Params has ``cube``) runs its
    # passes on each face of a light that surrounds its receivers; one that cannot says why here, and
    # such a light is refused (wsoft plan lists it) instead of left lit beyond one frustum
    cube_refusal: ClassVar[str] = ""
    # distant lights: the widest DistantLight ``angle`` (degrees) a technique that sizes the sun by
    # tan(angle / 2) (a disk across its axis, not the cone's solid angle: its penumbrae, blocker
    # search, denoiser or soft light view) gets right; a wider one gets a warning naming the light,
    # its angle and this limit. Measured: the sun overhead of ground +-6 and a 1 x 1 occluder at
    # z = 1, 128 x 96 seen obliquely, the largest |V - reference| (4096 samples) at seven ground
    # points under and beside the occluder stays within 0.1 up to it. The disk's own error for a
    # centred occluder is 0.054 at 60 degrees, 0.10 at 80, 0.16 at 100, 0.25 at 120. None: the
    # reference (the cone sampled uniformly in solid angle) and the techniques that draw the sun's
    # central direction alone (hard, pcf, vsm, esm, evsm, msm, izb: no penumbra sized by the angle)
    distant_angle_limit: ClassVar[float | None] = None

    def __init__(self, params):
        self.params = params

    # -- parameters ------------------------------------------------------------------------------
    @classmethod
    def make_params(cls, values: dict[str, Any] | None = None):
        """Build ``Params`` from a dict (strings from the CLI are converted); unknown keys are errors."""
        values = dict(values or {})
        fields = {f.name: f for f in dataclasses.fields(cls.Params)}
        unknown = sorted(set(values) - set(fields))
        if unknown:
            raise ParameterError(
                f"technique {cls.name!r} has no parameter {', '.join(unknown)}; its parameters: {', '.join(fields) or 'none'}"
            )
        hints = typing.get_type_hints(cls.Params)
        conv = {k: _convert(k, hints.get(k, fields[k].type), v, cls.name) for k, v in values.items()}
        try:
            p = cls.Params(**conv)
        except ValueError as exc:
            raise ParameterError(f"{cls.name}: {exc}") from None
        return p

    @classmethod
    def defaults(cls) -> dict[str, Any]:
        return {f.name: f.default for f in dataclasses.fields(cls.Params)}

    def changed_params(self) -> dict[str, Any]:
        """The parameters that differ from their defaults (in declaration order)."""
        d = self.defaults()
        return {k: v for k, v in dataclasses.asdict(self.params).items() if v != d[k] and not (isinstance(v, float) and math.isnan(v))}

    # -- what it supports ------------------------------------------------------------------------
    def supports(self, scene, light) -> str | None:
        """``None`` when the technique can render ``light`` of ``scene``, else the reason it cannot.
        Subclasses that override it start with ``super().supports(scene, light)``."""
        from wsoft.scene.types import LIGHT_DOME, LIGHT_POINT  # here: parsing the command line imports no Warp (wsoft.scene does)

        why = self.shadow_controls_refusal(light)
        if why is None and light.kind == LIGHT_POINT and self.point_refusal:
            return self.point_refusal
        if why is None and light.kind == LIGHT_DOME and self.dome_refusal:
            return self.dome_refusal
        return why

    def shadow_controls_refusal(self, light) -> str | None:
        """Why the technique cannot honour ``light``'s UsdLux shadow controls (a finite
        ``inputs:shadow:distance`` and a :attr:`distance_refusal`), else None."""
        if light.distance_limited and self.distance_refusal:
            return f"inputs:shadow:distance = {light.shadow_distance:g} cannot be honoured: {self.distance_refusal}"
        return None

    def instancing_why(self) -> str:
        """"" when this instance (its parameters) keeps a stage's instances, else why it needs the
        triangle soup (:attr:`instancing_refusal` unless a parameter changes it: ``omni=paraboloid``
        traces the soup)."""
        if getattr(self.params, "omni", "cube") == "paraboloid":
            return "a dual-paraboloid map traces the flattened triangle soup"
        return self.instancing_refusal

    def cube_guard_texels(self) -> float:
        """Texels past a cube map's face edge that this instance's kernels read (its widest filter,
        blur or search radius in texels): each face is drawn with a guard band at least that wide,
        so a kernel crossing an edge reads the neighbouring directions from the face's own map."""
        return 2.0

    def add_cube_passes(self, ctx, light, faces):
        """The passes for ``light``'s cube map (``faces``, :class:`~wsoft.lightspace.cube.CubeFace`):
        by default :meth:`add_passes` on each face (drawn with :meth:`cube_guard_texels`'s guard band)
        and each receiver's visibility from its own face
        (:meth:`~wsoft.pipeline.context.RenderContext.select_cube_faces`); the key of the visibility."""
        return ctx.ctx.select_cube_faces(ctx, light, faces, [self.add_passes(ctx, f) for f in faces])

    def add_paraboloid_passes(self, ctx, light):
        """The passes for ``light`` on a dual-paraboloid map instead of a cube map
        (:mod:`wsoft.lightspace.paraboloid`): a technique whose ``Params`` has ``omni`` implements it
        (most through :meth:`paraboloid_shadow`)."""
        raise DeclarationError(f"technique {self.name!r} has no dual-paraboloid map passes")

    def paraboloid_shadow(self, ctx, light, *, size: int, pattern: str, taps: int, radius: float, bias: float, plane_slope: float):
        """The shadow pass of a depth-comparing technique on ``light``'s dual-paraboloid map
        (:meth:`~wsoft.pipeline.context.RenderContext.paraboloid_depth`, ``size`` texels a side, a
        guard band of the kernel): per receiver, the fraction of ``taps`` (``pattern``: grid or
        poisson) within ``radius`` texels lit, each against the receiver's tangent plane along the tap
        texel's direction less ``plane_slope`` of its step per texel and ``bias`` (a fraction of the
        frame's extent); ``taps`` 1 with ``radius`` 0 is the classic shadow map's one texel.
        Counters: ``paraboloid_hemispheres``, ``paraboloid_texels``; a receiver at the light's centre
        gets V = 1 and a warning."""
        import warp as wp

        from wsoft.accel.filters import taps_on
        from wsoft.lightspace.paraboloid import HEMISPHERES, guard_texels_for, paraboloid_visibility

        gbuf = ctx.gbuffer()
        depth = ctx.ctx.paraboloid_depth(light, size, guard_texels_for(radius))
        out = ctx.visibility_key(light)
        name = ctx.pass_name(f"{self.name}_paraboloid", light)

        def run(res):
            gb, dm = res[gbuf], res[depth]
            tp = taps_on(ctx.device, pattern, taps) if taps > 1 else None
            arr = tp.array if tp is not None else wp.array([[0.5, 0.5]], dtype=wp.vec2, device=ctx.device)
            vis, at_light = paraboloid_visibility(dm, gb, arr, tp.count if tp is not None else 1, pattern == "poisson", radius, bias,
                                                  plane_slope, light.shadow_distance, ctx.device)
            c = ctx.counters(light)
            c["paraboloid_hemispheres"] = [HEMISPHERES[h] for h in dm.view.drawn]
            c["paraboloid_texels"] = dm.view.texels
            if at_light:
                ctx.ctx.warn(name, f"light {light.path}: {at_light} visible samples lie at its centre (no direction to it): V = 1 there")
            return {out: ctx.visibility(vis)}

        return ctx.add_pass(name, inputs=(gbuf, depth), outputs=(out,), run=run, stage="shadow", light=light)

    def bake_support(self) -> str | None:
        """``None`` when the technique answers for any points given their positions and normals,
        so that it can bake visibility into a stage (:mod:`wsoft.baking`: its G-buffer holds mesh
        vertices and texel centres, with no camera and no pixel grid), else the reason it cannot
        (it casts eye rays, or reads a per-pixel input)."""
        return None

    # -- quality ---------------------------------------------------------------------------------
    @classmethod
    def quality_settings(cls) -> list[dict[str, Any]]:
        """Parameter sets a sweep should try: the defaults, then each quality knob's values one at a
        time from the defaults (deduplicated, in declaration order)."""
        out: list[dict[str, Any]] = [{}]
        d = cls.defaults()
        for q in cls.quality:
            for v in q.values:
                s = {} if v == d[q.param] else {q.param: v}
                if s not in out:
                    out.append(s)
        return out

    # -- passes ----------------------------------------------------------------------------------
    @classmethod
    def pass_spec(cls, stage: str) -> PassSpec:
        """The declaration of the pass ``stage`` (a :class:`~wsoft.errors.DeclarationError` when none)."""
        for spec in cls.passes:
            if spec.stage == stage:
                return spec
        raise DeclarationError(f"technique {cls.name!r} adds a pass of stage {stage!r}, which it does not declare "
                               f"(its passes: {', '.join(s.stage for s in cls.passes) or 'none'})")

    @classmethod
    def reads(cls) -> tuple[str, ...]:
        """The kinds of resource its passes read and do not write themselves (what it takes from the graph)."""
        written = cls.writes()
        return tuple(dict.fromkeys(k for s in cls.passes for k in s.reads + s.optional if k not in written))

    @classmethod
    def writes(cls) -> tuple[str, ...]:
        """The kinds of resource its passes write (``visibility`` among them)."""
        return tuple(dict.fromkeys(k for s in cls.passes for k in s.writes))

    @classmethod
    def declaration_problem(cls) -> str | None:
        """What is wrong with the class as a technique (for a plugin: why it is left out), else None:
        a name, a frozen ``Params`` dataclass, quick parameters and quality knobs it has, passes with
        distinct stages, one of which writes ``visibility``."""
        name = cls.__dict__.get("name")
        if not isinstance(name, str) or not name.isidentifier():
            return f"its name {name!r} is not an identifier"
        params = getattr(cls, "Params", None)
        if not (dataclasses.is_dataclass(params) and params.__dataclass_params__.frozen):
            return "its Params is not a frozen dataclass"
        fields = {f.name for f in dataclasses.fields(params)}
        named = set(cls.quick_params) | {q.param for q in cls.quality} | ({cls.size_param} if cls.size_param else set())
        if named - fields:
            return f"quick_params, quality or size_param name parameters it does not have: {', '.join(sorted(named - fields))}"
        stages = [s.stage for s in cls.passes]
        if not stages:
            return "it declares no passes"
        if len(set(stages)) != len(stages):
            return f"two of its passes share a stage: {', '.join(sorted({s for s in stages if stages.count(s) > 1}))}"
        if "visibility" not in cls.writes():
            return "none of its passes writes visibility"
        return None

    @classmethod
    def cube_map_problem(cls) -> str | None:
        """What a technique that draws light maps (its passes read ``light_view`` or ``light_depth``)
        lacks for a light that surrounds its receivers, else None: a ``Params`` without the parameter
        ``cube`` (:class:`~wsoft.params.LightViewParams`) and no :attr:`cube_refusal` gets no cube
        map, and its receivers beyond one frustum are left unshadowed."""
        if not set(LIGHT_MAP_KINDS) & set(cls.reads()) or cls.cube_refusal:
            return None
        if "cube" in {f.name for f in dataclasses.fields(cls.Params)}:
            return None
        return (f"its Params ({cls.Params.__name__}) lacks the parameter cube: subclass wsoft.params.LightViewParams so that a "
                "sphere, point or cylinder light around its receivers gets a cube map (else receivers beyond one frustum are left "
                "unshadowed), or set cube_refusal to refuse such a light")

    # -- the manual ------------------------------------------------------------------------------
    @classmethod
    def describe(cls) -> dict:
        hints = typing.get_type_hints(cls.Params)
        return {
            "name": cls.name,
            "summary": cls.summary,
            "reads": list(cls.reads()),
            "keeps_instances": not cls.instancing_refusal,
            "writes": list(cls.writes()),
            "passes": [s.describe() for s in cls.passes],
            "quick_params": dict(cls.quick_params),
            "size_param": cls.size_param,
            "parameters": [
                {"name": f.name, "type": getattr(hints.get(f.name), "__name__", str(f.type)), "default": f.default,
                 "range": range_text(f), "meaning": f.metadata.get("help", "")}
                for f in dataclasses.fields(cls.Params)
            ],
            "quality": [{"param": q.param, "values": list(q.values), "note": q.note} for q in cls.quality],
            "tolerance": dataclasses.asdict(cls.tolerance) if cls.tolerance else None,
            "cylinder_light": cls.cylinder_model,
            "distant_angle_limit": cls.distant_angle_limit,
        }

    def add_passes(self, ctx, light):  # pragma: no cover - interface
        raise NotImplementedError
