"""Sweep ``foundation``: ``hard`` and low-sample ``reference`` against the cached reference on the
bundled scenes at two resolutions, the rasterizer against one BVH ray per texel and against
earlier rasterizer revisions (:data:`BASELINES`, read from the git history of a checkout), and
reference shadow-ray throughput beside Embree's (embreex) on the same rays and thread count, and the
light depth map beside Mesa's llvmpipe (:mod:`wsoft.bench.llvmpipe`) on the same triangles, view
and target.

Only some kinds of rows: ``python -m wsoft.bench.foundation --only raster_llvmpipe [--quick]`` runs
the rows of those kinds that ``reports/foundation[-quick].jsonl`` does not hold yet and writes the
report from every row it holds.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from wsoft.bench.common import accuracy_table, error_vs_time, image_list, render_references, render_row, report_header
from wsoft.bench.harness import load

FULL_VIEWS = [
    ("box_plane", None), ("contact", None), ("cutout", None),
    ("multi_light", "Rect"), ("multi_light", "Disk"), ("multi_light", "Sphere"), ("multi_light", "Sun"),
    ("city", "Sun"), ("city", "Rect"),
]
QUICK_VIEWS = [("box_plane", None), ("cutout", None), ("multi_light", "Disk")]
# earlier rasterizer revisions timed against this checkout's: commit -> (its file, what it is)
BASELINES = {
    "da242d3": ("wsoft/raster/lightview.py",
                "the single depth rasterizer with runtime mode flags, before the fragment factory. Texels differ where it steps a "
                "large triangle's depth from a band's first row (this checkout's rasterizer steps it from its line's start, whichever "
                "band, so its map does not depend on the thread count), and where the only surfaces lie behind every receiver "
                "(deeper than the view's far depth: this checkout's rasterizer leaves them empty)"),
    "19e2496": ("wsoft/raster/rasterizer.py",
                "the fragment factory with every kernel projecting its triangles' corners itself and a flat loop, with a branch per "
                "texel, over boxes up to 8 texels (this checkout's projects each point once first, `project_points`, and loops over "
                "an orthographic view's boxes up to 16 texels without a branch per texel). Texels differ (Sun) where a triangle with "
                "a 9-16 texel box takes this checkout's flat loop, whose depth is evaluated from the box's first texel centre rather "
                "than from its line's"),
}


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


# -- rows --------------------------------------------------------------------------------------


def _timed(fn, repeats=3):
    """Wall and CPU time of the fastest of ``repeats`` calls of ``fn`` after one warm-up call."""
    import warp as wp

    fn()
    best = None
    for _ in range(repeats):
        wp.synchronize()
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wp.synchronize()
        t = (time.perf_counter() - t0, time.process_time() - c0)
        best = t if best is None or t[0] < best[0] else best
    return best


def _gbuffer_points(scene_name, device, width=320, height=240):
    import wsoft

    fr = wsoft.render(load(scene_name), "hard", width=width, height=height, device=device)
    return np.stack([fr["P.X"], fr["P.Y"], fr["P.Z"]], -1)[fr["A"] > 0]


def _light_map_view(case: dict, scene, light):
    """The scene on the case's device and the light view of a depth-map case: fitted to the
    receivers a 320x240 render sees, ``case["size"]`` texels per side."""
    from wsoft.lightspace.fit import fit_light_view
    from wsoft.scene.device import upload_scene

    ds, _ = scene.device_copy(case["device"], upload_scene)
    lo, hi = scene.bounds
    return ds, fit_light_view(light, _gbuffer_points(case["scene"], case["device"]), lo, hi, case["size"])


def _raster_vs_raycast(case: dict, ctx: dict) -> dict:
    from wsoft.parallel import cpu_threads
    from wsoft.lightspace.view import DEPTH_CLEAR
    from wsoft.raster.depth_map import rasterize
    from wsoft.raster.raycast import raycast_depth

    scene = load(case["scene"])
    light = scene.find_light(case["light"]) if case["light"] else scene.lights[0]
    dev = case["device"]
    ds, view = _light_map_view(case, scene, light)
    r_wall, r_cpu = _timed(lambda: rasterize(ds, view, alpha_tested=scene.has_cutouts), repeats=5)
    c_wall, c_cpu = _timed(lambda: raycast_depth(ds, view, alpha_tested=scene.has_cutouts), repeats=5)
    a = rasterize(ds, view, scene.has_cutouts).depth.numpy()
    b = raycast_depth(ds, view, scene.has_cutouts).depth.numpy()
    both = (a < DEPTH_CLEAR) & (b < DEPTH_CLEAR)
    return {
        "scene": case["scene"], "light": light.path, "device": dev, "size": case["size"], "triangles": scene.triangle_count,
        "threads": cpu_threads() if dev == "cpu" else None,
        "raster_ms": 1e3 * r_wall, "raster_cpu_over_wall": r_cpu / r_wall,
        "raycast_ms": 1e3 * c_wall, "raycast_cpu_over_wall": c_cpu / c_wall,
        "speedup": c_wall / r_wall,
        "coverage_mismatch": float(np.mean((a < DEPTH_CLEAR) != (b < DEPTH_CLEAR))),
        "depth_rel_err_p99": float(np.percentile(np.abs(a - b)[both] / b[both], 99)) if both.any() else 0.0,
    }


def _baseline_module(rev: str):
    """The rasterizer module of ``rev`` from the git history of the checkout wsoft runs from, or None
    (no such history). It runs against this checkout's package: an import of a name that its
    ``wsoft`` module does not hold takes the name from the module that defines it here
    (:func:`_resolve_moved_imports`)."""
    import ast
    import subprocess
    import sys
    import types

    import wsoft

    root = Path(wsoft.__file__).resolve().parents[1]
    where = f"{rev}:{BASELINES[rev][0]}"
    try:
        src = subprocess.run(["git", "show", where], cwd=root, capture_output=True, text=True, check=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    name = f"wsoft_baseline_{rev}"
    path = Path(cache_dir_for_baseline()) / f"{name}.py"
    path.write_text(src)  # a file, so that Warp can read the kernels' source (the lines keep their numbers)
    tree = _resolve_moved_imports(ast.parse(src, str(path)), where)
    mod = types.ModuleType(name)
    mod.__file__ = str(path)
    sys.modules[name] = mod
    exec(compile(tree, str(path), "exec", dont_inherit=True), mod.__dict__)  # not this file's __future__ annotations
    return mod


def _resolve_moved_imports(tree, where: str):
    """``tree`` (a module's AST) with each ``from wsoft.X import a, b`` (at any depth) split so that a
    name ``wsoft.X`` does not hold (neither an attribute nor a submodule) is imported from the wsoft
    module that holds it (:func:`_module_holding`), on the same line. ``where`` names the source in
    errors: an ImportError names a name that no module holds."""
    import ast
    import importlib

    def held(module: str, name: str) -> bool:
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name and (module == exc.name or module.startswith(exc.name + ".")):
                return False  # the module itself is not there
            raise
        if hasattr(mod, name):
            return True
        try:
            importlib.import_module(f"{module}.{name}")
        except ModuleNotFoundError:
            return False
        return True

    class Split(ast.NodeTransformer):
        def visit_ImportFrom(self, node):
            if node.level or not (node.module == "wsoft" or node.module.startswith("wsoft.")):
                return node
            keep, moved = [], {}
            for alias in node.names:
                if alias.name == "*" or held(node.module, alias.name):
                    keep.append(alias)
                else:
                    moved.setdefault(_module_holding(alias.name, f"{where}: from {node.module} import {alias.name}"), []).append(alias)
            if not moved:
                return node
            nodes = ([ast.ImportFrom(module=node.module, names=keep, level=0)] if keep else []) + [
                ast.ImportFrom(module=m, names=names, level=0) for m, names in moved.items()]
            return [ast.copy_location(n, node) for n in nodes]

    return ast.fix_missing_locations(Split().visit(tree))


def _wsoft_modules() -> list:
    """Every importable module of the wsoft package (its ``__main__`` aside), imported, by name."""
    import importlib
    import pkgutil

    import wsoft

    out = [wsoft]
    for info in sorted(pkgutil.walk_packages(wsoft.__path__, "wsoft."), key=lambda m: m.name):
        if info.name.rsplit(".", 1)[-1] == "__main__":
            continue
        try:
            out.append(importlib.import_module(info.name))
        except ImportError:  # an optional dependency missing here: it cannot be the one
            continue
    return out


def _module_holding(name: str, what: str) -> str:
    """The wsoft module ``name`` is taken from: of the modules that hold it, the one that defines it
    (its ``__module__``, else a top-level binding in its source), else any when they all hold the
    same object. ImportError (naming ``name`` and ``what``) when none holds it or the choice is not one."""
    import ast
    import inspect

    holders = [m for m in _wsoft_modules() if hasattr(m, name)]
    if not holders:
        raise ImportError(f"{what}: no wsoft module holds {name!r}", name=name)

    def binds(mod) -> bool:
        try:
            tree = ast.parse(inspect.getsource(mod))
        except (OSError, TypeError):
            return False
        def bound(t) -> bool:
            if isinstance(t, ast.Name):
                return t.id == name
            if isinstance(t, ast.Starred):
                return bound(t.value)
            return isinstance(t, (ast.Tuple, ast.List)) and any(bound(e) for e in t.elts)

        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.name == name:
                return True
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
            if any(bound(t) for t in targets):
                return True
        return False

    defining = [m for m in holders if getattr(getattr(m, name), "__module__", None) == m.__name__] or [m for m in holders if binds(m)]
    chosen = defining or holders
    if len({id(getattr(m, name)) for m in chosen}) > 1:
        raise ImportError(f"{what}: {name!r} is defined differently in " + ", ".join(m.__name__ for m in chosen), name=name)
    return chosen[0].__name__


def cache_dir_for_baseline() -> str:
    from wsoft.bench.harness import cache_dir

    d = cache_dir().parent / "baselines"
    d.mkdir(parents=True, exist_ok=True)
    return str(d)


def _raster_baseline(case: dict, ctx: dict) -> dict:
    """The rasterizer against the one of ``case["baseline"]`` on the same view, timed alternately in
    one process (11 rounds after a warm-up; median), with the maps compared texel by texel."""
    import statistics

    import warp as wp

    from wsoft.lightspace.view import DEPTH_CLEAR
    from wsoft.raster.depth_map import rasterize

    scene = load(case["scene"])
    light = scene.find_light(case["light"]) if case["light"] else scene.lights[0]
    row = {"scene": case["scene"], "light": light.path, "device": case["device"], "size": case["size"], "baseline": case["baseline"]}
    base = _baseline_module(case["baseline"])
    if base is None:
        return row | {"skipped": f"no git history with {case['baseline']}:{BASELINES[case['baseline']][0]} (run from a checkout)"}
    ds, view = _light_map_view(case, scene, light)
    # the same view for both (the baseline module's own LightView type, this checkout's view geometry):
    # the revisions fit views differently (a distant light's depth origin), the rasterizers are compared
    base_view = base.LightView(light_path=view.light_path, persp=view.persp, origin=view.origin, axes=view.axes, window=view.window,
                               near=view.near, far=view.far, width=view.width, height=view.height)
    checkout_fn = lambda: rasterize(ds, view, alpha_tested=scene.has_cutouts)  # noqa: E731
    base_fn = lambda: base.rasterize(ds, base_view, alpha_tested=scene.has_cutouts)  # noqa: E731
    a, b = checkout_fn().depth.numpy(), base_fn().depth.numpy()
    tn, tb = [], []
    for _ in range(11):
        for fn, acc in ((checkout_fn, tn), (base_fn, tb)):
            wp.synchronize()
            t0 = time.perf_counter()
            fn()
            wp.synchronize()
            acc.append(1e3 * (time.perf_counter() - t0))
    both = (a < DEPTH_CLEAR) & (b < DEPTH_CLEAR)
    rel = np.abs(a - b)[both] / b[both]
    return row | {"new_ms": statistics.median(tn), "baseline_ms": statistics.median(tb), "new_over_baseline": statistics.median(tn) / statistics.median(tb),
                  "new_ms_runs": tn, "baseline_ms_runs": tb, "identical_texels": float(np.mean(a == b)),
                  "coverage_mismatch": int(((a < DEPTH_CLEAR) != (b < DEPTH_CLEAR)).sum()), "max_rel_diff": float(rel.max()) if rel.size else 0.0}


def _raster_bound(case: dict, ctx: dict) -> dict:
    """The bound on the 15x target (:mod:`wsoft.bench.raster_bound`): the rasterizer, the idealised
    depth-only kernel and the fetch-and-box kernel on the same orthographic view and thread layout,
    and one BVH ray per texel, in 9 alternating rounds after a warm-up (medians)."""
    import statistics

    import warp as wp

    from wsoft.bench.raster_bound import Bound
    from wsoft.lightspace.view import DEPTH_CLEAR
    from wsoft.parallel import cpu_threads
    from wsoft.raster.depth_map import rasterize
    from wsoft.raster.rasterizer import BIG_TRIANGLE_TEXELS, CPU_CHUNK
    from wsoft.raster.triangle import SMALL_BOX_TEXELS
    from wsoft.raster.raycast import raycast_depth

    scene = load(case["scene"])
    light = scene.find_light(case["light"])
    dev = case["device"]
    ds, view = _light_map_view(case, scene, light)
    bound = Bound(ds, view, cpu_threads(), CPU_CHUNK)

    def clock(fn):
        wp.synchronize()
        t0 = time.perf_counter()
        fn()
        wp.synchronize()
        return 1e3 * (time.perf_counter() - t0)

    real_map = rasterize(ds, view, alpha_tested=scene.has_cutouts).depth.numpy()
    bound.draw()
    ideal_map = bound.depth()
    bound.fetch()
    texels = bound.texels.numpy().copy()
    raycast_depth(ds, view, alpha_tested=scene.has_cutouts)
    times = {"real": [], "draw": [], "small": [], "fetch": [], "ray": []}
    for k in range(9):
        steps = [("real", lambda: rasterize(ds, view, alpha_tested=scene.has_cutouts)), ("draw", lambda: bound.draw(BIG_TRIANGLE_TEXELS)),
                 ("small", lambda: bound.draw(SMALL_BOX_TEXELS)), ("fetch", bound.fetch),
                 ("ray", lambda: raycast_depth(ds, view, alpha_tested=scene.has_cutouts))]
        for name, fn in steps[k % 5:] + steps[: k % 5]:
            if name in ("draw", "small"):
                bound.clear()  # maps cleared off the clock (the rasterizer clears its own)
            times[name].append(clock(fn))
    a, r = ideal_map < DEPTH_CLEAR, real_map < DEPTH_CLEAR
    return {"scene": case["scene"], "light": light.path, "device": dev, "size": case["size"], "threads": cpu_threads(),
            "triangles": int(bound.T), "culled": int(bound.skip.numpy().sum()), "covering": int((texels > 0).sum()),
            "box_texels": int(texels.sum()), "large": int((texels > BIG_TRIANGLE_TEXELS).sum()), "small": int(((texels > 0) & (texels <= SMALL_BOX_TEXELS)).sum()), "small_box_texels": SMALL_BOX_TEXELS, "coverage_mismatch": int((a != r).sum()), "covered": int(r.sum()),
            **{f"{n}_ms": statistics.median(v) for n, v in times.items()}, **{f"{n}_ms_runs": v for n, v in times.items()}}


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


def bundled_scenes() -> list[str]:
    """Every bundled stage, by name."""
    from wsoft import usd_scenes

    return sorted(p.stem for p in Path(usd_scenes.folder()).iterdir() if p.suffix in (".usda", ".usdc", ".usdz"))


def _reference_frame(case: dict, ctx: dict) -> dict:
    """``reference samples=N`` on every light of a scene, per-ray against packet traversal: the
    reference passes' time (median of 3 after a warm-up), whether V is identical and, where not,
    how many pixels differ and by how much. A stage kept instanced (:func:`~wsoft.pipeline.load_stage`)
    is traced ray by ray only: packets walk the triangle soup."""
    import wsoft

    scene = load(case["scene"])
    kw = {"width": case["width"], "height": case["height"], "device": case["device"], "samples": case["samples"], "seed": 1}
    out = {"scene": case["scene"], "lights": len(scene.lights), "triangles": scene.total_triangles, "instanced": bool(scene.instanced)}
    frames = {}
    for mode in ("ray",) if scene.instanced else ("ray", "packet"):
        wsoft.render(scene, "reference", traversal=mode, **kw)
        runs = []
        for _ in range(3):
            fr = wsoft.render(scene, "reference", traversal=mode, **kw)
            st = fr.stats
            runs.append(sum(ms for name, ms in st["timings_ms"].items() if name.startswith("reference")))
        frames[mode] = fr
        out[f"{mode}_ms"] = float(np.median(runs))
        out[f"{mode}_frame_ms"] = st["timings_ms"]["total"]
    if scene.instanced:
        return out
    out["packet_over_ray"] = out["ray_ms"] / out["packet_ms"]
    chans = [c for c in frames["ray"].channels if c.startswith("V")]
    out["identical"] = all(np.array_equal(frames["ray"][c], frames["packet"][c]) for c in chans)
    differ = np.zeros(frames["ray"].V.shape, bool)
    for c in chans:
        differ |= frames["ray"][c] != frames["packet"][c]
    out["differing_pixels"] = int(differ.sum())
    out["max_abs_dv"] = float(max(np.abs(frames["ray"][c] - frames["packet"][c]).max() for c in chans if not c.endswith("stderr")))
    return out


def _throughput(case: dict, ctx: dict) -> dict:
    from wsoft.parallel import cpu_threads
    from wsoft.lightspace.light import disk_shaped
    from wsoft.raster.shadow_rays import ray_epsilon
    from wsoft.reference import reference_pattern, shadow_rays, trace_ray_packets, trace_reference, trace_rays
    from wsoft.reference.packets import packed_bvh
    from wsoft.pipeline import RenderContext, frame_setup
    from wsoft.raster.camera import camera_gpu
    from wsoft.raster.gbuffer import render_gbuffer
    from wsoft.scene.device import upload_scene

    scene = load(case["scene"])
    light = scene.find_light(case["light"]) if case["light"] else scene.lights[0]
    dev, w, h, n = case["device"], case["width"], case["height"], case["samples"]
    ds, _ = scene.device_copy(dev, upload_scene)
    ctx_r = RenderContext(scene, frame_setup(scene, w, h).camera, w, h, dev)
    gb = render_gbuffer(ds, camera_gpu(ctx_r.camera), w, h, 1, scene.has_cutouts)
    L = ctx_r.light_gpu(light)
    covered = int((gb.prim.numpy() >= 0).sum())
    nrays = covered * n
    pattern = reference_pattern(n, 0, True)
    eps = ray_epsilon(gb, light)
    disk = disk_shaped(light)
    threads = cpu_threads() if dev == "cpu" else None
    o, d, t = shadow_rays(ds, L, gb, pattern, disk, eps)
    packed_stats = packed_bvh(ds)[1]  # built once, outside the timings
    row = {"scene": case["scene"], "light": light.path, "device": dev, "rays": nrays, "threads": threads, "samples": n,
           "packed_bvh": packed_stats}
    # the reference pass (ray generation included) and the explicit rays (tracing only), per ray and in packets
    timed = {"pass_ray": lambda: trace_reference(ds, L, gb, pattern, disk, eps, "ray"),
             "pass_packet": lambda: trace_reference(ds, L, gb, pattern, disk, eps, "packet"),
             "rays_ray": lambda: trace_rays(ds, o, d, t),
             "rays_packet": lambda: trace_ray_packets(ds, o, d, t, n)}
    if dev == "cpu":  # what generation costs inside the pass, without tracing (bench/generation.py), on one thread
        import warp as wp

        from wsoft.bench.generation import generate_packets, random_draws
        from wsoft.parallel import launch_chunked
        from wsoft.reference import PER_THREAD

        ls = pattern.on(dev, disk)
        sink = wp.empty(gb.count, dtype=float, device=dev)
        parts = {"generation": lambda: launch_chunked(generate_packets, gb.count, inputs=[L, ls, gb.gpu(), eps, -1.0], outputs=[sink],
                                                      device=dev, min_chunk=256, per_thread=PER_THREAD),
                 "random_draws": lambda: launch_chunked(random_draws, gb.count, inputs=[ls, gb.gpu()], outputs=[sink], device=dev,
                                                        min_chunk=256, per_thread=PER_THREAD)}
        with _threads(1):
            for key, fn in parts.items():
                w1, _ = _timed(fn)
                row[f"{key}_1t_ns_per_ray"] = 1e9 * w1 / nrays
    for key, fn in timed.items():
        wall, cpu = _timed(fn)
        row[f"{key}_ms"], row[f"{key}_mrays_s"], row[f"{key}_cpu_over_wall"] = 1e3 * wall, nrays / wall / 1e6, cpu / wall
        if dev == "cpu":
            with _threads(1):
                w1, _ = _timed(fn)
            row[f"{key}_1t_mrays_s"] = nrays / w1 / 1e6
    warp_hits = trace_rays(ds, o, d, t).numpy()
    row["packets_identical"] = bool(np.array_equal(trace_ray_packets(ds, o, d, t, n).numpy(), warp_hits)
                                    and np.array_equal(timed["pass_ray"]()[0].numpy(), timed["pass_packet"]()[0].numpy()))
    row["occluded_fraction"] = float(warp_hits.mean())
    try:
        from embreex import mesh_construction, rtcore, rtcore_scene
    except ImportError:
        row["embree"] = "embreex not installed (pip install -e '.[peers]')"
        return row
    if scene.has_cutouts:
        row["embree"] = "skipped: scene has cutouts (embreex has no alpha-test filter)"
        return row
    es = rtcore_scene.EmbreeScene(rtcore.EmbreeDevice())
    mesh_construction.TriangleMesh(es, scene.points.astype(np.float32), scene.triangles.astype(np.int32))
    on, dn, tn = o.numpy().astype(np.float32), d.numpy().astype(np.float32), t.numpy().astype(np.float32)
    es.run(on[:1000], dn[:1000], dists=tn[:1000], query="OCCLUDED")  # builds the BVH
    # embreex traces a batch on the calling thread; run one batch per thread for the n-thread figure
    nt = threads or 1
    parts = [slice(i * len(on) // nt, (i + 1) * len(on) // nt) for i in range(nt)]
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(nt)
    res = {}

    def one():
        res["hits"] = es.run(on, dn, dists=tn, query="OCCLUDED")

    def many():
        list(pool.map(lambda sl: es.run(on[sl], dn[sl], dists=tn[sl], query="OCCLUDED"), parts))

    e1_wall, e1_cpu = _timed(one)
    en_wall, en_cpu = _timed(many)
    pool.shutdown()
    emb_hits = (res["hits"] >= 0).astype(np.int32)
    row.update({
        "embree_1t_mrays_s": nrays / e1_wall / 1e6,
        "embree_mrays_s": nrays / en_wall / 1e6, "embree_cpu_over_wall": en_cpu / en_wall,
        "agreement_with_embree": float(np.mean(emb_hits == warp_hits)),
    })
    for key in timed:
        row[f"{key}_over_embree"] = row[f"{key}_mrays_s"] / row["embree_mrays_s"]
        if f"{key}_1t_mrays_s" in row:
            row[f"{key}_over_embree_1t"] = row[f"{key}_1t_mrays_s"] / row["embree_1t_mrays_s"]
    return row


class _threads:
    """Temporarily set the number of CPU threads Warp launches use."""

    def __init__(self, n: int):
        self.n = n

    def __enter__(self):
        import os

        self.old = os.environ.get("WSOFT_THREADS")
        os.environ["WSOFT_THREADS"] = str(self.n)

    def __exit__(self, *exc):
        import os

        if self.old is None:
            os.environ.pop("WSOFT_THREADS", None)
        else:
            os.environ["WSOFT_THREADS"] = self.old


# -- report ------------------------------------------------------------------------------------


# Why a stage's packet and per-ray references differ, for the stages the sweep finds not identical
PACKET_DIFFERENCES = {
    "city": ["On `city` (pixel (79, 247) of the Rect light, one ray of 64) the ray passes through the shared edge of two",
             "axis-aligned triangles; Warp's per-ray walk drops their zero-thickness boxes, the packet reaches them, and a brute",
             "force over every triangle with Warp's own test finds the hit",
             "(`tests/test_packets.py::test_a_ray_grazing_a_shared_edge_that_warps_per_ray_walk_drops`)."],
    "hl2_like": ["On `hl2_like` (the Sky light; e.g. pixel (411, 313), one ray of 64) each ray passes through the shared edge of",
                 "two triangles of one alpha-tested card: a hole in the first it meets, present in the second less than 1e-5",
                 "further. The per-ray walk steps 1e-5 (1 + t) past a hole (not to meet it again) and so skips the second; the",
                 "packet tests each triangle at its own hit and agrees with a brute force over every triangle with the alpha test",
                 "(`tests/test_packets.py::test_a_ray_through_a_cutout_cards_shared_edge_that_the_per_ray_step_skips`)."],
    "fence_mesh": ["On `fence_mesh` (pixel (372, 426), one ray of 64) the ray meets two triangles at the same t = 2.1116 (their",
                   "shared edge): the per-ray walk reports it unblocked, the packet and a brute force over every triangle blocked (as",
                   "on `city`)."],
    "greece": ["On `greece` (Light1, pixel (391, 197), one ray of 64) the ray crosses a hole of one cutout and then meets a",
               "second cutout triangle on the edge of its texture's hole: from the ray's own origin (the packet, and a brute",
               "force over every triangle with the alpha test) the hit at t = 3.8518827 is in the hole and the ray is unblocked;",
               "the per-ray walk re-queries from 1e-5 (1 + t) past the first hole, meets it at 3.8518825 and the alpha test",
               "there says present."],
}


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    renders = [r for r in rows if r["case"]["kind"] == "render"]
    raster = [r for r in rows if r["case"]["kind"] == "raster_vs_raycast"]
    thr = [r for r in rows if r["case"]["kind"] == "ray_throughput"]
    L = report_header("foundation", rows, md, ctx)
    L += accuracy_table(renders)
    if raster:
        L += ["", "## Light depth map: rasterizer vs one BVH ray per texel (target: >= 15x, floor >= 10x; CPU time / wall >= 1.7 on 2 cores)", ""]
        L.append("| scene | light | device | size | triangles | raster ms | ray/texel ms | speedup | raster CPU/wall | ray CPU/wall | coverage mismatch | depth rel. err p99 |")
        L.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in raster:
            L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['device']} | {r['size']} | {r['triangles']} | {r['raster_ms']:.1f} | {r['raycast_ms']:.1f} | "
                     f"{r['speedup']:.1f}x | {r['raster_cpu_over_wall']:.2f} | {r['raycast_cpu_over_wall']:.2f} | {r['coverage_mismatch']:.2e} | {r['depth_rel_err_p99']:.1e} |")
    if thr:
        L += ["", "## Reference shadow-ray throughput beside Embree (same rays, same thread count)", ""]
        L.append("Embree runs through embreex, which traces a batch on the calling thread: the 1-thread columns are the like-for-like")
        L.append("figure; for N threads Embree gets one batch per Python thread (embreex holds the GIL part of the time: see its CPU/wall).")
        L.append("`pass`: the reference's tracing kernel, which generates each ray from its light sample (the stratified sample, the")
        L.append("light point, the direction) before tracing it; `rays`: the same rays written out first and traced from arrays, as")
        L.append("Embree traces them. `ray`: one ray at a time through Warp's `mesh_query_ray_anyhit`; `packet`: a receiver's rays 32")
        L.append("at a time through the same BVH (`wsoft.reference.packets`). Target: packet ≥ 1.0× Embree on the same rays,")
        L.append("1 thread and all threads. `identical`: packet and per-ray answers equal bit for bit (pass visibility and ray hits).")
        L.append("")
        L.append("| scene | light | samples | threads | rays | traced | Warp ray Mrays/s | Warp packet Mrays/s | Embree Mrays/s | packet / Embree | "
                 "packet / ray | 1 thread: ray | packet | Embree | packet / Embree | identical |")
        L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in thr:
            if "pass_packet_mrays_s" not in r:
                continue  # a row without the packet columns (rerun the sweep)
            for kind in ("rays", "pass"):
                e, e1 = r.get("embree_mrays_s"), r.get("embree_1t_mrays_s")
                emb = f"{e:.2f} ({r['embree_cpu_over_wall']:.2f})" if e else str(r.get("embree", ""))
                ratio = f"{r[f'{kind}_packet_mrays_s'] / e:.2f}" if e else ""
                ratio1 = f"{r[f'{kind}_packet_1t_mrays_s'] / e1:.2f}" if e1 and f"{kind}_packet_1t_mrays_s" in r else ""
                L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['samples']} | {r['threads']} | {r['rays']} | "
                         f"{'from arrays' if kind == 'rays' else 'pass (generates its rays)'} | "
                         f"{r[f'{kind}_ray_mrays_s']:.2f} ({r[f'{kind}_ray_cpu_over_wall']:.2f}) | "
                         f"{r[f'{kind}_packet_mrays_s']:.2f} ({r[f'{kind}_packet_cpu_over_wall']:.2f}) | {emb} | {ratio} | "
                         f"{r[f'{kind}_packet_mrays_s'] / r[f'{kind}_ray_mrays_s']:.2f} | "
                         f"{r.get(f'{kind}_ray_1t_mrays_s', float('nan')):.2f} | {r.get(f'{kind}_packet_1t_mrays_s', float('nan')):.2f} | "
                         f"{e1 if e1 is None else f'{e1:.2f}'} | {ratio1} | {r['packets_identical']} |")
        gen = [r for r in thr if "generation_1t_ns_per_ray" in r and r.get("embree_1t_mrays_s") and "pass_packet_1t_mrays_s" in r]
        if gen:
            L += ["", "What the pass spends generating its rays, on one thread (ns of wall time per ray; `bench/generation.py`):",
                  "`generation`: the pass's kernel with its tracing left out (the stratified sample, the light point, the direction,",
                  "the plane and light-side tests); `random draws`: only its two random draws a sample, a chain of dependent draws",
                  "per receiver that the reference's samples fix bit for bit; `tracing in the pass`: the pass less `generation`.",
                  "For the pass to match Embree, generation must fit in `Embree` less `tracing in the pass`.", "",
                  "| scene | light | samples | pass | generation | random draws | tracing in the pass | Embree | room for generation |",
                  "|---|---|---|---|---|---|---|---|---|"]
            for r in gen:
                p1 = 1e3 / r["pass_packet_1t_mrays_s"]
                e1 = 1e3 / r["embree_1t_mrays_s"]
                g = r["generation_1t_ns_per_ray"]
                L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['samples']} | {p1:.1f} | {g:.1f} | {r['random_draws_1t_ns_per_ray']:.1f} | "
                         f"{p1 - g:.1f} | {e1:.1f} | {e1 - (p1 - g):.1f} |")
        pk = list({r["scene"]: r for r in thr if "packed_bvh" in r}.values())
        if pk:
            L += ["", "The packets' BVH: Warp's, repacked once per scene (both children's boxes in one 64-byte record, depth first; the",
                  "triangles' corners in leaf order): " + "; ".join(
                      f"{r['scene']}: {r['packed_bvh']['inner_nodes']} inner nodes, {r['packed_bvh']['bytes'] / 2**20:.1f} MiB, "
                      f"{r['packed_bvh']['build_ms']:.0f} ms" for r in pk) + "."]
    rf = [r for r in rows if r["case"]["kind"] == "reference_frame"]
    if rf:
        c0 = rf[0]["case"]
        L += ["", f"## `reference samples={c0['samples']}` at {c0['width']}×{c0['height']}: per-ray against packet traversal", ""]
        L.append("The reference passes of a frame (every light of the stage), median of 3 after a warm-up, with `traversal=ray` (one")
        L.append("ray at a time) and `traversal=packet` (the CPU default); `identical`: every light's V and V_stderr equal bit for bit.")
        L.append("")
        L.append("| scene | lights | triangles | ray ms | packet ms | speed-up | identical |")
        L.append("|---|---|---|---|---|---|---|")
        for r in rf:
            if r.get("instanced"):
                L.append(f"| {r['scene']} | {r['lights']} | {r['triangles']:,} (instanced) | {r['ray_ms']:.0f} | — | — | — |")
                continue
            L.append(f"| {r['scene']} | {r['lights']} | {r['triangles']:,} | {r['ray_ms']:.0f} | {r['packet_ms']:.0f} | {r['packet_over_ray']:.2f}× | "
                     f"{r['identical']} |")
        if any(r.get("instanced") for r in rf):
            L += ["", "Instanced stages (kept instanced by `instancing=auto`: they would not fit flattened) are traced ray by ray: "
                      "packets walk the triangle soup only."]
        odd = [r for r in rf if r.get("identical") is False]
        if odd:
            L += ["", "Not identical: " + "; ".join(
                f"`{r['scene']}`, {r.get('differing_pixels', '?')} pixel(s), max |ΔV| {r.get('max_abs_dv', float('nan')):.4f}" for r in odd) + "."]
            found = {r["scene"] for r in odd}
            for scene_name, lines in PACKET_DIFFERENCES.items():
                if scene_name in found:
                    L += ["", *lines]
            L += ["", "In every difference found the packet agrees with the brute force. Differences appear where a packet decides",
                  "rays that the per-ray walk would decide: a packet that gives up hands its rays to the per-ray walk, so the budget",
                  "(`WORK_PER_RAY`) moves them."]
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
    # CPU utilisation of the heavy passes inside renders
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
        from wsoft.parallel import cpu_threads

        L += ["", f"Target: every pass over 50 ms at CPU/wall ≥ 1.8 on {cpu_threads()} threads: "
              + ("met." if not low else "NOT met by " + "; ".join(low) + ".")]
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
