"""Sweep ``izb``: the irregular z-buffer's anti-aliasing modes on ``tower`` and ``tunnel_fan`` against
a pixel-area reference (64 sub-pixel eye samples per pixel, each ray-traced to the light's centre),
their cost per pass beside the paper's estimate (extra cost = edge fraction x N), the stencil's
conservativeness (aliased pixels it missed), and ``hard`` at 1024²–8192² on ``tunnel_fan``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from wsoft.bench.harness import load

SCENES = ("tower", "tunnel_fan")
IZB_PASSES = ("izb_stencil", "izb_samples", "izb_grid", "izb_light", "izb_resolve", "light_depth", "fit_light_view")
AREA_SAMPLES = 64


def cases(quick: bool, devices: list[str]) -> list[dict]:
    res = [(160, 120)] if quick else [(320, 240)]
    out = []
    for dev in devices:
        for scene in SCENES:
            for w, h in res:
                base = {"kind": "izb", "scene": scene, "device": dev, "width": w, "height": h}
                settings = [{"aa": "none"}, {"aa": "supersample", "samples": 4}]
                settings += [{"aa": "adaptive", "samples": n} for n in ((4,) if quick else (4, 8, 16))]
                if not quick:
                    settings += [{"aa": "supersample", "samples": 8}, {"aa": "supersample", "samples": 16},
                                 {"aa": "adaptive", "samples": 4, "stencil_raster": "ordinary"},
                                 {"aa": "adaptive", "samples": 4, "edge_threshold": 0.001},
                                 {"aa": "adaptive", "samples": 4, "stencil_rule": "listing"}]
                for s in settings:
                    out.append(base | {"technique": "izb", "params": s})
                if scene == "tunnel_fan":
                    for size in ((1024,) if quick else (1024, 2048, 4096, 8192)):
                        out.append(base | {"technique": "hard", "params": {"shadow_map_size": size}})
    return out


_AREA: dict = {}


def _area_reference(scene_name: str, w: int, h: int, device: str) -> np.ndarray:
    """Per pixel, the mean over 64 sub-pixel eye samples (the G-buffer's multi-sample pattern) of
    the ray-traced visibility of the light's centre (``reference samples=1 jitter=false``)."""
    import wsoft

    key = (scene_name, w, h, device)
    if key not in _AREA:
        fr = wsoft.render(load(scene_name), "reference", width=w, height=h, device=device, pixel_samples=AREA_SAMPLES,
                          samples=1, jitter=False)
        _AREA[key] = (fr.V.astype(np.float64), fr["A"] > 0)
    return _AREA[key]


def _resources(scene, params, w, h, device):
    from wsoft.render import build_graph, execute

    b = build_graph(scene, "izb", width=w, height=h, device=device, params=params)
    extra = [k for p in b.ctx.graph.passes.values() for k in p.outputs if str(k).startswith("izb_stencil")]
    res, _, _ = execute(b, device, extra=extra)
    return res


def run_case(case: dict, ctx: dict) -> dict:
    import wsoft

    scene = load(case["scene"])
    w, h, dev = case["width"], case["height"], case["device"]
    kw = dict(width=w, height=h, device=dev, **case["params"])
    wsoft.render(scene, case["technique"], **kw)  # warm-up (compilation)
    frames = []
    for _ in range(3):
        t0 = time.perf_counter()
        fr = wsoft.render(scene, case["technique"], **kw)
        frames.append((time.perf_counter() - t0, fr))
    frames.sort(key=lambda x: x[0])
    fr = frames[1][1]
    ref, covered = _area_reference(case["scene"], w, h, dev)
    V = fr.V.astype(np.float64)
    edge = covered & (ref > 0.0) & (ref < 1.0)
    row = {
        "scene": case["scene"], "technique": case["technique"], "params": case["params"], "device": dev, "width": w, "height": h,
        "timings_ms": fr.stats["timings_ms"], "memory_bytes": fr.stats.get("memory_bytes"),
        "counters": fr.counters(), "mae": float(np.abs(V - ref)[covered].mean()),
        "mae_edge": float(np.abs(V - ref)[edge].mean()) if edge.any() else 0.0, "edge_pixels_reference": int(edge.sum()),
    }
    p = case["params"]
    flagged = None
    if case["technique"] == "izb" and p.get("aa") == "adaptive":
        ss = wsoft.render(scene, "izb", width=w, height=h, device=dev, aa="supersample", samples=p.get("samples", 4))
        aliased = (ss.V > 0) & (ss.V < 1)
        res = _resources(scene, p, w, h, dev)
        flagged = next(v for k, v in res.items() if str(k).startswith("izb_stencil")).numpy().reshape(h, w).astype(bool)
        row.update(aliased=int(aliased.sum()), aliased_missed=int((aliased & ~flagged).sum()))
    if case["technique"] == "izb" and p.get("samples", 4) == 4 and p.get("aa") in ("none", "adaptive") and len(p) <= 2:
        out = Path(ctx["out_dir"]) / "izb"
        out.mkdir(parents=True, exist_ok=True)
        name = f"{case['scene']}_{p['aa']}.png"
        _png(V, out / name)
        row["image"] = f"izb/{name}"
        if flagged is not None:
            rgb = np.repeat(V[..., None], 3, -1) * 0.8
            rgb[flagged] = rgb[flagged] * 0.5 + np.array([0.5, 0.1, 0.1])
            _png(rgb, out / f"{case['scene']}_stencil.png")
            row["stencil_image"] = f"izb/{case['scene']}_stencil.png"
    return row


def _png(a: np.ndarray, path: Path) -> None:
    from PIL import Image

    Image.fromarray((np.clip(a, 0, 1) * 255 + 0.5).astype(np.uint8)).save(path)


def _pass_ms(r: dict, name: str) -> float:
    return sum(v for k, v in r["timings_ms"].items() if k.startswith(name))


def _izb_ms(r: dict) -> float:
    return sum(_pass_ms(r, n) for n in IZB_PASSES)


def _counter(r: dict, name: str, default=0):
    return r["counters"].get(name, default)


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = [line for line in report_header("izb", rows, md, ctx) if not line.startswith(("Error is against", "penumbra ="))]
    L.append("")
    L.append(f"Reference: per pixel the mean over {AREA_SAMPLES} sub-pixel eye samples (the G-buffer's multi-sample pattern) of the "
             "ray-traced visibility of the light's centre (`reference samples=1 jitter=false`); `MAE edge`: pixels where it is "
             "strictly between 0 and 1. Times: median of 3 renders after a warm-up; `izb ms`: the technique's passes (stencil "
             "map and view included); `none ×`: that time over `aa=none`'s on the same frame; `paper`: 1 + edge fraction × N, the "
             "chapter's estimate. `missed`: pixels whose N sub-samples disagree (`supersample`) that the stencil did not flag.")
    L.append("")
    L.append("| scene | res | technique | params | frame ms | izb ms | none × | paper 1+ef×N | edge fraction | samples | list max / mean / p99 | "
             "pairs | tests | grid + lists MiB | MAE | MAE edge | aliased | missed |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    none = {(r["scene"], r["width"]): _izb_ms(r) for r in rows if r["technique"] == "izb" and r["params"] == {"aa": "none"}}
    order = {"none": 0, "adaptive": 1, "supersample": 2}
    for r in sorted(rows, key=lambda r: (r["scene"], r["width"], r["technique"], order.get(r["params"].get("aa"), 3),
                                         r["params"].get("samples", 0), str(r["params"]))):
        p = r["params"]
        ptxt = ", ".join(f"{k}={v}" for k, v in p.items())
        if r["technique"] == "hard":
            L.append(f"| {r['scene']} | {r['width']}x{r['height']} | hard | {ptxt} | {r['timings_ms']['total']:.1f} | | | | | | | | | | "
                     f"{r['mae']:.4f} | {r['mae_edge']:.4f} | | |")
            continue
        ms = _izb_ms(r)
        base = none.get((r["scene"], r["width"]))
        ef = _counter(r, "edge_fraction", None)
        n = p.get("samples", 4)
        paper = f"{1 + ef * n:.2f}" if ef is not None and p.get("aa") == "adaptive" else ""
        mib = (_counter(r, "grid_bytes") + _counter(r, "list_bytes")) / 2**20
        missed = f"{r['aliased_missed']} ({100 * r['aliased_missed'] / max(r['aliased'], 1):.1f}%)" if "aliased" in r else ""
        L.append(f"| {r['scene']} | {r['width']}x{r['height']} | izb | {ptxt} | {r['timings_ms']['total']:.1f} | {ms:.1f} | "
                 f"{ms / base:.2f} | {paper} | {'' if ef is None else f'{ef:.3f}'} | {_counter(r, 'samples_inserted')} | "
                 f"{_counter(r, 'list_max')} / {_counter(r, 'list_mean'):.2f} / {_counter(r, 'list_p99'):.0f} | "
                 f"{_counter(r, 'triangle_cell_pairs')} | {_counter(r, 'sample_tests')} | {mib:.1f} | {r['mae']:.4f} | {r['mae_edge']:.4f} | "
                 f"{r.get('aliased', '')} | {missed} |" if base else f"| {r['scene']} | | izb | {ptxt} | | | | | | | | | | | | | | |")
    L += ["", "## Passes (ms)", "", "| scene | params | " + " | ".join(IZB_PASSES) + " |", "|---|---|" + "---|" * len(IZB_PASSES)]
    for r in sorted((r for r in rows if r["technique"] == "izb"), key=lambda r: (r["scene"], str(r["params"]))):
        L.append(f"| {r['scene']} | {', '.join(f'{k}={v}' for k, v in r['params'].items())} | "
                 + " | ".join(f"{_pass_ms(r, n):.1f}" for n in IZB_PASSES) + " |")
    imgs = [r for r in rows if r.get("image")]
    if imgs:
        L += ["", "## Images", "", "Single sample (`aa=none`), adaptive 4× rotated grid, and the stencil's potential-edge pixels (red; Fig. 1.6.9).", ""]
        for r in sorted(imgs, key=lambda r: (r["scene"], r["params"]["aa"])):
            L.append(f"**{r['scene']} / aa={r['params']['aa']}**")
            L.append("")
            L.append(f"![{r['scene']} {r['params']['aa']}]({r['image']})")
            L.append("")
            if r.get("stencil_image"):
                L.append(f"**{r['scene']} / stencil**")
                L.append("")
                L.append(f"![{r['scene']} stencil]({r['stencil_image']})")
                L.append("")
    md.write_text("\n".join(L) + "\n")
