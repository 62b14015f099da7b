"""Shared fixtures: in-memory stages, devices, small render sizes, the command line in-process, and
the quick mode's CUDA compile started in a process of its own when the session begins."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from wsoft.metrics.exact import parallel_rect_exact  # noqa: F401  (tests import it from here)
from wsoft.stages import add_box, add_camera, add_quad, add_rect_light, make_stage  # noqa: F401  (the tests' stage builders)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "usd_scenes")
DISTANT_ONLY = {"csm"}  # techniques that shadow DistantLights alone (each declines a local light with its reason)
SKY_ONLY = {"gtao", "skymaps"}  # techniques that shadow a DomeLight alone (each declines every other light with its reason)


def skip_if_no_local_lights(technique: str) -> None:
    """Skip a test over local lights for a technique of :data:`DISTANT_ONLY` or :data:`SKY_ONLY`
    (its own tests cover it)."""
    if technique in DISTANT_ONLY:
        pytest.skip(f"{technique} shadows DistantLights alone; this test's lights are local")
    if technique in SKY_ONLY:
        pytest.skip(f"{technique} shadows a DomeLight alone; this test's lights are local")


_CUDA_FILE = "test_cuda_compile.py"
_CUDA_NEWEST = "test_every_module_compiles_for_cuda[newest]"
_BACKGROUND = pytest.StashKey[dict]()


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """The CUDA compile's tests run last; when the newest architecture's compile is selected beside
    other tests, it starts now in a process of its own (``tests/cuda_check.py``, on the cores but
    one: NVRTC then works while the tests, mostly on one core, run), and its test reads the result
    (:func:`background_result`)."""
    cuda = [i for i in items if i.nodeid.split("::")[0].endswith(_CUDA_FILE)]
    if not cuda or len(cuda) == len(items):
        return
    items[:] = [i for i in items if i not in cuda] + cuda
    if not any(i.nodeid.endswith(_CUDA_NEWEST) for i in cuda):
        return
    folder = Path(tempfile.mkdtemp(prefix="wsoft-cuda-check-"))
    out, log = folder / "newest.json", folder / "stderr.txt"
    workers = max(1, min(4, (os.cpu_count() or 1) - 1))
    with open(log, "wb") as err:
        proc = subprocess.Popen([sys.executable, str(Path(__file__).with_name("cuda_check.py")), "newest", str(out), str(workers)],
                                stdout=subprocess.DEVNULL, stderr=err)
    config.stash[_BACKGROUND] = {"proc": proc, "out": out, "log": log, "folder": folder}


def background_result(config, timeout: float = 1800.0) -> dict | None:
    """The result of the newest architecture's CUDA compile that the session started
    (:func:`pytest_collection_modifyitems`), once it ends; None where none was started (the test
    compiles in its own process then). A compile process that failed is an assertion naming its
    exit code and its last lines; one that found no NVRTC skips the test with the reason."""
    job = config.stash.get(_BACKGROUND, None)
    if job is None:
        return None
    rc = job["proc"].wait(timeout=timeout)
    if rc != 0 or not job["out"].is_file():
        tail = job["log"].read_text(errors="replace").strip().splitlines()[-20:]
        raise AssertionError(f"the CUDA compile process exited {rc}:\n" + "\n".join(tail))
    result = json.loads(job["out"].read_text())
    if "skip" in result:
        pytest.skip(result["skip"])
    return result


def pytest_unconfigure(config):
    job = config.stash.get(_BACKGROUND, None)
    if job is None:
        return
    if job["proc"].poll() is None:  # the session ended before its test read it
        job["proc"].kill()
        job["proc"].wait()
    shutil.rmtree(job["folder"], ignore_errors=True)


def _devices():
    import warp as wp

    import wsoft.parallel  # noqa: F401

    wp.init()
    wanted = os.environ.get("WSOFT_TEST_DEVICES")  # e.g. "cuda:0" (python -m wsoft.gpu_check sets it)
    if wanted:
        return [d.strip() for d in wanted.split(",") if d.strip()]
    devs = ["cpu"]
    if wp.is_cuda_available():
        devs.append("cuda:0")
    return devs


DEVICES = _devices()


@pytest.fixture(params=DEVICES)
def device(request):
    return request.param


def wsoft_cli(*args, cwd: str | None = None) -> subprocess.CompletedProcess:
    """``wsoft ARGS`` through the command line's own ``main``, in this process
    (:func:`wsoft.cli.run_captured`; a new interpreter per call costs seconds, and tests of what only
    a fresh process shows, imports and USD's C++ output, run one), from ``cwd``: its exit code and
    what it printed, as ``subprocess.run`` gives them."""
    from wsoft.cli import run_captured

    here = os.getcwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        rc, out, err = run_captured(args)
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["wsoft", *map(str, args)], rc, out, err)


def scene_path(name: str) -> str:
    return os.path.join(SCENES, name)


def box_plane_ground_error(f, min_penumbra: int = 100):
    """Error of a render of ``box_plane.usda`` on its ground against :func:`parallel_rect_exact`:
    (MAE, MAE in the exact penumbra, max). Asserts the view holds at least ``min_penumbra``
    penumbra pixels, so a test cannot pass on an empty penumbra."""
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    exact = parallel_rect_exact(f["P.X"], f["P.Y"], 3.0, 1.0, 1.0, 0.5)
    err = np.abs(f.V - exact)[g]
    pen = ((exact > 0.01) & (exact < 0.99))[g]
    assert pen.sum() > min_penumbra
    return err.mean(), err[pen].mean(), err.max()
