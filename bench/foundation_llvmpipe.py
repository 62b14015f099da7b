"""Sweep ``foundation``'s rows of the light depth map beside Mesa's llvmpipe
(:mod:`wsoft.bench.llvmpipe`) on the same triangles, view and target (``raster_llvmpipe``,
``raster_llvmpipe_fill``), and their sections of the report."""

from __future__ import annotations

import time

import numpy as np

from wsoft.bench.harness import load


def _depth_pass_inputs(case: dict, scene, light):
    """What the ``hard`` technique's depth-map pass of ``light`` rasterizes, from a render of the
    case's size and map size: (device scene, light view, alpha-tested, the triangles drawn or None
    for every one, the pass's own map)."""
    from wsoft.pipeline import build_graph, execute

    built = build_graph(scene, "hard", width=case["width"], height=case["height"], camera=None, light=light.path, device=case["device"],
                        pixel_samples=1, params={"shadow_map_size": case["size"]}, history=None)
    keys = [k for k in built.ctx.graph.producers if k.kind in ("scene", "light_view", "light_depth")]
    res, _, _ = execute(built, case["device"], extra=keys)
    pick = {k.kind: res[k] for k in keys}
    return pick["scene"], pick["light_view"], pick["light_depth"].alpha_tested, scene.casting_triangles(light), pick["light_depth"]


def _raster_llvmpipe(case: dict, ctx: dict) -> dict:
    """The light depth map of the ``hard`` technique's pass (its view, its triangles, alpha-tested
    as it is) drawn by wsoft's rasterizer and by Mesa's llvmpipe (:mod:`wsoft.bench.llvmpipe`) with
    as many threads, timed in ``case["rounds"]`` alternating rounds after a warm-up of each (the
    first of a round turns from round to round; medians, and the median of the rounds' ratios),
    the maps compared texel by texel. wsoft: one call of :func:`~wsoft.raster.depth_map.rasterize`
    (its instance culling, clears and merges included); llvmpipe: clear, draw calls, ``glFinish``
    (context start and buffer upload apart). Skipped, with the reason, where the peer cannot run."""
    import os
    import statistics

    import warp as wp

    from wsoft.bench import llvmpipe
    from wsoft.parallel import cpu_threads
    from wsoft.raster.depth_map import rasterize

    threads = cpu_threads()
    scene = load(case["scene"])
    light = scene.find_light(case["light"]) if case["light"] else scene.lights[0]
    row = {"scene": case["scene"], "light": light.path, "device": case["device"], "size": case["size"], "threads": threads,
           "triangles": scene.total_triangles, "instanced": bool(scene.instanced), "load_before": round(os.getloadavg()[0], 2)}
    reason = llvmpipe.unavailable(threads)
    if reason:
        return row | {"skipped": reason}
    ds, view, alpha, casting, pass_map = _depth_pass_inputs(case, scene, light)
    peer = llvmpipe.LlvmpipeDepthMap(ds, view, alpha_tested=alpha, triangles=casting, threads=threads)
    own = lambda: rasterize(ds, view, alpha_tested=alpha, triangles=casting)  # noqa: E731

    def clock(fn):
        wp.synchronize()
        t0 = time.perf_counter()
        fn()
        wp.synchronize()
        return 1e3 * (time.perf_counter() - t0)

    own_map = own()
    peer.draw()
    tw, tg = [], []
    for k in range(case["rounds"]):
        for name in (("wsoft", "gl") if k % 2 == 0 else ("gl", "wsoft")):
            if name == "wsoft":
                tw.append(clock(own))
            else:
                tg.append(clock(peer.draw))
    ratios = [a / b for a, b in zip(tw, tg)]
    same_as_pass = bool(np.array_equal(own_map.depth.numpy(), pass_map.depth.numpy()))
    cmp = llvmpipe.compare(own_map.depth.numpy(), peer)
    drawn = sum(v * n for _, v, n, _ in peer.draws) // 3
    out = row | {
        "persp": bool(view.persp), "alpha_tested": alpha, "gl": llvmpipe.context_info(), "draw_calls": peer.draw_calls, "gl_triangles": int(drawn),
        "instances_drawn": peer.instances_drawn, "wsoft_instances_drawn": own_map.instances_drawn, "upload_ms": peer.upload_ms,
        "wsoft_ms": statistics.median(tw), "llvmpipe_ms": statistics.median(tg), "wsoft_ms_runs": tw, "llvmpipe_ms_runs": tg,
        "time_ratio": statistics.median(ratios), "time_ratio_runs": ratios, "map_is_the_pass_map": same_as_pass,
        "gl_near": peer.gl_near, "near": float(view.near), "far": float(view.far), **cmp}
    peer.release()
    return out


def _large_triangles(ds, view, triangles: np.ndarray) -> np.ndarray:
    """Which of the soup's ``triangles`` the CPU rasterizer draws in its banded pass for large
    triangles: a texel box (clipped to the map) over ``BIG_TRIANGLE_TEXELS``, or crossing a
    perspective view's near plane (far faces of closed surfaces included: the rasterizer culls
    them before it looks at their box, llvmpipe draws them)."""
    from wsoft.raster.rasterizer import BIG_TRIANGLE_TEXELS

    idx = ds.indices.numpy().reshape(-1, 3)[triangles]
    v = view.to_view(ds.points.numpy().astype(np.float64))[idx]  # [T, 3 corners, 3]
    z = v[..., 2]
    crossing = np.zeros(len(idx), bool)
    if view.persp:
        crossing = (z.min(axis=1) < view.near) & (z.max(axis=1) >= view.near)
        v = v[..., :2] / np.where(z > 0, z, 1.0)[..., None]
    l, r, b, t = view.window
    x = (v[..., 0] - l) / (r - l) * view.width
    y = (v[..., 1] - b) / (t - b) * view.height
    bw = np.minimum(x.max(axis=1), view.width) - np.maximum(x.min(axis=1), 0.0)
    bh = np.minimum(y.max(axis=1), view.height) - np.maximum(y.min(axis=1), 0.0)
    return crossing | ((bw >= 0) & (bh >= 0) & (bw * bh > BIG_TRIANGLE_TEXELS))


def _raster_llvmpipe_fill(case: dict, ctx: dict) -> dict:
    """Where the time of a map of few large triangles goes, beside llvmpipe: the row's map drawn
    whole, its large triangles only (:func:`_large_triangles`), the others only, and no triangle
    (the map's clear and set-up), each by both, in ``case["rounds"]`` rounds whose order turns from
    round to round (medians); the texels each draws (its depth map's coverage)."""
    import statistics

    import warp as wp

    from wsoft.bench import llvmpipe
    from wsoft.lightspace.view import DEPTH_CLEAR
    from wsoft.parallel import cpu_threads
    from wsoft.raster.depth_map import rasterize

    threads = cpu_threads()
    scene = load(case["scene"])
    light = scene.find_light(case["light"]) if case["light"] else scene.lights[0]
    row = {"scene": case["scene"], "light": light.path, "device": case["device"], "size": case["size"], "threads": threads,
           "triangles": scene.total_triangles}
    reason = llvmpipe.unavailable(threads)
    if reason:
        return row | {"skipped": reason}
    if scene.instanced:
        return row | {"skipped": "an instanced stage (its maps draw every triangle)"}
    ds, view, alpha, casting, _ = _depth_pass_inputs(case, scene, light)
    tris = np.arange(scene.triangle_count, dtype=np.int32) if casting is None else np.asarray(casting, np.int32)
    large = _large_triangles(ds, view, tris)
    sets = {"all": tris, "large": tris[large], "small": tris[~large], "none": tris[:0]}
    peers = {k: llvmpipe.LlvmpipeDepthMap(ds, view, alpha_tested=alpha, triangles=v, threads=threads) for k, v in sets.items()}
    jobs = {}
    for k, v in sets.items():
        jobs[f"wsoft_{k}"] = lambda v=v: rasterize(ds, view, alpha_tested=alpha, triangles=v)
        jobs[f"llvmpipe_{k}"] = peers[k].draw

    def clock(fn):
        wp.synchronize()
        t0 = time.perf_counter()
        fn()
        wp.synchronize()
        return 1e3 * (time.perf_counter() - t0)

    covered = {k: int((rasterize(ds, view, alpha_tested=alpha, triangles=v).depth.numpy() < DEPTH_CLEAR).sum()) for k, v in sets.items()}
    for p in peers.values():
        p.draw()
    names = list(jobs)
    times = {n: [] for n in names}
    for k in range(case["rounds"]):
        for n in names[k % len(names):] + names[: k % len(names)]:
            times[n].append(clock(jobs[n]))
    for p in peers.values():
        p.release()
    return row | {"large": int(large.sum()), "small": int((~large).sum()), "covered": covered,
                  **{f"{n}_ms": statistics.median(v) for n, v in times.items()}, **{f"{n}_ms_runs": v for n, v in times.items()}}


def _llvmpipe_section(rows: list[dict]) -> list[str]:
    """The report's rows of the light depth map beside llvmpipe."""
    if not rows:
        return []
    L = ["", "## Light depth map beside Mesa's llvmpipe (same triangles, view and target; alternating rounds in one process)", ""]
    L.append("The `hard` technique's depth-map pass of the light (its view, fitted to what a render of the row's size sees, its")
    L.append("triangles, cutouts alpha-tested as it does) drawn by wsoft's rasterizer (one `rasterize` call: its instance culling,")
    L.append("clears and merges included) and by llvmpipe through moderngl on a headless EGL context (`wsoft.bench.llvmpipe`:")
    L.append("`LP_NUM_THREADS` = wsoft's threads; a depth-only 24-bit target, depth test `LESS`, no face culling; clear, draw calls")
    L.append("and `glFinish` timed, the context's start and the buffers' upload apart). An instanced stage is drawn by instanced")
    L.append("rendering: per prototype one draw of its opaque triangles (indexed) and one per cutout, instanced over the instances")
    L.append("whose bounds reach the view (chosen with wsoft's own test while the buffers are filled, outside llvmpipe's time).")
    L.append("Each time is the median of the rounds (each round runs both, the first turning from round to round); `wsoft / llvmpipe`:")
    L.append("the median of the rounds' ratios of time; `speed`: its inverse, wsoft's speed as a multiple of llvmpipe's (target ≥ 0.5).")
    L.append("Maps: llvmpipe's window depths turned back into wsoft's linear view depth; `coverage differs`: texels drawn in one map")
    L.append("only; over texels drawn in both, |Δz| (scene units) and in steps of the 24-bit target; `surface differs`: texels more")
    L.append("than 16 steps apart (another triangle nearest at the texel centre: the rasterizers' rules on shared edges and")
    L.append("silhouettes). `load`: the host's 1-minute load average before the row and as it finished.")
    L.append("")
    L.append("| scene | light | view | size | threads | triangles drawn (draw calls) | wsoft ms | llvmpipe ms | wsoft / llvmpipe | speed | "
             "coverage differs | surface differs | max / mean \\|Δz\\| | 24-bit steps: max (p99) | upload ms | load |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        lt = r["light"].split("/")[-1]
        if "skipped" in r:
            L.append(f"| {r['scene']} | {lt} | | {r['size']} | {r['threads']} | skipped: {r['skipped']} | | | | | | | | | | |")
            continue
        inst = f", {r['instances_drawn']:,} instances" if r["instanced"] else ""
        L.append(f"| {r['scene']} | {lt} | {'perspective' if r['persp'] else 'orthographic'}{', alpha-tested' if r['alpha_tested'] else ''} | "
                 f"{r['size']} | {r['threads']} | {r['gl_triangles']:,}{inst} ({r['draw_calls']}) | {r['wsoft_ms']:.0f} | {r['llvmpipe_ms']:.0f} | "
                 f"{r['time_ratio']:.2f} | {1.0 / r['time_ratio']:.2f}× | {r['coverage_differs']:.1e} | {r['surface_differs']:.1e} | "
                 f"{r['max_abs_diff']:.3g} / {r['mean_abs_diff']:.2g} | {r['max_diff_in_steps']:.3g} ({r['p99_diff_in_steps']:.2g}) | "
                 f"{r['upload_ms']:.0f} | {r['load_before']:.1f}, {r['machine']['load']:.1f} |")
    done = [r for r in rows if "skipped" not in r]
    if done:
        g = done[0]["gl"]
        L += ["", f"Renderer: {g.get('renderer', '?')}, OpenGL {g.get('version', '?')}, moderngl {g.get('moderngl', '?')}; context start "
                  f"{g.get('start_ms', float('nan')):.0f} ms. Target (speed ≥ 0.5× llvmpipe's): "
                  + ("met on every row." if all(1.0 / r["time_ratio"] >= 0.5 for r in done) else
                     "NOT met on " + ", ".join(f"{r['scene']} {r['light'].split('/')[-1]}" for r in done if 1.0 / r["time_ratio"] < 0.5) + ".")]
        odd = [r for r in done if not r["map_is_the_pass_map"]]
        if odd:
            L.append("The timed call's map differs from the render pass's on " + ", ".join(f"{r['scene']} {r['light'].split('/')[-1]}" for r in odd) + ".")
    return L


def _llvmpipe_fill_section(rows: list[dict]) -> list[str]:
    """The report's rows of where a fill-bound map's time goes, beside llvmpipe."""
    if not rows:
        return []
    L = ["", "## Few large triangles beside llvmpipe: where the time goes", ""]
    L.append("The same comparison on a map that a few large triangles fill (a ground plane under a handful of objects): the map")
    L.append("drawn whole, its `large` triangles only (texel box over `BIG_TRIANGLE_TEXELS`, or crossing the near plane: the")
    L.append("rasterizer's banded pass; far faces it culls first included), the `small` ones only, and `none` (the clear and set-up),")
    L.append("each by both in the same")
    L.append("alternating rounds (medians). `ns / texel`: (large − none) over the texels the large triangles cover, the fill cost.")
    L.append("")
    L.append("| scene | size | threads | triangles (large) | texels covered: all, large, small | wsoft ms: all / large / small / none | "
             "llvmpipe ms: all / large / small / none | wsoft / llvmpipe (all) | fill ns / texel: wsoft, llvmpipe | load |")
    L.append("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "skipped" in r:
            L.append(f"| {r['scene']} | {r['size']} | {r['threads']} | skipped: {r['skipped']} | | | | | | |")
            continue
        c = r["covered"]
        w = " / ".join(f"{r[f'wsoft_{k}_ms']:.1f}" for k in ("all", "large", "small", "none"))
        g = " / ".join(f"{r[f'llvmpipe_{k}_ms']:.1f}" for k in ("all", "large", "small", "none"))
        fill = [1e6 * (r[f"{s}_large_ms"] - r[f"{s}_none_ms"]) / max(c["large"], 1) for s in ("wsoft", "llvmpipe")]
        L.append(f"| {r['scene']} | {r['size']} | {r['threads']} | {r['triangles']:,} ({r['large']}) | {c['all']:,}, {c['large']:,}, {c['small']:,} | "
                 f"{w} | {g} | {r['wsoft_all_ms'] / r['llvmpipe_all_ms']:.2f} | {fill[0]:.1f}, {fill[1]:.1f} | {r['machine']['load']:.1f} |")
    done = [r for r in rows if "skipped" not in r]
    if done:
        L += ["", "Per row: " + "; ".join(
            f"{r['scene']} {r['size']}²: the large triangles alone take {r['wsoft_large_ms'] / r['wsoft_all_ms']:.0%} of wsoft's time for the whole "
            f"map, and wsoft fills a texel in {(r['wsoft_large_ms'] - r['wsoft_none_ms']) / max(r['llvmpipe_large_ms'] - r['llvmpipe_none_ms'], 1e-9):.1f}× "
            f"llvmpipe's time" for r in done) + "."]
    return L
