"""Compiling every Warp module of the package for CUDA without a GPU (PTX through the NVRTC that
Warp's wheels carry), for ``tests/test_cuda_compile.py``: which modules own kernels
(:func:`kernel_modules`, the rasterizer's specialisations generated first), where each
architecture's PTX is kept between runs (:func:`ptx_dir`) and the compile itself
(:func:`compile_all`: one error line per module that fails).

Run as a script (``python tests/cuda_check.py ARCH OUT.json``) it compiles every module for ``ARCH``
(``newest`` or a number) and writes the errors and the time to ``OUT.json``: the quick mode starts it
when the session begins (``tests/conftest.py``), so that NVRTC works on a core the tests leave idle,
and its test reads the file at the end of the session."""

from __future__ import annotations

import importlib
import json
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import warp as wp

import wsoft

NEWEST = "newest"  # the newest architecture the NVRTC targets (sm_90 for CUDA 12 and 13)
SKIP_PREFIXES = ("wsoft.__main__", "wsoft.bench", "wsoft.usd_scenes", "wsoft.gpu_check")
# the corner sources whose code is the same for every fragment: compiled for one fragment, on one arch
OTHER_SOURCES = ((True, False), (False, False))


def rasterizer_kernels(sources=((False, True),), fragments=None) -> list:
    """Every specialised rasterizer kernel: fragment x projection x conservative x alpha x listed x deferring
    x where the corners come from (``sources``: (instanced, projected first) pairs; default: the points,
    projected first, as a whole mesh is drawn). ``fragments``: names (default: every registered fragment)."""
    from wsoft.raster.rasterizer import FRAGMENTS, ORTHOGRAPHIC, PERSPECTIVE, make_rasterizer

    out = []
    for name, spec in FRAGMENTS.items():
        if fragments is not None and name not in fragments:
            continue
        for view in (PERSPECTIVE, ORTHOGRAPHIC):
            for conservative in (False, True):
                for alpha in (False, True):
                    r = make_rasterizer(view, spec.func, conservative=conservative, alpha=alpha)
                    out += [r.kernel(listed, defer, instanced, preproj) for listed in (False, True) for defer in (False, True)
                            for instanced, preproj in sources]
    return out


def kernel_modules() -> dict[str, object]:
    """Warp module name -> module, for every module of the package that owns at least one kernel."""
    kernels = []
    root = Path(wsoft.__file__).parent
    bench = Path(importlib.import_module("wsoft.bench").__path__[0])  # bench/ in a checkout, wsoft/bench installed
    files = [(p, p.relative_to(root.parent)) for p in sorted(root.rglob("*.py"))]  # every file: namespace packages (wsoft.raster) included
    if not bench.is_relative_to(root):
        files += [(p, Path("wsoft", "bench") / p.relative_to(bench)) for p in sorted(bench.rglob("*.py"))]
    for path, rel in files:
        parts = list(rel.with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        name = ".".join(parts)
        bench_kernels = name.startswith("wsoft.bench.") and "@wp.kernel" in path.read_text()  # the benchmarks' own kernels
        if name.startswith(SKIP_PREFIXES) and not bench_kernels:
            continue
        mod = importlib.import_module(name)
        kernels += [v for v in vars(mod).values() if isinstance(v, wp.Kernel)]
    kernels += rasterizer_kernels()
    return {k.module.name: k.module for k in kernels}


def nvrtc_missing() -> str | None:
    """Why CUDA compilation cannot run here (no NVRTC in this Warp build), or None."""
    wp.init()
    try:
        from warp._src import context
    except ImportError:  # another Warp layout: its runtime is not where this test looks
        return f"Warp {wp.__version__} keeps its runtime elsewhere (no warp._src.context)"
    core = getattr(context.runtime, "core", None)
    if core is None or not hasattr(core, "wp_cuda_compile_program"):
        return "this Warp build has no CUDA compiler (NVRTC)"
    return None


def newest_arch() -> int:
    """The newest architecture this NVRTC targets (sm_90 where Warp does not say)."""
    from warp._src import context

    return max(getattr(context.runtime, "nvrtc_supported_archs", None) or [90])


def ptx_dir(arch: int) -> Path:
    """Where the PTX of ``arch`` is kept between runs: a folder of wsoft's cache (not Warp's kernel cache).
    Warp names each module's PTX by the hash of its code and options and compiles only a module whose
    PTX of that hash is missing, so an unchanged module is not compiled again and any change is."""
    return Path(os.environ.get("WSOFT_CACHE_DIR", Path.home() / ".cache" / "wsoft")) / "cuda-check" / f"sm_{arch}"


def compile_all(modules: dict, arch: int, folder: Path, workers: int | None = None) -> list[str]:
    """Compile ``modules`` (name -> Warp module) for ``arch`` into ``folder``, on ``workers`` threads
    (default: up to 4, one a core): one line per module that fails (its name, the arch and the
    compiler's message), none when every module compiled."""

    def build(item):
        name, module = item
        where = folder / name
        try:
            made = [Path(a) for a in wp.compile_aot_module(module, arch=arch, module_dir=str(where), use_ptx=True)]
        except Exception as exc:  # noqa: BLE001 - any compiler error is the finding
            return f"{name} (sm_{arch}): {' '.join(str(exc).split())[:2000]}"
        ptx = [a for a in made if a.suffix == ".ptx" and a.is_file()]
        if not ptx:
            return f"{name} (sm_{arch}): no PTX written"
        stems = {a.name.split(f".sm{arch}.")[0] + "." for a in ptx}
        for old in where.iterdir():  # an earlier version's files of this module
            if not any(old.name.startswith(st) for st in stems):
                old.unlink()
        return None

    n = workers if workers is not None else max(1, min(4, os.cpu_count() or 1))
    with ThreadPoolExecutor(max_workers=n) as pool:
        return [e for e in pool.map(build, sorted(modules.items())) if e]


def main(argv: list[str]) -> int:
    """``ARCH OUT.json [WORKERS]``: compile every module for ``ARCH`` and write
    ``{"arch", "modules", "errors", "seconds"}`` (or ``{"skip": why}`` without NVRTC) to ``OUT.json``."""
    arch_arg, out = argv[0], Path(argv[1])
    workers = int(argv[2]) if len(argv) > 2 else None
    t0 = time.perf_counter()
    why = nvrtc_missing()
    if why:
        result = {"skip": why}
    else:
        arch = newest_arch() if arch_arg == NEWEST else int(arch_arg)
        modules = kernel_modules()
        errors = compile_all(modules, arch, ptx_dir(arch), workers)
        result = {"arch": arch, "modules": len(modules), "errors": errors, "seconds": round(time.perf_counter() - t0, 1)}
    tmp = out.with_suffix(".part")
    tmp.write_text(json.dumps(result))
    tmp.replace(out)  # the file appears whole
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
