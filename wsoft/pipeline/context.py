"""The render context: the frame graph's shared providers (the scene on the device, the G-buffer,
light views and depth maps, the receiver's horizon). What one technique instance sees of them is a
:class:`~wsoft.pipeline.technique_context.TechniqueContext` (:meth:`RenderContext.technique`).

Providers register their own passes once, so techniques that need the same depth map share it.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import Any

import numpy as np
import warp as wp

from wsoft.errors import DeclarationError
from wsoft.graph import FrameGraph, Key, Pass
from wsoft.lightspace.cube import (
    CUBE_KINDS, FACE_NAMES, CubeDecision, CubeFace, cube_decision, cube_frame, fit_cube_views, outside_view_remedy, select_cube_face, vec6i,
)
from wsoft.lightspace.light import disk_shaped, light_gpu, reached_receivers
from wsoft.lightspace.fit import fit_light_view, near_caster_warning
from wsoft.lightspace.stable import fit_stable_view
from wsoft.lightspace.view import far_light, outside_view_warning
from wsoft.params import VIEWS
from wsoft.pipeline.framing import Framing
from wsoft.pipeline.technique_context import TechniqueContext, Visibility
from wsoft.raster.camera import camera_gpu
from wsoft.raster.gbuffer import GBuffer, render_gbuffer
from wsoft.raster.horizon import clip_to_front, front_counts, front_fraction
from wsoft.raster.depth_map import rasterize
from wsoft.scene.device import upload_scene
from wsoft.scene.types import LIGHT_DISTANT, LIGHT_DOME, Camera, Light, Scene


SCENE = Key("scene")
GBUFFER = Key("gbuffer")
GBUFFER_CHANNELS = Key("gbuffer_channels")


FAR_DEPTH_LIMIT = 1e-4
"""The coarsest float32 depth spacing at a far local light's far plane, as a fraction of the frame's
extent, that its shadow maps take without a warning (the default depth biases are 1e-4 of the
extent: past it they cannot separate a caster from its receiver)."""


def _bounds_of(points: np.ndarray):
    """(lo, hi) of world points [N, 3] (None, None for none)."""
    if len(points) == 0:
        return None, None
    return points.min(axis=0).astype(np.float64), points.max(axis=0).astype(np.float64)


class RenderContext:
    """What techniques build their passes with; providers register the shared passes once."""

    def __init__(self, scene: Scene, camera: Camera, width: int, height: int, device: str, pixel_samples: int = 1,
                 framing: Framing | None = None, origin: np.ndarray | None = None, origin_warning: str = "", history=None):
        self.scene = scene
        self.history = history  # a sequence's wsoft.pipeline.history.History (None: a single frame)
        self.origin = origin  # world position of the frame's origin (None: world space; see wsoft.pipeline.framing.local_origin)
        self.origin_warning = origin_warning
        self.camera = camera
        self.width = width
        self.height = height
        self.device = device
        self.pixel_samples = pixel_samples
        self.framing = framing  # where the camera, size and data window came from (None: given directly)
        self.graph = FrameGraph()
        self.counters: dict[str, Any] = {"frame": {}, "passes": {}, "techniques": {}}
        self._labels = {l.path: scene.light_label(l) for l in scene.lights}
        self._cube: dict[str, CubeDecision] = {}  # light path -> whether its views form a cube map (cube_decision)
        self._probe: tuple[np.ndarray, str] | None = None
        self.warnings: dict[str, list[str]] = {}  # pass name -> warnings it raised (a frame lists those of its passes)
        self.fit_receivers: dict[str, np.ndarray] | None = history.fit_receivers if history is not None else None
        """Light path -> world points [N, 3] that a ``view=sequence`` light view
        (:func:`~wsoft.lightspace.stable.fit_stable_view`) is fitted to besides the frame's
        receivers: the sequence renderer's :class:`~wsoft.pipeline.history.History` gives the
        receivers of all its frames, so the view is fitted once per sequence. None (a single
        frame, or a light absent from it): the view is the frame's stable view."""

    def warn(self, pass_name: str, message: str) -> None:
        """A problem found while running a pass (receivers left unmapped, non-finite values): it
        goes into the stats' ``warnings`` of every frame that needs the pass, and the CLI prints it."""
        self.warnings.setdefault(pass_name, []).append(message)

    # -- naming ------------------------------------------------------------------------------------
    def label(self, light: Light) -> str:
        """The light's label in keys, pass names and channels; a cube map's face adds its name (``Lamp/+x``)."""
        base = self._labels.get(light.path, light.name)
        return f"{base}/{light.face_name}" if isinstance(light, CubeFace) else base

    # -- cube maps -----------------------------------------------------------------------------------
    PROBE_WIDTH = 128  # pixels across the low-resolution G-buffer that decides which lights get a cube map

    def probe_receivers(self) -> tuple[np.ndarray, str]:
        """The receivers of a low-resolution G-buffer (:data:`PROBE_WIDTH` pixels across, the frame's
        camera, one sample per pixel) as world points [N, 3], and its size (``"128x96"``): what
        decides, while the graph is built, which lights get a cube map and which faces it draws.
        Timed in the frame's counters (``cube_probe_ms``)."""
        if self._probe is None:
            t0 = time.perf_counter()
            ds, _ = self.scene.device_copy(self.device, upload_scene)
            pw = min(self.width, self.PROBE_WIDTH)
            ph = max(1, round(self.height * pw / max(self.width, 1)))
            gb = render_gbuffer(ds, camera_gpu(self.camera), pw, ph, 1, self.scene.has_cutouts)
            prim = gb.prim.numpy()
            self._probe = (gb.pos.numpy()[prim >= 0].astype(np.float64), f"{pw}x{ph}")
            self.counters["frame"]["cube_probe_ms"] = 1e3 * (time.perf_counter() - t0)
        return self._probe

    def cube_decision(self, light: Light) -> CubeDecision:
        """Whether ``light``'s views form a cube map and which faces hold receivers
        (:func:`~wsoft.lightspace.cube.cube_decision`, from :meth:`probe_receivers`), decided once per frame."""
        d = self._cube.get(light.path)
        if d is None:
            if light.kind in CUBE_KINDS:
                rec, probe = self.probe_receivers()
                d = cube_decision(light, rec, probe)
            else:
                d = CubeDecision(light.path, False, 0.0, (), "")
            self._cube[light.path] = d
        return d

    def cube_faces(self, light: Light, mode: str | None) -> list[CubeFace] | None:
        """The faces a technique with ``cube=mode`` (None: a technique without light views) draws of
        ``light``, or None: one view."""
        if mode is None or light.kind not in CUBE_KINDS or isinstance(light, CubeFace):
            return None
        d = self.cube_decision(light)
        if not d.cube(mode):
            return None
        return [CubeFace.of(light, k) for k in d.faces]

    def _cube_view(self, face: CubeFace, size: int, soft: bool, guard: float) -> Key:
        """Resource: the view of one face of ``face``'s light's cube map; one pass fits the views of
        every face it draws (:func:`~wsoft.lightspace.cube.fit_cube_views`), the same window for all."""
        gk = self.gbuffer()
        faces = self.cube_decision(face).faces
        base = self._labels.get(face.path, face.name)
        variant = f"@{size}" + ("+soft" if soft else "") + f"+guard{guard:g}"
        keys = {k: Key("light_view", f"{base}/{FACE_NAMES[k]}", variant=variant) for k in faces}
        name = f"fit_cube[{base}]{variant}"

        def run(res):
            gb: GBuffer = res[gk]
            prim = gb.prim.numpy()
            rec = reached_receivers(face, gb.pos.numpy()[prim >= 0])
            views, facts = fit_cube_views(face, rec, faces, size, guard, casters=self.scene.caster_points if soft else None)
            c = self.pass_counters(name)
            c.update(cube_faces=[FACE_NAMES[k] for k in faces], receivers_per_face=facts["receivers"], guard=facts["guard"],
                     texels=len(faces) * size * size)
            if facts["guard_capped"]:
                c["guard_capped"] = True
            return {keys[k]: views[k] for k in faces}

        self.add(Pass(name, (gk,), tuple(keys.values()), run, kind="light_map", light=base))
        return keys[face.face]

    def light_gpu(self, light: Light):
        return light_gpu(light, self.scene.diagonal, self.device)

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

        name = "gbuffer_alpha" if alpha else "gbuffer"

        def run(res):
            if self.origin is not None:
                self.counters["frame"]["local_origin"] = [float(x) for x in self.origin]
            if self.origin_warning:
                self.warn(name, self.origin_warning)
            return {GBUFFER: render_gbuffer(res[sk], cam, self.width, self.height, self.pixel_samples, alpha)}

        return self.add(Pass(name, (sk,), (GBUFFER,), run, kind="gbuffer"))

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
            if self.origin is not None:  # back to world space, on covered pixels only
                pos = np.where(hit.any(axis=0)[..., None], pos.astype(np.float64) + self.origin, 0.0)
            for i, axis in enumerate("XYZ"):  # the G-buffer writes zeros on background samples
                ch[f"P.{axis}"] = np.ascontiguousarray(pos[..., i], dtype=np.float32)
                ch[f"N.{axis}"] = np.ascontiguousarray(nrm[..., i], dtype=np.float32)
            ch["Z"] = dist.astype(np.float32)
            ch["A"] = (nhit / gb.spp).astype(np.float32)
            return {GBUFFER_CHANNELS: {"channels": ch, "hit": hit, "nhit": nhit, "spp": gb.spp, "shape": (gb.height, gb.width)}}

        return self.add(Pass("gbuffer_channels", (gk,), (GBUFFER_CHANNELS,), run, kind="resolve"))

    def light_view(self, light: Light, size: int, soft: bool = False, view: str = "fitted", guard: float = 2.0) -> Key:
        """Resource: a :class:`LightView` of ``light`` fitted to the receivers in view.

        A :class:`~wsoft.lightspace.cube.CubeFace` gets its face of the light's cube map, with a guard
        band of at least ``guard`` texels (:meth:`_cube_view`; its window is fixed by the light's frame,
        so ``stable`` and ``sequence`` give the same view).

        ``soft``: widened so that casters blocking any part of the whole light are mapped.
        ``view``: ``fitted`` (:func:`fit_light_view`), ``stable`` (:func:`fit_stable_view`: its
        texel grid anchored at the world origin; its pass's counters record ``view``, ``radius``,
        ``texel``, ``snap_offset``) or ``sequence`` (the stable view fitted also to
        :attr:`fit_receivers`, the receivers of every frame of the sequence: one view for all its
        frames); each is its own resource, shared by the techniques that ask for the same."""
        if isinstance(light, CubeFace):
            _stable(view)
            return self._cube_view(light, size, soft, guard)
        gk = self.gbuffer()
        stable = _stable(view)
        whole_sequence = view == "sequence"
        key = Key("light_view", self.label(light), variant=_view_variant(size, soft, view))
        name = f"fit_{key}"

        probe = soft and light.kind != LIGHT_DISTANT and light.extent() > 0.0
        sk = self.scene_arrays() if probe else None

        def run(res):
            gb: GBuffer = res[gk]
            prim = gb.prim.numpy()
            rec = reached_receivers(light, gb.pos.numpy()[prim >= 0])
            lo, hi = self.scene.bounds
            distant = light.kind == LIGHT_DISTANT  # its depth range starts at the nearest caster over the receivers
            region = self._fit_region(light) if whole_sequence else None
            extra = {"anchor": self._world_origin(), "region": region, "down": self._down()} if stable else {}
            fit = functools.partial(fit_stable_view if stable else fit_light_view, light, rec, lo, hi, size,
                                    casters=self.scene.caster_points if soft or distant else None, all_casters=lambda: self.scene.caster_points,
                                    caster_triangles=self.scene.caster_mesh if distant else None,
                                    **extra)
            view = fit()
            if probe:
                view = self._grown_for_casters(res[sk], light, view, fit, name)
            self.pass_counters(name)["receivers_outside"] = view.receivers_outside
            if view.snap is not None:
                self.pass_counters(name).update(view="stable", **view.snap)
            if light.one_sided:
                self.pass_counters(name)["receivers_behind_light"] = view.receivers_behind
            if view.persp and far_light(light, *_bounds_of(rec)):
                spacing = float(np.spacing(np.float32(view.far)))
                if spacing > FAR_DEPTH_LIMIT * view.extent:
                    self.warn(name, f"light {light.path} is {view.far:.3g} from the receivers: float32 depths there are {spacing:.3g} apart, "
                              f"{spacing / view.extent:.2g} of the frame's extent (more than {FAR_DEPTH_LIMIT:g}): its shadow-map depths "
                              "and biases lose precision (shadows may thin or vanish); a DistantLight models a light this far")
            if soft and view.persp and view.nearest_caster < light.extent():
                self.warn(name, near_caster_warning(light, view.nearest_caster))
            if view.receivers_outside:
                from wsoft.techniques import unmapped_techniques

                self.warn(name, outside_view_warning(light, f"{view.receivers_outside} of {len(rec)} visible samples",
                                                     outside_view_remedy(light, self.cube_decision(light), unmapped_techniques())))
            return {key: view}

        return self.add(Pass(name, (gk,) if sk is None else (gk, sk), (key,), run, kind="light_map", light=self.label(light)))

    def _world_origin(self) -> np.ndarray:
        """The world origin in the frame's coordinates (a frame far from it works about :attr:`origin`)."""
        return np.zeros(3) if self.origin is None else -np.asarray(self.origin, np.float64)

    def _down(self) -> np.ndarray:
        """The stage's downward direction (minus its up axis)."""
        return -np.eye(3)[2 if self.scene.up_axis == "Z" else 1]

    def _fit_region(self, light: Light) -> np.ndarray | None:
        """The points :attr:`fit_receivers` gives for ``light``, in the frame's coordinates (None: none)."""
        pts = None if self.fit_receivers is None else self.fit_receivers.get(light.path)
        if pts is None:
            return None
        pts = np.asarray(pts, np.float64).reshape(-1, 3)
        return pts if self.origin is None else pts - np.asarray(self.origin, np.float64)

    PROBE_SIZE = 64  # texels per side of the coarse map that finds casters a soft view's window must grow for

    def _grown_for_casters(self, ds, light: Light, view, fit, name: str):
        """A soft view of a local light grown until its window holds every caster that can block
        part of the light from a receiver, the interiors of triangles whose vertices lie far
        outside included (a ceiling just below a lamp, which :func:`fit_light_view`'s vertex test
        misses): a coarse conservative depth map (:data:`PROBE_SIZE` texels a side) of the window
        widened by its own size on every side (within ±80°) finds, per side, the casters beyond that
        edge that can block part of the light from the farthest receiver (a caster at depth z
        within w (1/z - 1/z_far) of the edge); a side grows for them (``fit(side_growth=...)``) when
        they ask for more than two coarse texels beyond the growth the vertices gave, until no side
        does (at most four times). ``grown_for_casters`` in the pass's counters: how many times."""
        from wsoft.lightspace.view import MAX_TAN

        casting = self.scene.casting_triangles(light)
        w = light.extent()
        grown = 0
        need = np.zeros(4)
        n = self.PROBE_SIZE
        for _ in range(4):
            l, r, b, t = view.window
            pl, pr = max(l - (r - l), -MAX_TAN), min(r + (r - l), MAX_TAN)
            pb, pt = max(b - (t - b), -MAX_TAN), min(t + (t - b), MAX_TAN)
            coarse = dataclasses.replace(view, width=n, height=n, window=(pl, pr, pb, pt))
            d = rasterize(ds, coarse, alpha_tested=False, conservative=True, triangles=casting).depth.numpy()
            tx, ty = (pr - pl) / n, (pt - pb) / n
            x0 = pl + tx * np.arange(n)  # texel edges (rows from the bottom)
            y0 = pb + ty * np.arange(n)
            z = np.where((d > 0.0) & (d < view.far), d, np.inf)
            reach = w * (1.0 / z - 1.0 / view.far)  # how far from it a caster at depth z blocks part of the light
            gx, gy = np.meshgrid(x0, y0)
            beyond = (l - (gx + tx), gx - r, b - (gy + ty), gy - t)  # distance of the texel's near side past each edge
            inside_y = (gy + ty >= b) & (gy <= t)
            inside_x = (gx + tx >= l) & (gx <= r)
            more = False
            for k, (dist, across) in enumerate(zip(beyond, (inside_y, inside_y, inside_x, inside_x))):
                hit = (dist > 0.0) & across & (reach >= dist)
                g = float(reach[hit].max()) if hit.any() else 0.0
                if g > max(view.growth, need[k]) + 2.0 * max(tx, ty):
                    need[k], more = g, True
            if not more:
                break
            wider = fit(side_growth=tuple(float(x) for x in need))
            if wider.window == view.window:
                break
            view, grown = wider, grown + 1
        if grown:
            self.pass_counters(name)["grown_for_casters"] = grown
        return view

    def light_depth(self, light: Light, size: int, conservative: bool = False, soft: bool = False, inner: bool = False,
                    opaque: bool = False, faces: str = "all", view: str = "fitted", guard: float = 2.0, read: int | None = None) -> Key:
        """Resource: a :class:`~wsoft.raster.depth_map.DepthMap` of the :meth:`light_view` ``view``
        (``fitted`` or ``stable``) of ``light`` (alpha-tested only if the scene has
        cutouts); ``inner``: the map of depths that certainly block a whole texel (inner coverage);
        ``opaque``: cutouts not alpha-tested (each covers every texel it touches: with
        ``conservative``, a map no occluder escapes); ``faces``: ``all``, or only ``back`` faces of
        closed surfaces or ``open`` surfaces (:func:`~wsoft.scene.device.face_surfaces`). Only the
        triangles that cast ``light``'s shadow are drawn (its ``collection:shadowLink``,
        :meth:`Scene.casting_triangles`); the key is the light's own, so lights with different links
        never share a map. ``read`` (an int r, not with ``conservative``, ``inner``, ``opaque`` or a
        face subset): only the texels the G-buffer's samples read and those within r texels of them
        are drawn, one ray each (:func:`~wsoft.raster.raycast.raycast_read`), the others left
        ``DEPTH_CLEAR``; counters ``drawn_by`` (``rays``), ``texels_read`` and ``read_radius``."""
        if read is not None and (conservative or inner or opaque or faces != "all"):
            raise DeclarationError("a depth map of the texels receivers read is drawn at texel centres, alpha-tested, every face: "
                                   "not conservative, inner, opaque or of some faces")
        sk = self.scene_arrays()
        casting = self.scene.casting_triangles(light)  # None: every triangle (no list, no extra work)
        vk = self.light_view(light, size, soft, view, guard)
        alpha = self.scene.has_cutouts and not opaque
        flavour = (("_alpha" if alpha else "") + ("_inner" if inner else "_conservative" if conservative else "")
                   + ("" if faces == "all" else f"_{faces}"))
        variant = vk.variant if isinstance(light, CubeFace) else _view_variant(size, soft, view)
        if read is not None:
            flavour += f"_read{int(read)}"
            return self._read_depth(light, Key("light_depth", self.label(light), variant=variant, flavour=flavour), sk, vk, alpha, int(read))
        key = Key("light_depth", self.label(light), variant=variant, flavour=flavour)
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

    def _read_depth(self, light: Light, key: Key, sk: Key, vk: Key, alpha: bool, radius: int) -> Key:
        """:meth:`light_depth` with ``read``: the map at the texels the G-buffer's samples read (within ``radius``)."""
        from wsoft.raster.raycast import raycast_read

        gk = self.gbuffer()
        name = str(key)

        def run(res):
            dm = raycast_read(res[sk], res[vk], res[gk], alpha, light.shadow_excluded, radius)
            c = self.pass_counters(name)
            c.update(drawn_by="rays", texels_read=dm.texels_read, read_radius=radius)
            return {key: dm}

        return self.add(Pass(name, (sk, vk, gk), (key,), run, kind="light_map", light=self.label(light)))

    def paraboloid_depth(self, light: Light, size: int, guard: float) -> Key:
        """Resource: a :class:`~wsoft.lightspace.paraboloid.ParaboloidMap` of ``light``, the
        alternative to its cube map (``omni=paraboloid``): the hemispheres that own a receiver of the
        G-buffer, ``size`` texels a side, a guard band of ``guard`` texels past the equator, drawn by
        one ray per texel (:func:`~wsoft.raster.paraboloid.draw_paraboloid`) through the triangles
        that cast ``light``'s shadow (alpha-tested if the scene has cutouts). Counters: the
        hemispheres drawn, receivers per hemisphere, the guard band, texels and rays."""
        from wsoft.lightspace.paraboloid import fit_paraboloid_view
        from wsoft.raster.paraboloid import draw_paraboloid

        sk, gk = self.scene_arrays(), self.gbuffer()
        casting = self.scene.casting_triangles(light)
        alpha = self.scene.has_cutouts
        key = Key("light_depth", self.label(light), variant=f"@{size}+paraboloid+guard{guard:g}", flavour="_alpha" if alpha else "")
        name = f"paraboloid[{self.label(light)}]@{size}+guard{guard:g}"

        def run(res):
            gb: GBuffer = res[gk]
            prim = gb.prim.numpy()
            view = fit_paraboloid_view(light, reached_receivers(light, gb.pos.numpy()[prim >= 0]), size, guard, self.scene.diagonal)
            dm = draw_paraboloid(res[sk], view, alpha, casting)
            c = self.pass_counters(name)
            c.update(hemispheres=[("+z", "-z")[h] for h in view.drawn], receivers_per_hemisphere=view.receivers,
                     guard_texels=float(guard), window_radius=view.radius, texels=view.texels, rays=dm.rays)
            if casting is not None:
                c["casting_triangles"] = int(len(casting))
            return {key: dm}

        return self.add(Pass(name, (sk, gk), (key,), run, kind="light_map", light=self.label(light)))

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
        if light.kind == LIGHT_DOME:  # a dome's V is already over the receiver's hemisphere (wsoft.scene.dome)
            return vis_key
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

    def select_cube_faces(self, tctx: "TechniqueContext", light: Light, faces: list[CubeFace], vis_keys: list[Key]) -> Key:
        """Resource: a technique's visibility of ``light`` from its cube map: each G-buffer sample's
        from the face its direction from the light's centre belongs to (:func:`select_cube_face`).
        The technique's counters for the light: ``cube_faces`` (the faces drawn), ``cube_texels``
        (texels of the face views its passes read). A sample at the light's centre (no direction)
        gets V = 1 and a warning; so does one whose face the probe found empty."""
        gk = self.gbuffer()
        out = tctx.visibility_key(light)
        name = tctx.pass_name(f"{tctx.tech.name}_cube_select", light)
        views = list(dict.fromkeys(tctx.face_views.get(light.path, [])))
        frame = cube_frame(light)
        slots = [-1] * 6
        for s, f in enumerate(faces):
            slots[f.face] = s

        def run(res):
            gb: GBuffer = res[gk]
            dev = self.device
            vis = wp.empty(gb.count, dtype=float, device=dev)
            face_of = wp.empty(gb.count, dtype=wp.int32, device=dev)
            dummy = wp.ones(1, dtype=float, device=dev)
            arrays = [res[vis_keys[slots[k]]].vis if slots[k] >= 0 else dummy for k in range(6)]
            ext = self.scene.diagonal
            from wsoft.parallel import launch_chunked

            launch_chunked(select_cube_face, gb.count,
                           inputs=[gb.pos, gb.prim, wp.vec3(*np.asarray(light.position, np.float64)), wp.mat33(*frame.T.ravel()),
                                   vec6i(*slots), *arrays, float(1e-7 * ext)],
                           outputs=[vis, face_of], device=dev)
            self.report_cube_faces(tctx, light, faces, face_of, int(sum(res[k].width * res[k].height for k in views)), name)
            return {out: tctx.visibility(vis)}

        return tctx.ctx.add(Pass(name, (gk, *vis_keys, *views), (out,), run, kind="technique", stage="cube_select",
                                 technique=tctx.label_, light=self.label(light)))

    def report_cube_faces(self, tctx: "TechniqueContext", light: Light, faces: list[CubeFace], face_of: wp.array, texels: int,
                          name: str) -> None:
        """A technique's counters for ``light``'s cube map (``cube_faces``, ``cube_texels``: the
        texels of the face views its passes read) and the warnings of pass ``name`` for the samples
        ``face_of`` (:func:`select_cube_face`'s codes) left lit: at the light's centre, in a face
        not drawn."""
        fo = face_of.numpy()
        total = int(np.count_nonzero(fo != 6))
        c = tctx.counters(light)
        c["cube_faces"] = [f.face_name for f in faces]
        c["cube_texels"] = int(texels)
        at_light, undrawn = int(np.count_nonzero(fo == -1)), int(np.count_nonzero(fo == -2))
        if at_light:
            self.warn(name, f"light {light.path}: {at_light} of {total} visible samples lie at its centre (no direction to it): "
                            "V = 1 there")
        if undrawn:
            self.warn(name, f"light {light.path}: {undrawn} of {total} visible samples lie in cube-map faces the "
                            f"{self.cube_decision(light).probe} probe found no receiver in, which were not drawn: they are "
                            "left unshadowed")

    def provide(self, key: Key, value: Any, *, name: str | None = None, kind: str = "reference") -> Key:
        """A resource computed outside the graph (a cached reference image): a pass that hands it over."""
        return self.add(Pass(name or str(key), (), (key,), lambda res: {key: value}, kind=kind))

    def technique(self, tech, label: str) -> "TechniqueContext":
        return TechniqueContext(self, tech, label)


def _stable(view: str) -> bool:
    """Is ``view`` (a :data:`~wsoft.params.VIEWS` value) a stable one (``stable`` or ``sequence``)?"""
    if view not in VIEWS:
        raise DeclarationError(f"light view {view!r} is not one of {', '.join(VIEWS)}")
    return view != "fitted"


def _view_variant(size: int, soft: bool, view: str) -> str:
    """The variant of a light view's (and its depth maps') key: map size, ``+soft``, ``+stable`` or ``+sequence``."""
    return f"@{size}" + ("+soft" if soft else "") + (f"+{view}" if view != "fitted" else "")


def light_behind_warning(light: Light, n: int, total: int) -> str:
    """The warning for the ``n`` of ``total`` receivers behind a rect or disk light's plane."""
    d = ", ".join(f"{c:.3g}" for c in np.round(np.asarray(light.direction, np.float64), 6) + 0.0)
    return (f"light {light.path}: {n} of {total} visible samples lie behind its emitting plane (a {light.kind_name} light emits "
            f"from its front only, toward ({d})) and get none of its light (V = 0)")
