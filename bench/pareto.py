"""Sweep ``pareto``: what accuracy costs in time, for every technique on the same frames.

For every bundled scene and each of its shadow-casting lights, one frame graph holds every
registered technique that supports the light, at each of its declared quality settings
(``Technique.quality_settings()``: its defaults, then each quality knob's values one at a time)
and two sizes of its light-space map or grid (its ``size_param``), plus ``reference`` at 1-256 samples (its own quality knob, seed 1).
Passes they have in common (the G-buffer, each depth map, ESSM's SATs across its shading knobs,
SSM's pruning structures across budgets) run once. Each technique's frame time is the sum of
the passes it needs (shared ones included), median of 3 runs after a warm-up (a setting whose
warm-up frame takes over :data:`ONCE_OVER_MS` is timed by that frame alone, and the report lists
it); its error is the metric pass's against a reference of :data:`GROUND_TRUTH` samples (seed 0)
on the same pixels.

The report plots, per scene and light, penumbra MAE against frame time (log axes) with each
technique's Pareto front and the reference's curve, and tabulates the Pareto-optimal settings
and the time each technique needs to reach penumbra MAE 0.05 and 0.02. A light whose reference
has no penumbra (a point light: every pixel lit or not) is measured by the MAE over all covered
pixels instead, and the report says so on each of its lines (:func:`row_metric`). A technique
registered later appears without editing this file.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from wsoft.bench.harness import ground_truth, load, measure, reference

GROUND_TRUTH = 1024  # light samples of the reference every error is measured against
SIZES = (1024, 2048)
TARGETS = (0.05, 0.02)  # penumbra MAE the table asks each technique to reach
QUICK_SCENES = ("box_plane", "contact")
CURVE_SEED = 1  # the reference's curve is independent of the ground truth (seed 0)
ONCE_OVER_MS = 60_000.0  # a setting whose warm-up frame takes longer is timed by that frame alone (harness.measure's once_over_ms)


# stages left out of the full sweep: forest (56M instanced triangles: techniques that read the triangle
# soup cannot flatten it; its own evidence is `wsoft bench instancing`) and the analogs of Forest et al.'s
# scenes, measured by their own sweep (`wsoft bench stsv`); and the animated stages, sequences whose first
# frames repeat a stage above (bridge_sun_sweep, ramp_static) or nearly so (ramp_slide; city_flyby from a low camera;
# open_world_flyby and open_world_sunset from open_world's camera).
# Every other bundled stage is swept, a frame per shadow-casting light: the interiors (room_lamp, corridor_torch:
# a sphere light whose receivers surround it) among them.
NOT_IN_PARETO = ("forest", "fence_perforated", "fence_mesh", "hl2_like", "factory", "greece", "wedge_overlap",
                 "city_flyby", "bridge_sun_sweep", "ramp_slide", "ramp_static", "open_world_flyby", "open_world_sunset")


def scene_lights(name: str) -> list[str]:
    return [l.path for l in load(name).lights]


def cases(quick: bool, devices: list[str]) -> list[dict]:
    from wsoft import usd_scenes

    names = QUICK_SCENES if quick else tuple(n for n in usd_scenes.names() if n not in NOT_IN_PARETO)
    w, h = (160, 120) if quick else (640, 480)
    out = []
    for dev in devices:
        for name in names:
            for light in scene_lights(name):
                out.append({"kind": "frame", "scene": name, "light": light, "device": dev, "width": w, "height": h,
                            "ground_truth": 64 if quick else GROUND_TRUTH, "sizes": [512] if quick else list(SIZES), "quick": quick})
    return out


def settings(scene, light, sizes: list[int], quick: bool, refused: list | None = None) -> list[tuple[str, dict]]:
    """(technique, params) of every registered technique that supports ``light``, over its quality
    settings and the map sizes; the reference over its sample counts. A combination the technique's
    own parameters refuse (``skymaps``: 256 directions of 2048² maps exceed its memory cap) is left
    out, and appended to ``refused`` as {technique, params, reason}."""
    from wsoft.errors import ParameterError
    from wsoft.pipeline.build import refusal
    from wsoft.techniques import TECHNIQUES, create

    out = []
    for name in sorted(TECHNIQUES):
        cls = TECHNIQUES[name]
        if refusal(name, scene, light) is not None:
            continue
        qs = cls.quality_settings()
        if quick:
            qs = qs[:2]
        if name == "reference":
            q = cls.quality[0]
            values = q.values[:3] if quick else q.values
            out += [(name, {q.param: v, "seed": CURVE_SEED}) for v in values]
            continue
        maps = [{cls.size_param: size} for size in sizes] if cls.size_param else [{}]
        for params in ({**m, **q} for m in maps for q in qs):
            try:
                create(name, params)
            except ParameterError as exc:
                if refused is not None:
                    refused.append({"technique": name, "params": params, "reason": str(exc)})
                continue
            if (name, params) not in out:  # a quality knob on the map size itself repeats a map size's setting
                out.append((name, params))
    return out


def references(case: dict) -> list[dict]:
    """The reference :func:`run_case` measures against (error-only work a distributed sweep runs apart)."""
    return [{"name": case["scene"], "width": case["width"], "height": case["height"], "light": case["light"], "samples": case["ground_truth"],
             "device": case["device"]}]


def run_case(case: dict, ctx: dict) -> dict:
    name, light = case["scene"], case["light"]
    scene = load(name)
    L = scene.find_light(light)
    ref = reference(name, width=case["width"], height=case["height"], light=light, samples=case["ground_truth"], device=case["device"])
    truth = ground_truth(name, ref, light)
    refused: list[dict] = []
    techs = settings(scene, L, case["sizes"], case["quick"], refused)
    fs = measure(name, techs, device=case["device"], width=case["width"], height=case["height"], light=light, truth=truth,
                 once_over_ms=ONCE_OVER_MS)
    entries = []
    for (tech, params), (label, fr) in zip(techs, fs.items()):
        st = fr.stats
        entries.append({
            "technique": tech, "label": label, "params": params, "frame_ms": st["timings_ms"]["total"],
            "frame_ms_runs": st["timings_ms_runs"], "by_kind_ms": st["timings_by_kind_ms"], "shared_passes": sorted(st["shared_passes"]),
            "error": st["error"], "warnings": [w for w in st["warnings"] if w not in scene.warnings],
            **({"timed_once": True} if st.get("timed_once") else {}),
        })
    return {"scene": name, "light": L.path, "light_kind": L.kind_name, "device": case["device"], "width": case["width"], "height": case["height"],
            "ground_truth_samples": case["ground_truth"], "ground_truth_ms": float(ref["ms"]), "entries": entries,
            "graph_passes": len(fs.stats["passes"]), "shared_pass_count": len(fs.stats["shared_passes"]), "refused_settings": refused}


# -- report -------------------------------------------------------------------------------------------


def pareto_front(points: list[tuple[float, float, dict]]) -> list[tuple[float, float, dict]]:
    """The points no other point beats in both time and error, by increasing time."""
    front, best = [], math.inf
    for t, e, x in sorted(points, key=lambda p: (p[0], p[1])):
        if e < best:
            front.append((t, e, x))
            best = e
    return front


def row_metric(row: dict) -> str:
    """The error a row is ranked by: ``mae_penumbra``, or ``mae`` (over every covered pixel) where the
    reference has no penumbra pixel (a point light), whose penumbra MAE is 0 for any shadow."""
    return "mae_penumbra" if any(e["error"]["penumbra_pixels"] > 0 for e in row["entries"]) else "mae"


METRIC_TEXT = {"mae_penumbra": "penumbra MAE", "mae": "MAE over all pixels (no penumbra)"}


def _err(entry: dict, metric: str = "mae_penumbra") -> float:
    return entry["error"][metric]


def flip_text(entry: dict) -> str:
    """The entry's ꟻLIP (whole-image mean of the shaded image against the reference's), ``-`` where
    the row has none (rows measured without the reference's shaded image)."""
    f = entry["error"].get("flip")
    return "-" if f is None else f"{f:.4f}"


def size_param(technique: str) -> str | None:
    """The parameter the sweep turned as ``technique``'s map size (None: none, or not registered in this process)."""
    from wsoft.techniques import TECHNIQUES

    cls = TECHNIQUES.get(technique)
    return cls.size_param if cls is not None else None


def setting_text(entry: dict) -> str:
    p = entry["params"]
    if entry["technique"] == "reference":
        return f"reference {p['samples']} spp"
    size = size_param(entry["technique"])
    rest = ", ".join(f"{k}={v}" for k, v in p.items() if k != size)
    return f"{entry['technique']}" + (f" {p[size]}²" if size in p else "") + (f" {rest}" if rest else "")


def time_to_reach(entries: list[dict], target: float, metric: str = "mae_penumbra") -> dict | None:
    """The fastest entry whose error (``metric``, :func:`row_metric`) is at most ``target``."""
    ok = [e for e in entries if _err(e, metric) <= target]
    return min(ok, key=lambda e: e["frame_ms"]) if ok else None


MODERN = ("rtdenoise", "msm", "msm_soft", "evsm")  # what engines ship today
PAPERS = ("salzman", "essm", "vssm", "ssm", "izb", "dcs", "pwedge")  # the five papers' techniques


def dominates(a: list[tuple[float, float]], b: list[tuple[float, float]]) -> bool:
    """Does the set of (time, error) points ``a`` dominate ``b``: every point of ``b`` has a point of
    ``a`` at most as slow and at most as wrong, strictly better in one of the two?"""
    return bool(a) and bool(b) and all(any(ta <= tb and ea <= eb and (ta < tb or ea < eb) for ta, ea in a) for tb, eb in b)


def dominance_section(rows: list[dict], techs: list[str]) -> list[str]:
    """Where a modern baseline dominates a paper's technique (its Pareto front lies at or below every
    setting of the paper's front, in time and error) and where it does not, per scene and light."""
    modern = [m for m in MODERN if m in techs]
    papers = [p for p in PAPERS if p in techs]
    if not modern or not papers:
        return []
    L = ["## Where a modern baseline dominates a paper's technique", "",
         "A modern technique *dominates* a paper's on a frame when every setting of the paper's Pareto front has a setting of the "
         "modern one at most as slow and at most as wrong (the row's error: penumbra MAE, or all pixels' MAE for a point light). "
         "Cells: frames (scene and light) where it dominates / frames where both ran; then the frames where it does not.", "",
         "| paper's technique | " + " | ".join(modern) + " |", "|---|" + "---|" * len(modern)]
    detail = []
    for p in papers:
        cells = []
        for m in modern:
            won, lost = [], []
            for r in sorted(rows, key=lambda r: (r["scene"], r["light"])):
                metric = row_metric(r)
                pts = {t: pareto_front([(e["frame_ms"], _err(e, metric), e) for e in r["entries"] if e["technique"] == t]) for t in (p, m)}
                if not pts[p] or not pts[m]:
                    continue
                name = f"{r['scene']}/{r['light'].split('/')[-1]}"
                (won if dominates([(t, e) for t, e, _ in pts[m]], [(t, e) for t, e, _ in pts[p]]) else lost).append(name)
            cells.append(f"{len(won)} / {len(won) + len(lost)}")
            if won or lost:
                detail.append(f"* `{m}` over `{p}`: dominates on {', '.join(won) or 'none'}; not on {', '.join(lost) or 'none'}.")
        L.append(f"| {p} | " + " | ".join(cells) + " |")
    return L + [""] + detail + [""]


def motion_section(temporal_rows: Path) -> list[str]:
    """Each technique's flicker and ꟻLIP at its defaults on the animated stages, from the rows of
    ``wsoft bench temporal`` beside this report (nothing when there are none)."""
    from wsoft.bench.harness import read_rows

    rows = read_rows(temporal_rows)
    if not rows:
        return []
    stages = [f"{r['scene']}/{r['light'].split('/')[-1]}" for r in rows]
    labels = sorted({e["label"] for r in rows for e in r["entries"]})
    L = ["## In motion: flicker and ꟻLIP on the animated stages", "",
         f"From `wsoft bench temporal` ([temporal.md](temporal.md), {rows[0]['width']}x{rows[0]['height']}, every technique at its defaults "
         "with 1024² maps): flicker against the reference (mean |ΔV − ΔV_ref| at the same surface point over the frame pairs) and "
         "the mean ꟻLIP over the frames, `flicker / ꟻLIP` per stage (`n/a`: not applicable).", "",
         "| setting | " + " | ".join(stages) + " |", "|---|" + "---|" * len(stages)]
    for label in labels:
        cells = []
        for r in rows:
            e = next((e for e in r["entries"] if e["label"] == label), None)
            cells.append("n/a" if e is None else f"{e['temporal']['flicker']:.4f} / " + (f"{e['flip']:.4f}" if e.get("flip") is not None else "-"))
        L.append(f"| {label} | " + " | ".join(cells) + " |")
    L += ["", "The fastest setting to reach penumbra MAE 0.05 (mean over the frames) with less flicker than the reference at 16 samples:", ""]
    for r, stage in zip(rows, stages):
        ref16 = next((e for e in r["entries"] if e["label"] == "reference(samples=16)"), None)
        lim = ref16["temporal"]["flicker"] if ref16 else math.inf
        ok = [e for e in r["entries"] if e["temporal"]["mae_penumbra"] <= 0.05 and e["temporal"]["flicker"] < lim]
        e = min(ok, key=lambda e: e["frame_ms"]) if ok else None
        L.append(f"* {stage}: " + (f"{e['label']}, {e['frame_ms']:.0f} ms (flicker {e['temporal']['flicker']:.4f} against the reference's "
                                    f"{lim:.4f})" if e else "none reaches it"))
    return L + [""]


def plot(row: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metric = row_metric(row)
    entries = row["entries"]
    techs = sorted({e["technique"] for e in entries})
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    from wsoft.palette import style

    for t in techs:
        mine = [(e["frame_ms"], max(_err(e, metric), 1e-4), e) for e in entries if e["technique"] == t]
        color, marker = style(t)["color"], style(t)["marker"]
        if t == "reference":
            pts = sorted(mine, key=lambda p: p[0])
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "-", color=color, marker=".",
                    label=f"reference ({pts[0][2]['params']['samples']}-{pts[-1][2]['params']['samples']} spp)")
            for x, y, e in pts:
                ax.annotate(str(e["params"]["samples"]), (x, y), fontsize=6)
            continue
        ax.scatter([p[0] for p in mine], [p[1] for p in mine], s=10, color=color, marker=marker, alpha=0.45)
        front = pareto_front(mine)
        ax.plot([p[0] for p in front], [p[1] for p in front], "--", color=color, marker=marker, markersize=4, label=t)
    for target in TARGETS:
        ax.axhline(target, color="grey", linewidth=0.6, linestyle=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("frame time (ms)", fontsize=8)
    ax.set_ylabel(f"{METRIC_TEXT[metric]} of V", fontsize=8)
    ax.set_title(f"{row['scene']} / {row['light'].split('/')[-1]} ({row['light_kind']}), {row['width']}x{row['height']}, {row['device']}", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _light_cell(row: dict) -> str:
    """The light's name, marked where the row ranks by the MAE over all pixels (:func:`row_metric`)."""
    name = row["light"].split("/")[-1]
    return name if row_metric(row) == "mae_penumbra" else f"{name} (all pixels)"


def choice_section(rows: list[dict]) -> list[str]:
    """Which technique to use: per scene and light, the fastest setting of any technique (the
    reference included) that reaches each target, and the fastest that is not the reference; then
    how often each technique is that fastest one."""
    L = ["## Which technique to use", "",
         "Per scene and light, the fastest setting of all (the reference at its sample counts included) whose error is at most "
         "each target, and the fastest real-time technique (not the reference) reaching 0.05 (`-`: none does). "
         "Error: penumbra MAE, or all pixels' MAE for a point light.", "",
         "| scene | light | fastest to " + " | fastest to ".join(f"≤ {t}" for t in TARGETS) + f" | fastest but the reference to ≤ {TARGETS[0]} |",
         "|---|---|" + "---|" * (len(TARGETS) + 1)]
    wins: dict[float, dict[str, int]] = {t: {} for t in TARGETS}
    for r in sorted(rows, key=lambda r: (r["scene"], r["light"])):
        metric = row_metric(r)
        cells = []
        for t in TARGETS:
            e = time_to_reach(r["entries"], t, metric)
            if e is not None:
                wins[t][e["technique"]] = wins[t].get(e["technique"], 0) + 1
            cells.append("-" if e is None else f"{setting_text(e)}, {e['frame_ms']:.0f} ms")
        e = time_to_reach([x for x in r["entries"] if x["technique"] != "reference"], TARGETS[0], metric)
        cells.append("-" if e is None else f"{setting_text(e)}, {e['frame_ms']:.0f} ms")
        L.append(f"| {r['scene']} | {_light_cell(r)} | " + " | ".join(cells) + " |")
    L.append("")
    for t in TARGETS:
        tally = ", ".join(f"`{k}` {n}" for k, n in sorted(wins[t].items(), key=lambda kv: (-kv[1], kv[0])))
        L.append(f"* Fastest to ≤ {t} on {sum(wins[t].values())} of {len(rows)} frames: {tally or 'none'}.")
    return L + [""]


RUN_GAP_S = 3600.0  # rows finished further apart than this came from separate runs of the sweep


def measured_in_runs(rows: list[dict]) -> list[str]:
    """When the rows came from more than one run of the sweep (finish times over :data:`RUN_GAP_S`
    apart, as a resumed sweep leaves them), a line per run: when, how (in-process or on Dask
    workers) and which frames, so a reader sees which rows were measured with which code."""
    import datetime

    def when(r):
        return datetime.datetime.fromisoformat(r["finished"]) if r.get("finished") else None

    timed = sorted((r for r in rows if when(r)), key=when)
    runs: list[list[dict]] = []
    for r in timed:
        if runs and (when(r) - when(runs[-1][-1])).total_seconds() <= RUN_GAP_S:
            runs[-1].append(r)
        else:
            runs.append([r])
    if len(runs) < 2:
        return []
    out = [f"The rows come from {len(runs)} runs of the sweep (a rerun resumes: it measures only the frames it lacks, with the code of "
           "its day; each row's finish time, host and load are in the rows file):"]
    for g in runs:
        how = "on Dask workers" if all(r.get("worker") for r in g) else "in-process" if not any(r.get("worker") for r in g) else "mixed"
        frames = ", ".join(f"{r['scene']}/{r['light'].split('/')[-1]}" for r in g)
        out.append(f"* {g[0]['finished']} to {g[-1]['finished']}, {how}, {len(g)} rows: {frames}.")
    return out


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = report_header("pareto", rows, md, ctx)
    if not rows:
        md.write_text("\n".join(L) + "\n")
        return
    L += measured_in_runs(rows)
    techs = sorted({e["technique"] for r in rows for e in r["entries"]})
    sizes = sorted({e["params"][size_param(e["technique"])] for r in rows for e in r["entries"] if size_param(e["technique"]) in e["params"]})
    L.append(f"Every registered technique that supports the light ({', '.join(techs)}) at each of its declared quality settings and")
    L.append(f"map sizes {', '.join(f'{s}²' for s in sizes)}, and the reference at "
             f"{', '.join(sorted({str(e['params']['samples']) for r in rows for e in r['entries'] if e['technique'] == 'reference'}, key=int))} samples,")
    L.append(f"in **one frame graph per scene and light**: the passes they share run once (on average "
             f"{sum(r['shared_pass_count'] for r in rows) / len(rows):.0f} of {sum(r['graph_passes'] for r in rows) / len(rows):.0f} passes a graph).")
    L.append(f"Errors: penumbra MAE against a {'/'.join(sorted({str(r['ground_truth_samples']) for r in rows}))}-sample reference (seed 0) on the same pixels;")
    L.append("ꟻLIP: NVIDIA's perceptual difference of the shaded image against the reference's, as the PNGs show them (whole-image")
    L.append("mean; `-`: a row measured without the reference's shaded image);")
    L.append("frame ms: the passes a technique needs, shared ones included (median of 3 after a warm-up). Dashed lines: each")
    L.append("technique's Pareto front over its settings (faint points: the rest); solid: the reference's curve; dotted: MAE 0.05 and 0.02.")
    plain = sorted(f"{r['scene']}/{r['light'].split('/')[-1]}" for r in rows if row_metric(r) == "mae")
    if plain:
        L.append(f"The reference of {', '.join(plain)} has no penumbra pixel (a point light: every pixel is lit or not), where penumbra")
        L.append("MAE is 0 for any shadow: those lines rank by the MAE over all covered pixels, and say so (`all pixels`).")
        if any(e["technique"] == "izb" for r in rows if row_metric(r) == "mae" for e in r["entries"]):
            L.append("There `izb` (the exact hard shadow of the light's centre) is not exactly 0 either: its shadow ray aims at the")
            L.append("light's centre from the offset origin, the reference's leaves the offset origin in the direction from the surface")
            L.append("point to the light. The two part only on knife-edge rays, which pass within the offset of an edge; each")
            L.append("equals a brute force over every triangle on its own rays")
            L.append("(`tests/test_izb.py::test_none_differs_from_the_reference_only_where_their_ray_conventions_do`).")
    once = [f"{r['scene']}/{r['light'].rsplit('/', 1)[-1]} {e.get('label') or e['technique']} ({e['frame_ms'] / 1e3:.0f} s)"
            for r in rows for e in r["entries"] if e.get("timed_once")]
    if once:
        L.append(f"Timed by their warm-up frame alone (a frame over {ONCE_OVER_MS / 1e3:.0f} s, not repeated): " + "; ".join(once) + ".")
    refused = {(x["technique"], json.dumps(x["params"], sort_keys=True)): x["reason"] for r in rows for x in r.get("refused_settings", [])}
    if refused:
        L.append("Settings left out because the technique's own parameters refuse them (not measured): "
                 + "; ".join(f"`{t}` {', '.join(f'{k}={v}' for k, v in json.loads(ps).items())} ({why})" for (t, ps), why in sorted(refused.items())) + ".")
    L.append("")
    L += choice_section(rows)
    L.append("## Time to reach penumbra MAE 0.05 and 0.02")
    L.append("")
    L.append("The fastest setting of each technique that reaches the target, per scene and light (`-`: not reached by any of its settings).")
    L.append("")
    head = "| scene | light | " + " | ".join(techs) + " |"
    for target in TARGETS:
        L += [f"### penumbra MAE ≤ {target}", "", head, "|---|---|" + "---|" * len(techs)]
        for r in sorted(rows, key=lambda r: (r["scene"], r["light"])):
            cells = []
            for t in techs:
                mine = [e for e in r["entries"] if e["technique"] == t]
                if not mine:
                    cells.append("n/a")
                    continue
                e = time_to_reach(mine, target, row_metric(r))
                cells.append("-" if e is None else f"{e['frame_ms']:.0f} ms ({setting_text(e).split(' ', 1)[1] if ' ' in setting_text(e) else ''})")
            L.append(f"| {r['scene']} | {_light_cell(r)} | " + " | ".join(cells) + " |")
        L.append("")
    L += dominance_section(rows, techs)
    L += motion_section(md.parent / "temporal.jsonl")
    L += ["## Pareto-optimal settings per scene and light (all techniques together)", ""]
    L.append("| scene | light | setting | frame ms | penumbra MAE | MAE | MAE facing the light | penumbra pixels | ꟻLIP |")
    L.append("|---|---|---|---|---|---|---|---|---|")
    for r in sorted(rows, key=lambda r: (r["scene"], r["light"])):
        pts = [(e["frame_ms"], _err(e, row_metric(r)), e) for e in r["entries"]]
        for t, e, x in pareto_front(pts):
            L.append(f"| {r['scene']} | {_light_cell(r)} | {setting_text(x)} | {t:.1f} | {_err(x):.4f} | {x['error']['mae']:.4f} | "
                     f"{x['error']['facing']['mae']:.4f} | {x['error']['penumbra_pixels']} | {flip_text(x)} |")
    not_applicable = sorted({(r["scene"], r["light"].split("/")[-1], t) for r in rows for t in techs
                             if not any(e["technique"] == t for e in r["entries"])})
    if not_applicable:
        L += ["", "Not applicable (the technique's `supports` declined the light): "
              + "; ".join(f"{t} on {s}/{l}" for s, l, t in not_applicable) + "."]
    warned = sorted({(r["scene"], w) for r in rows for e in r["entries"] for w in e["warnings"]})
    if warned:
        L += ["", "Warnings: " + "; ".join(f"{s}: {w}" for s, w in warned)]
    L += ["", "## Error against time, per scene and light", ""]
    for r in sorted(rows, key=lambda r: (r["scene"], r["light"])):
        rel = Path("images") / ctx["stem"] / f"{r['scene']}-{r['light'].split('/')[-1]}-{r['device'].replace(':', '')}.png"
        plot(r, md.parent / rel)
        L += [f"![{r['scene']} {r['light']}]({rel.as_posix()})", ""]
    L += ["## Every setting", "", "| scene | light | setting | frame ms | penumbra MAE | MAE | ꟻLIP | >3se | shared passes |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r["scene"], r["light"])):
        for e in sorted(r["entries"], key=lambda e: (e["technique"], e["frame_ms"])):
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {setting_text(e)} | {e['frame_ms']:.1f} | {_err(e):.4f} | {e['error']['mae']:.4f} | "
                     f"{flip_text(e)} | {e['error'].get('frac_outside_3se', 0):.3f} | {len(e['shared_passes'])} |")
    md.write_text("\n".join(L) + "\n")
