"""Shared fixtures: in-memory stages, devices, small render sizes, the command line in-process."""

from __future__ import annotations

import os
import subprocess

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
