"""The CUDA path without a GPU: every Warp module of the package that owns kernels is compiled for
CUDA (PTX through the NVRTC that Warp's wheels carry) into a folder beside wsoft's reference cache (:func:`ptx_dir`;
the user's kernel cache is left alone; a module whose code is unchanged is not compiled again): for
the newest architecture this NVRTC targets in the quick mode, and for sm_70, sm_75 and sm_80 in the
full mode (``-m slow``). An architecture this NVRTC cannot target
is skipped with the reason (CUDA 13's NVRTC dropped Volta, sm_70). Generic kernels compile
through their declared overloads; the rasterizer's specialised kernels (one Warp module per
projection, fragment, conservative/alpha, listed/deferring combination) are generated first. A
module added later is picked up by the walk over the package, with no edit here."""

from __future__ import annotations

import importlib
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import warp as wp

import wsoft

NEWEST = "newest"  # the newest architecture the NVRTC targets (sm_90 for CUDA 12 and 13)
ARCHS = (NEWEST, pytest.param(70, marks=pytest.mark.slow), pytest.param(75, marks=pytest.mark.slow), pytest.param(80, marks=pytest.mark.slow))
SKIP_PREFIXES = ("wsoft.__main__", "wsoft.bench", "wsoft.usd_scenes", "wsoft.gpu_check")


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


# the corner sources whose code is the same for every fragment: compiled for one fragment, on one arch
OTHER_SOURCES = ((True, False), (False, False))


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


def _nvrtc_missing() -> str | None:
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


@pytest.fixture(scope="module")
def modules():
    why = _nvrtc_missing()
    if why:
        pytest.skip(why)
    return kernel_modules()


def test_every_kernel_module_is_found(modules):
    names = set(modules)
    for expected in ("wsoft.reference", "wsoft.reference.packets", "wsoft.raster.gbuffer", "wsoft.raster.horizon", "wsoft.accel.sat", "wsoft.techniques.essm",
                     "wsoft.techniques.ssm.kernels"):
        assert expected in names
    raster = {k.module.name for k in rasterizer_kernels()}  # the specialised rasterizers: one "unique" module each
    from wsoft.raster.rasterizer import FRAGMENTS

    assert len(raster) == 32 * len(FRAGMENTS) and raster <= names
    assert all(m.kernels for m in modules.values())


@pytest.mark.parametrize("arch", ARCHS)
def test_every_module_compiles_for_cuda(modules, arch):
    from warp._src import context  # importable: the fixture checked

    supported = getattr(context.runtime, "nvrtc_supported_archs", None)
    if arch == NEWEST:
        arch = newest_arch()
    elif supported is not None and arch not in supported:
        version = ".".join(map(str, context.runtime.get_nvrtc_version()))
        pytest.skip(f"this NVRTC (CUDA {version}) cannot target sm_{arch}; it targets sm_{min(supported)} and newer")
    _compile_all(modules, arch, ptx_dir(arch))


def newest_arch() -> int:
    """The newest architecture this NVRTC targets (sm_90 where Warp does not say)."""
    from warp._src import context

    return max(getattr(context.runtime, "nvrtc_supported_archs", None) or [90])


def ptx_dir(arch: int) -> Path:
    """Where the PTX of ``arch`` is kept between runs: a folder of wsoft's cache (not Warp's kernel cache).
    Warp names each module's PTX by the hash of its code and options and compiles only a module whose
    PTX of that hash is missing, so an unchanged module is not compiled again and any change is."""
    return Path(os.environ.get("WSOFT_CACHE_DIR", Path.home() / ".cache" / "wsoft")) / "cuda-check" / f"sm_{arch}"


def _compile_all(modules: dict, arch: int, folder: Path) -> None:
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

    with ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1))) as pool:
        errors = [e for e in pool.map(build, sorted(modules.items())) if e]
    assert not errors, "\n".join(errors)


@pytest.mark.slow
def test_the_rasterizers_other_corner_sources_compile_for_cuda(modules):
    """Instanced work items and corners projected per triangle (short triangle lists) are the same code
    for every fragment and architecture: those specialisations for one fragment, on one arch."""
    extra = {k.module.name: k.module for k in rasterizer_kernels(OTHER_SOURCES, fragments=("depth_min",))}
    assert len(extra) == 64 and not set(extra) & set(modules)
    _compile_all(extra, newest_arch(), ptx_dir(newest_arch()))
