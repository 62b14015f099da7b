"""Sweep ``filtered``: the filtered shadow maps (pcf, pcss, vsm, esm, salzman) x shadow-map size
x each technique's main quality parameter, against the cached reference, with the reference's own
error at low sample counts for scale; Salzman with and without its far bound and at 8 vs 32
bits, and the torch-under-the-bridge images.

On ``lightmapped_bridge`` Salzman's map holds the dynamic casters only, so its rows are measured
against a reference whose occluders are the dynamic casters (``casters=dynamic``).
"""

from __future__ import annotations

from pathlib import Path

from wsoft.bench.common import (accuracy_table, counters, error_vs_time, image_list, lowest_mae, params_text, render_references, render_row,
                                report_header)

TECHNIQUES = ("pcf", "pcss", "vsm", "esm", "salzman")  # each swept over its main quality knob (Technique.quality[0])


def main_knob(name: str):
    """A technique's main quality knob (parameter, values) as the technique declares it."""
    from wsoft.techniques import get_technique

    q = get_technique(name).quality[0]
    return q.param, list(q.values)
DYNAMIC_SCENES = {"lightmapped_bridge"}
FULL_VIEWS = [("box_plane", None), ("contact", None), ("penumbra_ramp", None), ("lightmapped_bridge", "Sun")]
QUICK_VIEWS = [("box_plane", None)]


references = render_references  # each render row's reference: error-only jobs of a distributed sweep (wsoft.bench.dist)


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = []
    views = QUICK_VIEWS if quick else FULL_VIEWS
    w, h = (160, 120) if quick else (640, 480)
    sizes = [512] if quick else [512, 1024, 2048]
    ref_samples = 64 if quick else 256
    for dev in devices:
        for scene, light in views:
            base = {"kind": "render", "scene": scene, "light": light, "device": dev, "width": w, "height": h, "ref_samples": ref_samples}
            for tech in TECHNIQUES:
                name, values = main_knob(tech)
                values = values[1:2] if quick else values
                for size in sizes:
                    for v in values:
                        image = size == sizes[len(sizes) // 2] and v == values[len(values) // 2]
                        row = base | {"technique": tech, "params": {"shadow_map_size": size, name: v}, "image": image}
                        if tech == "salzman" and scene in DYNAMIC_SCENES:
                            row["ref_casters"] = "dynamic"
                        out.append(row)
            # Salzman's variants: without the far bound, and stored in 8 bits
            mid = sizes[len(sizes) // 2]
            for variant in ({"far_bound": False}, {"bits": 8}, {"far_bound": False, "bits": 8}):
                row = base | {"technique": "salzman", "params": {"shadow_map_size": mid, "radius": 4, **variant}, "image": False}
                if scene in DYNAMIC_SCENES:
                    row["ref_casters"] = "dynamic"
                out.append(row)
            for n in ([4] if quick else [4, 16, 64]):
                out.append(base | {"technique": "reference", "params": {"samples": n, "seed": 1}, "image": False})
        if not quick:
            out.append({"kind": "torch", "scene": "lightmapped_bridge", "light": "Sun", "device": dev, "width": 640, "height": 480})
        from wsoft.stages.failures import FAILURES

        for name in FAILURES:
            out.append({"kind": "failure", "name": name, "device": dev, "width": 192, "height": 192})
    return out


def run_case(case: dict, ctx: dict) -> dict:
    if case.get("kind") == "torch":
        return torch_images(case, ctx)
    if case.get("kind") == "failure":
        return failure_images(case, ctx)
    return render_row(case, ctx)


def failure_images(case: dict, ctx: dict) -> dict:
    """A known failure (wsoft.stages.failures): the technique, the reference and their difference."""
    import wsoft
    from wsoft.bench.common import params_label, side_by_side
    from wsoft.stages.failures import FAILURES

    build, tech, params, ref_params = FAILURES[case["name"]]
    scene = wsoft.load_scene(build())
    kw = dict(width=case["width"], height=case["height"], device=case["device"])
    fs = wsoft.compare(scene, [(tech, params), ("reference", ref_params)], **kw)
    fr, ref = fs[tech], fs["reference"]
    label = params_label(tech, params)
    info = {"scene": case["name"], "light": None, "technique": tech, "device": case["device"], "ref_samples": ref_params["samples"],
            "ref_casters": ref_params.get("casters", "all")}
    image = side_by_side(info, label, fr.V, ref.V, ref["A"], ctx)
    return {"name": case["name"], "technique": tech, "params": params, "image": image, "error": fr.stats["error"]}


def torch_images(case: dict, ctx: dict) -> dict:
    """The paper's torch under the bridge: the lightmap masked by Salzman's map with and without
    the far bound (R G B side by side)."""
    import numpy as np
    from PIL import Image, ImageDraw

    import wsoft
    from wsoft.bench.harness import load
    from wsoft.io import to_srgb8

    scene = load(case["scene"])
    panels, stats = [], {}
    for far in (True, False):
        fr = wsoft.render(scene, "salzman", width=case["width"], height=case["height"], light=case["light"], device=case["device"], far_bound=far)
        panels.append(np.stack([to_srgb8(fr[c]) for c in "RGB"], -1))
        stats[f"far_bound={far}"] = fr.stats["timings_ms"]["total"]
    h, w = panels[0].shape[:2]
    img = Image.new("RGB", (2 * w, h + 18), (255, 255, 255))
    for i, p in enumerate(panels):
        img.paste(Image.fromarray(p, "RGB"), (i * w, 18))
    d = ImageDraw.Draw(img)
    d.text((4, 3), "salzman, far bound on: the torch still lights the riverbed", fill=(0, 0, 0))
    d.text((w + 4, 3), "far bound off: the character's shadow masks the torch under the bridge", fill=(0, 0, 0))
    rel = Path("images") / ctx["stem"] / "torch_under_the_bridge.png"
    (ctx["out_dir"] / rel).parent.mkdir(parents=True, exist_ok=True)
    img.save(ctx["out_dir"] / rel)
    return {"scene": case["scene"], "device": case["device"], "image": str(rel), "frame_ms": stats}


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    torch = [r for r in rows if r["case"].get("kind") == "torch"]
    failures = [r for r in rows if r["case"].get("kind") == "failure"]
    rows = [r for r in rows if r["case"].get("kind") not in ("torch", "failure")]
    L = report_header("filtered", rows, md, ctx)
    sizes = sorted({r["params"]["shadow_map_size"] for r in rows if "shadow_map_size" in r["params"]})
    knobs = {t: main_knob(t)[0] for t in TECHNIQUES}
    swept = {t: sorted({r["params"][knobs[t]] for r in rows if r["technique"] == t}) for t in TECHNIQUES}
    ref_n = sorted({r["params"]["samples"] for r in rows if r["technique"] == "reference"})
    L.append(f"Each technique runs at shadow-map sizes {', '.join(map(str, sizes))} and the values of its main quality parameter")
    L.append("(declared by the technique, `Technique.quality`): " + "; ".join(f"{t}: {knobs[t]} {', '.join(f'{v:g}' for v in swept[t])}" for t in TECHNIQUES) + ".")
    L.append(f"`reference` rows are the ray tracer itself at {', '.join(map(str, ref_n))} samples, for scale. Salzman")
    L.append("also runs without its far bound and at 8 bits. On `lightmapped_bridge` its map holds only the dynamic")
    L.append("casters (character, ball), so it is measured against a reference whose occluders are those casters; there")
    L.append("the far bound *removes* the character's shadow from the riverbed under the deck (which that reference counts")
    L.append("as occluded) — the point is the lighting: with it the torch under the bridge is not masked (image below).")
    L.append("")
    L += accuracy_table(rows)
    best = lowest_mae(rows)
    L += ["", "## Lowest MAE per scene and technique", "", "| scene | technique | params | frame ms | MAE | MAE penumbra |", "|---|---|---|---|---|---|"]
    for (scene, tech), r in sorted(best.items()):
        p = params_text(r["case"]["params"])
        L.append(f"| {scene} | {tech} | {p} | {r['timings_ms']['total']:.1f} | {r['error']['mae']:.4f} | {r['error']['mae_penumbra']:.4f} |")
    variant_sizes = {r["params"]["shadow_map_size"] for r in rows if r["technique"] == "salzman" and not r["params"]["far_bound"]}
    sal = [r for r in rows if r["technique"] == "salzman" and r["params"]["radius"] == 4 and r["params"]["shadow_map_size"] in variant_sizes]
    if sal:
        L += ["", "## Salzman: far bound and storage", "", "| scene | far bound | bits | frame ms | MAE | MAE penumbra | fraction blurred | receivers rejected by the grid |", "|---|---|---|---|---|---|---|---|"]
        for r in sorted(sal, key=lambda r: (r["scene"], not r["params"]["far_bound"], r["params"]["bits"])):
            c = counters(r)
            L.append(f"| {r['scene']} | {r['params']['far_bound']} | {r['params']['bits']} | {r['timings_ms']['total']:.1f} | {r['error']['mae']:.4f} | "
                     f"{r['error']['mae_penumbra']:.4f} | {c['fraction_blurred']:.3f} | {c['receivers_rejected_by_grid']:.3f} |")
    L += error_vs_time(rows, md, ctx, f"filtered: {', '.join(TECHNIQUES)} over map size and quality; reference over samples")
    L += image_list(rows, f"technique at map {sizes[len(sizes) // 2] if sizes else '?'} and its middle quality, reference, |difference| x4")
    for t in torch:
        L += ["", "## The torch under the bridge (Salzman's far bound)", "", f"![torch]({t['image']})"]
    if failures:
        L += ["", "## Known failures (each pinned by a test; scenes in `wsoft/stages/failures.py`)", ""]
        what = {
            "pcss_overlapping_blockers": "PCSS: blockers at two depths average too near the light; the filter grows and light enters the lower occluder's umbra.",
            "vsm_stacked_occluders": "VSM: an upper occluder's edge over a lower one's umbra; the variance lets light bleed in (bleed reduction 0 here).",
            "esm_contact": "ESM: a thin plate just above the ground; exp(-c (z - d)) stays above 0 and light leaks into the contact shadow (c = 20 here).",
            "salzman_receiver_between_casters": "Salzman: a shelf between two casters; the blur averages their depths and the shelf escapes near the upper caster's edge.",
        }
        for f in failures:
            L += [f"**{f['name']}**: {what.get(f['name'], '')} MAE {f['error']['mae']:.4f}.", "", f"![{f['name']}]({f['image']})", ""]
    md.write_text("\n".join(L) + "\n")
