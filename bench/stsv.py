"""Sweep ``stsv``: Forest et al. 2009 (soft textured shadow volumes) measured here: ``dcs``
(depth complexity sampling) and ``pwedge`` (penumbra wedges), each with STSV for perforated
triangles.

* **Fig. 11** — ``fence_perforated`` (2 alpha-textured triangles, STSV) against ``fence_mesh`` (the
  same fence as ~224k opaque triangles in flat strips, silhouette edges) with ``dcs`` (and
  ``pwedge``) at 16 samples: frame time and error against the reference (paper: 90 vs 3.3 fps,
  27x), and the two fences' references against each other (they must cast the same shadow).
* **Figs. 8–9** — per scene (the paper's three: ``hl2_like``, ``factory``, ``greece``) and light,
  frame time and per-pass times at 720x576 and 1024² for 16 and 64 samples, for ``pwedge`` + STSV, ``dcs`` + STSV (``v_coef``) and ``dcs`` with
  the Monte-Carlo direct-lighting estimator, with the techniques' counters and pwedge's LS_buffer
  memory (exactly samples x pixels bits).
* **Fig. 4(a)** — ``wedge_overlap``: the penumbra wedges' overlap artifact beside ``dcs`` and the
  reference (images).
* **Fig. 5** — error and noise against the reference per sample distribution (stratified, Poisson
  disk at the paper's minimum distances, (0,2)-sequence, uniform random), decorrelated between
  pixels by rotation, 4x4 interleaving or a new set per pixel, on ``fence_perforated``.
* **§5.2** — against ``ssm`` (MSSM, 1024² map) on ``factory``.
* **Targets** — ``dcs`` and ``pwedge`` at 64 stratified samples against the *exact* answer
  (:mod:`wsoft.metrics.exact`) on ``box_plane`` and on ``cutout``'s checkerboard fence: penumbra
  MAE <= 0.03.

Errors come from the frame graph's metric pass against the cached reference (``bench common``),
except the targets' rows, measured against the closed form on the ground pixels it holds for.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from wsoft.bench.common import params_text, render_row

FIG8_SCENES = ("hl2_like", "factory", "greece")  # the paper's three test scenes (the fences are Fig. 11's)
PATTERNS = ("stratified", "poisson", "sobol02", "random")
VARIANTS = (("pwedge", {}), ("dcs", {}), ("dcs", {"estimator": "direct"}))  # Figs. 8-9: the frameworks, and dcs's two estimators


def _lights(scene: str) -> list[str]:
    from wsoft.bench.harness import load

    return [l.path for l in load(scene).lights]


def cases(quick: bool, devices: list[str]) -> list[dict]:
    w, h = (180, 144) if quick else (720, 576)
    ref = 64 if quick else 1024
    out = []
    for dev in devices:
        base = {"device": dev, "width": w, "height": h, "ref_samples": ref}
        for scene in ("fence_perforated", "fence_mesh"):
            for tech in ("dcs", "pwedge"):
                out.append(base | {"kind": "fig11", "scene": scene, "light": None, "technique": tech, "params": {"samples": 16}, "image": True})
        out.append({"kind": "fence_refs", "device": dev, "width": w, "height": h, "ref_samples": ref})
        out.append({"kind": "fig11_rounds", "device": dev, "width": w, "height": h, "rounds": 3})
        for scene in (("fence_perforated", "factory") if quick else FIG8_SCENES):
            for light in (_lights(scene)[:1] if quick else _lights(scene)):
                scene_ref = {"ref_samples": 64 if quick else 256}  # per light of every scene: fewer reference samples
                for tech, params in VARIANTS:
                    for n in ((16,) if quick else (16, 64)):
                        row = base | scene_ref | {"kind": "scene", "scene": scene, "light": light, "technique": tech, "params": params | {"samples": n}}
                        out.append(row)
                        if not quick:
                            out.append(row | {"width": 1024, "height": 1024})
        for tech in ("pwedge", "dcs"):
            out.append(base | {"kind": "overlap", "scene": "wedge_overlap", "light": None, "technique": tech, "params": {"samples": 64}, "image": True})
        for pattern in (("stratified", "poisson") if quick else PATTERNS):
            for dec in ("rotate", "interleave", "per_pixel"):
                if dec == "per_pixel" and pattern in ("poisson", "sobol02"):
                    continue  # generated on the host only: no per-pixel sets
                out.append(base | {"kind": "fig5", "scene": "fence_perforated", "light": None, "technique": "dcs",
                                   "params": {"samples": 16, "pattern": pattern, "decorrelate": dec}})
        for tech, params in (("dcs", {"samples": 16}), ("pwedge", {"samples": 16}), ("ssm", {"shadow_map_size": 1024})):
            out.append(base | {"kind": "mssm", "scene": "factory", "light": None, "technique": tech, "params": params, "image": True})
        for scene in ("box_plane", "cutout"):
            for tech in ("dcs", "pwedge"):
                out.append({"kind": "target", "scene": scene, "device": dev, "technique": tech, "params": {"samples": 64, "pattern": "stratified"},
                            "width": 160 if quick else 320, "height": 120 if quick else 240})
    return out


def run_case(case: dict, ctx: dict) -> dict:
    if case["kind"] == "target":
        return _target(case)
    if case["kind"] == "fence_refs":
        return _fence_refs(case)
    if case["kind"] == "fig11_rounds":
        return _fig11_rounds(case)
    row = render_row(case, ctx, extra=_off_by if case["kind"] == "overlap" else None)
    row["kind"] = case["kind"]
    return row


def _off_by(frame, ref) -> dict:
    """Pixels whose V is off the reference's by more than 0.1 (Fig. 4(a)'s artifact)."""
    covered = ref["A"] > 0
    return {"off_by_0_1": int((np.abs(frame.V - ref["V"]) > 0.1)[covered].sum())}


def _fence_refs(case: dict) -> dict:
    """``fence_mesh``'s cached reference against ``fence_perforated``'s (same view, light, samples
    and seed, so the difference is the geometry's, not the sampling's) on the pixels both cover."""
    from wsoft.bench.harness import reference

    kw = {"width": case["width"], "height": case["height"], "light": None, "samples": case["ref_samples"], "device": case["device"]}
    a, b = reference("fence_perforated", **kw), reference("fence_mesh", **kw)
    both = (a["A"] > 0) & (b["A"] > 0)
    pen = both & (((a["V"] > 0.01) & (a["V"] < 0.99)) | ((b["V"] > 0.01) & (b["V"] < 0.99)))
    d = (b["V"] - a["V"])
    return {"kind": "fence_refs", "width": case["width"], "height": case["height"], "ref_samples": case["ref_samples"], "pixels": int(both.sum()),
            "penumbra_pixels": int(pen.sum()), "mean_dv": float(d[both].mean()), "mean_abs_dv": float(np.abs(d[both]).mean()),
            "mean_dv_penumbra": float(d[pen].mean()), "mean_abs_dv_penumbra": float(np.abs(d[pen]).mean()), "max_abs_dv": float(np.abs(d[both]).max()),
            "stderr_mean": float(a["V_stderr"][both].mean())}


def _fig11_rounds(case: dict) -> dict:
    """Fig. 11's ratio in alternating rounds in one process: ``dcs`` (16 samples) on ``fence_mesh``
    and on ``fence_perforated`` (STSV), one after the other, ``rounds`` times after a warm-up of each."""
    import wsoft
    from wsoft.bench.harness import load

    kw = {"width": case["width"], "height": case["height"], "device": case["device"], "samples": 16}
    scenes = {n: load(n) for n in ("fence_perforated", "fence_mesh")}
    for s in scenes.values():
        wsoft.render(s, "dcs", **kw)  # compile and warm
    times = {n: [] for n in scenes}
    for _ in range(case["rounds"]):
        for n, s in scenes.items():
            t0 = time.perf_counter()
            wsoft.render(s, "dcs", **kw)
            times[n].append(1e3 * (time.perf_counter() - t0))
    ratios = [m / p for m, p in zip(times["fence_mesh"], times["fence_perforated"])]
    return {"kind": "fig11_rounds", "width": case["width"], "height": case["height"], "times_ms": times, "ratios": ratios,
            "median_ratio": float(np.median(ratios))}


def _target(case: dict) -> dict:
    """Penumbra MAE against the closed form on the ground pixels it holds for (median-of-3 time)."""
    import wsoft
    from wsoft.bench.harness import load
    from wsoft.metrics.exact import CUTOUT, cutout_exact, parallel_rect_exact

    scene = load(case["scene"])
    kw = dict(width=case["width"], height=case["height"], device=case["device"], **case["params"])
    wsoft.render(scene, case["technique"], **kw)  # compile
    times, fr = [], None
    for _ in range(3):
        t0 = time.perf_counter()
        fr = wsoft.render(scene, case["technique"], **kw)
        times.append(time.perf_counter() - t0)
    g = (fr["A"] > 0) & (np.abs(fr["P.Z"]) < 1e-3)
    if case["scene"] == "box_plane":
        exact = parallel_rect_exact(fr["P.X"], fr["P.Y"], 3.0, 1.0, 1.0, 0.5)
    else:
        exact = cutout_exact(fr["P.X"], fr["P.Y"])
        g &= fr["P.X"] < CUTOUT["x_max"]
    err = np.abs(fr.V - exact)[g]
    pen = ((exact > 0.01) & (exact < 0.99))[g]
    return {"kind": "target", "scene": case["scene"], "technique": case["technique"], "params": case["params"], "device": case["device"],
            "width": case["width"], "height": case["height"], "frame_ms": 1e3 * float(np.median(times)), "pixels": int(g.sum()),
            "penumbra_pixels": int(pen.sum()), "mae": float(err.mean()), "mae_penumbra": float(err[pen].mean()), "max": float(err.max())}


def _c(row: dict) -> dict:
    t = row["counters"]["techniques"].get(row["technique"], {})
    return t.get(row["light_label"], {})


def _own_ms(row: dict) -> float:
    return float(sum(ms for name, ms in row["timings_ms"].items() if row["pass_kinds"].get(name) in ("technique", "light_map")))


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = report_header("stsv", [r for r in rows if r.get("kind") != "target"], md, ctx)
    L += ["Forest et al. 2009: `dcs` (depth complexity sampling) and `pwedge` (penumbra wedges), each with soft "
          "textured shadow volumes (STSV) for alpha-perforated triangles. Both run on this CPU: the paper's figures are a GPU's.", ""]
    by = lambda k: [r for r in rows if r.get("kind") == k]  # noqa: E731
    f11 = {(r["scene"], r["technique"]): r for r in by("fig11")}
    L += ["## Fig. 11: 2 perforated triangles (STSV) against the same fence as opaque geometry", "",
          "| scene | technique | triangles | frame ms | technique passes ms | MAE | MAE penumbra | image |", "|---|---|---|---|---|---|---|---|"]
    for s in ("fence_perforated", "fence_mesh"):
        for t in ("dcs", "pwedge"):
            r = f11.get((s, t))
            if r:
                L.append(f"| {s} | {t} | {r['counters']['frame']['triangles']:,} | {r['timings_ms']['total']:.1f} | {_own_ms(r):.1f} | "
                         f"{r['error']['mae']:.4f} | {r['error']['mae_penumbra']:.4f} | ![]({r.get('image', '')}) |")
    for r in by("fence_refs"):
        ok = r["mean_abs_dv"] <= 0.01
        L += ["", f"The two fences' references ({r['width']}x{r['height']}, {r['ref_samples']} samples, the same samples): fence_mesh's V "
              f"minus fence_perforated's over the {r['pixels']:,} pixels both cover: mean {r['mean_dv']:+.4f}, mean |ΔV| {r['mean_abs_dv']:.4f} "
              f"(max {r['max_abs_dv']:.3f}); on the {r['penumbra_pixels']:,} penumbra pixels mean {r['mean_dv_penumbra']:+.4f}, mean |ΔV| "
              f"{r['mean_abs_dv_penumbra']:.4f}; a reference's mean standard error there is {r['stderr_mean']:.4f}. Target mean |ΔV| <= 0.01 "
              f"(the two fences cast the same shadow, so the ratio below compares equal work): **{'met' if ok else 'not met'}**. "
              "fence_mesh's strips lie in the texture's plane where its texels are opaque (`wsoft.stages.scenes.stsv.fence_wires`)."]
    for t in ("dcs", "pwedge"):
        a, b = f11.get(("fence_perforated", t)), f11.get(("fence_mesh", "dcs"))
        if a and b:
            ratio = b["timings_ms"]["total"] / a["timings_ms"]["total"]
            own = _own_ms(b) / max(_own_ms(a), 1e-9)
            met = ratio >= 25.0
            L += ["", f"Frame time ratio fence_mesh with dcs / fence_perforated with {t} (STSV): **{ratio:.1f}x** (technique passes alone "
                  f"{own:.1f}x); target >= 25x at comparable error: **{'met' if met else 'not met'}** (penumbra MAE "
                  f"{a['error']['mae_penumbra']:.4f} vs {b['error']['mae_penumbra']:.4f})."]
    for r in by("fig11_rounds"):
        t = r["times_ms"]
        L += ["", f"In alternating rounds in one process ({r['width']}x{r['height']}, dcs at 16 samples on both, {len(r['ratios'])} rounds after a "
              f"warm-up; the rows above time each scene on its own): fence_mesh {', '.join(f'{x:.0f}' for x in t['fence_mesh'])} ms, "
              f"fence_perforated {', '.join(f'{x:.0f}' for x in t['fence_perforated'])} ms; ratio per round "
              f"{', '.join(f'{x:.1f}' for x in r['ratios'])}, median **{r['median_ratio']:.1f}x** (target >= 25x: "
              f"**{'met' if r['median_ratio'] >= 25 else 'not met'}**)."]
    L += ["", "Paper: 90 vs 3.3 fps (27x) on a GPU. Fig. 4's panels (a) pwedge + STSV and (b) dcs + STSV beside the reference are "
          "the fence_perforated images above (only perforated triangles cast there, so the two agree bit for bit); the wedges' "
          "overlap artifact of panel (a) is shown on wedge_overlap below.", "", "## Figs. 8–9: per scene and light", "",
          "Reference: 256 samples per pixel here (1024 for Figs. 11 and 5 and §5.2). `dcs direct` is the Monte-Carlo direct-lighting "
          "estimator (each sample weighted by its unshadowed irradiance); its V is a different quantity from the reference's plain "
          "fraction of samples, so part of its error is that difference. LS_buffer: pwedge's per-pixel STSV bitmask, "
          "`samples x pixels` bits exactly (the 'bits/px' column is its measured size over the frame's pixels).", "",
          "| scene | light | res | technique | samples | frame ms | G-buffer ms | technique passes (ms) | silhouette / potential edges | "
          "receiver-edge tests | perforated | STSV tests | LS_buffer KiB (bits/px) | grid MiB | MAE | MAE penumbra |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(by("scene"), key=lambda r: (r["scene"], r["light"], r["width"], r["params"]["samples"], r["technique"], params_text(r["params"]))):
        c = _c(r)
        passes = ", ".join(f"{n.split('[')[0]} {ms:.0f}" for n, ms in r["timings_ms"].items() if r["pass_kinds"].get(n) in ("technique", "light_map"))
        tech = r["technique"] + (" direct" if r["params"].get("estimator") == "direct" else "")
        ls = c.get("ls_buffer_bytes")
        ls_text = f"{ls / 1024:.0f} ({8 * ls / (r['width'] * r['height']):g})" if ls is not None else "–"
        L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['width']}x{r['height']} | {tech} | {r['params']['samples']} | "
                 f"{r['timings_ms']['total']:.0f} | {sum(ms for n, ms in r['timings_ms'].items() if r['pass_kinds'].get(n) == 'gbuffer'):.0f} | "
                 f"{passes} | {c.get('silhouette_edges', c.get('potential_edges', 0)):,} | {c.get('wedge_tests', 0):,} | "
                 f"{c.get('perforated_triangles', 0):,} | {c.get('stsv_tests', 0):,} | {ls_text} | "
                 f"{c.get('grid_bytes', 0) / 2**20:.1f} | {r['error']['mae']:.4f} | {r['error']['mae_penumbra']:.4f} |")
    sc = by("scene")
    pairs = [(a, b) for a in sc for b in sc if a["technique"] == "pwedge" and b["technique"] == "dcs" and b["params"].get("estimator", "v_coef") == "v_coef"
             and (a["scene"], a["light"], a["width"], a["params"]["samples"]) == (b["scene"], b["light"], b["width"], b["params"]["samples"])]
    if pairs:
        tr = [a["timings_ms"]["total"] / b["timings_ms"]["total"] for a, b in pairs]
        bits = [8 * _c(a)["ls_buffer_bytes"] == a["params"]["samples"] * a["width"] * a["height"] for a, _ in pairs if "ls_buffer_bytes" in _c(a)]
        L += ["", f"Over the {len(pairs)} (scene, light, resolution, samples) settings: pwedge's frame time is {min(tr):.2f}–{max(tr):.2f}x dcs's "
              f"(median {float(np.median(tr)):.2f}x); its penumbra MAE is lower than dcs's in "
              f"{sum(a['error']['mae_penumbra'] < b['error']['mae_penumbra'] for a, b in pairs)} of them. "
              f"LS_buffer exactly samples x pixels bits: {sum(bits)} of {len(bits)} rows with perforated triangles."]
    same = lambda r: (r["scene"], r["light"], r["width"], r["params"]["samples"])  # noqa: E731
    plain = {same(r): r for r in sc if r["technique"] == "dcs" and r["params"].get("estimator", "v_coef") == "v_coef"}
    direct = [(r, plain[same(r)]) for r in sc if r["params"].get("estimator") == "direct" and same(r) in plain]
    if direct:
        dr = [a["timings_ms"]["total"] / b["timings_ms"]["total"] for a, b in direct]
        L += ["", f"dcs's direct-lighting estimator takes {min(dr):.2f}–{max(dr):.2f}x (median {float(np.median(dr)):.2f}x) the "
              f"frame time of its v_coef over {len(dr)} settings: the per-sample weights cost little beside the counts."]
    L += ["", "## Fig. 4(a): overlapping silhouettes (wedge_overlap, 64 samples)", "",
          "| technique | frame ms | MAE | MAE penumbra | pixels off by > 0.1 | receivers clamped | image |", "|---|---|---|---|---|---|---|"]
    for r in by("overlap"):
        L.append(f"| {r['technique']} | {r['timings_ms']['total']:.0f} | {r['error']['mae']:.4f} | {r['error']['mae_penumbra']:.4f} | "
                 f"{r.get('off_by_0_1', 0):,} | {_c(r).get('clamped', '–')} | ![]({r.get('image', '')}) |")
    L += ["", "pwedge adds the covered areas of overlapping silhouettes: too dark where the light's centre is visible past both sheets, too "
          "light where both hide it, and the fence card's LS_buffer bits add to SheetD's wedge coverage (the paper's Fig. 4(a) fence). "
          "dcs counts per light sample and has none of it. `tests/test_pwedge.py` checks pwedge against the closed form of the artifact."]
    L += ["", "## Fig. 5: sample distributions on fence_perforated (16 samples)", "",
          "| pattern | between pixels | frame ms | MAE | RMSE | MAE penumbra |", "|---|---|---|---|---|---|"]
    for r in by("fig5"):
        p = r["case"]["params"]
        L.append(f"| {p['pattern']} | {p['decorrelate']} | {r['timings_ms']['total']:.0f} | {r['error']['mae']:.4f} | {r['error']['rmse']:.4f} | "
                 f"{r['error']['mae_penumbra']:.4f} |")
    f5 = by("fig5")
    if f5:
        m = [r["error"]["mae_penumbra"] for r in f5]
        L += ["", f"Penumbra MAE spans {min(m):.4f}–{max(m):.4f} over these {len(f5)} settings ({(max(m) - min(m)) / min(m):.1%} of the "
              "smallest): at 16 samples every setting decorrelates the pixels, and the per-pixel sampling error (a binomial "
              "standard error of up to 0.125 at 16 samples) dominates the differences between distributions."]
    L += [""]
    L += ["## §5.2: against `ssm` (MSSM) on factory", "", "| technique | params | frame ms | MAE | MAE penumbra | image |", "|---|---|---|---|---|---|"]
    for r in by("mssm"):
        L.append(f"| {r['technique']} | {params_text(r['case']['params'])} | {r['timings_ms']['total']:.0f} | {r['error']['mae']:.4f} | "
                 f"{r['error']['mae_penumbra']:.4f} | ![]({r.get('image', '')}) |")
    m = {r["technique"]: r for r in by("mssm")}
    q = m.get("ssm")
    for t in ("dcs", "pwedge"):
        d = m.get(t)
        if d and q:
            L += ["", f"{t} takes {d['timings_ms']['total'] / q['timings_ms']['total']:.2f}x ssm's frame time at penumbra MAE "
                  f"{d['error']['mae_penumbra']:.4f} against {q['error']['mae_penumbra']:.4f}."]
    if q:
        L += ["", "Paper: STSV 5x faster than MSSM and better quality, on a GPU; here all run on this CPU."]
    L += [""]
    L += ["## Targets: dcs and pwedge at 64 stratified samples against the exact answer", "",
          "| scene | technique | res | frame ms | ground pixels | penumbra pixels | MAE | MAE penumbra | max | target (penumbra MAE <= 0.03) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in by("target"):
        L.append(f"| {r['scene']} | {r['technique']} | {r['width']}x{r['height']} | {r['frame_ms']:.0f} | {r['pixels']:,} | {r['penumbra_pixels']:,} | {r['mae']:.4f} | "
                 f"{r['mae_penumbra']:.4f} | {r['max']:.3f} | {'met' if r['mae_penumbra'] <= 0.03 else 'not met'} |")
    L += ["", "Exact answers: `wsoft.metrics.exact` (box_plane: a square occluder parallel to the light; cutout: the fence's 8x8 "
          "checkerboard cells, its ground where x < 1.9, out of the opaque box's reach)."]
    md.write_text("\n".join(L) + "\n")
