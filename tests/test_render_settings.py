"""UsdRender settings: which prim (flag > metadata > GetStageRenderSettings > none), its camera,
resolution, pixel aspect and conform policy (analytically, pixel by pixel), data window (a crop of
the same pixels), includedPurposes (which geometry loads), the output product (V under the
RenderVar's name, productName as the default output), flags overriding, and every bad value as
one line naming the file and the prim, exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, add_camera, add_quad, add_rect_light, make_stage

import wsoft
from wsoft.io import read_exr
from wsoft.raster.camera import conform_aperture
from wsoft.scene.render_settings import data_window_pixels
from wsoft.scene.types import Camera

HARD = {"shadow_map_size": 256}


def _settings(st, path="/Render/Settings", *, resolution=(32, 24), camera=None, **attrs):
    """A RenderSettings prim: ``resolution``, the ``camera`` relationship (a path or a list of
    paths), and any ``UsdRender.SettingsBase`` / ``Settings`` attribute as a keyword
    (``pixelAspectRatio=2``, ``dataWindowNDC=(0, 0, .5, .5)``, ``includedPurposes=[...]``)."""
    from pxr import Gf, UsdRender

    rs = UsdRender.Settings.Define(st, path)
    if resolution is not None:
        rs.CreateResolutionAttr(Gf.Vec2i(*resolution))
    if camera is not None:
        rs.CreateCameraRel().SetTargets([camera] if isinstance(camera, str) else list(camera))
    for name, value in attrs.items():
        if name == "dataWindowNDC":
            value = Gf.Vec4f(*value)
        getattr(rs, f"Create{name[0].upper()}{name[1:]}Attr")(value)
    return rs


def _box_scene(*, second_camera=True):
    """Ground, a square occluder under a rect light, two cameras looking at them from different sides."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    add_quad(st, "/World/Occluder", (0, 0, 1), 0.5)
    add_rect_light(st, "/World/Light", (0, 0, 3), 1, 1)
    add_camera(st, "/World/Cam1", (0, -6, 5), (0, 0, 0))
    if second_camera:
        add_camera(st, "/World/Cam2", (5, 3, 4), (0, 0, 0))
    return st


def _main(*args):
    """The CLI in-process: (exit code, stdout, stderr)."""
    from wsoft.cli import run_captured

    return run_captured(args)


def _save(st, tmp_path, name="scene.usda") -> str:
    path = str(tmp_path / name)
    st.GetRootLayer().Export(path)
    return path


# -- which settings, which camera, which size ------------------------------------------------------


def test_settings_pick_the_second_camera_at_their_resolution(device):
    st = _box_scene()
    _settings(st, resolution=(40, 20), camera="/World/Cam2")
    st.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    scene = wsoft.load_scene(st)
    assert scene.render_settings.path == "/Render/Settings" and scene.render_settings_source == "metadata"
    f = wsoft.render(scene, "hard", device=device, **HARD)
    assert f.V.shape == (20, 40) and f.stats["camera"] == "/World/Cam2"
    fr = f.stats["framing"]
    assert (fr["render_settings"], fr["render_settings_source"], fr["camera_source"], fr["resolution_source"]) == (
        "/Render/Settings", "metadata", "render settings", "render settings")
    assert fr["conform_policy"] == "expandAperture" and fr["pixel_aspect"] == 1.0  # UsdRender's fallbacks
    first = wsoft.render(scene, "hard", camera="/World/Cam1", device=device, **HARD)
    assert first.V.shape == (20, 40) and first.stats["camera"] == "/World/Cam1"
    assert np.abs(first["P.X"] - f["P.X"]).max() > 1.0  # another view
    assert f.V[f["A"] > 0].min() < 0.5  # the occluder's shadow is in view


def test_flags_override_the_settings(device):
    st = _box_scene()
    _settings(st, resolution=(40, 20), camera="/World/Cam2")
    st.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    scene = wsoft.load_scene(st)
    f = wsoft.render(scene, "hard", width=16, height=12, camera="/World/Cam1", device=device, **HARD)
    assert f.V.shape == (12, 16) and f.stats["camera"] == "/World/Cam1"
    assert f.stats["framing"]["camera_source"] == "flag" and f.stats["framing"]["resolution_source"] == "flag"
    # one of the two alone keeps the settings' aspect (2:1)
    assert wsoft.render(scene, "hard", width=20, device=device, **HARD).V.shape == (10, 20)
    assert wsoft.render(scene, "hard", height=5, device=device, **HARD).V.shape == (5, 10)


def test_selection_order_flag_metadata_get_stage_render_settings_none(monkeypatch):
    from pxr import UsdRender

    st = _box_scene()
    _settings(st, "/Render/A", resolution=(30, 20))
    _settings(st, "/Render/B", resolution=(20, 30))
    s = wsoft.load_scene(st)
    assert s.render_settings is None and s.render_settings_source == "none"
    assert wsoft.plan(s, ["hard"])["framing"]["resolution"] == [640, 480]  # the defaults without settings
    st.SetMetadata("renderSettingsPrimPath", "/Render/A")
    s = wsoft.load_scene(st)
    assert (s.render_settings.path, s.render_settings.source, s.render_settings.resolution) == ("/Render/A", "metadata", (30, 20))
    s = wsoft.load_scene(st, render_settings="/Render/B")
    assert (s.render_settings.path, s.render_settings_source) == ("/Render/B", "flag")
    # stale metadata is passed over with a warning; GetStageRenderSettings is asked next
    st.SetMetadata("renderSettingsPrimPath", "/Render/Gone")
    s = wsoft.load_scene(st)
    assert s.render_settings is None and any("renderSettingsPrimPath = '/Render/Gone'" in w for w in s.warnings)
    # usd-core's GetStageRenderSettings reads that same metadata; a build whose lookup finds more is honoured
    monkeypatch.setattr(UsdRender.Settings, "GetStageRenderSettings", staticmethod(lambda stage: UsdRender.Settings(stage.GetPrimAtPath("/Render/B"))))
    s = wsoft.load_scene(st)
    assert (s.render_settings.path, s.render_settings_source) == ("/Render/B", "GetStageRenderSettings")
    st.SetMetadata("renderSettingsPrimPath", "/Render/A")
    assert wsoft.load_scene(st).render_settings_source == "metadata"  # metadata before GetStageRenderSettings


def test_render_reloads_a_scene_file_for_other_settings(tmp_path, device):
    st = _box_scene()
    _settings(st, "/Render/A", resolution=(30, 20))
    _settings(st, "/Render/B", resolution=(20, 30))
    path = _save(st, tmp_path)
    scene = wsoft.load_scene(path)
    assert scene.render_settings is None
    assert wsoft.render(scene, "hard", render_settings="/Render/B", device=device, **HARD).V.shape == (30, 20)
    assert wsoft.render(path, "hard", render_settings="/Render/A", device=device, **HARD).V.shape == (20, 30)
    # a scene of an open (here in-memory) stage is loaded again from that stage
    assert wsoft.render(wsoft.load_scene(st), "hard", render_settings="/Render/B", device=device, **HARD).V.shape == (30, 20)


# -- the camera's window conformed to the image -----------------------------------------------------

# aperture 24 x 12 mm (2:1) at 18 mm; image 32 x 24 (4:3) with square pixels (image aspect 4/3) or
# pixels twice as wide as tall (8/3): the window's tan(half field) per policy, worked by hand from
# UsdRender's rules (expand grows the window, crop shrinks it, adjustPixelAspectRatio keeps it)
T0 = (12 / 18, 6 / 18)
CONFORMED = {
    (1.0, "expandAperture"): (2 / 3, 1 / 2),
    (1.0, "cropAperture"): (4 / 9, 1 / 3),
    (1.0, "adjustApertureWidth"): (4 / 9, 1 / 3),
    (1.0, "adjustApertureHeight"): (2 / 3, 1 / 2),
    (1.0, "adjustPixelAspectRatio"): T0,
    (2.0, "expandAperture"): (8 / 9, 1 / 3),
    (2.0, "cropAperture"): (2 / 3, 1 / 4),
    (2.0, "adjustApertureWidth"): (8 / 9, 1 / 3),
    (2.0, "adjustApertureHeight"): (2 / 3, 1 / 4),
    (2.0, "adjustPixelAspectRatio"): T0,
}


@pytest.mark.parametrize("par,policy", sorted(CONFORMED))
def test_conform_policy_puts_each_world_point_at_its_pixel(par, policy, device):
    """A camera at the origin looking down -Z at a wall z = -d: the pixel (row, col) sees the wall
    at x = ((col + 0.5) / W * 2 - 1) tx d, y = (1 - (row + 0.5) / H * 2) ty d, with (tx, ty)
    the window of the table above."""
    from pxr import Gf, UsdGeom

    d = 10.0
    st = make_stage()
    add_quad(st, "/World/Wall", (0, 0, -d), 2 * d)
    add_rect_light(st, "/World/Light", (0, 0, 5), 1, 1)
    cam = UsdGeom.Camera.Define(st, "/World/Cam")  # no transform: at the origin, looking down -Z, +Y up
    cam.CreateFocalLengthAttr(18.0)
    cam.CreateHorizontalApertureAttr(24.0)
    cam.CreateVerticalApertureAttr(12.0)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 1000))
    _settings(st, resolution=(32, 24), camera="/World/Cam", pixelAspectRatio=par, aspectRatioConformPolicy=policy)
    scene = wsoft.load_scene(st, render_settings="/Render/Settings")
    f = wsoft.render(scene, "hard", device=device, **HARD)
    tx, ty = CONFORMED[(par, policy)]
    assert f.stats["framing"]["conform_policy"] == policy
    rows, cols = np.mgrid[0:24, 0:32]
    assert np.all(f["A"] == 1.0)
    np.testing.assert_allclose(f["P.X"], ((cols + 0.5) / 32 * 2 - 1) * tx * d, atol=2e-4)
    np.testing.assert_allclose(f["P.Y"], (1 - (rows + 0.5) / 24 * 2) * ty * d, atol=2e-4)
    # the same as the camera maths alone
    c = conform_aperture(Camera("/c", np.eye(4), tan_half=T0), 32, 24, par, policy)
    np.testing.assert_allclose(c.tan_half, (tx, ty), rtol=1e-12)


def test_without_settings_the_horizontal_field_is_kept():
    c = conform_aperture(Camera("/c", np.eye(4), tan_half=(0.5, 0.1), offset=(0.2, 0.1)), 40, 30)
    assert c.tan_half == (0.5, 0.5 * 30 / 40) and c.offset == (0.2, 0.1)


# -- the data window ---------------------------------------------------------------------------------


def test_data_window_is_a_crop_of_the_same_pixels(device):
    st = _box_scene()
    _settings(st, "/Render/Full", resolution=(32, 24), camera="/World/Cam1")
    _settings(st, "/Render/Window", resolution=(32, 24), camera="/World/Cam1", dataWindowNDC=(0.25, 0.5, 0.75, 1.0))
    full = wsoft.render(wsoft.load_scene(st, render_settings="/Render/Full"), "hard", device=device, **HARD)
    win = wsoft.render(wsoft.load_scene(st, render_settings="/Render/Window"), "hard", device=device, **HARD)
    # NDC y runs up from the bottom: y 0.5..1 is the top half; x 0.25..0.75 the middle columns
    assert data_window_pixels((0.25, 0.5, 0.75, 1.0), 32, 24) == (8, 0, 24, 12)
    assert win.V.shape == (12, 16) and win.stats["width"] == 16 and win.stats["height"] == 12
    assert win.stats["framing"]["data_window"] == [8, 0, 24, 12] and win.stats["framing"]["resolution"] == [32, 24]
    assert set(win.channels) == set(full.channels)
    for name, a in win.channels.items():
        assert np.array_equal(a, full[name][0:12, 8:24]), name
    assert (win["A"] > 0).any() and (win["A"] == 0).any()  # both ground and sky in the window: a real comparison


def test_data_window_rounding_and_clipping():
    assert data_window_pixels((0.0, 0.0, 1.0, 1.0), 32, 24) == (0, 0, 32, 24)
    assert data_window_pixels((-0.5, -0.5, 0.5, 0.25), 32, 24) == (0, 18, 16, 24)  # overscan clipped to the image
    x0, y0, x1, y1 = data_window_pixels((0.1, 0.1, 0.11, 0.11), 8, 8)
    assert x0 == x1 and y0 == y1  # selects no pixel


# -- includedPurposes ------------------------------------------------------------------------------------


def test_included_purposes_decide_which_geometry_casts(device):
    from pxr import UsdGeom

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 4)
    add_quad(st, "/World/Blocker", (0, 0, 1), 0.5).CreatePurposeAttr(UsdGeom.Tokens.proxy)
    add_rect_light(st, "/World/Light", (0, 0, 3), 1, 1)
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    _settings(st, "/Render/Default", camera="/World/Cam")
    _settings(st, "/Render/Proxy", camera="/World/Cam", includedPurposes=["default", "render", "proxy"])

    def under_blocker(f):
        m = (f["A"] > 0) & (np.abs(f["P.X"]) < 0.4) & (np.abs(f["P.Y"]) < 0.4) & (np.abs(f["P.Z"]) < 1e-3)  # umbra: |x|, |y| < 0.5
        assert m.sum() >= 4
        return f.V[m]

    plain = wsoft.load_scene(st)  # no settings: default and render, as always
    assert plain.prims == ["/World/Ground"] and plain.purposes == ("default", "render")
    dflt = wsoft.load_scene(st, render_settings="/Render/Default")
    assert dflt.prims == ["/World/Ground"]
    proxy = wsoft.load_scene(st, render_settings="/Render/Proxy")
    assert proxy.prims == ["/World/Ground", "/World/Blocker"] and proxy.purposes == ("default", "render", "proxy")
    assert np.all(under_blocker(wsoft.render(dflt, "hard", device=device, **HARD)) == 1.0)
    assert np.all(under_blocker(wsoft.render(proxy, "hard", device=device, **HARD)) == 0.0)


def test_a_child_with_its_own_included_purpose_loads_under_an_excluded_parent():
    from pxr import UsdGeom

    st = make_stage()
    proxy = UsdGeom.Xform.Define(st, "/World/Proxy")
    proxy.CreatePurposeAttr(UsdGeom.Tokens.proxy)
    add_quad(st, "/World/Proxy/Inherits", (0, 0, 0), 1)
    add_quad(st, "/World/Proxy/Render", (3, 0, 0), 1).CreatePurposeAttr(UsdGeom.Tokens.render)  # USD: computed purpose render
    assert wsoft.load_scene(st).prims == ["/World/Proxy/Render"]


# -- the output product ---------------------------------------------------------------------------------


def _product_stage(tmp_path, var_name="shadowVis", source_name="visibility", product_name=None):
    from pxr import UsdRender

    st = _box_scene(second_camera=False)
    rs = _settings(st, camera="/World/Cam1")
    var = UsdRender.Var.Define(st, f"/Render/Vars/{var_name}")
    var.CreateSourceNameAttr(source_name)
    color = UsdRender.Var.Define(st, "/Render/Vars/color")
    color.CreateSourceNameAttr("Ci")
    prod = UsdRender.Product.Define(st, "/Render/Product")
    prod.CreateProductNameAttr(product_name if product_name is not None else str(tmp_path / "product.exr"))
    prod.CreateOrderedVarsRel().SetTargets([color.GetPath(), var.GetPath()])
    rs.CreateProductsRel().SetTargets([prod.GetPath()])
    st.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    return st


@pytest.mark.parametrize("var_name,source_name", [("shadowVis", "visibility"), ("visibility", "shadow")])
def test_product_names_the_v_channel_and_the_default_output(tmp_path, var_name, source_name):
    path = _save(_product_stage(tmp_path, var_name, source_name), tmp_path)
    rc, out, err = _main("render", path, "-t", "hard", "--set", "shadow_map_size=256", "--device", "cpu")
    assert rc == 0, err
    ch = read_exr(str(tmp_path / "product.exr"))
    assert var_name in ch and "V" not in ch and ch[var_name].shape == (24, 32)
    assert f"wrote {tmp_path / 'product.exr'}" in out
    rc, _, err = _main("render", path, "-t", "hard", "--set", "shadow_map_size=256", "--device", "cpu", "--out", tmp_path / "flag.exr")
    assert rc == 0, err
    assert np.array_equal(read_exr(str(tmp_path / "flag.exr"))[var_name], ch[var_name])  # --out wins; the name stays
    f = wsoft.render(path, "hard", device="cpu", **HARD)
    assert f.exr_names["V"] == var_name and np.array_equal(f.V, ch[var_name])  # in memory it is still V
    assert f.stats["framing"]["visibility_var"] == var_name and f.stats["framing"]["product"] == "/Render/Product"


def test_the_output_product_overrides_the_settings(tmp_path):
    """What the output product authors wins over its settings (UsdRenderComputeSpec); the rest stays."""
    from pxr import Gf, UsdRender

    st = _product_stage(tmp_path)
    add_camera(st, "/World/Cam2", (5, 3, 4), (0, 0, 0))
    UsdRender.Settings(st.GetPrimAtPath("/Render/Settings")).CreatePixelAspectRatioAttr(2.0)
    prod = UsdRender.Product(st.GetPrimAtPath("/Render/Product"))
    prod.CreateResolutionAttr(Gf.Vec2i(20, 10))
    prod.CreateCameraRel().SetTargets(["/World/Cam2"])
    rs = wsoft.load_scene(st).render_settings
    assert (rs.resolution, rs.camera, rs.camera_from, rs.pixel_aspect) == ((20, 10), "/World/Cam2", "/Render/Product", 2.0)
    assert rs.output.visibility_var == "shadowVis" and rs.output.visibility_var_path == "/Render/Vars/shadowVis"


def test_plan_says_which_settings_and_camera(tmp_path):
    path = _save(_product_stage(tmp_path), tmp_path)
    rc, out, err = _main("plan", path, "-t", "hard")
    assert rc == 0, err
    assert "render settings: /Render/Settings (from metadata)" in out
    assert "camera: /World/Cam1 (from render settings); 32x24 (from render settings), pixel aspect 1, expandAperture" in out
    assert "V as 'shadowVis'" in out and "product.exr" in out
    rc, out, _ = _main("plan", path, "--json", "--camera", "/World/Cam1", "--render-settings", "/Render/Settings")
    fr = json.loads(out)["framing"]
    assert (fr["render_settings"], fr["render_settings_source"], fr["camera"], fr["camera_source"]) == (
        "/Render/Settings", "flag", "/World/Cam1", "flag")
    rc, out, _ = _main("plan", _save(_box_scene(), tmp_path, "plain.usda"), "-t", "hard")
    assert "render settings: none" in out and "camera: /World/Cam1 (from first camera); 640x480 (from default)" in out


# -- bad input: one line naming the file and the prim, exit 2 -------------------------------------------------


def _bad(case: str, tmp_path):
    """(stage, extra CLI arguments, the prim the message names, the words it holds)."""
    st = _box_scene()
    st.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    if case == "not_settings":
        _settings(st)
        return st, ["--render-settings", "/World/Cam1"], "/World/Cam1", "a Camera prim, not a RenderSettings prim"
    if case == "missing_settings":
        return st, ["--render-settings", "/Render/Nope"], "/Render/Nope", "do not exist"
    if case == "no_camera_target":
        _settings(st, camera=[])
        return st, [], "/Render/Settings", "camera relationship has 0 targets"
    if case == "two_camera_targets":
        _settings(st, camera=["/World/Cam1", "/World/Cam2"])
        return st, [], "/Render/Settings", "camera relationship has 2 targets"
    if case == "camera_not_a_camera":
        _settings(st, camera="/World/Light")
        return st, [], "/Render/Settings", "targets /World/Light, a RectLight prim, not a Camera"
    if case == "zero_resolution":
        _settings(st, resolution=(0, 24))
        return st, [], "/Render/Settings", "resolution = (0, 24) must be positive"
    if case == "negative_resolution":
        _settings(st, resolution=(32, -2))
        return st, [], "/Render/Settings", "resolution = (32, -2) must be positive"
    if case == "empty_window":
        _settings(st, dataWindowNDC=(0.5, 0.0, 0.5, 1.0))
        return st, [], "/Render/Settings", "dataWindowNDC = (0.5, 0, 0.5, 1) is empty or inverted"
    if case == "inverted_window":
        _settings(st, dataWindowNDC=(0.0, 0.8, 1.0, 0.2))
        return st, [], "/Render/Settings", "is empty or inverted"
    if case == "window_without_pixels":
        _settings(st, resolution=(8, 8), dataWindowNDC=(0.1, 0.1, 0.11, 0.11))
        return st, [], "/Render/Settings", "selects no pixel of a 8x8 image"
    if case.startswith("pixel_aspect_"):
        _settings(st, pixelAspectRatio={"zero": 0.0, "negative": -1.0, "nan": float("nan"), "inf": float("inf")}[case[13:]])
        return st, [], "/Render/Settings", "pixelAspectRatio"
    if case == "policy":
        _settings(st, aspectRatioConformPolicy="stretch")
        return st, [], "/Render/Settings", "aspectRatioConformPolicy = 'stretch' is not one of"
    if case == "var_is_a_channel":
        return _product_stage(tmp_path, var_name="Z"), [], "/Render/Vars/Z", "RenderVar name 'Z' is already one of the frame's channels"
    if case == "product_format":
        return (_product_stage(tmp_path, product_name=str(tmp_path / "product.tif")), ["--no-out"], "/Render/Product",
                ".tif is not a format wsoft writes")
    raise AssertionError(case)


BAD = ["not_settings", "missing_settings", "no_camera_target", "two_camera_targets", "camera_not_a_camera", "zero_resolution",
       "negative_resolution", "empty_window", "inverted_window", "window_without_pixels", "pixel_aspect_zero", "pixel_aspect_negative",
       "pixel_aspect_nan", "pixel_aspect_inf", "policy", "var_is_a_channel", "product_format"]


@pytest.mark.parametrize("case", BAD)
def test_bad_settings_are_one_line_and_exit_2(tmp_path, case):
    st, extra, prim, needle = _bad(case, tmp_path)
    path = _save(st, tmp_path)
    out = [] if "--no-out" in extra else ["--out", tmp_path / "o.exr"]
    extra = [a for a in extra if a != "--no-out"]
    rc, _, err = _main("render", path, "-t", "hard", *extra, "--device", "cpu", *out)
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wsoft: error: ") and needle in lines[0], err
    assert path in lines[0] and (prim is None or f": {prim}: " in lines[0])
    assert not (tmp_path / "o.exr").exists()


def test_a_bad_settings_prim_is_one_line_in_a_fresh_process_too(tmp_path):
    st, extra, prim, needle = _bad("not_settings", tmp_path)
    p = subprocess.run([sys.executable, "-m", "wsoft", "render", _save(st, tmp_path), "-t", "hard", *extra, "--out", str(tmp_path / "o.exr")],
                       capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert [ln for ln in p.stderr.splitlines() if ln.startswith("wsoft: error")] == p.stderr.strip().splitlines()
    assert needle in p.stderr and prim in p.stderr
