"""Rendered frames: :class:`Frame` (per-pixel channels and the stats, the JSON contract) and
:class:`FrameSet` (several techniques of one graph), and how a graph's run becomes them
(:func:`frames_of`: per technique the passes it needed, their times, memory and counters, what
it shared, its warnings; a non-finite value is counted and warned, never hidden)."""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from wsoft.errors import NonFiniteWarning
from wsoft.graph import Resources
from wsoft.io import nonfinite_counts
from wsoft.parallel import cpu_threads
from wsoft.pipeline.build import Built


@dataclass
class Frame:
    """A rendered frame: ``channels`` (name -> float32 [H, W]) and ``stats`` (the JSON contract)."""

    channels: dict[str, np.ndarray]
    stats: dict[str, Any]
    exr_names: dict[str, str] = dataclasses.field(default_factory=dict)
    """Channels written to the EXR under another name: ``V`` (and ``V_stderr``) under the name of
    the output product's visibility RenderVar (:mod:`wsoft.scene.render_settings`)."""
    error_maps: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    """Per-pixel error maps a comparison measured (``flip``: ꟻLIP against the reference, float32
    [H, W] in [0, 1]); not written to the EXR."""

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
        """The shaded image (``R G B``, sRGB, 8 bits) as PNG; ``V`` when there is no colour."""
        from wsoft.io import write_png

        write_png(path, self.channels)

    def write_v_png(self, path: str) -> None:
        """``V`` as a 16-bit linear grey PNG (0 -> 0, 1 -> 65535), the visibility itself rather than
        the shaded image (``wsoft render --out x.png``)."""
        from wsoft.io import write_gray_png

        write_gray_png(path, self.V, bits=16)


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


def frame_ms(total_ms: float, records: list[dict], closure: set[str], single: bool) -> float:
    """A technique's frame time: alone in its graph, the wall time of the render less the passes it
    does not need (a metric pass, a ground truth handed in); beside others, the sum of the passes
    it needs, shared ones included."""
    if single:
        return total_ms - sum(r["ms"] for r in records if r["name"] not in closure)
    return sum(r["ms"] for r in records if r["name"] in closure)


def camera_model(ctx) -> dict:
    """The camera the G-buffer cast its rays with, in world space (``to_world`` 4x4, ``tan_half``,
    ``offset``, ``orthographic``), the full image's size and the data window's pixels (``crop``):
    what :class:`wsoft.metrics.temporal.FrameCamera` projects world points with."""
    cam = ctx.camera
    m = np.array(cam.to_world, np.float64)
    if ctx.origin is not None:  # the render worked in a frame centred near the camera: back to world space
        m[:3, 3] += np.asarray(ctx.origin, np.float64)
    crop = ctx.framing.crop if ctx.framing is not None else None
    return {"to_world": m.tolist(), "tan_half": [float(x) for x in cam.tan_half], "offset": [float(x) for x in cam.offset],
            "orthographic": bool(cam.orthographic), "width": int(ctx.width), "height": int(ctx.height),
            "crop": list(crop) if crop is not None else None}


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
                  "skinned_meshes": scene.skinned,
                  "meters_per_unit": scene.meters_per_unit, "instancing": built.instancing},
        "width": ctx.framing.out_size[0] if ctx.framing is not None else ctx.width,  # the written image (the data window)
        "height": ctx.framing.out_size[1] if ctx.framing is not None else ctx.height,
        "pixel_samples": ctx.pixel_samples,
        "camera": ctx.camera.path,
        "camera_model": camera_model(ctx),
        "framing": ctx.framing.describe() if ctx.framing is not None else None,
        "warnings": list(scene.warnings),
        "notes": list(scene.notes),
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
        if scene.skinned:  # UsdSkel's posing ran at load, before the graph: reported apart from the passes' total
            timings["skin"] = scene.skin_ms
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
