"""Sweep ``filtered``: the filtered shadow maps (pcf, pcss, vsm, esm) x shadow-map size x each
technique's main quality parameter, against the cached reference, with the reference's own
error at low sample counts for scale.
"""

from __future__ import annotations

from pathlib import Path

from bench.common import accuracy_table, error_vs_time, image_list, render_row, report_header

# technique -> (main quality parameter, its values, fixed parameters)
QUALITY = {
    "pcf": ("taps", [4, 16, 64], {"radius": 2.0}),
    "pcss": ("filter_samples", [16, 36, 100], {"blocker_samples": 16}),
    "vsm": ("radius", [1, 2, 4], {}),
    "esm": ("c", [40.0, 80.0, 160.0], {}),
}
FULL_VIEWS = [("box_plane", None), ("contact", None), ("penumbra_ramp", None), ("lightmapped_bridge", "Sun")]
QUICK_VIEWS = [("box_plane", None)]


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = []
    views = QUICK_VIEWS if quick else FULL_VIEWS
    w, h = (160, 120) if quick else (640, 480)
    sizes = [512] if quick else [512, 1024, 2048]
    ref_samples = 64 if quick else 256
    for dev in devices:
        for scene, light in views:
            base = {"kind": "render", "scene": scene, "light": light, "device": dev, "width": w, "height": h, "ref_samples": ref_samples}
            for tech, (name, values, fixed) in QUALITY.items():
                values = values[1:2] if quick else values
                for size in sizes:
                    for v in values:
                        image = size == sizes[len(sizes) // 2] and v == values[len(values) // 2]
                        out.append(base | {"technique": tech, "params": {"shadow_map_size": size, name: v, **fixed}, "image": image})
            for n in ([4] if quick else [4, 16, 64]):
                out.append(base | {"technique": "reference", "params": {"samples": n, "seed": 1}, "image": False})
    return out


def run_case(case: dict, ctx: dict) -> dict:
    return render_row(case, ctx)


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    L = report_header("filtered", rows, md, ctx)
    L.append("Each technique runs at shadow-map sizes 512, 1024 and 2048 and three values of its main quality parameter")
    L.append("(pcf: taps at radius 2 texels; pcss: filter taps with 16 blocker taps; vsm: prefilter radius; esm: exponent c);")
    L.append("`reference` rows are the ray tracer itself at 4, 16 and 64 samples, for scale. `salzman` joins this sweep")
    L.append("when it lands (issue 3 is not finished).")
    L.append("")
    L += accuracy_table(rows)
    best = {}
    for r in rows:
        key = (r["scene"], r["technique"])
        if key not in best or r["error"]["mae"] < best[key]["error"]["mae"]:
            best[key] = r
    L += ["", "## Lowest MAE per scene and technique", "", "| scene | technique | params | frame ms | MAE | MAE penumbra |", "|---|---|---|---|---|---|"]
    for (scene, tech), r in sorted(best.items()):
        p = ", ".join(f"{k}={v}" for k, v in r["case"]["params"].items())
        L.append(f"| {scene} | {tech} | {p} | {r['timings_ms']['total']:.1f} | {r['error']['mae']:.4f} | {r['error']['mae_penumbra']:.4f} |")
    L += error_vs_time(rows, md, ctx, "filtered: pcf, pcss, vsm, esm over map size and quality; reference over samples")
    L += image_list(rows, "technique at map 1024 and its middle quality, reference, |difference| x4")
    md.write_text("\n".join(L) + "\n")
