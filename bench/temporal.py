"""Sweep ``temporal``: shadows in motion. Every technique over the bundled animated stages, with its
flicker against the reference, its mean and worst error over the frames, and its frame time.

For each stage of :data:`SCENES` (a camera flying and turning over ``city`` under the sun, the sun
turning over ``lightmapped_bridge`` while its character walks, a rect light sliding over
``penumbra_ramp``, ``penumbra_ramp`` standing still for a stochastic technique's crawl, and the
skinned ``walker`` stepping under a rect light: a moving character's contact shadow) and each
light it names, every frame of :data:`FRAMES` is one frame graph holding every registered technique
that supports the light at its defaults (its map at :data:`MAP`), the shadow-map techniques again
with ``view=stable`` (a texel grid that stays put), ``hard`` and ``pcss`` also with
``view=sequence`` (one light view for every frame), ``rtdenoise`` with 8 frames of history (``history=8``)
beside its default (none), and the reference at :data:`REFERENCE_SAMPLES` samples
(new samples each frame, as an engine draws them). The ground truth of each frame is the reference
at :data:`GROUND_TRUTH` samples with seed 0 in every frame, cached by time code
(:func:`wsoft.bench.harness.reference`). Errors and flicker come from
:func:`wsoft.pipeline.sequence.compare_sequence` (:mod:`wsoft.metrics.temporal`: pixels paired
through the camera's motion, disocclusions left out); a technique's time is the median over the
frames of the passes it needs (shared ones included), one run per frame.

The report plots per stage flicker against frame time with the Pareto front, tabulates every
setting, states the targets as rows (the stable ``hard`` and ``pcss`` at least halve their flicker
on ``city_flyby`` at equal or lower mean MAE; the reference at 64 samples flickers by no more than
its own noise on the still stage), says per stage which setting is fastest to reach penumbra MAE
0.05 with less flicker than the reference at 16 samples, and shows four consecutive frames of the
reference, ``hard``, ``pcss`` and the stable ``pcss`` where their shadows shimmer most.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from wsoft.bench.harness import ground_truth, load, reference, scene_file

SCENES = {"city_flyby": ("/World/Lights/Sun",), "bridge_sun_sweep": ("/World/Lights/Sun",), "ramp_slide": None, "ramp_static": None,
          "walker": None}
FRAMES = {"city_flyby": "1:24", "bridge_sun_sweep": "1:47:2", "ramp_slide": "1:47:2", "ramp_static": "1:24", "walker": "1:47:2"}
QUICK_SCENES = {"ramp_slide": "1:3", "ramp_static": "1:3"}
SIZE = (256, 192)
QUICK_SIZE = (64, 48)
MAP = 1024
GROUND_TRUTH = 256
REFERENCE_SAMPLES = (4, 16, 64)
TARGET_MAE = 0.05
STRIP = ("reference", "hard", "pcss", "pcss(view=stable)")
SEQUENCE_VIEWS = ("hard", "pcss")  # also with one light view for the whole sequence (view=sequence)


def cases(quick: bool, devices: list[str]) -> list[dict]:
    scenes = QUICK_SCENES if quick else FRAMES
    w, h = QUICK_SIZE if quick else SIZE
    out = []
    for dev in devices:
        for name, frames in scenes.items():
            lights = SCENES[name] or tuple(l.path for l in load(name).lights)
            for light in lights:
                out.append({"kind": "sequence", "scene": name, "light": light, "frames": frames, "device": dev, "width": w, "height": h,
                            "ground_truth": 32 if quick else GROUND_TRUTH, "map": 256 if quick else MAP, "quick": quick})
    return out


def settings(scene, light, map_size: int, quick: bool) -> list[tuple[str, dict]]:
    """(technique, params): every registered technique that supports ``light`` at its defaults (its
    map at ``map_size``), the stable view of those with a ``view`` parameter, rtdenoise without
    history, and the reference at :data:`REFERENCE_SAMPLES` (quick: the first two)."""
    import dataclasses

    from wsoft.pipeline.build import refusal
    from wsoft.techniques import TECHNIQUES

    out = []
    for name in sorted(TECHNIQUES):
        cls = TECHNIQUES[name]
        if refusal(name, scene, light) is not None:
            continue
        if name == "reference":
            out += [(name, {"samples": n}) for n in (REFERENCE_SAMPLES[:2] if quick else REFERENCE_SAMPLES)]
            continue
        base = {cls.size_param: map_size} if cls.size_param else {}
        out.append((name, base))
        fields = {f.name for f in dataclasses.fields(cls.Params)}
        if "view" in fields:
            out.append((name, {**base, "view": "stable"}))
            if name in SEQUENCE_VIEWS:
                out.append((name, {**base, "view": "sequence"}))
        if name == "rtdenoise" and "history" in fields:
            out.append((name, {**base, "history": 8}))
    return out


def measure_sequence(name: str, light: str, techs: list, case: dict):
    """``techs`` over the bundled stage ``name``'s ``case["frames"]`` (``case``: width, height,
    device, ground_truth samples) against the cached reference per frame: (the sequence, its labels in
    ``techs``' order, the light's label, the reference's ms per frame)."""
    from wsoft.metrics.sequences import compare_sequence

    kw = dict(width=case["width"], height=case["height"], light=light, device=case["device"])
    ref_ms: list[float] = []

    def truth(scene_t, t):
        ref = reference(name, samples=case["ground_truth"], time=t, scene=scene_t, **kw)
        ref_ms.append(float(ref["ms"]))
        return ground_truth(name, ref, light)

    seq = compare_sequence(scene_file(name), techs, frames=case["frames"], ground_truth=truth, **kw)
    labels = list(seq.frames[0])
    return seq, labels, seq.frames[0][labels[0]].stats["light_labels"][0], ref_ms


def run_case(case: dict, ctx: dict) -> dict:
    name, light = case["scene"], case["light"]
    scene = load(name)
    L = scene.find_light(light)
    techs = settings(scene, L, case["map"], case["quick"])
    seq, labels, ll, ref_ms = measure_sequence(name, light, techs, case)
    entries = []
    for (tech, params), label in zip(techs, labels):
        frames = [fs[label] for fs in seq.frames]
        ms = [f.stats["timings_ms"]["total"] for f in frames]
        errs = [f.stats["error"] for f in frames]
        entries.append({
            "technique": tech, "label": label, "params": params, "frame_ms": float(np.median(ms)), "frame_ms_frames": ms,
            "temporal": seq.summary["temporal"][label][ll],
            "mae_penumbra_frames": [e["mae_penumbra"] for e in errs],
            "flip": float(np.mean([e["flip"] for e in errs])) if all("flip" in e for e in errs) else None,
            "counters_last": frames[-1].counters(),
            "warnings": sorted({w for f in frames for w in f.stats["warnings"] if w not in scene.warnings}),
        })
    row = {"scene": name, "light": L.path, "light_kind": L.kind_name, "device": case["device"], "width": case["width"],
           "height": case["height"], "frames": seq.times, "ground_truth_samples": case["ground_truth"],
           "ground_truth_ms": float(np.median(ref_ms)) if ref_ms else None, "entries": entries, "cost": {k: v for k, v in seq.summary.items()
                                                                                                    if k != "temporal"},
           "warnings": seq.warnings, "static": any("temporal_std" in e["temporal"] for e in entries)}
    if not case["quick"]:
        row["strip"] = strip(seq, ll, row, ctx)
    return row


# -- images -------------------------------------------------------------------------------------------


def _window(frames: list, label: str, ref: str, ll: str, w: int, h: int) -> tuple[int, int, int, int, int]:
    """The 4 consecutive frames and the ``w x h`` crop where ``label``'s V changes most between
    consecutive frames beyond the reference's (``ref``) change at the same pixels: (first frame, x0,
    y0, x1, y1)."""
    best = (0, 0, 0, -1.0)
    for k in range(len(frames) - 3):
        d = np.zeros_like(np.asarray(frames[k][label][f"V.{ll}"], np.float64))
        for j in range(k, k + 3):
            dv = frames[j + 1][label][f"V.{ll}"] - frames[j][label][f"V.{ll}"]
            dr = frames[j + 1][ref][f"V.{ll}"] - frames[j][ref][f"V.{ll}"]
            d += np.nan_to_num(np.abs(dv - dr), nan=1.0)
        H, W = d.shape
        c = np.cumsum(np.cumsum(np.pad(d, ((1, 0), (1, 0))), 0), 1)
        sums = c[h:, w:] - c[:-h, w:] - c[h:, :-w] + c[:-h, :-w]
        y, x = np.unravel_index(int(np.argmax(sums)), sums.shape)
        if sums[y, x] > best[3]:
            best = (k, int(x), int(y), float(sums[y, x]))
    k, x, y, _ = best
    return k, x, y, x + w, y + h


def strip(seq, ll: str, row: dict, ctx: dict) -> str | None:
    """Four consecutive frames' crops of :data:`STRIP` (those in the row) where ``hard`` shimmers
    most, as a labelled PNG under the report's images; its path relative to the report."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.metrics.temporal import FrameCamera

    refs = [l for l in seq.frames[0] if l.startswith("reference")]
    if "hard" not in seq.frames[0] or not refs:
        return None
    big = max(refs, key=lambda l: seq.frames[0][l].stats["params"]["samples"])  # the most samples stands for the ground truth
    labels = [big if l == "reference" else l for l in STRIP if l == "reference" or l in seq.frames[0]]
    frames = seq.frames
    H, W = np.asarray(frames[0]["hard"]["A"]).shape
    k, x0, y0, x1, y1 = _window(frames, "hard", big, ll, max(W // 4, 8), max(H // 4, 6))
    rel = Path("images") / ctx["stem"] / f"{row['scene']}-{ll}-strip.png"
    fig, axes = plt.subplots(len(labels), 4, figsize=(7.2, 1.9 * len(labels)), squeeze=False)
    for r, label in enumerate(labels):
        for c in range(4):
            v = frames[k + c][label][f"V.{ll}"]
            name = label
            ax = axes[r][c]
            ax.imshow(np.asarray(v)[y0:y1, x0:x1], cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if c == 0:
                ax.set_ylabel(name, fontsize=7)
            if r == 0:
                ax.set_title(f"frame {seq.times[k + c]:g}", fontsize=7)
    moving = any(not FrameCamera.of(frames[j]["hard"].stats).same_view(FrameCamera.of(frames[j + 1]["hard"].stats)) for j in range(k, k + 3))
    fig.suptitle(f"{row['scene']} / {ll}: V in a {x1 - x0}x{y1 - y0} crop at ({x0}, {y0}) of four consecutive frames, where hard changes "
                 "most beyond the reference" + (" (the camera moves: the crop stays put in the image)" if moving else ""), fontsize=7)
    fig.tight_layout()
    path = ctx["out_dir"] / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return rel.as_posix()


def plot(row: dict, path: Path) -> None:
    """Flicker against frame time (log axes), each technique one marker, the Pareto front dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.bench.pareto import pareto_front
    from wsoft.palette import style

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    pts = []
    for e in row["entries"]:
        t, f = e["frame_ms"], max(e["temporal"]["flicker"], 1e-6)
        pts.append((t, f, e))
        st = style(e["technique"])
        stable = e["params"].get("view") == "stable"
        ax.scatter([t], [f], color=st["color"], marker=st["marker"], s=28, facecolors="none" if stable else st["color"],
                   label=e["label"])
    front = pareto_front(pts)
    ax.plot([p[0] for p in front], [p[1] for p in front], "--", color="grey", linewidth=0.8, label="Pareto front")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("frame time (ms, median over the frames)", fontsize=8)
    ax.set_ylabel("flicker against the reference (mean |ΔV − ΔV_ref|)", fontsize=8)
    ax.set_title(f"{row['scene']} / {row['light'].split('/')[-1]}, {len(row['frames'])} frames, {row['width']}x{row['height']}, {row['device']}",
                 fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=5, ncol=3, loc="best")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- report -------------------------------------------------------------------------------------------


def _entry(row: dict, label: str) -> dict | None:
    return next((e for e in row["entries"] if e["label"] == label), None)


def target_rows(rows: list[dict]) -> list[str]:
    """The issue's targets as table rows: stable hard/pcss on city_flyby, the reference's crawl on the still stage."""
    L = ["| target | measured | met |", "|---|---|---|"]
    for r in rows:
        if r["scene"] != "city_flyby":
            continue
        for t in ("hard", "pcss"):
            for v in ("stable", "sequence"):
                a, b = _entry(r, t), _entry(r, f"{t}(view={v})")
                if a is None or b is None:
                    continue
                fa, fb = a["temporal"]["flicker"], b["temporal"]["flicker"]
                ma, mb = a["temporal"]["mae"], b["temporal"]["mae"]
                ratio = fa / fb if fb > 0 else math.inf
                L.append(f"| {t} view={v} flickers ≥ 2x less than fitted on city_flyby at ≤ mean MAE | flicker {fa:.5f} → {fb:.5f} "
                         f"({ratio:.2f}x), mean MAE {ma:.4f} → {mb:.4f} | {'yes' if ratio >= 2.0 and mb <= ma else 'no'} |")
    for r in rows:
        if r["scene"] != "city_flyby":
            continue
        for t in ("hard", "pcss"):
            a, b = _entry(r, t), _entry(r, f"{t}(view=sequence)")
            if a is not None and b is not None:
                L.append(f"| (bound) {t} with one light view for the whole flight (view=sequence: the sun and the city stand still, so its "
                         f"shadow map is the same in every frame): the flicker no light-view policy removes here | {b['temporal']['flicker']:.5f} "
                         f"(fitted: {a['temporal']['flicker']:.5f}) | - |")
    for r in rows:
        if not r["static"]:
            continue
        refs = [e for e in r["entries"] if e["technique"] == "reference"]
        if not refs:
            continue
        e = max(refs, key=lambda e: e["params"]["samples"])
        m = e["temporal"]
        if "flicker_excess" not in m:
            continue
        ok = m["flicker_excess"] <= 2.0 * m["flicker_se"]
        L.append(f"| reference {e['params']['samples']} spp (new samples each frame) on the still {r['scene']}: its flicker no more than its "
                 f"standard errors allow (own noise: sqrt(2/π) sqrt(se_t² + se_t-1²), excess within 2 se of the flicker) | "
                 f"flicker {m['flicker']:.5f}, own noise {m['own_noise']:.5f}, excess {m['flicker_excess']:+.5f} ± {m['flicker_se']:.5f} "
                 f"(temporal std {m.get('temporal_std', 0):.5f}) | {'yes' if ok else 'no'} |")
    return L


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = [line.replace("Times: median of 3 runs after a warm-up.", "Times: one run per frame, the median over the frames.")
         for line in report_header("temporal", rows, md, ctx)]
    if not rows:
        md.write_text("\n".join(L) + "\n")
        return
    L.append("Every registered technique that supports the light at its defaults (maps "
             f"{rows[0]['entries'][0]['params'].get('shadow_map_size', MAP)}² where it has one), the shadow-map techniques again with "
             "`view=stable` (`hard` and `pcss` also `view=sequence`), `rtdenoise` without and with temporal accumulation (`history=8`), and the reference at "
             f"{', '.join(str(n) for n in REFERENCE_SAMPLES)} samples drawing new samples each frame, all in one frame graph per frame.")
    L.append(f"Ground truth: the reference at {rows[0]['ground_truth_samples']} samples, seed 0 in every frame (its noise does not crawl).")
    L.append("**Flicker**: the mean over pixels and frame pairs of |ΔV − ΔV_ref| at the same surface point (the same pixel while the camera")
    L.append("stands still, else the pixel of the previous frame that saw the same world point; disocclusions left out); its standard error")
    L.append("from the pixels' spread. Where the camera moves, paired points lie up to half a pixel footprint apart: an edge sharper")
    L.append("than a pixel changes V between them though nothing moved, so there flicker includes the edge's own aliasing (the bound rows")
    L.append("measure it with a shadow map that is the same in every frame).")
    L.append("**Mean MAE** and **mean penumbra MAE** over the frames; the **worst frame** by penumbra MAE.")
    L.append("Frame ms: the median over the frames of the passes a technique needs (shared ones included), one run per frame.")
    L.append("")
    L += ["## Targets", ""] + target_rows(rows) + [""]
    L += ["## Fastest to penumbra MAE 0.05 with less flicker than the reference at 16 samples", "",
          "| scene | light | setting | frame ms | mean penumbra MAE | flicker | reference 16 spp flicker |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        ref16 = _entry(r, "reference(samples=16)")
        lim = ref16["temporal"]["flicker"] if ref16 else math.inf
        ok = [e for e in r["entries"] if e["temporal"]["mae_penumbra"] <= TARGET_MAE and e["temporal"]["flicker"] < lim]
        if ok:
            e = min(ok, key=lambda e: e["frame_ms"])
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {e['label']} | {e['frame_ms']:.1f} | {e['temporal']['mae_penumbra']:.4f} | "
                     f"{e['temporal']['flicker']:.5f} | {lim:.5f} |")
        else:
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | none reaches it | - | - | - | {lim:.5f} |")
    L.append("")
    for r in rows:
        ll = r["light"].split("/")[-1]
        L += [f"## {r['scene']} / {ll} ({len(r['frames'])} frames, time codes {r['frames'][0]:g}..{r['frames'][-1]:g})", ""]
        rel = Path("images") / ctx["stem"] / f"{r['scene']}-{ll}-flicker.png"
        plot(r, md.parent / rel)
        L += [f"![{r['scene']} flicker against time]({rel.as_posix()})", ""]
        if r.get("strip"):
            L += [f"![{r['scene']} four frames]({r['strip']})", ""]
        c = r["cost"]
        floor = next((e["temporal"].get("flicker_noise") for e in r["entries"]), None)
        if floor is not None:
            L.append(f"The ground truth's own frame-to-frame noise, from its standard errors (an upper bound: its seed is the same in every "
                     f"frame): {floor:.5f}.")
        pre = c.get("receivers_ms", 0.0)
        L.append(f"Scene on the device: {c['scene_built']} built, {c.get('scene_refit', 0)} refit, {c['scene_reused']} reused; loading "
                 f"{c['load_ms'] / max(c['frames'], 1):.0f} ms a frame, refits {c.get('refit_ms', 0):.0f} ms, uploads {c['upload_ms']:.0f} ms in all"
                 + (f"; the G-buffer pass over every frame for `view=sequence` (where the first copy was built) {pre / 1e3:.1f} s." if pre else "."))
        L.append("")
        static = r["static"]
        L.append("| setting | frame ms | flicker ± se | own change | mean MAE | mean penumbra MAE | worst frame (penumbra MAE) | ꟻLIP |"
                 + (" temporal std |" if static else ""))
        L.append("|---|---:|---:|---:|---:|---:|---|---:|" + ("---:|" if static else ""))
        for e in sorted(r["entries"], key=lambda e: e["temporal"]["flicker"]):
            m = e["temporal"]
            w = m.get("worst_frame", {})
            L.append(f"| {e['label']} | {e['frame_ms']:.1f} | {m['flicker']:.5f} ± {m['flicker_se']:.5f} | {m['change']:.5f} | {m['mae']:.4f} | "
                     f"{m['mae_penumbra']:.4f} | {w.get('time', 0):g} ({w.get('mae_penumbra', 0):.4f}) | "
                     + (f"{e['flip']:.4f}" if e.get("flip") is not None else "-") + " |"
                     + (f" {m.get('temporal_std', 0):.5f} |" if static else ""))
        L.append("")
        warned = sorted({w for e in r["entries"] for w in e["warnings"]})
        if warned:
            L += ["Warnings: " + "; ".join(warned), ""]
    md.write_text("\n".join(L) + "\n")
