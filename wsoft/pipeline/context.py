"""The render context: the frame graph's shared providers (the scene on the device, the G-buffer,
light views and depth maps, the receiver's horizon) and what one technique instance sees of them
(:class:`TechniqueContext`: its keys, pass names and counters, and :meth:`~TechniqueContext.add_pass`,
which checks each pass against the technique's :class:`~wsoft.techniques.PassSpec`).

Providers register their own passes once, so techniques that need the same depth map share it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from wsoft.errors import DeclarationError
from wsoft.graph import FrameGraph, Key, Pass
from wsoft.lightspace.light import disk_shaped, light_gpu
from wsoft.lightspace.fit import fit_light_view
from wsoft.lightspace.view import outside_view_warning
from wsoft.pipeline.framing import Framing
from wsoft.raster.camera import camera_gpu
from wsoft.raster.gbuffer import GBuffer, render_gbuffer
from wsoft.raster.horizon import clip_to_front, front_counts, front_fraction
from wsoft.raster.depth_map import rasterize
from wsoft.scene.device import upload_scene
from wsoft.scene.types import LIGHT_DISTANT, Camera, Light, Scene


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
            if light.one_sided:
                self.pass_counters(name)["receivers_behind_light"] = view.receivers_behind
            if view.receivers_outside:
                self.warn(name, outside_view_warning(light, f"{view.receivers_outside} of {len(rec)} visible samples"))
            return {key: view}

        return self.add(Pass(name, (gk,), (key,), run, kind="light_map", light=self.label(light)))

    def light_depth(self, light: Light, size: int, conservative: bool = False, soft: bool = False, inner: bool = False,
                    opaque: bool = False, faces: str = "all") -> Key:
        """Resource: a :class:`~wsoft.raster.depth_map.DepthMap` (alpha-tested only if the scene has
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

    def light_behind(self, light: Light) -> Key | None:
        """Resource: how many covered G-buffer samples lie on or behind a rect or disk light's
        emitting plane (they get none of its light: every technique gives them V = 0), counted once
        per light and warned about with the light's path (counter ``receivers_behind_light``).
        None, and no pass, when the light emits all around or every corner of the scene's bounds
        lies in front of its plane by more than 1e-3 of the scene's diagonal."""
        if not light.one_sided:
            return None
        lo, hi = self.scene.bounds
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        ahead = (corners - np.asarray(light.position, np.float64)) @ np.asarray(light.direction, np.float64)
        if ahead.min() > 1e-3 * self.scene.diagonal:
            return None
        gk = self.gbuffer()
        key = Key("light_behind", self.label(light))
        name = f"light_behind[{self.label(light)}]"

        def run(res):
            gb = res[gk]
            covered = gb.prim.numpy() >= 0
            n = light.points_behind(gb.pos.numpy()[covered])
            self.pass_counters(name)["receivers_behind_light"] = n
            if n:
                self.warn(name, light_behind_warning(light, n, int(covered.sum())))
            return {key: n}

        return self.add(Pass(name, (gk,), (key,), run, kind="shade", light=self.label(light)))

    def clip_to_front(self, tctx: "TechniqueContext", light: Light, vis_key: Key) -> Key:
        """A technique's visibility of ``light`` capped by the light's front fraction (V = min(V,
        front)); a technique that applies the horizon itself (``horizon = "exact"``) keeps its own,
        handed on only where :meth:`light_behind` has receivers to count (else ``vis_key`` itself)."""
        bk = self.light_behind(light)
        exact = tctx.tech.horizon == "exact"
        if exact and bk is None:
            return vis_key
        fk = None if exact else self.front_fraction(light, centre=tctx.tech.horizon == "centre")
        key = Key("visibility", self.label(light), technique=tctx.label_, variant="front")

        def run(res):
            v = res[vis_key]
            return {key: v if exact else Visibility(clip_to_front(v.vis, res[fk]), v.stderr)}

        inputs = (vis_key,) + tuple(k for k in (fk, bk) if k is not None)
        return self.add(Pass(tctx.pass_name(f"horizon_{tctx.tech.name}", light), inputs, (key,), run, kind="shade", stage="horizon",
                             technique=tctx.label_, light=self.label(light)))

    def provide(self, key: Key, value: Any, *, name: str | None = None, kind: str = "reference") -> Key:
        """A resource computed outside the graph (a cached reference image): a pass that hands it over."""
        return self.add(Pass(name or str(key), (), (key,), lambda res: {key: value}, kind=kind))

    def technique(self, tech, label: str) -> "TechniqueContext":
        return TechniqueContext(self, tech, label)


def light_behind_warning(light: Light, n: int, total: int) -> str:
    """The warning for the ``n`` of ``total`` receivers behind a rect or disk light's plane."""
    d = ", ".join(f"{c:.3g}" for c in np.round(np.asarray(light.direction, np.float64), 6) + 0.0)
    return (f"light {light.path}: {n} of {total} visible samples lie behind its emitting plane (a {light.kind_name} light emits "
            f"from its front only, toward ({d})) and get none of its light (V = 0)")


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
