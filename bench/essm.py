"""Sweep ``essm``: what ESSM's accuracy costs in time on the paper-analog scenes — ESSM over its map
size, H, rasterization level X, micro-subdivision n, precision bits μ and SAT storage, against VSSM
and brute-force PCSS over map size and the reference's own sample count, all measured against the
cached 256-sample reference; plus ESSM's hard cases (contact umbra, non-planar kernel with and
without micro-subdivision) as images.
"""

from __future__ import annotations

from pathlib import Path

from bench.common import accuracy_table, error_vs_time, image_list, lowest_mae, render_row, report_header, side_by_side

FULL_VIEWS = [("ogre", None), ("plants", None), ("dinosaurs", None), ("city", "Rect")]
QUICK_VIEWS = [("box_plane", None)]
# ESSM variations at 1024² (one parameter at a time from the paper's defaults): group -> list of params
VARIATIONS = {
    "H": [{"H": 2.0}, {"H": 10.0}],
    "X": [{"level": 1}, {"level": 2}],
    "n": [{"subdivision": 1}, {"subdivision": 5}],
    "mu": [{"mu": 16}, {"mu": 24}],
    "sat": [{"sat": "uint32"}, {"sat": "float32"}],
    "c": [{"c": 8.0}, {"c": 20.0}, {"c": 27.7}],  # around the optimal R = 13.9 of the μ = 20 tile grid
}


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = []
    views = QUICK_VIEWS if quick else FULL_VIEWS
    w, h = (160, 120) if quick else (640, 480)
    sizes = [512] if quick else [512, 1024, 2048]
    ref_samples = 64 if quick else 256
    for dev in devices:
        for scene, light in views:
            base = {"kind": "render", "scene": scene, "light": light, "device": dev, "width": w, "height": h, "ref_samples": ref_samples}
            for tech in ("essm", "vssm", "pcss"):
                for size in sizes:
                    image = size == (512 if quick else 1024)
                    out.append(base | {"technique": tech, "params": {"shadow_map_size": size}, "image": image, "group": f"{tech} map size"})
            if not quick:
                for group, variants in VARIATIONS.items():
                    for v in variants:
                        out.append(base | {"technique": "essm", "params": {"shadow_map_size": 1024, **v}, "image": False, "group": f"essm {group}"})
            for n in ([4] if quick else [4, 16, 64]):
                out.append(base | {"technique": "reference", "params": {"samples": n, "seed": 1}, "image": False, "group": "reference samples"})
        for name in ("contact_box", "nonplanar", "nonplanar_no_subdivision"):
            out.append({"kind": "case", "name": name, "device": dev, "width": 192, "height": 192})
    return out


def run_case(case: dict, ctx: dict) -> dict:
    if case["kind"] == "case":
        return hard_case(case, ctx)
    row = render_row(case, ctx, extra=lambda fr, ref: facing_error(case, fr, ref))
    row["group"] = case["group"]
    return row


def facing_error(case: dict, fr, ref) -> dict:
    """The error over receivers that face the light's centre only: where the geometric answer is
    not simply 0 because the surface turns away from the light (ESM and VSM leak there, a depth
    test does not)."""
    import numpy as np

    from bench.harness import load
    from wsoft.metrics import visibility_error
    from wsoft.scene.types import LIGHT_DISTANT

    light = next(li for li in load(case["scene"]).lights if li.path == fr.stats["light"])
    n = np.stack([fr["N.X"], fr["N.Y"], fr["N.Z"]], -1)
    if light.kind == LIGHT_DISTANT:
        facing = n @ light.frame[:, 2] > 0.0
    else:
        p = np.stack([fr["P.X"], fr["P.Y"], fr["P.Z"]], -1)
        facing = np.einsum("...i,...i->...", n, light.position - p) > 0.0
    return {"error_facing": visibility_error(fr.V, ref["V"], ref["V_stderr"], ref["A"] * facing),
            "fraction_facing": float(facing[ref["A"] > 0].mean())}


CASES = {
    # name -> (builder name, ESSM params, what it shows)
    "contact_box": ("essm_contact_box", {}, "a cube on the ground: the umbra stays dark up to the contact line"),
    "nonplanar": ("essm_nonplanar", {}, "a plate between an occluder above and the ground below, 3x3 micro-subdivision"),
    "nonplanar_no_subdivision": ("essm_nonplanar", {"subdivision": 1}, "the same without micro-subdivision: the clamped ESM lights the plate's penumbra"),
}


def hard_case(case: dict, ctx: dict) -> dict:
    import wsoft
    from bench import essm_cases
    from wsoft.metrics import visibility_error

    builder, params, _ = CASES[case["name"]]
    scene = wsoft.load_scene(getattr(essm_cases, builder)())
    kw = {"width": case["width"], "height": case["height"], "device": case["device"]}
    fr = wsoft.render(scene, "essm", **kw, **params)
    ref = wsoft.render(scene, "reference", **kw, samples=256)
    label = "essm " + " ".join(f"{k}={v}" for k, v in params.items())
    info = {"scene": case["name"], "light": None, "technique": "essm", "device": case["device"], "ref_samples": 256}
    image = side_by_side(info, label, fr.V, ref.V, ref["A"], ctx)
    brighter = float((fr.V - ref.V)[ref["A"] > 0].max())
    return {"name": case["name"], "params": params, "image": image, "error": visibility_error(fr.V, ref.V, ref["V_stderr"], ref["A"]),
            "max_brighter_than_reference": brighter}


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    hard = [r for r in rows if r["case"]["kind"] == "case"]
    renders = [r for r in rows if r["case"]["kind"] == "render"]
    L = report_header("essm", rows, md, ctx)
    L.append("ESSM (paper defaults: μ = 20 tile grid, 3x3 micro-subdivision, H = 5, Level0, optimal c) at map sizes 512-2048, and")
    L.append("one parameter at a time at 1024² (H 2/10, level X 1/2, subdivision n 1/5, μ 16/24, full uint32 / float32 SAT, c 8/20/27.7);")
    L.append("VSSM (float32 SAT, 5x5 subdivision) and brute-force PCSS (16 blocker + 36 filter taps) over map size; the reference")
    L.append("ray tracer at 4/16/64 samples for scale.")
    L.append("")
    L += accuracy_table(renders)
    best = lowest_mae(renders)
    L += ["", "## Lowest MAE per scene and technique", "",
          "`MAE facing`: over the receivers whose normal faces the light's centre only (the rest are turned away from the light,",
          "where the answer is 0 and ESM/VSM's leak shows; a depth test, as in PCSS, gets them right).", "",
          "| scene | technique | params | frame ms | MAE | MAE penumbra | MAE facing | fraction facing |", "|---|---|---|---|---|---|---|---|"]
    for (scene, tech), r in sorted(best.items()):
        p = ", ".join(f"{k}={v}" for k, v in r["case"]["params"].items())
        fe = r.get("error_facing", {}).get("mae", float("nan"))
        L.append(f"| {scene} | {tech} | {p} | {r['timings_ms']['total']:.1f} | {r['error']['mae']:.4f} | {r['error']['mae_penumbra']:.4f} | "
                 f"{fe:.4f} | {r.get('fraction_facing', float('nan')):.2f} |")
    defaults = [r for r in renders if r["technique"] in ("essm", "vssm", "pcss") and r["case"]["params"] == {"shadow_map_size": 1024}]
    if defaults:
        L += ["", "## At 1024², default parameters", "", "| scene | technique | frame ms | MAE | MAE facing | MAE penumbra |", "|---|---|---|---|---|---|"]
        for r in sorted(defaults, key=lambda r: (r["scene"], r["technique"])):
            fe = r.get("error_facing", {}).get("mae", float("nan"))
            L.append(f"| {r['scene']} | {r['technique']} | {r['timings_ms']['total']:.1f} | {r['error']['mae']:.4f} | {fe:.4f} | {r['error']['mae_penumbra']:.4f} |")
    # one line per (technique, swept parameter) in the plot
    plot_rows = [r | {"technique": r.get("group", r["technique"])} for r in renders]
    L += error_vs_time(plot_rows, md, ctx, "essm over map size / H / X / n / mu / SAT storage / c; vssm, pcss over map size; reference over samples")
    L += image_list(renders, "ESSM, VSSM and PCSS at map 1024, reference, |difference| x4")
    if hard:
        L += ["", "## Hard cases (pinned by tests/test_essm.py)", ""]
        for r in hard:
            what = CASES[r["name"]][2]
            text = (f"**{r['name']}**: {what}. MAE {r['error']['mae']:.4f}; largest excess over the reference (incorrectly lit) "
                    f"{r['max_brighter_than_reference']:.3f}.")
            L += [text, "", f"![{r['name']}]({r['image']})", ""]
    md.write_text("\n".join(L) + "\n")
