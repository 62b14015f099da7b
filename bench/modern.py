"""Sweep ``modern``: what engines ship today (denoised low-sample ray tracing, moment and
exponential-variance shadow maps) beside the papers' techniques, on the same frames.

For each scene of :data:`SCENES` and each of its shadow-casting lights, one frame graph holds the
modern techniques of :data:`MODERN` at each of their declared quality settings, the baselines of
:data:`BASELINES` at theirs, and ``reference`` at 1, 4 and 16 samples; errors are the metric
pass's against a :data:`GROUND_TRUTH`-sample reference on the same pixels, times the passes a
technique needs (shared ones included), median of 3 runs after a warm-up (:func:`wsoft.bench.harness.measure`).
On the stacked-occluder stage the report adds each technique's light *leak*: the fraction of the
reference's umbra pixels (V = 0) that a technique lights above 0.2. Two scenes get a strip of
images: ``rtdenoise`` at 1 sample with each denoiser beside the reference.

The report states the issue's targets as rows: ``rtdenoise`` at its defaults reaching penumbra MAE
0.035 on ``box_plane``, ``contact`` and ``penumbra_ramp`` in less time than the reference at 16
samples in the same graph; ``msm``'s leak at most half of ``vsm``'s; ``msm_soft``'s penumbra MAE
within 1.5x of ``essm``'s on ``ogre`` and ``dinosaurs``. A technique not registered in the running
process is left out and the report says so.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from wsoft.bench.harness import ground_truth, load, measure, reference
from wsoft.bench.pareto import row_metric, setting_text, time_to_reach

MODERN = ("rtdenoise", "msm", "msm_soft", "evsm")
BASELINES = ("hard", "pcss", "vsm", "essm", "vssm")
REFERENCE_SAMPLES = (1, 4, 16)
SCENES = ("box_plane", "contact", "penumbra_ramp", "ogre", "dinosaurs", "stacked_plates")
QUICK_SCENES = ("box_plane", "stacked_plates")
IMAGE_SCENES = ("box_plane", "contact")
GROUND_TRUTH = 1024
SIZE = (640, 480)  # the pareto sweep's frames
MAP = 1024
TARGETS = (0.05, 0.02)
LEAK_LIT = 0.2  # an umbra pixel lit above this leaks (wsoft.metrics.leak.LEAK_THRESHOLD)


def _registered() -> set[str]:
    from wsoft.techniques import TECHNIQUES

    return set(TECHNIQUES)


def cases(quick: bool, devices: list[str]) -> list[dict]:
    from wsoft import usd_scenes

    from wsoft.stages.moment_cases import stage_file

    have = set(usd_scenes.names())
    files = {n: n for n in have} | {"stacked_plates": stage_file(3)}  # the stacked occluders: a stage written into the cache
    names = [n for n in (QUICK_SCENES if quick else SCENES) if n in files]
    w, h = (96, 72) if quick else SIZE
    out = []
    for dev in devices:
        for name in names:
            for light in [l.path for l in load(files[name]).lights]:
                out.append({"kind": "frame", "scene": name, "file": files[name], "light": light, "device": dev, "width": w, "height": h,
                            "ground_truth": 64 if quick else GROUND_TRUTH, "map": 256 if quick else MAP, "quick": quick})
    return out


def settings(scene, light, map_size: int, quick: bool) -> list[tuple[str, dict]]:
    """(technique, params): the modern techniques and the baselines that support ``light``, at
    their quality settings (quick: the first two) and ``map_size`` for their maps; the reference at
    :data:`REFERENCE_SAMPLES`."""
    from wsoft.pipeline.build import refusal
    from wsoft.techniques import TECHNIQUES

    out = []
    for name in [t for t in MODERN + BASELINES if t in TECHNIQUES]:
        cls = TECHNIQUES[name]
        if refusal(name, scene, light) is not None:
            continue
        qs = cls.quality_settings()
        if quick:
            qs = qs[:2]
        m = {cls.size_param: map_size} if cls.size_param else {}
        out += [(name, {**m, **q}) for q in qs]
    out += [("reference", {"samples": s, "seed": 1}) for s in REFERENCE_SAMPLES]
    return out


def leak(v: np.ndarray, truth_v: np.ndarray, covered: np.ndarray) -> float:
    """The fraction of the reference's umbra pixels (covered, V = 0) that ``v`` lights above
    :data:`LEAK_LIT` (:func:`wsoft.metrics.leak.umbra_leak`); NaN where the reference has no umbra."""
    from wsoft.metrics.leak import umbra_leak

    u = umbra_leak(v, truth_v, covered, LEAK_LIT)
    return u["leak"] if u["umbra_pixels"] else math.nan


def run_case(case: dict, ctx: dict) -> dict:
    name, light, file = case["scene"], case["light"], case["file"]
    scene = load(file)
    L = scene.find_light(light)
    ref = reference(file, width=case["width"], height=case["height"], light=light, samples=case["ground_truth"], device=case["device"])
    truth = ground_truth(file, ref, light)
    techs = settings(scene, L, case["map"], case["quick"])
    fs = measure(file, techs, device=case["device"], width=case["width"], height=case["height"], light=light, truth=truth)
    covered = ref["A"] > 0
    entries = []
    for (tech, params), (label, fr) in zip(techs, fs.items()):
        st = fr.stats
        entries.append({"technique": tech, "label": label, "params": params, "frame_ms": st["timings_ms"]["total"],
                        "frame_ms_runs": st["timings_ms_runs"], "error": st["error"], "leak": leak(fr.V, ref["V"], covered),
                        "warnings": [w for w in st["warnings"] if w not in scene.warnings]})
    row = {"scene": name, "light": L.path, "light_kind": L.kind_name, "device": case["device"], "width": case["width"], "height": case["height"],
           "ground_truth_samples": case["ground_truth"], "entries": entries, "umbra_pixels": int((covered & (ref["V"] <= 0)).sum())}
    if name in IMAGE_SCENES and "rtdenoise" in _registered():
        row["strip"] = _strip(name, file, light, case, ref, ctx)
    return row


def _strip(name: str, file: str, light: str, case: dict, ref: dict, ctx: dict) -> str:
    """rtdenoise at 1 sample with each denoiser beside the reference: a labelled PNG under
    ``images/<stem>/``; its path relative to the report."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import wsoft

    denoisers = ("none", "atrous", "penumbra")
    techs = [("rtdenoise", {"samples": 1, "denoiser": d}) for d in denoisers]
    fs = wsoft.render(load(file), techs, width=case["width"], height=case["height"], light=light, device=case["device"])
    panels = [(f"rtdenoise 1 spp, {d}", fr.V) for d, fr in zip(denoisers, fs.values())] + [(f"reference {case['ground_truth']} spp", ref["V"])]
    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 2.8), constrained_layout=True)
    for ax, (title, v) in zip(axes, panels):
        im = ax.imshow(np.where(ref["A"] > 0, v, np.nan), cmap="magma", vmin=0.0, vmax=1.0)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.colorbar(im, ax=axes, shrink=0.8, label="visibility V")
    fig.suptitle(f"{name}: {light.split('/')[-1]}", fontsize=10)
    rel = Path("images") / ctx["stem"] / f"{name}-rtdenoise.png"
    out = Path(ctx["out_dir"]) / rel
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return rel.as_posix()


# -- report -------------------------------------------------------------------------------------------


def _default_entry(entries: list[dict], technique: str) -> dict | None:
    """``technique``'s entry at its defaults (the first of its quality settings)."""
    mine = [e for e in entries if e["technique"] == technique]
    return mine[0] if mine else None


def _ref16(entries: list[dict]) -> dict | None:
    return next((e for e in entries if e["technique"] == "reference" and e["params"]["samples"] == 16), None)


def targets(rows: list[dict]) -> list[tuple[str, str, str]]:
    """(target, measured, met: yes / no / not measured) rows of the issue's targets."""
    out = []
    for scene in ("box_plane", "contact", "penumbra_ramp"):
        r = next((r for r in rows if r["scene"] == scene), None)
        e = _default_entry(r["entries"], "rtdenoise") if r else None
        ref = _ref16(r["entries"]) if r else None
        what = f"rtdenoise (defaults) on {scene}: penumbra MAE ≤ 0.035 in less time than reference 16 spp"
        if e is None or ref is None:
            out.append((what, "not measured", "not measured"))
            continue
        ok = e["error"]["mae_penumbra"] <= 0.035 and e["frame_ms"] < ref["frame_ms"]
        out.append((what, f"MAE {e['error']['mae_penumbra']:.4f}, {e['frame_ms']:.1f} ms vs reference 16 spp {ref['frame_ms']:.1f} ms "
                    f"(MAE {ref['error']['mae_penumbra']:.4f})", "yes" if ok else "no"))
    r = next((r for r in rows if r["scene"] == "stacked_plates"), None)
    msm, vsm = (_default_entry(r["entries"], t) if r else None for t in ("msm", "vsm"))
    what = "msm's leak ≤ half of vsm's on stacked_plates"
    if msm is None or vsm is None:
        out.append((what, "not measured", "not measured"))
    else:
        out.append((what, f"msm {msm['leak']:.3f}, vsm {vsm['leak']:.3f}", "yes" if msm["leak"] <= 0.5 * vsm["leak"] else "no"))
    for scene in ("ogre", "dinosaurs"):
        r = next((r for r in rows if r["scene"] == scene), None)
        ms, es = (_default_entry(r["entries"], t) if r else None for t in ("msm_soft", "essm"))
        what = f"msm_soft's penumbra MAE within 1.5x of essm's on {scene}"
        if ms is None or es is None:
            out.append((what, "not measured", "not measured"))
            continue
        a, b = ms["error"]["mae_penumbra"], es["error"]["mae_penumbra"]
        out.append((what, f"msm_soft {a:.4f}, essm {b:.4f} ({a / b:.2f}x)", "yes" if a <= 1.5 * b else "no"))
    return out


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = report_header("modern", rows, md, ctx)
    if not rows:
        md.write_text("\n".join(L) + "\n")
        return
    techs = sorted({e["technique"] for r in rows for e in r["entries"]})
    missing = [t for t in MODERN if t not in techs]
    L.append(f"Modern techniques ({', '.join(t for t in MODERN if t in techs)}) and baselines "
             f"({', '.join(t for t in BASELINES if t in techs)}) at each of their declared quality settings, maps "
             f"{'/'.join(sorted({str(e['params'][k]) for r in rows for e in r['entries'] for k in e['params'] if k.endswith('_size')}))}², "
             f"and the reference at {', '.join(map(str, REFERENCE_SAMPLES))} samples, in one frame graph per scene and light.")
    L.append(f"Errors against a {'/'.join(sorted({str(r['ground_truth_samples']) for r in rows}))}-sample reference (seed 0) on the same pixels; "
             "frame ms: the passes a technique needs, shared ones included (median of 3 after a warm-up).")
    L.append(f"Leak: the fraction of the reference's umbra pixels (V = 0) a technique lights above {LEAK_LIT}.")
    if missing:
        L.append(f"Not registered in the process that wrote the rows: {', '.join(missing)}.")
    L += ["", "## Targets", "", "| target | measured | met |", "|---|---|---|"]
    L += [f"| {a} | {b} | {c} |" for a, b, c in targets(rows)]
    L += ["", "## Time to reach penumbra MAE 0.05 and 0.02", "",
          "The fastest setting of each technique that reaches the target (`-`: none of its settings does).", ""]
    for target in TARGETS:
        L += [f"### penumbra MAE ≤ {target}", "", "| scene | light | " + " | ".join(techs) + " |", "|---|---|" + "---|" * len(techs)]
        for r in sorted(rows, key=lambda r: (r["scene"], r["light"])):
            cells = []
            for t in techs:
                mine = [e for e in r["entries"] if e["technique"] == t]
                e = time_to_reach(mine, target, row_metric(r)) if mine else None
                cells.append("n/a" if not mine else "-" if e is None else f"{e['frame_ms']:.0f} ms")
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | " + " | ".join(cells) + " |")
        L.append("")
    leaky = [r for r in rows if r["umbra_pixels"]]
    if leaky:
        L += ["## Light leak per technique (defaults)", "", "| scene | light | umbra pixels | " + " | ".join(techs) + " |",
              "|---|---|---|" + "---|" * len(techs)]
        for r in sorted(leaky, key=lambda r: (r["scene"], r["light"])):
            cells = []
            for t in techs:
                e = _default_entry(r["entries"], t)
                cells.append("n/a" if e is None or math.isnan(e["leak"]) else f"{e['leak']:.3f}")
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['umbra_pixels']} | " + " | ".join(cells) + " |")
        L.append("")
    strips = [r for r in rows if r.get("strip")]
    if strips:
        L += ["## rtdenoise at 1 sample: raw, à-trous, penumbra-guided, reference", ""]
        L += [f"![{r['scene']}]({r['strip']})" for r in strips] + [""]
    L += ["## Every setting", "", "| scene | light | setting | frame ms | penumbra MAE | MAE | leak |", "|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r["scene"], r["light"])):
        for e in sorted(r["entries"], key=lambda e: (e["technique"], e["frame_ms"])):
            lk = "" if math.isnan(e["leak"]) else f"{e['leak']:.3f}"
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {setting_text(e)} | {e['frame_ms']:.1f} | "
                     f"{e['error']['mae_penumbra']:.4f} | {e['error']['mae']:.4f} | {lk} |")
    warned = sorted({(r["scene"], w) for r in rows for e in r["entries"] for w in e["warnings"]})
    if warned:
        L += ["", "Warnings: " + "; ".join(f"{s}: {w}" for s, w in warned)]
    md.write_text("\n".join(L) + "\n")
