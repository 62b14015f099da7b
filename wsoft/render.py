"""``wsoft.render``: build a frame graph for a technique and a scene, run what is needed.

Follow a render from here: :func:`render` makes a :class:`RenderContext`, the technique adds
its passes per shadow-casting light (asking the context for the G-buffer, depth maps or the
scene's arrays, which register their own passes), ``shade`` (a Warp kernel,
:mod:`wsoft.raster.shade`) lights every G-buffer sample with the visibilities, and ``resolve``
turns per-sample results into per-pixel channels. Only passes feeding those run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from wsoft.errors import ParameterError, SceneError
from wsoft.graph import FrameGraph, Pass, buffer_bytes
from wsoft.parallel import cpu_threads, resolve_device
from wsoft.raster.camera import camera_gpu, fit_aspect
from wsoft.raster.gbuffer import GBuffer, render_gbuffer
from wsoft.lightspace.light import light_gpu
from wsoft.lightspace.view import fit_light_view
from wsoft.raster.rasterizer import rasterize
from wsoft.raster.shade import shade as shade_samples
from wsoft.scene.device import upload_scene
from wsoft.scene.types import Camera, Light, Scene
from wsoft.scene.usd import auto_camera, load_scene


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
    """What a technique builds its passes with; providers register the shared passes once."""

    def __init__(self, scene: Scene, camera: Camera, width: int, height: int, device: str, pixel_samples: int = 1):
        self.scene = scene
        self.camera = camera
        self.width = width
        self.height = height
        self.device = device
        self.pixel_samples = pixel_samples
        self.graph = FrameGraph()
        self.counters: dict[str, Any] = {}
        names = [l.name for l in scene.lights]
        self._labels = {l.path: (l.name if names.count(l.name) == 1 else l.path) for l in scene.lights}

    # -- naming ------------------------------------------------------------------
    def label(self, light: Light) -> str:
        return self._labels.get(light.path, light.name)

    def visibility_key(self, light: Light) -> str:
        return f"visibility[{self.label(light)}]"

    def visibility(self, vis: wp.array, stderr: wp.array | None = None) -> Visibility:
        return Visibility(vis, stderr)

    def light_gpu(self, light: Light):
        return light_gpu(light, self.scene.diagonal)

    def add_pass(self, name: str, inputs, outputs, run, kind: str = "technique") -> str:
        self.graph.add(Pass(name, tuple(inputs), tuple(outputs), run, kind))
        return outputs[0]

    # -- providers ---------------------------------------------------------------
    def scene_arrays(self) -> str:
        """Resource ``scene``: a :class:`DeviceScene` (BVH, triangles, cutouts, textures)."""
        key = "scene"

        def run(res):
            ds, cached = self.scene.device_copy(self.device, upload_scene)
            self.counters["scene_upload_cached"] = cached
            return {key: ds}

        self.graph.add(Pass("upload_scene", (), (key,), run))
        return key

    def gbuffer(self) -> str:
        """Resource ``gbuffer``: a :class:`GBuffer` (alpha-tested variant only if the scene has cutouts)."""
        sk = self.scene_arrays()
        alpha = self.scene.has_cutouts
        cam = camera_gpu(self.camera)

        def run(res):
            return {"gbuffer": render_gbuffer(res[sk], cam, self.width, self.height, self.pixel_samples, alpha)}

        self.graph.add(Pass("gbuffer_alpha" if alpha else "gbuffer", (sk,), ("gbuffer",), run))
        return "gbuffer"

    def light_view(self, light: Light, size: int, soft: bool = False) -> str:
        """Resource: a :class:`LightView` of ``light`` fitted to the receivers in view.

        ``soft``: widened so that casters blocking any part of the whole light are mapped."""
        gk = self.gbuffer()
        key = f"light_view[{self.label(light)}]@{size}" + ("+soft" if soft else "")

        def run(res):
            gb: GBuffer = res[gk]
            prim = gb.prim.numpy()
            rec = gb.pos.numpy()[prim >= 0]
            lo, hi = self.scene.bounds
            view = fit_light_view(light, rec, lo, hi, size, casters=self.scene.points if soft else None)
            self.counters[f"receivers_outside_light_view[{self.label(light)}]"] = view.receivers_outside
            return {key: view}

        self.graph.add(Pass(f"fit_{key}", (gk,), (key,), run))
        return key

    def light_depth(self, light: Light, size: int, conservative: bool = False, soft: bool = False) -> str:
        """Resource: a :class:`DepthMap` (alpha-tested only if the scene has cutouts)."""
        sk = self.scene_arrays()
        vk = self.light_view(light, size, soft)
        alpha = self.scene.has_cutouts
        name = "light_depth" + ("_alpha" if alpha else "") + ("_conservative" if conservative else "")
        key = f"{name}[{self.label(light)}]@{size}" + ("+soft" if soft else "")

        def run(res):
            dm = rasterize(res[sk], res[vk], alpha_tested=alpha, conservative=conservative)
            if dm.private_maps:
                self.counters[f"{key}.cpu_private_maps"] = dm.private_maps
                self.counters[f"{key}.large_triangles"] = dm.big_triangles
            return {key: dm}

        self.graph.add(Pass(key, (sk, vk), (key,), run))
        return key


@dataclass
class Frame:
    """A rendered frame: ``channels`` (name -> float32 [H, W]) and ``stats`` (the JSON contract)."""

    channels: dict[str, np.ndarray]
    stats: dict[str, Any]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.channels[name]

    @property
    def V(self) -> np.ndarray:
        return self.channels["V"]

    def write_exr(self, path: str) -> None:
        from wsoft.io import write_exr

        write_exr(path, self.channels)

    def write_png(self, path: str) -> None:
        from wsoft.io import write_png

        write_png(path, self.channels)


def _pick_camera(scene: Scene, camera, width: int, height: int) -> Camera:
    if isinstance(camera, Camera):
        cam = camera
    elif camera:
        cam = scene.find_camera(str(camera))
    elif scene.cameras:
        cam = scene.cameras[0]
    else:
        cam = auto_camera(scene, width / height)
    return fit_aspect(cam, width, height)


def build_graph(scene: Scene, technique, *, width: int, height: int, camera=None, light=None, device: str = "cpu", pixel_samples: int = 1):
    """Register every pass for ``technique`` on ``scene``; returns (context, requested outputs, lights)."""
    if not scene.lights:
        why = ""
        if scene.unshadowed_lights:
            why = f" ({len(scene.unshadowed_lights)} light(s) have shadow:enable = false)"
        elif scene.skipped_lights:
            why = f" (not handled: {', '.join(s.path + ' ' + s.kind for s in scene.skipped_lights)})"
        raise SceneError(f"no shadow-casting light{why}", file=scene.path)
    lights = [scene.find_light(str(light))] if light else list(scene.lights)
    cam = _pick_camera(scene, camera, width, height)
    ctx = RenderContext(scene, cam, width, height, device, pixel_samples)
    vis_keys = [technique.add_passes(ctx, l) for l in lights]
    gk = ctx.gbuffer()
    labels = [ctx.label(l) for l in lights]

    sk = ctx.scene_arrays()
    light_structs = [ctx.light_gpu(l) for l in lights]

    def shade_pass(res):
        rgb = shade_samples(res[sk], res[gk], [(L, res[vk].vis) for L, vk in zip(light_structs, vis_keys)])
        return {"rgb_samples": rgb}

    ctx.graph.add(Pass("shade", (sk, gk, *vis_keys), ("rgb_samples",), shade_pass, kind="resolve"))

    def resolve(res):
        """Per-sample results -> per-pixel channels (means over the pixel's covered samples)."""
        gb: GBuffer = res[gk]
        prim = gb.host("prim")
        hit = prim >= 0
        nhit = hit.sum(axis=0)
        cov = nhit / gb.spp
        rgb = res["rgb_samples"].numpy().reshape(gb.spp, gb.height, gb.width, 3)
        if gb.spp == 1:
            pos, nrm, dist = gb.host("pos")[0], gb.host("nrm")[0], gb.host("dist")[0]
            rgb = rgb[0]
        else:
            first = np.argmax(hit, axis=0)[None]  # first covered sample per pixel
            pos = np.take_along_axis(gb.host("pos"), first[..., None], axis=0)[0]
            nrm = np.take_along_axis(gb.host("nrm"), first[..., None], axis=0)[0]
            dist = np.take_along_axis(gb.host("dist"), first, axis=0)[0]
            rgb = rgb.mean(axis=0)  # background samples are black: the mean is already coverage-weighted
        ch: dict[str, np.ndarray] = {}
        for label, vk in zip(labels, vis_keys):
            v = res[vk].vis.numpy().reshape(gb.spp, gb.height, gb.width)
            vv = v[0] if gb.spp == 1 else np.where(nhit > 0, (v * hit).sum(axis=0) / np.maximum(nhit, 1), 1.0)
            ch[f"V.{label}"] = vv.astype(np.float32)
            if res[vk].stderr is not None:
                e = res[vk].stderr.numpy().reshape(gb.spp, gb.height, gb.width)
                ee = np.sqrt((e * e * hit).sum(axis=0)) / np.maximum(nhit, 1)
                ch[f"V_stderr.{label}"] = ee.astype(np.float32)
        ch["V"] = ch[f"V.{labels[0]}"]
        if f"V_stderr.{labels[0]}" in ch:
            ch["V_stderr"] = ch[f"V_stderr.{labels[0]}"]
        for i, axis in enumerate("XYZ"):  # the G-buffer writes zeros on background samples
            ch[f"P.{axis}"] = np.ascontiguousarray(pos[..., i], dtype=np.float32)
            ch[f"N.{axis}"] = np.ascontiguousarray(nrm[..., i], dtype=np.float32)
        ch["Z"] = dist.astype(np.float32)
        ch["A"] = cov.astype(np.float32)
        for i, c in enumerate("RGB"):
            ch[c] = np.ascontiguousarray(rgb[..., i], dtype=np.float32)
        return {"channels": ch}

    ctx.graph.add(Pass("resolve", (gk, *vis_keys, "rgb_samples"), ("channels",), resolve, kind="resolve"))
    return ctx, ["channels"], lights



def render(
    scene,
    technique: str,
    *,
    width: int = 640,
    height: int = 480,
    camera=None,
    light=None,
    device: str | None = None,
    pixel_samples: int = 1,
    time_code: float | None = None,
    **params,
) -> Frame:
    """Render ``technique`` on ``scene`` (a :class:`Scene` or a USD path) and return a :class:`Frame`.

    ``camera``: a camera prim path (default: the stage's first camera, else an automatic one).
    ``light``: a light path or name for ``V`` (default: every shadow-casting light, ``V`` = the
    first). ``params``: the technique's parameters (see ``wsoft techniques``).
    """
    from wsoft.techniques import create

    if not isinstance(scene, Scene):
        scene = load_scene(scene, time=time_code)
    if width < 1 or height < 1 or width * height > 64 * 1024 * 1024:
        raise ParameterError(f"bad image size {width}x{height}")
    if not 1 <= pixel_samples <= 64:
        raise ParameterError(f"pixel_samples {pixel_samples} out of range [1, 64]")
    tech = create(technique, params)
    dev = resolve_device(device)
    t0 = time.perf_counter()
    ctx, requested, lights = build_graph(scene, tech, width=width, height=height, camera=camera, light=light, device=dev, pixel_samples=pixel_samples)
    with wp.ScopedDevice(dev):
        res, records = ctx.graph.execute(requested, dev)
    total = 1e3 * (time.perf_counter() - t0)
    channels = res["channels"]
    import dataclasses

    stats = {
        "technique": tech.name,
        "params": dataclasses.asdict(tech.params),
        "device": dev,
        "threads": cpu_threads() if dev == "cpu" else None,
        "scene": {
            "path": scene.path,
            "triangles": scene.triangle_count,
            "time": scene.time,
            "up_axis": scene.up_axis,
            "meters_per_unit": scene.meters_per_unit,
        },
        "width": width,
        "height": height,
        "pixel_samples": pixel_samples,
        "camera": ctx.camera.path,
        "lights": [l.path for l in lights],
        "light": lights[0].path,
        "timings_ms": {**{r["name"]: round(r["ms"], 3) for r in records}, "total": round(total, 3)},
        "cpu_ms": {r["name"]: round(r["cpu_ms"], 3) for r in records},
        "memory_bytes": buffer_bytes({k: v for k, v in res.items() if k != "channels"}),
        "counters": {**ctx.counters, "triangles": scene.triangle_count, "pixels": width * height, "gbuffer_samples": width * height * pixel_samples},
        "passes": [r["name"] for r in records],
        "warnings": list(scene.warnings),
    }
    return Frame(channels=channels, stats=stats)


def plan(scene: Scene, techniques: list[str] | None = None, *, width: int = 640, height: int = 480, light=None) -> dict:
    """What would run: shadow-casting lights, skipped lights, cutout materials, passes per technique."""
    from wsoft.techniques import TECHNIQUES, create

    out = {
        "scene": scene.path,
        "triangles": scene.triangle_count,
        "up_axis": scene.up_axis,
        "meters_per_unit": scene.meters_per_unit,
        "lights": [{"path": l.path, "kind": l.kind_name, "size": l.size_description()} for l in scene.lights],
        "skipped_lights": [{"path": l.path, "kind": l.kind_name, "reason": "shadow:enable = false"} for l in scene.unshadowed_lights]
        + [{"path": s.path, "kind": s.kind, "reason": s.reason} for s in scene.skipped_lights],
        "cutout_materials": [{"path": p, "triangles": n} for p, n in scene.cutout_triangle_counts().items()],
        "dynamic_prims": scene.dynamic_prims(),
        "baked_light_triangles": 0 if scene.tri_baked is None else int(np.count_nonzero(~np.isnan(scene.tri_baked[:, 0, 0]))),
        "cameras": [c.path for c in scene.cameras],
        "warnings": list(scene.warnings),
        "techniques": {},
    }
    if not scene.lights:
        return out
    for name in techniques or sorted(TECHNIQUES):
        tech = create(name, {})
        ctx, requested, _ = build_graph(scene, tech, width=width, height=height, light=light, device="cpu")
        out["techniques"][name] = [p.name for p in ctx.graph.schedule(requested)]
    return out
