"""``vsmap`` (virtual shadow maps, wsoft.accel.virtual_pages): pages requested from the G-buffer give
the same V as a dense map of the same resolution; an overflowing pool falls back to coarser
levels with one warning; a sequence reuses pages while the light stands still, drops all of them
when it moves and those a moving caster crosses; bad parameters are one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

import wsoft
from wsoft.accel import virtual_passes
from wsoft.accel.virtual_pages import VirtualConfig, VirtualPages, distant_layout, light_casters, request_pages
from wsoft.errors import ParameterError
from wsoft.pipeline.history import History
from wsoft.raster.depth_map import rasterize
from wsoft.scene.device import upload_scene
from wsoft.stages.builders import add_box, add_camera, add_point_light, add_quad, add_sun, make_stage

SMALL = dict(virtual_size=2048, page_size=128, clip_levels=6, first_extent=4.0, width=80, height=60, device="cpu")


def sun_stage(sun_rotate=(0.0, -30.0, 0.0), cams=((6, -7, 5),), dynamic_box: bool = False):
    """A ground of half-side 12 with three boxes (one ``wsoft:dynamic`` plate if asked), a 0.53-degree sun, cameras looking at the origin."""
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 12)
    add_box(st, "/World/B1", (-1, -1, 0), (1, 1, 2))
    add_box(st, "/World/B2", (3, 2, 0), (4, 3, 1))
    add_box(st, "/World/B3", (-6, 4, 0), (-4, 6, 3))
    if dynamic_box:
        add_quad(st, "/World/Plate", (-3.0, -3.0, 1.0), 0.6, dynamic=True)
    add_sun(st, "/World/Sun", 0.53, sun_rotate)
    for i, eye in enumerate(cams):
        add_camera(st, f"/World/Cam{i}", eye, (0, 0, 0), focal=18)
    return wsoft.load_scene(st)


def test_requested_pages_give_the_dense_maps_visibility(monkeypatch):
    """Every sample at level 0 (lod_bias -8): V through the requested pages equals V through every
    page of the level drawn (a dense 2048^2 map), and the requested pages are a part of them; the
    pool's pages hold the dense map's depths."""
    scene = sun_stage()
    kw = dict(SMALL, lod_bias=-8.0, pool_pages=4096, clip_levels=1, first_extent=60.0)
    sparse = wsoft.render(scene, "vsmap", **kw)
    c = sparse.counters()
    assert 0 < c["requested"] < c["dense_pages"] == 256 and c["unmapped_samples"] == 0

    real = virtual_passes.request_pages

    def every_page(*a, **k):
        req, level = real(*a, **k)
        req[:] = 1
        return req, level

    monkeypatch.setattr(virtual_passes, "request_pages", every_page)
    dense = wsoft.render(scene, "vsmap", **kw)
    assert dense.counters()["rendered"] == 256
    cov = sparse["A"] > 0
    assert np.array_equal(sparse.V[cov], dense.V[cov])
    assert 0.05 < np.mean(sparse.V[cov] < 0.5) < 0.9  # shadows are there to compare

    # the pool's pages against one dense rasterization of the level's map
    cfg = VirtualConfig(virtual_size=512, page_size=128, pool_pages=16, clip_levels=1, first_extent=30.0)
    lo, hi = scene.bounds
    layout = distant_layout(scene.lights[0], lo, hi, np.array([6.0, -7.0, 5.0]), cfg)
    ds, _ = scene.device_copy("cpu", upload_scene)
    pages = VirtualPages(cfg, "cpu")
    pages.update(layout, np.ones((1, 4, 4), np.int32), ds, light_casters(scene, scene.lights[0]), None, alpha=False)
    full = rasterize(ds, layout.tile_view(0, int(layout.corners[0][0]), int(layout.corners[0][1]), 4, 128), alpha_tested=False).depth.numpy()
    pool = pages.pool.numpy()
    differ = 0
    for (k, gx, gy), phys in pages.resident.items():
        x, y = (gx - layout.corners[0][0]) * 128, (gy - layout.corners[0][1]) * 128
        differ += int(np.sum(pool[phys * 128:(phys + 1) * 128] != full[y:y + 128, x:x + 128]))
    assert len(pages.resident) == 16 and differ <= 0.001 * 512 * 512  # the same texels (rounding may move a handful on edges)


def test_overflow_falls_back_to_a_coarser_level_with_one_warning():
    """A pool too small for the requests: the finest pages go to coarser levels (counted), one
    warning names pool_pages, and no sample is left without a depth."""
    scene = sun_stage()
    kw = dict(SMALL, lod_bias=-3.0)
    big = wsoft.render(scene, "vsmap", pool_pages=4096, **kw)
    cb = big.counters()
    assert cb["overflow_pages"] == 0 and cb["requested"] > 24
    small = wsoft.render(scene, "vsmap", pool_pages=24, **kw)
    cs = small.counters()
    assert cs["overflow_pages"] > 0 and cs["rendered"] <= 24 and cs["unmapped_samples"] == 0
    warns = [w for w in small.stats["warnings"] if "pool_pages" in w]
    assert len(warns) == 1 and "coarser level" in warns[0]
    cov = big["A"] > 0
    assert np.mean(np.abs(big.V - small.V)[cov]) < 0.1  # coarser, not missing: the shadows stay where they were
    assert np.mean(small.V[cov] < 0.5) > 0.5 * np.mean(big.V[cov] < 0.5)


def test_a_pool_that_cannot_hold_the_coarsest_level_is_an_error():
    with pytest.raises(ParameterError, match="pool_pages=1 cannot hold"):
        wsoft.render(sun_stage(), "vsmap", pool_pages=1, **dict(SMALL, clip_levels=1, first_extent=60.0, lod_bias=4.0))


def test_a_still_light_reuses_its_pages_and_a_moving_one_invalidates_them():
    """Three frames with the camera moving a little: from the second frame on at least 90% of the
    requested pages are reused; the sun turning drops every page."""
    cams = ((6, -7, 5), (6.05, -7, 5), (6.1, -7.02, 5))
    scene = sun_stage(cams=cams)
    h = History()
    kw = dict(SMALL, pool_pages=1024, lod_bias=-2.0, frame_history=h)
    frames = []
    for i in range(3):
        frames.append(wsoft.render(scene, "vsmap", camera=f"/World/Cam{i}", **kw))
        h.advance()
    c0, c1, c2 = (f.counters() for f in frames)
    assert c0["reused"] == 0 and c0["rendered"] == c0["requested"] > 10
    for c in (c1, c2):
        assert c["reused"] >= 0.9 * c["requested"] and c["rendered"] == c["requested"] - c["reused"]
    fresh = wsoft.render(scene, "vsmap", camera="/World/Cam2", **dict(kw, frame_history=None))
    assert np.array_equal(fresh.V, frames[2].V)  # reused pages hold what a fresh frame draws
    turned = sun_stage(sun_rotate=(0.0, -33.0, 0.0), cams=cams)
    f3 = wsoft.render(turned, "vsmap", camera="/World/Cam2", **kw)
    c3 = f3.counters()
    assert c3["reused"] == 0 and c3["invalidated"] == c2["resident"] and c3["rendered"] == c3["requested"]


def test_a_moving_caster_invalidates_only_its_pages():
    """A dynamic plate moves between frames: the pages under its old and new place are drawn
    again, the others reused, and V equals a fresh render's."""
    scene = sun_stage(dynamic_box=True)
    assert scene.tri_dynamic is not None and scene.tri_dynamic.any()
    h = History()
    kw = dict(SMALL, pool_pages=1024, lod_bias=-2.0, frame_history=h)
    wsoft.render(scene, "vsmap", **kw)
    h.advance()
    dyn = np.unique(scene.triangles[scene.tri_dynamic])
    scene.points[dyn] += np.array([0.5, 0.0, 0.0], np.float32)
    scene.changed()
    f1 = wsoft.render(scene, "vsmap", **kw)
    c1 = f1.counters()
    assert 0 < c1["invalidated"] < c1["resident"] and c1["reused"] > 0
    fresh = wsoft.render(scene, "vsmap", **dict(kw, frame_history=None))
    assert np.array_equal(fresh.V, f1.V)


def test_bad_parameters_and_lights():
    with pytest.raises(ParameterError, match="multiple of page_size"):
        wsoft.techniques.create("vsmap", {"virtual_size": 1000})
    with pytest.raises(ParameterError, match="power of two"):
        wsoft.techniques.create("vsmap", {"virtual_size": 384, "page_size": 128})
    with pytest.raises(ParameterError, match="perfect square"):
        wsoft.techniques.create("vsmap", {"taps": 5})
    with pytest.raises(ParameterError, match="no parameter"):
        wsoft.techniques.create("vsmap", {"pages": 5})
    st = make_stage()
    add_quad(st, "/World/G", (0, 0, 0), 3)
    add_point_light(st, "/World/P", (0, 0, 2))
    add_camera(st, "/World/Cam", (0, -4, 3), (0, 0, 0))
    scene = wsoft.load_scene(st)
    tech = wsoft.techniques.create("vsmap", {})
    assert "point light" in tech.supports(scene, scene.lights[0])


def test_the_request_kernel_marks_every_sample_page(device):
    """On every device: each covered sample's page at its level is requested."""
    from wsoft.raster.camera import camera_gpu
    from wsoft.raster.gbuffer import render_gbuffer

    scene = sun_stage()
    cfg = VirtualConfig(virtual_size=2048, clip_levels=9, first_extent=4.0, lod_bias=-6.0)
    ds, _ = scene.device_copy(device, upload_scene)
    cam = scene.cameras[0]
    gb = render_gbuffer(ds, camera_gpu(cam), 40, 30, 1, False)
    lo, hi = scene.bounds
    layout = distant_layout(scene.lights[0], lo, hi, cam.position, cfg)
    req, level = request_pages(layout, cfg, gb, cam, 30, 0.0, device)
    pos = gb.pos.numpy()
    covered = gb.prim.numpy() >= 0
    assert covered.sum() > 100 and np.all(level[covered] >= 0) and len(set(level[covered])) >= 2  # several levels in use
    req = req.reshape(layout.levels, cfg.pages, cfg.pages)
    v = (pos - layout.origin) @ layout.axes
    for i in np.flatnonzero(covered)[::7]:
        k = level[i]
        pw = cfg.page_size * layout.texel0 * 2.0 ** k
        gx, gy = int(np.floor(v[i, 0] / pw)), int(np.floor(v[i, 1] / pw))
        assert req[k, gy - layout.corners[k][1], gx - layout.corners[k][0]] == 1
