"""Building one frame graph for one or several techniques on a scene: each technique's passes per
shadow-casting light it supports (through a :class:`~wsoft.pipeline.technique_context.TechniqueContext`),
capped by the receiver's horizon, then ``shade`` (a Warp kernel, :mod:`wsoft.raster.shade`: every
G-buffer sample lit with a technique's visibilities) and ``resolve`` (per-sample results to
per-pixel channels); :func:`execute` runs what the requested channels need."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.errors import ParameterError, SceneError
from wsoft.graph import Key, Pass, Resources
from wsoft.lightspace.light import reach_mask
from wsoft.lightspace.view import MAX_HALF_ANGLE
from wsoft.pipeline.context import RenderContext, TechniqueContext
from wsoft.pipeline.framing import frame_setup, local_origin
from wsoft.pipeline.loading import flatten_for, instancing_plan
from wsoft.raster.shade import shade as shade_samples
from wsoft.scene.types import LIGHT_DISTANT, LIGHT_SPHERE, Light, Scene


CHOOSERS: dict = {}
"""Name -> factory (its parameters -> a Technique instance) of techniques chosen per light by a
package above the pipeline: ``wsoft.auto`` registers ``auto`` when imported. Such an instance has
``technique_for(ctx, light)`` -> (the chosen technique instance, a record with ``record()``): the
light's passes are the chosen one's, and the record goes into the frame's counters (``auto``)."""


def technique_labels(techs: list) -> list[str]:
    """A label per technique instance: its name when it is the only one of its kind, else the name
    with the parameters that differ from the defaults, ``pcss(filter_samples=100)``."""
    names = [t.name for t in techs]
    labels = []
    for t in techs:
        if names.count(t.name) == 1:
            labels.append(t.name)
            continue
        ch = t.changed_params()
        labels.append(t.name + "(" + ",".join(f"{k}={v}" for k, v in ch.items()) + ")" if ch else t.name)
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise ParameterError(f"the same technique with the same parameters is asked for twice: {', '.join(dup)}")
    return labels


def is_several(technique) -> bool:
    """Is ``technique`` a list of techniques (rather than one name, one (name, params) pair or one instance)?"""
    pair = isinstance(technique, tuple) and len(technique) == 2 and isinstance(technique[1], dict)
    return isinstance(technique, (list, tuple)) and not pair


def as_techniques(technique, params: dict) -> list:
    """``technique`` (a name, a (name, params) pair, a Technique, or a list of those) as Technique instances."""
    from wsoft.techniques import Technique, create

    def one(t, p):
        if isinstance(t, Technique):
            if p:
                raise ParameterError("parameters go to the technique's create(), not render()")
            return t
        if isinstance(t, tuple) and len(t) == 2:
            t, p = t
        if isinstance(t, str) and t in CHOOSERS:  # a technique chosen per light by a package above (wsoft.auto)
            return CHOOSERS[t](p)
        if t == "auto":
            raise ParameterError("technique 'auto' is wsoft.auto's: import wsoft.auto first (wsoft.render and the command line do)")
        if isinstance(t, str):
            return create(t, p)
        raise ParameterError(f"not a technique: {t!r}")

    if is_several(technique):
        if params:
            raise ParameterError("with several techniques give each its parameters as (name, {key: value}), not as keywords")
        if not technique:
            raise ParameterError("no technique to render")
        return [one(t, {}) for t in technique]
    return [one(technique, params)]


@dataclass
class Built:
    """A frame graph built for some techniques: the context, each technique's lights, outputs
    and the lights it was not applicable to (with the reason)."""

    ctx: RenderContext
    labels: list[str]
    techniques: list
    lights: dict[str, list[Light]]
    visibility: dict[str, list[Key]]
    channels: dict[str, Key]
    skipped: dict[str, list[tuple[Light, str]]]
    instancing: dict = dataclasses.field(default_factory=lambda: {"mode": "none"})  # instancing_plan: instances kept, flattened, or none

    @property
    def requested(self) -> list[Key]:
        return [self.channels[l] for l in self.labels]


def build_graph(scene: Scene, technique, *, width: int | None = None, height: int | None = None, camera=None, light=None,
                device: str = "cpu", pixel_samples: int = 1, params: dict | None = None, strict: bool = True, history=None) -> Built:
    """Register every pass for ``technique`` (one or several, see :func:`render`) on ``scene``.

    ``width``, ``height``, ``camera``: as :func:`frame_setup` resolves them (None: the scene's
    render settings, else the defaults).

    A technique that does not support a light skips it; with ``strict`` a technique left with no
    light is an error naming the reason (``wsoft plan`` builds with ``strict=False`` to list it).
    ``history``: a sequence's :class:`~wsoft.pipeline.history.History` (None: a single frame)."""
    if not scene.lights:
        why = ""
        if scene.unshadowed_lights:
            why = f" ({len(scene.unshadowed_lights)} light(s) have shadow:enable = false)"
        elif scene.skipped_lights:
            why = f" (skipped: {'; '.join(f'{s.path} {s.kind}: {s.reason}' for s in scene.skipped_lights)})"
        raise SceneError(f"no shadow-casting light{why}", file=scene.path)
    techs = as_techniques(technique, params or {})
    labels = technique_labels(techs)
    instancing = instancing_plan(scene, techs, labels)
    if instancing["mode"] == "flattened" and strict:
        scene = flatten_for(scene, instancing)
    fr = frame_setup(scene, width, height, camera)
    origin, origin_warning = local_origin(scene, fr.camera)
    if origin is not None:  # far from the world origin: every pass works in a frame centred on what the camera sees
        scene = scene.translated(-origin)
        cam = fr.camera
        m = np.array(cam.to_world, np.float64)
        m[:3, 3] -= origin
        fr = dataclasses.replace(fr, camera=dataclasses.replace(cam, to_world=m))
    lights = [scene.find_light(str(light))] if light else list(scene.lights)
    ctx = RenderContext(scene, fr.camera, fr.width, fr.height, device, pixel_samples, framing=fr, origin=origin, origin_warning=origin_warning,
                        history=history)
    built = Built(ctx, labels, techs, {}, {}, {}, {})
    built.instancing = instancing
    for tech, label in zip(techs, labels):
        tctx = ctx.technique(tech, label)
        mine, skipped = supported_lights(tech, scene, lights, ctx)
        built.skipped[label] = skipped
        if not mine:
            if strict:
                raise ParameterError(f"{label}: " + "; ".join(f"{l.path}: {why}" for l, why in skipped), file=scene.path)
            built.lights[label] = []
            continue
        built.lights[label] = mine
        if hasattr(tech, "technique_for"):  # auto: its budget is split between the lights it renders
            tech.light_count = len(mine)
        built.visibility[label] = [visibility_of(ctx, tctx, l) for l in mine]
        built.channels[label] = _add_resolve(ctx, tech, label, mine, built.visibility[label], single=len(techs) == 1)
    return built


def supported_lights(tech, scene: Scene, lights: list[Light], ctx: RenderContext | None = None) -> tuple[list[Light], list[tuple[Light, str]]]:
    """``lights`` split into those ``tech`` supports and (light, reason) for the others; with ``ctx``,
    a technique with a :attr:`~wsoft.techniques.Technique.cube_refusal` also refuses a light whose
    receivers no single frustum of at most ±80° holds (:meth:`~wsoft.pipeline.context.RenderContext.cube_decision`)."""
    mine, skipped = [], []
    for l in lights:
        why = tech.supports(scene, l)
        if why is None and ctx is not None and tech.cube_refusal:
            d = ctx.cube_decision(l)
            if d.cube("auto") and d.half_angle > MAX_HALF_ANGLE:  # beyond the widest single frustum
                why = f"it needs a cube map ({d.why('auto')}), which {tech.name} cannot use: {tech.cube_refusal}"
        if why is None:
            mine.append(l)
        else:
            skipped.append((l, why))
    return mine, skipped


def refusal(technique, scene: Scene, light: Light, *, width: int | None = None, height: int | None = None, camera=None) -> str | None:
    """Why ``technique`` (a name, or (name, params)) renders nothing of ``light`` in a frame of
    ``scene`` (``width``, ``height``, ``camera`` as :func:`build_graph` takes them): its
    :meth:`~wsoft.techniques.Technique.supports`, or, for a technique with a
    :attr:`~wsoft.techniques.Technique.cube_refusal`, a light whose receivers in that frame need a
    cube map (decided as :func:`build_graph` decides it); None when it renders the light. What the
    sweeps ask before they put a technique in a frame's graph."""
    from wsoft.techniques import create

    name, params = technique if isinstance(technique, tuple) else (technique, {})
    tech = create(name, params)
    why = tech.supports(scene, light)
    if why is not None or not tech.cube_refusal:
        return why
    built = build_graph(scene, (name, params), width=width, height=height, camera=camera, light=light.path, strict=False)
    return {l.path: w for l, w in built.skipped[built.labels[0]]}.get(light.path)


def visibility_of(ctx: RenderContext, tctx: TechniqueContext, light: Light) -> Key:
    """Register a technique's passes for ``light``; the key of its per-sample visibility, capped by
    the receiver's horizon (a point sees only the light in front of its tangent plane, and nothing
    of a rect or disk light behind its emitting plane): the reference applies it per light sample,
    every other technique is capped by its front fraction; receivers behind a one-sided light are
    counted and warned about (:meth:`~wsoft.pipeline.context.RenderContext.light_behind`)."""
    tech = tctx.tech
    if hasattr(tech, "technique_for"):  # auto: the light's passes are those of the setting chosen for it
        tech, choice = tech.technique_for(ctx, light)
        tctx = ctx.technique(tech, tctx.label_)
        tctx.counters(light)["auto"] = choice.record()
    faces = ctx.cube_faces(light, getattr(tech.params, "cube", None))
    if faces and getattr(tech.params, "omni", "cube") == "paraboloid":  # a dual-paraboloid map in the cube map's place
        vk = tech.add_paraboloid_passes(tctx, light)
    elif faces:  # a cube map: the technique's passes on each face, each receiver's visibility from its own face
        vk = tech.add_cube_passes(tctx, light, faces)
    else:
        vk = tech.add_passes(tctx, light)
    if tctx.ctx.graph.producers.get(vk) and tctx.counters(light).get("auto", {}).get("warning"):
        ctx.warn(ctx.graph.producers[vk], tctx.counters(light)["auto"]["warning"])
    if tech.distance_caveat and light.distance_limited:
        ctx.warn(ctx.graph.producers[vk], distance_caveat_warning(tech, light))
    if tech.ellipsoid_caveat and light.kind == LIGHT_SPHERE and light.elliptical:
        ctx.warn(ctx.graph.producers[vk], ellipsoid_caveat_warning(tech, light))
    if light.kind == LIGHT_DISTANT and tech.distant_angle_limit is not None and light.angle_deg > tech.distant_angle_limit:
        ctx.warn(ctx.graph.producers[vk], distant_angle_warning(tech, light))
    return ctx.clip_to_front(tctx, light, vk)


def ellipsoid_caveat_warning(tech, light: Light) -> str:
    """The warning of a technique that models an ellipsoidal sphere light approximately
    (:attr:`~wsoft.techniques.Technique.ellipsoid_caveat`)."""
    semi = " x ".join(f"{a:g}" for a in light.semi_axes)
    return (f"light {light.path}: a SphereLight scaled into an ellipsoid (semi-axes {semi}): {tech.name} models it as "
            f"{tech.ellipsoid_caveat} of radius {light.radius:g} (the reference samples the silhouette ellipse each point sees)")


def distant_angle_warning(tech, light: Light) -> str:
    """The warning of a technique measured to get a DistantLight right only up to its
    :attr:`~wsoft.techniques.Technique.distant_angle_limit`, for a wider one."""
    return (f"light {light.path}: DistantLight angle {light.angle_deg:g} degrees is wider than {tech.name} is measured to get right "
            f"(up to {tech.distant_angle_limit:g}: it sizes the sun by tan(angle / 2), a disk across its axis, not by the cone's solid "
            "angle); the reference samples the whole cone (`wsoft techniques --json` gives each technique's distant_angle_limit)")


def distance_caveat_warning(tech, light: Light) -> str:
    """The warning of a technique that tests ``inputs:shadow:distance`` against some casters only
    (:attr:`~wsoft.techniques.Technique.distance_caveat`), naming those that test every caster."""
    from wsoft.techniques import TECHNIQUES

    exact = [n for n, c in TECHNIQUES.items() if not c.distance_refusal and not c.distance_caveat]
    return (f"light {light.path}: inputs:shadow:distance = {light.shadow_distance:g} is tested against {tech.distance_caveat}: a caster "
            f"behind it within the distance is missed ({' and '.join(exact) or 'no technique'} test every caster)")


def _add_resolve(ctx: RenderContext, tech, label: str, lights: list[Light], vis_keys: list[Key], single: bool) -> Key:
    """Shade and resolve one technique's visibilities into per-pixel channels."""
    gk = ctx.gbuffer()
    sk = ctx.scene_arrays()
    ck = ctx.gbuffer_channels()
    light_structs = [ctx.light_gpu(l) for l in lights]
    light_labels = [ctx.label(l) for l in lights]
    rgb_key = Key("rgb_samples", technique=label)
    out = Key("channels", technique=label)
    crop = ctx.framing.crop if ctx.framing is not None else None

    def shade_pass(res):
        return {rgb_key: shade_samples(res[sk], res[gk], [(L, res[vk].vis, l) for L, l, vk in zip(light_structs, lights, vis_keys)])}

    def resolve(res):
        """Per-sample results -> per-pixel channels (means over the pixel's covered samples)."""
        g = res[ck]
        hit, nhit, spp = g["hit"], g["nhit"], g["spp"]
        h, w = g["shape"]
        rgb = res[rgb_key].numpy().reshape(spp, h, w, 3)
        rgb = rgb[0] if spp == 1 else rgb.mean(axis=0)  # background samples are black: the mean is already coverage-weighted
        ch: dict[str, np.ndarray] = {}
        for ll, vk in zip(light_labels, vis_keys):
            v = res[vk].vis.numpy().reshape(spp, h, w)
            vv = v[0] if spp == 1 else np.where(nhit > 0, (v * hit).sum(axis=0) / np.maximum(nhit, 1), 1.0)
            ch[f"V.{ll}"] = vv.astype(np.float32)
            if res[vk].stderr is not None:
                e = res[vk].stderr.numpy().reshape(spp, h, w)
                ee = np.sqrt((e * e * hit).sum(axis=0)) / np.maximum(nhit, 1)
                ch[f"V_stderr.{ll}"] = ee.astype(np.float32)
        if any(l.shaping.coned for l in lights):
            pos = res[gk].host("pos")
            for ll, l in zip(light_labels, lights):
                if l.shaping.coned:  # reach.<light>: 1 where the cone reaches a covered sample of the pixel (docs/outputs.md)
                    reached = np.zeros(hit.shape, bool)
                    reached[hit] = reach_mask(l, pos[hit])
                    ch[f"reach.{ll}"] = reached.any(axis=0).astype(np.float32)
        ch["V"] = ch[f"V.{light_labels[0]}"]
        if f"V_stderr.{light_labels[0]}" in ch:
            ch["V_stderr"] = ch[f"V_stderr.{light_labels[0]}"]
        ch.update(g["channels"])
        for i, c in enumerate("RGB"):
            ch[c] = np.ascontiguousarray(rgb[..., i], dtype=np.float32)
        if crop is not None:  # the data window: the whole image was rendered, these pixels are kept
            x0, y0, x1, y1 = crop
            ch = {k: np.ascontiguousarray(v[y0:y1, x0:x1]) for k, v in ch.items()}
        return {out: ch}

    sname, rname = ("shade", "resolve") if single else (f"shade[{label}]", f"resolve[{label}]")
    ctx.add(Pass(sname, (sk, gk, *vis_keys), (rgb_key,), shade_pass, kind="shade", technique=label))
    ctx.add(Pass(rname, (ck, gk, *vis_keys, rgb_key), (out,), resolve, kind="resolve", technique=label))
    return out


def execute(built: Built, device: str, *, extra: list[Key] | None = None, check_immutable: bool = False,
            progress=None) -> tuple[Resources, list[dict], float]:
    """Run a built graph for its techniques' channels (and ``extra`` resources); (resources, records, ms).
    ``progress``: see :meth:`FrameGraph.execute`."""
    t0 = time.perf_counter()
    with wp.ScopedDevice(device):
        res, records = built.ctx.graph.execute(built.requested + list(extra or []), device, check_immutable=check_immutable,
                                               progress=progress)
    return res, records, 1e3 * (time.perf_counter() - t0)
