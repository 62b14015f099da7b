"""The ray-traced reference against exact answers."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import add_camera, add_quad, add_rect_light, make_stage, parallel_rect_exact, scene_path

import wsoft


def test_parallel_rectangles_exact_within_3_stderr(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "reference", width=128, height=96, device=device, samples=256)
    ground = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    exact = parallel_rect_exact(f["P.X"], f["P.Y"], 3.0, 1.0, 1.0, 0.5)
    v, se = f["V"], f["V_stderr"]
    err = (v - exact)[ground]
    pen = ((exact > 0.01) & (exact < 0.99))[ground]
    assert pen.sum() > 150 and (exact[ground] == 0).sum() > 50  # penumbra and umbra are both in view
    outside = np.abs(err) > 3 * se[ground]
    assert outside.mean() <= 0.003, f"{outside.sum()} of {ground.sum()} pixels outside 3 stderr"
    # unbiased on average: the mean error is within 3 standard errors of the mean
    assert abs(err[pen].mean()) < 3 * np.sqrt((se[ground][pen] ** 2).sum()) / pen.sum()


def test_non_square_sample_count_is_unbiased(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "reference", width=64, height=48, device=device, samples=200, seed=3)
    ground = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    exact = parallel_rect_exact(f["P.X"], f["P.Y"], 3.0, 1.0, 1.0, 0.5)
    err = (f["V"] - exact)[ground]
    assert (np.abs(err) > 3 * f["V_stderr"][ground]).mean() <= 0.005
    assert abs(err.mean()) < 0.01


def test_point_light_gives_binary_shadow(device):
    from pxr import Gf, UsdGeom, UsdLux

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 4)
    add_quad(st, "/World/O", (0, 0, 1), 0.5)
    pt = UsdLux.SphereLight.Define(st, "/World/P")
    pt.CreateTreatAsPointAttr(True)
    UsdGeom.XformCommonAPI(pt).SetTranslate(Gf.Vec3d(0, 0, 3))
    add_camera(st, "/World/Cam", (0, -0.01, 8), (0, 0, 0), focal=10)
    f = wsoft.render(wsoft.load_scene(st), "reference", width=64, height=64, device=device, samples=16)
    v = f["V"][f["A"] > 0]
    assert set(np.unique(v)) == {0.0, 1.0}
    # the umbra is the occluder scaled by 3/(3-1) = 1.5 about the light's foot: half side 0.75
    ground = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3)
    inside = ground & (np.abs(f["P.X"]) < 0.7) & (np.abs(f["P.Y"]) < 0.7)
    outside = ground & ((np.abs(f["P.X"]) > 0.8) | (np.abs(f["P.Y"]) > 0.8))
    assert inside.sum() > 10 and np.all(f["V"][inside] == 0) and np.all(f["V"][outside] == 1)


@pytest.mark.parametrize("pattern,expected", [("checker", 0.5), ("quarter", 0.75)])
def test_cutout_lets_the_right_fraction_through(tmp_path, device, pattern, expected):
    from test_loader import _texture, add_cutout_material

    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 4)
    q = add_quad(st, "/World/Fence", (0, 0, 1), 1, st=True)
    # 16x16 cells over the 2x2 quad; the light (2x2 at z=2) seen from the ground through the
    # plane z=1 covers a 1x1 square = 8x8 cells, whatever the point under the centre
    add_cutout_material(st, q, _texture(tmp_path, pattern=pattern, n=16, size=256))
    add_rect_light(st, "/World/L", (0, 0, 2), 2, 2)
    add_camera(st, "/World/Cam", (0, -3, 0.5), (0, 0, 0), focal=25)
    scene = wsoft.load_scene(st)
    assert scene.has_cutouts
    f = wsoft.render(scene, "reference", width=64, height=64, device=device, samples=1024)
    ground = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-3) & (np.abs(f["P.X"]) < 0.2) & (np.abs(f["P.Y"]) < 0.2)
    assert ground.sum() > 3
    v = f["V"][ground]
    assert np.all(np.abs(v - expected) < 3 * f["V_stderr"][ground] + 0.02)
    assert "reference_alpha[L]" in f.stats["passes"]


def test_deterministic_seed(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    a = wsoft.render(scene, "reference", width=32, height=24, device=device, samples=16, seed=1)
    b = wsoft.render(scene, "reference", width=32, height=24, device=device, samples=16, seed=1)
    c = wsoft.render(scene, "reference", width=32, height=24, device=device, samples=16, seed=2)
    assert np.array_equal(a.V, b.V)
    assert not np.array_equal(a.V, c.V)


@pytest.mark.parametrize("light", ["Rect", "Disk", "Sphere", "Sun"])
def test_each_light_kind_finite_and_in_range(device, light):
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    f = wsoft.render(scene, "reference", width=48, height=36, device=device, samples=16, light=light)
    v = f["V"][f["A"] > 0]
    assert np.all(np.isfinite(v)) and v.min() >= 0 and v.max() <= 1
    assert v.min() < 0.5 and v.max() == 1.0  # some shadow and some light


def test_cpu_thread_count_does_not_change_result(monkeypatch):
    scene = wsoft.load_scene(scene_path("contact.usda"))
    monkeypatch.setenv("WSOFT_THREADS", "1")
    a = wsoft.render(scene, "reference", width=40, height=30, device="cpu", samples=16)
    monkeypatch.setenv("WSOFT_THREADS", "2")
    b = wsoft.render(scene, "reference", width=40, height=30, device="cpu", samples=16)
    assert np.array_equal(a.V, b.V)
