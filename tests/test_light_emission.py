"""What a light emits and how wide it is: a DistantLight wider than a technique models is warned
about, naming the light, its angle and the technique's limit; the shaded image follows each light's
intensity, exposure and colour (a light that emits nothing is skipped, a negative one warned about);
render settings whose purposes leave nothing to draw say so."""

from __future__ import annotations

import numpy as np
import pytest

import wsoft
from wsoft.errors import SceneError
from wsoft.stages.builders import add_camera, add_quad, add_rect_light, add_sun, make_stage
from wsoft.techniques import TECHNIQUES


def _stage(light="rect", angle=0.53, **emit):
    """Ground +-6, a 1 x 1 occluder at z = 1, a 0.5 x 0.5 rect light at (3, 0, 3) facing down (or a
    sun overhead of ``angle``), a camera straight down from z = 12; ``emit``: authored light inputs."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 6)
    add_quad(st, "/World/Occluder", (0, 0, 1), 0.5)
    if light == "rect":
        lt = add_rect_light(st, "/World/Light", (3, 0, 3), 0.5, 0.5)
    else:
        lt = add_sun(st, "/World/Light", angle, toward=(0, 0, 1))
    for name, value in emit.items():
        getattr(lt, f"Create{name[0].upper()}{name[1:]}Attr")(value)
    add_camera(st, "/World/Cam", (0, 0.001, 12), (0, 0, 0), up=(0, 1, 0))
    return st


def _warnings(frame):
    return [w for w in frame.stats.get("warnings", [])]


# -- a wide distant light ----------------------------------------------------------------------------------


def test_a_sun_wider_than_a_technique_models_is_warned_about_once_with_its_limit():
    scene = wsoft.load_scene(_stage("sun", 120.0))
    fs = wsoft.render(scene, ["pcss", "pwedge", "hard", ("reference", {"samples": 16})], width=48, height=36)
    for name in ("pcss", "pwedge"):
        lim = TECHNIQUES[name].distant_angle_limit
        lines = [w for w in _warnings(fs[name]) if "DistantLight angle" in w]
        assert len(lines) == 1 and "/World/Light" in lines[0] and "120 degrees" in lines[0] and f"up to {lim:g}" in lines[0]
        assert "the reference samples the whole cone" in lines[0]
    for name in ("hard", "reference"):  # the central direction alone; the whole cone sampled
        assert not [w for w in _warnings(fs[name]) if "DistantLight angle" in w]
    planned = wsoft.plan(scene, ["pcss", "hard"])["warnings"]
    assert [w for w in planned if w.startswith("pcss: ") and "DistantLight angle 120" in w]
    assert not [w for w in planned if w.startswith("hard: ")]
    narrow = wsoft.render(wsoft.load_scene(_stage("sun", 70.0)), "pcss", width=48, height=36)  # at its limit
    assert not [w for w in _warnings(narrow) if "DistantLight angle" in w]


# -- emission in the shaded image ----------------------------------------------------------------------------


def _rgb(frame):
    return np.stack([frame[c] for c in "RGB"], -1)


def test_the_shaded_image_follows_the_lights_colour_and_skips_a_dark_light():
    white = wsoft.render(wsoft.load_scene(_stage(intensity=10.0)), "hard", width=48, height=36)
    red = wsoft.render(wsoft.load_scene(_stage(intensity=10.0, color=(1.0, 0.0, 0.0))), "hard", width=48, height=36)
    lit = (white["A"] > 0) & (white.V > 0.99)
    assert lit.sum() > 100
    assert np.array_equal(white.V, red.V)  # V is geometry alone
    assert _rgb(red)[lit][:, 1].max() < 0.5 * _rgb(white)[lit][:, 1].mean()  # no green from a red light
    assert _rgb(red)[lit][:, 0].mean() > 0.9 * _rgb(white)[lit][:, 0].mean()
    for emit in ({"intensity": 0.0}, {"intensity": -5.0}, {"exposure": 0.0, "intensity": 10.0, "color": (0.0, 0.0, 0.0)}):
        scene = wsoft.load_scene(_stage(**emit))
        assert not scene.lights and scene.skipped_lights[0].reason.startswith("emits nothing")
        assert any("/World/Light" in n and "emits nothing" in n for n in scene.notes)
        with pytest.raises(SceneError, match="emits nothing"):
            wsoft.render(scene, "hard", width=48, height=36)
    assert any("inputs:intensity" in w and "negative" in w for w in wsoft.load_scene(_stage(intensity=-5.0)).warnings)


def test_a_negative_colour_is_warned_about_and_read_as_zero():
    scene = wsoft.load_scene(_stage(intensity=10.0, color=(-1.0, 0.5, -2.0)))
    assert scene.lights[0].color == (0.0, 0.5, 0.0)
    assert any("/World/Light" in w and "inputs:color" in w and "negative" in w for w in scene.warnings)
    f = wsoft.render(scene, "hard", width=48, height=36)
    lit = (f["A"] > 0) & (f.V > 0.99)
    rgb = _rgb(f)[lit]
    assert rgb[:, 1].mean() > 2.0 * rgb[:, 0].mean()  # green light; red and blue only the ambient


def test_two_lights_sum_by_their_emission_and_the_image_is_exposed_not_blown_out():
    st = _stage(intensity=10.0)
    lt = add_rect_light(st, "/World/Dim", (-3, 0, 3), 0.5, 0.5, intensity=1.0)
    lt.CreateColorAttr((0.0, 0.0, 1.0))
    f = wsoft.render(wsoft.load_scene(st), "reference", width=48, height=36, samples=16)
    rgb = _rgb(f)[f["A"] > 0]
    assert rgb.max() <= 1.0 and (rgb >= 0.999).mean() < 0.05  # exposed: at most the brightest 1 % saturate, plus rounding
    blue = rgb[:, 2] - rgb[:, 0]
    assert blue.max() > 0.01 and blue.min() >= -1e-6  # the blue light shows, and only as blue
    assert rgb[:, 0].mean() > 2.0 * blue.mean()  # and a tenth as bright as the white one


def test_exposure_colour_temperature_and_normalize_are_read_as_usdlux_defines():
    from pxr import UsdLux

    base = wsoft.load_scene(_stage(intensity=10.0)).lights[0]
    assert base.intensity == 10.0
    assert wsoft.load_scene(_stage(intensity=10.0, exposure=2.0)).lights[0].intensity == 40.0
    tinted = wsoft.load_scene(_stage(intensity=10.0, exposure=1.0, color=(1.0, 0.5, 0.0)))
    assert wsoft.plan(tinted, ["hard"])["lights"][0]["radiance"] == [20.0, 10.0, 0.0]
    assert wsoft.load_scene(_stage(intensity=10.0, normalize=True)).lights[0].intensity == pytest.approx(10.0 / 0.25)
    warm = wsoft.load_scene(_stage(intensity=10.0, enableColorTemperature=True, colorTemperature=3000.0)).lights[0]
    assert warm.color == pytest.approx(tuple(UsdLux.BlackbodyTemperatureAsRgb(3000.0)), rel=1e-6)
    sun = wsoft.load_scene(_stage("sun", 60.0, intensity=2.0, normalize=True)).lights[0]
    assert sun.intensity == pytest.approx(2.0 / (np.pi * np.sin(np.radians(30.0)) ** 2))


# -- render settings that leave nothing ---------------------------------------------------------------------


def test_render_settings_including_no_purpose_name_the_prim_and_attribute(tmp_path):
    from pxr import Gf, UsdRender

    from wsoft.cli import run_captured

    st = _stage()
    rs = UsdRender.Settings.Define(st, "/Render/Settings")
    rs.CreateResolutionAttr(Gf.Vec2i(32, 24))
    rs.CreateIncludedPurposesAttr([])
    with pytest.raises(SceneError, match="includedPurposes = \\[\\].*leave nothing to draw") as exc:
        wsoft.load_scene(st, render_settings="/Render/Settings")
    assert "/Render/Settings" in str(exc.value)
    path = str(tmp_path / "empty.usda")
    st.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    st.GetRootLayer().Export(path)
    rc, out, err = run_captured(["render", path, "-t", "hard", "--out", str(tmp_path / "v.exr")])
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "/Render/Settings" in lines[0] and "includedPurposes" in lines[0] and "nothing to draw" in lines[0]


# -- receivers beyond one frustum ------------------------------------------------------------------------------


def test_a_rect_light_beyond_one_frustum_warns_what_happened_and_plan_says_so(tmp_path):
    """A rect light low over a wide ground: pcss and hard (which do build cube maps, for sphere,
    point and cylinder lights) say a rect light's map is one frustum and name the techniques that
    shadow those receivers; ``plan`` says the same; no claim that the technique builds no cube map."""
    from wsoft.stages.adversarial.lights import b_rect_grazing

    scene = wsoft.load_scene(b_rect_grazing(str(tmp_path)))
    fs = wsoft.render(scene, ["pcss", "hard"], width=48, height=36)
    for name in ("pcss", "hard"):
        lines = [w for w in _warnings(fs[name]) if "single-frustum view" in w]
        assert len(lines) == 1 and "/World/Light" in lines[0] and "rect light's map in one frustum" in lines[0]
        assert "which this technique does not build" not in lines[0]
        assert "pwedge" in lines[0] and "reference" in lines[0] and "rtdenoise" in lines[0]
    p = wsoft.plan(scene, ["pcss"])
    view = p["light_views"]["/World/Light"]
    assert "rect light's map in one frustum" in view and "unshadowed" in view and "reference" in view


def test_a_sphere_light_drawn_in_one_frustum_says_cube_auto_would_hold_its_receivers(tmp_path):
    from wsoft.stages.adversarial import b_lamp_sphere

    f = wsoft.render(wsoft.load_scene(b_lamp_sphere(str(tmp_path))), "hard", width=48, height=36, cube="never")
    lines = [w for w in _warnings(f) if "single-frustum view" in w]
    assert len(lines) == 1 and "cube=auto draws a cube map" in lines[0] and "which this technique does not build" not in lines[0]


def test_an_extreme_but_finite_emission_shades_as_any_other():
    """2^exposure and intensity at float32's ends: the exposure is relative, so the image is the same."""
    frames = [wsoft.render(wsoft.load_scene(_stage(**emit)), "hard", width=48, height=36)
              for emit in ({"intensity": 10.0}, {"intensity": 1e-30, "exposure": -100.0}, {"intensity": 3e38})]
    for f in frames[1:]:
        assert np.isfinite(_rgb(f)).all() and np.allclose(_rgb(f), _rgb(frames[0]), atol=1e-5)
