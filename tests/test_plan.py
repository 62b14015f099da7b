"""Only what the scene calls for: passes follow scene features and requested lights."""

from __future__ import annotations

import numpy as np
import pytest
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
    assert [l["path"] for l in p["lights"]] == ["/World/Lights/Rect", "/World/Lights/Disk", "/World/Lights/Sphere", "/World/Lights/Sun",
                                                "/World/Lights/Dome"]
    skipped = {l["path"]: l["reason"] for l in p["skipped_lights"]}
    assert skipped["/World/Lights/NoShadow"] == "shadow:enable = false"
    for name, passes in p["techniques"].items():
        assert not any("NoShadow" in x for x in passes)
        if name == "hard":  # a technique without a dome model runs no pass for the sky (wsoft.scene.dome)
            assert not any("Dome" in x for x in passes)


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
    assert set(f.stats["timings_ms"]) == set(f.stats["passes"]) | {"total", "compile"}


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


def test_several_techniques_share_one_graph(device):
    """Each technique's visibility carries its technique (pcf and pcss do not share 'visibility[Light]'),
    the G-buffer runs once, hard and pcf share their depth map, and each frame equals its own render."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    kw = dict(width=48, height=36, device=device)
    fs = wsoft.render(scene, ["hard", "pcf", "pcss", ("pcss", {"filter_samples": 16})], **kw)
    assert list(fs) == ["hard", "pcf", "pcss", "pcss(filter_samples=16)"]
    assert fs.stats["passes"].count("gbuffer") == 1
    shared = fs.stats["shared_passes"]
    assert set(shared["gbuffer"]) == set(fs) and set(shared["light_depth[Light]@1024"]) == {"hard", "pcf"}
    assert set(shared["light_depth[Light]@1024+soft"]) == {"pcss", "pcss(filter_samples=16)"}
    assert fs["pcf"].stats["shared_passes"]["light_depth[Light]@1024"] == ["hard"]
    for label, tech in (("hard", ("hard", {})), ("pcss(filter_samples=16)", ("pcss", {"filter_samples": 16}))):
        alone = wsoft.render(scene, tech[0], **kw, **tech[1])
        assert np.array_equal(fs[label].V, alone.V)
        own = {"pcss[Light]": "pcss[pcss(filter_samples=16):Light]",  # a labelled instance's own passes
               "horizon_pcss[Light]": "horizon_pcss[pcss(filter_samples=16):Light]"} if label != "hard" else {}
        want = {own.get(n, n) for n in alone.stats["passes"]} - {"shade", "resolve"} | {f"shade[{label}]", f"resolve[{label}]"}
        assert set(fs[label].stats["passes"]) == want
    # a technique's frame time counts the passes it needs, shared ones included
    st = fs["pcf"].stats
    assert st["timings_ms"]["total"] == pytest.approx(sum(v for k, v in st["timings_ms"].items() if k not in ("total", "compile")), abs=0.01)


def test_same_technique_twice_with_the_same_parameters_is_an_error():
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    with pytest.raises(wsoft.ParameterError, match="asked for twice: pcss"):
        wsoft.render(scene, ["pcss", ("pcss", {})], width=8, height=8, device="cpu")
    with pytest.raises(wsoft.ParameterError, match="as \\(name, \\{key: value\\}\\)"):
        wsoft.render(scene, ["pcss", "hard"], width=8, height=8, device="cpu", shadow_map_size=512)


def test_essm_instances_share_their_sat_across_shading_knobs():
    """ESSM's basis and SAT depend on the storage, not on H or the subdivision: built once."""
    scene = wsoft.load_scene(scene_path("box_plane.usda"))
    fs = wsoft.render(scene, [("essm", {"H": 2.0}), ("essm", {"subdivision": 1}), ("essm", {"mu": 16})], width=32, height=24, device="cpu")
    sat = [p for p in fs.stats["passes"] if p.startswith("essm_sat")]
    assert sat == ["essm_sat[Light]@1024", "essm_sat[Light]@1024{mu=16}"]
    assert set(fs.stats["shared_passes"]["essm_sat[Light]@1024"]) == {"essm(H=2.0)", "essm(subdivision=1)"}


def test_metric_pass_matches_the_host_error():
    """wsoft.compare's error comes from a metric pass: the same numbers as visibility_error (and
    ꟻLIP's flip_error of the shaded images) on the frames."""
    from wsoft.metrics import facing_light, visibility_error
    from wsoft.metrics.flip import flip_error

    scene = wsoft.load_scene(scene_path("contact.usda"))
    fs = wsoft.compare(scene, ["pcss", "hard"], samples=16, width=40, height=30, device="cpu")
    ref = fs["reference"]
    assert fs.stats["reference"] == "reference" and "errors" not in ref.stats
    for label in ("pcss", "hard"):
        e = fs[label].stats["error"]
        want = visibility_error(fs[label].V, ref.V, ref["V_stderr"], ref["A"], facing=facing_light(fs[label].channels, scene.lights[0]))
        want |= flip_error(fs[label].channels, ref.channels)[0]
        assert e == want and e["flip"] > 0.0 and e["penumbra_pixels"] > 20 and e["facing"]["pixels"] + e["not_facing"]["pixels"] == e["pixels"]
        assert fs[label].stats["pass_kinds"].get(f"error[{label}:Light]") is None  # the metric is not part of the frame's time
    assert fs.stats["pass_kinds"]["error[pcss:Light]"] == "metric" and fs.stats["pass_kinds"]["flip[pcss]"] == "metric"


def test_nan_in_an_image_is_counted_and_scored():
    from wsoft.metrics import visibility_error

    v = np.array([[np.nan, 0.5], [1.0, 1.0]])
    ref = np.array([[0.0, 0.5], [1.0, 1.0]])
    with pytest.warns(RuntimeWarning, match="1 pixels of the image are not finite"):
        e = visibility_error(v, ref)
    assert e["nan_pixels"] == 1 and e["max"] == 1.0 and e["mae"] == pytest.approx(0.25)
