"""UsdLux ShapingAPI: the loader reads and checks it, the shaded image honours it, receivers outside
a light's cone are masked out of its metrics (``reach.<light>``), and a narrow spot's views are one
frustum fitted to its cone."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from pxr import Sdf, UsdLux

import wsoft
from wsoft.cli import run_captured
from wsoft.io import read_exr
from wsoft.lightspace.light import LightGPU, light_gpu, light_reaches, reach_mask, shaping_weight, shaping_weights
from wsoft.metrics import compare
from wsoft.stages.builders import add_box, add_camera, add_point_light, add_quad, add_sphere_light, add_sun, make_stage

W, H = 160, 120
HEIGHT = 3.0  # the spot's height over the ground
FAR_BOX_X = (3.5, 4.1)  # a box about 50-54 degrees off the spot's axis (tan 52 x 3 = 3.84)


def _spot_stage(cone=30.0, *, radius=0.1, box=True, far_box=True, point=False, **shaping):
    """A ground +-5, optionally a box under the spot and one beside it, a spot (sphere light of
    ``radius``, or a point light) HEIGHT over the origin facing down, with ``ShapingAPI`` of ``cone``
    degrees (None: no ShapingAPI) and ``shaping`` (``ConeSoftness=...``, ``Focus=...``, ``FocusTint=...``)."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    if box:
        add_box(st, "/World/Box", (-0.3, -0.3, 0), (0.3, 0.3, 0.6))
    if far_box:
        add_box(st, "/World/Far", (FAR_BOX_X[0], -0.3, 0), (FAR_BOX_X[1], 0.3, 0.6))
    light = (add_point_light(st, "/World/Light", (0, 0, HEIGHT)) if point else add_sphere_light(st, "/World/Light", (0, 0, HEIGHT), radius))
    if cone is not None:
        api = UsdLux.ShapingAPI.Apply(light.GetPrim())
        api.CreateShapingConeAngleAttr(float(cone))
        for k, v in shaping.items():
            getattr(api, f"CreateShaping{k}Attr")(v)
    add_camera(st, "/World/Cam", (0, -7, 6), (0.5, 0, 0))
    return st


def _save(st, tmp_path, name="spot") -> str:
    path = str(tmp_path / f"{name}.usda")
    st.GetRootLayer().Export(path)
    return path


def _off_axis_deg(f) -> np.ndarray:
    """Degrees off the spot's axis (straight down from (0, 0, HEIGHT)) of each pixel's point."""
    r = np.hypot(f["P.X"], f["P.Y"])
    return np.degrees(np.arctan2(r, HEIGHT - f["P.Z"]))


# -- the loader --------------------------------------------------------------------------------------------


def test_the_loader_reads_every_shaping_input():
    st = _spot_stage(40.0, ConeSoftness=0.25, Focus=2.0, FocusTint=(0.1, 0.2, 0.3))
    light = wsoft.load_scene(st).lights[0]
    assert (light.shaping.cone_deg, light.shaping.softness, light.shaping.focus) == (40.0, 0.25, 2.0)
    assert light.shaping.focus_tint == pytest.approx((0.1, 0.2, 0.3))
    assert light.shaping.shaped and light.shaping.coned
    unshaped = wsoft.load_scene(_spot_stage(None)).lights[0]
    assert not unshaped.shaping.shaped and unshaped.shaping.cone_deg == 180.0


def test_an_applied_shaping_api_with_nothing_authored_is_the_fallback_hemisphere():
    st = _spot_stage(None)
    UsdLux.ShapingAPI.Apply(st.GetPrimAtPath("/World/Light"))
    assert wsoft.load_scene(st).lights[0].shaping.cone_deg == 90.0


def test_an_ies_file_is_read_beside_the_cone_without_a_warning():
    """The profile and the cone both shape the light (tests/test_ies.py has the profile's own cases)."""
    from wsoft.scene.ies import example_path

    st = _spot_stage(30.0)
    UsdLux.ShapingAPI(st.GetPrimAtPath("/World/Light")).CreateShapingIesFileAttr(Sdf.AssetPath(example_path()))
    scene = wsoft.load_scene(st)
    s = scene.lights[0].shaping
    assert s.ies is not None and s.coned and s.cone_deg == 30.0 and not scene.warnings


def test_shaping_on_a_distant_light_warns_and_is_not_applied():
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    sun = add_sun(st, "/World/Sun", 1.0)
    UsdLux.ShapingAPI.Apply(sun.GetPrim()).CreateShapingConeAngleAttr(20.0)
    add_camera(st, "/World/Cam", (0, -7, 6), (0, 0, 0))
    scene = wsoft.load_scene(st)
    assert not scene.lights[0].shaping.shaped
    assert any("/World/Sun" in w and "DistantLight" in w and "not applied" in w for w in scene.warnings)


@pytest.mark.parametrize("attr, value", [
    ("ConeAngle", 200.0), ("ConeAngle", -1.0), ("ConeAngle", float("nan")), ("ConeSoftness", -0.5), ("ConeSoftness", float("inf")),
    ("Focus", -2.0), ("Focus", float("nan")), ("FocusTint", (float("nan"), 0.0, 0.0)),
])
def test_bad_shaping_exits_2_naming_prim_and_attribute(tmp_path, attr, value):
    st = _spot_stage(30.0)
    getattr(UsdLux.ShapingAPI(st.GetPrimAtPath("/World/Light")), f"CreateShaping{attr}Attr")(value)
    rc, _, err = run_captured(["render", _save(st, tmp_path), "-t", "hard", "--width", "32", "--height", "24",
                                 "--out", str(tmp_path / "v.exr")])
    lines = err.strip().splitlines()
    name = {"ConeAngle": "shaping:cone:angle", "ConeSoftness": "shaping:cone:softness", "Focus": "shaping:focus",
            "FocusTint": "shaping:focusTint"}[attr]
    assert rc == 2 and len(lines) == 1 and "/World/Light" in lines[0] and name in lines[0], err


# -- the shaping factor ------------------------------------------------------------------------------------


@wp.kernel
def _weights(L: LightGPU, d: wp.array[wp.vec3],
             # outputs
             out: wp.array[wp.vec3]):
    i = wp.tid()
    out[i] = shaping_weight(L, d[i])


def _factor_formula(theta_deg, cone, softness, focus, tint):
    """smoothstep(cos cone, cos(cone (1 - softness)), cos theta) x (f + (1 - f) tint), f = cos^focus; 0 past the cone."""
    c = np.cos(np.radians(theta_deg))
    lo, hi = math.cos(math.radians(cone)), math.cos(math.radians(cone * (1.0 - softness)))
    t = np.clip((c - lo) / (hi - lo), 0.0, 1.0) if hi > lo else np.ones_like(c)
    w = np.where(c < lo, 0.0, t * t * (3.0 - 2.0 * t))
    f = np.maximum(c, 0.0) ** focus if focus > 0 else np.ones_like(c)
    return w[:, None] * (f[:, None] + (1.0 - f[:, None]) * np.asarray(tint)[None])


@pytest.mark.parametrize("cone, softness, focus, tint", [(30.0, 0.0, 0.0, (0, 0, 0)), (30.0, 0.4, 0.0, (0, 0, 0)),
                                                         (60.0, 1.0, 3.0, (0.2, 0.5, 1.0)), (120.0, 0.2, 1.5, (0, 0, 0))])
def test_softness_and_focus_follow_the_formula_on_device_and_host(cone, softness, focus, tint):
    st = _spot_stage(cone, ConeSoftness=softness, Focus=focus, FocusTint=tint)
    light = wsoft.load_scene(st).lights[0]
    theta = np.linspace(0.0, 179.0, 400)
    d = np.stack([np.sin(np.radians(theta)), np.zeros_like(theta), -np.cos(np.radians(theta))], -1)  # from the light, off -Z
    want = _factor_formula(theta, cone, softness, focus, tint)
    assert np.allclose(shaping_weights(light, d), want, atol=1e-9)
    out = wp.empty(len(d), dtype=wp.vec3, device="cpu")
    wp.launch(_weights, len(d), inputs=[light_gpu(light, 10.0), wp.array(d.astype(np.float32), dtype=wp.vec3, device="cpu")],
              outputs=[out], device="cpu")
    assert np.allclose(out.numpy(), want, atol=2e-5)
    lit_to = min(cone * (1 - softness), 90.0 if focus > 0 else 180.0)  # the focus's cosine power is 0 past 90 degrees
    assert (want[theta > cone] == 0).all() and (want[theta < lit_to - 1e-6, 0] > 0).all()


@wp.kernel
def _reaches(L: LightGPU, p: wp.array[wp.vec3],
             # outputs
             out: wp.array[wp.int32]):
    i = wp.tid()
    out[i] = wp.where(light_reaches(L, p[i]), 1, 0)


@pytest.mark.parametrize("cone", [10.0, 30.0, 89.0, 120.0, 170.0])
@pytest.mark.parametrize("radius", [0.0, 0.3])
def test_the_reach_mask_is_the_cone_widened_by_the_light_on_host_and_device(cone, radius):
    """A point is reached when its angle off the axis is at most the cone's plus asin(r / d), on
    the host (:func:`reach_mask`) and the device (:func:`light_reaches`) alike."""
    st = _spot_stage(cone, radius=radius, point=radius == 0.0)
    light = wsoft.load_scene(st).lights[0]
    pts = np.random.default_rng(1).normal(size=(4000, 3)) * 3 + np.array([0.0, 0.0, HEIGHT])
    v = pts - light.position
    d = np.linalg.norm(v, axis=1)
    off = np.degrees(np.arccos(np.clip(-v[:, 2] / d, -1, 1)))
    edge = cone + np.degrees(np.arcsin(np.clip(radius / d, 0, 1)))
    want = (off <= edge) | (d <= radius)
    clear = np.abs(off - edge) > 1e-3
    assert want.any() and (~want).any()
    assert (reach_mask(light, pts) == want)[clear].all()
    out = wp.empty(len(pts), dtype=wp.int32, device="cpu")
    wp.launch(_reaches, len(pts), inputs=[light_gpu(light, 10.0), wp.array(pts.astype(np.float32), dtype=wp.vec3, device="cpu")],
              outputs=[out], device="cpu")
    assert (out.numpy().astype(bool) == want)[clear].all()


# -- the image and the metrics ------------------------------------------------------------------------------


def _edge_pixel_deg(f) -> np.ndarray:
    """Per pixel, how many degrees off the axis one pixel's step spans there (the larger neighbour step)."""
    a = _off_axis_deg(f)
    gx = np.abs(np.diff(a, axis=1, append=a[:, -1:]))
    gy = np.abs(np.diff(a, axis=0, append=a[-1:, :]))
    return np.maximum(gx, gy)


@pytest.mark.parametrize("technique", ["reference", "hard"])
def test_the_cone_edge_on_the_ground_is_the_analytic_one_within_a_pixel(tmp_path, technique):
    """A 30-degree point spot over a bare ground: the lit disc in the shaded image and the reach
    mask end where the cone meets the ground, ``3 tan 30``, within one pixel."""
    st = _spot_stage(30.0, box=False, far_box=False, point=True)
    f = wsoft.render(wsoft.load_scene(st), technique, width=W, height=H, **({"samples": 16} if technique == "reference" else {}))
    ground = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-4)
    a = _off_axis_deg(f)
    slack = _edge_pixel_deg(f) + 1e-3
    inside, outside = ground & (a < 30.0 - slack), ground & (a > 30.0 + slack)
    assert inside.sum() > 200 and outside.sum() > 2000
    ambient = float(f["R"][outside].max())
    assert float(f["R"][inside].min()) > 1.2 * ambient  # every pixel inside the cone is lit past the ambient
    assert np.ptp(f["R"][outside]) < 1e-6  # and every pixel outside it has the ambient alone
    reach = f["reach.Light"]
    assert (reach[inside] == 1).all() and (reach[outside] == 0).all()
    if technique == "hard":
        assert (f["V"][inside] > 0.99).all()


def test_softness_fades_the_shaded_image_as_the_formula_says(tmp_path):
    """The shaded ground under a soft 40-degree point spot against the same without shaping: their
    lit parts' ratio follows the shaping factor (normalised on the axis)."""
    soft = wsoft.render(wsoft.load_scene(_spot_stage(40.0, box=False, far_box=False, point=True, ConeSoftness=0.5, Focus=1.0)), "hard", width=W, height=H)
    plain = wsoft.render(wsoft.load_scene(_spot_stage(None, box=False, far_box=False, point=True)), "hard", width=W, height=H)
    ground = (soft["A"] > 0) & (np.abs(soft["P.Z"]) < 1e-4)
    lit = lambda f: f["R"].astype(np.float64) - float(f["R"][ground].min())  # the ambient removed
    a = _off_axis_deg(soft)
    keep = ground & (a < 38.0) & (lit(plain) > 0.05) & (plain["R"] < 0.999) & (soft["R"] < 0.999)
    ratio = lit(soft)[keep] / lit(plain)[keep]
    want = _factor_formula(a[keep], 40.0, 0.5, 1.0, (0, 0, 0))[:, 0]
    k = ratio[np.argmin(a[keep])] / want[np.argmin(a[keep])]  # the two images' exposures differ by one factor
    assert np.abs(ratio / k - want).max() < 0.03


def test_receivers_outside_the_cone_are_masked_counted_and_in_the_exr(tmp_path):
    path = _save(_spot_stage(30.0), tmp_path)
    rc, _, err = run_captured(["render", path, "-t", "hard", "--width", "64", "--height", "48", "--out", str(tmp_path / "v.exr")])
    assert rc == 0, err
    ch = read_exr(str(tmp_path / "v.exr"))
    assert "reach.Light" in ch and 0 < ch["reach.Light"].mean() < 0.5
    fs = compare(path, ["hard"], samples=16, width=64, height=48)
    e = fs["hard"].stats["error"]
    covered = int((fs["hard"]["A"] > 0).sum())
    assert e["unreached_pixels"] > 0 and e["pixels"] + e["unreached_pixels"] == covered


def test_a_box_beside_a_30_degree_spot_casts_nothing_into_the_metrics_and_no_warning(tmp_path):
    """The box 50-54 degrees off a 30-degree spot's axis: its would-be shadow (the reference's V < 1
    beyond it) lies wholly outside the reach mask, and no pass warns of it."""
    fs = compare(_save(_spot_stage(30.0), tmp_path), ["hard", "pcss", "pwedge"], samples=16, width=W, height=H)
    ref = fs["reference"]
    beyond = (ref["A"] > 0) & (ref["P.X"] > FAR_BOX_X[1]) & (ref["V"] < 0.99)
    assert beyond.sum() > 20  # the would-be shadow is in view
    for label in ("hard", "pcss", "pwedge"):
        f = fs[label]
        assert (f["reach.Light"][beyond] == 0).all()
        assert not f.stats["warnings"], f.stats["warnings"]
        assert f.stats["error"]["mae"] < 0.01


# -- only what the scene calls for ------------------------------------------------------------------------------


def test_a_30_degree_spot_gets_one_frustum_and_plan_says_why(tmp_path):
    path = _save(_spot_stage(30.0), tmp_path)
    rc, out, err = run_captured(["plan", path])
    assert rc == 0, err
    assert "one frustum: its cone (shaping:cone:angle 30)" in out
    assert "emits: in a cone of 30 degrees" in out
    f = wsoft.render(path, "hard", width=64, height=48)
    assert not any(p.startswith("fit_cube") for p in f.stats["passes"]) and any(p.startswith("fit_light_view") for p in f.stats["passes"])
    plain = wsoft.render(wsoft.load_scene(_spot_stage(None)), "hard", width=64, height=48)
    assert any(p.startswith("fit_cube") for p in plain.stats["passes"])  # the same light unshaped: a cube map


def test_no_technique_warns_about_receivers_outside_the_cone(tmp_path):
    """Every technique on the 30-degree spot with a box outside its cone: no warning (the receivers
    the cone does not reach are masked, never 'left out of a view')."""
    from wsoft.techniques import TECHNIQUES, create

    path = _save(_spot_stage(30.0), tmp_path)
    scene = wsoft.load_scene(path)
    names = sorted(n for n in TECHNIQUES if create(n, {}).supports(scene, scene.lights[0]) is None)  # those drawing a sphere light
    assert len(names) >= 10
    fs = wsoft.render(path, names, width=48, height=36)
    assert len(fs.frames) == len(names)
    assert {label: f.stats["warnings"] for label, f in fs.frames.items() if f.stats["warnings"]} == {}


def test_cone_meets_balls_is_the_distance_to_the_widened_cone():
    """A ball meets the region a 30-degree spot can light (the cone widened by the light's radius)
    when its centre is within the light's radius plus its own of the cone; a cone past 90 degrees
    rules nothing out."""
    from wsoft.lightspace.light import cone_meets_balls

    light = wsoft.load_scene(_spot_stage(30.0, radius=0.1)).lights[0]
    # on the ground 3 below: the cone's edge at x = 3 tan 30 = 1.732; a ball at x, radius rb, meets it
    # when its distance to the edge line, (x - 1.732) cos 30, is at most 0.1 + rb
    xs = np.array([0.0, 1.9, 2.2, 2.4, 4.0])
    c = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], -1)
    got = cone_meets_balls(light, c, np.full(len(xs), 0.2))
    want = (xs - 3 * math.tan(math.radians(30))) * math.cos(math.radians(30)) <= 0.3
    assert (got == want).all() and got.any() and not got.all()
    wide = wsoft.load_scene(_spot_stage(120.0)).lights[0]
    assert cone_meets_balls(wide, c, np.zeros(len(xs))).all()


def test_the_reach_mask_of_a_frames_receivers_is_the_devices_test():
    """From REACH_ON_DEVICE points up the mask runs light_reaches on the CPU threads: it agrees with
    the float64 test on 40000 points around a 30-degree spot."""
    import wsoft.lightspace.light as lm

    light = wsoft.load_scene(_spot_stage(30.0, radius=0.3)).lights[0]
    pts = np.random.default_rng(2).normal(size=(40000, 3)) * 3 + np.array([0.0, 0.0, HEIGHT])
    fast = lm.reach_mask(light, pts)
    slow = np.concatenate([lm.reach_mask(light, pts[k:k + lm.REACH_ON_DEVICE - 1]) for k in range(0, len(pts), lm.REACH_ON_DEVICE - 1)])
    assert len(pts) >= lm.REACH_ON_DEVICE and fast.any() and (~fast).any()
    assert (fast != slow).sum() <= 2  # float32 against float64, on the cone's edge only


def test_pwedge_draws_only_the_edges_and_wedges_a_30_degree_spots_cone_can_use():
    """The box outside the cone adds no silhouette edge; the wedge tests fall to a small share of the
    unshaped light's (the cost the spot saves; its time: `wsoft bench lights`)."""
    shaped = wsoft.render(wsoft.load_scene(_spot_stage(30.0)), "pwedge", width=80, height=60)
    inside = wsoft.render(wsoft.load_scene(_spot_stage(30.0, far_box=False)), "pwedge", width=80, height=60)
    plain = wsoft.render(wsoft.load_scene(_spot_stage(None)), "pwedge", width=80, height=60)
    c = {k: f.stats["counters"]["techniques"]["pwedge"]["Light"] for k, f in (("shaped", shaped), ("inside", inside), ("plain", plain))}
    assert c["shaped"]["silhouette_edges"] == c["inside"]["silhouette_edges"] < c["plain"]["silhouette_edges"]
    assert c["shaped"]["wedge_tests"] <= 0.1 * c["plain"]["wedge_tests"]
    same = (shaped["reach.Light"] > 0) & (shaped["P.X"] == inside["P.X"]) & (shaped["P.Y"] == inside["P.Y"]) & (shaped["A"] > 0)
    assert same.sum() > 300 and np.array_equal(shaped["V"][same], inside["V"][same])  # the far box changed nothing the cone reaches


@pytest.mark.slow
def test_the_shaded_ground_is_the_closed_form_per_channel_under_a_coloured_tinted_spot():
    """A point spot (cone 50, softness 0.3, focus 2, focusTint (0.2, 0.5, 1), colour (1, 0.8, 0.6),
    intensity 3, exposure 1) over a grey ground: each channel is ``a + b E_c`` with
    ``E_c = colour_c shaping_c(theta) cos(theta) / (d^2 + 1/pi)`` (one ``a`` and ``b`` for the frame:
    albedo, ambient and exposure); the channels' own fits agree on ``b``."""
    st = _spot_stage(50.0, box=False, far_box=False, point=True, ConeSoftness=0.3, Focus=2.0, FocusTint=(0.2, 0.5, 1.0))
    lux = UsdLux.LightAPI(st.GetPrimAtPath("/World/Light"))
    lux.CreateColorAttr((1.0, 0.8, 0.6))
    lux.CreateIntensityAttr(3.0)
    lux.CreateExposureAttr(1.0)
    f = wsoft.render(wsoft.load_scene(st), "hard", width=96, height=72)
    g = (f["A"] > 0) & (np.abs(f["P.Z"]) < 1e-4) & (f["R"] < 0.999) & (f["G"] < 0.999) & (f["B"] < 0.999)
    P = np.stack([f["P.X"][g], f["P.Y"][g], f["P.Z"][g]], -1).astype(np.float64)
    v = P - np.array([0.0, 0.0, HEIGHT])
    dist = np.linalg.norm(v, axis=1)
    theta = np.degrees(np.arccos(-v[:, 2] / dist))
    shape = _factor_formula(theta, 50.0, 0.3, 2.0, (0.2, 0.5, 1.0))
    fall = (HEIGHT / dist) / (dist ** 2 + 1.0 / math.pi)
    slopes = []
    for k, (ch, colour) in enumerate(zip("RGB", (1.0, 0.8, 0.6))):
        E = colour * shape[:, k] * fall
        A = np.stack([np.ones_like(E), E], -1)
        coef, *_ = np.linalg.lstsq(A, f[ch][g].astype(np.float64), rcond=None)
        assert np.abs(A @ coef - f[ch][g]).max() < 4e-3, ch
        slopes.append(coef[1])
    assert (theta < 30).sum() > 200 and (theta > 50).sum() > 200  # inside and outside the cone in view
    assert np.ptp(slopes) < 0.01 * max(slopes)  # one exposure for all three: colour and tint carried per channel
