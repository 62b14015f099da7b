"""UsdLux DomeLight: the loader reads the sky (colour, intensity, exposure, a latlong EXR or .hdr
texture in OpenEXR's layout, the dome's transform), refuses what it cannot read in one line, the
reference's V matches closed forms (a uniform dome over a parallel square: 1 - the form factor; a
polar-cap sky), the shaded image adds the dome's irradiance x V, and every technique without a dome
model declines the dome with a reason."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, UsdLux

import wsoft
from wsoft.cli import run_captured
from wsoft.io import write_exr
from wsoft.rgbe import RgbeError, read_rgbe, write_rgbe
from wsoft.scene.dome import LIGHT_DOME, Dome, irradiance, is_dome, radiance, sample_texels, texel_directions, texel_of
from wsoft.scene.usd_dome import dome_brightest_direction
from wsoft.stages.builders import add_quad, add_rect_light, make_stage
from wsoft.stages.light_cases import cap_texture, cap_visibility, dome_square_stage, form_factor

W, H = 64, 48


def _dome_stage(texture: str | None = None, **kw):
    return dome_square_stage(texture, **kw)


def _ground(f) -> np.ndarray:
    P = np.stack([f[f"P.{c}"] for c in "XYZ"], -1)
    return (f["A"] > 0.99) & (np.abs(P[..., 2]) < 1e-4) & (np.abs(P[..., 0]) < 3) & (np.abs(P[..., 1]) < 3)


def _save(st, tmp_path, name="dome") -> str:
    path = str(tmp_path / f"{name}.usda")
    st.GetRootLayer().Export(path)
    return path


# -- the loader --------------------------------------------------------------------------------------------


def test_a_constant_dome_is_read_with_its_emission_and_turned_pole():
    st = _dome_stage(Intensity=2.0, Exposure=1.0, Color=Gf.Vec3f(0.5, 1.0, 0.25))
    sc = wsoft.load_scene(st)
    (light,) = sc.lights
    assert light.kind == LIGHT_DOME and is_dome(light) and light.kind_name == "dome" and light.dome.constant
    assert light.intensity == pytest.approx(4.0) and light.color == pytest.approx((0.5, 1.0, 0.25))
    assert np.allclose(light.dome.rotation[:, 1], (0, 0, 1), atol=1e-9)  # the +Y pole turned onto +Z
    assert "sky, constant" in light.size_description()


def test_domelight_1_pole_axis_scene_on_a_z_up_stage_puts_the_pole_on_z():
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 2.0)
    d = UsdLux.DomeLight_1.Define(st, "/World/Sky")
    (light,) = wsoft.load_scene(st).lights
    assert np.allclose(light.dome.rotation[:, 1], (0, 0, 1), atol=1e-9)
    d.CreatePoleAxisAttr("Y")
    (light,) = wsoft.load_scene(st).lights
    assert np.allclose(light.dome.rotation[:, 1], (0, 1, 0), atol=1e-9)


def test_the_latlong_layout_is_openexrs():
    """Centre of the image: +Z; a quarter from the left (longitude +pi/2): +X; the top row: +Y."""
    r, c = texel_of(np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [-1, 0, 0]]), (8, 16))
    assert list(r) == [4, 4, 0, 7, 4] and list(c) == [8, 4, 8, 8, 12]
    d = texel_directions((8, 16))
    assert np.allclose(np.linalg.norm(d, axis=-1), 1.0) and d[0, 0, 1] > 0.9 and d[4, 8, 2] > 0.9


@pytest.mark.parametrize("ext", ["hdr", "exr"])
def test_a_latlong_texture_is_read_and_its_brightest_texel_points_where_the_layout_says(tmp_path, ext):
    """A sky black but for one texel at longitude +pi/2 (+X in the dome's frame), latitude ~22
    degrees: with the dome turned pole-up onto Z, that is world (+X, +Z-ish)."""
    tex = np.full((16, 32, 3), 0.01, np.float32)
    tex[6, 8] = (50.0, 40.0, 30.0)  # column 8 of 32: longitude pi - 2 pi 8.5 / 32 ~ +pi/2 + small; row 6: latitude ~ 22.5 - 11
    path = str(tmp_path / f"sky.{ext}")
    if ext == "hdr":
        write_rgbe(path, tex)
    else:
        write_exr(path, {c: tex[..., i] for i, c in enumerate("RGB")})
    (light,) = wsoft.load_scene(_dome_stage(path)).lights
    assert light.dome.texture.shape == (16, 32, 3)
    assert np.allclose(light.dome.texture, tex, rtol=1e-2)  # RGBE keeps 8 bits of mantissa
    d = dome_brightest_direction(light)
    lat = math.pi / 2 - math.pi * 6.5 / 16
    lon = math.pi - 2 * math.pi * 8.5 / 32
    local = np.array([math.cos(lat) * math.sin(lon), math.sin(lat), math.cos(lat) * math.cos(lon)])
    world = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]) @ local  # rotateX(90): +Y -> +Z, +Z -> -Y
    assert np.allclose(d, world, atol=1e-6) and d[0] > 0.8
    assert np.allclose(radiance(light, d[None])[0], (50.0, 40.0, 30.0), rtol=1e-2)


def test_rgbe_reads_the_run_length_rows_and_refuses_broken_files():
    w = 8
    row = bytes([2, 2, 0, w]) + b"".join(bytes([128 + w, v]) for v in (128, 64, 0, 129))  # runs: every pixel (128, 64, 0) x 2^(129 - 128) / 256
    img = read_rgbe(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 8\n" + row)
    assert img.shape == (1, 8, 3) and np.allclose(img[0, :, 0], 128.5 / 256 * 2) and np.allclose(img[0, :, 2], 0.5 / 256 * 2)
    for bad, why in [(b"P6\n", "not a Radiance"), (b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 8\n", "FORMAT"),
                     (b"#?RADIANCE\n\n+Y 1 +X 8\n" + bytes(32), "resolution"), (b"#?RADIANCE\n\n-Y 2 +X 8\n" + bytes(32), "ends before"),
                     (b"#?RADIANCE\n\n-Y 1 +X 8\n" + bytes([2, 2, 0, 8, 200, 1]), "run past")]:
        with pytest.raises(RgbeError, match=why):
            read_rgbe(bad)


@pytest.mark.parametrize("case", ["missing", "malformed", "not_latlong", "format", "nan"])
def test_a_dome_texture_that_cannot_be_used_exits_2_naming_file_prim_and_attribute(tmp_path, case):
    path = str(tmp_path / "sky.hdr")
    fmt = None
    if case == "malformed":
        open(path, "wb").write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X 8\n" + bytes(20))
    elif case == "not_latlong":
        write_rgbe(path, np.ones((4, 4, 3)))
    elif case == "format":
        write_rgbe(path, np.ones((4, 8, 3)))
        fmt = "mirroredBall"
    elif case == "nan":
        path = str(tmp_path / "sky.exr")
        t = np.ones((4, 8), np.float32)
        t[1, 1] = np.nan
        import OpenEXR

        with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"R": t, "G": t, "B": t}) as f:
            f.write(path)
    stage = _save(_dome_stage(path, fmt=fmt), tmp_path)
    rc, _, err = run_captured(["render", stage, "-t", "reference", "--set", "samples=1", "--width", "16", "--height", "12",
                               "--out", str(tmp_path / "v.exr")])
    lines = err.strip().splitlines()
    attr = "inputs:texture:format" if case == "format" else "inputs:texture:file"
    assert rc == 2 and len(lines) == 1 and "/World/Sky" in lines[0] and attr in lines[0] and stage in lines[0], err


def test_a_black_or_negative_texture_is_warned_about(tmp_path):
    black, neg = str(tmp_path / "black.hdr"), str(tmp_path / "neg.exr")
    write_rgbe(black, np.zeros((4, 8, 3)))
    t = np.ones((4, 8), np.float32)
    t[0, 0] = -2.0
    write_exr(neg, {"R": t, "G": t, "B": t})
    (w,) = wsoft.load_scene(_dome_stage(black)).warnings
    assert "/World/Sky" in w and "black" in w and "emits nothing" in w
    sc = wsoft.load_scene(_dome_stage(neg))
    assert any("negative radiance" in w for w in sc.warnings) and sc.lights[0].dome.texture.min() == 0.0


def test_a_portal_light_is_skipped_in_one_line_and_the_dome_still_lights(tmp_path):
    st = _dome_stage()
    UsdLux.PortalLight.Define(st, "/World/Portal")
    sc = wsoft.load_scene(st)
    assert [l.path for l in sc.lights] == ["/World/Sky"]
    assert any("/World/Portal" in w and "not honoured" in w for w in sc.warnings)


# -- which techniques take a dome --------------------------------------------------------------------------


def test_every_technique_without_a_dome_model_declines_it_with_one_line():
    from wsoft.techniques import TECHNIQUES, create

    sc = wsoft.load_scene(_dome_stage())
    (light,) = sc.lights
    declined = 0
    for name, cls in TECHNIQUES.items():
        why = create(name, {}).supports(sc, light)
        if cls.dome_refusal:
            assert why and "\n" not in why, name
            declined += 1
        else:
            assert why is None, (name, why)
    assert declined >= 10 and TECHNIQUES["reference"].dome_refusal == ""


def test_a_technique_skips_the_dome_with_its_reason_and_renders_the_other_light():
    st = _dome_stage()
    add_rect_light(st, "/World/Rect", (0, 0, 3), 1, 1)
    f = wsoft.render(wsoft.load_scene(st), "hard", width=32, height=24)
    assert "V.Rect" in f.channels and "V.Sky" not in f.channels
    assert any("/World/Sky skipped" in w and "not the sky" in w for w in f.stats["warnings"])


def test_the_frame_graph_runs_only_the_passes_the_dome_needs():
    """The reference's graph for a dome: its ray pass, no light view, depth map or horizon pass; plan lists why hard declines it."""
    p = wsoft.plan(wsoft.load_scene(_dome_stage()))
    sky = [x for x in p["techniques"]["reference"] if "[Sky]" in x]
    assert sky == ["reference_dome[Sky]"], p["techniques"]["reference"]
    assert "hard" not in p["techniques"] and "not the sky" in str(p["not_applicable"]["hard"])
    assert p["lights"][0]["emits"]["side"] == "from the sky (constant)"


# -- the reference ------------------------------------------------------------------------------------------


def test_uniform_dome_over_a_parallel_square_is_one_minus_the_form_factor():
    """V = 1 - F(point -> square): 99% of ground pixels within 3 standard errors, and the error at
    256 rays (a shifted rank-1 lattice) against the closed form: RMS <= 0.005, under a quarter of 16 rays'."""
    sc = wsoft.load_scene(_dome_stage())
    rms = {}
    for n in (16, 256):
        f = wsoft.render(sc, "reference", width=W, height=H, samples=n)
        m = _ground(f)
        exact = np.array([1.0 - form_factor(x, y) for x, y in zip(f["P.X"][m], f["P.Y"][m])])
        assert m.sum() > 1500 and exact.min() < 0.8  # pixels under the square, well shadowed, are in view
        z = np.abs(f["V"][m] - exact) / np.maximum(f["V_stderr"][m], 1e-9)
        assert (z <= 3.0).mean() >= 0.99, (n, (z > 3).sum())
        rms[n] = float(np.sqrt(((f["V"][m] - exact) ** 2).mean()))
    assert rms[256] <= 0.005 and rms[256] < 0.25 * rms[16], rms


def test_a_textured_dome_uses_its_texture_its_orientation_and_the_mis_ratio(tmp_path):
    """A polar cap (latitude > 60 degrees) of radiance 1 over the square occluder: V at a ground
    point is 1 - (cosine-weighted solid angle of the cap blocked by the square) / (pi sin^2 30),
    integrated numerically; the reference (texture path: cosine and radiance draws, MIS ratio) within 3 se."""
    path = str(tmp_path / "cap.hdr")
    write_rgbe(path, cap_texture())
    sc = wsoft.load_scene(_dome_stage(path))
    f = wsoft.render(sc, "reference", width=W // 2, height=H // 2, samples=256)
    m = np.flatnonzero(_ground(f))[::3]  # every third ground pixel: the quadrature costs per pixel
    v, se, px, py = (f[c].ravel()[m] for c in ("V", "V_stderr", "P.X", "P.Y"))
    exact = np.array([cap_visibility(x, y, steps=100) for x, y in zip(px, py)])
    assert len(m) > 150 and exact.min() < 0.25 and exact.max() > 0.99  # under the square most of the cap is hidden; far out none of it
    z = np.abs(v - exact) / np.maximum(se, 1e-9)
    assert (z <= 3.0).mean() >= 0.99 and np.abs(v - exact).mean() < 0.02


def test_a_dome_whose_shadow_link_leaves_the_occluder_out_sees_the_whole_sky():
    st = _dome_stage()
    link = UsdLux.LightAPI(st.GetPrimAtPath("/World/Sky")).GetShadowLinkCollectionAPI()
    link.CreateExcludesRel().AddTarget("/World/Occluder")
    f = wsoft.render(wsoft.load_scene(st), "reference", width=32, height=24, samples=16)
    m = _ground(f)
    assert m.sum() > 300 and (f["V"][m] == 1.0).all()


def test_importance_sampling_of_a_texture_integrates_its_solid_angle():
    """Draws from the 2D CDF: the mean of 1/pdf over a sky lit only in its upper half is 2 pi, and no draw lands where it is black."""
    d = Dome(texture=cap_texture(16, 0.0))
    rng = np.random.default_rng(1)
    w, pdf = sample_texels(d.table, *rng.random((4, 40000)))
    assert (w[:, 1] >= -1e-9).all() and np.mean(1.0 / pdf) == pytest.approx(2 * math.pi, rel=1e-6)


# -- shading ------------------------------------------------------------------------------------------------


def test_the_shaded_image_adds_the_dome_irradiance_times_v():
    """Flat ground and square top under a constant dome: every normal sees E = pi L, exposed to 1, so
    a pixel is albedo (ambient + (1 - ambient) V)."""
    from wsoft.raster.shade import AMBIENT

    f = wsoft.render(wsoft.load_scene(_dome_stage()), "reference", width=32, height=24, samples=16)
    m = _ground(f)
    assert np.allclose(f["R"][m], 0.8 * (AMBIENT + (1 - AMBIENT) * f["V"][m]), atol=2e-3)


def test_sh_irradiance_of_a_textured_dome_is_within_a_few_percent_of_brute_force():
    tex = np.zeros((32, 64, 3), np.float32)
    tex[:, :] = np.linspace(0.2, 1.0, 32)[:, None, None]  # brighter toward the nadir row: a smooth sky
    tex[4:8, 10:14] = 20.0  # and a bright patch

    class L:
        color, intensity, dome = (1.0, 1.0, 1.0), 1.0, Dome(texture=tex)

    dirs = texel_directions((32, 64)).reshape(-1, 3)
    from wsoft.scene.dome import row_solid_angles

    area = np.repeat(row_solid_angles(32, 64), 64)
    for n in ([0, 1.0, 0], [0, -1.0, 0], [1.0, 0, 0], [0.6, 0.8, 0]):
        n = np.asarray(n)
        exact = (tex.reshape(-1, 3)[:, 0] * np.maximum(dirs @ n, 0) * area).sum()
        assert irradiance(L, n[None])[0, 0] == pytest.approx(exact, rel=0.08)
