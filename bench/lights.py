"""Sweep ``lights``: lights as production stages author them, against closed forms and the reference.

Rows (:func:`cases`):

* ``cone_edge``: a 30° point spot (``UsdLux.ShapingAPI``) 3 over a bare ground
  (:func:`~wsoft.stages.light_cases.spot_stage`), ``reference`` and ``hard``: where the lit disc
  of the shaded image ends against the analytic edge ``3 tan 30°``, in pixels (the largest distance
  of a pixel lit outside the cone or dark inside it from the edge).
* ``spot_cost``: a 30° spot (a sphere light of radius 0.1 with a box under it) against the same
  light without ``ShapingAPI``, for ``hard``, ``pcss`` and ``pwedge`` at their defaults: the time
  of the technique's passes (the light views and maps and its own passes: pass kinds ``light_map``
  and ``technique``), the median of :data:`SPOT_ROUNDS` rounds alternating the two stages.
* ``dome_convergence``: a uniform dome over a parallel square (the reference at 16 to 1024 rays,
  8 seeds each): the standard error it reports, the spread of V over the seeds, the error against
  ``V = 1 - F`` (:func:`~wsoft.stages.light_cases.form_factor`) and the share within 3 reported
  standard errors.
* ``dome_cap``: the reference's textured path (a latlong polar cap, MIS and the ratio estimator)
  against :func:`~wsoft.stages.light_cases.cap_visibility` at 256 rays.
* ``dome_technique``: every registered technique that takes a dome (``dome_refusal == ""``, the
  registry's, not a list here) on ``dome_uniform`` and ``dusk_street``'s sky, at its defaults: the
  error against the cached reference (256 rays) and the frame's time (median of 3).

Times are Warp's scalar CPU backend unless the row's device says otherwise.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

import numpy as np

from wsoft.bench.harness import cache_dir

SPOT_TECHS = ("hard", "pcss", "pwedge")
DOME_SAMPLES = (16, 64, 256, 1024)
QUICK_DOME_SAMPLES = (16, 256)
SEEDS = 8
DOME_SCENES = (("dome_uniform", "/World/Sky"), ("dusk_street", "/World/Lights/Sky"))
REF_SAMPLES = 256


def dome_techniques() -> list[str]:
    """The registered techniques that render a dome, the reference aside."""
    from wsoft.techniques import TECHNIQUES

    return sorted(n for n, c in TECHNIQUES.items() if getattr(c, "dome_refusal", "x") == "" and n != "reference")


def cases(quick: bool, devices: list[str]) -> list[dict]:
    w, h = (96, 72) if quick else (160, 120)
    out = []
    for dev in devices:
        for tech in ("reference", "hard"):
            out.append({"kind": "cone_edge", "scene": "spot_cone_edge", "technique": tech, "device": dev, "width": w, "height": h})
        for tech in SPOT_TECHS:
            out.append({"kind": "spot_cost", "scene": "spot_cost", "technique": tech, "device": dev, "width": w, "height": h})
        out.append({"kind": "dome_convergence", "scene": "dome_square", "device": dev, "width": 64, "height": 48,
                    "samples": list(QUICK_DOME_SAMPLES if quick else DOME_SAMPLES), "seeds": 4 if quick else SEEDS})
        out.append({"kind": "dome_cap", "scene": "dome_cap", "device": dev, "width": 32, "height": 24, "samples": 256})
        for scene, light in DOME_SCENES:
            for tech in dome_techniques():
                out.append({"kind": "dome_technique", "scene": scene, "light": light, "technique": tech, "device": dev, "width": w, "height": h,
                            "ref_samples": 64 if quick else REF_SAMPLES, "quick": quick})
    return out


def run_case(case: dict, ctx: dict) -> dict:
    return {"cone_edge": _cone_edge, "spot_cost": _spot_cost, "dome_convergence": _dome_convergence, "dome_cap": _dome_cap,
            "dome_technique": _dome_technique}[case["kind"]](case)


def _stage_file(name: str, build) -> str:
    """A case's stage written once under the references' cache (``build(path)`` writes it)."""
    d = cache_dir() / "lights_stages"
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"{name}.usda"
    if not path.exists():
        st = build(str(path))
        st.GetRootLayer().Save()
    return str(path)


def _cone_edge(case: dict) -> dict:
    import wsoft
    from wsoft.stages.light_cases import SPOT_HEIGHT, off_axis_deg, spot_stage

    f = _stage_file("spot_point30", lambda p: spot_stage(30.0, box=False, point=True, path=p))
    params = {"samples": 16} if case["technique"] == "reference" else {}
    fr = wsoft.render(wsoft.load_scene(f), case["technique"], width=case["width"], height=case["height"], device=case["device"], **params)
    ground = (fr["A"] > 0) & (np.abs(fr["P.Z"]) < 1e-4)
    a = off_axis_deg(fr)
    gy, gx = np.gradient(np.where(ground, a, np.nan))
    per_px = np.nanmedian(np.hypot(gx, gy)[ground & (np.abs(a - 30.0) < 3.0)])  # degrees per pixel at the edge
    outside = ground & (a > 30.0)
    ambient = float(fr["R"][ground & (a > 33.0)].max())
    lit = fr["R"] > ambient * (1.0 + 1e-4)
    wrong = ground & ((lit & outside) | (~lit & ~outside))
    off = np.abs(a[wrong] - 30.0) / per_px
    return {"scene": "spot_cone_edge", "technique": case["technique"], "device": case["device"], "width": case["width"], "height": case["height"],
            "edge_radius": SPOT_HEIGHT * math.tan(math.radians(30.0)), "deg_per_px": float(per_px), "misclassified": int(wrong.sum()),
            "max_edge_offset_px": float(off.max()) if off.size else 0.0, "ground_pixels": int(ground.sum())}


SPOT_ROUNDS = 5


def _technique_ms(fr) -> float:
    """The light views and maps and the technique's own passes (:func:`wsoft.bench.common.shadow_ms`'s kinds)."""
    t = fr.stats["timings_by_kind_ms"]
    return float(sum(t.get(k, 0.0) for k in ("light_map", "technique", "reference")))


def _spot_cost(case: dict) -> dict:
    import wsoft

    from wsoft.stages.light_cases import spot_stage

    out = {"scene": "spot_cost", "technique": case["technique"], "device": case["device"], "width": case["width"], "height": case["height"]}
    kw = dict(width=case["width"], height=case["height"], device=case["device"])
    scenes = {label: wsoft.load_scene(_stage_file(f"spot_sphere_{label}", lambda p, c=cone: spot_stage(c, path=p)))
              for label, cone in (("shaped", 30.0), ("unshaped", None))}
    for sc in scenes.values():  # warm-up: kernels compile
        wsoft.render(sc, case["technique"], **kw)
    runs: dict[str, list] = {label: [] for label in scenes}
    for _ in range(SPOT_ROUNDS):  # alternating rounds: a load on the machine falls on both alike
        for label, sc in scenes.items():
            runs[label].append(wsoft.render(sc, case["technique"], **kw))
    for label, frames in runs.items():
        ms = [_technique_ms(r) for r in frames]
        med = frames[ms.index(statistics.median_low(ms))]
        tech = next(iter(med.stats["counters"]["techniques"].values()), {})
        light = next(iter(tech.values()), {}) if isinstance(tech, dict) else {}
        out[label] = {"technique_ms": statistics.median_low(ms), "runs_ms": ms, "frame_ms": med.stats["timings_ms"]["total"],
                      "cube_faces": light.get("cube_faces", []), "passes": [p for p in med.stats["timings_ms"] if p not in ("total", "compile")]}
    out["ratio"] = out["shaped"]["technique_ms"] / out["unshaped"]["technique_ms"]
    return out


def _dome_convergence(case: dict) -> dict:
    import wsoft
    from wsoft.stages.light_cases import dome_square_stage, form_factor

    f = _stage_file("dome_square", lambda p: dome_square_stage(path=p))
    scene = wsoft.load_scene(f)
    out = {"scene": "dome_square", "device": case["device"], "width": case["width"], "height": case["height"], "points": {}}
    exact = mask = None
    for n in case["samples"]:
        vs, es, ms = [], [], []
        for seed in range(case["seeds"]):
            t0 = time.perf_counter()
            fr = wsoft.render(scene, "reference", width=case["width"], height=case["height"], device=case["device"], samples=n, seed=seed)
            ms.append(fr.stats["timings_ms"]["total"] if seed else (time.perf_counter() - t0) * 1e3)
            if mask is None:
                P = np.stack([fr[f"P.{c}"] for c in "XYZ"], -1)
                mask = (fr["A"] > 0.99) & (np.abs(P[..., 2]) < 1e-4) & (np.abs(P[..., 0]) < 3) & (np.abs(P[..., 1]) < 3)
                exact = np.array([1.0 - form_factor(x, y) for x, y in P[mask][:, :2]])
            vs.append(fr.V[mask])
            es.append(fr["V_stderr"][mask])
        v, e = np.array(vs), np.array(es)
        spread = v.std(axis=0, ddof=1)
        err = v - exact
        out["points"][str(n)] = {
            "reported_se_mean": float(e.mean()), "reported_se_p95": float(np.percentile(e, 95)),
            "seed_sd_mean": float(spread.mean()), "seed_sd_p95": float(np.percentile(spread, 95)), "seed_sd_max": float(spread.max()),
            "rms_error": float(np.sqrt((err ** 2).mean())), "max_error": float(np.abs(err).max()), "bias": float(err.mean()),
            "within_3se": float((np.abs(err) <= 3.0 * np.maximum(e, 1e-12)).mean()),
            "frame_ms": float(statistics.median(ms[1:] if len(ms) > 1 else ms)),
        }
    out["pixels"] = int(mask.sum())
    out["v_min"] = float(exact.min())
    return out


def _dome_cap(case: dict) -> dict:
    import wsoft
    from wsoft.rgbe import write_rgbe
    from wsoft.stages.light_cases import cap_texture, cap_visibility, dome_square_stage

    d = cache_dir() / "lights_stages"
    d.mkdir(parents=True, exist_ok=True)
    write_rgbe(str(d / "cap.hdr"), cap_texture())
    f = _stage_file("dome_cap", lambda p: dome_square_stage("cap.hdr", path=p))
    fr = wsoft.render(wsoft.load_scene(f), "reference", width=case["width"], height=case["height"], device=case["device"], samples=case["samples"])
    P = np.stack([fr[f"P.{c}"] for c in "XYZ"], -1)
    m = (fr["A"] > 0.99) & (np.abs(P[..., 2]) < 1e-4) & (np.abs(P[..., 0]) < 3) & (np.abs(P[..., 1]) < 3)
    exact = np.array([cap_visibility(x, y) for x, y in P[m][:, :2]])
    err = fr.V[m] - exact
    e = fr["V_stderr"][m]
    return {"scene": "dome_cap", "device": case["device"], "width": case["width"], "height": case["height"], "samples": case["samples"],
            "pixels": int(m.sum()), "mae": float(np.abs(err).mean()), "max_error": float(np.abs(err).max()),
            "reported_se_mean": float(e.mean()), "within_3se": float((np.abs(err) <= 3.0 * np.maximum(e, 1e-12)).mean()),
            "frame_ms": fr.stats["timings_ms"]["total"]}


def _dome_technique(case: dict) -> dict:
    from wsoft.bench.common import render_row
    from wsoft.techniques import TECHNIQUES

    params = dict(TECHNIQUES[case["technique"]].quick_params) if case.get("quick") else {}
    row = render_row(case | {"params": params}, {})
    return {k: row[k] for k in ("scene", "technique", "params", "device", "width", "height", "light", "ref_samples", "timings_ms", "error",
                                "reference_ms", "warnings")} | {"frame_ms": row["timings_ms"]["total"]}


# -- the report -------------------------------------------------------------------------------------


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = report_header("lights", rows, md, ctx)
    L += ["Lights as production stages author them: `UsdLux.ShapingAPI` cones and the sky (`DomeLight`). Every time is Warp's "
          "scalar CPU backend on this machine unless the row's device says otherwise; no number here comes from elsewhere."]
    loads = [r["machine"]["load"] for r in rows if r.get("machine", {}).get("load") is not None]
    if loads:
        cores = rows[0]["machine"].get("cores", "?")
        L.append(f"The host's load (1-minute average) as the rows finished: {min(loads):.1f}-{max(loads):.1f} on {cores} cores: other "
                 "processes shared the CPU, so every time carries their noise (the spot's ratios come from alternating rounds).")
    L.append("")
    by = lambda k: [r for r in rows if r["case"]["kind"] == k]  # noqa: E731
    edges = by("cone_edge")
    if edges:
        r0 = edges[0]
        L += ["## The cone's edge on a plane", "",
              f"A point light 3 over a bare ground with `shaping:cone:angle = 30`: the lit disc's analytic edge is the circle of radius "
              f"3 tan 30° = {r0['edge_radius']:.4f}. A pixel is lit where its shaded R exceeds the ambient; the offset is the largest "
              "distance, in pixels (the off-axis angle's gradient at the edge), of a pixel lit outside the cone or dark inside it "
              "from the analytic edge.", "",
              "| technique | pixels | degrees / pixel at the edge | misclassified pixels | largest offset (px) | within 1 px |", "|---|---:|---:|---:|---:|---|"]
        for r in edges:
            L.append(f"| {r['technique']} | {r['width']}x{r['height']} | {r['deg_per_px']:.3f} | {r['misclassified']} | "
                     f"{r['max_edge_offset_px']:.2f} | {'yes' if r['max_edge_offset_px'] <= 1.0 else 'no'} |")
        L.append("")
    cost = by("spot_cost")
    if cost:
        L += ["## A 30° spot's cost against the same light unshaped", "",
              "A sphere light (radius 0.1) 3 over a ground ±5 with a 0.6 box under it, with `shaping:cone:angle = 30` and without "
              "`ShapingAPI`. Technique ms: the light views, depth maps and the technique's own passes (pass kinds `light_map` and "
              f"`technique`), the median of {SPOT_ROUNDS} rounds alternating the two stages after a warm-up of each. Target (issue): ≤ 0.4.", "",
              "| technique | pixels | shaped ms | unshaped ms | ratio | ≤ 0.4 | unshaped views |", "|---|---:|---:|---:|---:|---|---|"]
        for r in cost:
            faces = r["unshaped"]["cube_faces"]
            views = f"cube map, {len(faces)} faces" if faces else "one frustum"
            L.append(f"| {r['technique']} | {r['width']}x{r['height']} | {r['shaped']['technique_ms']:.1f} | {r['unshaped']['technique_ms']:.1f} | "
                     f"{r['ratio']:.2f} | {'yes' if r['ratio'] <= 0.4 else 'no'} | {views} |")
        L.append("")
    conv = by("dome_convergence")
    if conv:
        r = conv[0]
        L += ["## The dome reference: convergence and the analytic check", "",
              "A uniform dome over a 1 x 1 square at height 1 parallel to the ground: at a ground point V = 1 − F, F the "
              f"point-to-rectangle form factor (closed form, four corner rectangles superposed). {r['pixels']} ground pixels of "
              f"{r['width']}x{r['height']} (V down to {r['v_min']:.3f}); {r['case']['seeds']} seeds per sample count. The reported "
              "standard error is the reference's own (the independent-sampling bound sqrt(p(1-p)/N), as every reference reports); "
              "the seed spread is the standard deviation of V over the seeds (the stratified estimator's actual error); "
              "within 3 se: the share of pixels whose V lies within 3 reported standard errors of the closed form.", "",
              "| rays | reported se (mean / p95) | seed spread (mean / p95 / max) | RMS error | max error | bias | within 3 se | frame ms |",
              "|---:|---|---|---:|---:|---:|---:|---:|"]
        for n, p in r["points"].items():
            L.append(f"| {n} | {p['reported_se_mean']:.4f} / {p['reported_se_p95']:.4f} | {p['seed_sd_mean']:.4f} / {p['seed_sd_p95']:.4f} / "
                     f"{p['seed_sd_max']:.4f} | {p['rms_error']:.4f} | {p['max_error']:.4f} | {p['bias']:+.5f} | {100 * p['within_3se']:.1f}% | "
                     f"{p['frame_ms']:.0f} |")
        p256 = r["points"].get("256")
        if p256:
            L += ["", f"At 256 rays: the reported standard error averages {p256['reported_se_mean']:.4f} and the seeds' spread "
                  f"{p256['seed_sd_mean']:.4f} (the issue's target 0.005: "
                  f"{'met' if p256['seed_sd_mean'] <= 0.005 else 'not met'} by the spread, "
                  f"{'met' if p256['reported_se_mean'] <= 0.005 else 'not met'} by the reported bound)."]
        L.append("")
        L += _convergence_figure(r, md)
    cap = by("dome_cap")
    if cap:
        r = cap[0]
        L += ["## The textured dome: a polar cap", "",
              "A latlong sky of radiance 1 within 30° of the zenith and 0 elsewhere (a `.hdr` of 48 x 24 texels, the cap whole rows), "
              "over the same square: V = 1 − (the cap's cosine-weighted solid angle the square hides) / (π sin² 30°), by a midpoint "
              "quadrature of 300 x 600 cells. The reference's textured path: half its rays cosine-weighted, half drawn from the "
              "texture's 2D CDF, the balance heuristic's weights, V the ratio estimator.", "",
              "| rays | pixels | MAE | max error | reported se (mean) | within 3 se | frame ms |", "|---:|---:|---:|---:|---:|---:|---:|",
              f"| {r['samples']} | {r['pixels']} | {r['mae']:.4f} | {r['max_error']:.4f} | {r['reported_se_mean']:.4f} | "
              f"{100 * r['within_3se']:.1f}% | {r['frame_ms']:.0f} |", ""]
    techs = by("dome_technique")
    L += ["## Dome techniques", ""]
    if techs:
        L += ["Every registered technique that renders a dome (`dome_refusal` empty), at its defaults, on the bundled stages' skies; "
              "error against the cached reference on the same pixels; frame ms: median of 3 after a warm-up.", "",
              "| scene | technique | pixels | reference rays | MAE | penumbra MAE | frame ms |", "|---|---|---:|---:|---:|---:|---:|"]
        for r in sorted(techs, key=lambda r: (r["scene"], r["technique"])):
            e = r["error"]
            L.append(f"| {r['scene']} | {r['technique']} | {r['width']}x{r['height']} | {r['ref_samples']} | {e.get('mae', math.nan):.4f} | "
                     f"{e.get('mae_penumbra', math.nan):.4f} | {r['frame_ms']:.1f} |")
    else:
        L.append("No technique other than the reference renders a dome in this run (none is registered with `dome_refusal = \"\"`).")
    L.append("")
    md.write_text("\n".join(L) + "\n")


def _convergence_figure(row: dict, md: Path) -> list[str]:
    """Reported se, seed spread and RMS error against rays, log-log; the 1/sqrt(N) slope for scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.bench.common import log_ticks
    from wsoft.palette import style

    n = np.array([int(k) for k in row["points"]])
    ref = style("reference")
    fig, ax = plt.subplots(figsize=(5.5, 4.0))
    for key, label, ls in (("reported_se_mean", "reported se (mean)", "-"), ("seed_sd_mean", "spread over seeds (mean)", "--"),
                           ("rms_error", "RMS error vs closed form", ":")):
        ax.plot(n, [row["points"][str(k)][key] for k in n], ls, color=ref["color"], marker=ref["marker"] if ls == "-" else "o",
                markersize=5, label=label)
    ax.plot(n, 0.5 / np.sqrt(n), color="0.6", lw=0.8, label="0.5 / sqrt(N)")
    ax.axhline(0.005, color="0.3", lw=0.8, ls="-.", label="0.005")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rays per pixel (N)")
    ax.set_ylabel("error in V")
    ax.set_title("Dome reference: uniform dome over a parallel square")
    log_ticks(ax)
    ax.legend(fontsize=8)
    fig.tight_layout()
    png = md.with_name(md.stem + "-convergence.png")
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return [f"![convergence]({png.name})", ""]
