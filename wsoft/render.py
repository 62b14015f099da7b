"""``wsoft.render``: build one frame graph for one or several techniques on a scene, run what is needed.

Follow a render from here: :func:`render` makes a :class:`RenderContext`; each technique adds
its passes per shadow-casting light it supports, through a :class:`TechniqueContext` (which
asks the render context for the G-buffer, depth maps or the scene's arrays; those register
their own passes once, so techniques that need the same depth map share it); ``shade`` (a
Warp kernel, :mod:`wsoft.raster.shade`) lights every G-buffer sample with a technique's
visibilities, and ``resolve`` turns its per-sample results into per-pixel channels. Only passes
feeding the requested channels run; the stats say which ran, of what kind, and which several
techniques shared.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from wsoft.errors import DeclarationError, NonFiniteWarning, ParameterError, SceneError
from wsoft.io import nonfinite_counts
from wsoft.graph import FrameGraph, Key, Pass, Resources
from wsoft.lightspace.light import disk_shaped, light_gpu
from wsoft.lightspace.view import fit_light_view, outside_view_warning
from wsoft.parallel import compile_time, cpu_threads, resolve_device
from wsoft.raster.camera import camera_gpu, conform_aperture
from wsoft.raster.gbuffer import GBuffer, render_gbuffer
from wsoft.raster.horizon import clip_to_front, front_counts, front_fraction
from wsoft.raster.rasterizer import rasterize
from wsoft.raster.shade import shade as shade_samples
from wsoft.scene.device import upload_scene
from wsoft.scene.render_settings import RenderSettings, data_window_pixels
from wsoft.scene.types import LIGHT_DISTANT, Camera, Light, Scene
from wsoft.scene.usd import auto_camera, load_scene

SCENE = Key("scene")
GBUFFER = Key("gbuffer")
GBUFFER_CHANNELS = Key("gbuffer_channels")


@dataclass
class Visibility:
    """Per G-buffer sample visibility of one light (flat float32), optional standard error."""

    vis: wp.array
    stderr: wp.array | None = None

    def arrays(self) -> dict[str, wp.array]:
        out = {"vis": self.vis}
        if self.stderr is not None:
            out["stderr"] = self.stderr
        return out


class RenderContext:
    """What techniques build their passes with; providers register the shared passes once."""

    def __init__(self, scene: Scene, camera: Camera, width: int, height: int, device: str, pixel_samples: int = 1,
                 framing: Framing | None = None):
        self.scene = scene
        self.camera = camera
        self.width = width
        self.height = height
        self.device = device
        self.pixel_samples = pixel_samples
        self.framing = framing  # where the camera, size and data window came from (None: given directly)
        self.graph = FrameGraph()
        self.counters: dict[str, Any] = {"frame": {}, "passes": {}, "techniques": {}}
        self._labels = {l.path: scene.light_label(l) for l in scene.lights}
        self.warnings: dict[str, list[str]] = {}  # pass name -> warnings it raised (a frame lists those of its passes)

    def warn(self, pass_name: str, message: str) -> None:
        """A problem found while running a pass (receivers left unmapped, non-finite values): it
        goes into the stats' ``warnings`` of every frame that needs the pass, and the CLI prints it."""
        self.warnings.setdefault(pass_name, []).append(message)

    # -- naming ------------------------------------------------------------------------------------
    def label(self, light: Light) -> str:
        return self._labels.get(light.path, light.name)

    def light_gpu(self, light: Light):
        return light_gpu(light, self.scene.diagonal)

    def pass_counters(self, name: str) -> dict:
        """The counters of a pass (``stats["counters"]["passes"][name]``)."""
        return self.counters["passes"].setdefault(name, {})

    def add(self, p: Pass) -> Key:
        self.graph.add(p)
        return p.outputs[0]

    # -- providers -----------------------------------------------------------------------------------
    def scene_arrays(self) -> Key:
        """Resource ``scene``: a :class:`DeviceScene` (BVH, triangles, cutouts, textures)."""

        def run(res):
            ds, cached = self.scene.device_copy(self.device, upload_scene)
            self.counters["frame"]["scene_upload_cached"] = cached
            return {SCENE: ds}

        return self.add(Pass("upload_scene", (), (SCENE,), run, kind="scene"))

    def gbuffer(self) -> Key:
        """Resource ``gbuffer``: a :class:`GBuffer` (alpha-tested variant only if the scene has cutouts)."""
        sk = self.scene_arrays()
        alpha = self.scene.has_cutouts
        cam = camera_gpu(self.camera)

        def run(res):
            return {GBUFFER: render_gbuffer(res[sk], cam, self.width, self.height, self.pixel_samples, alpha)}

        return self.add(Pass("gbuffer_alpha" if alpha else "gbuffer", (sk,), (GBUFFER,), run, kind="gbuffer"))

    def gbuffer_channels(self) -> Key:
        """Resource ``gbuffer_channels``: per-pixel P, N, Z, A (host float32 [H, W]) and the
        coverage masks the resolves share."""
        gk = self.gbuffer()

        def run(res):
            gb: GBuffer = res[gk]
            prim = gb.host("prim")
            hit = prim >= 0
            nhit = hit.sum(axis=0)
            if gb.spp == 1:
                pos, nrm, dist = gb.host("pos")[0], gb.host("nrm")[0], gb.host("dist")[0]
            else:
                first = np.argmax(hit, axis=0)[None]  # first covered sample per pixel
                pos = np.take_along_axis(gb.host("pos"), first[..., None], axis=0)[0]
                nrm = np.take_along_axis(gb.host("nrm"), first[..., None], axis=0)[0]
                dist = np.take_along_axis(gb.host("dist"), first, axis=0)[0]
            ch: dict[str, np.ndarray] = {}
            for i, axis in enumerate("XYZ"):  # the G-buffer writes zeros on background samples
                ch[f"P.{axis}"] = np.ascontiguousarray(pos[..., i], dtype=np.float32)
                ch[f"N.{axis}"] = np.ascontiguousarray(nrm[..., i], dtype=np.float32)
            ch["Z"] = dist.astype(np.float32)
            ch["A"] = (nhit / gb.spp).astype(np.float32)
            return {GBUFFER_CHANNELS: {"channels": ch, "hit": hit, "nhit": nhit, "spp": gb.spp, "shape": (gb.height, gb.width)}}

        return self.add(Pass("gbuffer_channels", (gk,), (GBUFFER_CHANNELS,), run, kind="resolve"))

    def light_view(self, light: Light, size: int, soft: bool = False) -> Key:
        """Resource: a :class:`LightView` of ``light`` fitted to the receivers in view.

        ``soft``: widened so that casters blocking any part of the whole light are mapped."""
        gk = self.gbuffer()
        key = Key("light_view", self.label(light), variant=f"@{size}" + ("+soft" if soft else ""))
        name = f"fit_{key}"

        def run(res):
            gb: GBuffer = res[gk]
            prim = gb.prim.numpy()
            rec = gb.pos.numpy()[prim >= 0]
            lo, hi = self.scene.bounds
            distant = light.kind == LIGHT_DISTANT  # its depth range starts at the nearest caster over the receivers
            view = fit_light_view(light, rec, lo, hi, size, casters=self.scene.caster_points if soft or distant else None)
            self.pass_counters(name)["receivers_outside"] = view.receivers_outside
            if view.receivers_outside:
                self.warn(name, outside_view_warning(light, f"{view.receivers_outside} of {len(rec)} visible samples"))
            return {key: view}

        return self.add(Pass(name, (gk,), (key,), run, kind="light_map", light=self.label(light)))

    def light_depth(self, light: Light, size: int, conservative: bool = False, soft: bool = False, inner: bool = False,
                    opaque: bool = False, faces: str = "all") -> Key:
        """Resource: a :class:`~wsoft.raster.rasterizer.DepthMap` (alpha-tested only if the scene has
        cutouts); ``inner``: the map of depths that certainly block a whole texel (inner coverage);
        ``opaque``: cutouts not alpha-tested (each covers every texel it touches: with
        ``conservative``, a map no occluder escapes); ``faces``: ``all``, or only ``back`` faces of
        closed surfaces or ``open`` surfaces (:func:`~wsoft.scene.device.face_surfaces`). Only the
        triangles that cast ``light``'s shadow are drawn (its ``collection:shadowLink``,
        :meth:`Scene.casting_triangles`); the key is the light's own, so lights with different links
        never share a map."""
        sk = self.scene_arrays()
        casting = self.scene.casting_triangles(light)  # None: every triangle (no list, no extra work)
        vk = self.light_view(light, size, soft)
        alpha = self.scene.has_cutouts and not opaque
        flavour = (("_alpha" if alpha else "") + ("_inner" if inner else "_conservative" if conservative else "")
                   + ("" if faces == "all" else f"_{faces}"))
        key = Key("light_depth", self.label(light), variant=f"@{size}" + ("+soft" if soft else ""), flavour=flavour)
        name = str(key)

        def run(res):
            dm = rasterize(res[sk], res[vk], alpha_tested=alpha, conservative=conservative, inner=inner, faces=faces,
                           triangles=casting)
            if casting is not None:
                self.pass_counters(name)["casting_triangles"] = int(len(casting))
            if dm.private_maps:
                c = self.pass_counters(name)
                c["cpu_private_maps"] = dm.private_maps
                c["large_triangles"] = dm.big_triangles
            return {key: dm}

        return self.add(Pass(name, (sk, vk), (key,), run, kind="light_map", light=self.label(light)))

    def front_fraction(self, light: Light, centre: bool = False) -> Key:
        """Resource: per G-buffer sample, the fraction of ``light`` in front of the receiver's tangent
        plane (:mod:`wsoft.raster.horizon`), shared by every technique (``centre``: whether the
        light's centre is in front, 1 or 0)."""
        gk = self.gbuffer()
        key = Key("front", self.label(light), variant="centre" if centre else "")
        name = f"front_{'centre' if centre else 'fraction'}[{self.label(light)}]"
        L = self.light_gpu(light)
        disk = disk_shaped(light)

        def run(res):
            gb = res[gk]
            front = front_fraction(L, gb, disk, self.device, centre)
            self.pass_counters(name).update(front_counts(front, gb.prim.numpy() >= 0))
            return {key: front}

        return self.add(Pass(name, (gk,), (key,), run, kind="shade", light=self.label(light)))

    def clip_to_front(self, tctx: "TechniqueContext", light: Light, vis_key: Key) -> Key:
        """A technique's visibility of ``light`` capped by the light's front fraction (V = min(V, front))."""
        fk = self.front_fraction(light, centre=tctx.tech.horizon == "centre")
        key = Key("visibility", self.label(light), technique=tctx.label_, variant="front")

        def run(res):
            v = res[vis_key]
            return {key: Visibility(clip_to_front(v.vis, res[fk]), v.stderr)}

        return self.add(Pass(tctx.pass_name(f"horizon_{tctx.tech.name}", light), (vis_key, fk), (key,), run, kind="shade", stage="horizon",
                             technique=tctx.label_, light=self.label(light)))

    def provide(self, key: Key, value: Any, *, name: str | None = None, kind: str = "reference") -> Key:
        """A resource computed outside the graph (a cached reference image): a pass that hands it over."""
        return self.add(Pass(name or str(key), (), (key,), lambda res: {key: value}, kind=kind))

    def technique(self, tech, label: str) -> "TechniqueContext":
        return TechniqueContext(self, tech, label)


class TechniqueContext:
    """A :class:`RenderContext` seen by one technique instance (``label`` tells instances apart):
    its keys, pass names and counters carry the label; the shared providers are the render
    context's own."""

    def __init__(self, ctx: RenderContext, tech, label: str):
        self.ctx = ctx
        self.tech = tech
        self.label_ = label

    # the render context's state and providers
    scene = property(lambda self: self.ctx.scene)
    device = property(lambda self: self.ctx.device)
    width = property(lambda self: self.ctx.width)
    height = property(lambda self: self.ctx.height)
    pixel_samples = property(lambda self: self.ctx.pixel_samples)
    camera = property(lambda self: self.ctx.camera)

    def scene_arrays(self) -> Key:
        return self.ctx.scene_arrays()

    def gbuffer(self) -> Key:
        return self.ctx.gbuffer()

    def light_view(self, light: Light, size: int, soft: bool = False) -> Key:
        return self.ctx.light_view(light, size, soft)

    def light_depth(self, light: Light, size: int, conservative: bool = False, soft: bool = False, inner: bool = False,
                    opaque: bool = False, faces: str = "all") -> Key:
        return self.ctx.light_depth(light, size, conservative, soft, inner, opaque, faces)

    def label(self, light: Light) -> str:
        return self.ctx.label(light)

    def light_gpu(self, light: Light):
        return self.ctx.light_gpu(light)

    # -- keys and names ------------------------------------------------------------------------------
    def visibility_key(self, light: Light) -> Key:
        return Key("visibility", self.label(light), technique=self.label_)

    def key(self, kind: str, light: Light, variant: str = "") -> Key:
        """A resource of this technique instance alone."""
        return Key(kind, self.label(light), technique=self.label_, variant=variant)

    def shared_key(self, kind: str, light: Light, size: int, *params: str) -> Key:
        """A resource any instance of this technique may share: it depends on the light, the map
        ``size`` and the named parameters only (non-default values appear in the variant)."""
        p = self.tech.params
        d = self.tech.defaults()
        extra = ",".join(f"{n}={getattr(p, n)}" for n in params if getattr(p, n) != d[n])
        return Key(kind, self.label(light), variant=f"@{size}" + (f"{{{extra}}}" if extra else ""))

    def pass_name(self, base: str, light: Light, suffix: str = "") -> str:
        """``base[light]suffix``, or ``base[label:light]suffix`` for a labelled instance."""
        inner = self.label(light) if self.label_ == self.tech.name else f"{self.label_}:{self.label(light)}"
        return f"{base}[{inner}]{suffix}"

    def visibility(self, vis: wp.array, stderr: wp.array | None = None) -> Visibility:
        return Visibility(vis, stderr)

    def counters(self, light: Light) -> dict:
        """This technique's counters for ``light`` (``stats["counters"]["techniques"][label][light]``)."""
        t = self.ctx.counters["techniques"].setdefault(self.label_, {})
        return t.setdefault(self.label(light), {})

    def add_pass(self, name: str, inputs, outputs, run, *, stage: str, kind: str | None = None, light: Light | None = None) -> Key:
        """Register a pass of this technique, of its declared ``stage`` (:class:`~wsoft.techniques.PassSpec`:
        the kinds of ``inputs`` and ``outputs`` must be the declared ones, else a
        :class:`~wsoft.errors.DeclarationError`); ``name`` from :meth:`pass_name`, ``kind`` defaults
        to ``reference`` for the reference and ``technique`` otherwise."""
        check_declared(self.tech, name, stage, inputs, outputs)
        if kind is None:
            kind = "reference" if self.tech.name == "reference" else "technique"
        shared = all(not k.technique for k in outputs)
        return self.ctx.add(Pass(name, tuple(inputs), tuple(outputs), run, kind=kind, stage=stage,
                                 technique="" if shared else self.label_, light=self.label(light) if light is not None else ""))


def check_declared(tech, name: str, stage: str, inputs, outputs) -> None:
    """Raise a :class:`~wsoft.errors.DeclarationError` unless the pass ``name`` of ``tech`` reads and
    writes the kinds of resource its :class:`~wsoft.techniques.PassSpec` of ``stage`` declares
    (every declared read, optional ones or not, nothing else; exactly the declared writes)."""
    spec = tech.pass_spec(stage)
    got_in, got_out = {k.kind for k in inputs}, {k.kind for k in outputs}
    need, may = set(spec.reads), set(spec.reads) | set(spec.optional)
    if not need <= got_in <= may or got_out != set(spec.writes):
        raise DeclarationError(f"technique {tech.name!r}: pass {name!r} reads {', '.join(sorted(got_in)) or 'nothing'} and writes "
                               f"{', '.join(sorted(got_out))}; its stage {stage!r} declares {spec.text()}")


# --------------------------------------------------------------------------- frames


@dataclass
class Frame:
    """A rendered frame: ``channels`` (name -> float32 [H, W]) and ``stats`` (the JSON contract)."""

    channels: dict[str, np.ndarray]
    stats: dict[str, Any]
    exr_names: dict[str, str] = dataclasses.field(default_factory=dict)
    """Channels written to the EXR under another name: ``V`` (and ``V_stderr``) under the name of
    the output product's visibility RenderVar (:mod:`wsoft.scene.render_settings`)."""

    def __getitem__(self, name: str) -> np.ndarray:
        return self.channels[name]

    @property
    def V(self) -> np.ndarray:
        return self.channels["V"]

    def counters(self, light: str | None = None) -> dict:
        """The technique's counters for ``light`` (a label; default: the frame's first light)."""
        t = next(iter(self.stats["counters"]["techniques"].values()), {})
        if light is None:
            light = self.stats["light_labels"][0]
        return t.get(light, {})

    def write_exr(self, path: str) -> None:
        """The channels as float32 EXR (``V`` under :attr:`exr_names`' name when the render
        settings name a visibility RenderVar)."""
        from wsoft.io import write_exr

        write_exr(path, {self.exr_names.get(k, k): v for k, v in self.channels.items()})

    def write_png(self, path: str) -> None:
        from wsoft.io import write_png

        write_png(path, self.channels)


class FrameSet(Mapping):
    """Several techniques rendered in one graph: technique label -> :class:`Frame`, and the
    graph's own ``stats`` (every pass that ran, which techniques shared which)."""

    def __init__(self, frames: dict[str, Frame], stats: dict[str, Any]):
        self.frames = frames
        self.stats = stats

    def __getitem__(self, label: str) -> Frame:
        return self.frames[label]

    def __iter__(self):
        return iter(self.frames)

    def __len__(self) -> int:
        return len(self.frames)


# --------------------------------------------------------------------------- building the graph


DEFAULT_SIZE = (640, 480)


@dataclass
class Framing:
    """How a frame maps onto pixels: the camera (its window conformed to the image), the full
    image's size, the data window that is kept, and where each came from. Built by
    :func:`frame_setup`; the stats' ``framing`` is :meth:`describe`."""

    camera: Camera
    """The camera, its window conformed (:func:`~wsoft.raster.camera.conform_aperture`)."""
    width: int
    """Full image width in pixels (the settings' ``resolution``, a flag, or 640)."""
    height: int
    """Full image height in pixels."""
    crop: tuple[int, int, int, int] | None
    """The data window (x0, y0, x1, y1), half-open, rows from the top; None: the whole image."""
    pixel_aspect: float
    """A pixel's width over its height."""
    conform_policy: str
    """The ``aspectRatioConformPolicy`` applied (``adjustApertureHeight`` without settings)."""
    camera_source: str
    """``flag`` (asked for), ``render settings`` (their ``camera`` relationship), ``first camera``
    (the stage's first) or ``automatic``."""
    size_source: str
    """``flag``, ``render settings`` (their ``resolution``) or ``default`` (640 x 480)."""
    settings: RenderSettings | None = None
    """The scene's :class:`~wsoft.scene.render_settings.RenderSettings`, or None."""
    settings_source: str = "none"
    """How they were chosen (``flag``, ``metadata``, ``GetStageRenderSettings``, ``none``)."""

    @property
    def out_size(self) -> tuple[int, int]:
        """The written image's (width, height): the data window's."""
        if self.crop is None:
            return self.width, self.height
        x0, y0, x1, y1 = self.crop
        return x1 - x0, y1 - y0

    def describe(self) -> dict:
        rs = self.settings
        out = rs.output if rs is not None else None
        return {
            "render_settings": rs.path if rs is not None else None,
            "render_settings_source": self.settings_source,
            "camera": self.camera.path,
            "camera_source": self.camera_source,
            "resolution": [self.width, self.height],
            "resolution_source": self.size_source,
            "pixel_aspect": self.pixel_aspect,
            "conform_policy": self.conform_policy,
            "data_window": list(self.crop) if self.crop is not None else None,
            "product": out.path if out is not None else None,
            "product_name": out.product_name if out is not None and out.product_name else None,
            "visibility_var": out.visibility_var if out is not None else None,
        }


def frame_setup(scene: Scene, width: int | None = None, height: int | None = None, camera=None) -> Framing:
    """The camera and image of a render of ``scene``: what is given wins, then the scene's render
    settings (``Scene.render_settings``), then wsoft's defaults.

    Size: ``width`` and ``height``; one of them alone keeps the settings' aspect (the other is
    derived from their resolution); else the settings' ``resolution``; else 640 x 480 (either
    alone, as before: ``width=100`` gives 100 x 480). Camera: ``camera`` (a path or a
    :class:`Camera`), else the settings' ``camera``, else the stage's first camera, else an
    automatic one framing the scene. The window is conformed to the image with the settings'
    ``pixelAspectRatio`` and ``aspectRatioConformPolicy`` (without settings: square pixels and the
    horizontal field of view kept), and the settings' ``dataWindowNDC`` picks the pixels kept."""
    rs = scene.render_settings
    if width is not None and height is not None:
        size_source = "flag"
    elif rs is not None:
        rw, rh = rs.resolution
        if width is None and height is None:
            width, height, size_source = rw, rh, "render settings"
        elif width is None:
            width, size_source = max(1, int(round(height * rw / rh))), "flag"
        else:
            height, size_source = max(1, int(round(width * rh / rw))), "flag"
    else:
        size_source = "default" if width is None and height is None else "flag"
        width = DEFAULT_SIZE[0] if width is None else width
        height = DEFAULT_SIZE[1] if height is None else height
    _check_sizes(width, height, 1)
    par = rs.pixel_aspect if rs is not None else 1.0
    policy = rs.conform_policy if rs is not None else "adjustApertureHeight"
    if isinstance(camera, Camera):
        cam, cam_source = camera, "flag"
    elif camera:
        cam, cam_source = scene.find_camera(str(camera)), "flag"
    elif rs is not None and rs.camera:
        cam, cam_source = scene.find_camera(rs.camera), "render settings"
    elif scene.cameras:
        cam, cam_source = scene.cameras[0], "first camera"
    else:
        cam, cam_source = auto_camera(scene, par * width / height), "automatic"
    crop = None
    if rs is not None and rs.has_data_window:
        crop = data_window_pixels(rs.data_window, width, height)
        if crop[0] == crop[2] or crop[1] == crop[3]:
            ndc = ", ".join(f"{x:g}" for x in rs.data_window)
            raise ParameterError(f"dataWindowNDC ({ndc}) selects no pixel of a {width}x{height} image", file=scene.path, prim=rs.path)
        if crop == (0, 0, width, height):
            crop = None
    return Framing(conform_aperture(cam, width, height, par, policy), width, height, crop, par, policy, cam_source, size_source,
                   rs, scene.render_settings_source)


def _pick_camera(scene: Scene, camera, width: int, height: int) -> Camera:
    """The conformed camera of a ``width x height`` render (:func:`frame_setup`)."""
    return frame_setup(scene, width, height, camera).camera


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
            return create(t[0], t[1])
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
                device: str = "cpu", pixel_samples: int = 1, params: dict | None = None, strict: bool = True) -> Built:
    """Register every pass for ``technique`` (one or several, see :func:`render`) on ``scene``.

    ``width``, ``height``, ``camera``: as :func:`frame_setup` resolves them (None: the scene's
    render settings, else the defaults).

    A technique that does not support a light skips it; with ``strict`` a technique left with no
    light is an error naming the reason (``wsoft plan`` builds with ``strict=False`` to list it)."""
    if not scene.lights:
        why = ""
        if scene.unshadowed_lights:
            why = f" ({len(scene.unshadowed_lights)} light(s) have shadow:enable = false)"
        elif scene.skipped_lights:
            why = f" (not handled: {', '.join(s.path + ' ' + s.kind for s in scene.skipped_lights)})"
        raise SceneError(f"no shadow-casting light{why}", file=scene.path)
    techs = as_techniques(technique, params or {})
    labels = technique_labels(techs)
    instancing = instancing_plan(scene, techs, labels)
    if instancing["mode"] == "flattened" and strict:
        scene = flatten_for(scene, instancing)
    lights = [scene.find_light(str(light))] if light else list(scene.lights)
    fr = frame_setup(scene, width, height, camera)
    ctx = RenderContext(scene, fr.camera, fr.width, fr.height, device, pixel_samples, framing=fr)
    built = Built(ctx, labels, techs, {}, {}, {}, {})
    built.instancing = instancing
    for tech, label in zip(techs, labels):
        tctx = ctx.technique(tech, label)
        mine, skipped = supported_lights(tech, scene, lights)
        built.skipped[label] = skipped
        if not mine:
            if strict:
                raise ParameterError(f"{label}: " + "; ".join(f"{l.path}: {why}" for l, why in skipped), file=scene.path)
            built.lights[label] = []
            continue
        built.lights[label] = mine
        built.visibility[label] = [visibility_of(ctx, tctx, l) for l in mine]
        built.channels[label] = _add_resolve(ctx, tech, label, mine, built.visibility[label], single=len(techs) == 1)
    return built


FLATTEN_LIMIT = 20_000_000  # instanced triangles beyond which a stage is not flattened for a technique that needs it


def instancing_plan(scene: Scene, techs: list, labels: list[str]) -> dict:
    """How ``scene``'s instances are drawn for ``techs``: ``mode`` ``none`` (the stage has none),
    ``kept`` (every technique keeps them: prototypes once, :mod:`wsoft.scene.instancing`) or
    ``flattened`` (a technique reads the triangle soup: ``needs`` lists (label, reason))."""
    if not scene.instanced:
        return {"mode": "none"}
    inst = scene.instances
    needs = [(label, t.instancing_why()) for t, label in zip(techs, labels) if t.instancing_why()]
    return {"mode": "flattened" if needs else "kept", "needs": needs, "instances": inst.count, "prototypes": len(inst.prototypes),
            "prototype_triangles": inst.prototype_triangles, "instanced_triangles": inst.instanced_triangles,
            "soup_triangles": scene.triangle_count}


def flatten_for(scene: Scene, plan: dict) -> Scene:
    """``scene`` flattened for the techniques of ``plan`` that read the triangle soup; an error when
    it would hold more than :data:`FLATTEN_LIMIT` triangles (name the techniques and those that keep instances)."""
    who = "; ".join(f"{label} ({why})" for label, why in plan["needs"])
    if scene.total_triangles > FLATTEN_LIMIT:
        from wsoft.techniques import TECHNIQUES

        keep = ", ".join(n for n, t in sorted(TECHNIQUES.items()) if not t.instancing_refusal)
        raise ParameterError(f"{who}: needs the stage flattened, {scene.total_triangles:,} triangles from {plan['instances']:,} instances "
                             f"(more than {FLATTEN_LIMIT:,}); techniques that keep instances: {keep}", file=scene.path)
    return scene.flattened()


def supported_lights(tech, scene: Scene, lights: list[Light]) -> tuple[list[Light], list[tuple[Light, str]]]:
    """``lights`` split into those ``tech`` supports and (light, reason) for the others."""
    mine, skipped = [], []
    for l in lights:
        why = tech.supports(scene, l)
        if why is None:
            mine.append(l)
        else:
            skipped.append((l, why))
    return mine, skipped


def visibility_of(ctx: RenderContext, tctx: TechniqueContext, light: Light) -> Key:
    """Register a technique's passes for ``light``; the key of its per-sample visibility, capped by
    the receiver's horizon (a point sees only the light in front of its tangent plane): the
    reference applies it per light sample, every other technique is capped by its front fraction."""
    tech = tctx.tech
    vk = tech.add_passes(tctx, light)
    if tech.distance_caveat and light.distance_limited:
        ctx.warn(ctx.graph.producers[vk], distance_caveat_warning(tech, light))
    return vk if tech.horizon == "exact" else ctx.clip_to_front(tctx, light, vk)


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
        return {rgb_key: shade_samples(res[sk], res[gk], [(L, res[vk].vis, l.shadow_color)
                                                          for L, l, vk in zip(light_structs, lights, vis_keys)])}

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
    ctx.add(Pass(rname, (ck, *vis_keys, rgb_key), (out,), resolve, kind="resolve", technique=label))
    return out


# --------------------------------------------------------------------------- render


def _check_sizes(width: int | None, height: int | None, pixel_samples: int) -> None:
    """Image size (None: not given, resolved later) and samples per pixel in range."""
    if width is not None and height is not None and (width < 1 or height < 1 or width * height > 64 * 1024 * 1024):
        raise ParameterError(f"bad image size {width}x{height}")
    if (width is not None and width < 1) or (height is not None and height < 1):
        raise ParameterError(f"bad image size {'?' if width is None else width}x{'?' if height is None else height}")
    if not 1 <= pixel_samples <= 64:
        raise ParameterError(f"pixel_samples {pixel_samples} out of range [1, 64]")


def execute(built: Built, device: str, *, extra: list[Key] | None = None, check_immutable: bool = False,
            progress=None) -> tuple[Resources, list[dict], float]:
    """Run a built graph for its techniques' channels (and ``extra`` resources); (resources, records, ms).
    ``progress``: see :meth:`FrameGraph.execute`."""
    t0 = time.perf_counter()
    with wp.ScopedDevice(device):
        res, records = built.ctx.graph.execute(built.requested + list(extra or []), device, check_immutable=check_immutable,
                                               progress=progress)
    return res, records, 1e3 * (time.perf_counter() - t0)


def frame_ms(total_ms: float, records: list[dict], closure: set[str], single: bool) -> float:
    """A technique's frame time: alone in its graph, the wall time of the render less the passes it
    does not need (a metric pass, a ground truth handed in); beside others, the sum of the passes
    it needs, shared ones included."""
    if single:
        return total_ms - sum(r["ms"] for r in records if r["name"] not in closure)
    return sum(r["ms"] for r in records if r["name"] in closure)


def cpu_over_wall(record: dict) -> float:
    """A pass's CPU time over its wall time: how many CPU threads it kept busy on average (the
    process's CPU time, so other work in the process during the pass counts too)."""
    return round(record["cpu_ms"] / record["ms"], 3) if record["ms"] > 0 else 0.0


def frames_of(built: Built, res: Resources, records: list[dict], total_ms: float, compile_ms: float = 0.0) -> FrameSet:
    """One :class:`Frame` per technique with its own stats; the set's stats cover the whole graph.

    ``total_ms``: the render's wall time; ``compile_ms``: the part of it Warp spent compiling or
    loading modules (:func:`~wsoft.parallel.compile_time`), left out of ``total`` and reported as
    ``timings_ms["compile"]`` (the records' pass times already leave it out)."""
    total_ms -= compile_ms
    ctx, scene = built.ctx, built.ctx.scene
    graph = ctx.graph
    closures = {label: graph.closure([built.channels[label]]) for label in built.labels if label in built.channels}
    users: dict[str, list[str]] = {}
    for label, names in closures.items():
        for n in names:
            users.setdefault(n, []).append(label)
    shared = {n: ls for n, ls in users.items() if len(ls) > 1}
    memory: dict[str, int] = {}
    for r in records:
        memory.update(r["bytes"])
    base = {
        "device": ctx.device,
        "threads": cpu_threads() if ctx.device == "cpu" else None,
        "scene": {"path": scene.path, "triangles": scene.total_triangles, "time": scene.time, "up_axis": scene.up_axis,
                  "meters_per_unit": scene.meters_per_unit, "instancing": built.instancing},
        "width": ctx.framing.out_size[0] if ctx.framing is not None else ctx.width,  # the written image (the data window)
        "height": ctx.framing.out_size[1] if ctx.framing is not None else ctx.height,
        "pixel_samples": ctx.pixel_samples,
        "camera": ctx.camera.path,
        "framing": ctx.framing.describe() if ctx.framing is not None else None,
        "warnings": list(scene.warnings),
    }
    out = scene.render_settings.output if scene.render_settings is not None else None
    exr_names = {"V": out.visibility_var, "V_stderr": f"{out.visibility_var}_stderr"} if out is not None else {}
    frame_counters = {**ctx.counters["frame"], "triangles": scene.total_triangles, "pixels": ctx.width * ctx.height,
                      "gbuffer_samples": ctx.width * ctx.height * ctx.pixel_samples}
    frames = {}
    single = len(built.labels) == 1
    for tech, label in zip(built.techniques, built.labels):
        if label not in built.channels:
            continue
        mine = [r for r in records if r["name"] in closures[label]]
        timings = {r["name"]: round(r["ms"], 3) for r in mine}
        kinds: dict[str, float] = {}
        for r in mine:
            kinds[r["kind"]] = round(kinds.get(r["kind"], 0.0) + r["ms"], 3)
        warns = list(base["warnings"]) + [f"{label}: light {l.path} skipped: {why}" for l, why in built.skipped[label]]
        warns += [f"{r['name']}: {w}" for r in mine for w in ctx.warnings.get(r["name"], [])]
        lights = built.lights[label]
        stats = {
            **base,
            "technique": tech.name,
            "label": label,
            "params": dataclasses.asdict(tech.params),
            "lights": [l.path for l in lights],
            "light": lights[0].path,
            "light_labels": [ctx.label(l) for l in lights],
            "timings_ms": {**timings, "total": round(frame_ms(total_ms, records, closures[label], single), 3),
                           "compile": round(compile_ms if single else sum(r.get("compile_ms", 0.0) for r in mine), 3)},
            "timings_by_kind_ms": kinds,
            "cpu_ms": {r["name"]: round(r["cpu_ms"], 3) for r in mine},
            "cpu_over_wall": {r["name"]: cpu_over_wall(r) for r in mine},
            "memory_bytes": {k: v for r in mine for k, v in r["bytes"].items()},
            "counters": {"frame": frame_counters,
                         "passes": {n: c for n, c in ctx.counters["passes"].items() if n in closures[label]},
                         "techniques": {label: ctx.counters["techniques"].get(label, {})}},
            "passes": [r["name"] for r in mine],
            "pass_kinds": {r["name"]: r["kind"] for r in mine},
            "pass_stages": {r["name"]: r["stage"] for r in mine if r["stage"]},
            "shared_passes": {n: [x for x in shared[n] if x != label] for n in timings if n in shared},
            "warnings": warns,
        }
        channels = res[built.channels[label]]
        bad = nonfinite_counts(channels)  # never hidden: counted, warned, and a test failure in the suite
        stats["nonfinite"] = bad
        if bad:
            msg = f"{label}: non-finite values (NaN/inf) in " + ", ".join(f"{k} ({n})" for k, n in bad.items())
            stats["warnings"].append(msg)
            warnings.warn(msg, NonFiniteWarning, stacklevel=2)
        frames[label] = Frame(channels=channels, stats=stats, exr_names=exr_names)
    stats = {
        **base,
        "techniques": list(frames),
        "timings_ms": {**{r["name"]: round(r["ms"], 3) for r in records}, "total": round(total_ms, 3), "compile": round(compile_ms, 3)},
        "cpu_ms": {r["name"]: round(r["cpu_ms"], 3) for r in records},
        "cpu_over_wall": {r["name"]: cpu_over_wall(r) for r in records},
        "memory_bytes": memory,
        "counters": {"frame": frame_counters, **{k: v for k, v in ctx.counters.items() if k != "frame"}},
        "passes": [r["name"] for r in records],
        "pass_kinds": {r["name"]: r["kind"] for r in records},
        "shared_passes": shared,
        "skipped": {label: [{"light": l.path, "reason": why} for l, why in sk] for label, sk in built.skipped.items() if sk},
        "warnings": list(base["warnings"]) + [f"{r['name']}: {w}" for r in records for w in ctx.warnings.get(r["name"], [])],
    }
    return FrameSet(frames, stats)


def render(
    scene,
    technique,
    *,
    width: int | None = None,
    height: int | None = None,
    camera=None,
    light=None,
    device: str | None = None,
    pixel_samples: int = 1,
    time_code: float | None = None,
    render_settings: str | None = None,
    progress=None,
    **params,
) -> Frame | FrameSet:
    """Render on ``scene`` (a :class:`Scene` or a USD path) and return a :class:`Frame`, or a
    :class:`FrameSet` when ``technique`` is a list.

    ``technique``: a name with its parameters as keywords (``render(scene, "pcss",
    filter_samples=64)``), or a list of names, ``(name, {params})`` pairs and
    :class:`~wsoft.techniques.Technique` instances, rendered in one graph that shares the passes
    they have in common (``render(scene, ["pcss", ("essm", {"H": 2}), "reference"])``).
    ``width``, ``height``, ``camera`` (a camera prim path): None takes them from the scene's
    render settings, else 640 x 480 and the stage's first camera, else an automatic one (see
    :func:`frame_setup`; the settings' pixel aspect, conform policy and data window apply whatever
    was given). ``render_settings``: the ``RenderSettings`` prim to use (None: the stage's own, see
    :mod:`wsoft.scene.render_settings`); a :class:`Scene` loaded with other settings is loaded
    again from its file, since their ``includedPurposes`` may change its geometry.
    ``light``: a light path or name (default: every shadow-casting light; ``V`` = the first a
    technique supports). A light a technique does not support is skipped with a warning.
    ``progress``: called as ``progress(done, total, pass_name)`` before each pass of the graph and
    ``progress(total, total, None)`` after the last (the command line's progress bar).

    With a ``dataWindowNDC`` the whole image is rendered and the frame's channels are the data
    window's pixels (``stats["framing"]["data_window"]``), the same values as the whole render's.
    """
    scene = with_render_settings(scene, render_settings, time_code)
    _check_sizes(width, height, pixel_samples)
    several = is_several(technique)
    dev = resolve_device(device)
    from wsoft.techniques import TECHNIQUES  # noqa: F401  (the technique modules load before the clock starts)

    t0 = time.perf_counter()
    built = build_graph(scene, technique, width=width, height=height, camera=camera, light=light, device=dev,
                        pixel_samples=pixel_samples, params=params)
    res, records, _ = execute(built, dev, progress=progress)
    t1 = time.perf_counter()
    fs = frames_of(built, res, records, 1e3 * (t1 - t0), compile_ms=1e3 * compile_time(t0, t1)[0])
    if several:
        return fs
    return fs[built.labels[0]]


INSTANCING_MODES = ("auto", "keep", "flatten")
AUTO_KEEP_TRIANGLES = 4_000_000  # instancing=auto keeps instances when they place more triangles than this


def load_stage(path, *, time: float | None = None, render_settings: str | None = None, instancing: str = "auto") -> Scene:
    """Load a stage for rendering. ``instancing``: ``keep`` — PointInstancers and instanceable prims
    stay instances (prototypes once; techniques that read the triangle soup get it flattened by
    the frame graph, :func:`instancing_plan`); ``flatten`` — one triangle soup (every instance's
    copy); ``auto`` (default) — keep them when they place more than :data:`AUTO_KEEP_TRIANGLES`
    triangles (a stage that would not fit flattened), else flatten (the soup lets the reference
    trace in packets, faster on CPU than rays through the top level)."""
    if instancing not in INSTANCING_MODES:
        raise ParameterError(f"instancing {instancing!r} is not one of {', '.join(INSTANCING_MODES)}")
    if instancing == "flatten":
        return load_scene(path, time=time, render_settings=render_settings)
    scene = load_scene(path, time=time, render_settings=render_settings, instancing=True)
    if instancing == "auto" and scene.instanced and scene.instances.instanced_triangles <= AUTO_KEEP_TRIANGLES:
        return scene.flattened()
    return scene


def with_render_settings(scene, render_settings: str | None, time_code: float | None = None) -> Scene:
    """``scene`` (a :class:`Scene` or what :func:`load_scene` opens) loaded with the render
    settings ``render_settings`` (None: as it is, or the stage's own)."""
    if not isinstance(scene, Scene):
        return load_stage(scene, time=time_code, render_settings=render_settings)
    if render_settings is None:
        return scene
    have = scene.render_settings.path if scene.render_settings is not None else None
    if have == str(render_settings):
        return scene
    import os

    if os.path.isfile(scene.path):  # the settings' includedPurposes may change the geometry
        return load_scene(scene.path, time=scene.time, render_settings=str(render_settings))
    raise ParameterError(f"this scene was loaded with render settings {have or '(none)'} and has no file to load again; "
                         f"pass render_settings={str(render_settings)!r} to load_scene", file=scene.path)


COLOR_APPLIED = "applied to R G B, not to V"
FALLOFF_APPLIED = "not applied (UsdLux gives no formula for the fade; the shadow ends sharply at shadow:distance)"


def shadow_controls(scene: Scene, light: Light) -> dict:
    """A light's UsdLux shadow controls as ``wsoft plan`` lists them: the ``collection:shadowLink``
    membership (prims it leaves out of the shadow, of the prims loaded), ``inputs:shadow:distance``
    (None: unlimited) and which techniques honour it, the shadow colour (applied to ``R G B``, not
    to ``V``) and falloff (not applied)."""
    from wsoft.techniques import TECHNIQUES

    out = [scene.prims[i] for i in light.shadow_excluded]
    casting = scene.casting_mask(light)
    refused = sorted(n for n, c in TECHNIQUES.items() if c.distance_refusal)
    return {
        "link": {"excluded_prims": len(out), "prims": len(scene.prims), "excluded": out[:5],
                 "casting_triangles": scene.triangle_count if casting is None else int(casting.sum()),
                 "applied": "excluded prims cast no shadow of this light (still seen, still receive it)" if out else "every prim casts"},
        "distance": light.shadow_distance if light.distance_limited else None,
        "distance_applied": ("unlimited" if not light.distance_limited else
                             f"honoured by {', '.join(n for n in sorted(TECHNIQUES) if n not in refused)}; refused by {', '.join(refused)}"),
        "color": list(light.shadow_color),
        "color_applied": COLOR_APPLIED,
        "falloff": light.shadow_falloff,
        "falloff_gamma": light.shadow_falloff_gamma,
        "falloff_applied": FALLOFF_APPLIED if light.shadow_falloff > 0 else "none authored (falloff <= 0)",
    }


def plan(scene: Scene, techniques: list[str] | None = None, *, width: int | None = None, height: int | None = None, light=None,
         camera=None) -> dict:
    """What would run: shadow-casting lights (with their UsdLux shadow controls,
    :func:`shadow_controls`), skipped lights, cutout materials, the purposes loaded, the framing
    (``framing``: which render settings prim and camera, where each came from, the resolution,
    conform policy and data window; see :meth:`Framing.describe`), and per technique the passes
    (with their kinds) or why it is not applicable to a light."""
    from wsoft.techniques import TECHNIQUES

    out = {
        "scene": scene.path,
        "triangles": scene.total_triangles,
        "instancing": instancing_plan(scene, [], []),
        "up_axis": scene.up_axis,
        "meters_per_unit": scene.meters_per_unit,
        "lights": [{"path": l.path, "kind": l.kind_name, "size": l.size_description(), "shadow": shadow_controls(scene, l)}
                   for l in scene.lights],
        "skipped_lights": [{"path": l.path, "kind": l.kind_name, "reason": "shadow:enable = false"} for l in scene.unshadowed_lights]
        + [{"path": s.path, "kind": s.kind, "reason": s.reason} for s in scene.skipped_lights],
        "cutout_materials": [{"path": p, "triangles": n} for p, n in scene.cutout_triangle_counts().items()],
        "dynamic_prims": scene.dynamic_prims(),
        "baked_light_triangles": 0 if scene.tri_baked is None else int(np.count_nonzero(~np.isnan(scene.tri_baked[:, 0, 0]))),
        "cameras": [c.path for c in scene.cameras],
        "purposes": list(scene.purposes),
        "framing": frame_setup(scene, width, height, camera).describe(),
        "warnings": list(scene.warnings),
        "techniques": {},
        "not_applicable": {},
    }
    if not scene.lights:
        return out
    for name in techniques or sorted(TECHNIQUES):
        built = build_graph(scene, name, width=width, height=height, camera=camera, light=light, device="cpu", strict=False)
        label = built.labels[0]
        if built.instancing["mode"] == "flattened":
            why = built.instancing["needs"][0][1]
            if scene.total_triangles > FLATTEN_LIMIT:  # render refuses it: say so instead of listing passes
                out["not_applicable"][name] = [{"light": "(every light)", "reason": f"{why}: needs the stage flattened, "
                                                f"{scene.total_triangles:,} triangles (more than {FLATTEN_LIMIT:,})"}]
                continue
            out.setdefault("flattened_for", {})[name] = why
        if built.skipped[label]:
            out["not_applicable"][name] = [{"light": l.path, "reason": why} for l, why in built.skipped[label]]
        if label in built.channels:
            out["techniques"][name] = [p.name for p in built.ctx.graph.schedule([built.channels[label]])]
            out.setdefault("pass_kinds", {}).update({p.name: p.kind for p in built.ctx.graph.schedule([built.channels[label]])})
    return out
