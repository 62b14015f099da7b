"""Sweep ``ssm-table2``: scene x micro-occluder budget b_mo (5, the 5-12 radial budget map, 9, 10,
12, inf) — frame time, share of pixels that backproject, mean and standard deviation of the
micro-occluders each of them processes — beside Schwarz & Stamminger's Table 2, with the error
against the cached ray-traced reference.

Settings as the paper's results: a 1024^2 shadow map with a YSM (1024^2/256^2), jittered 16 x 16
occlusion bitmasks, micropatches; smooth LOQ and blending for finite budgets, none for inf.
"""

from __future__ import annotations

import math
from pathlib import Path

from wsoft.bench.common import counters, render_row, report_header, stage_ms

# Table 2 of the paper: (their figure, b_mo) -> (fps, % pixels backprojecting, mean, stdev of micro-occluders)
PAPER = [
    ("Fig. 1 b", "fig1_plant", "5", 82.6, 15.6, 33.3, 13.7),
    ("Fig. 1 d", "fig1_plant", "5-12", 35.8, 13.0, 164, 138),
    ("Fig. 1 c", "fig1_plant", "12", 27.1, 11.7, 480, 313),
    ("Fig. 1", "fig1_plant", "inf", 23.9, 11.0, 548, 351),
    ("Fig. 8", "fig8_tree", "9", 46.7, 9.2, 158, 80.2),
    ("Fig. 8", "fig8_tree", "inf", 15.0, 8.0, 1372, 1003),
    ("Fig. 10 a", "palm_dino", "10", 24.8, 12.7, 194, 84.8),
    ("Fig. 10 b", "palm_dino", "inf", 7.1, 11.2, 3632, 2166),
]
SCENES = ["fig1_plant", "fig8_tree", "palm_dino"]
BUDGETS = ["5", "5-12", "9", "10", "12", "inf"]
BASE = {"shadow_map_size": 1024, "structure": "ysm", "occluder": "micropatch", "visibility": "bitmask", "bitmask_size": 16, "pattern": "jittered"}


def budget_params(b: str) -> dict:
    if b == "5-12":
        return {"budget": 12.0, "budget_map": "radial", "budget_min": 5.0}
    return {"budget": math.inf if b == "inf" else float(b)}


def cases(quick: bool, devices: list[str]) -> list[dict]:
    scenes = ["fig1_plant"] if quick else SCENES
    budgets = ["5", "5-12", "inf"] if quick else BUDGETS
    w, h = (160, 120) if quick else (640, 480)
    out = []
    for dev in devices:
        for scene in scenes:
            for b in budgets:
                out.append({"kind": "render", "scene": scene, "light": None, "device": dev, "width": w, "height": h,
                            "ref_samples": 64 if quick else 256, "technique": "ssm", "budget": b,
                            "params": BASE | budget_params(b), "image": False})
    return out


def run_case(case: dict, ctx: dict) -> dict:
    row = render_row(case, ctx)
    row["budget"] = case["budget"]
    return row


def _ssm(r: dict, name: str):
    return counters(r)[name]


def shadow_ms(r: dict) -> float:
    return stage_ms(r, "structure", "search", "smooth", "backprojection")


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    L = report_header("ssm-table2", rows, md, ctx)
    L.append("`ssm` with a 1024² map, YSM 1024²/256², micropatches, jittered 16×16 occlusion bitmasks; `5-12` is the radial")
    L.append("budget map of the paper's Fig. 1d (12 at the centre, 5 at the left and right borders). Finite budgets smooth the")
    L.append("LOQ map (11×11) and blend levels; `inf` uses level 0 with neither. `backprojecting` = share of covered pixels")
    L.append("that backproject; `mean`/`stdev` = micro-occluders processed per backprojecting pixel (both levels when")
    L.append("blending). `frame ms` is the whole frame (G-buffer, light depth map, structures, search, backprojection,")
    L.append("shading); `ssm ms` only the technique's passes. Our scenes are analogues of the paper's (not its models), seen")
    res = ", ".join(sorted({f"{r['width']}×{r['height']}" for r in rows})) or "?"
    L.append(f"at {res} rather than 1024×768, and our times are CPU times (threads below), so compare the trends.")
    L.append("")
    L.append("`backprojecting (all)` = the same share over every pixel (background included; the paper does not say which it")
    L.append("uses); `search width` = mean side of the backprojecting pixels' search areas in level-0 texels (the work a pixel")
    L.append("would do at level 0 is about its square: read the budget speed-up against it).")
    L.append("")
    L.append("| scene | b_mo | device | frame ms | ssm ms | backprojecting | backprojecting (all) | search width | mean | stdev | levels used | MAE | MAE penumbra |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    order = {b: i for i, b in enumerate(BUDGETS)}
    for r in sorted(rows, key=lambda r: (r["device"], r["scene"], order.get(r["budget"], 99))):
        lv = _ssm(r, "levels_used")
        lv_s = " ".join(f"{k}:{v}" for k, v in sorted(lv.items(), key=lambda kv: int(kv[0])))
        L.append(f"| {r['scene']} | {r['budget']} | {r['device']} | {r['timings_ms']['total']:.1f} | {shadow_ms(r):.1f} | "
                 f"{100 * _ssm(r, 'backprojecting_fraction'):.1f}% | {100 * counters(r).get('backprojecting_fraction_all_pixels', float('nan')):.1f}% | "
                 f"{counters(r).get('search_width_mean_texels', float('nan')):.0f} | {_ssm(r, 'occluders_mean'):.1f} | {_ssm(r, 'occluders_stdev'):.1f} | "
                 f"{lv_s} | {r['error']['mae']:.4f} | {r['error']['mae_penumbra']:.4f} |")
    L += ["", "## The paper's Table 2 (GeForce 8800 GTX, 1024×768)", ""]
    L.append("| paper scene | our analogue | b_mo | fps | pixels | avg | stdev |")
    L.append("|---|---|---|---|---|---|---|")
    for fig, scene, b, fps, pix, avg, sd in PAPER:
        L.append(f"| {fig} | {scene} | {b} | {fps} | {pix}% | {avg} | {sd} |")
    L += ["", "## Targets", ""]
    by = {(r["device"], r["scene"], r["budget"]): r for r in rows}
    for dev in sorted({r["device"] for r in rows}):
        a, b = by.get((dev, "fig1_plant", "5")), by.get((dev, "fig1_plant", "inf"))
        if a and b:
            f = b["timings_ms"]["total"] / a["timings_ms"]["total"]
            s = shadow_ms(b) / max(shadow_ms(a), 1e-9)
            L.append(f"- b_mo = 5 at least 2.5× faster than b_mo = ∞ on `fig1_plant` ({dev}): frame {b['timings_ms']['total']:.1f} / "
                     f"{a['timings_ms']['total']:.1f} ms = **{f:.1f}×** ({'met' if f >= 2.5 else 'NOT met'}); technique passes alone "
                     f"{shadow_ms(b):.1f} / {shadow_ms(a):.1f} ms = {s:.1f}×. (Paper: 82.6 / 23.9 fps = {82.6 / 23.9:.1f}×.)")
    L.append("")
    spans = []
    for scene in sorted({r["scene"] for r in rows}):
        sh = [100 * _ssm(r, "backprojecting_fraction") for r in rows if r["scene"] == scene]
        spans.append(f"{scene} {min(sh):.1f}–{max(sh):.1f}%")
    L.append(f"The share of backprojecting pixels over the budgets: {'; '.join(spans)} (the paper: 11.0% at ∞ to 15.6% at 5 on")
    L.append("Fig. 1). Only the lit / umbra decision uses the region grown to the support of the coarser micro-occluders (§6);")
    L.append("for micropatches that growth only snaps the region to the level's cells, so the share hardly moves with the budget")
    L.append("here (the search area itself, which sets the refinement and the level, is not grown). Two umbra conditions go beyond the")
    L.append("paper's text: a pixel is umbra only when its grown region lies inside the map and every texel there is nearer")
    L.append("than the receiver's tangent plane anywhere in it (so the receiver's own surface never makes it umbra).")
    inf_row = next((r for r in rows if r["scene"] == "fig1_plant" and r["budget"] == "inf"), None)
    if inf_row is not None:
        wdt = counters(inf_row).get("search_width_mean_texels", float("nan"))
        L.append(f"A mean search width of {wdt:.0f} texels at b_mo = ∞ on fig1_plant is ~{wdt * wdt:,.0f} texels a pixel at level 0")
        L.append(f"({_ssm(inf_row, 'occluders_mean'):,.0f} micro-occluders processed on average), against about 23 × 23 for the paper's 548")
        L.append("micro-occluders a pixel: our light is larger relative to the scene, so a budget saves far more here than the")
        L.append("paper's 3.5× (which is against a ~23-texel search).")
    md.write_text("\n".join(L) + "\n")
