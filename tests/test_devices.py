"""Kernels whose CPU and CUDA behaviour can differ (README, "Devices and threads"):

* launches chunked differently by device (``launch_chunked``: slices on a CPU thread pool, one
  launch on CUDA; the rasterizer: private targets or bands on CPU, bands with atomics on CUDA) —
  every technique's frame must not depend on how its launches are cut: 1 thread and 5 threads
  give the same image bit for bit, and so does ``cuda:0`` when a GPU is present (to a float
  tolerance: the CUDA compiler contracts multiply-adds);
* atomics across threads (the rasterizer's fragments: ``tests/test_threads.py`` on CPU, here the
  CUDA depth maps against the CPU's);
* float64 in kernels (the SAT box integrals of ``wsoft.accel.sat``): the same sums on both.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DEVICES, DISTANT_ONLY, SKY_ONLY, scene_path

import wsoft
from wsoft.techniques import TECHNIQUES

SMALL = dict(width=40, height=30)


def _params(technique: str) -> dict:
    return TECHNIQUES[technique].quick_params


@pytest.mark.parametrize("technique", sorted(TECHNIQUES))
def test_frames_do_not_depend_on_how_launches_are_chunked(monkeypatch, technique):
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    frames = []
    for threads in ("1", "5"):
        monkeypatch.setenv("WSOFT_THREADS", threads)
        frames.append(wsoft.render(scene, technique, light="Sun" if technique in DISTANT_ONLY else "Dome" if technique in SKY_ONLY else "Disk" if technique != "ssm" else "Rect", device="cpu", **SMALL, **_params(technique)))
    a, b = frames
    assert (a["A"] > 0).sum() > 500
    for ch in ("V", "R", "G", "B"):
        assert np.array_equal(a[ch], b[ch]), (technique, ch, np.abs(a[ch] - b[ch]).max())


GPU = [d for d in DEVICES if d != "cpu"]


@pytest.mark.skipif(not GPU, reason="no GPU here: this comparison runs where one is present (python -m wsoft.gpu_check)")
@pytest.mark.parametrize("technique", sorted(TECHNIQUES))
def test_cuda_frames_match_the_cpu(technique):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    cpu = wsoft.render(scene, technique, device="cpu", **SMALL, **_params(technique))
    for dev in GPU:
        gpu = wsoft.render(scene, technique, device=dev, **SMALL, **_params(technique))
        assert np.array_equal(cpu["A"], gpu["A"])
        d = np.abs(cpu.V - gpu.V)
        # binary decisions at a texel boundary may flip where float contraction moves a depth by an ulp
        assert np.mean(d > 1e-3) < 0.01 and np.median(d) < 1e-5, (technique, dev, d.max(), np.mean(d > 1e-3))


@pytest.mark.skipif(not GPU, reason="no GPU here: this comparison runs where one is present (python -m wsoft.gpu_check)")
def test_cuda_depth_maps_match_the_cpu():
    """The rasterizer's CUDA path (bands with atomic_min) against the CPU's private targets."""
    from wsoft.raster.depth_map import rasterize
    from wsoft.scene.device import upload_scene
    from wsoft.lightspace.fit import fit_light_view

    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    for light in scene.lights:
        lo, hi = scene.bounds
        view = fit_light_view(light, scene.caster_points, lo, hi, 512)
        maps = {}
        for dev in ["cpu", *GPU]:
            ds, _ = scene.device_copy(dev, upload_scene)
            maps[dev] = rasterize(ds, view, alpha_tested=False).depth.numpy()
        for dev in GPU:
            a, b = maps["cpu"], maps[dev]
            assert np.array_equal(a >= 1e30, b >= 1e30)
            both = a < 1e30
            assert np.allclose(a[both], b[both], rtol=1e-5), (light.path, dev)


@pytest.mark.skipif(not GPU, reason="no GPU here: this comparison runs where one is present (python -m wsoft.gpu_check)")
def test_cuda_sat_box_sums_match_the_cpu():
    """float64 in a kernel (the SAT's corner differences): the same sums on CUDA as on CPU."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    for tech in ("essm", "vssm"):
        cpu = wsoft.render(scene, tech, device="cpu", **SMALL, shadow_map_size=512)
        for dev in GPU:
            gpu = wsoft.render(scene, tech, device=dev, **SMALL, shadow_map_size=512)
            assert np.abs(cpu.V - gpu.V).max() < 1e-3, (tech, dev)


def test_gpu_check_writes_its_report(tmp_path):
    """``python -m wsoft.gpu_check`` end to end on the CPU (one small quick sweep, no tests)."""
    import subprocess
    import sys

    from conftest import ROOT

    p = subprocess.run([sys.executable, "-m", "wsoft.gpu_check", "--device", "cpu", "--skip-tests", "--sweeps", "ssm-table1",
                        "--out-dir", str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert p.returncode == 0, p.stderr
    md = (tmp_path / "gpu-check.md").read_text()
    assert "# GPU check on cpu" in md and "### ssm-table1" in md
    rows = [ln for ln in md.splitlines() if ln.startswith("| build ")]
    assert len(rows) >= 4 and all(float(r.split("|")[2]) > 0 for r in rows)
    bad = subprocess.run([sys.executable, "-m", "wsoft.gpu_check", "--device", "cuda:99"], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "cuda:99" in bad.stderr
