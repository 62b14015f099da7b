"""Sequences: a stage rendered at a run of time codes, one frame each, and what is shared between them.

:func:`render_sequence` renders one or several techniques at every time code of ``frames``
(``"A:B"``, ``"A:B:STEP"``, ``"A"`` or a list, within the stage's time range, :func:`stage_time_codes`):
each frame is the stage at that time code (animated cameras, lights, transforms, points,
visibility). The stage is opened once; each frame is read from it at its time code, or, when only
cameras, lights and render settings are animated (:func:`wsoft.scene.usd.static_geometry`), the
first frame's geometry is kept and only those are read again. The scene's
device copy (triangles, cutouts, the BVH, and what the techniques cache on it) is kept from one
frame to the next while the geometry is the same (a moving camera or light; compared by content);
where only points moved (the same triangles, a walking character) the copy's points are updated
and its BVH refitted (:func:`wsoft.scene.device.refit_scene`); anything else (triangles appearing,
instances moving) builds it again. Each frame's stats say which (``sequence.scene``: ``reused``,
``refit`` or ``built``) and what loading, refitting and uploading cost. Compiled kernels are shared
by the process.

Each frame's render gets the sequence's :class:`~wsoft.pipeline.history.History`: the per-pixel
stochastic techniques (the reference, rtdenoise) draw other light samples in each frame (seed +
the frame's index) unless ``reseed=False``, as an engine does, so that their noise changes from
frame to frame as it would on screen (the crawl :func:`wsoft.metrics.temporal.temporal_std`
measures); time-aware techniques (rtdenoise's temporal accumulation) read what they kept from the
previous frame. The object-based techniques' sample sets are the papers' fixed patterns, the same
in every frame.

:func:`wsoft.metrics.sequences.compare_sequence` adds a ground truth per frame and the temporal
measures of :mod:`wsoft.metrics.temporal` over the frames.

Frames are written as render delegates write a sequence: ``name.0012.exr`` (:func:`frame_path`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import time as _time
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from wsoft.errors import ParameterError
from wsoft.params import parse_frames
from wsoft.pipeline.history import History
from wsoft.scene.types import Scene


def stage_time_codes(stage, frames, file: str) -> list[float]:
    """The time codes of ``frames`` (``"a:b"``, ``"a:b:step"``, ``"a"``, a number or a list of
    numbers) on ``stage``: finite, and within its time range
    (:func:`wsoft.scene.usd_time.time_range`: its ``startTimeCode``–``endTimeCode``, else the span
    of its time samples and spline knots); a :class:`ParameterError` naming the file otherwise, and
    for a stage with no time range at all (nothing authored over time: every frame the same)."""
    from wsoft.scene.usd_time import time_range

    if isinstance(frames, str):
        try:
            times = parse_frames(frames)
        except ValueError as exc:
            raise ParameterError(f"--frames {exc}", file=file) from None
    else:
        try:
            times = [float(t) for t in (frames if hasattr(frames, "__iter__") else [frames])]
        except (TypeError, ValueError):
            raise ParameterError(f"frames {frames!r}: need one or more finite time codes", file=file) from None
        if not times or not all(math.isfinite(t) for t in times):
            raise ParameterError(f"frames {frames!r}: need one or more finite time codes", file=file)
    span = f"{min(times):g}..{max(times):g}" if len(times) > 1 else f"{times[0]:g}"
    rng = time_range(stage)
    if rng is None:
        raise ParameterError(f"frames {span}: the stage has no time range (no startTimeCode / endTimeCode, no time sample, "
                             "spline or value clip): every frame would be the same stage; render it once (--time, or time=), "
                             "or author startTimeCode and endTimeCode", file=file)
    out = [t for t in times if not rng.start - 1e-9 <= t <= rng.end + 1e-9]
    if out:
        raise ParameterError(f"frames {span} lie outside the stage's time range {rng.describe()}", file=file)
    return times


def stage_is_animated(stage) -> bool:
    """Does any value on the stage vary over time (:func:`wsoft.scene.usd_time.stage_animation`:
    time samples, splines, value clips, points moved by velocity)?"""
    from wsoft.scene.usd_time import stage_animation

    return stage_animation(stage).animated


def frame_token(t: float) -> str:
    """A time code as render delegates number frames: ``0012`` for 12, ``12.5`` for 12.5, ``m3`` for −3."""
    return f"{int(t):04d}" if float(t).is_integer() and t >= 0 else f"{t:g}".replace("-", "m")


def frame_path(path: str, t: float) -> str:
    """``out/x.exr`` at time code 12 -> ``out/x.0012.exr`` (the frame number before the extension)."""
    root, ext = os.path.splitext(path)
    return f"{root}.{frame_token(t)}{ext}"


def geometry_digest(scene: Scene, points: bool = True) -> str:
    """A digest of everything a scene's device copy is built from (points, triangles and their
    per-triangle fields, materials, textures, instances): equal digests, equal device copies.
    ``points=False``: all of it but the points (equal: the same triangles, moved)."""
    h = hashlib.blake2b(digest_size=20)

    def add(x) -> None:
        if x is None:
            h.update(b"-")
        elif isinstance(x, np.ndarray):
            h.update(str((x.dtype, x.shape)).encode())
            h.update(np.ascontiguousarray(x).tobytes())
        elif dataclasses.is_dataclass(x):
            for f in dataclasses.fields(x):
                add(getattr(x, f.name))
        elif isinstance(x, (list, tuple)):
            h.update(f"[{len(x)}".encode())
            for y in x:
                add(y)
        elif isinstance(x, dict):
            for k in sorted(x, key=str):
                h.update(str(k).encode())
                add(x[k])
        else:
            h.update(repr(x).encode())

    for name in (("points",) if points else ()) + ("triangles", "tri_prim", "tri_material", "tri_uv", "tri_double_sided", "tri_closed", "tri_dynamic", "tri_baked",
                 "materials", "textures", "instances", "prims"):
        add(getattr(scene, name))
    return h.hexdigest()


@dataclass
class Sequence:
    """A rendered sequence: ``times`` (the time codes), ``frames`` (a :class:`~wsoft.pipeline.Frame`
    per time code, or a :class:`~wsoft.pipeline.FrameSet` for several techniques), ``stats`` per
    frame (time, load / upload / render ms, whether the scene's device copy was ``built`` or
    ``reused``), ``summary`` (totals, the techniques' temporal measures after
    :func:`wsoft.metrics.sequences.compare_sequence`) and ``warnings`` (the sequence's own, once)."""

    times: list[float]
    frames: list
    stats: list[dict] = field(default_factory=list)
    summary: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    render_settings: object = None  # the first frame's RenderSettings (wsoft.scene.render_settings), or None
    receivers_ms: float = 0.0  # the G-buffer pass over every frame for view=sequence light views (0: none)
    ground_truths: list = field(default_factory=list)  # compare_sequence: each frame's wsoft.metrics.GroundTruth

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, i: int):
        return self.frames[i]

    def __iter__(self) -> Iterator:
        return iter(self.frames)


class _Loader:
    """Reads a stage at time codes: the stage opened once, each frame's scene loaded from it, its
    device copy carried over from the previous frame while the geometry's digest is the same."""

    def __init__(self, scene, render_settings: str | None, instancing: str, subdiv_level: int | None = None,
                 material_purpose: str | None = None):
        from wsoft.scene.usd import diagnostic_lines, open_stage, stage_file
        from wsoft.pipeline.loading import load_stage  # noqa: F401  (imported before frames are timed)
        from pxr import Usd, UsdUtils

        self.render_settings = render_settings
        self.instancing = instancing
        self.subdiv_level = subdiv_level if subdiv_level is not None else scene.subdiv_level if isinstance(scene, Scene) else 0
        self.material_purpose = material_purpose or (scene.material_purpose if isinstance(scene, Scene) else "full")
        self.warnings: list[str] = []
        if isinstance(scene, Scene):
            source = scene.__dict__.get("_loaded_from", (scene.path, None))[0]
            if render_settings is None and scene.render_settings is not None:
                self.render_settings = scene.render_settings.path
        else:
            source = scene
        if isinstance(source, Usd.Stage):
            self.stage = source
        else:
            delegate = UsdUtils.CoalescingDiagnosticDelegate()
            self.stage = open_stage(os.fspath(source))
            self.warnings += diagnostic_lines(delegate.TakeUncoalescedDiagnostics(), os.fspath(source))
        self.file = stage_file(self.stage)
        self._prev: Scene | None = None
        self._digest: str | None = None
        self._shape: str | None = None
        self.static: bool | None = None  # the stage's geometry is not animated (wsoft.scene.usd.static_geometry)

    def load(self, t: float) -> tuple[Scene, dict]:
        from wsoft.pipeline.loading import load_stage
        from wsoft.scene.usd import static_geometry, with_views_at

        t0 = _time.perf_counter()
        if self.static is None:
            self.static = static_geometry(self.stage)
        if self.static and self._prev is not None and not self._prev.instanced:
            scene = with_views_at(self._prev, self.stage, t, self.render_settings)
            t1 = _time.perf_counter()
            self._prev = scene
            return scene, {"time": t, "load_ms": round(1e3 * (t1 - t0), 3), "digest_ms": 0.0, "refit_ms": 0.0, "scene": "reused",
                           "geometry": "static: lights and cameras read again"}
        scene = load_stage(self.stage, time=t, render_settings=self.render_settings, instancing=self.instancing, subdiv_level=self.subdiv_level,
                           material_purpose=self.material_purpose)
        t1 = _time.perf_counter()
        digest, shape = geometry_digest(scene), geometry_digest(scene, points=False)
        t2 = _time.perf_counter()
        cache = self._prev.__dict__.get("_device_cache") if self._prev is not None else None
        how = "built"
        if cache and digest == self._digest:
            scene.__dict__["_device_cache"] = cache
            how = "reused"
        elif cache and shape == self._shape and not scene.instanced:
            from wsoft.scene.device import refit_scene

            scene.__dict__["_device_cache"] = {dev: refit_scene(ds, scene) for dev, ds in cache.items()}
            self._prev.__dict__.pop("_device_cache", None)  # its copy holds this frame's points: built again if it renders
            how = "refit"
        t3 = _time.perf_counter()
        self._prev, self._digest, self._shape = scene, digest, shape
        return scene, {"time": t, "load_ms": round(1e3 * (t1 - t0), 3), "digest_ms": round(1e3 * (t2 - t1), 3),
                       "refit_ms": round(1e3 * (t3 - t2), 3) if how == "refit" else 0.0, "scene": how}


def frame_costs(fr) -> dict:
    """The frame's own times: the techniques' frame ms (one or several)."""
    if hasattr(fr, "frames"):
        return {label: f.stats["timings_ms"]["total"] for label, f in fr.items()}
    return {fr.stats["label"]: fr.stats["timings_ms"]["total"]}


def _frames_and_loader(scene, frames, render_settings, instancing, subdiv_level=None, material_purpose=None):
    loader = _Loader(scene, render_settings, instancing, subdiv_level, material_purpose)
    times = stage_time_codes(loader.stage, frames, loader.file)
    if len(times) > 1 and not stage_is_animated(loader.stage):
        loader.warnings.append(f"{loader.file}: nothing on the stage varies over time (no time sample, spline or value clip): its "
                               f"{len(times)} frames are the same stage; --time (time=) renders it once")
    return loader, times


def start_sequence(scene, frames, render_settings, instancing, techs: list, reseed: bool, subdiv_level: int | None = None,
                   material_purpose: str | None = None, **view):
    """A sequence's loader, its empty :class:`Sequence` and its :class:`History` (with the receivers
    of every frame when a technique asks for ``view=sequence``); ``view``: the render's size, camera,
    light, device and pixel samples; ``subdiv_level``: None, a :class:`Scene`'s own (else 0)."""
    loader, times = _frames_and_loader(scene, frames, render_settings, instancing, subdiv_level, material_purpose)
    seq = Sequence(times=times, frames=[], warnings=list(loader.warnings))
    history = History(reseed)
    if _wants_sequence_views(techs):
        t0 = _time.perf_counter()
        history.fit_receivers = sequence_receivers(loader, times, **view)
        seq.receivers_ms = round(1e3 * (_time.perf_counter() - t0), 3)
    return loader, seq, history


def note_upload(fr, info: dict) -> None:
    """The scene upload's cost in ``info`` (near 0 when the device copy was reused)."""
    info["upload_ms"] = round(float(fr.stats["timings_ms"].get("upload_scene", 0.0)), 3)


def render_sequence(scene, technique, *, frames, width: int | None = None, height: int | None = None, camera=None, light=None,
                    device: str | None = None, pixel_samples: int = 1, render_settings: str | None = None, instancing: str = "auto",
                    reseed: bool = True, progress=None, subdiv_level: int | None = None, material_purpose: str | None = None,
                    **params) -> Sequence:
    """Render ``technique`` (one, or a list as :func:`wsoft.render` takes it) on ``scene`` (a USD
    path or a bundled stage's name, an open ``Usd.Stage`` or a :class:`Scene`, whose source is read again at each time code)
    at every time code of ``frames`` (see :func:`stage_time_codes`); a :class:`Sequence`.

    ``progress``: called as ``progress(done, total, time_code)`` after each frame. The other
    arguments as :func:`wsoft.render` takes them; ``subdiv_level``: how many times subdivision
    surfaces are refined (:func:`~wsoft.scene.usd.load_scene`; None: a :class:`Scene`'s own, else
    0); ``material_purpose``: ``full`` or ``preview`` (None: a :class:`Scene`'s own, else ``full``). A stage with a time range and nothing varying over time renders the same stage at every time code and says so in ``warnings``."""
    from wsoft.pipeline import as_techniques, is_several, render

    techs = as_techniques(technique, params)
    several = is_several(technique)
    loader, seq, history = start_sequence(scene, frames, render_settings, instancing, techs, reseed, subdiv_level, material_purpose,
                                          width=width, height=height, camera=camera, light=light, device=device, pixel_samples=pixel_samples)
    for i, t in enumerate(seq.times):
        sc, info = loader.load(t)
        if i == 0:
            seq.render_settings = sc.render_settings
        t0 = _time.perf_counter()
        fr = render(sc, techs if several else techs[0], width=width, height=height, camera=camera, light=light, device=device,
                    pixel_samples=pixel_samples, frame_history=history)
        history.advance()
        info["render_ms"] = round(1e3 * (_time.perf_counter() - t0), 3)
        info["frame_ms"] = frame_costs(fr)
        note_upload(fr, info)
        stamp_frame(fr, info, i, len(seq.times))
        seq.frames.append(fr)
        seq.stats.append(info)
        if progress is not None:
            progress(i + 1, len(seq.times), t)
    seq.summary = cost_summary(seq)
    return seq


def stamp_frame(fr, info: dict, index: int, count: int) -> None:
    """Record the frame's place in its sequence in its stats (and in each technique's)."""
    mark = {**info, "index": index, "frames": count}
    if hasattr(fr, "frames"):
        fr.stats["sequence"] = mark
        for f in fr.values():
            f.stats["sequence"] = mark
    else:
        fr.stats["sequence"] = mark


def _wants_sequence_views(techs: list) -> bool:
    return any(getattr(t.params, "view", None) == "sequence" for t in techs)


def sequence_receivers(loader: "_Loader", times: list[float], *, width, height, camera, light, device, pixel_samples: int = 1) -> dict:
    """Light path -> the world points the camera sees in every frame of ``times`` (the covered
    G-buffer samples of each, a G-buffer-only pass per frame): what ``view=sequence`` light views
    are fitted to, one view for the whole sequence."""
    import warp as wp

    from wsoft.parallel import resolve_device
    from wsoft.pipeline import build_graph
    from wsoft.pipeline.context import GBUFFER

    dev = resolve_device(device)
    pts = []
    lights: list[str] = []
    for t in times:
        sc, _ = loader.load(t)
        built = build_graph(sc, "hard", width=width, height=height, camera=camera, light=light, device=dev, pixel_samples=pixel_samples,
                            strict=False)
        with wp.ScopedDevice(dev):
            res, _ = built.ctx.graph.execute([GBUFFER], dev)
        gb = res[GBUFFER]
        p = gb.pos.numpy()[gb.prim.numpy() >= 0].astype(np.float64)
        if built.ctx.origin is not None:
            p += np.asarray(built.ctx.origin, np.float64)
        pts.append(p)
        lights = [l.path for l in sc.lights]
    allp = np.concatenate(pts) if pts else np.zeros((0, 3))
    return {path: allp for path in lights}


def cost_summary(seq: Sequence) -> dict:
    st = seq.stats
    return {"frames": len(st), "time_codes": [seq.times[0], seq.times[-1]] if seq.times else [],
            "scene_built": sum(1 for s in st if s["scene"] == "built"), "scene_refit": sum(1 for s in st if s["scene"] == "refit"),
            "scene_reused": sum(1 for s in st if s["scene"] == "reused"), "refit_ms": round(sum(s["refit_ms"] for s in st), 3),
            "load_ms": round(sum(s["load_ms"] for s in st), 3), "upload_ms": round(sum(s.get("upload_ms", 0.0) for s in st), 3),
            "render_ms": round(sum(s["render_ms"] for s in st), 3), "receivers_ms": seq.receivers_ms}
