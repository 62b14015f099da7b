"""``hard`` against the reference with one sample at the light's centre."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import scene_path

import wsoft
from wsoft.techniques import TECHNIQUES


@pytest.mark.parametrize("file,light", [("box_plane.usda", None), ("contact.usda", None), ("multi_light.usda", "Rect"), ("multi_light.usda", "Disk"), ("multi_light.usda", "Sphere"), ("multi_light.usda", "Sun"), ("cutout.usda", None)])
def test_hard_matches_centre_sample_reference(device, file, light):
    scene = wsoft.load_scene(scene_path(file))
    kw = dict(width=160, height=120, device=device, light=light)
    hard = wsoft.render(scene, "hard", shadow_map_size=2048, **kw)
    ref = wsoft.render(scene, "reference", samples=1, jitter=False, **kw)
    cov = hard["A"] > 0
    v, r = hard.V[cov], ref.V[cov]
    assert set(np.unique(v)) <= {0.0, 1.0}
    assert (r == 0).sum() > 50  # there is a shadow to get right
    agree = np.mean(v == r)
    assert agree > 0.99, f"only {agree:.4f} of pixels agree"


def test_contact_shadow_reaches_the_contact(device):
    """Under the cube resting on the ground, the ground right next to it is in shadow."""
    scene = wsoft.load_scene(scene_path("contact.usda"))
    hard = wsoft.render(scene, "hard", width=160, height=120, device=device, shadow_map_size=2048)
    ref = wsoft.render(scene, "reference", width=160, height=120, device=device, samples=1, jitter=False)
    near_contact = (hard["A"] > 0) & (np.abs(hard["P.Y"]) < 0.02) & (ref.V == 0)
    assert near_contact.sum() > 10
    assert np.mean(hard.V[near_contact] == 0) > 0.97  # no light leaking under the contact


def test_bias_is_needed_and_default_is_enough(device):
    scene = wsoft.load_scene(scene_path("contact.usda"))
    kw = dict(width=120, height=90, device=device, shadow_map_size=1024)
    none = wsoft.render(scene, "hard", bias=0.0, slope_bias=0.0, **kw)
    dflt = wsoft.render(scene, "hard", **kw)
    ref = wsoft.render(scene, "reference", width=120, height=90, device=device, samples=1, jitter=False)
    cov = dflt["A"] > 0
    acne = np.mean((none.V == 0) & (ref.V == 1) & cov)
    fixed = np.mean((dflt.V == 0) & (ref.V == 1) & cov)
    assert acne > fixed  # without bias, lit surfaces shadow themselves somewhere


def test_conservative_parameter_runs_conservative_pass(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "hard", width=32, height=24, device=device, conservative=True)
    assert "light_depth_conservative[Light]@1024" in f.stats["passes"]


def test_unknown_parameter_lists_known():
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    with pytest.raises(wsoft.ParameterError, match="shadow_map_size, bias, slope_bias, receiver_bias, plane_slope_bias, conservative"):
        wsoft.render(scene, "hard", width=8, height=8, device="cpu", sample=4)
    with pytest.raises(wsoft.ParameterError, match="techniques: " + ", ".join(sorted(TECHNIQUES))):
        wsoft.render(scene, "nope", width=8, height=8, device="cpu")
    with pytest.raises(wsoft.ParameterError, match="not a valid int"):
        wsoft.render(scene, "hard", width=8, height=8, device="cpu", shadow_map_size="big")


# ------------------------------------------------------------------------------- map_texels=read


@pytest.mark.parametrize("file,light", [("cutout.usda", None), ("multi_light.usda", "Rect"), ("multi_light.usda", "Sun"),
                                        ("room_lamp.usda", None)])
def test_read_texels_map_casts_the_rasterized_maps_shadow(device, file, light):
    """map_texels=read (one ray per texel a receiver reads) against the rasterized map: the same
    binary shadow but where a texel centre lies on a triangle's edge (cutouts alpha-tested; a
    perspective, an orthographic view and a cube map's faces)."""
    scene = wsoft.load_scene(scene_path(file))
    kw = dict(width=96, height=72, device=device, light=light, shadow_map_size=512)
    read = wsoft.render(scene, "hard", map_texels="read", **kw)
    full = wsoft.render(scene, "hard", map_texels="all", **kw)
    cov = full["A"] > 0
    assert (full.V[cov] == 0).sum() > 50
    assert np.mean(read.V[cov] != full.V[cov]) < 0.002
    maps = {n: c for n, c in read.stats["counters"]["passes"].items() if c.get("drawn_by") == "rays"}
    assert maps and all(0 < c["texels_read"] <= cov.sum() for c in maps.values())
    assert not any("_read" in n for n in full.stats["passes"])


def test_read_texels_map_holds_the_rasterized_depths_at_the_texels_read(device):
    """At every texel a receiver reads, the read map's depth is the rasterized map's (to float
    rounding; a texel whose centre lies on an edge may differ); every other texel is DEPTH_CLEAR;
    the texels read are exactly the receivers' texels, as the view places them."""
    from wsoft.lightspace.fit import fit_light_view
    from wsoft.lightspace.view import DEPTH_CLEAR
    from wsoft.raster.camera import camera_gpu
    from wsoft.raster.depth_map import rasterize
    from wsoft.raster.gbuffer import render_gbuffer
    from wsoft.raster.raycast import raycast_read, read_texels
    from wsoft.pipeline import frame_setup
    from wsoft.scene.device import upload_scene

    scene = wsoft.load_scene(scene_path("cutout.usda"))
    ds = upload_scene(scene, device)
    gb = render_gbuffer(ds, camera_gpu(frame_setup(scene, 120, 90).camera), 120, 90, 1, True)
    covered = gb.prim.numpy() >= 0
    rec = gb.pos.numpy()[covered]
    view = fit_light_view(scene.lights[0], rec, *scene.bounds, 256)
    read = raycast_read(ds, view, gb, alpha_tested=True)
    full = rasterize(ds, view, alpha_tested=True).depth.numpy().reshape(-1)
    a = read.depth.numpy().reshape(-1)
    x, y = view.texel_coords(rec)  # float64 on the host: a point within rounding of a texel's edge may fall on either side
    inside = (x >= 0) & (x < view.width) & (y >= 0) & (y < view.height)
    host = np.unique(np.floor(y[inside]).astype(int) * view.width + np.floor(x[inside]).astype(int))
    want = read_texels(gb, view)
    assert read.texels_read == len(want) > 1000
    assert len(np.setxor1d(want, host)) <= 0.005 * len(want)  # receivers on the fitted window's edge
    others = np.ones(a.size, bool)
    others[want] = False
    assert np.all(a[others] == DEPTH_CLEAR)
    both = (a[want] != DEPTH_CLEAR) & (full[want] != DEPTH_CLEAR)
    assert np.mean((a[want] != DEPTH_CLEAR) != (full[want] != DEPTH_CLEAR)) < 0.005  # coverage: edge texels only
    assert np.abs(a[want][both] - full[want][both]).max() <= 1e-5 * np.abs(full[want][both]).max()


def test_map_texels_auto_reads_on_a_stage_of_many_placed_triangles(device):
    """auto: rays for the texels read on the instanced forest (56 million placed triangles against
    a small frame's samples), the rasterizer on box_plane; read refuses conservative rasterization."""
    forest = wsoft.load_scene(scene_path("forest.usdc"), instancing=True)
    f = wsoft.render(forest, "hard", width=40, height=30, device=device, shadow_map_size=256, light="/World/Lights/Sun")
    assert [c["drawn_by"] for n, c in f.stats["counters"]["passes"].items() if n.startswith("light_depth")] == ["rays"]
    box = wsoft.load_scene(scene_path("box_plane.usda"))
    b = wsoft.render(box, "hard", width=40, height=30, device=device, shadow_map_size=256)
    assert any(n.startswith("light_depth[") for n in b.stats["passes"]) and not any("_read" in n for n in b.stats["passes"])
    with pytest.raises(wsoft.ParameterError, match="map_texels=read"):
        wsoft.render(box, "hard", width=8, height=8, device=device, map_texels="read", conservative=True)
