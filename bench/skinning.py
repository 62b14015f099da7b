"""Sweep ``skinning``: what UsdSkel's posing costs, and the skinned character's shadows in motion.

Two kinds of row:

* ``cost``: a sheet of N points (N = 10³ … 10⁶; quick 10³, 10⁴) hanging 1 above a ground under a
  rect light, skinned to a chain of four joints with four influences a point, by linear blending
  and by dual quaternions. At time code 10 (the chain bent) the row times, in :data:`ROUNDS`
  alternating rounds in one process (medians): wsoft's posing of the sheet at load (the stats'
  ``skin``: blend shapes, skinning transforms, the skinning kernel), usd-core's own
  ``SkinningQuery.ComputeSkinnedPoints`` on the same points (the peer), the whole load
  (``load_scene``), and one frame of ``hard`` and ``pcss`` at 320 x 240 with its passes (the
  G-buffer, the scene's upload, the technique's passes).
* ``sequence``: the bundled ``walker`` (a 12-joint figure stepping and waving) over frames
  :data:`FRAMES`, every technique that supports its rect light at its defaults against the
  reference at :data:`GROUND_TRUTH` samples per frame (:func:`wsoft.metrics.sequences.compare_sequence`):
  mean penumbra MAE over the frames, flicker against the reference's, and frame time.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

POINTS = (1_000, 10_000, 100_000, 1_000_000)
QUICK_POINTS = (1_000, 10_000)
METHODS = ("classicLinear", "dualQuaternion")
ROUNDS = 3
FRAME = (320, 240)
FRAMES, QUICK_FRAMES = "1:48:4", "1:9:4"
SIZE, QUICK_SIZE = (256, 192), (64, 48)
GROUND_TRUTH, QUICK_GROUND_TRUTH = 256, 32


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = []
    for dev in devices:
        for n in QUICK_POINTS if quick else POINTS:
            for m in METHODS:
                out.append({"kind": "cost", "points": n, "method": m, "device": dev, "width": FRAME[0] // (4 if quick else 1),
                            "height": FRAME[1] // (4 if quick else 1)})
        w, h = QUICK_SIZE if quick else SIZE
        out.append({"kind": "sequence", "scene": "walker", "frames": QUICK_FRAMES if quick else FRAMES, "device": dev, "width": w, "height": h,
                    "ground_truth": QUICK_GROUND_TRUTH if quick else GROUND_TRUTH, "quick": quick})
    return out


def sheet_stage(n: int, method: str):
    """A skinned sheet of about ``n`` points (a square grid over [-1.5, 1.5]², 1 above a ground of ±4),
    a chain of four joints along x bending about y by 20° each at time code 10, a 1 x 1 rect light 4 up."""
    from pxr import UsdGeom

    from wsoft.stages.builders import add_camera, add_quad, add_rect_light, make_stage
    from wsoft.stages.skel import add_skeleton, add_skinned_bar

    stage = make_stage()
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(10)
    add_quad(stage, "/World/Ground", (0, 0, 0), 4)
    add_rect_light(stage, "/World/Light", (0, 0, 4), 1.0, 1.0)
    add_camera(stage, "/World/Cam", (0, -0.01, 8), (0, 0, 0))
    side = max(2, int(round(np.sqrt(n))))
    u = np.linspace(-1.5, 1.5, side)
    x, y = np.meshgrid(u, u, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), np.ones(side * side)], 1)
    i, j = np.meshgrid(np.arange(side - 1), np.arange(side - 1), indexing="ij")
    a = (i * side + j).ravel()
    quads = np.stack([a, a + side, a + side + 1, a + 1], 1)
    joints = ["j0", "j0/j1", "j0/j1/j2", "j0/j1/j2/j3"]
    offsets = [(-1.5, 0.0, 1.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0)]
    poses = {0: [((0, 1, 0), 0.0)] * 4, 10: [((0, 1, 0), 0.0)] + [((0, 1, 0), 20.0)] * 3}
    add_skeleton(stage, "/World/Char", joints, offsets, poses)
    centers = np.array([-1.0, 0.0, 1.0, 2.0]) - 0.5
    w = np.exp(-((pts[:, :1] - centers[None]) / 0.8) ** 2)
    w /= w.sum(1, keepdims=True)
    mesh = add_skinned_bar(stage, "/World/Char/Sheet", "/World/Char/Skel", pts, [4] * len(quads), quads.ravel(),
                           np.tile(np.arange(4), len(pts)), w.ravel(), 4, method=method)
    UsdGeom.Mesh(mesh).CreateDoubleSidedAttr(True)
    return stage


def _usd_skin_ms(stage, t: float) -> float:
    """usd-core's ComputeSkinnedPoints of the sheet at ``t`` (the skinning transforms computed first, untimed)."""
    from pxr import UsdGeom

    from wsoft.stages.skel import usd_skinning

    prim = stage.GetPrimAtPath("/World/Char/Sheet")
    query, target = usd_skinning(prim)
    xf = query.ComputeSkinningTransforms(t)
    pts = UsdGeom.Mesh(prim).GetPointsAttr().Get(t)
    t0 = time.perf_counter()
    ok = target.ComputeSkinnedPoints(xf, pts, t)
    ms = (time.perf_counter() - t0) * 1e3
    assert ok
    return ms


def _cost(case: dict) -> dict:
    import wsoft

    stage = sheet_stage(case["points"], case["method"])
    kw = dict(width=case["width"], height=case["height"], device=case["device"])
    wsoft.render(wsoft.load_scene(stage, time=10.0), ["hard", "pcss"], **kw)  # warm-up: compiles
    runs: dict[str, list[float]] = {}
    passes: dict[str, list[dict]] = {"hard": [], "pcss": []}
    for _ in range(ROUNDS):
        t0 = time.perf_counter()
        scene = wsoft.load_scene(stage, time=10.0)
        runs.setdefault("load_ms", []).append((time.perf_counter() - t0) * 1e3)
        runs.setdefault("skin_ms", []).append(scene.skin_ms)
        runs.setdefault("usd_skin_ms", []).append(_usd_skin_ms(stage, 10.0))
        for tech in ("hard", "pcss"):
            fr = wsoft.render(scene, tech, **kw)
            runs.setdefault(f"{tech}_total_ms", []).append(fr.stats["timings_ms"]["total"])
            passes[tech].append(fr.stats["timings_by_kind_ms"])
    med = {k: float(statistics.median(v)) for k, v in runs.items()}
    kinds = {t: {k: float(statistics.median([p.get(k, 0.0) for p in ps])) for k in ps[0]} for t, ps in passes.items()}
    return {"kind": "cost", "points": int(scene.points.shape[0]) - 4, "triangles": scene.triangle_count, "method": case["method"],
            "device": case["device"], "width": case["width"], "height": case["height"], **med, "runs": runs, "passes_by_kind_ms": kinds}


def _sequence(case: dict) -> dict:
    from wsoft.bench.harness import load
    from wsoft.bench.temporal import measure_sequence
    from wsoft.pipeline.build import refusal
    from wsoft.techniques import TECHNIQUES

    name = case["scene"]
    scene = load(name)
    light = scene.lights[0]
    techs = [(t, {"samples": 16} if t == "reference" else {}) for t in sorted(TECHNIQUES) if refusal(t, scene, light) is None]
    seq, labels, ll, _ = measure_sequence(name, light.path, techs, case)
    entries = []
    for (tech, params), label in zip(techs, labels):
        frames = [fs[label] for fs in seq.frames]
        entries.append({"technique": tech, "label": label, "params": params,
                        "frame_ms": float(np.median([f.stats["timings_ms"]["total"] for f in frames])),
                        "skin_ms": float(np.median([f.stats["timings_ms"].get("skin", 0.0) for f in frames])),
                        "mae_penumbra": float(np.mean([f.stats["error"]["mae_penumbra"] for f in frames])),
                        "temporal": seq.summary["temporal"][label][ll]})
    return {"kind": "sequence", "scene": name, "light": light.path, "device": case["device"], "width": case["width"],
            "height": case["height"], "frames": seq.times, "ground_truth_samples": case["ground_truth"], "entries": entries,
            "warnings": seq.warnings}


def run_case(case: dict, ctx: dict) -> dict:
    return _cost(case) if case["kind"] == "cost" else _sequence(case)


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from matplotlib import colormaps

    from wsoft.bench.common import report_header

    colours = colormaps["tab10"]
    L = [line for line in report_header("skinning", rows, md, ctx) if not line.startswith(("Error is against", "penumbra =", "Times:", "Rows:"))]
    cost = sorted((r for r in rows if r["kind"] == "cost"), key=lambda r: (r["method"], r["points"]))
    seqs = [r for r in rows if r["kind"] == "sequence"]
    L.insert(-1, f"Rows: {len(cost)} on a skinned sheet (posing cost), {len(seqs)} on `walker` (in motion); device "
                 f"{', '.join(sorted({r['device'] for r in rows}))}.")
    if cost:
        L.insert(-1, "The machine was shared while these rows ran: read times as ratios within a row (its rounds alternate).")
    if cost:
        L += ["## What posing costs", "",
              f"A skinned sheet (four joints, four influences a point) at time code 10; {ROUNDS} alternating rounds in one process, "
              "medians. *skin*: wsoft's posing at load (the stats' `skin`); *usd-core*: `ComputeSkinnedPoints` on the same points "
              "(the peer); *load*: the whole `load_scene`; then one frame of `hard` and `pcss` (their G-buffer, upload and "
              f"technique passes, at {cost[0]['width']}x{cost[0]['height']}).", "",
              "| method | points | triangles | skin ms | usd-core ms | usd-core / skin | load ms | hard frame ms | pcss frame ms | pcss technique passes ms |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in cost:
            L.append(f"| {r['method']} | {r['points']:,} | {r['triangles']:,} | {r['skin_ms']:.2f} | {r['usd_skin_ms']:.2f} | "
                     f"{r['usd_skin_ms'] / max(r['skin_ms'], 1e-9):.2f} | {r['load_ms']:.1f} | {r['hard_total_ms']:.1f} | "
                     f"{r['pcss_total_ms']:.1f} | {r['passes_by_kind_ms']['pcss'].get('technique', 0.0):.1f} |")
        for m in METHODS:
            rs = [r for r in cost if r["method"] == m]
            if rs:
                ratios = [r["usd_skin_ms"] / max(r["skin_ms"], 1e-9) for r in rs]
                faster = [r["points"] for r, q in zip(rs, ratios) if q > 1.0]
                L.append(f"* `{m}`: usd-core / wsoft {min(ratios):.2f}–{max(ratios):.2f}; wsoft's kernel is the faster "
                         + (f"from {min(faster):,} points." if faster else "at no size measured (usd-core's own loop is faster on this CPU)."))
        L.append("")
        fig, ax = plt.subplots(figsize=(6.4, 4.0))
        for k, m in enumerate(METHODS):
            rs = [r for r in cost if r["method"] == m]
            if rs:
                ax.loglog([r["points"] for r in rs], [r["skin_ms"] for r in rs], "o-", color=colours(k), label=f"wsoft skin ({m})")
                ax.loglog([r["points"] for r in rs], [r["usd_skin_ms"] for r in rs], "s--", color=colours(k), label=f"usd-core ({m})")
        rs = [r for r in cost if r["method"] == METHODS[0]]
        ax.loglog([r["points"] for r in rs], [r["load_ms"] for r in rs], "^:", color=colours(2), label="whole load_scene")
        ax.loglog([r["points"] for r in rs], [r["pcss_total_ms"] for r in rs], "v:", color=colours(3), label="pcss frame")
        ax.set_xlabel("points skinned")
        ax.set_ylabel("ms (median of rounds)")
        ax.set_title("UsdSkel posing against the frame's other costs")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        rel = Path("images") / ctx["stem"] / "skin_cost.png"
        (ctx["out_dir"] / rel).parent.mkdir(parents=True, exist_ok=True)
        fig.tight_layout()
        fig.savefig(ctx["out_dir"] / rel, dpi=120)
        plt.close(fig)
        L += ["", f"![skinning time against points, beside usd-core's and the frame's]({rel.as_posix()})", ""]
    for r in (r for r in rows if r["kind"] == "sequence"):
        L += [f"## `{r['scene']}` in motion", "",
              f"Frames {r['frames'][0]:g} to {r['frames'][-1]:g} ({len(r['frames'])} frames), {r['width']}x{r['height']}, light "
              f"`{r['light']}`; every technique at its defaults (the reference at 16 samples) against the reference at "
              f"{r['ground_truth_samples']} samples per frame. *flicker*: the technique's frame-to-frame change beyond the ground "
              "truth's (`wsoft.metrics.temporal`).", "",
              "| technique | mean penumbra MAE | flicker | frame ms (median) | skin ms (load) |", "|---|---:|---:|---:|---:|"]
        for e in sorted(r["entries"], key=lambda e: e["mae_penumbra"]):
            fl = e["temporal"].get("flicker")
            L.append(f"| {e['label']} | {e['mae_penumbra']:.4f} | {fl:.4f} | {e['frame_ms']:.1f} | {e['skin_ms']:.2f} |" if fl is not None
                     else f"| {e['label']} | {e['mae_penumbra']:.4f} | - | {e['frame_ms']:.1f} | {e['skin_ms']:.2f} |")
        if r["warnings"]:
            L += ["", "Warnings: " + "; ".join(r["warnings"])]
        L.append("")
    md.write_text("\n".join(L) + "\n")
