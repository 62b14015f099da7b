"""Sweep ``worlds``: shadows of the sun over large worlds, where one shadow map cannot cover the view.
Cascaded shadow maps (``csm``), virtual shadow maps (``vsmap``) and shadow-map ray tracing over them
(``smrt``) against the reference at 16 samples, with ``pcss`` and ``pcf`` for context.

Frames (one row each): ``city`` and ``open_world`` under their sun, every registered technique of
:data:`TECHNIQUES` at each of its quality settings (``Technique.quality_settings()``), ``pcss`` and
``pcf`` at their defaults with a :data:`CONTEXT_MAP`² map, and the reference at 16 samples, all in one
frame graph (shared passes run once), timed as :func:`wsoft.bench.harness.measure` times them; errors
against the reference at the preset's ground-truth samples (seed 0), cached on disk. Each entry
keeps its technique's counters (``csm``: splits, texel sizes, cascade bytes; ``vsmap``/``smrt``: pages
requested, rendered, reused, evicted, the pool) and ``csm``'s error in a band of :data:`BAND_PX`
pixels around each cascade split against its error away from the splits (:func:`split_band_error`),
and, as its control, the same ratio of ``pcss`` and ``pcf`` (one map, no splits) on the pixels of the
default ``csm``'s bands: the share of csm's ratio the split itself adds, apart from what lies in the
band (a split falls where the frame's receivers are, and those pixels hold the shadow edges).

Sequences (one row each): ``open_world_flyby`` (the camera flying 2 m above the ground, the sun
still) and ``open_world_sunset`` (the same flight, the sun sinking), every frame a frame graph of the
defaults of :data:`TECHNIQUES`, ``csm`` again with fitted cascades (``stable=false``), ``pcss`` and the
reference at 16 samples, measured by :func:`wsoft.bench.temporal.measure_sequence` (flicker from
:mod:`wsoft.metrics.temporal`); the pages each frame renders and reuses are kept per frame.

Sizes (:data:`PRESETS`): ``full`` (640 x 480, a 256-sample ground truth per frame, 48 frames: the
issue's targets, hours of the scalar CPU backend) and ``cpu`` (160 x 120, 64 samples, the first 5
frames), chosen by ``$WSOFT_WORLDS`` (default ``full``); ``--quick`` runs :data:`QUICK` on the
``tiny`` open_world (:data:`wsoft.stages.scenes.open_world.SIZES`), written once into the cache
folder. A technique of :data:`TECHNIQUES` not registered in this process is listed in the report
as not registered, never a failed row. The report is written by :mod:`wsoft.bench.worlds_report`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from wsoft.bench.harness import ground_truth, load, measure, reference
from wsoft.bench.worlds_report import CONTEXT, CONTEXT_MAP, PRESET_ENV, TECHNIQUES, registered, report  # noqa: F401  (the harness calls mod.report)

SUN = "/World/Lights/Sun"
FRAMES = ("city", "open_world")
SEQUENCES = ("open_world_flyby", "open_world_sunset")
PRESETS = {"full": {"size": [640, 480], "ground_truth": 256, "frames": "1:48", "repeats": 3},
           "cpu": {"size": [160, 120], "ground_truth": 64, "frames": "1:5", "repeats": 1}}
QUICK = {"size": [64, 48], "ground_truth": 32, "frames": "1:3", "repeats": 1}
BAND_PX = 16          # width of the band around each csm split (pixels)
TINY = "worlds-tiny"  # the cache folder of the tiny open_world (--quick)


def preset_name() -> str:
    """The preset ``$WSOFT_WORLDS`` names (``full`` when unset); another value is a one-line error."""
    from wsoft.errors import ParameterError

    name = os.environ.get(PRESET_ENV, "full") or "full"
    if name not in PRESETS:
        raise ParameterError(f"${PRESET_ENV}={name!r} is not one of {', '.join(PRESETS)}")
    return name


def tiny_folder() -> Path:
    """Where ``--quick`` finds the tiny open_world and its sequences (written when missing)."""
    from wsoft.env import cache_dir

    return cache_dir() / TINY


def tiny_stages() -> dict[str, str]:
    """The tiny ``open_world``, ``open_world_flyby`` and ``open_world_sunset``: name -> file (written once)."""
    from wsoft.stages.scenes.open_world import write_world

    d = tiny_folder()
    files = {n: d / (n + (".usdc" if n == "open_world" else ".usda")) for n in ("open_world", *SEQUENCES)}
    if not all(f.is_file() for f in files.values()):
        return write_world(str(d), "tiny")
    return {n: str(f) for n, f in files.items()}


def cases(quick: bool, devices: list[str]) -> list[dict]:
    cfg = QUICK if quick else PRESETS[preset_name()]
    preset = "quick" if quick else preset_name()
    if quick:
        d = tiny_folder()
        frames = [str(d / "open_world.usdc")]
        seqs = [str(d / (n + ".usda")) for n in SEQUENCES]
    else:
        frames, seqs = list(FRAMES), list(SEQUENCES)
    w, h = cfg["size"]
    base = {"light": SUN, "width": w, "height": h, "ground_truth": cfg["ground_truth"], "repeats": cfg["repeats"], "preset": preset}
    out = []
    for dev in devices:
        out += [{"kind": "frame", "scene": s, "device": dev, **base} for s in frames]
        out += [{"kind": "sequence", "scene": s, "frames": cfg["frames"], "device": dev, **base} for s in seqs]
    return out


def frame_settings(scene, light, quick: bool) -> list[tuple[str, dict]]:
    """(technique, params) of a frame row: each registered technique of :data:`TECHNIQUES` at its
    quality settings (quick: the first two), ``pcss`` and ``pcf`` at :data:`CONTEXT_MAP`² (quick:
    512²), the reference at 16 samples (seed 1: apart from the ground truth's seed 0); those that
    refuse the light left out."""
    from wsoft.pipeline.build import refusal
    from wsoft.techniques import TECHNIQUES as REG

    out = []
    for name in registered()[0]:
        if refusal(name, scene, light) is None:
            qs = REG[name].quality_settings()
            out += [(name, dict(q)) for q in (qs[:2] if quick else qs)]
    for name in CONTEXT:
        if name in REG and refusal(name, scene, light) is None:
            out.append((name, {REG[name].size_param: 512 if quick else CONTEXT_MAP}))
    out.append(("reference", {"samples": 16, "seed": 1}))
    return out


def sequence_settings(scene, light) -> list[tuple[str, dict]]:
    """(technique, params) of a sequence row: the defaults of each registered technique of
    :data:`TECHNIQUES`, ``csm`` with fitted cascades, ``pcss`` and the reference at 16 samples."""
    from wsoft.pipeline.build import refusal
    from wsoft.techniques import TECHNIQUES as REG

    out = []
    for name in registered()[0]:
        if refusal(name, scene, light) is None:
            out.append((name, {}))
            if name == "csm":
                out.append((name, {"stable": False}))
    if "pcss" in REG and refusal("pcss", scene, light) is None:
        out.append(("pcss", {REG["pcss"].size_param: CONTEXT_MAP}))
    out.append(("reference", {"samples": 16}))
    return out


def memory(tech: str, params: dict, counters: dict) -> dict:
    """A technique's shadow memory from its parameters and counters: ``csm``: its cascade maps
    (``map_bytes``); ``vsmap``/``smrt``: the pool's capacity (``pool_pages`` pages of ``page_size``²
    float32) and what is resident this frame (``pool_mib``); a one-map technique: its map (float32)."""
    from wsoft.techniques import TECHNIQUES as REG

    if tech == "csm":
        return {"cascade_bytes": counters.get("map_bytes")}
    if "pool_pages" in counters:
        return {"pool_bytes": int(counters["pool_pages"]) * int(counters.get("page_size", 128)) ** 2 * 4,
                "resident_bytes": int(round(float(counters.get("pool_mib", 0.0)) * 2 ** 20))}
    cls = REG.get(tech)
    size = params.get(cls.size_param) if cls is not None and cls.size_param else None
    return {"map_bytes": int(size) ** 2 * 4} if size else {}


def view_depth(frame) -> np.ndarray:
    """Each pixel's camera depth (along the view axis) from the frame's ``P`` channels; NaN where nothing is covered."""
    m = np.asarray(frame.stats["camera_model"]["to_world"], np.float64)
    eye, fwd = m[:3, 3], -m[:3, 2]
    P = np.stack([np.asarray(frame[f"P.{c}"], np.float64) for c in "XYZ"], axis=-1)
    d = (P - eye) @ fwd
    return np.where(np.asarray(frame["A"]) > 0.5, d, np.nan)


def split_band_error(frame, ref_v: np.ndarray, splits, band: int = BAND_PX) -> dict:
    """``csm``'s mean |V - V_ref| over covered pixels within ``band`` / 2 pixels of a cascade split
    (where the cascade a pixel's depth falls in changes between neighbouring pixels) and away from
    the splits; ``ratio`` = band over away (None where either region is empty or the away error is 0)."""
    from scipy.ndimage import distance_transform_edt

    d = view_depth(frame)
    cov = np.isfinite(d)
    inner = np.asarray(splits, np.float64)[1:-1]  # the splits between cascades (not the near and far ends)
    c = np.searchsorted(inner, np.where(cov, d, 0.0))
    edge = np.zeros_like(cov)
    for a, b in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))), ((slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
        diff = (c[a] != c[b]) & cov[a] & cov[b]
        edge[a] |= diff
        edge[b] |= diff
    err = np.abs(np.asarray(frame.V, np.float64) - np.asarray(ref_v, np.float64))
    ok = cov & np.isfinite(err)
    if not edge.any():
        return {"band_pixels": 0, "away_pixels": int(ok.sum()), "band_mae": None, "away_mae": float(err[ok].mean()) if ok.any() else None,
                "ratio": None}
    near = distance_transform_edt(~edge) <= band / 2.0 - 1.0  # edge pixels lie on both sides of the split: band / 2 rows each side
    inb, away = ok & near, ok & ~near
    bm = float(err[inb].mean()) if inb.any() else None
    am = float(err[away].mean()) if away.any() else None
    return {"band_pixels": int(inb.sum()), "away_pixels": int(away.sum()), "band_mae": bm, "away_mae": am,
            "ratio": bm / am if bm is not None and am else None}


def load_and_build(name: str, device: str) -> tuple:
    """The stage ``name`` as the sweep renders it (:func:`wsoft.bench.harness.load`) and its device
    copy (BVHs and arrays, kept on the scene for the renders that follow): (scene, seconds to load,
    seconds to build); a time is None where this process had done that work before."""
    import time

    import warp as wp

    from wsoft.bench.harness import _SCENES, scene_file
    from wsoft.parallel import resolve_device
    from wsoft.scene.device import upload_scene

    fresh = scene_file(name) not in _SCENES
    t0 = time.perf_counter()
    scene = load(name)
    t_load = time.perf_counter() - t0 if fresh else None
    dev = resolve_device(device)
    t0 = time.perf_counter()
    _, reused = scene.device_copy(dev, upload_scene)
    wp.synchronize_device(dev)
    return scene, t_load, None if reused else time.perf_counter() - t0


def frame_row(case: dict, ctx: dict) -> dict:
    name, light = case["scene"], case["light"]
    scene, load_s, build_s = load_and_build(name, case["device"])
    L = scene.find_light(light)
    ref = reference(name, width=case["width"], height=case["height"], light=light, samples=case["ground_truth"], device=case["device"])
    truth = ground_truth(name, ref, light)
    techs = frame_settings(scene, L, case["preset"] == "quick")
    fs = measure(name, techs, device=case["device"], width=case["width"], height=case["height"], light=light, truth=truth,
                 repeats=case["repeats"])
    entries = []
    for (tech, params), (label, fr) in zip(techs, fs.items()):
        st = fr.stats
        counters = fr.counters()
        e = {"technique": tech, "label": label, "params": params, "frame_ms": st["timings_ms"]["total"], "frame_ms_runs": st["timings_ms_runs"],
             "error": st["error"], "counters": counters, "memory": memory(tech, params, counters),
             "warnings": [w for w in st["warnings"] if w not in scene.warnings]}
        if tech == "csm" and counters.get("splits"):
            e["split_band"] = split_band_error(fr, ref["V"], counters["splits"])
        entries.append(e)
    splits = next((e["counters"]["splits"] for e in entries if e["technique"] == "csm" and e["counters"].get("splits")), None)
    if splits:  # the control: a map without splits, on the pixels of csm's (default) bands
        for e, fr in zip(entries, fs.values()):
            if e["technique"] in CONTEXT:
                e["split_band"] = split_band_error(fr, ref["V"], splits)
    row = {"scene": Path(name).stem, "light": L.path, "device": case["device"], "width": case["width"], "height": case["height"],
           "ground_truth_samples": case["ground_truth"], "ground_truth_ms": float(ref["ms"]), "entries": entries,
           "triangles": int(scene.total_triangles), "instanced": bool(scene.instanced), "load_s": load_s, "build_s": build_s,
           "preset": case["preset"]}
    if case["preset"] != "quick":
        row["image"] = frame_image(row, fs, ref, ctx)
    return row


def sequence_row(case: dict, ctx: dict) -> dict:
    from wsoft.bench.temporal import measure_sequence

    name, light = case["scene"], case["light"]
    scene = load(name)
    L = scene.find_light(light)
    techs = sequence_settings(scene, L)
    seq, labels, ll, ref_ms = measure_sequence(name, light, techs, case)
    entries = []
    for (tech, params), label in zip(techs, labels):
        frames = [fs[label] for fs in seq.frames]
        counters = [f.counters() for f in frames]
        entries.append({"technique": tech, "label": label, "params": params,
                        "frame_ms_frames": [f.stats["timings_ms"]["total"] for f in frames],
                        "mae_penumbra_frames": [f.stats["error"]["mae_penumbra"] for f in frames],
                        "temporal": seq.summary["temporal"][label][ll],
                        "counters_frames": [{k: v for k, v in c.items() if isinstance(v, (int, float, str, bool))} for c in counters],
                        "memory": memory(tech, params, counters[-1])})
    return {"scene": Path(name).stem, "light": L.path, "device": case["device"], "width": case["width"], "height": case["height"],
            "frames": seq.times, "ground_truth_samples": case["ground_truth"], "ground_truth_ms": float(np.median(ref_ms)) if ref_ms else None,
            "entries": entries, "preset": case["preset"], "warnings": seq.warnings}


def run_case(case: dict, ctx: dict) -> dict:
    if case["preset"] == "quick":
        tiny_stages()
    return frame_row(case, ctx) if case["kind"] == "frame" else sequence_row(case, ctx)


def frame_image(row: dict, fs, ref: dict, ctx: dict) -> str:
    """The reference's V and the default setting of each technique of the row (V and V − V_ref), as a
    labelled PNG under the report's images; its path relative to the report."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [(e["label"], fs[e["label"]]) for e in row["entries"] if not e["params"] or e["technique"] in CONTEXT]
    shown = [(l, f) for l, f in shown if not l.startswith("reference")][:5]
    fig, axes = plt.subplots(2, len(shown) + 1, figsize=(2.6 * (len(shown) + 1), 4.4), squeeze=False, layout="constrained")
    A = np.asarray(ref["A"]) > 0.5
    rv = np.where(A, np.asarray(ref["V"]), np.nan)
    axes[0][0].imshow(rv, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    axes[0][0].set_title(f"reference {row['ground_truth_samples']} spp", fontsize=7)
    axes[1][0].axis("off")
    im = None
    for k, (label, fr) in enumerate(shown, start=1):
        v = np.where(A, np.asarray(fr.V), np.nan)
        axes[0][k].imshow(v, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        axes[0][k].set_title(label, fontsize=7)
        im = axes[1][k].imshow(v - rv, cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
        axes[1][k].set_title("V − V_ref", fontsize=7)
    for ax in np.ravel(axes):
        ax.set_xticks([])
        ax.set_yticks([])
    if im is not None:
        fig.colorbar(im, ax=axes[1][-1], label="V − V_ref (red: lighter)")
    fig.suptitle(f"{row['scene']} / {row['light'].split('/')[-1]}, {row['width']}x{row['height']}: V (lit 1, shadowed 0)", fontsize=8)
    rel = Path("images") / ctx["stem"] / f"{row['scene']}-V.png"
    path = ctx["out_dir"] / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return rel.as_posix()
