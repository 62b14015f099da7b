"""Sweep ``foundation``: ``hard`` and low-sample ``reference`` against the cached reference on the
bundled scenes at two resolutions, the rasterizer against one BVH ray per texel and against
earlier rasterizer revisions (:data:`BASELINES`, read from the git history of a checkout), and
reference shadow-ray throughput beside Embree's (embreex) on the same rays and thread count, and the
light depth map beside Mesa's llvmpipe (:mod:`wsoft.bench.llvmpipe`) on the same triangles, view
and target. The rows live by subject in ``foundation_raster``, ``foundation_rays`` and
``foundation_llvmpipe``; this module holds the cases, the report and the entry points.

Only some kinds of rows: ``python -m wsoft.bench.foundation --only raster_llvmpipe [--quick]`` runs
the rows of those kinds that ``reports/foundation[-quick].jsonl`` does not hold yet and writes the
report from every row it holds.
"""

from __future__ import annotations

from pathlib import Path

from wsoft.bench.common import accuracy_table, error_vs_time, image_list, render_references, render_row, report_header
from wsoft.bench.foundation_llvmpipe import _llvmpipe_fill_section, _llvmpipe_section, _raster_llvmpipe, _raster_llvmpipe_fill
from wsoft.bench.foundation_raster import BASELINES, _raster_baseline, _raster_bound, _raster_vs_raycast
from wsoft.bench.foundation_rays import _reference_frame, _throughput, rays_sections

FULL_VIEWS = [
    ("box_plane", None), ("contact", None), ("cutout", None),
    ("multi_light", "Rect"), ("multi_light", "Disk"), ("multi_light", "Sphere"), ("multi_light", "Sun"),
    ("city", "Sun"), ("city", "Rect"),
]
QUICK_VIEWS = [("box_plane", None), ("cutout", None), ("multi_light", "Disk")]



references = render_references  # each render row's reference: error-only jobs of a distributed sweep (wsoft.bench.dist)


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = []
    views = QUICK_VIEWS if quick else FULL_VIEWS
    resolutions = [(160, 120)] if quick else [(320, 240), (640, 480)]
    ref_samples = 64 if quick else 256
    sizes = [1024] if quick else [1024, 2048]
    low_samples = [4] if quick else [4, 16, 64]
    for dev in devices:
        for scene, light in views:
            for w, h in resolutions:
                base = {"kind": "render", "scene": scene, "light": light, "device": dev, "width": w, "height": h, "ref_samples": ref_samples}
                for size in sizes:
                    image = (w, h) == resolutions[-1] and size == sizes[-1]
                    out.append(base | {"technique": "hard", "params": {"shadow_map_size": size}, "image": image})
                for n in low_samples:
                    out.append(base | {"technique": "reference", "params": {"samples": n, "seed": 1}, "image": False})
        if quick:
            out.append({"kind": "raster_vs_raycast", "scene": "contact", "light": None, "size": 1024, "device": dev})
            out.append({"kind": "ray_throughput", "scene": "contact", "light": None, "width": 80, "height": 60, "samples": 4, "device": dev})
            out.append({"kind": "reference_frame", "scene": "cutout", "width": 160, "height": 120, "samples": 16, "device": dev})
            if dev == "cpu":
                out.append({"kind": "raster_llvmpipe", "scene": "contact", "light": None, "size": 512, "width": 160, "height": 120, "rounds": 3,
                            "device": dev})
        else:
            for light in ("Sun", "Rect"):
                out.append({"kind": "raster_vs_raycast", "scene": "city", "light": light, "size": 2048, "device": dev})
                for rev in BASELINES:
                    out.append({"kind": "raster_baseline", "scene": "city", "light": light, "size": 2048, "device": dev, "baseline": rev})
            if dev == "cpu":
                out.append({"kind": "raster_bound", "scene": "city", "light": "Sun", "size": 2048, "device": dev})
            for samples in (16, 64):
                out.append({"kind": "ray_throughput", "scene": "city", "light": "Sun", "width": 320, "height": 240, "samples": samples, "device": dev})
                out.append({"kind": "ray_throughput", "scene": "contact", "light": None, "width": 320, "height": 240, "samples": samples, "device": dev})
            for scene in bundled_scenes():
                out.append({"kind": "reference_frame", "scene": scene, "width": 640, "height": 480, "samples": 64, "device": dev})
            if dev == "cpu":
                for scene, light, rounds in LLVMPIPE_VIEWS:
                    out.append({"kind": "raster_llvmpipe", "scene": scene, "light": light, "size": 2048, "width": 320, "height": 240,
                                "rounds": rounds, "device": dev})
                for size in (512, 2048):
                    out.append({"kind": "raster_llvmpipe_fill", "scene": "contact", "light": None, "size": size, "width": 320, "height": 240,
                                "rounds": 7, "device": dev})
    return out


# the light depth maps drawn beside llvmpipe: (scene, light, alternating rounds)
LLVMPIPE_VIEWS = [("city", "Sun", 7), ("city", "Rect", 7), ("forest", "Sun", 3), ("forest", "Rect", 3)]


def run_case(case: dict, ctx: dict) -> dict:
    return {"render": render_row, "raster_vs_raycast": _raster_vs_raycast, "ray_throughput": _throughput, "reference_frame": _reference_frame,
            "raster_baseline": _raster_baseline, "raster_bound": _raster_bound, "raster_llvmpipe": _raster_llvmpipe,
            "raster_llvmpipe_fill": _raster_llvmpipe_fill}[case["kind"]](case, ctx)


def bundled_scenes() -> list[str]:
    """Every bundled stage, by name."""
    from wsoft import usd_scenes

    return sorted(p.stem for p in Path(usd_scenes.folder()).iterdir() if p.suffix in (".usda", ".usdc", ".usdz"))


def cpu_use_section(renders: list[dict]) -> list[str]:
    """CPU time over wall time of the heavy passes (light maps, the reference) inside the CPU
    renders, those over 20 ms, and the target for those over 50 ms: met, not met by which, or not
    measured where no pass took that long."""
    L: list[str] = []
    util = []
    for r in renders:
        for k, ms in r["timings_ms"].items():
            if ms > 20 and r.get("pass_kinds", {}).get(k) in ("light_map", "reference") and r["device"] == "cpu":
                util.append((r["scene"], r["width"], k, ms, r["cpu_ms"][k] / ms))
    if util:
        L += ["", "## CPU time / wall time of heavy passes in the renders above (passes over 20 ms)", ""]
        L.append("| scene | width | pass | ms | CPU/wall |")
        L.append("|---|---|---|---|---|")
        for s, w, k, ms, u in sorted(util):
            L.append(f"| {s} | {w} | {k} | {ms:.1f} | {u:.2f} |")
        low = [f"{s} {w} {k} ({ms:.0f} ms, {u:.2f})" for s, w, k, ms, u in sorted(util) if ms > 50 and u < 1.8]
        longest = max(ms for _, _, _, ms, _ in util)
        from wsoft.parallel import cpu_threads

        target = f"Target: every pass over 50 ms at CPU/wall ≥ 1.8 on {cpu_threads()} threads: "
        if longest <= 50:
            L += ["", target + f"not measured at this size (no pass took over 50 ms; the longest {longest:.0f} ms)."]
        else:
            L += ["", target + ("met." if not low else "NOT met by " + "; ".join(low) + ".")]
    return L


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    renders = [r for r in rows if r["case"]["kind"] == "render"]
    raster = [r for r in rows if r["case"]["kind"] == "raster_vs_raycast"]
    L = report_header("foundation", rows, md, ctx)
    L += accuracy_table(renders)
    if raster:
        L += ["", "## Light depth map: rasterizer vs one BVH ray per texel (target: >= 15x, floor >= 10x; CPU time / wall >= 1.7 on 2 cores)", ""]
        L.append("| scene | light | device | size | triangles | raster ms | ray/texel ms | speedup | raster CPU/wall | ray CPU/wall | coverage mismatch | depth rel. err p99 |")
        L.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in raster:
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['device']} | {r['size']} | {r['triangles']} | {r['raster_ms']:.1f} | {r['raycast_ms']:.1f} | "
                     f"{r['speedup']:.1f}x | {r['raster_cpu_over_wall']:.2f} | {r['raycast_cpu_over_wall']:.2f} | {r['coverage_mismatch']:.2e} | {r['depth_rel_err_p99']:.1e} |")
    L += rays_sections(rows)
    base = [r for r in rows if r["case"]["kind"] == "raster_baseline"]
    if base:
        L += ["", "## The rasterizer against earlier versions of itself (same view, alternating runs in one process)", ""]
        L.append("`baseline`: the rasterizer module of an earlier commit, loaded from the git history; `checkout`: this checkout's. Median of 11")
        L.append("alternating runs each, on the same view, with the sweep's thread count. The earlier versions:")
        L.append("")
        for rev in dict.fromkeys(r["baseline"] for r in base):
            L.append(f"- `{rev}`: {BASELINES[rev][1] if rev in BASELINES else 'not in BASELINES'}.")
        L.append("")
        L.append("| scene | light | device | size | baseline | baseline ms | checkout ms | checkout / baseline | identical texels | max rel. difference |")
        L.append("|---|---|---|---|---|---|---|---|---|---|")
        for r in base:
            if "skipped" in r:
                L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['device']} | {r['size']} | {r['baseline']} | {r['skipped']} | | | | |")
                continue
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['device']} | {r['size']} | {r['baseline']} | {r['baseline_ms']:.1f} | {r['new_ms']:.1f} | "
                     f"{r['new_over_baseline']:.3f} | {r['identical_texels']:.5f} | {r['max_rel_diff']:.1e} |")
    bound = [r for r in rows if r["case"]["kind"] == "raster_bound"]
    if bound:
        L += ["", "## A bound on the 15x target: an idealised rasterizer on the same view (`wsoft.bench.raster_bound`)", ""]
        L.append("Two stripped kernels in the rasterizer's own CPU layout (a private map per worker, interleaved chunks of triangles):")
        L.append("`fetch + box`: per triangle only the fetch of its three projected corners and its texel box, no drawing (a floor")
        L.append("under any kernel that gives a triangle a thread); `idealised draw`: depth only, every triangle the rasterizer draws")
        L.append("(its culled far faces skipped for free) by a branch-free loop over its box; no clipping, spans, alpha test or bands, maps")
        L.append("cleared off the clock and never merged, the points projected beforehand, the `large` triangles (boxes over")
        L.append("`BIG_TRIANGLE_TEXELS`, the rasterizer's banded second pass) left out. Drawing them too, it draws the same map (`coverage mismatch`;")
        L.append("`tests/test_raster_bound.py`). `small boxes only`: the same kernel drawing only the triangles whose box holds at most")
        L.append("`SMALL_BOX_TEXELS` texel centres (most of them). Each time: the median of 9 rounds, each running all five (the ray per")
        L.append("texel too) in an order that turns from round to round.")
        L.append("`budget`: the ray time / 15, what the 15x target allows.")
        L.append("")
        L.append("| scene | light | size | threads | triangles (culled, covering a texel, large) | ray/texel ms | budget ms | rasterizer ms (x) | idealised draw ms (x) | small boxes only: triangles, ms (x) | fetch + box ms (x) | coverage mismatch |")
        L.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in bound:
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['size']} | {r['threads']} | {r['triangles']} ({r['culled']}, {r['covering']}, {r['large']}) | "
                     f"{r['ray_ms']:.1f} | {r['ray_ms'] / 15:.1f} | {r['real_ms']:.1f} ({r['ray_ms'] / r['real_ms']:.1f}x) | "
                     f"{r['draw_ms']:.1f} ({r['ray_ms'] / r['draw_ms']:.1f}x) | {r['small']} (box <= {r['small_box_texels']}), {r['small_ms']:.1f} ({r['ray_ms'] / r['small_ms']:.1f}x) | {r['fetch_ms']:.1f} ({r['ray_ms'] / r['fetch_ms']:.1f}x) | "
                     f"{r['coverage_mismatch']} of {r['covered']} |")
        for r in bound:
            verdict = "within" if r["draw_ms"] <= r["ray_ms"] / 15 else "over"
            L.append("")
            L.append(f"{r['scene']} {r['light'].split('/')[-1]}: the idealised draw alone takes {r['draw_ms']:.1f} ms, {verdict} the {r['ray_ms'] / 15:.1f} ms "
                     f"that 15x allows ({r['draw_ms'] / (r['ray_ms'] / 15):.2f} of it), before the clears, the merge, the projection and the large "
                     f"triangles the rasterizer also pays for; its small-box triangles alone take {r['small_ms']:.1f} ms ({r['small_ms'] / (r['ray_ms'] / 15):.2f} of it).")
    L += _llvmpipe_section([r for r in rows if r["case"]["kind"] == "raster_llvmpipe"])
    L += _llvmpipe_fill_section([r for r in rows if r["case"]["kind"] == "raster_llvmpipe_fill"])
    L += cpu_use_section(renders)
    sizes = sorted({r["params"]["shadow_map_size"] for r in renders if r["technique"] == "hard"})
    samples = sorted({r["params"]["samples"] for r in renders if r["technique"] == "reference"})
    refs = sorted({r["ref_samples"] for r in renders})
    L += error_vs_time(renders, md, ctx, f"foundation: hard (map {', '.join(map(str, sizes))}) and reference ({', '.join(map(str, samples))} samples) "
                                         f"vs a {'/'.join(map(str, refs))}-sample reference")
    L += image_list(renders, "hard, reference, |difference| x4")
    md.write_text("\n".join(L) + "\n")


def run_only(kinds: list[str], quick: bool = False, out_dir: str = "reports") -> int:
    """Run the rows of ``kinds`` (case kinds: ``raster_llvmpipe``...) on the CPU that the sweep's rows
    file does not hold yet, then write the report from every row it holds (as ``wsoft bench
    foundation`` does, without running the other kinds' missing rows). Returns 1 if a row failed."""
    import sys

    from wsoft.bench.harness import case_key, finished_rows, run_in_process

    cs = cases(quick=quick, devices=["cpu"])
    unknown = sorted(set(kinds) - {c["kind"] for c in cs})
    if unknown:
        print(f"foundation: no rows of kind {', '.join(unknown)}; kinds: {', '.join(sorted({c['kind'] for c in cs}))}", file=sys.stderr)
        return 2
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = "foundation-quick" if quick else "foundation"
    jsonl = out / f"{stem}.jsonl"
    done = {r["key"] for r in finished_rows(jsonl)}
    todo = [c for c in cs if c["kind"] in kinds and case_key(c) not in done]
    ctx = {"out_dir": out, "stem": stem, "quick": quick}
    failed = run_in_process("foundation", sys.modules[__name__], todo, ctx, jsonl)
    keys = {case_key(c) for c in cs}
    rows = [r for r in finished_rows(jsonl) if r["key"] in keys]
    cmd = "wsoft bench foundation" + (" --quick" if quick else "") + (f" --out-dir {out_dir}" if str(out_dir) != "reports" else "")
    report(rows, out / f"{stem}.md", ctx | {"command": cmd})
    print(f"wrote {out / f'{stem}.md'} ({len(rows)} rows; ran {len(todo)} of kind {', '.join(kinds)})", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(prog="python -m wsoft.bench.foundation", description="run only some kinds of the foundation sweep's rows")
    ap.add_argument("--only", action="append", required=True, metavar="KIND", help="a case kind (repeatable), e.g. raster_llvmpipe")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out-dir", default="reports")
    raise SystemExit(run_only(ap.parse_args().only, ap.parse_args().quick, ap.parse_args().out_dir))
