"""Only what the scene calls for: passes follow scene features and requested lights."""

from __future__ import annotations

from conftest import scene_path

import wsoft


def test_no_alpha_pass_without_cutouts():
    p = wsoft.plan(wsoft.load_scene(scene_path("multi_light.usda")))
    assert p["cutout_materials"] == []
    for passes in p["techniques"].values():
        assert not any("alpha" in x for x in passes)


def test_alpha_passes_with_cutouts():
    p = wsoft.plan(wsoft.load_scene(scene_path("cutout.usda")))
    assert p["cutout_materials"] == [{"path": "/World/Looks/FenceMat", "triangles": 2}]
    assert "light_depth_alpha[Light]@1024" in p["techniques"]["hard"]
    assert "gbuffer_alpha" in p["techniques"]["hard"]
    assert "reference_alpha[Light]" in p["techniques"]["reference"]


def test_no_pass_for_a_disabled_or_unhandled_light():
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    p = wsoft.plan(scene)
    assert [l["path"] for l in p["lights"]] == ["/World/Lights/Rect", "/World/Lights/Disk", "/World/Lights/Sphere", "/World/Lights/Sun"]
    skipped = {l["path"]: l["reason"] for l in p["skipped_lights"]}
    assert skipped["/World/Lights/NoShadow"] == "shadow:enable = false"
    assert "not handled" in skipped["/World/Lights/Dome"]
    for passes in p["techniques"].values():
        assert not any("NoShadow" in x or "Dome" in x for x in passes)


def test_light_selection_culls_other_lights(device):
    scene = wsoft.load_scene(scene_path("multi_light.usda"))
    f = wsoft.render(scene, "hard", width=32, height=24, device=device, light="/World/Lights/Disk")
    assert not any("Rect" in x or "Sun" in x for x in f.stats["passes"])
    assert "hard[Disk]" in f.stats["passes"]
    assert "V.Disk" in f.channels and "V.Rect" not in f.channels
    assert (f.V == f["V.Disk"]).all()


def test_render_stats_list_passes_that_ran(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    f = wsoft.render(scene, "reference", width=16, height=12, device=device, samples=4)
    assert f.stats["passes"] == ["upload_scene", "gbuffer", "reference[Light]", "gbuffer_channels", "shade", "resolve"]
    assert f.stats["pass_kinds"] == {"upload_scene": "scene", "gbuffer": "gbuffer", "reference[Light]": "reference",
                                     "gbuffer_channels": "resolve", "shade": "shade", "resolve": "resolve"}
    assert set(f.stats["timings_ms"]) == set(f.stats["passes"]) | {"total"}


def test_device_copy_is_reused_until_changed(device):
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    a = wsoft.render(scene, "hard", width=16, height=12, device=device)
    b = wsoft.render(scene, "hard", width=16, height=12, device=device)
    assert a.stats["counters"]["frame"]["scene_upload_cached"] is False
    assert b.stats["counters"]["frame"]["scene_upload_cached"] is True
    assert (a.V == b.V).all()
    scene.points[:, 2] += 1.0  # lift everything: the camera now sees the scene from closer
    scene.changed()
    c = wsoft.render(scene, "hard", width=16, height=12, device=device)
    assert c.stats["counters"]["frame"]["scene_upload_cached"] is False
    assert not (c["P.Z"] == a["P.Z"]).all()
