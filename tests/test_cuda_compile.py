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

import pytest
from conftest import background_result
from cuda_check import NEWEST, OTHER_SOURCES, compile_all, kernel_modules, newest_arch, nvrtc_missing, ptx_dir, rasterizer_kernels

ARCHS = (NEWEST, pytest.param(70, marks=pytest.mark.slow), pytest.param(75, marks=pytest.mark.slow), pytest.param(80, marks=pytest.mark.slow))


@pytest.fixture(scope="module")
def modules():
    why = nvrtc_missing()
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
def test_every_module_compiles_for_cuda(modules, arch, request):
    """The newest architecture's compile runs in the process the session started at its beginning
    (``tests/conftest.py``: NVRTC on a core the other tests leave idle) where there is one, else here."""
    from warp._src import context  # importable: the fixture checked

    supported = getattr(context.runtime, "nvrtc_supported_archs", None)
    if arch == NEWEST:
        started = background_result(request.config)
        if started is not None:
            assert started.get("arch") == newest_arch() and started.get("modules") == len(modules), started
            assert not started["errors"], "\n".join(started["errors"])
            return
        arch = newest_arch()
    elif supported is not None and arch not in supported:
        version = ".".join(map(str, context.runtime.get_nvrtc_version()))
        pytest.skip(f"this NVRTC (CUDA {version}) cannot target sm_{arch}; it targets sm_{min(supported)} and newer")
    errors = compile_all(modules, arch, ptx_dir(arch))
    assert not errors, "\n".join(errors)


@pytest.mark.slow
def test_the_rasterizers_other_corner_sources_compile_for_cuda(modules):
    """Instanced work items and corners projected per triangle (short triangle lists) are the same code
    for every fragment and architecture: those specialisations for one fragment, on one arch."""
    extra = {k.module.name: k.module for k in rasterizer_kernels(OTHER_SOURCES, fragments=("depth_min",))}
    assert len(extra) == 64 and not set(extra) & set(modules)
    errors = compile_all(extra, newest_arch(), ptx_dir(newest_arch()))
    assert not errors, "\n".join(errors)
