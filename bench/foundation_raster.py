"""Sweep ``foundation``'s rows of the light depth map's rasterizer: against one BVH ray per texel
(``raster_vs_raycast``), against earlier revisions of itself read from the git history
(``raster_baseline``, :data:`BASELINES`) and against an idealised bound
(``raster_bound``); :func:`timed`, the fastest of a few calls, which the other rows use too."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from wsoft.bench.harness import load

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


def timed(fn, repeats=3):
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
    r_wall, r_cpu = timed(lambda: rasterize(ds, view, alpha_tested=scene.has_cutouts), repeats=5)
    c_wall, c_cpu = timed(lambda: raycast_depth(ds, view, alpha_tested=scene.has_cutouts), repeats=5)
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
