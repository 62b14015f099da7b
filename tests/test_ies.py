"""IES profiles (``shaping:ies:*``): the LM-63 reader on the format's corner cases, the loader's
errors, the device's bilinear lookup against the host's, ``angleScale`` and ``normalize``, the
shaded image against its closed form, and the reference's weighting of a shaped area light's
samples (``V = sum(visible w) / sum(w)``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from pxr import Sdf, UsdLux

import wsoft
from wsoft.cli import run_captured
from wsoft.lightspace.light import LightGPU, light_gpu, shaping_weight, shaping_weights
from wsoft.scene.ies import EXAMPLE, IesError, example_path, ies_angle, parse_ies, read_ies
from wsoft.stages.builders import add_camera, add_point_light, add_quad, add_rect_light, add_sphere_light, make_stage

W, H = 160, 120


def _lm63(v, h, cd, *, header="IESNA:LM-63-2002", tilt="TILT=NONE", ptype=1, mult=1.0, keywords=("[TEST] t",), sep=" ") -> str:
    """An LM-63 file of vertical angles ``v``, horizontal ``h`` and candela rows ``cd`` (one per
    horizontal angle)."""
    lines = ([header] if header else []) + list(keywords) + [tilt]
    lines += [f"1 -1 {mult:g} {len(v)} {len(h)} {ptype} 2 0 0 0", "1.0 1.0 10"]
    lines += [sep.join(f"{x:g}" for x in v), sep.join(f"{x:g}" for x in h)]
    lines += [sep.join(f"{x:g}" for x in row) for row in cd]
    return "\n".join(lines) + "\n"


V3 = [0.0, 45.0, 90.0]


# -- the reader ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("header, version", [("IESNA:LM-63-2002", "2002"), ("IESNA:LM-63-1995", "1995"), ("IESNA91", "1991"),
                                             (None, "1986")])
def test_each_header_version_is_read(header, version):
    p = parse_ies(_lm63(V3, [0.0], [[100, 50, 0]], header=header, keywords=() if header is None else ("[TEST] t",)))
    assert p.version == version and p.vertical == (0.0, 45.0, 90.0)
    assert p.sample(np.array([22.5]), np.array([123.0]))[0] == pytest.approx(75.0)


def test_keywords_and_numbers_split_over_lines_and_commas():
    text = _lm63(V3, [0.0, 90.0], [[100, 50, 0], [80, 40, 0]], keywords=("[TEST] a", "[MANUFAC] b", "[MORE] c"), sep=", ")
    text = text.replace("0, 45, 90", "0,\n45\n 90")  # a field running over lines
    p = parse_ies(text)
    assert dict(p.keywords)["MANUFAC"] == "b" and p.candela[1] == (80.0, 40.0, 0.0)


def test_tilt_include_is_read_and_tilt_file_refused():
    inc = _lm63(V3, [0.0], [[100, 50, 0]], tilt="TILT=INCLUDE\n1\n3\n0 45 90\n1 0.9 0.8")
    assert parse_ies(inc).tilt == "INCLUDE" and parse_ies(inc).candela == ((100.0, 50.0, 0.0),)
    with pytest.raises(IesError, match="TILT=lamp.tlt: tilt data in another file"):
        parse_ies(_lm63(V3, [0.0], [[100, 50, 0]], tilt="TILT=lamp.tlt"))
    with pytest.raises(IesError, match="geometry 7"):
        parse_ies(_lm63(V3, [0.0], [[1, 1, 1]], tilt="TILT=INCLUDE\n7\n1\n0\n1"))


@pytest.mark.parametrize("ptype, name", [(2, "B"), (3, "A")])
def test_types_a_and_b_are_refused_in_one_line(ptype, name):
    with pytest.raises(IesError, match=f"photometric type {name}: only type C"):
        parse_ies(_lm63(V3, [0.0], [[100, 50, 0]], ptype=ptype))


def test_candela_multiplier_scales_every_value():
    p = parse_ies(_lm63(V3, [0.0], [[100, 50, 0]], mult=2.5))
    assert p.candela == ((250.0, 125.0, 0.0),) and p.peak() == 250.0


# a profile whose value encodes its plane: I(v, h) = (10 + h / 10) (1 - v / 90)
def _planes(h):
    return [[(10 + a / 10) * (1 - b / 90) for b in V3] for a in h]


@pytest.mark.parametrize("h, at, want_h", [
    ([0.0], [0, 77, 200, 359], [0, 0, 0, 0]),  # one plane: the same all round
    ([0.0, 45.0, 90.0], [30, 100, 200, 300], [30, 80, 20, 60]),  # a quadrant mirrored into four
    ([0.0, 90.0, 180.0], [30, 100, 200, 300], [30, 100, 160, 60]),  # a half mirrored about 0-180
    ([0.0, 90.0, 180.0, 270.0, 360.0], [30, 100, 200, 300], [30, 100, 200, 300]),  # every plane
])
def test_symmetric_horizontal_sets_unfold_by_mirroring(h, at, want_h):
    p = parse_ies(_lm63(V3, h, _planes(h)))
    got = p.sample(np.full(len(at), 45.0), np.asarray(at, float))
    want = (10 + np.asarray(want_h, float) / 10) * 0.5
    assert np.allclose(got, want)


def test_bilinear_between_angles_and_zero_outside_the_vertical_range():
    p = parse_ies(_lm63([0.0, 30.0, 90.0], [0.0, 90.0], [[90, 60, 0], [30, 20, 10]]))
    # at v 15, h 45: rows (75, 25) -> 50; at v 60, h 0: 30
    assert p.sample(np.array([15.0, 60.0, 91.0, 180.0]), np.array([45.0, 0.0, 0.0, 0.0])) == pytest.approx([50.0, 30.0, 0.0, 0.0])
    up = parse_ies(_lm63([90.0, 180.0], [0.0], [[5, 10]]))  # an uplight: 90..180
    assert up.sample(np.array([45.0, 135.0]), np.array([0.0, 0.0])) == pytest.approx([0.0, 7.5])


@pytest.mark.parametrize("text, match", [
    ("", "is empty"),
    ("IESNA:LM-63-1999\nTILT=NONE\n", "unknown version"),
    ("IESNA:LM-63-2002\n[TEST] x\n", "no TILT= line"),
    (_lm63(V3, [0.0], [[100, 50]]), "ends after 2 of the 3 numbers of the candela values"),
    (_lm63(V3, [0.0], [[100, 50, 0, 7]]), "numbers past the"),
    (_lm63(V3, [0.0], [[100, 777, 0]]).replace("777", "x"), r"line 8: 'x' in the candela values \(1 x 3\) is not a number"),
    (_lm63([0.0, 90.0, 45.0], [0.0], [[1, 1, 1]]), "strictly ascending"),
    (_lm63([10.0, 90.0], [0.0], [[1, 1]]), "vertical angles 10..90"),
    (_lm63(V3, [0.0, 120.0], [[1, 1, 1], [1, 1, 1]]), "horizontal angles 0..120"),
    (_lm63(V3, [0.0], [[1, -1, 1]]), "negative"),
    (_lm63(V3, [0.0], [[0, 0, 0]]), "emits nothing"),
    (_lm63(V3, [0.0], [[1, 1, 1]], mult=0.0), "candela multiplier 0"),
])
def test_malformed_profiles_say_what_is_wrong(text, match):
    with pytest.raises(IesError, match=match):
        parse_ies(text)


def test_the_bundled_example_is_installed_and_is_its_formula():
    assert example_path().endswith(EXAMPLE)
    p = read_ies(example_path())
    v, h = np.array([0.0, 30.0, 60.0, 12.5]), np.array([0.0, 90.0, 225.0, 10.0])  # 225 folds to 45
    want = 1000 * np.cos(np.radians(v)) ** 4 * (1 + 0.3 * np.cos(np.radians(2 * h)))
    assert np.allclose(p.sample(v[:3], h[:3]), want[:3], rtol=2e-3)  # on the grid: rounded to 0.1 cd
    assert abs(p.sample(v[3:], h[3:])[0] / want[3] - 1) < 0.02  # between grid angles: bilinear
    assert p.mean_intensity() == pytest.approx(100.0, rel=0.01)  # (1/4pi) 2pi 1000/5


def test_angle_scale_is_openusds_formula():
    assert ies_angle(np.array([0.0, 90.0, 180.0]), 0.0) == pytest.approx([0.0, 90.0, 180.0])
    # (theta - 180) / (1 + s) + 180: s = 1 maps 0 -> 90 and 90 -> 135; s = -0.5 maps 90 -> 0 (clamped below)
    assert ies_angle(np.array([0.0, 90.0]), 1.0) == pytest.approx([90.0, 135.0])
    assert ies_angle(np.array([90.0, 135.0]), -0.5) == pytest.approx([0.0, 90.0])


# -- the loader ---------------------------------------------------------------------------------------------


def _ies_stage(tmp_path=None, *, text=None, file=None, kind="point", cone=None, scale=None, normalize=None, box=False):
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    if kind == "point":
        light = add_point_light(st, "/World/Light", (0, 0, 3))
    elif kind == "sphere":
        light = add_sphere_light(st, "/World/Light", (0, 0, 3), 0.1)
    else:
        light = add_rect_light(st, "/World/Light", (0, 0, 3), 2.0, 2.0)
    api = UsdLux.ShapingAPI.Apply(light.GetPrim())
    if text is not None:
        file = str(tmp_path / "lamp.ies")
        open(file, "w").write(text)
    api.CreateShapingIesFileAttr(Sdf.AssetPath(file or example_path()))
    api.CreateShapingConeAngleAttr(180.0 if cone is None else cone)
    if scale is not None:
        api.CreateShapingIesAngleScaleAttr(scale)
    if normalize is not None:
        api.CreateShapingIesNormalizeAttr(normalize)
    add_camera(st, "/World/Cam", (0, -7, 6), (0.5, 0, 0))
    return st


def test_the_loader_reads_the_profile_and_its_inputs():
    light = wsoft.load_scene(_ies_stage(scale=0.25, normalize=True)).lights[0]
    s = light.shaping
    assert s.ies is not None and s.shaped and not s.coned and s.ies_angle_scale == 0.25 and s.ies_normalize
    assert s.ies_divisor() == pytest.approx(s.ies.mean_intensity())
    plain = wsoft.load_scene(_ies_stage()).lights[0].shaping
    assert not plain.ies_normalize and plain.ies_divisor() == pytest.approx(1300.0)


@pytest.mark.parametrize("case, attr, words", [
    ("missing", "shaping:ies:file", "cannot be read"),
    ("malformed", "shaping:ies:file", "photometric type B"),
    ("scale", "shaping:ies:angleScale", "must be > -1"),
    ("nan", "shaping:ies:angleScale", "not a finite number"),
])
def test_bad_ies_input_exits_2_in_one_line_naming_prim_and_attribute(tmp_path, case, attr, words):
    kw = {"missing": dict(file=str(tmp_path / "none.ies")), "malformed": dict(text=_lm63(V3, [0.0], [[1, 1, 1]], ptype=2)),
          "scale": dict(scale=-1.0), "nan": dict(scale=float("nan"))}[case]
    st = _ies_stage(tmp_path, **kw)
    path = str(tmp_path / "s.usda")
    st.GetRootLayer().Export(path)
    rc, _, err = run_captured(["render", path, "-t", "hard", "--width", "32", "--height", "24", "--out", str(tmp_path / "v.exr")])
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "/World/Light" in lines[0] and attr in lines[0] and words in lines[0], err


def test_a_negative_angle_scale_above_minus_one_is_read():
    assert wsoft.load_scene(_ies_stage(scale=-0.5)).lights[0].shaping.ies_angle_scale == -0.5


# -- the device's factor against the host's ------------------------------------------------------------------


@wp.kernel
def _weights(L: LightGPU, d: wp.array[wp.vec3],
             # outputs
             out: wp.array[wp.vec3]):
    i = wp.tid()
    out[i] = shaping_weight(L, d[i])


@pytest.mark.parametrize("scale, normalize, cone", [(0.0, False, None), (0.3, True, None), (-0.4, False, 40.0)])
def test_device_factor_is_the_hosts_bilinear_profile(scale, normalize, cone):
    light = wsoft.load_scene(_ies_stage(scale=scale, normalize=normalize, cone=cone)).lights[0]
    rng = np.random.default_rng(3)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    host = shaping_weights(light, d)
    out = wp.empty(len(d), dtype=wp.vec3, device="cpu")
    wp.launch(_weights, len(d), inputs=[light_gpu(light, 10.0), wp.array(d.astype(np.float32), dtype=wp.vec3, device="cpu")],
              outputs=[out], device="cpu")
    assert (host > 0).mean() > 0.05 and (host == 0).mean() > 0.2  # lit and unlit directions both drawn
    assert np.abs(out.numpy() - host).max() < 2e-4 * max(1.0, host.max())
    # the host's factor is the profile's at the scaled angle, over its divisor
    c = -d[:, 2]
    theta = ies_angle(np.degrees(np.arccos(np.clip(c, -1, 1))), scale)
    want = light.shaping.ies.sample(theta, np.degrees(np.arctan2(d[:, 1], d[:, 0]))) / light.shaping.ies_divisor()
    if cone is not None:
        want = np.where(np.degrees(np.arccos(np.clip(c, -1, 1))) > cone, 0.0, want)  # the cone cuts; it does not rescale
    assert np.allclose(host[:, 0], want, atol=1e-9)


def test_normalize_divides_by_the_mean_over_the_sphere_not_the_peak():
    """The reading chosen (UsdLux: "preserving the overall energy output"): normalize on divides by
    the mean intensity over 4 pi; off, by the peak. Their ratio along any direction is peak / mean."""
    on = wsoft.load_scene(_ies_stage(normalize=True)).lights[0]
    off = wsoft.load_scene(_ies_stage(normalize=False)).lights[0]
    d = np.array([[0.0, 0.0, -1.0], [math.sin(0.5), 0.0, -math.cos(0.5)]])
    ratio = shaping_weights(on, d)[:, 0] / shaping_weights(off, d)[:, 0]
    assert ratio == pytest.approx([1300.0 / on.shaping.ies.mean_intensity()] * 2)
    assert shaping_weights(off, d)[0, 0] == pytest.approx(1.0)  # the peak along -Z, horizontal 0


# -- the shaded image ----------------------------------------------------------------------------------------


def test_the_shaded_ground_is_the_closed_form_under_an_ies_point_light():
    """A point light with the example profile at ``angleScale`` 0.5 over a bare ground: each pixel's
    shade is ``a + b E`` with ``E = I(theta_ies, phi) cos(theta) / (d^2 + 1/pi)`` (a point light's
    unit area, docs/outputs.md; ``theta_ies = theta / 1.5 + 60``, so the profile's 90 degrees fall
    45 degrees off the axis), one ``a`` and ``b`` for the frame (albedo, ambient and exposure)."""
    f = wsoft.render(wsoft.load_scene(_ies_stage(normalize=False, scale=0.5)), "hard", width=96, height=72)
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-4) & (f["R"] < 0.999)
    P = np.stack([f["P.X"][g], f["P.Y"][g], f["P.Z"][g]], -1).astype(np.float64)
    v = P - np.array([0.0, 0.0, 3.0])
    dist = np.linalg.norm(v, axis=1)
    theta = np.degrees(np.arccos(-v[:, 2] / dist))
    I = read_ies(example_path()).sample(ies_angle(theta, 0.5), np.degrees(np.arctan2(v[:, 1], v[:, 0]))) / 1300.0
    E = I * (3.0 / dist) / (dist ** 2 + 1.0 / math.pi)
    assert (E > 0.05 * E.max()).sum() > 300 and (E == 0).sum() > 300  # lit and unlit (past 45 degrees) ground in view
    A = np.stack([np.ones_like(E), E], -1)
    coef, *_ = np.linalg.lstsq(A, f["R"][g].astype(np.float64), rcond=None)
    assert np.abs(A @ coef - f["R"][g]).max() < 4e-3  # float32 shading, 8 bits nowhere: within rounding
    assert coef[1] > 0.1
    dark = f["R"][g][E == 0]
    assert np.ptp(dark) < 1e-6  # where the profile is 0: the ambient alone
    assert (np.degrees(np.arctan2(np.hypot(P[:, 0], P[:, 1]), 3.0))[E == 0] > 37.0).all()  # the profile's zeros from 85 degrees


# -- the reference under a shaped area light ------------------------------------------------------------------


def _half_blocked_rect(focus: float):
    """A 2 x 2 rect light 3 above the ground with ``shaping:focus``, and a plate at height 1.5
    covering x < 0: from a ground point at x0 a light point at lx is visible iff lx >= -x0."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    from wsoft.stages.builders import add_mesh, quad_mesh

    add_mesh(st, "/World/Plate", quad_mesh([(-6, -6, 1.5), (0, -6, 1.5), (0, 6, 1.5), (-6, 6, 1.5)]), True, minimal=True)
    light = add_rect_light(st, "/World/Light", (0, 0, 3), 2.0, 2.0)
    if focus:
        UsdLux.ShapingAPI.Apply(light.GetPrim()).CreateShapingFocusAttr(focus)
        UsdLux.ShapingAPI(light.GetPrim()).CreateShapingConeAngleAttr(180.0)
    add_camera(st, "/World/Cam", (0, -6, 5), (0.0, 0, 0))
    return st


def _weighted_truth(x0, y0, focus, n=400):
    """sum(visible w) / sum(w) over a fine grid of the light, w = cos^focus of the direction from
    the light point to the receiver off -Z."""
    g = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    lx, ly = np.meshgrid(g, g, indexing="ij")
    v = np.stack([x0 - lx, y0 - ly, np.full_like(lx, -3.0)], -1)
    w = (3.0 / np.linalg.norm(v, axis=-1)) ** focus
    vis = lx >= -x0
    return float((w * vis).sum() / w.sum()), float(vis.mean())


@pytest.mark.parametrize("traversal", ["packet", pytest.param("ray", marks=pytest.mark.slow)])
def test_the_reference_weights_a_shaped_area_lights_samples(traversal):
    focus = 40.0
    f = wsoft.render(wsoft.load_scene(_half_blocked_rect(focus)), "reference", width=48, height=36,
                     samples=256, traversal=traversal)
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-4) & (np.abs(f["P.X"]) < 0.8) & (np.abs(f["P.Y"]) < 1.5)
    xs, ys, vs = f["P.X"][g], f["P.Y"][g], f["V"][g]
    assert len(xs) > 30
    truth = np.array([_weighted_truth(x, y, focus) for x, y in zip(xs, ys)])
    assert np.abs(truth[:, 0] - truth[:, 1]).max() > 0.1  # the weighting matters here
    se = f["V_stderr"][g]
    assert np.isfinite(se).all() and (se > 0).all()
    assert (np.abs(vs - truth[:, 0]) < 4.0 * se + 0.005).all()  # within its own standard error (weighted: fewer effective samples)
    assert np.abs(vs - truth[:, 0]).mean() < 0.01
    assert np.abs(vs - truth[:, 1]).max() > 0.08  # and the reference is not the plain fraction


@pytest.mark.slow
def test_an_unshaped_lights_reference_is_the_plain_fraction():
    f = wsoft.render(wsoft.load_scene(_half_blocked_rect(0.0)), "reference", width=48, height=36, samples=256)
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-4) & (np.abs(f["P.X"]) < 0.8) & (np.abs(f["P.Y"]) < 1.5)
    truth = np.array([_weighted_truth(x, y, 0.0)[1] for x, y in zip(f["P.X"][g], f["P.Y"][g])])
    assert np.abs(f["V"][g] - truth).max() < 0.03


def test_plan_names_the_profile(tmp_path):
    path = str(tmp_path / "s.usda")
    st = _ies_stage(scale=0.25, cone=60.0)
    st.GetRootLayer().Export(path)
    rc, out, err = run_captured(["plan", path])
    assert rc == 0, err
    assert f"IES profile: {example_path()} (angleScale 0.25, normalize off: over its peak), times the cone" in out
