"""Sweep ``essm-table1``: Shen, Feng & Yang's Table 1 — ESSM's time per stage on the paper-analog
scenes (G-buffer GB; ESSM basis and pyramid EB, here including the light-view fit and the depth
map; SAT tile grid STG; shadowing), beside the paper's own numbers.

Paper settings: μ = 20, 3x3 micro-subdivision, H = 5, Level0, a rectangular light. The paper does
not give Table 1's map sizes; Traffic matches its Table 2 at 4096² (same STG and Shadow ms), so
``city`` runs at 4096² and the others at 1024².
"""

from __future__ import annotations

from pathlib import Path

from wsoft.bench.common import kind_ms, report_header, stage_ms
from wsoft.bench.harness import measure_render

# scene -> (light, map size, paper scene name, paper faces)
SCENES = {
    "ogre": (None, 1024, "Ogre", "135k"),
    "plants": (None, 1024, "Plants", "141k"),
    "dinosaurs": (None, 1024, "Dinosaurs", "869k"),
    "city": ("Rect", 4096, "Traffic", "1285k"),
}
# the paper's Table 1 (ms on a GeForce GTX 465, 1280x960): GB, EB, STG, Shadow, Total
PAPER = {
    "Ogre": (2.10, 0.21, 1.90, 4.13, 8.34),
    "Plants": (2.32, 0.56, 4.43, 4.62, 11.93),
    "Dinosaurs": (5.25, 0.52, 4.22, 3.51, 13.50),
    "Traffic": (16.4, 9.6, 41.3, 10.4, 77.7),
}


def cases(quick: bool, devices: list[str]) -> list[dict]:
    w, h = (160, 120) if quick else (640, 480)
    out = []
    for dev in devices:
        for scene, (light, size, _, _) in SCENES.items():
            if quick and scene != "ogre":
                continue
            out.append({"kind": "stages", "scene": scene, "light": light, "device": dev, "width": w, "height": h,
                        "params": {"shadow_map_size": 512 if quick else size}})
    return out


def stages(row: dict) -> dict:
    """Table 1's columns from a render's pass kinds and ESSM's stages: GB the G-buffer; EB the light
    view, depth map and basis; STG the SAT; Shadow the shading."""
    return {"GB": kind_ms(row, "gbuffer"), "EB": kind_ms(row, "light_map") + stage_ms(row, "basis"), "STG": stage_ms(row, "sat"),
            "Shadow": stage_ms(row, "shadow"), "Total": row["timings_ms"]["total"]}


def run_case(case: dict, ctx: dict) -> dict:
    fr = measure_render(case["scene"], "essm", case["params"], device=case["device"], width=case["width"], height=case["height"], light=case["light"])
    st = fr.stats
    c = fr.counters()
    row = {"scene": case["scene"], "light": st["light"], "device": st["device"], "triangles": st["scene"]["triangles"],
           "width": case["width"], "height": case["height"], "params": st["params"], "timings_ms": st["timings_ms"],
           "timings_by_kind_ms": st["timings_by_kind_ms"], "pass_stages": st["pass_stages"], "timings_ms_runs": st["timings_ms_runs"],
           "cpu_ms": st["cpu_ms"], "sat": c["sat"], "lookups_per_sample": c["lookups_per_sample"], "c_normalised": c["c_normalised"]}
    return row | {"stages_ms": stages(row)}


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    L = report_header("essm-table1", rows, md, ctx)
    L.append("Shen, Feng & Yang, Table 1, regenerated: ESSM's time per stage (ms), ours beside the paper's. Ours: this machine's")
    res = ", ".join(sorted({f"{r['width']}x{r['height']}" for r in rows})) or "?"
    L.append(f"CPU (Warp kernels, all cores), {res} eye samples, one rect light, the paper's defaults (μ = 20 tile grid from the")
    L.append("pyramid test, recursive doubling with 8 reads per pass, 3x3 micro-subdivision, H = 5, Level0). The paper: a GeForce")
    L.append("GTX 465 at 1280x960. Absolute times are not comparable across that gap; the *shares* of the stages are. EB here")
    L.append("includes fitting the light view and rasterizing the depth map (the paper's EB renders the basis textures).")
    L.append("")
    L.append("| scene (paper's) | triangles (paper's) | map | GB | EB | STG | Shadow | Total | paper GB | paper EB | paper STG | paper Shadow | paper Total | tile (tiles/side) | passes | look-ups / sample | our stage shares GB/EB/STG/Shadow | paper's shares |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in sorted(rows, key=lambda r: list(SCENES).index(r["scene"]) if r["scene"] in SCENES else 99):
        _, _, pname, pfaces = SCENES.get(r["scene"], (None, None, "?", "?"))
        s = r["stages_ms"]
        p = PAPER.get(pname, (float("nan"),) * 5)
        ours = [s["GB"], s["EB"], s["STG"], s["Shadow"]]
        tot = sum(ours)
        shares = "/".join(f"{100 * x / tot:.0f}%" for x in ours)
        pshares = "/".join(f"{100 * x / sum(p[:4]):.0f}%" for x in p[:4])
        L.append(f"| {r['scene']} ({pname}) | {r['triangles']:,} ({pfaces}) | {r['params']['shadow_map_size']} | {s['GB']:.1f} | {s['EB']:.1f} | {s['STG']:.1f} | "
                 f"{s['Shadow']:.1f} | {s['Total']:.1f} | {p[0]} | {p[1]} | {p[2]} | {p[3]} | {p[4]} | {r['sat']['tile']} ({r['sat']['tiles_per_side']}) | "
                 f"{r['sat']['passes']} | {r['lookups_per_sample']:.1f} | {shares} | {pshares} |")
    L.append("")
    L.append("Total is the whole frame (it also holds the scene-array, shading and resolve passes); the shares are of GB+EB+STG+Shadow.")
    md.write_text("\n".join(L) + "\n")
